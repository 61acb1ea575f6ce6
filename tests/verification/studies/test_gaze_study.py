"""The value-of-calibration study (kinfw.verification.studies, ``kinfw reproduce gaze``):
its geometry against hand computations, its UR10 against the shipped URDF, and a small
run through the command line."""

import json
import math

import numpy as np
import pytest

from kinfw.cli._main import main as kinfw_main
from kinfw.control import GazeSolver
from kinfw.model import Robot, builtin_head_urdf, load_robot
from kinfw.simulation import perturb_robot
from kinfw.verification.studies import (
    HEAD_DISTANCE_M,
    head_points,
    pointing_errors_rad,
    triangulate,
    triangulation_errors_m,
    ur10_urdf,
)
from tests.erd import urdf_path


@pytest.fixture(scope="module")
def head():
    return load_robot(builtin_head_urdf())


def _camera_poses(robot, qs):
    return np.stack([robot.frame_poses(qs, c) for c in robot.default_cameras], axis=1)


def test_triangulate_skew_lines_gives_the_hand_computed_midpoint():
    # (s, 0, 0) and (1 + u, 2, 5 - 2u): the joining vector (1 + u - s, 2, 5 - 2u) is
    # perpendicular to both at u = 2.5, s = 3.5: closest points (3.5, 0, 0), (3.5, 2, 0)
    origins = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 5.0]])
    directions = np.array([[3.0, 0.0, 0.0], [1.0, 0.0, -2.0]])
    np.testing.assert_allclose(triangulate(origins, directions), [3.5, 1.0, 0.0], atol=1e-14)


def test_triangulate_intersecting_rays_gives_the_intersection():
    point = np.array([0.3, -0.2, 2.0])
    origins = np.array([[-0.1, 0.0, 0.0], [0.1, 0.05, 0.0]])
    batch = np.stack([origins, origins + 1.0])
    estimate = triangulate(batch, np.stack([point - origins, point - origins]))
    np.testing.assert_allclose(estimate, [point, point + 1.0], atol=1e-14)
    assert estimate.shape == (2, 3)


def test_a_perfect_model_has_no_pointing_or_triangulation_error(head):
    rng = np.random.default_rng(3)
    points, distance = head_points(head, 50, rng, head.default_cameras)
    assert np.all((distance >= HEAD_DISTANCE_M[0]) & (distance <= HEAD_DISTANCE_M[1]))
    lower, upper = head.joint_limits()
    qs = rng.uniform(lower, upper, size=(50, len(lower)))
    root_T = _camera_poses(head, qs)
    assert np.max(pointing_errors_rad(root_T, root_T, points[:, None])) < 1e-9
    assert np.max(triangulation_errors_m(root_T, root_T, points)) < 1e-9


def test_a_camera_offset_gives_the_hand_computed_pointing_error():
    # the true camera at the origin looks along z at a point 10 m away; the model puts
    # the camera 10 mm along its x axis: it sees the point at atan(0.01 / 10) off axis
    true_T = np.eye(4)
    model_T = np.eye(4)
    model_T[:3, 3] = [0.01, 0.0, 0.0]
    point = np.array([0.0, 0.0, 10.0])
    assert pointing_errors_rad(model_T, true_T, point) == pytest.approx(math.atan(1e-3), abs=1e-15)
    # a model camera turned by 0.02 rad about y: 0.02 rad for any point in front of it
    # in its x-z plane (perpendicular to the turn's axis)
    turned = np.eye(4)
    turned[:3, :3] = [
        [math.cos(0.02), 0, math.sin(0.02)],
        [0, 1, 0],
        [-math.sin(0.02), 0, math.cos(0.02)],
    ]
    points = np.array([[0.3, 0.0, 1.0], [0.0, 0.0, 3.0], [-1.0, 0.0, 2.0]])
    np.testing.assert_allclose(pointing_errors_rad(turned, true_T, points), 0.02, atol=1e-14)


