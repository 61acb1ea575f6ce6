"""Rigid transforms: the one place for kinfw's frame conventions.

Conventions
-----------
``a_T_b`` is the pose of frame ``b`` in frame ``a``: a 4x4 float64 matrix that maps
coordinates in ``b`` to coordinates in ``a``. Read names right to left so the inner
frame cancels::

    a_T_c = a_T_b @ b_T_c

``a_R_b`` is its rotation block, ``a_p_b`` its translation (the origin of ``b`` in
``a``). The papers' :math:`{}^aH_b` is our ``a_T_b``. Units are SI (metres, radians).
Quaternions are stored scalar last, ``quat_xyzw``, as Pinocchio/Eigen and SciPy do.

Every function accepts a single item or a batch with the batch axis first
(``(4, 4)`` or ``(n, 4, 4)``; ``(3,)`` or ``(n, 3)``) and returns the same layout.
Batches are processed with numpy broadcasting, never with a Python loop.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

_ORTHONORMAL_TOL = 1e-6


def skew(v: ArrayLike) -> NDArray[np.float64]:
    """Cross-product matrix ``[v]x`` with ``[v]x @ w == cross(v, w)``; shape ``(..., 3, 3)``."""
    v = np.asarray(v, dtype=float)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def vee(m: ArrayLike) -> NDArray[np.float64]:
    """Axial vector of the skew part of ``M``, ``0.5 * vee(M - M^T)``; shape ``(..., 3)``."""
    m = np.asarray(m, dtype=float)
    return 0.5 * np.stack(
        [m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]],
        axis=-1,
    )


def rot_z(angles: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrices about z, :math:`Rot(\\hat z, \\alpha)` of Shih et al. eq. (24).

    Parameters
    ----------
    angles : array_like, shape (...)
        Angles in radians.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    a = np.asarray(angles, dtype=float)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros((*a.shape, 3, 3))
    out[..., 0, 0], out[..., 0, 1] = c, -s
    out[..., 1, 0], out[..., 1, 1] = s, c
    out[..., 2, 2] = 1.0
    return out


def transform_from_rotation_translation(a_R_b: ArrayLike, a_p_b: ArrayLike) -> NDArray[np.float64]:
    """Assemble ``a_T_b`` from ``a_R_b`` (..., 3, 3) and ``a_p_b`` (..., 3)."""
    a_R_b = np.asarray(a_R_b, dtype=float)
    a_p_b = np.asarray(a_p_b, dtype=float)
    shape = np.broadcast_shapes(a_R_b.shape[:-2], a_p_b.shape[:-1])
    out = np.zeros((*shape, 4, 4))
    out[..., :3, :3] = a_R_b
    out[..., :3, 3] = a_p_b
    out[..., 3, 3] = 1.0
    return out


def inverse_transform(a_T_b: ArrayLike) -> NDArray[np.float64]:
    """``b_T_a`` from ``a_T_b`` (rigid inverse, no general matrix inversion)."""
    a_T_b = np.asarray(a_T_b, dtype=float)
    b_R_a = np.swapaxes(a_T_b[..., :3, :3], -1, -2)
    b_p_a = -np.einsum("...ij,...j->...i", b_R_a, a_T_b[..., :3, 3])
    return transform_from_rotation_translation(b_R_a, b_p_a)


def matrix_from_rotation_vector(rotvec: ArrayLike) -> NDArray[np.float64]:
    """Rodrigues' formula: rotation by ``|rotvec|`` radians about ``rotvec``; ``(..., 3, 3)``.

    Equals ``pin.exp3`` item by item (tested against it).
    """
    w = np.asarray(rotvec, dtype=float)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew(w)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * K + b * (K @ K)


def angle_between(u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Angle between vectors (any length, broadcast), ``atan2(|u x v|, u . v)``: accurate
    near 0 and pi, where ``arccos`` of the normalised dot product is not.

    Parameters
    ----------
    u, v : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (...)
        Angles in [0, pi] (rad).
    """
    u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
    cross = np.linalg.norm(np.cross(u, v), axis=-1)
    return np.arctan2(cross, np.einsum("...i,...i->...", u, v))


