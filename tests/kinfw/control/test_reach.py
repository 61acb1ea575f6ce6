"""kinfw.control against independent truth: targets made by Pinocchio FK of random
in-range configurations (verified again by FK, not by the result's fields), a planar
2R arm's hand geometry and a brute-force grid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kinfw.control import reach
from kinfw.model import Robot, RobotModelError, UnknownFrameError, load_robot
from tests.erd import urdf_path
from tests.robots import ARM_6R, PLANAR_2R


@pytest.fixture(scope="module")
def arm() -> Robot:
    return Robot(ARM_6R)


@pytest.fixture(scope="module")
def planar() -> Robot:
    return Robot(PLANAR_2R)


def random_configurations(robot: Robot, n: int, seed: int) -> np.ndarray:
    lower, upper = robot.joint_limits()
    lower = np.where(np.isfinite(lower), lower, -math.pi)
    upper = np.where(np.isfinite(upper), upper, math.pi)
    return np.random.default_rng(seed).uniform(lower, upper, size=(n, len(lower)))


def pose_errors(a_T: np.ndarray, b_T: np.ndarray) -> tuple[float, float]:
    """Distance (m) and rotation angle (rad) between two poses (atan2 of the rotation's
    sine and cosine: acos alone loses 1e-8 rad near zero)."""
    r = a_T[:3, :3].T @ b_T[:3, :3]
    sin = 0.5 * np.linalg.norm([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    angle = math.atan2(sin, 0.5 * (np.trace(r) - 1.0))
    return float(np.linalg.norm(a_T[:3, 3] - b_T[:3, 3])), angle


@pytest.mark.parametrize(
    ("name", "frame"), [("arm6", "flange"), ("ur10", "tool0")], ids=["arm6", "ur10"]
)
def test_fk_poses_are_reached(arm, name, frame):
    robot = arm if name == "arm6" else load_robot(urdf_path("ur_description/urdf/ur10_robot.urdf"))
    lower, upper = robot.joint_limits()
    for q_true in random_configurations(robot, 8, seed=1):
        target = robot.frame_poses(q_true, frame)
        result = reach(robot, frame, target)
        position, rotation = pose_errors(robot.frame_poses(result.q, frame), target)
        assert position < 1e-9 and rotation < 1e-9, (q_true, position, rotation)
        assert result.reached and result.rotation_error_rad is not None
        assert np.all(result.q >= lower) and np.all(result.q <= upper)


def test_fk_points_are_reached(arm):
    for q_true in random_configurations(arm, 8, seed=2):
        point = arm.frame_poses(q_true, "flange")[:3, 3]
        result = reach(arm, "flange", point)
        assert np.linalg.norm(arm.frame_poses(result.q, "flange")[:3, 3] - point) < 1e-9
        assert result.reached and result.rotation_error_rad is None


@pytest.mark.parametrize("target", [[6.0, 8.0, 0.0], [0.0, -10.0, 0.5]])
def test_out_of_reach_gives_distance_to_workspace(planar, target):
    """10 m from a planar 2R arm (0.5 + 0.3 m) within j1's range: the closest point is the
    stretched arm aimed at the target, |p_xy| - 0.8 m away in the plane (hand geometry),
    or, when the direction is beyond j1's range, the brute-force minimum of a grid."""
    target = np.array(target)
    result = reach(planar, "tool", target)
    assert not result.reached
    tip = planar.frame_poses(result.q, "tool")[:3, 3]
    assert result.position_error_m == pytest.approx(np.linalg.norm(tip - target), abs=1e-12)
    j1, j2 = np.meshgrid(np.linspace(-0.5, 0.5, 1001), np.linspace(-3, 3, 3001))
    x = 0.5 * np.cos(j1) + 0.3 * np.cos(j1 + j2)
    y = 0.5 * np.sin(j1) + 0.3 * np.sin(j1 + j2)
    brute = np.sqrt((x - target[0]) ** 2 + (y - target[1]) ** 2 + target[2] ** 2).min()
    assert result.position_error_m <= brute + 1e-12
    assert result.position_error_m == pytest.approx(brute, abs=1e-5)
    angle = math.atan2(target[1], target[0])
    if abs(angle) <= 0.5:
        expected = math.hypot(math.hypot(target[0], target[1]) - 0.8, target[2])
        assert result.position_error_m == pytest.approx(expected, abs=1e-9)
    else:
        assert "j1" in result.at_limits


def test_limits_are_respected(planar):
    """A point within the arm's radius but beyond j1's range: joints within limits, j1 at
    its limit, the error the grid minimum."""
    target = np.array([0.6 * math.cos(1.2), 0.6 * math.sin(1.2), 0.0])
    result = reach(planar, "tool", target)
    lower, upper = planar.joint_limits()
    assert np.all(result.q >= lower) and np.all(result.q <= upper)
    assert result.q[0] == 0.5 and result.at_limits == ("j1",)
    j2 = np.linspace(-3, 3, 600001)
    x = 0.5 * math.cos(0.5) + 0.3 * np.cos(0.5 + j2)
    y = 0.5 * math.sin(0.5) + 0.3 * np.sin(0.5 + j2)
    brute = np.hypot(x - target[0], y - target[1]).min()
    assert result.position_error_m == pytest.approx(brute, abs=1e-9)


