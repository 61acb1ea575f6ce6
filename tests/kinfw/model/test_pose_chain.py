"""The pose chain (``kinfw pose-chain``): a robot known by its hand poses alone.

Truths: Pinocchio's forward kinematics of the written URDF at the written joint values
gives back each logged pose; and through ``kinfw detect`` and ``kinfw calibrate
--params frames`` on rendered images, the camera's mount on the hand comes out as the
true robot's (Pinocchio FK of the simulation's true URDF).
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from kinfw.cli._main import main
from kinfw.geometry import matrix_from_rotation_vector, xyz_quat_xyzw_from_transform
from kinfw.measurements import read_hand_poses
from kinfw.model import POSE_CHAIN_JOINTS, load_robot, pose_chain_joint_values, pose_chain_urdf
from kinfw.observations import DatasetError
from tests.pin_se3 import angle, inverse, pin_fk
from tests.rendered_head import render_left_camera


def _poses(n: int, seed: int) -> np.ndarray:
    """Random hand poses, with a turn of 180 deg about y (a flange facing down) and
    pitches at +-90 deg (where yaw and roll are not unique)."""
    rng = np.random.default_rng(seed)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = [matrix_from_rotation_vector(v) for v in rng.normal(scale=1.5, size=(n, 3))]
    T[:, :3, 3] = rng.uniform(-1.5, 1.5, size=(n, 3))
    T[0, :3, :3] = matrix_from_rotation_vector([0.0, np.pi, 0.0])
    T[1, :3, :3] = matrix_from_rotation_vector([0.0, np.pi / 2, 0.0])
    T[2, :3, :3] = matrix_from_rotation_vector([0.3, -np.pi / 2, 0.0]) @ T[1, :3, :3]
    return T


@pytest.mark.parametrize("camera_on", ["hand", "base"])
def test_the_chain_puts_its_hand_at_every_logged_pose(camera_on):
    T = _poses(40, 1)
    urdf = pose_chain_urdf(camera="cam", hand="flange", camera_on=camera_on)
    q = pose_chain_joint_values(T)
    robot = load_robot(urdf)
    assert robot.exact_joints == POSE_CHAIN_JOINTS and robot.default_cameras == ("cam",)
    lower, upper = robot.joint_limits(POSE_CHAIN_JOINTS)
    assert np.all(q >= lower) and np.all(q <= upper)
    fk = pin_fk(urdf, POSE_CHAIN_JOINTS, q, "flange")
    np.testing.assert_allclose(fk, T, rtol=0, atol=1e-12)
    # the camera starts at its mount's identity, on the hand or on the base
    cam = pin_fk(urdf, POSE_CHAIN_JOINTS, q, "cam")
    expected = T if camera_on == "hand" else np.broadcast_to(np.eye(4), T.shape)
    np.testing.assert_allclose(cam, expected, rtol=0, atol=1e-12)


def test_colliding_names_and_an_unknown_mount_are_refused():
    with pytest.raises(ValueError, match="distinct names"):
        pose_chain_urdf(camera="hand")
    with pytest.raises(ValueError, match="camera_on"):
        pose_chain_urdf(camera="cam", camera_on="tool")


def _write_poses(path, names, T, extra=()):
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["image", *(f"hand_{k}" for k in ("x", "y", "z", "qx", "qy", "qz", "qw"))])
        for name, pose in zip(names, T, strict=True):
            xyz, q = xyz_quat_xyzw_from_transform(pose)
            w.writerow([name, *map(repr, map(float, [*xyz, *q]))])
        for row in extra:
            w.writerow(row)


def test_bad_pose_files_are_refused_naming_the_row(tmp_path, capsys):
    T = _poses(4, 2)
    path = tmp_path / "p.csv"
    _write_poses(path, ["a.png", "b.png", "c.png", "d.png"], T, [["e.png", 0, 0, 0, 0, 0, 0, 2]])
    argv = ["pose-chain", str(path), "--camera-frame", "cam"]
    argv += ["--urdf-out", str(tmp_path / "c.urdf"), "--joints-out", str(tmp_path / "j.csv")]
    assert main(argv) != 0
    err = capsys.readouterr().err
    assert "line 6 (image 'e.png'): quaternion (hand_qx, hand_qy, hand_qz, hand_qw)" in err
    assert not (tmp_path / "c.urdf").exists()
    (tmp_path / "q.csv").write_text("image,x,y,z,qx,qy,q_z,qw\na,0,0,0,0,0,0,1\n")
    with pytest.raises(DatasetError, match=r"header is \[image, x, y, z, qx, qy, q_z, qw\]"):
        read_hand_poses(tmp_path / "q.csv")


def test_the_columns_without_the_hand_prefix_are_read_alike(tmp_path):
    """``x, y, z, qx, qy, qz, qw`` (a flange-pose log as industrial_calibration's poses
    give it) read as the ``hand_*`` columns do."""
    T = _poses(5, 3)
    _write_poses(tmp_path / "a.csv", list("abcde"), T)
    text = (tmp_path / "a.csv").read_text().replace("hand_", "", 7)
    (tmp_path / "b.csv").write_text(text)
    a, b = read_hand_poses(tmp_path / "a.csv"), read_hand_poses(tmp_path / "b.csv")
    np.testing.assert_allclose(b.base_T_hands, T, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(a.base_T_hands, b.base_T_hands)
    assert b.images == tuple("abcde")


@pytest.mark.slow
def test_rendered_images_with_hand_poses_only_give_the_true_camera_mount(tmp_path, capsys):
    """The IIS head's left camera, 16 rendered chessboard images; the logged poses are
    those of its parent link ``vergence_left_link`` (the true robot's Pinocchio FK), no
    joint values. pose-chain -> detect -> calibrate (its default: frames, the chain's
    joints being exact): the exported mount
    ``vergence_left_link_T_left_camera`` is the truth's within 0.5 mm and 0.05 deg
    (measured: 0.05 mm, 0.002 deg; rendering and detection: ~0.05 px per corner); the
    identity start is centimetres off."""
    root = tmp_path
    cam = render_left_camera(root, 16, 6)
    with (cam / "joints.csv").open() as f:
        rows = list(csv.DictReader(f))
    names = [n for n in rows[0] if n != "image"]
    q = np.array([[float(r[n]) for n in names] for r in rows])
    truth = (root / "true.urdf").read_text()
    _write_poses(
        root / "poses.csv",
        [r["image"] for r in rows],
        pin_fk(truth, names, q, "vergence_left_link"),
    )
    argv = ["pose-chain", str(root / "poses.csv"), "--camera-frame", "left_camera"]
    argv += ["--hand", "vergence_left_link", "--urdf-out", str(root / "chain.urdf")]
    assert main([*argv, "--joints-out", str(cam / "chain_joints.csv")]) == 0
    argv = ["-q", "detect", *map(str, sorted(cam.glob("*.png"))), "--board", "chessboard:9x6:0.04"]
    argv += ["--joints", str(cam / "chain_joints.csv"), "--camera", str(cam / "camera.json")]
    assert main([*argv, "--frame", "left_camera", "--out", str(root / "det.json")]) == 0
    capsys.readouterr()
    argv = ["-q", "calibrate", str(root / "det.json"), "--urdf", str(root / "chain.urdf")]
    assert main([*argv, "--out", str(root / "cal.urdf")]) == 0  # the default: frames
    printed = capsys.readouterr().out
    true_mount = (
        inverse(pin_fk(truth, names, q[:1], "vergence_left_link")[0])
        @ pin_fk(truth, names, q[:1], "left_camera")[0]
    )
    found = load_robot(root / "cal.urdf").joint("left_camera_joint").parent_T_child
    mm = 1e3 * np.linalg.norm(found[:3, 3] - true_mount[:3, 3])
    deg = np.degrees(angle(found[:3, :3].T @ true_mount[:3, :3]))
    assert mm < 0.5 and deg < 0.05, (mm, deg)
    assert 1e3 * np.linalg.norm(true_mount[:3, 3]) > 10 or np.degrees(angle(true_mount[:3, :3])) > 5
    sidecar = json.loads((root / "cal.kinfw.json").read_text())
    assert sidecar["model"]["parameters"] == ["frames"]
    assert "exact" in sidecar["model"]["reason"]
    # the printed table of changed origins gives the mount (mm, as written in the URDF)
    row = next(line.split() for line in printed.splitlines() if "left_camera_joint" in line)
    np.testing.assert_allclose([float(v) for v in row[4:7]], 1e3 * found[:3, 3], atol=0.01)