def rotation_angle(a_R_b: ArrayLike) -> NDArray[np.float64]:
    """Rotation angle in [0, pi] of ``a_R_b`` (..., 3, 3), accurate near 0 and near pi."""
    R = np.asarray(a_R_b, dtype=float)
    sin_half2 = np.linalg.norm(vee(R), axis=-1)
    cos_ = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    return np.arctan2(sin_half2, cos_)


def rotation_vector_from_matrix(a_R_b: ArrayLike) -> NDArray[np.float64]:
    """Matrix logarithm of a rotation (``pin.log3``, vectorised); shape ``(..., 3)``.

    The axis is taken from the skew part away from pi and, near pi, from the symmetric
    part ``(sym(R) - cos(theta) I) / (1 - cos(theta)) = u u^T``, so the result is
    accurate over the whole range.
    """
    R = np.asarray(a_R_b, dtype=float)
    theta = rotation_angle(R)
    v = vee(R)
    sin_t = np.sin(theta)
    small = theta < 1e-8
    near_pi = theta > np.pi - 1e-3
    factor = np.where(small | near_pi, 1.0, theta / np.where(small | near_pi, 1.0, sin_t))
    out = np.where(small[..., None], v, v * factor[..., None])
    if np.any(near_pi):
        cos_t = np.where(near_pi, np.cos(theta), -1.0)[..., None, None]
        S = (0.5 * (R + np.swapaxes(R, -1, -2)) - cos_t * np.eye(3)) / (1.0 - cos_t)
        diag = np.diagonal(S, axis1=-2, axis2=-1)
        k = np.argmax(diag, axis=-1)
        col = np.take_along_axis(S, k[..., None, None].repeat(3, axis=-1), axis=-2)[..., 0, :]
        u = col / np.linalg.norm(col, axis=-1, keepdims=True)
        # The sign of u is fixed by the (small) skew part: sin(theta) u = vee(R).
        sgn = np.where(np.einsum("...i,...i->...", u, v) < 0.0, -1.0, 1.0)
        out = np.where(near_pi[..., None], (sgn * theta)[..., None] * u, out)
    return out


