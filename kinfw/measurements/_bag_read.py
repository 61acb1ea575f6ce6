"""ROS 1 and ROS 2 bags read: the joint states and one measurement stream.

A calibration recording in ROS is a bag: the robot's ``sensor_msgs/JointState`` on a
joint-state topic (``/joint_states``, ~100-500 Hz) and a measurement stream at its own
rate -- a motion-capture ``geometry_msgs/PoseStamped`` or ``PointStamped`` topic, or a
chain of ``/tf`` transforms (a tracker, a camera seeing a board). :func:`read_bag` reads
both with the ``rosbags`` package (pure Python, the ``ros`` extra: ROS 1 ``.bag`` files
and ROS 2 folders with ``metadata.yaml`` and ``.db3`` or ``.mcap`` storage, through
``rosbags.highlevel.AnyReader``); :func:`kinfw.measurements.measurements_from_bag`
(``_bag_align.py``) pairs each measurement with the joint values interpolated at its
stamp and writes the samples, :func:`kinfw.measurements.write_bag_images`
(``_bag_images.py``) writes the images of an image topic.

Stamps
------
Every message is placed at its ``header.stamp`` (a zero stamp, as some drivers leave it,
falls back to the bag's record time), in seconds from the first message of the bag.

TF chains
---------
``tf=(parent, child)`` composes ``parent_T_child`` through the TF tree of ``/tf`` and
``/tf_static`` (``tf2_msgs/TFMessage``): each edge is a ``parent_T_child`` transform.
The chain's stamps are those of its moving edge with the fewest messages; the other
moving edges are interpolated there (:func:`kinfw.measurements.interpolate_poses`, with
``max_gap_s``), static edges are constant.
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
from numpy.typing import NDArray

from kinfw.geometry import inverse_transform, transform_from_xyz_quat_xyzw
from kinfw.measurements._streams import interpolate_poses
from kinfw.observations import QUAT_NORM_TOL, DatasetError

if TYPE_CHECKING:
    from kinfw.model import Robot

log = logging.getLogger(__name__)

JOINT_STATE = "sensor_msgs/msg/JointState"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"
TRANSFORM_STAMPED = "geometry_msgs/msg/TransformStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
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


def stamp_ns(message: Any, record_ns: int) -> int:
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
    with open_bag(path) as (reader, topics, t0_ns):
        joints = read_joint_states(reader, path, topics, joint_states, robot, t0_ns)
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
def open_bag(path: Path) -> Iterator[tuple[Any, tuple[tuple[str, str, int], ...], int]]:
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


def bag_messages(
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


def read_joint_states(
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
    for record_ns, msg in bag_messages(reader, path, topics, topic, (JOINT_STATE,)):
        n += 1
        if len(msg.position) != len(msg.name):
            raise DatasetError(
                f"{path}: {topic} message {n - 1}: {len(msg.name)} joint names but "
                f"{len(msg.position)} positions"
            )
        t_ns = stamp_ns(msg, record_ns)
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
    for record_ns, msg in bag_messages(reader, path, topics, topic, (expected,)):
        t_ns.append(stamp_ns(msg, record_ns))
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
        for _, msg in bag_messages(reader, path, topics, topic, (TF_MESSAGE,)):
            for ts in msg.transforms:
                key = (ts.header.frame_id.lstrip("/"), ts.child_frame_id.lstrip("/"))
                p, o = ts.transform.translation, ts.transform.rotation
                row = [p.x, p.y, p.z, o.x, o.y, o.z, o.w]
                if topic == static:
                    statics[key] = row
                else:
                    edges[key][0].append(stamp_ns(ts, 0))
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
