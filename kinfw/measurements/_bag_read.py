"""ROS 1 and ROS 2 bags into :class:`kinfw.measurements.Measurements`, with time alignment.

A calibration recording in ROS is a bag: the robot's ``sensor_msgs/JointState`` on a
joint-state topic (``/joint_states``, ~100-500 Hz) and a measurement stream at its own
rate -- a motion-capture ``geometry_msgs/PoseStamped`` or ``PointStamped`` topic, or a
chain of ``/tf`` transforms (a tracker, a camera seeing a board). :func:`read_bag` reads
both with the ``rosbags`` package (pure Python, the ``ros`` extra: ROS 1 ``.bag`` files
and ROS 2 folders with ``metadata.yaml`` and ``.db3`` or ``.mcap`` storage, through
``rosbags.highlevel.AnyReader``); :func:`measurements_from_bag` pairs each measurement
with the joint values interpolated at its stamp and writes the samples.

Stamps
------
Every message is placed at its ``header.stamp`` (a zero stamp, as some drivers leave it,
falls back to the bag's record time), in seconds from the first message of the bag.

Time alignment
--------------
Joint values are interpolated linearly, per joint (each joint on its own stamps, so
joints published in separate messages are read too), at ``t_meas - offset_s``: the
convention of :mod:`kinfw.measurements` streams, ``offset_s`` added to the robot's stamps
(a robot sample stamped ``t`` happened at ``t + offset_s`` on the measurement clock; a
positive offset means the measurement stamps lag, as a mocap system stamping on
arrival). :func:`kinfw.identification.handeye.best_time_offset` estimates it from
:func:`time_offset_streams` (``kinfw import-bag --time-offset auto``). A measurement is
dropped, with its reason counted (:class:`BagAlignment`), when

- ``outside``: its shifted stamp lies outside a joint's stream (no extrapolation);
- ``gap``: the two joint samples around it are more than ``max_gap_s`` apart;
- ``fast``: linear interpolation there errs by more than ``max_interpolation_error``
  (rad or m), estimated from the joint's second difference (Notes of
  :func:`joint_values_at`);
- ``moving``: with ``still_speed`` set, a joint moves faster than that (rad/s or m/s):
  to keep only the still moments of a stop-and-go recording, where a timing error
  costs nothing.

TF chains
---------
``tf=(parent, child)`` composes ``parent_T_child`` through the TF tree of ``/tf`` and
``/tf_static`` (``tf2_msgs/TFMessage``): each edge is a ``parent_T_child`` transform.
The chain's stamps are those of its moving edge with the fewest messages; the other
moving edges are interpolated there (:func:`kinfw.measurements.interpolate_poses`, with
``max_gap_s``), static edges are constant.

Images
------
:func:`write_bag_images` writes the images of a ``sensor_msgs/Image`` or
``CompressedImage`` topic that the joint states place (the same drop rules) into a
folder, with the joint values per image in the CSV that ``kinfw detect --joints`` reads.
"""

from __future__ import annotations

import contextlib
import logging
from collections import defaultdict
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import (
    inverse_transform,
    quat_xyzw_from_matrix,
    transform_from_xyz_quat_xyzw,
)
from kinfw.measurements._dataset import Measurements
from kinfw.measurements._figaroh_csv import camera_link
from kinfw.measurements._file import measurements_from_dict
from kinfw.measurements._mounts import Mount
from kinfw.measurements._streams import interpolate_poses
from kinfw.observations import QUAT_NORM_TOL, DatasetError

if TYPE_CHECKING:
    from kinfw.model import Robot

log = logging.getLogger(__name__)

#: Why a measurement was not paired with joint values, in the order they are tested.
DROP_REASONS = ("outside", "gap", "fast", "moving")

JOINT_STATE = "sensor_msgs/msg/JointState"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"
TRANSFORM_STAMPED = "geometry_msgs/msg/TransformStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
#: The files :func:`write_bag_images` writes beside the images: the joint values per
#: image in the CSV that ``kinfw detect --joints`` reads, and the stamps.
IMAGE_JOINTS_CSV = "joints.csv"
IMAGE_STAMPS_JSON = "images.json"
#: ``sensor_msgs/Image`` encodings read: numpy type, channels, OpenCV conversion to the
#: channel order ``cv2.imwrite`` expects (BGR, BGRA) or None.
_ENCODINGS: dict[str, tuple[str, int, str | None]] = {
    "mono8": ("uint8", 1, None),
    "8UC1": ("uint8", 1, None),
    "mono16": ("uint16", 1, None),
    "16UC1": ("uint16", 1, None),
    "bgr8": ("uint8", 3, None),
    "8UC3": ("uint8", 3, None),
    "rgb8": ("uint8", 3, "COLOR_RGB2BGR"),
    "bgra8": ("uint8", 4, None),
    "rgba8": ("uint8", 4, "COLOR_RGBA2BGRA"),
}
_INSTALL = 'pip install "kinfw[ros]"'