def quat_xyzw_from_matrix(a_R_b: ArrayLike) -> NDArray[np.float64]:
    """Unit quaternion ``(x, y, z, w)`` with ``w >= 0`` of rotation matrices (..., 3, 3)."""
    R = np.asarray(a_R_b, dtype=float)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    # Shepperd's method: pick the largest of 4w^2, 4x^2, 4y^2, 4z^2 for stability.
    cand = np.stack(
        [1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22],
        axis=-1,
    )
    k = np.argmax(cand, axis=-1)
    r = np.sqrt(np.maximum(np.take_along_axis(cand, k[..., None], axis=-1)[..., 0], 1e-300))
    s = 0.5 / r
    d21, s21 = R[..., 2, 1] - R[..., 1, 2], R[..., 2, 1] + R[..., 1, 2]
    d02, s02 = R[..., 0, 2] - R[..., 2, 0], R[..., 0, 2] + R[..., 2, 0]
    d10, s10 = R[..., 1, 0] - R[..., 0, 1], R[..., 1, 0] + R[..., 0, 1]
    q = np.stack(
        [
            np.select([k == 0, k == 1, k == 2], [d21 * s, 0.5 * r, s10 * s], s02 * s),
            np.select([k == 0, k == 1, k == 2], [d02 * s, s10 * s, 0.5 * r], s21 * s),
            np.select([k == 0, k == 1, k == 2], [d10 * s, s02 * s, s21 * s], 0.5 * r),
            np.select([k == 0, k == 1, k == 2], [0.5 * r, d21 * s, d02 * s], d10 * s),
        ],
        axis=-1,
    )
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def _matrix_from_quat_xyzw(quat_xyzw: NDArray[np.float64]) -> NDArray[np.float64]:
    x, y, z, w = (quat_xyzw[..., i] for i in range(4))
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def transform_from_xyz_quat_xyzw(xyz: ArrayLike, quat_xyzw: ArrayLike) -> NDArray[np.float64]:
    """``a_T_b`` from a position (..., 3) and a unit quaternion (..., 4) stored scalar last.

    The quaternion must already be unit (the file readers renormalise and validate);
    it is renormalised here only against rounding.
    """
    q = np.asarray(quat_xyzw, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return transform_from_rotation_translation(_matrix_from_quat_xyzw(q), xyz)


def xyz_quat_xyzw_from_transform(
    a_T_b: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Position (..., 3) and scalar-last unit quaternion (..., 4), ``w >= 0``, of ``a_T_b``."""
    a_T_b = np.asarray(a_T_b, dtype=float)
    return a_T_b[..., :3, 3].copy(), quat_xyzw_from_matrix(a_T_b[..., :3, :3])


def check_rotation(
    a_R_b: ArrayLike, name: str = "rotation", tol: float = _ORTHONORMAL_TOL
) -> NDArray[np.float64]:
    """Validate rotation matrices (..., 3, 3): finite, orthonormal within ``tol``, det +1.

    Returns the array as float64; raises ``ValueError`` naming ``name`` and the first
    offending index otherwise.
    """
    R = np.asarray(a_R_b, dtype=float)
    if R.ndim < 2 or R.shape[-2:] != (3, 3):
        raise ValueError(f"{name}: expected shape (..., 3, 3), got {R.shape}")
    bad = ~np.isfinite(R).all(axis=(-2, -1))
    err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(-2, -1), initial=0.0)
    det = np.linalg.det(R) if R.size else np.ones(R.shape[:-2])
    bad |= (err > tol) | (det < 0.0)
    if np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        where = f"[{', '.join(map(str, idx))}]" if idx else ""
        raise ValueError(
            f"{name}{where}: not a rotation matrix (need R^T R = I within {tol:g} and det = +1; "
            f"orthonormality error {np.ravel(err)[0] if not idx else err[idx]:.3g}, "
            f"det {np.ravel(det)[0] if not idx else det[idx]:.6g})"
        )
    return R


def check_transform(
    a_T_b: ArrayLike, name: str = "transform", tol: float = _ORTHONORMAL_TOL
) -> NDArray[np.float64]:
    """Validate homogeneous rigid transforms (..., 4, 4); returns them as float64.

    Raises ``ValueError`` naming ``name`` (and the batch index) when the shape is wrong,
    a value is not finite, the last row is not ``[0, 0, 0, 1]`` or the rotation block is
    not a rotation.
    """
    T = np.asarray(a_T_b, dtype=float)
    if T.ndim < 2 or T.shape[-2:] != (4, 4):
        raise ValueError(f"{name}: expected shape (4, 4) or (n, 4, 4), got {T.shape}")
    bad_row = np.abs(T[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=-1) > tol
    bad_row |= ~np.isfinite(T).all(axis=(-2, -1))
    if np.any(bad_row):
        idx = tuple(int(i) for i in np.argwhere(bad_row)[0])
        where = f"[{', '.join(map(str, idx))}]" if idx else ""
        raise ValueError(f"{name}{where}: last row must be [0, 0, 0, 1] and all values finite")
    check_rotation(T[..., :3, :3], name=name, tol=tol)
    return T


def project_to_rotation(M: ArrayLike) -> NDArray[np.float64]:
    """Nearest rotation (Frobenius norm) to each 3x3 matrix, by SVD with the det fix."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=float))
    d = np.sign(np.linalg.det(U @ Vt))
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def average_transform(a_T_bs: ArrayLike) -> NDArray[np.float64]:
    """Chordal L2 mean of poses (n, 4, 4): mean translation, projected mean rotation.

    The rotation minimises the sum of squared Frobenius distances to the inputs
    (Hartley et al. 2013, "Rotation averaging", the chordal L2 mean).
    """
    T = np.asarray(a_T_bs, dtype=float)
    return transform_from_rotation_translation(
        project_to_rotation(T[:, :3, :3].mean(axis=0)), T[:, :3, 3].mean(axis=0)
    )
