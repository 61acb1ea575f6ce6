"""A URDF robot: Pinocchio for forward kinematics, the standard library's XML parser for
the URDF's structure.

:class:`Robot` is immutable: it keeps the URDF text it was built from, so a calibrated
robot is a new ``Robot`` built from new text (Pinocchio cannot change a joint's axis or
type in place, and rebuilding takes well under a millisecond).

Joint values always follow the URDF: revolute and continuous joints in radians,
prismatic joints in metres, in the order of a ``joint_names`` sequence given by the
caller (by default :attr:`Robot.joint_names`, the movable joints in URDF document order).
Joints a caller does not list are held at zero.

The URDF text is read and checked in :mod:`kinfw.model` (where :class:`JointInfo` and
:class:`RobotModelError` are defined; this module exports them).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from kinfw import progress
from kinfw.model._model_spec import ModelSpec
from kinfw.model._urdf_read import (
    JointInfo,
    RobotModelError,
    check_urdf_xml,
    parse_joints,
    pinocchio_model,
    up_vector,
    xml_text,
)


class UnknownFrameError(RobotModelError, KeyError):
    """A frame (link or joint) name that the URDF does not have."""

    def __str__(self) -> str:  # KeyError would print the message with quotes
        return str(self.args[0])


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


def _hints(element: ET.Element, source: str) -> dict[str, str]:
    """The attributes of the ``<kinfw>`` elements under ``<robot>``, merged (one element
    or several); an attribute given twice is refused."""
    out: dict[str, str] = {}
    for hint in element.findall("kinfw"):
        for key, value in hint.attrib.items():
            if key in out:
                raise RobotModelError(f"{source}: <kinfw {key}> is given twice")
            out[key] = value
    return out


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
    exact_joints : tuple of str
        Movable joints whose kinematics is exact, from ``<kinfw exact="j1 j2"/>``: their
        CPC parameters and zero offsets are never estimated, whatever the parameter set
        (a pose chain's joints, :func:`kinfw.model.pose_chain_urdf`, reproduce logged
        poses and carry no kinematic error). Every movable joint above an exact one must be
        exact too (they are a path's first joints), so their URDF origins and axes stay
        as written. Empty when absent.
    spec : ModelSpec
        What the URDF cannot hold (joint compliance, gear scales, couplings), beside it:
        empty for a URDF alone; a calibration's estimates for a calibrated robot read
        with its sidecar. Every estimation problem built on the robot includes its
        blocks (fixed with ``parameters="none"``), so predictions take the joint values
        after their hooks (:meth:`kinfw.model.ModelSpec.joint_values`).
    placeholder_joints : tuple of str
        Joints whose ``<origin>`` is a placeholder, not a nominal, from ``<kinfw
        placeholder="camera_joint"/>`` (the camera mount at identity that ``kinfw
        pose-chain`` writes for the calibration to estimate): the plausibility guard does
        not bound their change. Empty when absent.
    """

    def __reduce__(self) -> tuple:
        # pickles as its URDF text (worker processes rebuild the Pinocchio model)
        return (type(self), (self.urdf_xml, self.source, self.spec))

    def __init__(
        self, urdf_xml: str, source: str = "<urdf string>", spec: ModelSpec | None = None
    ) -> None:
        self.urdf_xml = urdf_xml
        self.source = source
        self.spec = ModelSpec() if spec is None else spec
        element = check_urdf_xml(urdf_xml, source)
        hint = _hints(element, source)
        self.joints, self.link_names, self.root_link = parse_joints(element, source)
        self.model = pinocchio_model(urdf_xml, source)
        self._data = self.model.createData()
        self._joint_by_name = {j.name: j for j in self.joints}
        self._joint_by_child = {j.child: j for j in self.joints}
        self.joint_names = tuple(j.name for j in self.joints if j.is_movable)
        self.default_frames = tuple(hint.get("frames", "").split())
        self.default_cameras = tuple(hint.get("cameras", "").split())
        self.default_up = up_vector(hint.get("up"), source)
        self.exact_joints = tuple(hint.get("exact", "").split())
        self.placeholder_joints = tuple(hint.get("placeholder", "").split())
        unknown = [n for n in self.placeholder_joints if n not in self._joint_by_name]
        if unknown:
            raise RobotModelError(
                f"{source}: <kinfw placeholder> names {unknown}, which are not joints of the "
                f"URDF; joints are {[j.name for j in self.joints]}"
            )
        not_movable = [n for n in self.exact_joints if n not in self.joint_names]
        if not_movable:
            raise RobotModelError(
                f"{source}: <kinfw exact> names {not_movable}, which are not movable joints "
                f"of the URDF; movable joints are {list(self.joint_names)}"
            )
        for name in self.exact_joints:  # the first joints of their paths (CPC's frames)
            above = [j.name for j in self.path_joints(self.joint(name).child) if j.is_movable]
            inexact = [j for j in above if j not in self.exact_joints]
            if inexact:
                raise RobotModelError(
                    f"{source}: <kinfw exact> names {name!r} but not {inexact}, above it: "
                    "exact joints must be the first movable joints of their paths (every "
                    "joint above an exact one exact too)"
                )
        for name in (*self.default_frames, *self.default_cameras):
            if not self.model.existFrame(name):
                raise RobotModelError(
                    f"{source}: <kinfw> names frame {name!r}, which the "
                    f"URDF does not have; links are {list(self.link_names)}"
                )
        # For each movable joint: (first index in pin q, is it continuous (nq = 2)).
        self._q_slot = {}
        for name in self.joint_names:
            pj = self.model.joints[self.model.getJointId(name)]
            self._q_slot[name] = (pj.idx_q, pj.nq == 2)

    def __repr__(self) -> str:
        spec = f", spec={list(self.spec.texts)}" if self.spec else ""
        return (
            f"Robot({self.source!r}, root={self.root_link!r}, joints={list(self.joint_names)}"
            f"{spec})"
        )

    def with_spec(self, spec: ModelSpec) -> Robot:
        """The same URDF with the robot blocks ``spec`` beside it (a calibration's
        compliance, gear scales, couplings: :class:`kinfw.model.ModelSpec`); the
        Pinocchio model is shared."""
        import copy

        out = copy.copy(self)
        out.spec = spec
        return out

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
    def joint_limits(
        self, joint_names: tuple[str, ...] | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Lower and upper limits (rad or m) of ``joint_names``; +-inf where unbounded."""
        names = self.joint_names if joint_names is None else joint_names
        js = [self.joint(n) for n in names]
        return np.array([j.lower for j in js]), np.array([j.upper for j in js])

    def pin_configurations(
        self, qs: ArrayLike, joint_names: tuple[str, ...] | None = None
    ) -> NDArray[np.float64]:
        """Pinocchio configuration vectors (n, nq) for URDF joint values ``qs`` (n, k).

        Unlisted joints stay at Pinocchio's neutral configuration (value zero);
        continuous joints get (cos q, sin q).
        """
        names = self.joint_names if joint_names is None else tuple(joint_names)
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        if qs.shape[1] != len(names):
            raise ValueError(
                f"qs: expected {len(names)} columns ({list(names)}), got shape {qs.shape}"
            )
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

    def velocity_index(self, name: str) -> int:
        """Index of movable joint ``name`` in Pinocchio's velocity vector (Jacobian column)."""
        if name not in self._q_slot:
            self.joint(name)  # raises for an unknown name
            raise RobotModelError(f"{self.source}: joint {name!r} is not movable")
        return int(self.model.joints[self.model.getJointId(name)].idx_v)

    def frame_poses(
        self, qs: ArrayLike, frame: str, joint_names: tuple[str, ...] | None = None
    ) -> NDArray[np.float64]:
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
            raise ValueError(
                f"qs: expected shape ({len(names)},) or (n, {len(names)}) "
                f"(columns {list(names)}), got {qs.shape}"
            )
        fid = self.frame_id(frame)
        configurations = self.pin_configurations(qs, joint_names)  # (n, nq); n = 1 for (k,)
        out = np.empty((len(configurations), 4, 4))
        for k, q in enumerate(configurations):
            pin.forwardKinematics(self.model, self._data, q)
            out[k] = pin.updateFramePlacement(self.model, self._data, fid).homogeneous
        return out[0] if qs.ndim == 1 else out


def builtin_head_urdf() -> Path:
    """Path of the built-in IIS-head URDF: ``robots/iis_head.urdf`` of the source tree, or
    the copy a regular (non-editable) install puts in ``kinfw/robots/``."""
    package = Path(__file__).resolve().parents[1]  # kinfw/
    for candidate in (
        package.parent / "robots" / "iis_head.urdf",
        package / "robots" / "iis_head.urdf",
    ):
        if candidate.is_file():
            return candidate
    raise OSError("the built-in IIS-head URDF is missing from this installation")


def load_robot(urdf: str | Path, *, xacro_args: Mapping[str, str] | None = None) -> Robot:
    """Load a URDF from a file path or an XML string (a ``robot_description``).

    Meshes are not loaded (a URDF whose meshes are missing loads fine). A xacro file
    (``.xacro``, or any document declaring the xacro namespace) is expanded with the
    ``xacro`` package (the ``ros`` extra) and ``xacro_args`` (``{"name": "value"}``, as
    ``name:=value`` on xacro's command line); the robot's URDF is the expanded text.

    Raises
    ------
    RobotModelError
        Naming the file when it cannot be read, expanded or parsed.
    """
    xml, source = xml_text(urdf, xacro_args)
    progress.stage(f"loading the URDF {source}")
    return Robot(xml, source)


def check_robot(robot: object, name: str) -> Robot:
    """``robot`` itself when it is a :class:`Robot`; else a TypeError naming the
    argument ``name`` (a path or URDF text: load it with :func:`load_robot`)."""
    if isinstance(robot, Robot):
        return robot
    raise TypeError(
        f"{name}: expected a Robot, got {type(robot).__name__} {robot!r:.60}"
        + (" (load it with kinfw.load_robot)" if isinstance(robot, str | Path) else "")
    )
