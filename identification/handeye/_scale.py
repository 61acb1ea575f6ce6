"""The scale factor of a camera's target translations against the robot's motion.

A board of the wrong size given to the pose estimation (a ChArUco square of 0.043 m for
0.034) scales every translation of ``camera_T_target`` by one factor and leaves the
rotations alone; a hand-eye solve takes the poses as given and absorbs the factor into
``hand_T_camera`` and ``base_T_target``. The hand's positions have the robot's scale, so
with the rotations known the factor is one more unknown of a linear system: at pose
``i``, the target's position in the base is

    base_p_link(i) + base_R_link(i) u + s base_R_camera(i) camera_p_target(i)
        = base_p_target_link(i) + base_R_target_link(i) v

with ``u`` the camera's position in the link it rides on (the hand; the base for a
static camera), ``v`` the target's in its own link (the base for a fixed target), and
``s``: the true translations are ``s`` times the measured ones.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Smallest relative singular value of the column-scaled system for which the factor is
#: estimated (else the motions do not determine it).
MIN_CONDITION = 1e-6


def translation_scale(
    *,
    base_T_links: ArrayLike,
    base_R_cameras: ArrayLike,
    camera_p_targets: ArrayLike,
    base_T_target_links: ArrayLike | None = None,
) -> tuple[float, float] | None:
    """The factor ``s`` of the measured target translations (module docstring) and its
    standard deviation, by linear least squares over ``(u, s, v)``.

    For ``kinfw handeye`` pose pairs (eye-in-hand, the package's convention), with the
    solved ``hand_T_camera``: ``translation_scale(base_T_links=base_T_hands,
    base_R_cameras=base_T_hands[:, :3, :3] @ hand_T_camera[:3, :3],
    camera_p_targets=camera_T_targets[:, :3, 3])``.

    Parameters
    ----------
    base_T_links : array_like, shape (n, 4, 4)
        Pose of the link the camera rides on (the hand) at each pose, in the base:
        the forward kinematics, whose lengths are the scale reference.
    base_R_cameras : array_like, shape (n, 3, 3)
        The camera's orientation in the base at each pose (the solved mount's; rotations
        do not depend on the board's size).
    camera_p_targets : array_like, shape (n, 3)
        The measured translations of ``camera_T_target``, in the poses' length unit.
    base_T_target_links : array_like, shape (n, 4, 4), optional
        Pose of the link the target rides on (eye-to-hand: the hand); default the base
        (a target fixed in the world).

    Returns
    -------
    (float, float) or None
        ``(s, sigma)``, sigma the least squares' (residual variance times
        ``(A^T A)^-1``: the kinematics' errors count as noise); None when the motions do
        not determine ``s`` (fewer rows than 8, a rank-deficient system).
    """
    base_T_links = np.asarray(base_T_links, dtype=float)
    n = len(base_T_links)
    target_links = (
        np.tile(np.eye(4), (n, 1, 1))
        if base_T_target_links is None
        else np.asarray(base_T_target_links, dtype=float)
    )
    st = np.einsum(
        "nij,nj->ni", np.asarray(base_R_cameras, float), np.asarray(camera_p_targets, float)
    )
    A = np.concatenate(
        [base_T_links[:, :3, :3], st[:, :, None], -target_links[:, :3, :3]], axis=2
    ).reshape(3 * n, 7)
    b = (target_links[:, :3, 3] - base_T_links[:, :3, 3]).reshape(3 * n)
    return _least_squares_scale(A, b)


def _least_squares_scale(A: NDArray, b: NDArray) -> tuple[float, float] | None:
    """``(s, sigma)``: the 4th unknown of ``A z = b`` by least squares and its standard
    deviation; None when ``A`` (column-scaled) is rank deficient or leaves no degrees of
    freedom."""
    c = np.linalg.norm(A, axis=0)
    if not (c > 0.0).all() or len(A) <= A.shape[1]:
        return None
    U, sv, Vt = np.linalg.svd(A / c, full_matrices=False)
    if sv[-1] < MIN_CONDITION * sv[0]:
        return None
    z = (Vt.T @ ((U.T @ b) / sv)) / c
    r = A @ z - b
    variance = float(r @ r) / (len(A) - A.shape[1])
    cov = (Vt.T / sv**2) @ Vt / np.outer(c, c)
    return float(z[3]), math.sqrt(max(variance * cov[3, 3], 0.0))
