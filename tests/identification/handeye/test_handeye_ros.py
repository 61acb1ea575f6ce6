"""ROS 2 outputs of a hand-eye calibration, each read back into a 4x4 transform by an
independent parser and compared with the calibration to 1e-9: the
static_transform_publisher arguments (argparse), the launch file (Python's ``ast``), the
easy_handeye2 YAML (PyYAML + Pinocchio's quaternion) and the URDF snippet (yourdfpy)."""

import argparse
import ast
import io

import numpy as np
import pinocchio as pin
import pytest
import yaml
import yourdfpy

from kinfw.identification.handeye import (
    ROS_FILES,
    HandEyeCalibration,
    static_transform_args,
    write_ros_outputs,
)


def _calibration(setup, rotvec):
    T = pin.SE3(pin.exp3(np.array(rotvec)), np.array([0.031, -0.12, 0.087])).homogeneous
    return HandEyeCalibration(
        setup=setup,
        mount_T_camera=T,
        holder_T_target=np.eye(4),
        covariance=np.eye(6) * 1e-6,
        verdict="determined",
        verdict_message="determined",
        n_samples=10,
        rejected=(),
        mount_frame="tool0" if setup == "eye-in-hand" else "base_link",
        camera_frame="camera_link",
    )


ROTATIONS = [
    [0.3, -1.2, 2.0],
    [0.0, np.pi / 2, 0.0],
    [np.pi, 0.0, 0.0],
]  # generic, gimbal, half turn


def _from_xyz_quat(xyz, q_xyzw):
    x, y, z, w = q_xyzw
    return pin.SE3(pin.Quaternion(w, x, y, z).normalized().matrix(), np.array(xyz)).homogeneous


def _parse_args(args):
    p = argparse.ArgumentParser()
    for name in ("x", "y", "z", "qx", "qy", "qz", "qw"):
        p.add_argument(f"--{name}", type=float)
    p.add_argument("--frame-id")
    p.add_argument("--child-frame-id")
    ns = p.parse_args(args)
    return (
        ns.frame_id,
        ns.child_frame_id,
        _from_xyz_quat([ns.x, ns.y, ns.z], [ns.qx, ns.qy, ns.qz, ns.qw]),
    )


@pytest.mark.parametrize("rotvec", ROTATIONS)
@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
def test_each_ros_output_reads_back_to_the_calibration(tmp_path, setup, rotvec):
    cal = _calibration(setup, rotvec)
    paths = write_ros_outputs(tmp_path, cal, base_frame="base_link", hand_frame="tool0")
    assert sorted(p.name for p in paths) == sorted(ROS_FILES.values())

    # the shell command: ros2 run tf2_ros static_transform_publisher ARGS
    words = (tmp_path / ROS_FILES["static_transform_publisher"]).read_text().split("\n")[1].split()
    assert words[:4] == ["ros2", "run", "tf2_ros", "static_transform_publisher"]
    parent, child, T = _parse_args(words[4:])
    assert (parent, child) == (cal.mount_frame, "camera_link")
    np.testing.assert_allclose(T, cal.mount_T_camera, atol=1e-9)

    # the launch file: a tf2_ros static_transform_publisher Node with those arguments
    tree = ast.parse((tmp_path / ROS_FILES["launch"]).read_text())
    node = next(
        n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "Node"
    )
    kw = {k.arg: ast.literal_eval(k.value) for k in node.keywords}
    assert (kw["package"], kw["executable"]) == ("tf2_ros", "static_transform_publisher")
    np.testing.assert_allclose(_parse_args(kw["arguments"])[2], cal.mount_T_camera, atol=1e-9)

    # easy_handeye2's calibration YAML
    data = yaml.safe_load((tmp_path / ROS_FILES["easy_handeye2"]).read_text())
    t, r = data["transform"]["translation"], data["transform"]["rotation"]
    T = _from_xyz_quat([t["x"], t["y"], t["z"]], [r["x"], r["y"], r["z"], r["w"]])
    np.testing.assert_allclose(T, cal.mount_T_camera, atol=1e-9)
    expected = {"eye-in-hand": "eye_in_hand", "eye-to-hand": "eye_on_base"}[setup]
    assert data["parameters"]["calibration_type"] == expected
    assert data["parameters"]["tracking_base_frame"] == "camera_link"

    # the URDF snippet, pasted into a robot with the mount link, loaded by yourdfpy
    snippet = (tmp_path / ROS_FILES["urdf"]).read_text()
    urdf = f'<robot name="r"><link name="{cal.mount_frame}"/>{snippet}</robot>'
    robot = yourdfpy.URDF.load(io.StringIO(urdf))
    T = robot.get_transform("camera_link", cal.mount_frame)
    np.testing.assert_allclose(T, cal.mount_T_camera, atol=1e-9)


def test_static_transform_args_are_ros2_named_flags():
    args = static_transform_args(_calibration("eye-in-hand", ROTATIONS[0]))
    assert args[0::2][:7] == ["--x", "--y", "--z", "--qx", "--qy", "--qz", "--qw"]
    assert args[-4:] == ["--frame-id", "tool0", "--child-frame-id", "camera_link"]