def test_both_cameras_shifted_shift_the_triangulated_point_by_the_same(head):
    rng = np.random.default_rng(4)
    points, _ = head_points(head, 20, rng, head.default_cameras)
    lower, upper = head.joint_limits()
    true_T = _camera_poses(head, rng.uniform(lower, upper, size=(20, len(lower))))
    model_T = true_T.copy()
    model_T[..., :3, 3] += [0.003, -0.004, 0.0]  # the rig known 5 mm off
    np.testing.assert_allclose(triangulation_errors_m(model_T, true_T, points), 0.005, atol=1e-9)


def test_pointing_and_raw_angle_obey_the_triangle_inequality_with_the_model_floor(head):
    # on the true camera's optical axis, the point lies at the raw angle; the model's
    # remaining angle (error_rad) and the pointing error bound it both ways
    true_head = load_robot(perturb_robot(head, np.random.default_rng(5), origin_mm=5.0))
    points, _ = head_points(head, 15, np.random.default_rng(6), head.default_cameras)
    solver = GazeSolver(head)
    fixations = [solver.fixate(p) for p in points]
    qs = np.array([f.q for f in fixations])
    floor = np.array([f.error_rad for f in fixations])
    true_T, model_T = _camera_poses(true_head, qs), _camera_poses(head, qs)
    toward = points[:, None] - true_T[..., :3, 3]
    camera_p = np.einsum("pcji,pcj->pci", true_T[..., :3, :3], toward)
    raw = np.arccos(camera_p[..., 2] / np.linalg.norm(camera_p, axis=-1))
    pointing = pointing_errors_rad(model_T, true_T, points[:, None])
    assert np.all(np.abs(raw - pointing) <= floor + 1e-9)
    assert np.all(raw <= floor + pointing + 1e-9)


def test_ur10_from_dh_matches_the_shipped_ur10_urdf():
    shipped = load_robot(urdf_path("ur_description/urdf/ur10_robot.urdf"))
    ours = Robot(ur10_urdf(), "<ur10>")
    assert ours.joint_names == shipped.joint_names
    qs = np.random.default_rng(7).uniform(-math.pi, math.pi, size=(20, 6))
    base_T_tool = np.linalg.inv(shipped.frame_poses(qs, "base")) @ shipped.frame_poses(qs, "tool0")
    np.testing.assert_allclose(ours.frame_poses(qs, "tool0"), base_T_tool, atol=1e-9)


@pytest.mark.slow
def test_reproduce_gaze_small_run_shows_calibration_helps(tmp_path, capsys):
    code = kinfw_main(["reproduce", "gaze", "--out", str(tmp_path), "--trials", "1", "--seed", "2"])
    out = capsys.readouterr().out
    assert code == 0
    assert "pointing error (deg)" in out and "UR10 reach" in out
    assert (tmp_path / "gaze.png").stat().st_size > 10_000
    doc = json.loads(
        (tmp_path / "gaze.json").read_text(),
        parse_constant=lambda c: pytest.fail(f"non-strict JSON constant {c}"),
    )
    nominal, calibrated = doc["summary"]["nominal"], doc["summary"]["calibrated"]
    for camera in doc["setup"]["cameras"]:
        assert (
            calibrated[camera]["pointing_deg"]["median"]
            < 0.2 * nominal[camera]["pointing_deg"]["median"]
        )
    for key in ("triangulation_mm", "arm_position_mm", "arm_rotation_deg"):
        assert calibrated[key]["p95"] < 0.2 * nominal[key]["median"], key
    # calibrated to noise level: well under the 5 mm / 1 deg errors of the true robots
    assert calibrated["arm_position_mm"]["median"] < 2.0
    assert np.array(doc["pointing_rad"]).shape == (1, 100, 2, 2)
    assert np.array(doc["arm_position_m"]).shape == (1, 50, 2)
