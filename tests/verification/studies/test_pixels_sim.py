"""Simulated images (``kinfw simulate --pixels``, ``kinfw demo --pixels``), their view,
and the pixel path against PnP poses and against the Cramér-Rao bound."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import chi2

from kinfw.camera import CameraIntrinsics, Chessboard
from kinfw.cli._main import main
from kinfw.geometry import transform_from_rotation_translation
from kinfw.identification import identify
from kinfw.measurements import read_measurements
from kinfw.model import Robot, load_robot
from kinfw.simulation import DEFAULT_CAMERA, visible_points
from kinfw.verification.studies import (
    arm_experiment,
    camera_target_errors,
    crlb_held_out,
    pose_errors,
    pose_path_data,
    target_pose,
)
from tests.robots import ARM_6R

BOARD = Chessboard(9, 6, 0.04)
CAMERA = CameraIntrinsics(640, 480, 600.0, 600.0, 319.5, 239.5, name="flange")
Q0 = np.array([0.3, -0.4, 0.9, 0.2, 0.7, -0.3])


def _rot_y(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


# -- visibility ----------------------------------------------------------------------------


def test_visible_points_against_hand_geometry():
    # board frame = camera frame; fx = 600, cx = 319.5, cy = 239.5, 640 x 480, margin 5 px
    points = np.array(
        [
            [0.0, 0.0, 1.0],  # image centre: seen
            [0.0, 0.0, -1.0],  # behind the camera
            [0.6, 0.0, 1.0],  # u = 679.5: right of the image
            [0.5, 0.0, 1.0],  # u = 619.5 <= 634.5: seen
            [0.0, 0.4, 1.0],  # v = 479.5 > 474.5: below the image (margin)
            [0.1, 0.1, 1.0],  # seen
        ]
    )
    eye = np.eye(4)[None]
    seen = visible_points(DEFAULT_CAMERA, eye, points, min_corners=3)
    np.testing.assert_array_equal(seen[0], [True, False, False, True, False, True])
    # three seen corners are too few for min_corners = 4: the whole image is dropped
    assert not visible_points(DEFAULT_CAMERA, eye, points, min_corners=4).any()
    # three seen corners on one line: dropped (PnP cannot use them)
    line = np.array([[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.2, 0.0, 1.0], [0.0, 0.0, -1.0]])
    assert not visible_points(DEFAULT_CAMERA, eye, line, min_corners=3).any()


@pytest.mark.parametrize(("tilt_deg", "kept"), [(0, True), (65, True), (75, False), (180, False)])
def test_an_image_of_a_board_seen_too_obliquely_or_from_behind_is_dropped(tilt_deg, kept):
    # a 10 cm board centred 1 m ahead, turned about its vertical axis: the line of sight
    # to its centre makes tilt_deg with its normal; every corner is in the image
    board = BOARD.points * 0.25
    centre = board.mean(axis=0)
    R = _rot_y(tilt_deg)
    c_T_b = transform_from_rotation_translation(R, np.array([0, 0, 1.0]) - R @ centre)
    c_p = board @ R.T + c_T_b[:3, 3]
    assert DEFAULT_CAMERA.in_view(c_p, margin_px=5).all()  # the angle alone decides
    seen = visible_points(DEFAULT_CAMERA, c_T_b[None], board)
    assert seen.all() == kept and seen.any() == kept


@pytest.mark.slow
def test_kinfw_simulate_pixels_writes_only_seen_whole_boards(tmp_path, capsys):
    cam = tmp_path / "left.json"
    small = CameraIntrinsics(320, 240, 300.0, 300.0, 159.5, 119.5, k1=-0.05, name="small")
    cam.write_text(json.dumps(small.to_dict()))
    out, truth = tmp_path / "px.json", tmp_path / "truth.urdf"
    args = ["simulate", "--pixels", "--stage", "2", "--stage2-samples", "12"]
    args += ["--out", str(out), "--truth-out", str(truth), "--camera", f"left_camera={cam}"]
    assert main([*args, "--pixel-sigma", "0", "--seed", "3"]) == 0
    text = capsys.readouterr().out
    assert "right_camera" in text and "default intrinsics" in text
    data = read_measurements(out)
    assert data.n_samples == 12 and data.cameras["left_camera"] == small
    for g in data.groups("pixels"):
        intr = g.intrinsics
        assert (intr == small) == (g.camera == "left_camera")
        _, rows = g.images()
        # a chessboard is found whole or not at all: 54 corners per image, ids 0..53
        for r in rows:
            np.testing.assert_array_equal(np.sort(g.point_id[r]), np.arange(BOARD.count))
        # noise-free: every pixel inside the image, 5 px from the border
        assert (g.uv >= 5 - 0.5).all()
        assert (g.uv[:, 0] <= intr.width - 0.5 - 5).all()
        assert (g.uv[:, 1] <= intr.height - 0.5 - 5).all()
    # --pixels without --stage: stage 1 poses and stage 2 images; --stage 1 is an error
    both = ["simulate", "--pixels", "--stage2-samples", "12", "--seed", "3"]
    both += ["--out", str(tmp_path / "both.json"), "--truth-out", str(truth)]
    assert main(both) == 0
    capsys.readouterr()
    both_data = read_measurements(tmp_path / "both.json")
    assert both_data.groups("pixels") and both_data.groups("pose")
    assert main(["-q", *both, "--stage", "1"]) == 2  # -q: the error alone on stderr
    err = capsys.readouterr().err
    assert err.startswith("kinfw simulate: error: --pixels --stage 1:"), err
    # a --camera for a frame that is not a stage 2 camera is a one-line error
    bad = [*args[:-2], "--camera", f"left_plate={cam}"]
    assert main(bad) == 2
    assert "'left_plate' is not a stage 2 camera" in capsys.readouterr().err


def test_simulated_pixels_are_behind_no_camera_against_the_true_robot():
    exp = arm_experiment(
        load_robot(ARM_6R), 5, camera="flange", intrinsics=CAMERA, q0=Q0, board=BOARD, sigma_px=0
    )
    (g,) = exp.data.groups("pixels")
    w_T_c = exp.truth.frame_poses(exp.data.qs[g.sample], "flange", exp.names)
    w_p = g.target_p @ exp.w_T_board[:3, :3].T + exp.w_T_board[:3, 3]
    c_p = np.einsum("nji,nj->ni", w_T_c[:, :3, :3], w_p - w_T_c[:, :3, 3])
    assert (c_p[:, 2] > 0).all()
    np.testing.assert_allclose(g.uv, CAMERA.project(c_p), atol=1e-9)


# -- demo, view ---------------------------------------------------------------------------


@pytest.mark.slow
def test_kinfw_demo_pixels_reports_reprojection_per_camera_and_image(tmp_path, capsys):
    assert main(["demo", "--pixels", "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "reprojection error on the calibration data" in text
    assert "held-out position RMS against the true robot" in text

    def refuse(token):
        raise ValueError(f"not strict JSON: {token}")

    report = json.loads((tmp_path / "report.json").read_text(), parse_constant=refuse)
    rep = report["reprojection_px"]
    # the images counted, not the configurations: per camera in the header, held out in
    # the report's reprojection_px_held_out
    held_px = report["reprojection_px_held_out"]
    n_held = sum(c["n_images"] for c in held_px["cameras"])
    assert len(held_px["images"]) == n_held > 0
    assert f"reprojection error on {n_held} held-out images (30 fresh configurations)" in text
    seen = ", ".join(f"{c['camera']} {c['n_images']}" for c in rep["cameras"])
    assert f"in 30 random configurations (images: {seen})" in text
    for c in held_px["cameras"]:
        assert 0.5 < c["rms_px"] < 0.9
    # px groups have their own stage table key
    assert "pixel_rms_px_by_stage" in report
    assert not any("pixels" in g for g in report["position_rms_mm_by_stage"]["refine"])
    assert {c["camera"] for c in rep["cameras"]} == {"left_camera", "right_camera"}
    assert sum(c["n_images"] for c in rep["cameras"]) == len(rep["images"]) > 20
    # the noise is 0.5 px per coordinate: a point's error norm has RMS ~ 0.5 sqrt(2)
    for c in rep["cameras"]:
        assert 0.5 < c["rms_px"] < 0.85
    assert rep["worst_images"][0]["rms_px"] == max(i["rms_px"] for i in rep["images"])
    held = {r["group"]: r for r in report["errors_vs_truth_held_out"]}
    assert held["left_camera (target)"]["after_position_rms_mm"] < 1.0


def test_the_view_draws_every_point_of_an_image_and_the_frustum():
    from kinfw.view import FRUSTUM_DEPTH, scene
    from tests.meshcat_scene import KINFW, RecordingWindow, scene_objects, scene_transforms

    exp = arm_experiment(
        load_robot(ARM_6R), 2, camera="flange", intrinsics=CAMERA, q0=Q0, board=BOARD, n_images=3
    )
    window = RecordingWindow()
    scene(exp.truth, data=exp.data, sample=1, window=window, targets=[("board", exp.w_T_board)])
    objects, transforms = scene_objects(window.commands), scene_transforms(window.commands)
    node = f"{KINFW}/measured/pixels/flange/board"
    balls = {p for p in objects if p.startswith(node + "/")}
    assert len(balls) == BOARD.count
    # at the truth the predicted points are the board's corners
    w_p = BOARD.points @ exp.w_T_board[:3, :3].T + exp.w_T_board[:3, 3]
    drawn = np.array(
        [
            transforms[f"{KINFW}/predicted/pixels/flange/board/{k}"][:3, 3]
            for k in range(BOARD.count)
        ]
    )
    np.testing.assert_allclose(drawn, w_p, atol=1e-6)
    # the frustum's rays end at the image's corners at 0.2 m (camera frame)
    cam = f"{KINFW}/cameras/flange/frustum"
    for k, uv in enumerate([[0, 0], [639, 0], [639, 479], [0, 479]]):
        T = transforms[f"{cam}/ray{k}"]
        length = objects[f"{cam}/ray{k}/stick"]["geometries"][0]["height"]
        tip = T[:3, 1] * length  # the stick runs along the node's y axis from its origin
        assert tip[2] == pytest.approx(FRUSTUM_DEPTH, abs=1e-9)
        np.testing.assert_allclose(CAMERA.project(tip), uv, atol=1e-6)


# -- pixels against poses, and the bound ------------------------------------------------------


@pytest.mark.slow
def test_the_pixel_path_beats_the_pose_path_on_the_same_images():
    exp = arm_experiment(
        load_robot(ARM_6R), 0, camera="flange", intrinsics=CAMERA, q0=Q0, board=BOARD
    )
    errors = {}
    for path, data in (("pixels", exp.data), ("pnp", pose_path_data(exp.data))):
        result = identify(exp.nominal, data, method="refine", loss="linear")
        robot = Robot(result.urdf_xml, path)
        errors[path] = camera_target_errors(exp, robot, target_pose(result.refined.unknowns))
    assert errors["pixels"][0] < 0.5 * errors["pnp"][0]  # position, m^2
    assert errors["pixels"][1] < errors["pnp"][1]  # rotation, rad^2


@pytest.mark.slow
def test_the_pixel_estimate_reaches_the_cramer_rao_bound():
    """Over 20 seeds the error of a held-out camera_T_target (6 numbers) whitened by its
    bound has sum of squares ~ chi2(6 * 20) if the estimate is efficient and unbiased:
    inside its 0.1 %-99.9 % quantiles [84, 168]; an estimate 1.5x worse than the
    bound in every direction would give ~270."""
    nees = []
    for seed in range(20):
        exp = arm_experiment(
            load_robot(ARM_6R), 100 + seed, camera="flange", intrinsics=CAMERA, q0=Q0,
            board=BOARD, n_test=3,
        )  # fmt: skip
        result = identify(exp.nominal, exp.data, method="refine", loss="linear", noise=exp.noise)
        robot = Robot(result.urdf_xml, "pixels")
        est = np.linalg.inv(robot.frame_poses(exp.q_test[:1], "flange", exp.names)) @ target_pose(
            result.refined.unknowns
        )
        _, _, cov, true = crlb_held_out(exp)
        e = pose_errors(est[0], true[0, 0])
        nees.append(float(e @ np.linalg.solve(cov[0, 0], e)))
    total = sum(nees)
    low, high = chi2.ppf([0.001, 0.999], 6 * len(nees))
    assert low < total < high, (total, nees)
