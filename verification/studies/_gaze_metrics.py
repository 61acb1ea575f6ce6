"""What a model's error does when it is used (issue 16; :mod:`kinfw.verification.studies`):
where a camera sees a point against where the model meant it, and the point triangulated
from two cameras' rays placed with the model's camera poses."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.control import camera_points
from kinfw.geometry import angle_between


def triangulate(root_p_origins: ArrayLike, root_directions: ArrayLike) -> NDArray[np.float64]:
    """Midpoint of the common perpendicular of two lines.

    Parameters
    ----------
    root_p_origins : array_like, shape (..., 2, 3)
        A point of each line (m).
    root_directions : array_like, shape (..., 2, 3)
        Each line's direction (any length, not parallel).

    Returns
    -------
    ndarray, shape (..., 3)
        The point midway between the lines' closest points (m).
    """
    p = np.asarray(root_p_origins, dtype=float)
    d = np.asarray(root_directions, dtype=float)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    w = p[..., 0, :] - p[..., 1, :]
    b = np.einsum("...i,...i->...", d[..., 0, :], d[..., 1, :])
    e0 = np.einsum("...i,...i->...", d[..., 0, :], w)
    e1 = np.einsum("...i,...i->...", d[..., 1, :], w)
    denominator = 1.0 - b * b  # > 0 unless parallel
    t0 = (b * e1 - e0) / denominator
    t1 = (e1 - b * e0) / denominator
    closest0 = p[..., 0, :] + t0[..., None] * d[..., 0, :]
    closest1 = p[..., 1, :] + t1[..., None] * d[..., 1, :]
    return 0.5 * (closest0 + closest1)


def pointing_errors_rad(
    model_root_T_cameras: ArrayLike, true_root_T_cameras: ArrayLike, root_p_point: ArrayLike
) -> NDArray[np.float64]:
    """Angle between the direction of the point in the true camera's frame and in the
    model's (both at the same commanded joints): the model's pointing error.

    Parameters
    ----------
    model_root_T_cameras, true_root_T_cameras : array_like, shape (..., 4, 4)
        Camera poses by the model and by the true robot, in the root frame (m).
    root_p_point : array_like, shape (..., 3)
        The point in the root frame (m).

    Returns
    -------
    ndarray, shape (...)
        Angles in [0, pi] (rad).
    """
    point = np.asarray(root_p_point, dtype=float)
    model = camera_points(model_root_T_cameras, point)
    return angle_between(model, camera_points(true_root_T_cameras, point))


def triangulation_errors_m(
    model_root_T_cameras: ArrayLike, true_root_T_cameras: ArrayLike, root_p_point: ArrayLike
) -> NDArray[np.float64]:
    """Triangulation of a point seen by two true cameras, with the model's camera poses.

    Each true camera sees the point along ``camera_p / |camera_p|`` (its frame); the
    model puts that ray at its own camera pose; the two rays are intersected
    (:func:`triangulate`).

    Parameters
    ----------
    model_root_T_cameras, true_root_T_cameras : array_like, shape (..., 2, 4, 4)
        The two cameras' poses by the model and by the true robot, root frame (m).
    root_p_point : array_like, shape (..., 3)
        The point (m).

    Returns
    -------
    ndarray, shape (...)
        Distance from the triangulated point to the point (m).
    """
    point = np.asarray(root_p_point, dtype=float)
    model = np.asarray(model_root_T_cameras, dtype=float)
    camera_rays = camera_points(true_root_T_cameras, point[..., None, :])
    root_rays = np.einsum("...ij,...j->...i", model[..., :3, :3], camera_rays)
    estimate = triangulate(model[..., :3, 3], root_rays)
    return np.linalg.norm(estimate - point, axis=-1)
