"""A URDF robot: Pinocchio for forward kinematics, the standard library's XML parser for
the URDF's structure.

:class:`Robot` is immutable: it keeps the URDF text it was built from, so a calibrated
robot is a new ``Robot`` built from new text (Pinocchio cannot change a joint's axis or
type in place, and rebuilding takes well under a millisecond).

Joint values always follow the URDF: revolute and continuous joints in radians,
prismatic joints in metres, in the order of a ``joint_names`` sequence given by the
caller (by default :attr:`Robot.joint_names`, the movable joints in URDF document order).
Joints a caller does not list are held at zero.
"""

from __future__ import annotations

import contextlib
import difflib
import io
import logging
import os
import re
import sys
import tempfile
import threading
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "JointInfo",
    "Robot",
    "RobotModelError",
    "Topology",
    "UnknownFrameError",
    "builtin_head_urdf",
    "load_robot",
]

MOVABLE_TYPES = ("revolute", "continuous", "prismatic")

logger = logging.getLogger(__name__)
_NATIVE_STDERR_LOCK = threading.Lock()
#: The "at line N in file.cpp" that ends each of urdfdom's stderr messages.
_URDFDOM_LINE = re.compile(r"\s*at line \d+ in \S+\s*")


class RobotModelError(ValueError):
    """The URDF cannot be used as asked (bad XML, unsupported joint on a needed path...)."""


class UnknownFrameError(RobotModelError, KeyError):
    """A frame (link or joint) name that the URDF does not have."""

    def __str__(self) -> str:  # KeyError would print the message with quotes
        return str(self.args[0])


@dataclass(frozen=True, slots=True)
class JointInfo:
    """One URDF joint as written in the file.

    Attributes
    ----------
    name, type, parent, child : str
        URDF joint name, type, parent link and child link.
    parent_T_child : ndarray, shape (4, 4)
        The joint's ``<origin>`` (pose of the child link in the parent link at q = 0).
    axis : ndarray, shape (3,)
        Unit joint axis in the child link frame (the URDF value, normalised).
    lower, upper : float
        Limits in rad or m; ``-inf`` / ``inf`` when the URDF gives none.
    mimic : str or None
        Name of the joint this one mimics.
    """

    name: str
    type: str
    parent: str
    child: str
    parent_T_child: NDArray[np.float64]
    axis: NDArray[np.float64]
    lower: float
    upper: float
    mimic: str | None

    @property
    def is_movable(self) -> bool:
        """True for revolute, continuous and prismatic joints (one scalar joint value)."""
        return self.type in MOVABLE_TYPES

    @property
    def is_revolute(self) -> bool:
        """True for revolute and continuous joints."""
        return self.type in ("revolute", "continuous")


@dataclass(frozen=True, slots=True)
class Topology:
    """The kinematic tree spanned by the paths from the root link to some frames.

    Only movable joints on those paths appear; fixed joints are folded into the
    geometry. Joints are ordered parents first (a stable topological sort of URDF
    document order), so ``parent[i] < i``.

    Attributes
    ----------
    joint_names : tuple of str
        Movable joints on the paths, parents first.
    revolute : tuple of bool
        True for a revolute or continuous joint, False for a prismatic one.
    parent : tuple of int
        Index (into ``joint_names``) of each joint's nearest movable ancestor, -1 when
        there is none (the joint hangs rigidly off the root link).
    frames : tuple of str
        The end frames (links or joint frames), in the order asked for.
    frame_parent : tuple of int
        Index of the last movable joint before each frame, -1 when the frame is rigidly
        attached to the root link.
    """

    joint_names: tuple[str, ...]
    revolute: tuple[bool, ...]
    parent: tuple[int, ...]
    frames: tuple[str, ...]
    frame_parent: tuple[int, ...]

    def children(self, i: int) -> tuple[int, ...]:
        """Joints whose parent is joint ``i`` (``-1`` for the root)."""
        return tuple(k for k, p in enumerate(self.parent) if p == i)

    def frames_after(self, i: int) -> tuple[int, ...]:
        """Indices of the end frames whose last movable joint is ``i`` (``-1``: root)."""
        return tuple(k for k, p in enumerate(self.frame_parent) if p == i)

    def chain(self, frame: str) -> tuple[int, ...]:
        """Joint indices from the root to ``frame``, root side first."""
        try:
            i = self.frame_parent[self.frames.index(frame)]
        except ValueError:
            raise UnknownFrameError(
                f"frame {frame!r} is not an end frame of this topology {self.frames}"
            ) from None
        out = []
        while i >= 0:
            out.append(i)
            i = self.parent[i]
        return tuple(reversed(out))

    @property
    def branch_points(self) -> tuple[int, ...]:
        """Joints (or -1, the root) after which the tree splits into several branches."""
        counts: dict[int, int] = {}
        for p in (*self.parent, *self.frame_parent):
            counts[p] = counts.get(p, 0) + 1
        return tuple(sorted(i for i, c in counts.items() if c > 1))


