"""A reach in meshcat: the robot at the answer, the target and the frame that reaches it.

:func:`reach_scene` draws a :class:`kinfw.control.Reach` (``kinfw reach --html``):

- the robot at :attr:`~kinfw.control.Reach.q` (Pinocchio's ``MeshcatVisualizer``,
  :func:`kinfw.view._robot.draw_robot`), solid;
- the target: a pose as a triad (x red, y green, z blue) with a ball at its origin, a
  point as a sphere;
- the reaching frame at the answer, a shorter, thinner triad with a smaller ball at its
  origin, green when the target is reached, orange otherwise;
- when not reached, a thin grey line from the frame's origin to the target's.

Paths below ``/meshcat/kinfw`` (root-link coordinates; the node's transform frames the
robot and the target, as :func:`kinfw.view.scene` does)::

    robot/visuals/<link>_<i>       the robot at the answer
    reach/target                   a pose: its triad (node transform root_T_target,
                                   children x, y, z, origin); a point: a sphere (node
                                   transform [I | point])
    reach/frame                    triad of the frame at the answer (root_T_frame)
    reach/to_target                (not reached) the line: a node [R | frame origin] whose
                                   child ``stick`` is a cylinder along the node's y axis

:func:`write_reach_html` writes the scene as one self-contained HTML file. meshcat is
imported inside the functions. (A module of its own beside :mod:`kinfw.view`, not an
extension of it: each draws one kind of :mod:`kinfw.control` answer, and the two share
only the primitives of :mod:`kinfw.view`.)
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from kinfw.model import Robot
from kinfw.view._draw import STICK_RADIUS, overlay_object, stick, transform_from_translation, triad
from kinfw.view._robot import frame_scene, robot_scene
from kinfw.view._scene import SOLID_RGBA

if TYPE_CHECKING:
    import meshcat

    from kinfw.control import Reach

TARGET_TRIAD_LENGTH = 0.1
"""Length of the target pose's triad axes, metres."""
FRAME_TRIAD_LENGTH = 0.07
"""Length of the reaching frame's triad axes, metres (shorter: the target shows around it)."""
TARGET_RGB = (0.85, 0.1, 0.1)
"""Colour of the target point's sphere and of the target pose's origin ball."""
TARGET_POINT_RADIUS = 0.015
"""Radius of a target point's sphere, metres."""
REACHED_RGB = (0.0, 0.7, 0.2)
"""Colour of the frame's origin ball when the target is reached."""
MISSED_RGB = (1.0, 0.55, 0.0)
"""Colour of the frame's origin ball when the target is not reached."""
TO_TARGET_RGB = (0.45, 0.45, 0.5)
"""Colour of the line from the frame's origin to a target it misses."""
TO_TARGET_RADIUS = 0.0008
"""Radius of that line, metres."""


def reach_scene(
    robot: Robot,
    result: Reach,
    *,
    window: object = None,
    up: ArrayLike | None = None,
    package_dirs: Sequence[str | Path] = (),
) -> meshcat.Visualizer:
    """Draw a reach (module docstring).

    Parameters
    ----------
    robot : Robot
        The model the reach was solved with.
    result : Reach
        From :func:`kinfw.control.reach`; a point target when its
        ``rotation_error_rad`` is None.
    window : object, optional
        A meshcat window, e.g. :class:`kinfw.view.OfflineWindow`; None starts a meshcat
        server on 127.0.0.1.
    up : array_like, shape (3,), optional
        Direction shown upwards, root frame; default the URDF's ``<kinfw up>`` hint, else z.
    package_dirs : sequence of path
        Folders searched for ``package://`` meshes (missing ones are skipped, logged).

    Returns
    -------
    meshcat.Visualizer
    """
    import meshcat.geometry as mg

    vis, root, up, robot_ps = robot_scene(
        robot,
        result.q,
        result.joint_names,
        SOLID_RGBA,
        window=window,
        up=up,
        package_dirs=package_dirs,
    )

    root_p_target = result.root_T_target[:3, 3]
    if result.rotation_error_rad is None:  # a point: orientation free
        root["reach/target"].set_object(overlay_object(mg.Sphere(TARGET_POINT_RADIUS), TARGET_RGB))
        root["reach/target"].set_transform(transform_from_translation(root_p_target))
    else:
        triad(
            root["reach/target"],
            result.root_T_target,
            length=TARGET_TRIAD_LENGTH,
            radius=1.5 * STICK_RADIUS,
            origin_rgb=TARGET_RGB,
        )
    root_T_frame = robot.frame_poses(result.q, result.frame, result.joint_names)
    triad(
        root["reach/frame"],
        root_T_frame,
        length=FRAME_TRIAD_LENGTH,
        radius=STICK_RADIUS,
        origin_rgb=REACHED_RGB if result.reached else MISSED_RGB,
    )
    if not result.reached:
        toward = root_p_target - root_T_frame[:3, 3]
        stick(root["reach/to_target"], root_T_frame[:3, 3], toward, TO_TARGET_RADIUS, TO_TARGET_RGB)

    focus = np.concatenate([robot_ps, root_T_frame[None, :3, 3], root_p_target[None]])
    frame_scene(vis, root, focus, up)
    return vis


def write_reach_html(robot: Robot, result: Reach, path: str | Path, **options: object) -> Path:
    """:func:`reach_scene` as one self-contained HTML file, written atomically
    (:func:`kinfw.view.write_html`); ``options`` go to :func:`reach_scene`."""
    from kinfw.view._html import OfflineWindow, write_html

    return write_html(reach_scene(robot, result, window=OfflineWindow(), **options), path)
