"""Least-squares rigid registration of corresponding 3D point sets (Arun et al. 1987).

Used for the stereo rig of stage 1 of Shih et al. (1992), section 3.3: the rig measures
the 3D centres of the nine circles of a calibration plate; registering them with the
circles' known positions on the plate gives the pose of the plate in the rig frame.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry._transforms import transform_from_rotation_translation

# Relative size of the second singular value below which a point set is called collinear.
_RANK_TOL = 1e-9


def register_points(frame_p: ArrayLike, meas_p: ArrayLike) -> NDArray[np.float64]:
    """Pose of a frame from its points, by Arun's SVD method with the reflection fix.

    Finds the rigid transform ``meas_T_frame`` minimising
    ``sum_i |meas_p[i] - (meas_R_frame @ frame_p[i] + meas_p_frame)|^2``.

    Parameters
    ----------
    frame_p : array_like, shape (N, 3) or (n, N, 3)
        Known positions of the points in the frame (e.g. the circle centres on the
        calibration plate), any length unit.
    meas_p : array_like, shape (N, 3) or (n, N, 3)
        Measured positions of the same points, in the same order, in the measurement
        frame, same unit. A batch ``(n, N, 3)`` registers ``n`` point sets at once
        (numpy's batched SVD, no Python loop); ``frame_p`` broadcasts against it.

    Returns
    -------
    meas_T_frame : ndarray, shape (4, 4) or (n, 4, 4)
        Pose of the frame in the measurement frame (translation in the input unit).
        Always a proper rotation (det = +1).

    Raises
    ------
    ValueError
        Wrong shapes, non-finite values, fewer than 3 points, or a point set (known or
        measured) that is collinear or coincident (rank < 2), naming the problem.

    Notes
    -----
    Shih et al. (1992) write eq. (16) as ``q_i = R p_i + t + e_i`` with ``p_i`` the
    *measured* points and ``q_i`` the plate points, so the paper's ``R, t`` are
    ``frame_R_meas, frame_p_meas``; this function returns the inverse, ``meas_T_frame``.
    In the paper's symbols: centroids ``p_bar, q_bar`` (eq. 18), centred points (eq. 19),
    ``H = sum_i p_bar_i q_bar_i^T`` (eq. 22), ``H = U S V^T`` and ``R = V U^T``
    maximises ``trace(R H)`` (eq. 21), ``t = q_bar - R p_bar`` (eq. 18). Hence
    ``meas_R_frame = U V^T`` and ``meas_p_frame = p_bar - meas_R_frame q_bar``.

    When ``det(V U^T) = -1`` (coplanar points, where the third singular value is zero
    and the sign of its singular vectors is arbitrary, or very noisy data) the SVD gives
    a reflection. The paper stops at ``det = +1``; following Arun et al. (sec. IV) and
    Umeyama (1991) the sign of the singular vector of the smallest singular value is
    flipped, ``R = V diag(1, 1, -1) U^T``, which is the least-squares rotation.

    References
    ----------
    Shih, Hung & Lin (1992), section 3.3, eqs. (16)-(22).
    Arun, Huang & Blostein (1987), "Least-squares fitting of two 3-D point sets",
    IEEE TPAMI 9(5), 698-700.
    Umeyama (1991), "Least-squares estimation of transformation parameters between two
    point patterns", IEEE TPAMI 13(4), 376-380.
    """
    frame_p = np.asarray(frame_p, dtype=float)
    meas_p = np.asarray(meas_p, dtype=float)
    for name, pts in (("frame_p", frame_p), ("meas_p", meas_p)):
        if pts.ndim not in (2, 3) or pts.shape[-1] != 3:
            raise ValueError(f"{name}: expected shape (N, 3) or (n, N, 3), got {pts.shape}")
        if not np.isfinite(pts).all():
            raise ValueError(f"{name}: contains non-finite values")
    if frame_p.shape[-2] != meas_p.shape[-2]:
        raise ValueError(
            f"frame_p and meas_p: need the same number of points, got {frame_p.shape[-2]} "
            f"and {meas_p.shape[-2]}"
        )
    n_points = frame_p.shape[-2]
    if n_points < 3:
        raise ValueError(f"register_points: need at least 3 points, got {n_points}")
    try:
        np.broadcast_shapes(frame_p.shape[:-2], meas_p.shape[:-2])
    except ValueError:
        raise ValueError(
            f"frame_p {frame_p.shape} and meas_p {meas_p.shape}: batch sizes differ"
        ) from None

    frame_c = frame_p.mean(axis=-2)  # paper's q_bar
    meas_c = meas_p.mean(axis=-2)  # paper's p_bar
    frame_d = frame_p - frame_c[..., None, :]  # q_bar_i
    meas_d = meas_p - meas_c[..., None, :]  # p_bar_i
    _check_rank(frame_d, "frame_p")
    _check_rank(meas_d, "meas_p")

    H = np.einsum("...ki,...kj->...ij", meas_d, frame_d)  # eq. (22): sum p_bar_i q_bar_i^T
    U, _, Vt = np.linalg.svd(H)
    # Reflection fix: d = det(V U^T) = det(U) det(V); flip the last singular vector if -1.
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    D = np.ones((*d.shape, 3))
    D[..., 2] = d
    meas_R_frame = np.einsum("...ij,...j,...jk->...ik", U, D, Vt)  # (V D U^T)^T
    meas_p_frame = meas_c - np.einsum("...ij,...j->...i", meas_R_frame, frame_c)
    return transform_from_rotation_translation(meas_R_frame, meas_p_frame)


def _check_rank(centred: NDArray[np.float64], name: str) -> None:
    """Raise unless every centred point set (..., N, 3) spans at least a plane."""
    s = np.linalg.svd(centred, compute_uv=False)  # (..., 3), descending
    scale = s[..., 0]
    bad = (scale <= 0.0) | (s[..., 1] <= _RANK_TOL * scale)
    if np.any(bad):
        idx = np.argwhere(np.atleast_1d(bad))[0]
        where = f"[{', '.join(map(str, idx))}]" if bad.ndim else ""
        raise ValueError(
            f"{name}{where}: points are collinear or coincident (rank < 2); "
            "registration needs at least 3 non-collinear points"
        )
