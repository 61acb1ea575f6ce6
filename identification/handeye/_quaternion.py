"""Quaternions of the hand-eye solvers, all scalar last ``(x, y, z, w)``: rotations
from them, the Hamilton product as matrices, sign-consistent quaternions of pose pairs
(:func:`consistent_quats_xyzw`), and the closed form of
``camera_T_target[i] ≈ camera_T_hand @ hand_T_base[i] @ base_T_target`` (in Hirsh's
letters ``A[i] ≈ X B[i] Y``; :mod:`kinfw.identification.handeye`) from them -- the top
singular pair of the mean product matrix (Hirsh et al.'s fixed point, the quaternion
counterpart of Shah's 2013 Kronecker solution: no singularity at any rotation angle) and
the translations by linear least squares -- for all poses at once or for a batch of pose
subsets (the consensus start of the maximum-likelihood fit).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import (
    quat_xyzw_from_matrix,
    skew,
    transform_from_rotation_translation,
    transform_from_xyz_quat_xyzw,
)


def rotation_from_quat_xyzw(quat_xyzw: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4), scalar last."""
    return transform_from_xyz_quat_xyzw(np.zeros(3), quat_xyzw)[..., :3, :3]


def left_product_matrix_xyzw(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """``L(p)`` with ``p * q = L(p) q`` (Hamilton product, Hirsh et al. section 2.2
    property 2), for quaternions ``p`` (..., 4), scalar last."""
    pv, pw = p[..., :3], p[..., 3]
    out = np.zeros((*p.shape[:-1], 4, 4))
    out[..., :3, :3] = pw[..., None, None] * np.eye(3) + skew(pv)
    out[..., :3, 3] = pv
    out[..., 3, :3] = -pv
    out[..., 3, 3] = pw
    return out


def right_product_matrix_xyzw(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R(q)`` with ``p * q = R(q) p``, for quaternions ``q`` (..., 4), scalar last."""
    qv, qw = q[..., :3], q[..., 3]
    out = np.zeros((*q.shape[:-1], 4, 4))
    out[..., :3, :3] = qw[..., None, None] * np.eye(3) - skew(qv)
    out[..., :3, 3] = qv
    out[..., 3, :3] = -qv
    out[..., 3, 3] = qw
    return out


def consistent_quats_xyzw(
    R_As: NDArray[np.float64], R_Bs: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Quaternions (n, 4), scalar last, of rotations ``R_A[i]``, ``R_B[i]`` (n, 3, 3) with
    signs such that ``q_A[i] = q_X q_B[i] q_Y`` (``R_A[i] = R_X R_B[i] R_Y``).

    The scalar part of ``q_A[i] q_A[j]^-1`` is ``s_i s_j`` times that of
    ``q_B[i] q_B[j]^-1`` (conjugation keeps it, Hirsh et al. Appendix A), so
    ``S_ij = (q_A[i] . q_A[j]) (q_B[i] . q_B[j]) = s_i s_j c_ij^2`` with ``c_ij^2 >= 0``:
    the signs ``s_i`` are those of the top eigenvector of ``S`` (Perron-Frobenius).
    ``S = Z Z^T`` with ``Z[i] = q_A[i] kron q_B[i]``, so that eigenvector is ``Z v``,
    ``v`` the top eigenvector of the 16x16 ``Z^T Z``. Sample order does not matter. The
    quaternions of ``R_B`` keep the sign of :func:`kinfw.geometry.quat_xyzw_from_matrix`
    (``w >= 0``).
    """
    n = len(R_As)
    q = quat_xyzw_from_matrix(np.concatenate([R_As, R_Bs]))
    q_As, q_Bs = q[:n], q[n:]
    Z = (q_As[:, :, None] * q_Bs[:, None, :]).reshape(n, 16)
    v = np.linalg.eigh(Z.T @ Z)[1][:, -1]
    return np.where((Z @ v < 0.0)[:, None], -q_As, q_As), q_Bs


@lru_cache(maxsize=1)
def product_tensor() -> NDArray:
    """``T[a, b]`` = ``K`` of the basis quaternions ``e_a``, ``e_b``: ``K`` is bilinear in
    ``(q_A, q_B)``, so ``K_i = sum_ab q_A[i, a] q_B[i, b] T[a, b]`` (one einsum)."""
    conj = np.array([-1.0, -1.0, -1.0, 1.0])
    E = np.eye(4)
    T = (left_product_matrix_xyzw(E)[:, None] @ right_product_matrix_xyzw(E * conj)[None]) * conj
    T.setflags(write=False)
    return T


def product_matrices(q_A: NDArray, q_B: NDArray) -> NDArray:
    """Per pose ``K_i`` with ``q_X = (mean_i K_i) q_Y`` at a fit (``N`` of
    :func:`kinfw.identification.handeye._axyb_iteration.iteration_matrix` is their mean):
    ``L(q_A) R(q_B^-1) diag(-1, -1, -1, 1)``."""
    return np.einsum("na,nb,abjk->njk", q_A, q_B, product_tensor(), optimize=False)


def closed_form_batch(
    K: NDArray, R_A: NDArray, t_A: NDArray, R_B: NDArray, t_B: NDArray
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Closed-form ``X = camera_T_hand``, ``Y = base_T_target`` for a batch of subsets:
    ``K`` (s, m, 4, 4) of :func:`product_matrices`, rotations ``R_A`` (s, m, 3, 3) and
    translations ``t_A`` (s, m, 3) of ``camera_T_target``, ``R_B``, ``t_B`` of
    ``hand_T_base``.

    Rotations: top singular pair of ``mean K`` (Hirsh's fixed point, Shah's closed form
    in quaternions; no singularity at any angle). Translations: linear least squares of
    ``t_X + R_X R_B t_Y = t_A - R_X t_B`` (6 unknowns), by the normal equations.

    Returns ``X``, ``Y`` (s, 4, 4) and their rotations' quaternions ``q_X``, ``q_Y``
    (s, 4), xyzw: for a pose with product matrix ``K_i``, ``|q_X^T K_i q_Y|`` is the
    cosine of half its residual rotation angle.
    """
    U, _, Vt = np.linalg.svd(K.mean(axis=1))
    R_X = rotation_from_quat_xyzw(U[:, :, 0])
    R_Y = rotation_from_quat_xyzw(Vt[:, 0, :])
    s, m = R_A.shape[:2]
    C = np.concatenate([np.broadcast_to(np.eye(3), (s, m, 3, 3)), R_X[:, None] @ R_B], axis=3)
    rhs = t_A - t_B @ np.swapaxes(R_X, 1, 2)
    C = C.reshape(s, 3 * m, 6)
    Ct = np.swapaxes(C, 1, 2)
    CtC = Ct @ C
    CtC += 1e-12 * np.eye(6) * np.trace(CtC, axis1=1, axis2=2)[:, None, None]
    sol = np.linalg.solve(CtC, Ct @ rhs.reshape(s, 3 * m, 1))[..., 0]
    X = transform_from_rotation_translation(R_X, sol[:, :3])
    Y = transform_from_rotation_translation(R_Y, sol[:, 3:])
    return X, Y, U[:, :, 0], Vt[:, 0, :]


def closed_form_start(
    camera_T_targets: NDArray[np.float64], hand_T_bases: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Closed-form ``camera_T_hand`` and ``base_T_target`` (each (4, 4), input length
    unit) of ``camera_T_target[i] ≈ camera_T_hand @ hand_T_base[i] @ base_T_target`` from
    all poses (each batch (n, 4, 4); see :func:`closed_form_batch`); valid at every
    rotation angle, order-independent."""
    A, B = camera_T_targets, hand_T_bases
    q_A, q_B = consistent_quats_xyzw(A[:, :3, :3], B[:, :3, :3])
    K = product_matrices(q_A, q_B)
    X, Y, _, _ = closed_form_batch(
        K[None], A[None, :, :3, :3], A[None, :, :3, 3], B[None, :, :3, :3], B[None, :, :3, 3]
    )
    return X[0], Y[0]
