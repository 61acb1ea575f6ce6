"""Bags written in the tests with rosbags' writers, from a simulated robot (plain helpers).

:func:`simulated_recording` moves a perturbed ``ARM_6R`` (the truth) continuously and
samples it twice: joint states at 100 Hz, and a motion-capture pose of a marker on the
flange at 30 Hz whose stamps lag the true instants by ``DELAY_S`` (an arrival stamp),
with noise.
:func:`write_bag` writes that as a ROS 1 ``.bag`` or a ROS 2 folder: ``/joint_states``
(joints shuffled, plus a gripper joint the URDF lacks), ``/mocap/pose``
(``PoseStamped`` in ``mocap``), ``/mocap/point`` (``PointStamped``) and, on ROS 2,
``/tf`` (``mocap -> rigid_body``) with ``/tf_static`` (``room -> mocap``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import matrix_from_rotation_vector, quat_xyzw_from_matrix
from kinfw.model import Robot, load_robot
from kinfw.simulation import perturb_poses, perturb_robot
from tests.robots import ARM_6R

#: The mocap stamps lag the true instants by this, seconds: the offset to recover.
DELAY_S = 0.023
#: Epoch of the recording's first stamp, seconds (a real clock: 2023-11-14).
EPOCH_S = 1_700_000_000
JOINT_RATE_HZ = 100.0
MOCAP_RATE_HZ = 30.0
#: The mocap's noise: per translation component (m) and rotation angle (rad), 1 sigma.
SIGMA_M, SIGMA_RAD = 1e-4, 2e-4


def _pose(rotvec, xyz) -> NDArray[np.float64]:
    T = np.eye(4)
    T[:3, :3] = matrix_from_rotation_vector(rotvec)
    T[:3, 3] = xyz
    return T


#: The marker's pose on the flange and the mocap frame's pose in the root (unknowns).
FLANGE_T_MARKER = _pose([0.2, -0.1, 0.3], [0.02, -0.03, 0.05])
ROOT_T_MOCAP = _pose([0.1, 0.05, 1.2], [1.5, -0.4, 0.2])
#: The static TF ``room -> mocap``.
ROOM_T_MOCAP = _pose([0.0, 0.0, 0.3], [0.5, 0.5, 0.0])


@dataclass(frozen=True)
class Recording:
    """A simulated recording: the nominal and true robots and both streams (seconds
    from :data:`EPOCH_S`)."""

    nominal: Robot
    truth: Robot
    joint_names: tuple[str, ...]
    t_joints: NDArray[np.float64]
    q_joints: NDArray[np.float64]
    t_mocap: NDArray[np.float64]
    mocap_T_markers: NDArray[np.float64]


def trajectory(t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Joint values of ``ARM_6R`` at instants ``t`` (s): six sines of distinct
    frequencies (0.2 to 0.7 Hz), amplitudes 0.5 to 1 rad; shape (len(t), 6)."""
    freq = np.array([0.21, 0.33, 0.27, 0.45, 0.38, 0.7])
    amp = np.array([0.9, 0.6, 0.7, 1.0, 0.8, 0.5])
    phase = np.array([0.0, 1.0, 2.0, 0.5, 1.5, 2.5])
    mid = np.array([0.2, -0.3, 0.4, 0.0, 0.3, -0.2])
    return mid + amp * np.sin(2 * np.pi * freq * np.asarray(t)[:, None] + phase)


def simulated_recording(duration_s: float = 12.0, seed: int = 4) -> Recording:
    """Joint states at 100 Hz over ``duration_s`` (exact); mocap at 30 Hz from 0.2 s to
    the end minus 0.2 s, stamped ``DELAY_S`` late, with noise ``SIGMA_M``, ``SIGMA_RAD``."""
    rng = np.random.default_rng(seed)
    nominal = load_robot(ARM_6R)
    truth = load_robot(perturb_robot(nominal, rng))
    names = nominal.joint_names
    t_joints = np.arange(0.0, duration_s, 1.0 / JOINT_RATE_HZ)
    t_true = np.arange(0.2, duration_s - 0.2, 1.0 / MOCAP_RATE_HZ)
    root_T_flanges = truth.frame_poses(trajectory(t_true), "flange", names)
    mocap_T_markers = np.linalg.inv(ROOT_T_MOCAP) @ root_T_flanges @ FLANGE_T_MARKER
    mocap_T_markers = perturb_poses(mocap_T_markers, rng, SIGMA_M, SIGMA_RAD)
    return Recording(
        nominal,
        truth,
        names,
        t_joints,
        trajectory(t_joints),
        t_true + DELAY_S,
        mocap_T_markers,
    )


def image_pixels(k: int) -> tuple[NDArray[np.uint8], NDArray[np.uint16]]:
    """Image ``k`` of :func:`write_bag`'s cameras: 4 x 6 RGB (``rgb8``) and 16-bit grey
    (``mono16``) whose values encode ``k`` and the pixel."""
    rgb = (np.arange(4 * 6 * 3).reshape(4, 6, 3) + 7 * k) % 256
    return rgb.astype(np.uint8), (np.arange(24).reshape(4, 6) * 1000 + k).astype(np.uint16)


