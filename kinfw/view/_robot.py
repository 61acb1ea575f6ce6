"""Drawing a URDF robot in meshcat and framing the view (helpers of :func:`kinfw.view.scene`).

:func:`draw_robot` draws a robot's visuals (meshes found from ``package://``,
``file://`` or relative paths) and returns the points to frame; when meshes are missing
it draws the links as a skeleton too (a triad per link frame, a segment along each joint
from its parent link's origin to its child's), with one logged warning for them all;
:func:`display_frame` chooses the display frame and the camera position that frame them,
:func:`set_camera` puts meshcat's orbit camera there.
"""

from __future__ import annotations

import logging
import math
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from kinfw.model import Robot, mesh_dirs, resolve_meshes
from kinfw.view._draw import stick, triad

if TYPE_CHECKING:
    import meshcat

logger = logging.getLogger("kinfw.view")

CAMERA_FOV_DEG = 30.0
"""Vertical field of view of the camera, degrees (meshcat's default, 75, distorts)."""
BACKGROUND_RGB = ((1.0, 1.0, 1.0), (0.88, 0.9, 0.93))
"""Background gradient (top, bottom)."""


# -- robot geometry ----------------------------------------------------------------------


#: Radius of the skeleton's segments and length of its link triads, metres.
SKELETON_RADIUS = 0.004
SKELETON_TRIAD = 0.05
#: Where the missing meshes are looked for, named in the warning: at most this many.
_SHOWN_PLACES = 3


def _visual_urdf(robot: Robot, package_dirs: Sequence[Path]) -> tuple[str, int]:
    """The robot's URDF with mesh paths made absolute and visuals whose mesh is missing
    removed, and how many are missing (one logged warning for them all)."""
    xml, missing = resolve_meshes(robot, package_dirs, "visual")
    if missing:
        places = list(
            dict.fromkeys(
                "package://" + m.filename[len("package://") :].partition("/")[0]
                if m.filename.startswith("package://")
                else f"{Path(m.filename).parent}/"
                for m in missing
            )
        )
        shown = ", ".join(places[:_SHOWN_PLACES]) + (", ..." if len(places) > _SHOWN_PLACES else "")
        searched = ", ".join(str(d) for d in mesh_dirs(package_dirs)) or "no package directory"
        logger.warning(
            "%s: %d visual mesh(es) not found under %s (searched %s): drawn as a skeleton; "
            "give --package-dir DIR (package_dirs in Python)",
            robot.source,
            len(missing),
            shown,
            searched,
        )
    return xml, len(missing)


