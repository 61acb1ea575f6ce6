"""The plausibility guard on the mount ``kinfw handeye --urdf`` writes (issue 35): board
images rendered from a camera on the flange where the URDF puts it, detected with the
board's true square size, give that mount; detected with a wrong square size (32 mm for
25 mm), the camera moves along its optical axis by centimetres and the mount is refused
before anything is written, unless ``--allow-large-changes``."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pinocchio as pin
import pytest

from kinfw.camera import Chessboard
from kinfw.cli._main import main
from kinfw.geometry import inverse_transform
from kinfw.model import load_robot
from kinfw.simulation import render_board
from tests.cli_run import without_dirs
from tests.kinfw.cli.test_handeye_images import BOARD, CAMERA, HAND_T_CAMERA, NAMES, Q0, _in_view
from tests.robots import ARM_6R

WRONG = Chessboard(BOARD.cols, BOARD.rows, 0.032)


def _with_camera(urdf: str) -> str:
    """ARM_6R with ``camera_link`` on the flange at the true ``HAND_T_CAMERA``."""
    xyz = " ".join(map(repr, HAND_T_CAMERA[:3, 3].tolist()))
    rpy = " ".join(map(repr, pin.rpy.matrixToRpy(HAND_T_CAMERA[:3, :3]).tolist()))
    joint = (
        f'<joint name="camera_joint" type="fixed"><parent link="flange"/>'
        f'<child link="camera_link"/><origin xyz="{xyz}" rpy="{rpy}"/></joint>'
        '<link name="camera_link"/></robot>'
    )
    return urdf.replace("</robot>", joint)


@pytest.fixture(scope="module")
def images(tmp_path_factory):
    """The rendered images and their joints CSV, and the URDF with the camera."""
    tmp = tmp_path_factory.mktemp("guard_handeye")
    robot = load_robot(ARM_6R)
    rng = np.random.default_rng(5)
    (tmp / "cam.json").write_text(json.dumps(CAMERA.to_dict()))
    (tmp / "arm.urdf").write_text(_with_camera(ARM_6R))
    w_T_c0 = robot.frame_poses(Q0, "flange", NAMES) @ HAND_T_CAMERA
    centre = np.array([4.0, 2.5, 0.0]) * BOARD.square_m
    w_T_board = w_T_c0 @ pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.45]) - centre).homogeneous
    qs = _in_view(robot, w_T_board, Q0 + rng.uniform(-0.35, 0.35, size=(400, 6)))[:12]
    c_T_bs = inverse_transform(robot.frame_poses(qs, "flange", NAMES) @ HAND_T_CAMERA) @ w_T_board
    paths = []
    for k, c_T_b in enumerate(c_T_bs):
        paths.append(tmp / f"{k:02d}.png")
        cv2.imwrite(str(paths[-1]), render_board(BOARD, CAMERA, c_T_b, noise_sigma=2.0, rng=rng))
    joints = tmp / "q.csv"
    joints.write_text(
        ",".join(NAMES) + "\n" + "".join(",".join(map(repr, q.tolist())) + "\n" for q in qs)
    )
    return tmp, paths, joints


def _detected(images, board: Chessboard):
    tmp, paths, joints = images
    out = tmp / f"px_{board.square_m}.json"
    detect = ["-q", "detect", *map(str, paths), "--board", board.spec(), "--joints", str(joints)]
    detect += ["--camera", str(tmp / "cam.json"), "--frame", "camera_link", "--out", str(out)]
    assert main(detect) == 0
    return out


def _handeye(images, pixels, out, *more):
    tmp = images[0]
    argv = ["-q", "handeye", str(pixels), "--urdf", str(tmp / "arm.urdf")]
    return main(
        [*argv, "--hand-frame", "flange", "--camera-frame", "camera_link", *more, "--out", str(out)]
    )


@pytest.mark.slow
def test_a_wrong_board_size_moves_the_mount_beyond_the_bound_and_is_refused(
    images, tmp_path, capsys
):
    right = _detected(images, BOARD)
    assert _handeye(images, right, tmp_path / "right.yaml") == 0  # the URDF's mount
    assert (tmp_path / "right.yaml").exists()
    wrong = _detected(images, WRONG)
    capsys.readouterr()
    assert _handeye(images, wrong, tmp_path / "wrong.yaml") == 2
    warning, *err = capsys.readouterr().err.strip().splitlines()
    # first the cause: the target translations follow the hand's motion at 25/32 = 0.78
    assert "seen by 'camera_link' looks " in warning
    assert float(warning.split(" looks ")[1].split()[0]) == pytest.approx(25 / 32, abs=0.01)
    assert err[0].startswith("kinfw handeye: error: ") and len(without_dirs(err[0])) < 200
    # the board 0.45 m away read 32/25 times its size: the camera 143 mm off (measured),
    # turned by less than 0.1 deg, against 20 mm / 2 deg
    moved = err[0].split("mount flange_T_camera_link ")[1].split()
    assert float(moved[0]) > 100.0 and moved[1] == "mm" and float(moved[3]) < 0.1
    assert any("the board's size" in line for line in err[1:])
    assert not (tmp_path / "wrong.yaml").exists()
    assert _handeye(images, wrong, tmp_path / "wrong.yaml", "--allow-large-changes") == 0
    assert "written (--allow-large-changes)" in capsys.readouterr().err
    assert (tmp_path / "wrong.yaml").exists()
