"""A fixation in meshcat: the robot at the solution, each camera's gaze ray and the point.

:func:`gaze_scene` draws a :class:`kinfw.control.Fixation` (``kinfw gaze --html``):

- the robot at :attr:`~kinfw.control.Fixation.q` (Pinocchio's ``MeshcatVisualizer``,
  :func:`kinfw.view._robot.draw_robot`), solid;
- per camera, its frame (a triad) and its aimed ray: from the optical centre along the
  ray the camera should see the point on (the optical axis, or a pixel's ray), as long as
  the distance from the camera to the point, green when every camera fixates the point,
  orange otherwise; when the point is missed, a thin grey line from the optical centre to
  the point shows by how much;
- the point, a sphere.

Paths below ``/meshcat/kinfw`` (root-link coordinates; the node's transform frames the
robot, the cameras and the point, as :func:`kinfw.view.scene` does)::

    robot/visuals/<link>_<i>       the robot at the solution
    cameras/<camera>               triad of a camera frame
    gaze/rays/<camera>             the aimed ray: a node [R | optical centre] whose child
                                   ``stick`` is a cylinder along the node's y axis
    gaze/to_point/<camera>         (not fixated) the line from the camera to the point
    gaze/point                     the point (a sphere)

:func:`write_gaze_html` writes the scene as one self-contained HTML file. meshcat is
imported inside the functions.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.model import Robot
from kinfw.observations import node_name
from kinfw.view._cameras import CAMERA_TRIAD_LENGTH
from kinfw.view._draw import (
    STICK_RADIUS,
    overlay_object,
    stick,
    transform_from_translation,
    triad,
)
from kinfw.view._robot import frame_scene, robot_scene
from kinfw.view._scene import SOLID_RGBA

if TYPE_CHECKING:
    import meshcat

    from kinfw.control import Fixation

RAY_RADIUS = 0.002
"""Radius of a gaze ray's cylinder, metres."""
FIXATED_RGB = (0.0, 0.7, 0.2)
"""Colour of the rays when every camera fixates the point."""
MISSED_RGB = (1.0, 0.55, 0.0)
"""Colour of the rays of a closest achievable fixation (not fixated)."""
TO_POINT_RGB = (0.45, 0.45, 0.5)
"""Colour of the line from a camera to a point it misses."""
POINT_RADIUS = 0.015
"""Radius of the fixated point's sphere, metres."""
POINT_RGB = (0.85, 0.1, 0.1)
"""Colour of the fixated point."""


def gaze_rays(robot: Robot, fixation: Fixation) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Where each camera's aimed ray starts and where it ends, in the root frame.

    Returns
    -------
    root_p_centres : ndarray, shape (n_cameras, 3)
        The optical centres at :attr:`Fixation.q` (m).
    root_p_ends : ndarray, shape (n_cameras, 3)
        The centre plus the aimed ray (root frame) times the distance from the centre to
        the point (m): the point itself for a fixating camera.
    """
    root_T_cameras = np.array(
        [robot.frame_poses(fixation.q, c, fixation.joint_names) for c in fixation.cameras]
    ).reshape(-1, 4, 4)
    centres = root_T_cameras[:, :3, 3]
    directions = np.einsum("nij,nj->ni", root_T_cameras[:, :3, :3], fixation.camera_rays)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    distances = np.linalg.norm(fixation.root_p_point - centres, axis=1)
    return centres, centres + distances[:, None] * directions


def gaze_scene(
    robot: Robot,
    fixation: Fixation,
    *,
    window: object = None,
    up: ArrayLike | None = None,
    package_dirs: Sequence[str | Path] = (),
) -> meshcat.Visualizer:
    """Draw a fixation (module docstring).

    Parameters
    ----------
    robot : Robot
        The model the fixation was solved with.
    fixation : Fixation
        From :func:`kinfw.control.fixate` (or :class:`GazeSolver`).
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
        fixation.q,
        fixation.joint_names,
        SOLID_RGBA,
        window=window,
        up=up,
        package_dirs=package_dirs,
    )
    centres, ends = gaze_rays(robot, fixation)
    rgb = FIXATED_RGB if fixation.fixated else MISSED_RGB
    for camera, centre, end in zip(fixation.cameras, centres, ends, strict=True):
        name = node_name(camera)
        root_T_camera = robot.frame_poses(fixation.q, camera, fixation.joint_names)
        triad(
            root["cameras/" + name],
            root_T_camera,
            length=CAMERA_TRIAD_LENGTH,
            radius=0.7 * STICK_RADIUS,
        )
        stick(root["gaze/rays/" + name], centre, end - centre, RAY_RADIUS, rgb)
        if not fixation.fixated:
            toward = fixation.root_p_point - centre
            stick(root["gaze/to_point/" + name], centre, toward, 0.4 * RAY_RADIUS, TO_POINT_RGB)
    root["gaze/point"].set_object(overlay_object(mg.Sphere(POINT_RADIUS), POINT_RGB))
    root["gaze/point"].set_transform(transform_from_translation(fixation.root_p_point))

    focus = np.concatenate([robot_ps, centres, fixation.root_p_point[None]])
    frame_scene(vis, root, focus, up)
    return vis


def write_gaze_html(robot: Robot, fixation: Fixation, path: str | Path, **options: object) -> Path:
    """:func:`gaze_scene` as one self-contained HTML file, written atomically
    (:func:`kinfw.view.write_html`); ``options`` go to :func:`gaze_scene`."""
    from kinfw.view._html import OfflineWindow, write_html

    return write_html(gaze_scene(robot, fixation, window=OfflineWindow(), **options), path)