@dataclass(frozen=True, slots=True)
class JointStates:
    """The joint readings of a bag, one stream per joint.

    Attributes
    ----------
    topic : str
        The ``sensor_msgs/JointState`` topic.
    names : tuple of str
        The URDF joints read, in the URDF's order.
    t_s : tuple of ndarray, shape (n_j,) each
        Per joint, its stamps in seconds from :attr:`BagRecording.t0_ns`, strictly
        increasing.
    qs : tuple of ndarray, shape (n_j,) each
        Per joint, its values at those stamps, rad or m.
    n_messages : int
        Messages read on the topic.
    ignored : tuple of str
        Joint names published that the URDF does not have (not read).
    """

    topic: str
    names: tuple[str, ...]
    t_s: tuple[NDArray[np.float64], ...]
    qs: tuple[NDArray[np.float64], ...]
    n_messages: int
    ignored: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class MeasuredStream:
    """The measurement stream of a bag: poses or points of one frame in another.

    Attributes
    ----------
    source : str
        The topic, or ``"/tf PARENT -> CHILD"`` for a TF chain.
    kind : {"pose", "point"}
        Poses (orientation measured) or points (position only).
    t_s : ndarray, shape (m,)
        Stamps in seconds from :attr:`BagRecording.t0_ns`, strictly increasing.
    parent_T_childs : ndarray, shape (m, 4, 4)
        Pose of the measured frame in the measuring frame at each stamp, metres; for
        points the rotation is the identity and only the position is measured.
    parent : str
        The measuring frame: the messages' ``header.frame_id`` or the TF parent (``""``
        when the messages leave it empty).
    n_messages : int
        Messages read (a TF chain: messages of its sparsest moving edge).
    """

    source: str
    kind: str
    t_s: NDArray[np.float64]
    parent_T_childs: NDArray[np.float64]
    parent: str
    n_messages: int


@dataclass(frozen=True, slots=True)
class BagRecording:
    """What :func:`read_bag` read from a bag.

    Attributes
    ----------
    path : Path
        The bag (a ROS 1 ``.bag`` file or a ROS 2 folder).
    ros_version : int
        1 or 2.
    t0_ns : int
        Time origin of every stamp, nanoseconds: the bag's first message.
    topics : tuple of (str, str, int)
        Every topic of the bag: name, message type, message count.
    joints : JointStates
        The joint readings.
    measured : MeasuredStream
        The measurement stream.
    """

    path: Path
    ros_version: int
    t0_ns: int
    topics: tuple[tuple[str, str, int], ...]
    joints: JointStates
    measured: MeasuredStream


@dataclass(frozen=True, slots=True)
class BagAlignment:
    """How the measurements of a bag were paired with joint values.

    Attributes
    ----------
    offset_s : float
        Time offset added to the joint stamps, seconds (module docstring).
    n_measured : int
        Measurements in the stream.
    kept : ndarray of int, shape (k,)
        Indices of the measurements written as samples, in time order.
    dropped : dict of str to int
        Per reason of :data:`DROP_REASONS`, how many measurements were dropped for it
        (each counted once, under the first reason that applies).
    """

    offset_s: float
    n_measured: int
    kept: NDArray[np.int64]
    dropped: dict[str, int]


@dataclass(frozen=True, slots=True)
class BagImages:
    """The images of a bag written by :func:`write_bag_images`.

    Attributes
    ----------
    directory : Path
        Where the images, :data:`IMAGE_JOINTS_CSV` and :data:`IMAGE_STAMPS_JSON` are.
    files : tuple of str
        The image files' names in ``directory``, in time order.
    t_s : ndarray, shape (k,)
        Their stamps, seconds from the bag's first message.
    joint_names : tuple of str
        The joints, in the URDF's order.
    qs : ndarray, shape (k, len(joint_names))
        Joint values interpolated at each image's stamp minus the offset, rad or m.
    alignment : BagAlignment
        Which images were kept (indices in the topic's time order) and why the others
        were dropped.
    """

    directory: Path
    files: tuple[str, ...]
    t_s: NDArray[np.float64]
    joint_names: tuple[str, ...]
    qs: NDArray[np.float64]
    alignment: BagAlignment


# ---------------------------------------------------------------------------------- reading


