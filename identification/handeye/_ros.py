"""ROS 2 outputs of a hand-eye calibration (``kinfw handeye --ros-out DIR``): the camera's
mount ``mount_T_camera`` as a static transform, in the forms ROS users load.

- :func:`static_transform_args`: the arguments of ROS 2's
  ``ros2 run tf2_ros static_transform_publisher`` (named-flag syntax, Humble and later:
  ``--x --y --z --qx --qy --qz --qw --frame-id --child-frame-id``);
- :func:`ros_launch_text`: a ROS 2 Python launch file publishing it (``launch_ros``'s
  ``Node``);
- :func:`easy_handeye_text`: easy_handeye2's calibration YAML (``parameters`` and
  ``transform: {translation, rotation}``), which its ``publish.launch.py`` loads;
- :func:`urdf_mount_text`: a URDF snippet, a fixed joint from the mount link to the
  camera link with the transform as its ``<origin xyz rpy>``.

Numbers are written by ``repr`` (exact round trip). The parent frame is the calibration's
``mount_frame`` (the hand eye-in-hand, the base eye-to-hand), the child its
``camera_frame``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kinfw.files import write_text_atomic
from kinfw.geometry import xyz_quat_xyzw_from_transform
from kinfw.identification.handeye._calibration import HandEyeCalibration

#: The files :func:`write_ros_outputs` writes, by what they hold.
ROS_FILES = {
    "static_transform_publisher": "static_transform_publisher.sh",
    "launch": "handeye.launch.py",
    "easy_handeye2": "handeye_calibration.yaml",
    "urdf": "handeye_mount.urdf",
}
#: Largest deviation accepted between the rotation and its roll-pitch-yaw angles.
RPY_TOL = 1e-12
_EASY_HANDEYE_TYPE = {"eye-in-hand": "eye_in_hand", "eye-to-hand": "eye_on_base"}


def _num(v: float) -> str:
    return repr(float(v))


def static_transform_args(calibration: HandEyeCalibration) -> list[str]:
    """Arguments of ``ros2 run tf2_ros static_transform_publisher`` publishing
    ``mount_T_camera`` (metres, quaternion scalar last) from ``mount_frame`` to
    ``camera_frame``."""
    xyz, q = xyz_quat_xyzw_from_transform(calibration.mount_T_camera)
    args: list[str] = []
    for name, v in zip(("x", "y", "z", "qx", "qy", "qz", "qw"), [*xyz, *q], strict=True):
        args += [f"--{name}", _num(v)]
    frames = ["--frame-id", calibration.mount_frame, "--child-frame-id", calibration.camera_frame]
    return [*args, *frames]


def ros_launch_text(calibration: HandEyeCalibration) -> str:
    """A ROS 2 Python launch file: one ``tf2_ros`` ``static_transform_publisher`` node
    with :func:`static_transform_args`."""
    args = ",\n                ".join(repr(a) for a in static_transform_args(calibration))
    return f'''"""Publish the hand-eye calibration ({calibration.setup}, written by kinfw handeye):
the pose of {calibration.camera_frame!r} in {calibration.mount_frame!r}."""

from launch import LaunchDescription
from launch_ros.actions import Node


def generate_launch_description():
    return LaunchDescription([
        Node(
            package="tf2_ros",
            executable="static_transform_publisher",
            name="handeye_publisher",
            arguments=[
                {args},
            ],
        ),
    ])
'''


def easy_handeye_text(calibration: HandEyeCalibration, base_frame: str, hand_frame: str) -> str:
    """easy_handeye2's calibration YAML of the mount: ``transform`` is the camera's pose
    in the effector (eye-in-hand) or in the robot base (eye-on-base)."""
    import yaml

    xyz, q = xyz_quat_xyzw_from_transform(calibration.mount_T_camera)
    data = {
        "parameters": {
            "name": "kinfw_handeye",
            "calibration_type": _EASY_HANDEYE_TYPE[calibration.setup],
            "robot_base_frame": base_frame,
            "robot_effector_frame": hand_frame,
            "tracking_base_frame": calibration.camera_frame,
            "tracking_marker_frame": "target",
        },
        "transform": {
            "translation": dict(zip("xyz", map(float, xyz), strict=True)),
            "rotation": dict(zip("xyzw", map(float, q), strict=True)),
        },
    }
    return yaml.safe_dump(data, sort_keys=False)


def urdf_mount_text(calibration: HandEyeCalibration) -> str:
    """A URDF snippet: the camera link and a fixed joint from the mount link to it whose
    ``<origin>`` is ``mount_T_camera`` (xyz metres, rpy radians: URDF's fixed-axis
    roll, pitch, yaw, ``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
    import pinocchio as pin

    T = np.asarray(calibration.mount_T_camera)
    rpy = pin.rpy.matrixToRpy(T[:3, :3])
    error = np.abs(pin.rpy.rpyToMatrix(rpy) - T[:3, :3]).max()
    if not error <= RPY_TOL:
        raise ValueError(f"mount_T_camera: rpy reproduce its rotation only to {error:.3g}")
    xyz = " ".join(map(_num, T[:3, 3]))
    rpy_text = " ".join(map(_num, rpy))
    camera = calibration.camera_frame
    return (
        f"<!-- hand-eye calibration ({calibration.setup}) by kinfw handeye: "
        f"paste into the robot's URDF -->\n"
        f'<link name="{camera}"/>\n'
        f'<joint name="{camera}_joint" type="fixed">\n'
        f'  <parent link="{calibration.mount_frame}"/>\n'
        f'  <child link="{camera}"/>\n'
        f'  <origin xyz="{xyz}" rpy="{rpy_text}"/>\n'
        "</joint>\n"
    )


def write_ros_outputs(
    directory: str | Path, calibration: HandEyeCalibration, *, base_frame: str, hand_frame: str
) -> list[Path]:
    """Write the four ROS 2 outputs (:data:`ROS_FILES`) into ``directory`` (created if
    missing); returns their paths. ``base_frame`` and ``hand_frame`` name the robot's
    frames in easy_handeye2's YAML."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    command = "ros2 run tf2_ros static_transform_publisher " + " ".join(
        static_transform_args(calibration)
    )
    texts = {
        "static_transform_publisher": f"#!/bin/sh\n{command}\n",
        "launch": ros_launch_text(calibration),
        "easy_handeye2": easy_handeye_text(calibration, base_frame, hand_frame),
        "urdf": urdf_mount_text(calibration),
    }
    return [write_text_atomic(directory / ROS_FILES[k], t) for k, t in texts.items()]
