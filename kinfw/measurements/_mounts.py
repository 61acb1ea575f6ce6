"""Frames the data name that the URDF lacks: a camera (or a marker body) mounted on a link.

A measurement file's top-level ``"mounts"`` section says, per such frame, which existing
link it is rigidly mounted on (and optionally a start pose); :func:`mounted_robot` adds
each as a new link on a new fixed joint, whose origin (the mount) the calibration then
estimates like any other fixed joint on a measured path and the export writes. The
original URDF's tags are kept as they are (:func:`kinfw.urdf.add_fixed_links`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import (
    check_transform,
    transform_from_xyz_quat_xyzw,
    xyz_quat_xyzw_from_transform,
)
from kinfw.observations import DatasetError, ObservationReader, frozen_array, read_quaternion

if TYPE_CHECKING:
    from kinfw.model import Robot


@dataclass(frozen=True, slots=True)
class Mount:
    """A frame the URDF lacks, rigidly mounted on one of its links.

    Attributes
    ----------
    parent : str
        The URDF link the frame is fixed to (e.g. ``"tool0"``).
    parent_T_frame : ndarray, shape (4, 4)
        Start value of the mount: the frame's pose in ``parent``, metres (identity when
        unknown; the calibration's hand-eye stage starts from the data where it can).
    """

    parent: str
    parent_T_frame: NDArray[np.float64] = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        T = check_transform(self.parent_T_frame, name=f"Mount({self.parent!r}).parent_T_frame")
        object.__setattr__(self, "parent_T_frame", frozen_array(T, np.float64))

    def same_as(self, other: Mount) -> bool:
        """True when both mount the frame on one parent with one start pose."""
        return self.parent == other.parent and bool(
            np.array_equal(self.parent_T_frame, other.parent_T_frame)
        )


def mounts_from_dict(p: ObservationReader, section: Any) -> dict[str, Mount]:
    """The ``"mounts"`` section of a file: ``{NAME: {"parent": LINK, "xyz": ...,
    "quat_xyzw": ...}}`` (``xyz`` in the file's length unit, both optional)."""
    out = {}
    for name, raw in p.obj(section, "mounts").items():
        at = f"mounts.{name}"
        entry = p.obj(raw, at)
        parent = p.get(entry, "parent", at, "the URDF link the frame is mounted on")
        parent = p.string(parent, f"{at}.parent")
        xyz = [0.0, 0.0, 0.0]
        if entry.get("xyz") is not None:
            xyz = p.lengths(p.numbers(entry["xyz"], 3, f"{at}.xyz"))
        quat = [0.0, 0.0, 0.0, 1.0]
        if entry.get("quat_xyzw") is not None:
            quat = read_quaternion(p, entry, at)
        quat = np.asarray(quat) / np.linalg.norm(quat)
        out[name] = Mount(parent, transform_from_xyz_quat_xyzw(xyz, quat))
    return out


def mounts_to_dict(mounts: Mapping[str, Mount]) -> dict[str, Any]:
    """The ``"mounts"`` section (SI), the start pose written only when it is not identity."""
    out = {}
    for name, mount in mounts.items():
        entry: dict[str, Any] = {"parent": mount.parent}
        if not np.array_equal(mount.parent_T_frame, np.eye(4)):
            xyz, quat = xyz_quat_xyzw_from_transform(mount.parent_T_frame)
            entry |= {"xyz": xyz.tolist(), "quat_xyzw": quat.tolist()}
        out[name] = entry
    return out


def mounted_robot(robot: Robot, mounts: Mapping[str, Mount], source: str = "<memory>") -> Robot:
    """The robot with each mounted frame it lacks added as a link on a fixed joint.

    Parameters
    ----------
    robot : Robot
        The URDF robot.
    mounts : mapping of str to Mount
        Frames by name (``Measurements.mounts``, or the CLI's ``--mount NAME:PARENT``).
    source : str
        Where the mounts come from, for messages.

    Returns
    -------
    Robot
        ``robot`` itself when it has every frame already (e.g. a calibrated URDF that
        was exported with them); else a robot whose URDF text is ``robot.urdf_xml`` with
        ``<link name="NAME"/>`` and ``<joint name="NAME_joint" type="fixed">`` (parent
        ``mount.parent``, origin ``mount.parent_T_frame``) appended per missing frame.

    Raises
    ------
    DatasetError
        A frame the URDF has on another parent than the mount says, or a parent that is
        not a link of the URDF (naming both and the links).
    """
    from kinfw.model import Robot
    from kinfw.urdf import ExportError, add_fixed_links

    new = {}
    for name, mount in mounts.items():
        if robot.has_frame(name):
            parent = next((j.parent for j in robot.joints if j.child == name), None)
            if parent != mount.parent:
                raise DatasetError(
                    f"{source}: mounts.{name}: {name!r} is mounted on {mount.parent!r}, but "
                    f"the URDF {robot.source} has it on {parent!r}; drop the mount or "
                    "rename the frame"
                )
            continue
        new[name] = (mount.parent, mount.parent_T_frame)
    if not new:
        return robot
    try:
        xml = add_fixed_links(robot.urdf_xml, new)
    except ExportError as exc:
        raise DatasetError(f"{source}: mounts: {exc}") from None
    return Robot(xml, robot.source, spec=robot.spec)
