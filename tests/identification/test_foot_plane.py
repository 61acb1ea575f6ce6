"""A table fixed to the foot a humanoid stands on (TALOS of example-robot-data).

Truth: TALOS's torso, both arms and its left leg (``talos_reduced.urdf``) with errors on
every joint of those paths (1 mm, 0.2 deg, :func:`kinfw.simulation.perturb_robot`). It
stands still (the left leg's six joints held at one bent configuration in every sample)
while a probe on each hand touches a table fixed in ``left_sole_link`` (``measured_in``),
60 contacts per arm, each solved by bisection on the elbow so that the true probe is on
the table (Pinocchio FK, to 1e-15 m). The leg's joints never move, but they carry no
observed frame, only the frame the table is fixed to: the table's unknown pose absorbs
the leg's constant transform, so the check of joint motion lets them through, the
calibration says so and keeps them at the nominal, and held-out contacts are predicted
as the truth's (up to the one scale contacts leave free).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinfw.geometry import inverse_transform
from kinfw.identification import identify
from kinfw.identification.problem import build_problem
from kinfw.measurements import (
    Measurements,
    check_joint_motion,
    fixed_in_experiment,
    observed_joints,
)
from kinfw.model import geometry_from_cpc, load_robot
from kinfw.observations import DatasetError
from kinfw.simulation import perturb_robot
from kinfw.urdf import export_urdf
from kinfw.verification.reporting import calibrate_and_report
from tests.contacts import TALOS_JOINTS, probe_distances, two_arm_contacts
from tests.erd import urdf_path

LEG = tuple(f"leg_left_{k}_joint" for k in range(1, 7))
STANCE = dict(zip(LEG, (0.02, -0.05, -0.4, 0.8, -0.4, 0.05), strict=True))
JOINTS = (*TALOS_JOINTS, *LEG)
FOOT = "left_sole_link"
OFFSETS = {
    "arm_left_7_link": np.array([0.01, 0.02, -0.2]),
    "arm_right_7_link": np.array([-0.01, 0.015, -0.21]),
}


def _table_in_foot(robot) -> np.ndarray:
    """The two-arm test's table (slightly tilted, 0.1 m above the base) as ``(n, d)`` in
    the foot's frame at the stance, the normal towards the foot's origin."""
    n = np.array([0.05, -0.03, -1.0]) / np.linalg.norm([0.05, -0.03, -1.0])
    d = n @ [0.3, 0.0, 0.1]
    q = np.array([[STANCE.get(j, 0.0) for j in JOINTS]])
    base_T_foot = robot.frame_poses(q, FOOT, JOINTS)[0]
    R, t = base_T_foot[:3, :3], base_T_foot[:3, 3]
    plane = np.append(R.T @ n, d - n @ t)
    return plane if plane[3] < 0 else -plane


@pytest.fixture(scope="module")
def standing():
    nominal = load_robot(urdf_path("talos_data/robots/talos_reduced.urdf"))
    rng = np.random.default_rng(1)
    truth = load_robot(perturb_robot(nominal, rng, joints=JOINTS))
    table = _table_in_foot(truth)
    data = two_arm_contacts(
        truth, table, OFFSETS, 60, rng, measured_in=FOOT, joint_names=JOINTS, fixed=STANCE
    )
    return nominal, truth, table, data


def test_the_still_leg_is_fixed_in_this_experiment_not_an_error(standing):
    nominal, _, _, data = standing
    assert fixed_in_experiment(data, nominal) == LEG
    with pytest.raises(DatasetError, match="leg_left_1_joint"):
        check_joint_motion(data, observed_joints(data, nominal))
    check_joint_motion(data, observed_joints(data, nominal), fixed=LEG)  # no error
    # a still joint on a probe's path is needed: refused, fixed or not elsewhere
    q = data.qs.copy()
    q[:, JOINTS.index("arm_left_6_joint")] = 0.1
    still_arm = Measurements(JOINTS, q, others=data.others)
    assert fixed_in_experiment(still_arm, nominal) == LEG
    with pytest.raises(DatasetError, match="'arm_left_6_joint' moves through 1 distinct"):
        check_joint_motion(still_arm, observed_joints(still_arm, nominal), fixed=LEG)
    # the leg moving: nothing is fixed
    q = data.qs.copy()
    q[::2, JOINTS.index("leg_left_4_joint")] += 0.1
    assert fixed_in_experiment(Measurements(JOINTS, q, others=data.others), nominal) == ()


@pytest.mark.slow
def test_standing_contacts_calibrate_with_the_leg_at_the_nominal(standing):
    """calibrate: the note names the leg's joints; the exported URDF's leg joints are
    the nominal's (origins and axes, 1e-9), and held-out distances of both probes from
    the table (new arm configurations, the same stance) are the truth's up to one
    common scale, to 1e-9 m."""
    nominal, truth, table, data = standing
    result = identify(nominal, data)
    (note,) = [n for n in result.notes if "fixed in this experiment" in n]
    assert all(j in note for j in LEG)
    exported = load_robot(result.urdf_xml)
    for j in LEG:
        moved = (
            inverse_transform(nominal.joint(j).parent_T_child) @ exported.joint(j).parent_T_child
        )
        np.testing.assert_allclose(moved, np.eye(4), rtol=0, atol=1e-9)
        np.testing.assert_allclose(exported.joint(j).axis, nominal.joint(j).axis, rtol=0, atol=1e-9)
    found = {(u.kind, u.name): u.value for u in result.refined.unknowns}
    rng = np.random.default_rng(2)
    q = np.column_stack(
        [
            rng.uniform(*truth.joint_limits((j,)), 200) * 0.8
            if j not in STANCE
            else np.full(200, STANCE[j])
            for j in JOINTS
        ]
    )
    pred, true = [], []
    for frame, offset in OFFSETS.items():
        side = "left" if "left" in frame else "right"
        o = found["offset", f"{frame}:{side}_tip"]
        pred.append(probe_distances(exported, q, JOINTS, frame, o, found["plane", "table"], FOOT))
        true.append(probe_distances(truth, q, JOINTS, frame, offset, table, FOOT))
    pred, true = np.concatenate(pred), np.concatenate(true)
    assert np.abs(true).max() > 0.1  # held out: off the table
    ratio = float(pred @ true / (true @ true))
    assert abs(ratio - 1.0) < 0.05
    np.testing.assert_allclose(pred, ratio * true, rtol=0, atol=1e-9)


def _distances(robot, found, qs) -> np.ndarray:
    """Both probes' signed distances (m) from the table at ``qs`` through ``robot``
    (Pinocchio), with the offsets and plane of ``found`` (the fit's unknowns), flattened."""
    return np.concatenate(
        [
            probe_distances(
                robot,
                qs,
                JOINTS,
                frame,
                found["offset", f"{frame}:{'left' if 'left' in frame else 'right'}_tip"],
                found["plane", "table"],
                FOOT,
            )
            for frame in OFFSETS
        ]
    )


def _exported_distances(nominal, problem, x, qs) -> np.ndarray:
    """:func:`_distances` for the problem's parameters ``x``, through the URDF exported as
    the calibration exports it (not the CasADi model)."""
    robot = load_robot(
        export_urdf(
            nominal,
            geometry_from_cpc(problem.model_at(x)),
            root_is_measurement_frame=problem.model_frame is None,
            base_motion=problem.base_motion_at(x),
        ).urdf_xml
    )
    return _distances(robot, {(u.kind, u.name): u.value for u in problem.unknowns_at(x)}, qs)


@pytest.mark.slow
def test_the_default_moves_the_export_only_along_determined_directions(standing):
    """Noisy standing contacts (0.2 mm) under the default (``parameters="auto"``: 0.8 rows
    per parameter, so the full set under a prior) leave the rigid motion of the robot
    with its table free: the prior's rows determine it, the data do not. The null space
    of the data's Jacobian, by central differences of the probes' distances through the
    exported URDF (Pinocchio), holds none of the estimate (the robot's chart coordinates
    in m and rad, the unknowns' weighted by UNKNOWN_WEIGHT), as without a prior. With the
    prior's rows in the Jacobian that finds the null space, 0.69 mm of it was left there."""
    from kinfw.identification.problem._refine import UNKNOWN_WEIGHT

    nominal, _, _, data = standing
    rng = np.random.default_rng(5)
    noisy = [
        replace(g, distance_m=g.distance_m + rng.normal(0, 2e-4, len(g.sample)))
        for g in data.others
    ]
    data = data.with_groups(noisy)
    result = calibrate_and_report(nominal, data)
    assert result.model.parameters == ("full",) and result.model.prior is not None
    refined = result.calibration.refined
    prior = result.model.prior
    problem = build_problem(nominal, data, parameters="full", prior=prior)
    assert problem.names == refined.parameter_names
    x, qs = refined.estimate, data.qs
    found = {(u.kind, u.name): u.value for u in refined.unknowns}
    np.testing.assert_allclose(  # this export of x is the calibration's URDF
        _exported_distances(nominal, problem, x, qs),
        _distances(load_robot(result.urdf_xml), found, qs),
        rtol=0,
        atol=1e-12,
    )
    cols = np.flatnonzero(refined.free)
    robot = np.concatenate([np.full(b.size, b in problem.robot_blocks) for b in problem.blocks])
    scale = np.where(robot[cols], 1.0, UNKNOWN_WEIGHT)
    h = 1e-6
    columns = [
        _exported_distances(nominal, problem, x + h * e, qs)
        - _exported_distances(nominal, problem, x - h * e, qs)
        for e in np.eye(len(x))[cols]
    ]
    J = np.stack(columns, axis=1) / (2 * h) / scale
    c = np.linalg.norm(J, axis=0)
    _, s, Vt = np.linalg.svd(J / c, full_matrices=True)
    s = np.concatenate([s, np.zeros(len(Vt) - len(s))])
    null = Vt[s < 1e-7 * s[0]]
    assert len(null) >= 3  # the robot's motion along the table, at least
    Q = np.linalg.qr((null / c).T)[0]
    y = scale * x[cols]
    assert np.linalg.norm(y) > 1e-2  # the fit moved
    assert np.linalg.norm(Q.T @ y) < 1e-9 * np.linalg.norm(y)