def test_free_joints_subset_keeps_the_others(arm):
    rng = np.random.default_rng(3)
    q_start = random_configurations(arm, 1, seed=4)[0]
    q_true = q_start.copy()
    q_true[:3] += rng.uniform(-0.3, 0.3, size=3)
    point = arm.frame_poses(q_true, "flange")[:3, 3]
    result = reach(arm, "flange", point, q_start=q_start, free_joints=("j1", "j2", "j3"))
    assert np.array_equal(result.q[3:], q_start[3:])
    assert np.linalg.norm(arm.frame_poses(result.q, "flange")[:3, 3] - point) < 1e-9


def test_bad_inputs_are_clear_errors(arm):
    with pytest.raises(UnknownFrameError, match="no frame 'hand'"):
        reach(arm, "hand", [0.1, 0.2, 0.3])
    with pytest.raises(RobotModelError, match=r"expected a point \(3,\) or a pose \(4, 4\)"):
        reach(arm, "flange", np.eye(4)[:3])
    with pytest.raises(RobotModelError, match="target point: expected 3 finite numbers"):
        reach(arm, "flange", [0.1, np.inf, 0.3])
    with pytest.raises(RobotModelError, match="'flange_joint' is not movable"):
        reach(arm, "flange", [0.1, 0.2, 0.3], free_joints=("j1", "flange_joint"))
    with pytest.raises(RobotModelError, match="no joint 'j9'"):
        reach(arm, "flange", [0.1, 0.2, 0.3], free_joints=("j1", "j9"))
    with pytest.raises(RobotModelError, match="frame 'l1': none of the joints"):
        reach(arm, "l1", [0.1, 0.2, 0.3], free_joints=("j2",))
    with pytest.raises(RobotModelError, match="q_start: expected 6 finite values"):
        reach(arm, "flange", [0.1, 0.2, 0.3], q_start=[0.0] * 5)
    bad = np.eye(4)
    bad[:3, :3] *= 2.0
    with pytest.raises(RobotModelError, match="target"):
        reach(arm, "flange", bad)


def test_one_joint_robot():
    """A one-joint model (Pinocchio hands back its Jacobian as a (6,) vector): the
    stretched 0.8 m arm reaches the point at angle 0.3 rad with j1 = 0.3 (by hand)."""
    robot = Robot(PLANAR_2R.replace('name="j2" type="revolute"', 'name="j2" type="fixed"'))
    assert robot.joint_names == ("j1",)
    result = reach(robot, "tool", [0.8 * math.cos(0.3), 0.8 * math.sin(0.3), 0.0])
    assert result.reached
    assert result.q[0] == pytest.approx(0.3, abs=1e-12)


def test_ur10_answer_is_the_turn_nearest_the_start():
    """The UR10's joints range over +-2 pi, so every pose has equivalents a whole turn
    apart: from the zero start the answer is the one within [-pi, pi] (the smallest
    motion), and it still reaches the pose by FK."""
    ur10 = load_robot(urdf_path("ur_description/urdf/ur10_robot.urdf"))
    q_true = np.array([6.0, -5.8, 1.0, 4.0, -4.5, 5.9])  # wound up: several near 2 pi
    target = ur10.frame_poses(q_true, "tool0")
    res = reach(ur10, "tool0", target, q_start=np.zeros(6))
    assert res.reached
    assert np.all(np.abs(res.q) <= math.pi + 1e-9), res.q
    assert max(pose_errors(ur10.frame_poses(res.q, "tool0"), target)) < 1e-9


def test_nearest_turn_by_hand():
    """Revolute values move by whole turns towards the reference within the limits; a
    turn that would leave the limits is not taken; prismatic values never move."""
    from kinfw.control import nearest_turn

    two_pi = 2 * math.pi
    x = np.array([5.5, 3.0, -6.0, 5.5])
    reference = np.array([0.0, -3.0, 6.0, 0.0])
    lower = np.array([-7.0, -3.1, -7.0, -7.0])
    upper = np.array([7.0, 3.1, 7.0, 7.0])
    revolute = np.array([True, True, True, False])
    np.testing.assert_allclose(
        nearest_turn(x, reference, lower, upper, revolute),
        [5.5 - two_pi, 3.0, -6.0 + 2 * two_pi, 5.5],
        atol=1e-15,
    )


def test_held_joint_outside_its_limits_is_an_error(arm):
    """A joint held at a value beyond its limits (20 rad: degrees typed as radians)
    would make an answer outside the limits: refused, naming the joint in degrees."""
    q = np.zeros(len(arm.joint_names))
    q[0] = 20.0
    with pytest.raises(RobotModelError, match=r"joint 'j1' is held .* at 1145\.92 deg"):
        reach(arm, "flange", [0.3, 0.2, 0.4], q_start=q, free_joints=("j2", "j3", "j5"))
    free = reach(arm, "flange", [0.3, 0.2, 0.4], q_start=q)  # j1 free: only a start, clipped
    assert free.q[0] <= 3.0