def _rosbags(path: Path) -> tuple[Any, Any, Any]:
    """``AnyReader``, ``get_typestore`` and ``Stores`` of rosbags, or the fix when missing."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise DatasetError(
            f"{path}: reading a ROS bag needs the rosbags package ({_INSTALL})"
        ) from None
    return AnyReader, get_typestore, Stores


def _stamp_ns(message: Any, record_ns: int) -> int:
    """``header.stamp`` in nanoseconds, or the record time when the stamp is zero."""
    stamp = message.header.stamp
    ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return ns if ns else record_ns


def _topic_list(topics: Sequence[tuple[str, str, int]]) -> str:
    return ", ".join(f"{name} ({msgtype}, {count})" for name, msgtype, count in topics) or "none"


def read_bag(
    path: str | Path,
    *,
    robot: Robot,
    joint_states: str = "/joint_states",
    pose: str | None = None,
    point: str | None = None,
    tf: tuple[str, str] | None = None,
    tf_topics: tuple[str, str] = ("/tf", "/tf_static"),
    max_gap_s: float | None = 0.05,
) -> BagRecording:
    """Read the joint states and one measurement stream of a ROS 1 or ROS 2 bag.

    Parameters
    ----------
    path : str or Path
        A ROS 1 ``.bag`` file, or a ROS 2 bag folder (``metadata.yaml`` and its
        ``.db3`` or ``.mcap`` files).
    robot : Robot
        The URDF robot: the joints read are those of its movable joints published on
        ``joint_states``.
    joint_states : str, keyword-only
        The ``sensor_msgs/JointState`` topic.
    pose, point : str, optional, keyword-only
        A ``geometry_msgs/PoseStamped`` (kind ``"pose"``) or ``PointStamped`` (kind
        ``"point"``) topic.
    tf : (str, str), optional, keyword-only
        ``(parent, child)``: the pose of ``child`` in ``parent`` composed through the TF
        tree at each stamp (module docstring); kind ``"pose"``.
    tf_topics : (str, str), keyword-only
        The dynamic and static ``tf2_msgs/TFMessage`` topics (a missing static topic is
        no TF edge).
    max_gap_s : float or None, keyword-only
        For a TF chain with several moving edges: the largest gap across which the
        others are interpolated at the sparsest one's stamps.

    Returns
    -------
    BagRecording

    Raises
    ------
    DatasetError
        Naming the bag and the topic: rosbags missing (with the ``pip install``), not
        exactly one of ``pose``, ``point``, ``tf``, a missing topic (with the topics the
        bag has), a topic of another message type, no joint of the URDF on
        ``joint_states`` (with the names published and the URDF's), a frame not in the
        TF tree (with the frames it has), no message, a stamp shared by two different
        messages.
    """
    path = Path(path)
    if sum(x is not None for x in (pose, point, tf)) != 1:
        raise DatasetError(
            f"{path}: give exactly one measurement stream: a PoseStamped topic, a "
            f"PointStamped topic or a TF chain (parent, child)"
        )
    with _open_bag(path) as (reader, topics, t0_ns):
        joints = _read_joint_states(reader, path, topics, joint_states, robot, t0_ns)
        if tf is not None:
            measured = _read_tf_chain(reader, path, topics, tf, tf_topics, t0_ns, max_gap_s)
        elif pose is not None:
            measured = _read_stamped(reader, path, topics, pose, True, t0_ns)
        else:
            measured = _read_stamped(reader, path, topics, str(point), False, t0_ns)
    return BagRecording(
        path=path,
        ros_version=1 if path.suffix == ".bag" else 2,
        t0_ns=t0_ns,
        topics=topics,
        joints=joints,
        measured=measured,
    )


@contextlib.contextmanager
def _open_bag(path: Path) -> Iterator[tuple[Any, tuple[tuple[str, str, int], ...], int]]:
    """An open ``AnyReader`` of the bag, its topics (name, type, count) and its first
    message's time (ns); errors name the bag."""
    AnyReader, get_typestore, Stores = _rosbags(path)
    if not path.exists():
        raise DatasetError(f"{path}: no such bag (a ROS 1 .bag file or a ROS 2 bag folder)")
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as err:  # rosbags' reader errors have no common base
        raise DatasetError(f"{path}: not a readable ROS 1 or ROS 2 bag ({err})") from None
    try:
        topics = tuple(
            (name, info.msgtype or "", int(info.msgcount))
            for name, info in sorted(reader.topics.items())
        )
        yield reader, topics, int(reader.start_time)
    finally:
        reader.close()


def _messages(
    reader: Any,
    path: Path,
    topics: Sequence[tuple[str, str, int]],
    topic: str,
    expected: tuple[str, ...],
) -> Iterator[tuple[int, Any]]:
    """``(record time ns, message)`` of ``topic``, checked to be one of ``expected``."""
    connections = [c for c in reader.connections if c.topic == topic]
    if not connections:
        raise DatasetError(
            f"{path}: no topic {topic!r} (expected {' or '.join(expected)}); the bag has: "
            f"{_topic_list(topics)}"
        )
    for c in connections:
        if c.msgtype not in expected:
            raise DatasetError(
                f"{path}: topic {topic!r} is {c.msgtype}, expected {' or '.join(expected)}"
            )
    for connection, record_ns, raw in reader.messages(connections=connections):
        yield record_ns, reader.deserialize(raw, connection.msgtype)


def _sorted_stream(
    path: Path, what: str, t_ns: list[int], values: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Stamps and values in time order, exact repeats dropped; a stamp shared by two
    different values raises."""
    t = np.asarray(t_ns, dtype=np.int64)
    order = np.argsort(t, kind="stable")
    t, values = t[order], values[order]
    same = np.flatnonzero(np.diff(t) == 0)
    if same.size:
        differ = np.any(values[same] != values[same + 1], axis=tuple(range(1, values.ndim)))
        if np.any(differ):
            k = int(same[np.argmax(differ)])
            raise DatasetError(
                f"{path}: {what}: two messages share the stamp {int(t[k])} ns but differ; "
                f"a stream needs one value per stamp"
            )
        keep = np.ones(len(t), dtype=bool)
        keep[same + 1] = False
        t, values = t[keep], values[keep]
    return t, values


def _read_joint_states(
    reader: Any,
    path: Path,
    topics: Sequence[tuple[str, str, int]],
    topic: str,
    robot: Robot,
    t0_ns: int,
) -> JointStates:
    movable = set(robot.joint_names)
    stamps: dict[str, list[int]] = defaultdict(list)
    values: dict[str, list[float]] = defaultdict(list)
    published: set[str] = set()
    n = 0
    for record_ns, msg in _messages(reader, path, topics, topic, (JOINT_STATE,)):
        n += 1
        if len(msg.position) != len(msg.name):
            raise DatasetError(
                f"{path}: {topic} message {n - 1}: {len(msg.name)} joint names but "
                f"{len(msg.position)} positions"
            )
        t_ns = _stamp_ns(msg, record_ns)
        for name, q in zip(msg.name, msg.position, strict=True):
            published.add(name)
            if name in movable:
                stamps[name].append(t_ns)
                values[name].append(float(q))
    if not n:
        raise DatasetError(f"{path}: topic {topic!r} has no messages")
    names = tuple(j for j in robot.joint_names if j in stamps)
    if not names:
        raise DatasetError(
            f"{path}: {topic} publishes no joint of {robot.source}: it has "
            f"{sorted(published)}, the URDF's movable joints are {list(robot.joint_names)}"
        )
    t_s, qs = [], []
    for name in names:
        t, q = _sorted_stream(path, f"{topic} joint {name!r}", stamps[name], np.array(values[name]))
        if not np.isfinite(q).all():
            raise DatasetError(f"{path}: {topic}: joint {name!r} has a value that is not finite")
        if len(t) < 2:
            raise DatasetError(
                f"{path}: {topic}: joint {name!r} has {len(t)} distinct stamp; interpolation "
                f"needs at least 2"
            )
        t_s.append((t - t0_ns) * 1e-9)
        qs.append(q)
    ignored = tuple(sorted(published - movable))
    if ignored:
        log.info("%s: %s: joints not in the URDF, not read: %s", path, topic, ignored)
    return JointStates(topic, names, tuple(t_s), tuple(qs), n, ignored)


def _read_stamped(
    reader: Any,
    path: Path,
    topics: Sequence[tuple[str, str, int]],
    topic: str,
    is_pose: bool,
    t0_ns: int,
) -> MeasuredStream:
    """A PoseStamped or PointStamped topic as a stream."""
    expected = POSE_STAMPED if is_pose else POINT_STAMPED
    t_ns, rows, parents = [], [], set()
    for record_ns, msg in _messages(reader, path, topics, topic, (expected,)):
        t_ns.append(_stamp_ns(msg, record_ns))
        parents.add(msg.header.frame_id)
        if is_pose:
            p, o = msg.pose.position, msg.pose.orientation
            rows.append([p.x, p.y, p.z, o.x, o.y, o.z, o.w])
        else:
            p = msg.point
            rows.append([p.x, p.y, p.z, 0.0, 0.0, 0.0, 1.0])
    if not rows:
        raise DatasetError(f"{path}: topic {topic!r} has no messages")
    if len(parents) > 1:
        raise DatasetError(
            f"{path}: {topic}: messages in several frames {sorted(parents)}; expected one"
        )
    t, data = _sorted_stream(path, topic, t_ns, np.array(rows))
    return MeasuredStream(
        source=topic,
        kind="pose" if is_pose else "point",
        t_s=(t - t0_ns) * 1e-9,
        parent_T_childs=_poses(path, topic, data),
        parent=parents.pop(),
        n_messages=len(rows),
    )


def _poses(path: Path, what: str, rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """Poses ``(n, 4, 4)`` from rows ``x, y, z, qx, qy, qz, qw``; raises unless finite with
    unit quaternions (within :data:`kinfw.observations.QUAT_NORM_TOL`)."""
    if not np.isfinite(rows).all():
        raise DatasetError(f"{path}: {what}: a message has a value that is not finite")
    norms = np.linalg.norm(rows[:, 3:], axis=1)
    if np.any(np.abs(norms - 1.0) > QUAT_NORM_TOL):
        k = int(np.argmax(np.abs(norms - 1.0)))
        raise DatasetError(
            f"{path}: {what}: orientation of message {k} (by stamp) has norm {norms[k]:.6g}, "
            f"expected a unit quaternion (x, y, z, w)"
        )
    return transform_from_xyz_quat_xyzw(rows[:, :3], rows[:, 3:])


def _read_tf_chain(
    reader: Any,
    path: Path,
    topics: Sequence[tuple[str, str, int]],
    tf: tuple[str, str],
    tf_topics: tuple[str, str],
    t0_ns: int,
    max_gap_s: float | None,
) -> MeasuredStream:
    """``parent_T_child`` through the TF tree (module docstring)."""
    parent, child = tf
    dynamic, static = tf_topics
    edges: dict[tuple[str, str], tuple[list[int], list[list[float]]]] = defaultdict(
        lambda: ([], [])
    )
    statics: dict[tuple[str, str], list[float]] = {}
    present = {name for name, _, _ in topics}
    for topic in (dynamic, static) if static in present else (dynamic,):
        for _, msg in _messages(reader, path, topics, topic, (TF_MESSAGE,)):
            for ts in msg.transforms:
                key = (ts.header.frame_id.lstrip("/"), ts.child_frame_id.lstrip("/"))
                p, o = ts.transform.translation, ts.transform.rotation
                row = [p.x, p.y, p.z, o.x, o.y, o.z, o.w]
                if topic == static:
                    statics[key] = row
                else:
                    edges[key][0].append(_stamp_ns(ts, 0))
                    edges[key][1].append(row)
    parent_of = {c: p for p, c in [*edges, *statics]}
    chain = _tf_path(path, parent_of, parent, child)
    moving = [e for e in chain if e[0] in edges]
    if not moving:
        raise DatasetError(
            f"{path}: the TF chain {parent} -> {child} is static (on {static}); nothing is measured"
        )
    streams = {}
    for key, _ in moving:
        t_ns, rows = edges[key]
        what = f"{dynamic} {key[0]} -> {key[1]}"
        t, data = _sorted_stream(path, what, t_ns, np.array(rows))
        streams[key] = ((t - t0_ns) * 1e-9, _poses(path, what, data))
    base = min(streams, key=lambda k: len(streams[k][0]))
    t_s = streams[base][0]
    valid = np.ones(len(t_s), dtype=bool)
    parent_T_childs = np.broadcast_to(np.eye(4), (len(t_s), 4, 4)).copy()
    for key, inverted in chain:
        if key in statics:
            edge_T = _poses(path, f"{static} {key[0]} -> {key[1]}", np.array([statics[key]]))
        elif key == base:
            edge_T = streams[key][1]
        else:
            t_edge, T_edge = streams[key]
            inside = (t_s >= t_edge[0]) & (t_s <= t_edge[-1])
            edge_T = np.broadcast_to(np.eye(4), (len(t_s), 4, 4)).copy()  # where valid
            if len(t_edge) > 1 and np.any(inside):
                edge_T[inside], ok = interpolate_poses(
                    t_edge, T_edge, t_s[inside], max_gap_s=max_gap_s
                )
                inside[inside] = ok
            valid &= inside
        parent_T_childs = parent_T_childs @ (inverse_transform(edge_T) if inverted else edge_T)
    if not np.any(valid):
        raise DatasetError(
            f"{path}: the TF chain {parent} -> {child}: its moving edges never overlap in time"
        )
    if not np.all(valid):
        log.info(
            "%s: TF chain %s -> %s: %d of %d stamps of %s -> %s dropped (the other moving "
            "edges do not cover them)",
            path,
            parent,
            child,
            int(np.count_nonzero(~valid)),
            len(t_s),
            *base,
        )
    return MeasuredStream(
        source=f"{dynamic} {parent} -> {child}",
        kind="pose",
        t_s=t_s[valid],
        parent_T_childs=parent_T_childs[valid],
        parent=parent,
        n_messages=len(t_s),
    )


def _tf_path(
    path: Path, parent_of: dict[str, str], parent: str, child: str
) -> list[tuple[tuple[str, str], bool]]:
    """The TF edges from ``parent`` to ``child``: ``((edge parent, edge child), inverted)``
    in the order they compose ``parent_T_child``."""
    frames = sorted({*parent_of, *parent_of.values()})
    for name in (parent, child):
        if name not in frames:
            raise DatasetError(f"{path}: no TF frame {name!r}; the TF tree has {frames}")

    def up(frame: str) -> list[str]:
        out = [frame]
        while out[-1] in parent_of and parent_of[out[-1]] not in out:
            out.append(parent_of[out[-1]])
        return out

    up_parent, up_child = up(parent), up(child)
    common = next((f for f in up_parent if f in up_child), None)
    if common is None:
        raise DatasetError(f"{path}: TF frames {parent!r} and {child!r} are in separate trees")
    rising = up_parent[: up_parent.index(common)]  # parent up to (not incl.) the common frame
    falling = up_child[: up_child.index(common)][::-1]
    return [((parent_of[f], f), True) for f in rising] + [
        ((parent_of[f], f), False) for f in falling
    ]


# ------------------------------------------------------------------------------ alignment


def joint_values_at(
    joints: JointStates,
    t_query: ArrayLike,
    *,
    max_gap_s: float | None = 0.05,
    max_interpolation_error: float | None = 1e-3,
    still_speed: float | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.str_]]:
    """Joint values interpolated linearly at some instants, and why any is unusable.

    Parameters
    ----------
    joints : JointStates
        The joint streams.
    t_query : array_like, shape (m,)
        Instants on the joints' clock, seconds from the bag's time origin.
    max_gap_s : float or None, keyword-only
        Largest span between the two joint samples around an instant.
    max_interpolation_error : float or None, keyword-only
        Largest estimated error of linear interpolation, rad or m (Notes).
    still_speed : float or None, keyword-only
        Largest joint speed, rad/s or m/s, over the span around an instant; None: any.

    Returns
    -------
    qs : ndarray, shape (m, len(joints.names))
        Joint values in the order of ``joints.names``, rad or m; NaN where unusable.
    reasons : ndarray of str, shape (m,)
        ``""`` where usable, else the first of :data:`DROP_REASONS` that applies to any
        joint.

    Notes
    -----
    Between samples ``k`` and ``k + 1`` (span ``h``, ``s = (t - t_k) / h``) the linear
    interpolant of a smooth ``q`` errs by ``s (1 - s) h^2 |q''| / 2``; ``q''`` is
    estimated by the second divided differences at ``k`` and ``k + 1`` (the larger).
    An instant equal to a stamp is exact: it is never ``gap`` nor ``fast``.
    """
    t_query = np.asarray(t_query, dtype=float)
    qs = np.full((len(t_query), len(joints.names)), np.nan)
    rank = np.zeros(len(t_query), dtype=int)  # 0: usable, else 1 + index in DROP_REASONS
    for j, (t, q) in enumerate(zip(joints.t_s, joints.qs, strict=True)):
        inside = (t_query >= t[0]) & (t_query <= t[-1])
        code = np.where(inside, 0, 1)
        k = np.clip(np.searchsorted(t, t_query, side="right") - 1, 0, len(t) - 2)
        h = t[k + 1] - t[k]
        s = np.clip((t_query - t[k]) / h, 0.0, 1.0)
        qs[:, j] = q[k] + s * (q[k + 1] - q[k])
        exact = (s == 0.0) | (s == 1.0)
        slope = np.diff(q) / np.diff(t)
        curvature = np.zeros(len(t))
        curvature[1:-1] = 2.0 * np.abs(np.diff(slope)) / (t[2:] - t[:-2])
        error = 0.5 * s * (1.0 - s) * h**2 * np.maximum(curvature[k], curvature[k + 1])
        if max_gap_s is not None:
            code = np.where((code == 0) & (h > max_gap_s) & ~exact, 2, code)
        if max_interpolation_error is not None:
            code = np.where((code == 0) & (error > max_interpolation_error), 3, code)
        if still_speed is not None:
            code = np.where((code == 0) & (np.abs(slope[k]) > still_speed), 4, code)
        rank = np.where(rank == 0, code, np.where(code, np.minimum(rank, code), rank))
    qs[rank > 0] = np.nan
    reasons = np.array(("", *DROP_REASONS))[rank]
    return qs, reasons


def time_offset_streams(
    recording: BagRecording, robot: Robot, frame: str, *, target: bool = False
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The two pose streams whose time offset
    :func:`kinfw.identification.handeye.best_time_offset` estimates.

    Parameters
    ----------
    recording : BagRecording
        A bag with a pose stream (``measured.kind == "pose"``).
    robot : Robot
        The nominal robot: its forward kinematics give the hand stream.
    frame : str
        The URDF frame the measured frame is rigidly attached to (a marker's link, or
        the camera link seeing a target).
    target : bool, keyword-only
        The poses are ``camera_T_target`` of a fixed target seen by a camera on
        ``frame``; else ``meas_T_marker`` of a marker on ``frame`` in a fixed
        measurement frame.

    Returns
    -------
    t_hand : ndarray, shape (n,)
        Stamps of the joint stream with the most samples, seconds.
    base_T_hands : ndarray, shape (n, 4, 4)
        ``root_T_frame`` by the nominal FK of the joints interpolated there, metres.
    t_eye : ndarray, shape (m,)
        The measurement stamps, seconds.
    target_T_eyes : ndarray, shape (m, 4, 4)
        The measured poses as the estimator's ``target_T_eye``: both set-ups are a
        hand-eye problem whose ``root_T_frame @ X @ inverse(target_T_eye)`` is constant
        at the right offset. A camera on ``frame`` seeing a fixed target: the inverse
        of ``camera_T_target`` (the constant is ``root_T_target``); a marker on
        ``frame`` seen from a fixed frame: ``mocap_T_marker`` itself (``X`` is
        ``frame_T_marker``, the constant ``root_T_mocap``).

    Raises
    ------
    DatasetError
        The stream has points, not poses (no hand-eye problem), or a joint that moves
        ``frame`` is not published.
    """
    measured = recording.measured
    if measured.kind != "pose":
        raise DatasetError(
            f"{recording.path}: {measured.source}: the time offset is estimated from "
            f"poses (orientations), and this stream has points; give the offset in seconds"
        )
    names = _published_joints(recording, robot, frame)
    j = max(range(len(names)), key=lambda i: len(recording.joints.t_s[i]))
    t_hand = recording.joints.t_s[j]
    qs, reasons = joint_values_at(
        recording.joints, t_hand, max_gap_s=None, max_interpolation_error=None
    )
    ok = reasons == ""
    base_T_hands = robot.frame_poses(qs[ok], frame, recording.joints.names)
    target_T_eyes = measured.parent_T_childs
    if target:
        target_T_eyes = inverse_transform(target_T_eyes)
    return t_hand[ok], base_T_hands, measured.t_s, target_T_eyes


def _published_joints(recording: BagRecording, robot: Robot, frame: str) -> tuple[str, ...]:
    """The joints read (the URDF's published joints), once every joint that moves
    ``frame`` is checked to be among them (an unpublished one would be held at zero)."""
    missing = [n for n in robot.movable_path(frame) if n not in recording.joints.names]
    if missing:
        raise DatasetError(
            f"{recording.path}: joints {missing} move {frame!r} but are not on "
            f"{recording.joints.topic} (it has {list(recording.joints.names)})"
        )
    return recording.joints.names


def measurements_from_bag(
    recording: BagRecording,
    *,
    robot: Robot,
    frame: str,
    offset_s: float = 0.0,
    marker: str | None = None,
    measured_in: str | None = None,
    target: str | None = None,
    camera_frame: str | None = None,
    max_gap_s: float | None = 0.05,
    max_interpolation_error: float | None = 1e-3,
    still_speed: float | None = None,
) -> tuple[Measurements, BagAlignment]:
    """One sample per usable measurement of a bag, the joints interpolated at its stamp.

    Parameters
    ----------
    recording : BagRecording
        What :func:`read_bag` read.
    robot : Robot
        The URDF robot.
    frame : str
        URDF frame the measured frame is on: the frame itself (a pose of the frame), a
        marker on it (``marker``), or the link carrying the camera (``target``).
    offset_s : float, keyword-only
        Added to the joint stamps, seconds (module docstring).
    marker : str, optional, keyword-only
        The measured poses or points are of a marker of unknown pose (offset) on
        ``frame``. Without it a pose is that of ``frame`` itself, a point has an unknown
        offset.
    measured_in : str, optional, keyword-only
        Measurement frame (not in the URDF; its pose is estimated). Default: the
        stream's frame (``header.frame_id``, the TF parent) unless it is the URDF root
        link or empty (then the root link).
    target : str, optional, keyword-only
        Read the poses as ``camera_T_target`` of a fixed target of that name seen by a
        camera (``target`` observations); needs ``camera_frame``; excludes ``marker``
        and ``measured_in``.
    camera_frame : str, optional, keyword-only
        With ``target``: the camera's own URDF link, fixed to ``frame`` (as for
        :func:`kinfw.measurements.measurements_from_figaroh_csv`).
    max_gap_s, max_interpolation_error, still_speed : float or None, keyword-only
        The drop rules (module docstring, :func:`joint_values_at`).

    Returns
    -------
    measurements : Measurements
        Joint values in SI; one observation per sample.
    alignment : BagAlignment
        Which measurements were kept and why the others were dropped.

    Raises
    ------
    DatasetError
        Naming the bag: a joint that moves ``frame`` not published, a stream frame that
        is a URDF frame other than the root link, ``target`` on points, no measurement
        within the joint states' time range after the offset (both ranges given), every
        measurement dropped (the counts).
    ValueError
        ``target`` with ``marker`` or ``measured_in``.
    """
    path, measured = recording.path, recording.measured
    names = _published_joints(recording, robot, frame)
    common: dict[str, Any] = {"frame": frame}
    mounts: dict[str, Mount] = {}
    if target is not None:
        if marker is not None or measured_in is not None:
            raise ValueError("target excludes marker and measured_in: the camera measures")
        if measured.kind != "pose":
            raise DatasetError(f"{path}: {measured.source}: a target needs poses, got points")
        link = camera_link(path, robot, frame, camera_frame)
        mounts = {camera_frame: link} if isinstance(link, Mount) else {}
        common = {"frame": camera_frame, "target": target}
        kind = "target"
    else:
        kind = measured.kind
        if marker is not None:
            common["marker"] = marker
        measured_in = _measurement_frame(recording, robot, measured_in)
        if measured_in is not None:
            common["measured_in"] = measured_in
    qs, alignment = _align(
        path,
        measured.source,
        recording.joints,
        measured.t_s,
        offset_s,
        max_gap_s=max_gap_s,
        max_interpolation_error=max_interpolation_error,
        still_speed=still_speed,
    )
    kept = alignment.kept
    xyz = measured.parent_T_childs[kept, :3, 3]
    quats = quat_xyzw_from_matrix(measured.parent_T_childs[kept, :3, :3])
    observations = [
        {**common, "kind": kind, "xyz": p}
        if kind == "point"
        else {**common, "kind": kind, "xyz": p, "quat_xyzw": o}
        for p, o in zip(xyz.tolist(), quats.tolist(), strict=True)
    ]
    doc = {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "m", "angle": "rad"},
        "joint_names": list(names),
        "samples": [
            {"q": q, "observations": [obs]}
            for q, obs in zip(qs[kept].tolist(), observations, strict=True)
        ],
    }
    return measurements_from_dict(doc, source=str(path)).with_mounts(mounts), alignment


def _align(
    path: Path,
    source: str,
    joints: JointStates,
    t_s: NDArray[np.float64],
    offset_s: float,
    **rules: float | None,
) -> tuple[NDArray[np.float64], BagAlignment]:
    """Joint values at stamps ``t_s`` of ``source`` (:func:`joint_values_at` with
    ``rules``) and the alignment; raises when no stamp overlaps the joint states or
    every one is dropped."""
    t_query = t_s - offset_s
    t_joints = np.concatenate([t[[0, -1]] for t in joints.t_s])
    lo, hi = float(np.max(t_joints[0::2])), float(np.min(t_joints[1::2]))
    if not np.any((t_query >= lo) & (t_query <= hi)):
        raise DatasetError(
            f"{path}: no measurement of {source} ([{t_s[0]:.3f}, {t_s[-1]:.3f}] s) lies "
            f"within the joint states' time range [{lo:.3f}, {hi:.3f}] s shifted by the "
            f"offset {offset_s:+.4f} s (seconds from the bag's start); are both stamped on "
            f"one clock?"
        )
    qs, reasons = joint_values_at(joints, t_query, **rules)
    kept = np.flatnonzero(reasons == "")
    dropped = {r: int(np.count_nonzero(reasons == r)) for r in DROP_REASONS}
    if not kept.size:
        raise DatasetError(
            f"{path}: every measurement of {source} was dropped: "
            + ", ".join(f"{n} {r}" for r, n in dropped.items())
        )
    return qs, BagAlignment(float(offset_s), len(t_s), kept, dropped)


def write_bag_images(
    path: str | Path,
    directory: str | Path,
    *,
    robot: Robot,
    images: str,
    joint_states: str = "/joint_states",
    offset_s: float = 0.0,
    max_gap_s: float | None = 0.05,
    max_interpolation_error: float | None = 1e-3,
    still_speed: float | None = None,
) -> BagImages:
    """Write the images of a bag that the joint states place, for ``kinfw detect``.

    Parameters
    ----------
    path : str or Path
        The bag (as for :func:`read_bag`).
    directory : str or Path
        Folder to write (created): ``image_00000.png``, ... (``.jpg`` for JPEG
        ``CompressedImage`` data, copied as recorded), :data:`IMAGE_JOINTS_CSV` (a
        header ``image, JOINT...`` and one row per image: ``kinfw detect --joints``)
        and :data:`IMAGE_STAMPS_JSON` (the bag, topic, offset, joint names, and per
        image its file, stamp and joint values; the dropped counts).
    robot : Robot
        The URDF robot (which joints are read).
    images : str, keyword-only
        A ``sensor_msgs/Image`` (encodings mono8, mono16, bgr8, rgb8, bgra8, rgba8,
        8UC1, 8UC3, 16UC1) or ``sensor_msgs/CompressedImage`` topic.
    joint_states, offset_s, max_gap_s, max_interpolation_error, still_speed
        As for :func:`read_bag` and :func:`measurements_from_bag`; ``still_speed``
        keeps the images taken while the robot stood (no motion blur, no timing error).

    Returns
    -------
    BagImages

    Raises
    ------
    DatasetError
        As :func:`read_bag`; an unsupported encoding (naming it and those read); no
        image within the joint states' time range, or every image dropped.
    """
    import cv2

    from kinfw.files import json_text, write_text_atomic

    path, directory = Path(path), Path(directory)
    expected = (IMAGE, COMPRESSED_IMAGE)
    with _open_bag(path) as (reader, topics, t0_ns):
        joints = _read_joint_states(reader, path, topics, joint_states, robot, t0_ns)
        stamps = []  # a first pass for the stamps: the images are written by the second
        for record_ns, msg in _messages(reader, path, topics, images, expected):
            stamps.append((_stamp_ns(msg, record_ns) - t0_ns) * 1e-9)
            if not hasattr(msg, "format") and msg.encoding not in _ENCODINGS:
                raise DatasetError(
                    f"{path}: {images}: image encoding {msg.encoding!r} is not read; expected "
                    f"one of {list(_ENCODINGS)} (or a CompressedImage topic)"
                )
        if not stamps:
            raise DatasetError(f"{path}: topic {images!r} has no messages")
        order = np.argsort(stamps, kind="stable")
        t_s = np.asarray(stamps)[order]
        qs, alignment = _align(
            path,
            images,
            joints,
            t_s,
            offset_s,
            max_gap_s=max_gap_s,
            max_interpolation_error=max_interpolation_error,
            still_speed=still_speed,
        )
        rank = {int(order[k]): i for i, k in enumerate(alignment.kept)}  # message -> file
        files = [""] * len(rank)
        directory.mkdir(parents=True, exist_ok=True)
        for m, (_, msg) in enumerate(_messages(reader, path, topics, images, expected)):
            if m in rank:
                data, suffix = _image_file(path, images, msg, cv2)
                files[rank[m]] = f"image_{rank[m]:05d}{suffix}"
                (directory / files[rank[m]]).write_bytes(data)
    qs = qs[alignment.kept]
    rows = [",".join(["image", *joints.names])]
    rows += [",".join([f, *map(repr, q)]) for f, q in zip(files, qs.tolist(), strict=True)]
    write_text_atomic(directory / IMAGE_JOINTS_CSV, "\n".join(rows) + "\n")
    record = {
        "bag": str(path),
        "topic": images,
        "t0_ns": t0_ns,
        "offset_s": float(offset_s),
        "joint_names": list(joints.names),
        "images": [
            {"file": f, "t_s": float(t), "q": q}
            for f, t, q in zip(files, t_s[alignment.kept], qs.tolist(), strict=True)
        ],
        "dropped": alignment.dropped,
    }
    write_text_atomic(directory / IMAGE_STAMPS_JSON, json_text(record) + "\n")
    return BagImages(directory, tuple(files), t_s[alignment.kept], joints.names, qs, alignment)


def _image_file(path: Path, topic: str, msg: Any, cv2: Any) -> tuple[bytes, str]:
    """The bytes of an image file and its suffix: a ``CompressedImage``'s data as
    recorded, an ``Image`` (encoding checked by the caller) encoded as PNG (lossless,
    16 bits kept)."""
    if hasattr(msg, "format"):  # CompressedImage
        return bytes(msg.data), ".png" if "png" in msg.format.lower() else ".jpg"
    dtype_name, channels, conversion = _ENCODINGS[msg.encoding]
    dtype = np.dtype(dtype_name).newbyteorder(">" if msg.is_bigendian else "<")
    row_bytes = msg.width * channels * dtype.itemsize
    rows = np.asarray(msg.data, dtype=np.uint8).reshape(msg.height, msg.step)[:, :row_bytes]
    pixels = np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("="))
    shape = (msg.height, msg.width) if channels == 1 else (msg.height, msg.width, channels)
    pixels = pixels.reshape(shape)
    if conversion is not None:
        pixels = cv2.cvtColor(pixels, getattr(cv2, conversion))
    ok, png = cv2.imencode(".png", pixels)
    if not ok:
        raise DatasetError(f"{path}: {topic}: an image could not be encoded as PNG")
    return png.tobytes(), ".png"


def _measurement_frame(
    recording: BagRecording, robot: Robot, measured_in: str | None
) -> str | None:
    """The ``measured_in`` of pose and point observations (see
    :func:`measurements_from_bag`)."""
    if measured_in is not None:
        return measured_in
    parent = recording.measured.parent.lstrip("/")
    if not parent or parent == robot.root_link:
        return None
    if robot.has_frame(parent):
        raise DatasetError(
            f"{recording.path}: {recording.measured.source} is measured in {parent!r}, a "
            f"frame of the URDF other than its root link {robot.root_link!r}; give the "
            f"measurement frame with --measured-in (measured_in=)"
        )
    return parent
