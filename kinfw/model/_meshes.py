"""Where a URDF's meshes are: ``package://``, ``file://`` and relative paths resolved.

Drawing a robot (:mod:`kinfw.view`) needs its visual meshes and checking self-collision
(:func:`kinfw.identification.planning.collision_free`) its collision meshes; both
resolve the URDF's mesh file names the same way: ``package://PKG/rest`` under each
package directory given (as ``DIR/PKG/rest`` or ``DIR/rest``), then the directories of
``ROS_PACKAGE_PATH``, then up the URDF file's own tree (``.../PKG/urdf/robot.urdf``);
relative paths from the URDF file's directory.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from kinfw.model._robot import Robot


@dataclass(frozen=True, slots=True)
class MissingMesh:
    """A mesh a URDF names that is not found.

    Attributes
    ----------
    link : str
        The link whose ``<visual>`` or ``<collision>`` names it.
    filename : str
        The file name as the URDF writes it.
    """

    link: str
    filename: str


def mesh_dirs(package_dirs: Sequence[str | Path]) -> tuple[Path, ...]:
    """Where ``package://`` meshes are looked for: ``package_dirs``, then the
    directories of ``ROS_PACKAGE_PATH``."""
    ros = os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)
    return tuple(Path(d) for d in package_dirs) + tuple(Path(d) for d in ros if d)


def _resolve_mesh(
    filename: str, base_dir: Path | None, package_dirs: Sequence[Path]
) -> Path | None:
    """The existing file a URDF mesh ``filename`` names, or None."""
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://") :].partition("/")
        candidates = []
        for d in package_dirs:
            candidates += [d / package / rest, d / rest]
        if base_dir is not None:  # .../<package>/urdf/robot.urdf: look up the tree
            candidates += [a / rest for a in (base_dir, *base_dir.parents) if a.name == package]
    elif filename.startswith("file://"):
        candidates = [Path(filename[len("file://") :])]
    else:
        path = Path(filename)
        candidates = [path if path.is_absolute() or base_dir is None else base_dir / path]
    return next((c.resolve() for c in candidates if c.is_file()), None)


def resolve_meshes(
    robot: Robot, package_dirs: Sequence[str | Path], element: str
) -> tuple[str, tuple[MissingMesh, ...]]:
    """The robot's URDF with the meshes of every ``<element>`` (``"visual"`` or
    ``"collision"``) as absolute paths, the elements whose mesh is not found removed;
    and those missing meshes.

    Parameters
    ----------
    robot : Robot
    package_dirs : sequence of path
        Where ``package://`` meshes live, before ``ROS_PACKAGE_PATH`` (:func:`mesh_dirs`).
    element : {"visual", "collision"}

    Returns
    -------
    urdf_xml : str
        The URDF text (unchanged when it names no mesh).
    missing : tuple of MissingMesh
    """
    if element not in ("visual", "collision"):
        raise ValueError(f"element: expected 'visual' or 'collision', got {element!r}")
    root = ET.fromstring(robot.urdf_xml)
    source = Path(robot.source)
    base_dir = source.resolve().parent if source.is_file() else None
    dirs = mesh_dirs(package_dirs)
    changed, missing = False, []
    for link in root.iter("link"):
        for item in list(link.findall(element)):
            mesh = item.find("geometry/mesh")
            if mesh is None:
                continue
            filename = mesh.get("filename", "")
            found = _resolve_mesh(filename, base_dir, dirs)
            if found is None:
                missing.append(MissingMesh(link.get("name", ""), filename))
                link.remove(item)
            else:
                mesh.set("filename", str(found))
            changed = True
    xml = ET.tostring(root, encoding="unicode") if changed else robot.urdf_xml
    return xml, tuple(missing)
