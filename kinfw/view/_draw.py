"""Drawing primitives of the Meshcat scenes (:mod:`kinfw.view._scene`, :mod:`kinfw.view._gaze`,
:mod:`kinfw.view._reach`): triads and thin cylinders drawn over everything (WebGL draws
lines one pixel wide whatever their ``linewidth``), and small transforms. meshcat is
imported inside the functions."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.model import Robot

if TYPE_CHECKING:
    import meshcat

TRIAD_LENGTH = 0.03
"""Length of a measured pose's triad, metres (a fixed target's is twice as long)."""
STICK_RADIUS = 0.0012
"""Radius of the cylinders that draw triad axes, metres."""
OVERLAY_RENDER_ORDER = 10
"""three.js renderOrder of triads and residual lines (drawn after the robots)."""


def rgb_int(rgb: Sequence[float]) -> int:
    """``0xRRGGBB`` of an RGB triple in [0, 1] (clipped)."""
    r, g, b = (round(255 * min(max(float(c), 0.0), 1.0)) for c in rgb[:3])
    return (r << 16) | (g << 8) | b


def overlay_material(rgb: Sequence[float]) -> Any:
    """Unlit colour drawn over everything (no depth test, rendered last), so that
    triads inside a link's visual and residuals behind the ghost stay visible."""
    import meshcat.geometry as mg

    return mg.MeshBasicMaterial(
        color=rgb_int(rgb), transparent=True, opacity=1.0, depthTest=False, depthWrite=False
    )


def overlay_object(geometry: Any, rgb: Sequence[float]) -> Any:
    """A meshcat mesh of ``geometry`` in :func:`overlay_material`, rendered after the
    robots (:data:`OVERLAY_RENDER_ORDER`)."""
    import meshcat.geometry as mg

    class OverlayMesh(mg.Mesh):
        def lower(self) -> dict[str, Any]:
            data = super().lower()
            data["object"]["renderOrder"] = OVERLAY_RENDER_ORDER
            return data

    return OverlayMesh(geometry, overlay_material(rgb))


def rotation_y_onto(direction: NDArray[np.float64]) -> NDArray[np.float64]:
    """A rotation whose y axis (meshcat's cylinder axis) is the unit ``direction``."""
    norm = np.linalg.norm(direction)
    if norm == 0.0:
        return np.eye(3)
    y = direction / norm
    x = np.cross(y, np.eye(3)[np.argmin(np.abs(y))])
    x /= np.linalg.norm(x)
    return np.column_stack([x, y, np.cross(x, y)])


def stick(
    node: meshcat.Visualizer,
    origin: ArrayLike,
    vector: ArrayLike,
    radius: float,
    rgb: Sequence[float],
) -> None:
    """A thin cylinder from ``origin`` to ``origin + vector`` (coordinates of the node's
    parent). ``node`` gets the transform ``[R | origin]``, R taking y onto ``vector``;
    its child ``stick`` holds the cylinder of height ``|vector|``."""
    import meshcat.geometry as mg

    vector = np.asarray(vector, dtype=float)
    length = float(np.linalg.norm(vector))
    parent_T_node = np.eye(4)
    parent_T_node[:3, :3] = rotation_y_onto(vector)
    parent_T_node[:3, 3] = origin
    node.set_transform(parent_T_node)
    node["stick"].set_object(overlay_object(mg.Cylinder(length, radius), rgb))
    node["stick"].set_transform(transform_from_translation([0.0, 0.5 * length, 0.0]))


def triad(
    node: meshcat.Visualizer,
    parent_T_frame: NDArray[np.float64],
    *,
    length: float = TRIAD_LENGTH,
    radius: float = STICK_RADIUS,
    origin_rgb: Sequence[float] | None = None,
) -> None:
    """Axes x (red), y (green), z (blue) of a frame: children ``x``, ``y``, ``z`` (and
    ``origin``, a small ball, when ``origin_rgb`` is given)."""
    import meshcat.geometry as mg

    node.set_transform(parent_T_frame)
    for axis, name in enumerate("xyz"):
        stick(node[name], np.zeros(3), length * np.eye(3)[axis], radius, np.eye(3)[axis])
    if origin_rgb is not None:
        node["origin"].set_object(overlay_object(mg.Sphere(2.0 * radius), origin_rgb))


def transform_from_translation(p: ArrayLike) -> NDArray[np.float64]:
    """``[I | p]``, shape (4, 4)."""
    T = np.eye(4)
    T[:3, 3] = p
    return T


def up_direction(robot: Robot, up: ArrayLike | None = None) -> NDArray[np.float64]:
    """The root frame's "up" for viewers: ``up`` when given (checked), else the URDF's
    ``<kinfw up>`` hint, else z."""
    if up is None:
        return np.array([0.0, 0.0, 1.0]) if robot.default_up is None else robot.default_up
    up = np.asarray(up, dtype=float)
    if up.shape != (3,) or not np.linalg.norm(up) > 0:
        raise ValueError(f"up: expected a non-zero 3-vector, got {up!r}")
    return up
