"""Meshcat scenes (imported when used): the nominal robot as a ghost beside the calibrated
one with the data and residuals (:func:`scene`), fixations and reaches, live on 127.0.0.1
or as one self-contained HTML file (:func:`write_html`).
"""

from __future__ import annotations

from kinfw.view._cameras import (
    FRUSTUM_DEPTH,
)
from kinfw.view._draw import (
    TRIAD_LENGTH,
    triad,
)
from kinfw.view._gaze import (
    gaze_scene,
    write_gaze_html,
)
from kinfw.view._html import (
    OfflineWindow,
    external_urls,
    write_html,
)
from kinfw.view._reach import (
    reach_scene,
    write_reach_html,
)
from kinfw.view._robot import (
    robot_scene,
)
from kinfw.view._scene import (
    GHOST_RGBA,
    SOLID_RGBA,
    residual_color,
    scene,
    targets_from_sidecar,
)
from kinfw.view._show import (
    show,
)

__all__ = [
    "FRUSTUM_DEPTH",
    "GHOST_RGBA",
    "SOLID_RGBA",
    "TRIAD_LENGTH",
    "OfflineWindow",
    "external_urls",
    "gaze_scene",
    "reach_scene",
    "residual_color",
    "robot_scene",
    "scene",
    "show",
    "targets_from_sidecar",
    "triad",
    "write_gaze_html",
    "write_html",
    "write_reach_html",
]