def write_bag(
    path: Path, recording: Recording, *, ros: int = 2, images: bool = False, mcap: bool = False
) -> Path:
    """Write ``recording`` as a ROS ``ros`` bag at ``path`` (module docstring; ROS 2 in
    SQLite, or with ``mcap`` in MCAP storage); with
    ``images``, also ``/camera/rgb`` (``rgb8``) and ``/camera/depth`` (``mono16``,
    big-endian) at 10 Hz, stamped on the joints' clock, image ``k`` at ``0.1 k + 0.05`` s
    (:func:`image_pixels`)."""
    from rosbags.typesys import Stores, get_typestore

    if ros == 1:
        from rosbags.rosbag1 import Writer

        typestore = get_typestore(Stores.ROS1_NOETIC)
        writer = Writer(path)
        serialize = typestore.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        typestore = get_typestore(Stores.ROS2_HUMBLE)
        storage = StoragePlugin.MCAP if mcap else StoragePlugin.SQLITE3
        writer = Writer(path, version=9, storage_plugin=storage)
        serialize = typestore.serialize_cdr
    types = typestore.types
    Time, Header = types["builtin_interfaces/msg/Time"], types["std_msgs/msg/Header"]
    Point, Quaternion = types["geometry_msgs/msg/Point"], types["geometry_msgs/msg/Quaternion"]
    Vector3 = types["geometry_msgs/msg/Vector3"]
    JointState = types["sensor_msgs/msg/JointState"]
    PoseStamped, Pose = types["geometry_msgs/msg/PoseStamped"], types["geometry_msgs/msg/Pose"]
    PointStamped = types["geometry_msgs/msg/PointStamped"]

    def header(t: float, frame_id: str):
        ns = EPOCH_S * 1_000_000_000 + round(t * 1e9)  # exact: no float near 1.7e18
        stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        extra = {"seq": 0} if ros == 1 else {}
        return Header(stamp=stamp, frame_id=frame_id, **extra), ns

    names = [*recording.joint_names[::-1], "gripper_finger_joint"]
    with writer:
        topics = {
            "/joint_states": JointState,
            "/mocap/pose": PoseStamped,
            "/mocap/point": PointStamped,
        }
        if ros == 2:
            TFMessage = types["tf2_msgs/msg/TFMessage"]
            topics |= {"/tf": TFMessage, "/tf_static": TFMessage}
        if images:
            Image = types["sensor_msgs/msg/Image"]
            topics |= {"/camera/rgb": Image, "/camera/depth": Image}
        conn = {
            name: writer.add_connection(name, cls.__msgtype__, typestore=typestore)
            for name, cls in topics.items()
        }
        messages = []
        for t, q in zip(recording.t_joints, recording.q_joints, strict=True):
            h, ns = header(t, "")
            position = np.array([*q[::-1], 0.01])
            empty = np.zeros(0)
            msg = JointState(header=h, name=names, position=position, velocity=empty, effort=empty)
            messages.append((ns, "/joint_states", msg))
        xyzs = recording.mocap_T_markers[:, :3, 3]
        quats = quat_xyzw_from_matrix(recording.mocap_T_markers[:, :3, :3])
        for t, p, o in zip(recording.t_mocap, xyzs, quats, strict=True):
            h, ns = header(t, "mocap")
            position = Point(x=p[0], y=p[1], z=p[2])
            orientation = Quaternion(x=o[0], y=o[1], z=o[2], w=o[3])
            messages.append((ns, "/mocap/pose", PoseStamped(h, Pose(position, orientation))))
            messages.append((ns, "/mocap/point", PointStamped(h, position)))
            if ros == 2:
                TransformStamped = types["geometry_msgs/msg/TransformStamped"]
                Transform = types["geometry_msgs/msg/Transform"]
                moving = TransformStamped(
                    h, "rigid_body", Transform(Vector3(x=p[0], y=p[1], z=p[2]), orientation)
                )
                messages.append((ns, "/tf", TFMessage([moving])))
        if ros == 2:
            h, ns = header(0.0, "room")
            p = ROOM_T_MOCAP[:3, 3]
            o = quat_xyzw_from_matrix(ROOM_T_MOCAP[:3, :3])
            transform = Transform(
                Vector3(x=p[0], y=p[1], z=p[2]), Quaternion(x=o[0], y=o[1], z=o[2], w=o[3])
            )
            static = TFMessage([TransformStamped(h, "mocap", transform)])
            messages.append((ns, "/tf_static", static))
        for k, t in enumerate(np.arange(0.05, recording.t_joints[-1], 0.1) if images else ()):
            h, ns = header(t, "camera")
            rgb, depth = image_pixels(k)
            color = Image(h, 4, 6, "rgb8", 0, 18, rgb.reshape(-1))
            grey = Image(h, 4, 6, "mono16", 1, 12, depth.astype(">u2").view(np.uint8).reshape(-1))
            messages += [(ns, "/camera/rgb", color), (ns, "/camera/depth", grey)]
        for ns, topic, msg in sorted(messages, key=lambda m: m[0]):
            writer.write(conn[topic], ns, serialize(msg, type(msg).__msgtype__))
    return path
