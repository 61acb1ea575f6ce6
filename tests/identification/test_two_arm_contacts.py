"""Two arms touching one table calibrate jointly (TALOS of example-robot-data).

Truth: TALOS's torso and both arms (``talos_reduced.urdf``) with errors on every joint
of those paths (1 mm, 0.2 deg, :func:`kinfw.simulation.perturb_robot`); a probe on each
arm's last link at an offset the fit does not know touches one tilted table, 60 contacts
per arm, each configuration solved by bisection on the elbow so that the true probe is on
the table (Pinocchio FK, to 1e-15 m). One plane unknown is shared by both arms' contacts.
"""

from __future__ import annotations

import numpy as np
import pytest

from kinfw.geometry import inverse_transform
from kinfw.identification import refine
from kinfw.identification.problem import WORLD_MOTION, NoiseModel
from kinfw.model import geometry_from_cpc, load_robot
from kinfw.simulation import perturb_robot
from kinfw.urdf import export_urdf
from kinfw.verification.evaluation import random_joint_values
from tests.contacts import TALOS_JOINTS, probe_distances, two_arm_contacts
from tests.erd import urdf_path

OFFSETS = {
    "arm_left_7_link": np.array([0.01, 0.02, -0.2]),
    "arm_right_7_link": np.array([-0.01, 0.015, -0.21]),
}


def _table() -> np.ndarray:
    """A slightly tilted table 0.1 m above the base, normal towards the base's origin."""
    n = np.array([0.05, -0.03, -1.0]) / np.linalg.norm([0.05, -0.03, -1.0])
    return np.append(n, n @ [0.3, 0.0, 0.1])


@pytest.fixture(scope="module")
def talos():
    nominal = load_robot(urdf_path("talos_data/robots/talos_reduced.urdf"))
    rng = np.random.default_rng(1)
    truth = load_robot(perturb_robot(nominal, rng, joints=TALOS_JOINTS))
    data = two_arm_contacts(truth, _table(), OFFSETS, 60, rng)
    return nominal, truth, data


def test_two_arms_on_one_table_share_the_plane_and_recover_the_truth(talos):
    """Noise-free: every contact back on the table; one plane, one probe per arm; the
    held-out distances of both probes from the table equal the truth's up to one common
    scale (what contacts determine), and the torso's first joint, whose line a rigid
    motion of robot and table absorbs, stays at the nominal (1e-8 m and rad: the
    projection's Gauss-Newton steps end at rounding of the ill-conditioned directions)."""
    nominal, truth, data = talos
    assert {g.frame for g in data.groups("plane")} == set(OFFSETS)
    result = refine(nominal, data, noise=NoiseModel(sigmas={"distance": 1e-4}))
    assert result.converged
    assert max(np.abs(g.component("distance")).max() for g in result.residuals) < 1e-10
    found = {(u.kind, u.name): u.value for u in result.unknowns}
    assert sorted(found) == [
        ("offset", "arm_left_7_link:left_tip"),
        ("offset", "arm_right_7_link:right_tip"),
        ("plane", "table"),
    ]
    ident = result.identifiability
    assert ident.n_parameters - ident.rank == 7  # a world motion and the scale
    # named: directions whose robot part acts on the contacts as a motion of the base
    # (3 of the world motion's 6 here: the in-plane ones change no distance, and one
    # needs the probes' offsets re-expressed), never more than the world motion's 6
    named = [why for _, why in ident.unidentifiable if why == WORLD_MOTION]
    assert 0 < len(named) <= 6
    exported = load_robot(export_urdf(nominal, geometry_from_cpc(result.model)).urdf_xml)
    q = random_joint_values(truth, TALOS_JOINTS, 200, np.random.default_rng(2))
    pred, true = [], []
    for frame, offset in OFFSETS.items():
        side = "left" if "left" in frame else "right"
        found_offset = found["offset", f"{frame}:{side}_tip"]
        pred.append(
            probe_distances(exported, q, TALOS_JOINTS, frame, found_offset, found["plane", "table"])
        )
        true.append(probe_distances(truth, q, TALOS_JOINTS, frame, offset, _table()))
    pred, true = np.concatenate(pred), np.concatenate(true)
    assert np.abs(true).max() > 0.1  # held out: off the table
    ratio = float(pred @ true / (true @ true))
    assert abs(ratio - 1.0) < 0.05
    np.testing.assert_allclose(pred, ratio * true, rtol=0, atol=1e-9)
    joint, nominal_joint = exported.joint("torso_1_joint"), nominal.joint("torso_1_joint")
    moved = inverse_transform(nominal_joint.parent_T_child) @ joint.parent_T_child
    np.testing.assert_allclose(moved, np.eye(4), rtol=0, atol=1e-8)
    np.testing.assert_allclose(joint.axis, nominal_joint.axis, rtol=0, atol=1e-8)
