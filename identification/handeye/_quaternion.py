"""Closed-form start of the maximum-likelihood hand-eye (:mod:`kinfw.identification.handeye`):
``P, Q`` of ``M[i] ≈ P N[i] Q`` from quaternions -- the top singular pair of the mean
product matrix (Hirsh et al.'s fixed point, the quaternion counterpart of Shah's 2013
Kronecker solution: no singularity at any rotation angle) and the translations by linear
least squares -- for all poses at once or for a batch of pose subsets (the consensus
start).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import transform_from_rotation_translation

__all__ = [
    "closed_form_batch",
    "closed_form_start",
    "consistent_quats",
    "product_matrices",
    "product_tensor",
]


@lru_cache(maxsize=1)
def product_tensor() -> NDArray:
    """``T[a, b]`` = ``K`` of the basis quaternions ``e_a``, ``e_b``: ``K`` is bilinear in
    ``(q_M, q_N)``, so ``K_i = sum_ab q_M[i, a] q_N[i, b] T[a, b]`` (one einsum)."""
    from kinfw.identification.handeye._axyb_iteration import (
        left_product_matrix_xyzw,
        right_product_matrix_xyzw,
    )

    conj = np.array([-1.0, -1.0, -1.0, 1.0])
    E = np.eye(4)
    T = (left_product_matrix_xyzw(E)[:, None] @ right_product_matrix_xyzw(E * conj)[None]) * conj
    T.setflags(write=False)
    return T


def product_matrices(q_M: NDArray, q_N: NDArray) -> NDArray:
    """Per pose ``K_i`` with ``q_P = (mean_i K_i) q_Q`` at a fit (see axb_iteration):
    ``L(q_M) R(q_N^-1) diag(-1, -1, -1, 1)``."""
    return np.einsum("na,nb,abjk->njk", q_M, q_N, product_tensor(), optimize=False)


def closed_form_batch(
    K: NDArray, R_M: NDArray, t_M: NDArray, R_N: NDArray, t_N: NDArray
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Closed-form P, Q for a batch of subsets: ``K`` (s, m, 4, 4), poses (s, m, ...).

    Rotations: top singular pair of ``mean K`` (Hirsh's fixed point, Shah's closed form
    in quaternions; no singularity at any angle). Translations: linear least squares of
    ``t_P + R_P R_N t_Q = t_M - R_P t_N`` (6 unknowns), by the normal equations.

    Returns ``P``, ``Q`` (s, 4, 4) and their rotations' quaternions ``q_P``, ``q_Q``
    (s, 4), xyzw: for a pose with product matrix ``K_i``, ``|q_P^T K_i q_Q|`` is the
    cosine of half its residual rotation angle.
    """
    from kinfw.identification.handeye._axyb_iteration import rotation_from_quat_xyzw

    U, _, Vt = np.linalg.svd(K.mean(axis=1))
    R_P = rotation_from_quat_xyzw(U[:, :, 0])
    R_Q = rotation_from_quat_xyzw(Vt[:, 0, :])
    s, m = R_M.shape[:2]
    C = np.concatenate([np.broadcast_to(np.eye(3), (s, m, 3, 3)), R_P[:, None] @ R_N], axis=3)
    rhs = t_M - t_N @ np.swapaxes(R_P, 1, 2)
    C = C.reshape(s, 3 * m, 6)
    Ct = np.swapaxes(C, 1, 2)
    CtC = Ct @ C
    CtC += 1e-12 * np.eye(6) * np.trace(CtC, axis1=1, axis2=2)[:, None, None]
    sol = np.linalg.solve(CtC, Ct @ rhs.reshape(s, 3 * m, 1))[..., 0]
    P = transform_from_rotation_translation(R_P, sol[:, :3])
    Q = transform_from_rotation_translation(R_Q, sol[:, 3:])
    return P, Q, U[:, :, 0], Vt[:, 0, :]


def consistent_quats(R_M: NDArray, R_N: NDArray) -> tuple[NDArray, NDArray]:
    """:func:`kinfw.identification.handeye.consistent_quats_xyzw`, both batches'
    quaternions in one call."""
    from kinfw.geometry import quat_xyzw_from_matrix

    n = len(R_M)
    q = quat_xyzw_from_matrix(np.concatenate([R_M, R_N]))
    q_M, q_N = q[:n], q[n:]
    Z = (q_M[:, :, None] * q_N[:, None, :]).reshape(n, 16)
    v = np.linalg.eigh(Z.T @ Z)[1][:, -1]
    return np.where((Z @ v < 0.0)[:, None], -q_M, q_M), q_N


def closed_form_start(M: NDArray, N: NDArray) -> tuple[NDArray, NDArray]:
    """Closed-form ``P, Q`` of ``M[i] ≈ P N[i] Q`` from all poses (see
    :func:`closed_form_batch`); valid at every rotation angle, order-independent."""
    q_M, q_N = consistent_quats(M[:, :3, :3], N[:, :3, :3])
    K = product_matrices(q_M, q_N)
    P, Q, _, _ = closed_form_batch(
        K[None], M[None, :, :3, :3], M[None, :, :3, 3], N[None, :, :3, :3], N[None, :, :3, 3]
    )
    return P[0], Q[0]