def _as_xml_text(urdf: str | Path) -> tuple[str, str]:
    """Return (xml_text, source) for a path or an XML string."""
    if isinstance(urdf, Path) or not str(urdf).lstrip().startswith("<"):
        path = Path(urdf)
        try:
            return path.read_text(encoding="utf-8"), str(path)
        except OSError as exc:
            raise RobotModelError(f"{path}: cannot read URDF ({exc.strerror})") from None
    return str(urdf), "<urdf string>"


def _check_xml(xml: str, source: str) -> ET.Element:
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        raise RobotModelError(f"{source}: not well-formed XML ({exc})") from None
    if root.tag != "robot":
        raise RobotModelError(f"{source}: not a URDF (the root element is <{root.tag}>, "
                              "expected <robot>)")
    _check_links_and_joints(root, source)
    return root


def _check_links_and_joints(root: ET.Element, source: str) -> None:
    """Check what urdfdom would refuse with a message on the C++ stderr: unnamed or
    repeated links and joints, and joints whose parent or child link is not declared."""
    links: list[str] = []
    for k, link in enumerate(root.findall("link")):
        name = link.get("name")
        if not name:
            raise RobotModelError(f"{source}: <link> number {k + 1} has no name")
        if name in links:
            raise RobotModelError(f"{source}: link {name!r} is declared twice")
        links.append(name)
    known = set(links)
    joints: set[str] = set()
    parent_joint: dict[str, str] = {}
    for k, joint in enumerate(root.findall("joint")):
        name = joint.get("name")
        if not name:
            raise RobotModelError(f"{source}: <joint> number {k + 1} has no name")
        if name in joints:
            raise RobotModelError(f"{source}: joint {name!r} is declared twice")
        joints.add(name)
        for role in ("parent", "child"):
            element = joint.find(role)
            link = None if element is None else element.get("link")
            if not link:
                raise RobotModelError(f"{source}: joint {name!r} has no <{role} link=...>")
            if link not in known:
                close = difflib.get_close_matches(link, links, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise RobotModelError(
                    f"{source}: joint {name!r}: its {role} link {link!r} is not a <link> of "
                    f"the URDF (links: {', '.join(links)}){hint}")
        child = joint.find("child").get("link")
        if child in parent_joint:
            raise RobotModelError(f"{source}: link {child!r} is the child of two joints, "
                                  f"{parent_joint[child]!r} and {name!r}")
        parent_joint[child] = name


@contextlib.contextmanager
def _captured_native_stderr() -> Iterator[io.StringIO]:
    """Redirect file descriptor 2 (where urdfdom's C++ code prints) to a buffer.

    Yields a buffer filled with what was printed once the block ends. Falls back to
    capturing nothing when descriptor 2 cannot be duplicated.
    """
    buffer = io.StringIO()
    with _NATIVE_STDERR_LOCK:  # one redirection at a time, or threads restore it wrongly
        try:
            saved = os.dup(2)
        except OSError:
            yield buffer
            return
        try:
            with tempfile.TemporaryFile(mode="w+b") as tmp:
                with contextlib.suppress(OSError, ValueError):
                    sys.stderr.flush()
                os.dup2(tmp.fileno(), 2)
                try:
                    yield buffer
                finally:
                    os.dup2(saved, 2)
                    tmp.seek(0)
                    buffer.write(tmp.read().decode("utf-8", "replace"))
        finally:
            os.close(saved)


def _up_vector(text: str | None, source: str) -> NDArray[np.float64] | None:
    if text is None:
        return None
    try:
        up = np.array([float(v) for v in text.split()])
    except ValueError:
        up = np.zeros(0)
    if up.shape != (3,) or not np.linalg.norm(up) > 0:
        raise RobotModelError(f"{source}: <kinfw up={text!r}>: expected three numbers, "
                              "not all zero")
    return up / np.linalg.norm(up)


def _floats(element: ET.Element | None, key: str, n: int, default: list[float],
            where: str) -> list[float]:
    """``n`` numbers of attribute ``key`` of ``element`` (``default`` when absent)."""
    text = None if element is None else element.get(key)
    if text is None:
        return default
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != n or not all(np.isfinite(values)):
        raise RobotModelError(f"{where}: {key}={text!r}: expected {n} finite numbers")
    return values


def _parse_joints(root: ET.Element, source: str
                  ) -> tuple[tuple[JointInfo, ...], tuple[str, ...], str]:
    """Joints (document order), links and the root link of a checked ``<robot>`` element
    (:func:`_check_xml`). Origins follow URDF: ``rpy`` is fixed-axis roll, pitch, yaw,
    ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (:func:`pinocchio.rpy.rpyToMatrix`)."""
    joints = []
    for element in root.findall("joint"):
        name, kind = element.get("name"), element.get("type")
        where = f"{source}: joint {name!r}"
        if kind not in (*MOVABLE_TYPES, "fixed", "floating", "planar"):
            raise RobotModelError(f"{where}: unknown type {kind!r}")
        origin = element.find("origin")
        parent_T_child = np.eye(4)
        parent_T_child[:3, 3] = _floats(origin, "xyz", 3, [0.0, 0.0, 0.0], f"{where} <origin>")
        parent_T_child[:3, :3] = pin.rpy.rpyToMatrix(
            np.array(_floats(origin, "rpy", 3, [0.0, 0.0, 0.0], f"{where} <origin>")))
        axis = np.array(_floats(element.find("axis"), "xyz", 3, [1.0, 0.0, 0.0],
                                f"{where} <axis>"))
        norm = np.linalg.norm(axis)
        if kind in MOVABLE_TYPES and not norm > 0.0:
            raise RobotModelError(f"{source}: joint {name!r} has a zero axis")
        limit = element.find("limit")
        lower = _floats(limit, "lower", 1, [-np.inf], f"{where} <limit>")[0]
        upper = _floats(limit, "upper", 1, [np.inf], f"{where} <limit>")[0]
        if kind == "continuous":
            lower, upper = -np.inf, np.inf
        mimic = element.find("mimic")
        joints.append(JointInfo(
            name=name, type=kind, parent=element.find("parent").get("link"),
            child=element.find("child").get("link"), parent_T_child=parent_T_child,
            axis=axis / norm if norm > 0 else axis, lower=lower, upper=upper,
            mimic=None if mimic is None else mimic.get("joint")))
    links = tuple(link.get("name") for link in root.findall("link"))
    children = {j.child for j in joints}
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        raise RobotModelError(f"{source}: expected one root link, found {roots}")
    return tuple(joints), links, roots[0]


class Robot:
    """A URDF robot model for forward kinematics and topology queries.

    Build it with :func:`load_robot`. Attributes are read-only.

    Attributes
    ----------
    urdf_xml : str
        The URDF text this robot was built from (kept for exact export).
    source : str
        File path, or ``"<urdf string>"``.
    model : pinocchio.Model
        The Pinocchio model (all URDF joints, continuous ones with nq = 2).
    root_link : str
        Name of the URDF root link: the default measurement frame.
    joints : tuple of JointInfo
        Every URDF joint, in document order.
    joint_names : tuple of str
        Movable joints (revolute, continuous, prismatic) in URDF document order.
    link_names : tuple of str
        Every URDF link, in document order.
    default_frames, default_cameras : tuple of str
        The robot's own hint of what is usually measured, from an optional element
        ``<kinfw frames="left_plate right_plate" cameras="left_camera right_camera"/>``
        under ``<robot>`` (URDF parsers ignore unknown elements, as they do
        ``<gazebo>``); empty when absent. The command line uses them as defaults.
    default_up : ndarray, shape (3,), or None
        The root frame's "up" direction for viewers, from ``<kinfw up="x y z"/>``.
    """

    def __reduce__(self) -> tuple:
        # pickles as its URDF text (worker processes rebuild the Pinocchio model)
        return (type(self), (self.urdf_xml, self.source))

    def __init__(self, urdf_xml: str, source: str = "<urdf string>") -> None:
        self.urdf_xml = urdf_xml
        self.source = source
        element = _check_xml(urdf_xml, source)
        hint = element.find("kinfw")
        self.joints, self.link_names, self.root_link = _parse_joints(element, source)
        model, error = None, None
        with _captured_native_stderr() as native:
            try:
                model = pin.buildModelFromXML(urdf_xml)
            except Exception as exc:  # Pinocchio raises ValueError/RuntimeError
                error = exc
        said = " ".join(native.getvalue().split())
        if model is None:  # urdfdom's own lines say why; Pinocchio's only that it failed
            lines = [m.strip().removeprefix("Error:").strip()
                     for m in _URDFDOM_LINE.sub("\n", said).splitlines()]
            why = "; ".join(m for m in lines if m) or str(error)
            raise RobotModelError(f"{source}: Pinocchio cannot load this URDF ({why})")
        if said:
            logger.debug("%s: urdfdom printed: %s", source, said)
        self.model = model
        self._data = self.model.createData()
        self._joint_by_name = {j.name: j for j in self.joints}
        self._joint_by_child = {j.child: j for j in self.joints}
        self.joint_names = tuple(j.name for j in self.joints if j.is_movable)
        hint = {} if hint is None else hint.attrib
        self.default_frames = tuple(hint.get("frames", "").split())
        self.default_cameras = tuple(hint.get("cameras", "").split())
        self.default_up = _up_vector(hint.get("up"), source)
        for name in (*self.default_frames, *self.default_cameras):
            if not self.model.existFrame(name):
                raise RobotModelError(f"{source}: <kinfw> names frame {name!r}, which the "
                                      f"URDF does not have; links are {list(self.link_names)}")
        # For each movable joint: (first index in pin q, is it continuous (nq = 2)).
        self._q_slot = {}
        for name in self.joint_names:
            pj = self.model.joints[self.model.getJointId(name)]
            self._q_slot[name] = (pj.idx_q, pj.nq == 2)

    def __repr__(self) -> str:
        return (f"Robot({self.source!r}, root={self.root_link!r}, "
                f"joints={list(self.joint_names)})")

    # -- names -------------------------------------------------------------------------
    def joint(self, name: str) -> JointInfo:
        """The URDF joint called ``name``; raises :class:`UnknownFrameError` otherwise."""
        try:
            return self._joint_by_name[name]
        except KeyError:
            raise UnknownFrameError(
                f"{self.source}: no joint {name!r}; movable joints are {list(self.joint_names)}"
            ) from None

    def has_frame(self, name: str) -> bool:
        """True if ``name`` is a link or joint of the URDF."""
        return self.model.existFrame(name)

    def frame_id(self, name: str) -> int:
        """Pinocchio frame index of a link or joint called ``name``.

        Unlike ``model.getFrameId`` (which returns ``nframes`` for an unknown name), this
        raises :class:`UnknownFrameError` naming the frame and the links available.
        A link name is preferred over a joint of the same name.
        """
        if not self.model.existFrame(name):
            raise UnknownFrameError(
                f"{self.source}: no frame {name!r}; links are {list(self.link_names)}"
            )
        if self.model.existFrame(name, pin.FrameType.BODY):
            return self.model.getFrameId(name, pin.FrameType.BODY)
        return self.model.getFrameId(name)

    def _link_of_frame(self, name: str) -> str:
        self.frame_id(name)
        if name in self.link_names:
            return name
        return self.joint(name).child  # a joint frame sits at its child link's origin at q=0

    def path_joints(self, frame: str) -> tuple[JointInfo, ...]:
        """All URDF joints (fixed ones too) from the root link to ``frame``, root first."""
        link = self._link_of_frame(frame)
        out = []
        while link in self._joint_by_child:
            j = self._joint_by_child[link]
            out.append(j)
            link = j.parent
        return tuple(reversed(out))

    def movable_path(self, frame: str) -> tuple[str, ...]:
        """Names of the movable joints from the root to ``frame``, root first.

        Raises
        ------
        RobotModelError
            If a floating, planar or mimic joint lies on the path (it cannot be
            identified from joint readings), naming the joint.
        """
        names = []
        for j in self.path_joints(frame):
            if j.type in ("floating", "planar"):
                raise RobotModelError(
                    f"{self.source}: joint {j.name!r} on the path to {frame!r} is {j.type}; "
                    "only revolute, continuous, prismatic and fixed joints are supported there"
                )
            if j.mimic is not None:
                raise RobotModelError(
                    f"{self.source}: joint {j.name!r} on the path to {frame!r} mimics "
                    f"{j.mimic!r}; mimic joints are not supported on measured paths"
                )
            if j.is_movable:
                names.append(j.name)
        return tuple(names)

    def topology(self, frames: tuple[str, ...] | list[str]) -> Topology:
        """The tree of movable joints that carries ``frames`` (see :class:`Topology`)."""
        frames = tuple(frames)
        if not frames:
            raise RobotModelError("topology: give at least one end frame")
        paths = {f: self.movable_path(f) for f in frames}
        used = {n for p in paths.values() for n in p}
        parent_name: dict[str, str | None] = {}
        for p in paths.values():
            for k, n in enumerate(p):
                parent_name[n] = p[k - 1] if k else None
        # Stable topological order: URDF order, each joint after its parent.
        order: list[str] = []
        pending = [n for n in self.joint_names if n in used]
        while pending:
            for n in pending:
                if parent_name[n] is None or parent_name[n] in order:
                    order.append(n)
                    pending.remove(n)
                    break
        index = {n: i for i, n in enumerate(order)}
        return Topology(
            joint_names=tuple(order),
            revolute=tuple(self._joint_by_name[n].is_revolute for n in order),
            parent=tuple(-1 if parent_name[n] is None else index[parent_name[n]] for n in order),
            frames=frames,
            frame_parent=tuple(index[paths[f][-1]] if paths[f] else -1 for f in frames),
        )

    # -- configurations and kinematics --------------------------------------------------
    def joint_limits(self, joint_names: tuple[str, ...] | None = None
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Lower and upper limits (rad or m) of ``joint_names``; +-inf where unbounded."""
        names = self.joint_names if joint_names is None else joint_names
        js = [self.joint(n) for n in names]
        return np.array([j.lower for j in js]), np.array([j.upper for j in js])

    def pin_configurations(self, qs: ArrayLike, joint_names: tuple[str, ...] | None = None
                           ) -> NDArray[np.float64]:
        """Pinocchio configuration vectors (n, nq) for URDF joint values ``qs`` (n, k).

        Unlisted joints stay at Pinocchio's neutral configuration (value zero);
        continuous joints get (cos q, sin q).
        """
        names = self.joint_names if joint_names is None else tuple(joint_names)
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        if qs.shape[1] != len(names):
            raise ValueError(f"qs: expected {len(names)} columns ({list(names)}), "
                             f"got shape {qs.shape}")
        out = np.tile(pin.neutral(self.model), (qs.shape[0], 1))
        for col, name in enumerate(names):
            if name not in self._q_slot:
                self.joint(name)  # raises for an unknown name
                raise RobotModelError(f"{self.source}: joint {name!r} is not movable")
            i, continuous = self._q_slot[name]
            if continuous:
                out[:, i], out[:, i + 1] = np.cos(qs[:, col]), np.sin(qs[:, col])
            else:
                out[:, i] = qs[:, col]
        return out

    def frame_poses(self, qs: ArrayLike, frame: str,
                    joint_names: tuple[str, ...] | None = None) -> NDArray[np.float64]:
        """Pose of ``frame`` in the root link, ``root_T_frame``, by Pinocchio FK.

        Batch in, batch out: one configuration of shape (k,) gives one pose, a batch of
        shape (n, k) gives n poses, with the batch axis kept for n = 1.

        Parameters
        ----------
        qs : array_like, shape (k,) or (n, k)
            URDF joint values (rad, m) in the order of ``joint_names``: one
            configuration, or a batch of n.
        frame : str
            Link or joint name.
        joint_names : sequence of str, optional
            Column order of ``qs``; default :attr:`joint_names`.

        Returns
        -------
        ndarray, shape (4, 4) for qs (k,), (n, 4, 4) for qs (n, k)
            ``root_T_frame``, metres.

        Raises
        ------
        ValueError
            ``qs`` neither (k,) nor (n, k).
        UnknownFrameError
            ``frame`` is neither a link nor a joint of the robot.
        """
        qs = np.asarray(qs, dtype=float)
        if qs.ndim not in (1, 2):
            names = self.joint_names if joint_names is None else tuple(joint_names)
            raise ValueError(f"qs: expected shape ({len(names)},) or (n, {len(names)}) "
                             f"(columns {list(names)}), got {qs.shape}")
        fid = self.frame_id(frame)
        configurations = self.pin_configurations(qs, joint_names)  # (n, nq); n = 1 for (k,)
        out = np.empty((len(configurations), 4, 4))
        for k, q in enumerate(configurations):
            pin.forwardKinematics(self.model, self._data, q)
            out[k] = pin.updateFramePlacement(self.model, self._data, fid).homogeneous
        return out[0] if qs.ndim == 1 else out


def builtin_head_urdf() -> Path:
    """Path of the built-in IIS-head URDF: ``urdf/iis_head.urdf`` of the source tree, or
    the copy a regular (non-editable) install puts in ``kinfw/urdf/``."""
    here = Path(__file__).resolve().parent
    for candidate in (here.parent / "urdf" / "iis_head.urdf", here / "urdf" / "iis_head.urdf"):
        if candidate.is_file():
            return candidate
    raise OSError("the built-in IIS-head URDF is missing from this installation")


def load_robot(urdf: str | Path) -> Robot:
    """Load a URDF from a file path or an XML string.

    Meshes are not loaded (a URDF whose meshes are missing loads fine).

    Raises
    ------
    RobotModelError
        Naming the file when it cannot be read or parsed.
    """
    xml, source = _as_xml_text(urdf)
    return Robot(xml, source)
