"""Joints declared exact (``<kinfw exact="..."/>``): never estimated, whatever the set.

Truths: the nominal URDF's own origins and axes (an exact joint's must come back
unchanged, to the digit, even where the data pull it); Pinocchio's forward kinematics of
the simulation's true robot (noise-free plates, recovered through the written URDF when
the exact joints are the truth's); and the model choice skipping its candidates when
every measured joint is exact.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import kinfw
from kinfw.geometry import angle_between
from kinfw.model import RobotModelError, load_robot
from kinfw.urdf import edit_urdf, origin_changes
from kinfw.verification.evaluation import choose_parameters
from tests.head_data import plate_data
from tests.paths import HEAD_URDF
from tests.pin_se3 import pin_fk

TABLE = ("x_table", "y_table")
PLATES = ("left_plate", "right_plate")


def _exact(xml: str, joints: tuple[str, ...]) -> str:
    """``xml`` with ``<kinfw exact="..."/>`` naming ``joints``."""
    return xml.replace("</robot>", f'  <kinfw exact="{" ".join(joints)}"/>\n</robot>')


@pytest.fixture(scope="module")
def experiment():
    """Noise-free plate poses of a head with 5 mm / 1 deg errors on every joint."""
    nominal = load_robot(HEAD_URDF)
    sim = kinfw.simulate(nominal, noise_m=0.0, noise_rad=0.0, error_mm=5.0, error_deg=1.0, seed=4)
    return nominal, sim


def _origins(robot, names):
    return {n: (robot.joint(n).parent_T_child, robot.joint(n).axis) for n in names}


@pytest.mark.slow
def test_exact_joints_keep_their_nominal_origins_where_the_data_pull_them(experiment):
    """A start that is the truth but for the table joints' axes, tilted by 0.36 deg, and
    100 noisy plate poses (0.5 mm, 0.3 deg): declared exact, ``full`` leaves the table
    joints' origins and axes as written; undeclared, ``full`` turns them back towards the
    truth's."""
    _, sim = experiment
    truth = load_robot(sim.truth_xml)
    tilt = pin.exp3(np.radians([0.3, -0.2, 0.0]))
    axes = {n: tilt @ truth.joint(n).axis for n in TABLE}
    wrong = edit_urdf(sim.truth_xml, joint_axes=axes)
    exact = load_robot(_exact(wrong, TABLE))
    data = plate_data(truth, 100, 3)
    fitted = load_robot(kinfw.calibrate(exact, data, parameters="full").urdf_xml)
    for name, (T, axis) in _origins(exact, TABLE).items():
        np.testing.assert_array_equal(fitted.joint(name).parent_T_child, T)
        np.testing.assert_array_equal(fitted.joint(name).axis, axis)
    free = load_robot(kinfw.calibrate(load_robot(wrong), data, parameters="full").urdf_xml)
    turned = [np.degrees(angle_between(free.joint(n).axis, axes[n])) for n in TABLE]
    assert min(turned) > 0.1, turned


@pytest.mark.slow
def test_exact_joints_that_are_the_truth_leave_the_rest_to_recover_it(experiment):
    """With the truth's table joints declared exact, ``full`` on noise-free plates gives
    the true robot's plate poses (Pinocchio) at random configurations to 1e-9."""
    nominal, sim = experiment
    truth = load_robot(sim.truth_xml)
    table = {n: truth.joint(n).parent_T_child for n in TABLE}
    axes = {n: truth.joint(n).axis for n in TABLE}
    start = _exact(edit_urdf(nominal.urdf_xml, joint_origins=table, joint_axes=axes), TABLE)
    fitted = kinfw.calibrate(load_robot(start), sim.data, parameters="full").urdf_xml
    names = sim.joint_names
    lower, upper = nominal.joint_limits(names)
    q = np.random.default_rng(0).uniform(lower, upper, size=(40, len(names)))
    for frame in PLATES:
        true_T = pin_fk(sim.truth_xml, names, q, frame)
        fit_T = pin_fk(fitted, names, q, frame)
        err = [
            np.linalg.norm(pin.log6(pin.SE3(a).inverse() * pin.SE3(b)).vector)
            for a, b in zip(true_T, fit_T, strict=True)
        ]
        assert max(err) < 1e-9, frame
    np.testing.assert_allclose(
        load_robot(fitted).joint("x_table").parent_T_child, table["x_table"], rtol=0, atol=1e-15
    )


def test_the_model_choice_fits_frames_alone_when_every_measured_joint_is_exact(experiment):
    nominal, sim = experiment
    exact = load_robot(_exact(nominal.urdf_xml, nominal.joint_names))
    choice = choose_parameters(exact, sim.data)
    assert (choice.parameters, choice.candidates, choice.k) == ("frames", (), 0)
    assert "exact" in choice.reason
    # a prefix only: the rest are scored or chosen by the rows as before
    partial = choose_parameters(load_robot(_exact(nominal.urdf_xml, TABLE)), sim.data)
    assert partial.parameters == "full" and "exact" not in partial.reason


@pytest.mark.parametrize(
    ("joints", "message"),
    [
        (("pan", "x_table"), r"'pan' but not \['y_table'\], above it"),
        (("left_plate_joint",), r"\['left_plate_joint'\], which are not movable joints"),
        (("elbow",), r"\['elbow'\], which are not movable joints"),
    ],
)
def test_an_exact_joint_must_be_movable_and_first_on_its_path(joints, message):
    with pytest.raises(RobotModelError, match=message):
        load_robot(_exact(HEAD_URDF.read_text(), joints))


def test_frames_moves_the_base_joint_and_the_end_frames_and_no_joint_axis(experiment):
    """``frames`` estimates the base and the end frames only: the export writes the base's
    motion into the root's fixed joint (``world_to_base``), and every movable joint keeps
    its origin and axis to the digit (before, the anchor was registered on the end frames
    and the table axes turned by ~0.5 deg to make up for it); the FK still reproduces the
    fit: the plates' in-sample residuals equal the fit's own (Pinocchio)."""
    nominal, sim = experiment
    result = kinfw.calibrate(nominal, sim.data, parameters="frames")
    fitted = load_robot(result.urdf_xml)
    for name in nominal.joint_names:
        np.testing.assert_array_equal(
            fitted.joint(name).parent_T_child, nominal.joint(name).parent_T_child
        )
        np.testing.assert_array_equal(fitted.joint(name).axis, nominal.joint(name).axis)
    moved = origin_changes(nominal, fitted)
    assert {c.joint for c in moved} <= {"world_to_base", "left_plate_joint", "right_plate_joint"}
    assert "world_to_base" in {c.joint for c in moved}
    model = result.calibration.refined.model
    q = sim.data.q_of(model.topology.joint_names)
    for frame in PLATES:
        np.testing.assert_allclose(
            pin_fk(result.urdf_xml, model.topology.joint_names, q, frame),
            model.frame_poses(q, frame),
            rtol=0,
            atol=1e-9,
        )
