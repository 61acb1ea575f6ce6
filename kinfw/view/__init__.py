"""Meshcat scenes (imported when used): the nominal robot as a ghost beside the calibrated
one with the data and residuals (:func:`scene`), fixations and reaches, live on 127.0.0.1
or as one self-contained HTML file (:func:`write_html`).
"""

from __future__ import annotations

from kinfw.view._cameras import (
    CAMERA_TRIAD_LENGTH,
    FRUSTUM_DEPTH,
    FRUSTUM_RADIUS,
    FRUSTUM_RGB,
    draw_cameras,
    frustum_corners,
)
from kinfw.view._draw import (
    OVERLAY_RENDER_ORDER,
    STICK_RADIUS,
    TRIAD_LENGTH,
    overlay_material,
    overlay_object,
    rgb_int,
    rotation_y_onto,
    stick,
    transform_from_translation,
    triad,
    up_direction,
)
from kinfw.view._gaze import gaze_rays, gaze_scene, write_gaze_html
from kinfw.view._html import OfflineWindow, external_urls, write_html
from kinfw.view._reach import reach_scene, write_reach_html
from kinfw.view._robot import (
    BACKGROUND_RGB,
    CAMERA_FOV_DEG,
    display_frame,
    draw_robot,
    frame_scene,
    robot_scene,
    set_camera,
)
from kinfw.view._scene import (
    GHOST_RGBA,
    RESIDUAL_COLOR_STOPS_MM,
    SOLID_RGBA,
    residual_color,
    scene,
    targets_from_sidecar,
)
from kinfw.view._show import show

__all__ = [
    "BACKGROUND_RGB",
    "CAMERA_FOV_DEG",
    "CAMERA_TRIAD_LENGTH",
    "FRUSTUM_DEPTH",
    "FRUSTUM_RADIUS",
    "FRUSTUM_RGB",
    "GHOST_RGBA",
    "OVERLAY_RENDER_ORDER",
    "RESIDUAL_COLOR_STOPS_MM",
    "SOLID_RGBA",
    "STICK_RADIUS",
    "TRIAD_LENGTH",
    "OfflineWindow",
    "display_frame",
    "draw_cameras",
    "draw_robot",
    "external_urls",
    "frame_scene",
    "frustum_corners",
    "gaze_rays",
    "gaze_scene",
    "overlay_material",
    "overlay_object",
    "reach_scene",
    "residual_color",
    "rgb_int",
    "robot_scene",
    "rotation_y_onto",
    "scene",
    "set_camera",
    "show",
    "stick",
    "targets_from_sidecar",
    "transform_from_translation",
    "triad",
    "up_direction",
    "write_gaze_html",
    "write_html",
    "write_reach_html",
]
