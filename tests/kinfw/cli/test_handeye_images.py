"""``kinfw handeye`` from images: board images rendered from a camera at a known pose on
the hand are detected (``kinfw detect``: pixels and the robot's joint values), then
``kinfw handeye PIXELS.json --urdf`` poses each image by PnP and calibrates; the result is
the known ``hand_T_camera``, and ``--holdout`` reads held-out images the same way."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pinocchio as pin
import pytest

from kinfw.camera import CameraIntrinsics, Chessboard
from kinfw.cli._main import main
from kinfw.geometry import inverse_transform, rotation_angle
from kinfw.identification.handeye import read_handeye_calibration
from kinfw.model import load_robot
from kinfw.simulation import render_board
from tests.board_views import board_in_view
from tests.robots import ARM_6R

NAMES = ("j1", "j2", "j3", "j4", "j5", "j6")
Q0 = np.array([0.3, -0.4, 0.9, 0.2, 0.7, -0.3])
CAMERA = CameraIntrinsics(640, 480, 520.0, 520.0, 319.5, 239.5, k1=-0.1, k2=0.03, name="cam")
BOARD = Chessboard(9, 6, 0.025)
#: The camera on the flange: 40 mm aside, 60 mm ahead, turned by 0.2 rad (the truth).
HAND_T_CAMERA = pin.SE3(pin.exp3(np.array([0.1, -0.15, 0.1])), np.array([0.04, -0.02, 0.06]))
HAND_T_CAMERA = HAND_T_CAMERA.homogeneous


def _images(tmp_path, name, robot, w_T_board, qs, rng):
    """Render, write the images and joint values, detect: the pixels file."""
    c_T_bs = inverse_transform(robot.frame_poses(qs, "flange", NAMES) @ HAND_T_CAMERA) @ w_T_board
    images = []
    for k, c_T_b in enumerate(c_T_bs):
        images.append(tmp_path / f"{name}_{k:02d}.png")
        cv2.imwrite(str(images[-1]), render_board(BOARD, CAMERA, c_T_b, noise_sigma=2.0, rng=rng))
    joints = tmp_path / f"{name}_q.csv"
    joints.write_text(
        ",".join(NAMES) + "\n" + "".join(",".join(map(repr, q.tolist())) + "\n" for q in qs)
    )
    out = tmp_path / f"{name}_px.json"
    detect = ["detect", *map(str, images), "--board", BOARD.spec(), "--joints", str(joints)]
    detect += ["--camera", str(tmp_path / "cam.json"), "--frame", "camera_link"]
    assert main([*detect, "--out", str(out)]) == 0
    return out


def _in_view(robot, w_T_board, qs):
    w_T_cameras = robot.frame_poses(qs, "flange", NAMES) @ HAND_T_CAMERA
    return qs[board_in_view(w_T_cameras, w_T_board, BOARD, CAMERA)]


@pytest.mark.slow
def test_handeye_from_detected_images_recovers_the_camera(tmp_path, capsys):
    robot = load_robot(ARM_6R)
    rng = np.random.default_rng(5)
    (tmp_path / "cam.json").write_text(json.dumps(CAMERA.to_dict()))
    (tmp_path / "arm.urdf").write_text(ARM_6R)
    w_T_c0 = robot.frame_poses(Q0, "flange", NAMES) @ HAND_T_CAMERA
    centre = np.array([4.0, 2.5, 0.0]) * BOARD.square_m
    w_T_board = w_T_c0 @ pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.45]) - centre).homogeneous
    qs = _in_view(robot, w_T_board, Q0 + rng.uniform(-0.35, 0.35, size=(400, 6)))[:20]
    assert len(qs) == 20
    fit = _images(tmp_path, "fit", robot, w_T_board, qs[:14], rng)
    held = _images(tmp_path, "held", robot, w_T_board, qs[14:], rng)
    capsys.readouterr()

    result = tmp_path / "handeye.yaml"
    argv = ["handeye", str(fit), "--urdf", str(tmp_path / "arm.urdf"), "--hand-frame", "flange"]
    argv += ["--holdout", str(held), "--out", str(result)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert f"14 pose pairs from {fit}" in out
    assert "holdout deg" in out

    calibration = read_handeye_calibration(result)
    X = calibration.mount_T_camera
    # 14 images of 54 corners at 0.45 m, each posed by PnP: 0.95 mm / 0.040 deg off
    # (measured; 1-sigma reported 0.19-0.24 mm, 0.016-0.022 deg); bounds 2x that, far
    # below the 72 mm / 11 deg the camera sits off the flange
    assert np.linalg.norm(X[:3, 3] - HAND_T_CAMERA[:3, 3]) < 2e-3
    assert np.degrees(rotation_angle(X[:3, :3].T @ HAND_T_CAMERA[:3, :3])) < 0.08
    # the 6 held-out images: 0.14 deg / 0.51 mm RMS loop closure (measured)
    lines = out.splitlines()
    row = lines[[line.split()[:1] for line in lines].index(["method"]) + 1]
    held_deg, held_mm = (float(v) for v in row.split()[-2:])
    assert held_deg < 0.3 and held_mm < 1.0, row


def test_handeye_with_urdf_refuses_a_file_without_target_or_pixels(tmp_path, capsys):
    (tmp_path / "arm.urdf").write_text(ARM_6R)
    data = {"format": "kinfw-measurements", "version": 1, "joint_names": list(NAMES)}
    data["units"] = {"length": "m", "angle": "rad"}
    point = {"kind": "point", "frame": "flange", "xyz": [0.0, 0.0, 0.0]}
    data["samples"] = [{"q": [0.0] * 6, "observations": [point]}] * 3
    (tmp_path / "poses.json").write_text(json.dumps(data))
    argv = ["handeye", str(tmp_path / "poses.json"), "--urdf", str(tmp_path / "arm.urdf")]
    assert main(argv) == 2
    assert "no target or pixels observations" in capsys.readouterr().err
