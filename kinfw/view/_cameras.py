"""Cameras in the calibration scene (:mod:`kinfw.view`): each camera's frame as a small
triad and, with intrinsics, its frustum (the image's corners at :data:`FRUSTUM_DEPTH`),
below ``/meshcat/kinfw/cameras/<camera>``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from kinfw.measurements import Measurements
from kinfw.model import Robot
from kinfw.observations import kind_of, node_name
from kinfw.view._draw import STICK_RADIUS, stick, triad

if TYPE_CHECKING:
    import meshcat

CAMERA_TRIAD_LENGTH = 0.02
"""Length of a camera frame's triad, metres (thinner and shorter than a measurement's)."""
FRUSTUM_DEPTH = 0.2
"""Depth of a camera's drawn frustum (the image's corners), metres."""
FRUSTUM_RADIUS = 0.0006
"""Radius of a frustum's cylinders, metres."""
FRUSTUM_RGB = (0.2, 0.2, 0.25)
"""Colour of a camera's frustum."""


def draw_cameras(
    root: meshcat.Visualizer,
    model: Robot,
    data: Measurements | None,
    q: NDArray,
    joint_names: tuple[str, ...],
) -> NDArray[np.float64]:
    """Each camera's frame (a small triad) at ``q`` and, when its intrinsics are known
    (the data's ``cameras`` section or a kind's), its frustum: the image's corners at
    :data:`FRUSTUM_DEPTH`. Cameras: the URDF's ``<kinfw cameras>`` hint and those the
    data's groups use. Returns the drawn optical centres (n, 3), root frame, m."""
    cameras = dict.fromkeys(model.default_cameras)
    if data is not None:
        cameras.update(
            dict.fromkeys(c for g in data.all_groups() for c in kind_of(g).camera_frames(g))
        )
    intrinsics = {} if data is None else dict(data.cameras)
    if data is not None:
        for g in data.all_groups():
            intrinsics.update(kind_of(g).cameras(g))
    drawn = []
    for camera in cameras:
        root_T_camera = model.frame_poses(q, camera, joint_names)
        node = root["cameras/" + node_name(camera)]
        triad(node, root_T_camera, length=CAMERA_TRIAD_LENGTH, radius=0.7 * STICK_RADIUS)
        drawn.append(root_T_camera[:3, 3])
        if camera in intrinsics:
            corners = frustum_corners(intrinsics[camera])
            for k, (a, b) in enumerate(zip(corners, np.roll(corners, -1, axis=0), strict=True)):
                stick(node[f"frustum/ray{k}"], np.zeros(3), a, FRUSTUM_RADIUS, FRUSTUM_RGB)
                stick(node[f"frustum/edge{k}"], a, b - a, FRUSTUM_RADIUS, FRUSTUM_RGB)
    return np.array(drawn).reshape(-1, 3)


def frustum_corners(intrinsics: Any, depth_m: float = FRUSTUM_DEPTH) -> NDArray[np.float64]:
    """The image's corners (pixel centres of the corner pixels, back-projected by
    :meth:`kinfw.camera.CameraIntrinsics.rays`)
    at a depth ``depth_m`` along the optical axis, in the camera's optical frame.

    Parameters
    ----------
    intrinsics : CameraIntrinsics
    depth_m : float
        Metres.

    Returns
    -------
    ndarray, shape (4, 3)
        Top-left, top-right, bottom-right, bottom-left (image order), metres.
    """
    w, h = intrinsics.width - 1.0, intrinsics.height - 1.0
    rays = intrinsics.rays(np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]))
    return depth_m * rays / rays[:, 2:]