def _draw_skeleton(
    vis: meshcat.Visualizer, robot: Robot, node: str, pin_q: NDArray, rgb: Sequence[float]
) -> NDArray[np.float64]:
    """Under ``node/skeleton``: a triad per link frame (``links/LINK``) and a segment
    per URDF joint from its parent link's origin to its child link's (``joints/JOINT``),
    at ``pin_q``; return the link origins, (m, 3), root-link coordinates."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, pin_q)
    root_T_links = {
        f.name: data.oMf[k].homogeneous
        for k, f in enumerate(robot.model.frames)
        if f.type == pin.FrameType.BODY
    }
    skeleton = vis[f"{node}/skeleton"]
    for link, root_T_link in root_T_links.items():
        triad(skeleton["links"][link], root_T_link, length=SKELETON_TRIAD, origin_rgb=rgb)
    for joint in robot.joints:
        a, b = root_T_links[joint.parent][:3, 3], root_T_links[joint.child][:3, 3]
        if np.linalg.norm(b - a) > 0:
            stick(skeleton["joints"][joint.name], a, b - a, SKELETON_RADIUS, rgb)
    return np.array([T[:3, 3] for T in root_T_links.values()]).reshape(-1, 3)


def _visual_model(robot: Robot, xml: str) -> pin.GeometryModel:
    try:
        return pin.buildGeomFromUrdfString(robot.model, xml, pin.GeometryType.VISUAL)
    except Exception as exc:  # a mesh that exists but cannot be read
        logger.warning(
            "%s: cannot load the visual geometry (%s); drawing primitives only", robot.source, exc
        )
        root = ET.fromstring(xml)
        for link in root.iter("link"):
            for visual in list(link.findall("visual")):
                if visual.find("geometry/mesh") is not None:
                    link.remove(visual)
        return pin.buildGeomFromUrdfString(
            robot.model, ET.tostring(root, encoding="unicode"), pin.GeometryType.VISUAL
        )


def draw_robot(
    vis: meshcat.Visualizer,
    robot: Robot,
    node: str,
    pin_q: NDArray,
    rgba: Sequence[float] | None,
    package_dirs: Sequence[Path],
) -> NDArray[np.float64]:
    """Draw ``robot`` at ``pin_q`` under ``node``; return the points to frame, (m, 3):
    the centres of the visuals of its moving links (of all links if none moves; the link
    frames' origins if it has no visuals or some of its meshes are missing). Missing
    meshes: one logged warning, and the links drawn as a skeleton under
    ``node/skeleton`` (``links/LINK`` triads, ``joints/JOINT`` segments)."""
    from pinocchio.visualize import MeshcatVisualizer

    xml, n_missing = _visual_urdf(robot, package_dirs)
    visual_model = _visual_model(robot, xml)
    viz = MeshcatVisualizer(robot.model, None, visual_model)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        viz.initViewer(viewer=vis)
        viz.loadViewerModel(rootNodeName=node, visual_color=None if rgba is None else list(rgba))
        viz.display(pin_q)
    for w in caught:
        logger.warning("%s: %s", robot.source, w.message)
    # Frame the moving part: the centres of the visuals behind a movable joint (Pinocchio
    # merges fixed joints, so parentJoint 0 means rigidly attached to the root link).
    placements = [
        (g.parentJoint, oMg.translation)
        for g, oMg in zip(visual_model.geometryObjects, viz.visual_data.oMg, strict=True)
    ]
    if n_missing:
        grey = (0.35, 0.35, 0.35) if rgba is None else rgba[:3]
        _draw_skeleton(vis, robot, node, pin_q, grey)
        placements = []  # frame the whole robot: its link frames, drawn or not
    if not placements:
        pin.updateFramePlacements(viz.model, viz.data)
        placements = [
            (f.parentJoint, oMf.translation)
            for f, oMf in zip(viz.model.frames, viz.data.oMf, strict=True)
            if f.type == pin.FrameType.BODY
        ]
    moving = [p for joint, p in placements if joint > 0]
    return np.array(moving or [p for _, p in placements]).reshape(-1, 3)


# -- camera ------------------------------------------------------------------------------


def display_frame(
    points: NDArray[np.float64],
    up: NDArray[np.float64],
    *,
    fov_deg: float,
    aspect: float = 4.0 / 3.0,
    pad: float = 0.08,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``display_T_root`` and the camera position in display coordinates.

    The display frame has its origin at the centre of the points' bounding box and
    ``up`` along z; its x axis points horizontally towards the root origin (the
    measurement system when the root is the measurement frame), or along the points'
    longest horizontal extent when the root origin is above or below the centre. The
    camera looks at the origin from 35 deg to the side of x and 15 deg above the
    horizon, just far enough that a ball of radius ``pad`` (metres) about every point
    is inside 85 % of the field of view (``fov_deg`` vertically) of a window of
    width / height ``aspect`` or wider.
    """
    up = up / np.linalg.norm(up)
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    x = -centre - (-centre @ up) * up
    if np.linalg.norm(x) < 1e-3 and len(points) > 1:
        flat = (points - centre) - np.outer((points - centre) @ up, up)
        x = np.linalg.svd(flat, full_matrices=False)[2][0]
        x = x - (x @ up) * up
    if np.linalg.norm(x) < 1e-9:  # nothing horizontal: any horizontal axis
        x = np.cross(up, np.eye(3)[np.argmin(np.abs(up))])
    x /= np.linalg.norm(x)
    root_R_display = np.column_stack([x, np.cross(up, x), up])
    display_T_root = np.eye(4)
    display_T_root[:3, :3] = root_R_display.T
    display_T_root[:3, 3] = -root_R_display.T @ centre
    display_ps = (points - centre) @ root_R_display

    azimuth, elevation = math.radians(35.0), math.radians(15.0)
    back = np.array(
        [
            math.cos(elevation) * math.cos(azimuth),
            math.cos(elevation) * math.sin(azimuth),
            math.sin(elevation),
        ]
    )
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    screen_up = np.cross(back, right)
    tan_v = 0.85 * math.tan(math.radians(fov_deg / 2))
    tan_h = aspect * tan_v
    # A point p is in view from distance D when |p.right| <= (D - p.back) tan_h and
    # |p.screen_up| <= (D - p.back) tan_v.
    depth = display_ps @ back
    need = np.maximum(
        (np.abs(display_ps @ right) + pad) / tan_h, (np.abs(display_ps @ screen_up) + pad) / tan_v
    )
    distance = max(float(np.max(depth + need)), 0.3)
    return display_T_root, distance * back


def set_camera(
    vis: meshcat.Visualizer, display_offset: NDArray[np.float64], fov_deg: float
) -> None:
    """Put meshcat's orbit camera at ``display_offset`` (it looks at the origin)."""
    # The camera lives in /Cameras/default/rotated, which turns three.js' y-up frame
    # into meshcat's z-up one: display (x, y, z) is three.js (x, z, -y).
    x, y, z = (float(v) for v in display_offset)
    vis["/Cameras/default"].set_transform(np.eye(4))
    camera = vis["/Cameras/default/rotated/<object>"]
    camera.set_property("position", [x, z, -y])
    camera.set_property("fov", fov_deg)


def frame_scene(
    vis: meshcat.Visualizer,
    root: meshcat.Visualizer,
    root_ps: NDArray[np.float64],
    up: NDArray[np.float64],
) -> None:
    """Frame a scene drawn under ``root`` (root-link coordinates) on the points
    ``root_ps`` (n, 3) with ``up`` up (:func:`display_frame`, :func:`set_camera`), hide
    meshcat's axes and grid, and set the background gradient."""
    display_T_root, camera_offset = display_frame(root_ps, up, fov_deg=CAMERA_FOV_DEG)
    root.set_transform(display_T_root)
    set_camera(vis, camera_offset, CAMERA_FOV_DEG)
    vis["/Axes"].set_property("visible", False)
    vis["/Grid"].set_property("visible", False)
    vis["/Background"].set_property("top_color", list(BACKGROUND_RGB[0]))
    vis["/Background"].set_property("bottom_color", list(BACKGROUND_RGB[1]))


def robot_scene(
    robot: Robot,
    q: NDArray[np.float64],
    joint_names: tuple[str, ...],
    rgba: tuple[float, float, float, float],
    *,
    window: object | None,
    up: ArrayLike | None,
    package_dirs: Sequence[str | Path],
) -> tuple[meshcat.Visualizer, meshcat.Visualizer, NDArray[np.float64], NDArray[np.float64]]:
    """A meshcat scene with one robot drawn at the joint values ``q`` (``joint_names``
    order), in ``rgba``, under ``/meshcat/kinfw/robot``: the start of the scenes of
    :mod:`kinfw.view._gaze` and :mod:`kinfw.view._reach`.

    Returns
    -------
    vis, root : meshcat.Visualizer
        The scene and its ``kinfw`` node (root-link coordinates).
    up : ndarray, shape (3,)
        The checked up direction (:func:`kinfw.view._draw.up_direction`).
    robot_ps : ndarray, shape (n, 3)
        Points of the drawn robot, for :func:`frame_scene`.
    """
    import meshcat

    from kinfw.view._draw import up_direction

    up = up_direction(robot, up)
    vis = meshcat.Visualizer() if window is None else meshcat.Visualizer(window=window)
    pin_q = robot.pin_configurations(q, joint_names)[0]
    robot_ps = draw_robot(vis, robot, "kinfw/robot", pin_q, rgba, package_dirs)
    return vis, vis["kinfw"], up, robot_ps
