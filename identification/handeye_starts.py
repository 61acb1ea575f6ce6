"""Closed-form starts for hand-eye ``A X = X B`` and robot-world ``A = X B Y``, vectorised.

Every function here is a pure function of the absolute poses, in the conventions of the
solvers (:func:`identification.handeye.solve_axxb` and :func:`identification.axb.solve_axyb`):

``A X = X B`` (eye-in-hand)
    ``A[i] = base_T_hand`` (forward kinematics), ``B[i] = eye_T_target`` (camera
    extrinsics); ``X = hand_T_eye`` and ``Y = base_T_target = A[i] @ X @ B[i]`` for all ``i``.
    The closed forms use the relative motions of every pair ``i < j``::

        A_ij X = X B_ij,   A_ij = inv(A[j]) @ A[i],   B_ij = B[j] @ inv(B[i])

    (OpenCV's ``calibrateHandEye`` builds the same ``Hgij``, ``Hcij``), and ``Y`` is then
    the average of ``A[i] @ X @ B[i]`` on SE(3) (chordal L2 mean).
``A = X B Y`` (robot-world and hand-eye)
    ``A[i] = camera_T_target``, ``B[i] = hand_T_root``; ``X = camera_T_hand``,
    ``Y = root_T_target`` with ``A[i] = X @ B[i] @ Y``. OpenCV's
    ``calibrateRobotWorldHandEye`` returns ``gripper2cam = X`` and ``base2world = inv(Y)``.

Every method returns ``(X, Y)`` as ``(4, 4)`` arrays in the input length unit, or raises
:class:`StartError` (a ``ValueError``) when its system cannot determine the answer.
:func:`rank_starts` scores candidates by their absolute-pose residuals.

Length unit. Park, Daniilidis' rotation, and Shah's rotation do not use lengths. Andreff's,
Daniilidis' and Li's systems put lengths and rotation entries in one linear system, so
their noisy solutions depend on the length unit (OpenCV's change by up to 135 deg between
m and mm, issue 13). Here the lengths are divided by the RMS length of the data before the
solve and the translations multiplied back after, which makes every method exactly
equivariant to the unit (the answer in mm is 1000 x the answer in m).

Sample order. Sums over unordered pairs are invariant to the order of the samples when a
pair and its reverse give the same equations up to an orthogonal factor (Park's ``M``,
Andreff's rotation rows, Daniilidis' rows). Where they do not (the translation rows of
Park and Andreff), both orders of every pair are used, as in ``solve_axxb``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.transforms import (
    average_transform,
    check_transform,
    inverse_transform,
    project_to_rotation,
    quat_xyzw_from_matrix,
    rotation_angle,
    rotation_vector_from_matrix,
    skew,
    transform_from_rotation_translation,
    transform_from_xyz_quat_xyzw,
)

__all__ = [
    "AXXB_STARTS",
    "AXYB_STARTS",
    "ORTHONORMAL_TOL",
    "RankedStart",
    "StartError",
    "andreff_axxb",
    "candidate_starts",
    "check_pose_pairs",
    "daniilidis_axxb",
    "li_axyb",
    "park_axxb",
    "rank_starts",
    "shah_axyb",
]

log = logging.getLogger(__name__)

#: Relative singular value below which a linear system is taken as rank-deficient.
RANK_TOL = 1e-10
#: Accepted orthonormality error of input rotations of every hand-eye solver: real data
#: printed with six significant digits is off by ~1e-6 (Tabb DS1: 1.2e-6); accepted
#: rotations are re-orthonormalised.
ORTHONORMAL_TOL = 1e-5

Pose = NDArray[np.float64]


class StartError(ValueError):
    """A closed form cannot determine ``X`` (and ``Y``) from these poses; says why."""


# -- input ---------------------------------------------------------------------------------


def check_pose_pairs(
    A: ArrayLike,
    B: ArrayLike,
    *,
    error: type[ValueError] = ValueError,
    prefix: str = "",
    why: str = "two motions about different axes",
) -> tuple[Pose, Pose]:
    """Validate two pose batches (n, 4, 4) paired pose by pose, n >= 3: the inputs of
    every hand-eye solver here, in :mod:`identification.handeye` and in
    :mod:`identification.axb`.

    The checks of :func:`kinfw.transforms.check_transform`, on both batches in one pass
    (the hot path of a 3-view solve); rotations off by more than 1e-12 are
    re-orthonormalised (real data printed with six digits is off by ~1e-6). Errors are
    raised as ``error`` with ``prefix`` (e.g. ``"park_axxb: "``), naming the batch and
    the index; ``why`` says what three poses are needed for.
    """
    T_A, T_B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    for name, T in (("A", T_A), ("B", T_B)):
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise error(f"{prefix}{name}: expected shape (n, 4, 4), got {T.shape}")
    if T_A.shape != T_B.shape:
        raise error(
            f"{prefix}A and B must hold the same number of poses, got A {T_A.shape} "
            f"and B {T_B.shape}"
        )
    n = len(T_A)
    if n < 3:
        raise error(f"{prefix}at least 3 poses are needed ({why}), got {n}")
    T = np.concatenate([T_A, T_B])
    R = T[:, :3, :3]
    err = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2))
    bad = ~np.isfinite(T).all(axis=(1, 2)) | (np.abs(T[:, 3] - (0.0, 0.0, 0.0, 1.0)).max(1) > 0)
    bad |= ~(err <= ORTHONORMAL_TOL) | ~(np.linalg.det(R) > 0.0)
    if np.any(bad):
        k = int(np.argmax(bad))
        name, idx = ("A", k) if k < n else ("B", k - n)
        try:
            check_transform(T[k], name=f"{prefix}{name}[{idx}]", tol=ORTHONORMAL_TOL)
        except ValueError as e:
            raise error(str(e)) from e
        raise error(f"{prefix}{name}[{idx}]: not a rigid transform")  # pragma: no cover
    off = err > 1e-12
    if np.any(off):
        T = T.copy()
        T[off, :3, :3] = project_to_rotation(R[off])
    return T[:n], T[n:]


def _check_pair(A: ArrayLike, B: ArrayLike, method: str) -> tuple[Pose, Pose]:
    """:func:`check_pose_pairs` for the closed forms (:class:`StartError`, named)."""
    return check_pose_pairs(A, B, error=StartError, prefix=f"{method}: ")


@lru_cache(maxsize=64)
def _pairs(n: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices ``i < j`` of every unordered pair of ``n`` poses (cached: read-only)."""
    i, j = np.triu_indices(n, 1)
    i.flags.writeable = j.flags.writeable = False
    return i, j


def _prepare_axxb(A: ArrayLike, B: ArrayLike, method: str) -> tuple[Pose, Pose, Pose, Pose]:
    """Checked poses ``A``, ``B`` and their relative motions ``A_ij``, ``B_ij``."""
    base_T_hands, eye_T_targets = _check_pair(A, B, method)
    return base_T_hands, eye_T_targets, *_relative_motions(base_T_hands, eye_T_targets)


def _relative_motions(base_T_hands: Pose, eye_T_targets: Pose) -> tuple[Pose, Pose]:
    """``A_ij = inv(A[j]) A[i]`` and ``B_ij = B[j] inv(B[i])`` for every pair ``i < j``."""
    i, j = _pairs(len(base_T_hands))
    A_inv = inverse_transform(base_T_hands)
    B_inv = inverse_transform(eye_T_targets)
    return A_inv[j] @ base_T_hands[i], eye_T_targets[j] @ B_inv[i]


def _length_scale(*translations: NDArray[np.float64]) -> float:
    """RMS length over the given (m, 3) translations; 1 when all are zero."""
    t = np.concatenate([np.reshape(x, (-1, 3)) for x in translations])
    scale = float(np.sqrt(np.mean(np.sum(t**2, axis=1))))
    return scale if scale > 0.0 else 1.0


def _scaled(T: Pose, s: float) -> Pose:
    """Poses with their translations divided by ``s``."""
    out = T.copy()
    out[..., :3, 3] /= s
    return out


def _target_from_hand_eye(base_T_hands: Pose, hand_T_eye: Pose, eye_T_targets: Pose) -> Pose:
    """``Y = base_T_target``: chordal L2 mean of ``A[i] @ X @ B[i]`` over the poses."""
    return average_transform(base_T_hands @ hand_T_eye @ eye_T_targets)


def _solve_normal(N: NDArray[np.float64], r: NDArray[np.float64], what: str) -> NDArray:
    """Solve the symmetric positive semi-definite ``N x = r``; raise when rank-deficient."""
    w, V = np.linalg.eigh(N)
    if w[0] <= RANK_TOL * w[-1]:
        raise StartError(what)
    return V @ ((V.T @ r) / w)


def _translation_axxb(
    A_ijs: Pose, B_ijs: Pose, hand_R_eye: NDArray[np.float64], method: str
) -> NDArray[np.float64]:
    """``t_X`` from ``(I - R_A) t_X = t_A - R_X t_B`` over both orders of every pair.

    Tsai & Lenz 1989 eq. (15) / Park & Martin 1994 eq. (16): linear least squares, solved
    by the 3x3 normal equations. ``(I - R_A)^T (I - R_A) = 2 I - R_A - R_A^T`` is the same
    for a motion and its inverse; the right-hand sides add.
    """
    R_As, t_As, R_Bs, t_Bs = A_ijs[:, :3, :3], A_ijs[:, :3, 3], B_ijs[:, :3, :3], B_ijs[:, :3, 3]
    C = np.eye(3) - R_As
    d = t_As - t_Bs @ hand_R_eye.T
    # Reverse motions: R_A^T, -R_A^T t_A, -R_B^T t_B.
    C_rev = np.eye(3) - np.swapaxes(R_As, 1, 2)
    d_rev = -np.einsum("kji,kj->ki", R_As, t_As) + np.einsum(
        "ij,kli,kl->kj", hand_R_eye.T, R_Bs, t_Bs
    )
    N = 2.0 * np.einsum("kji,kjl->il", C, C)
    r = np.einsum("kji,kj->i", C, d) + np.einsum("kji,kj->i", C_rev, d_rev)
    return _solve_normal(
        N,
        r,
        f"{method}: the translation of X is not determined: all motions turn about one "
        "axis (the translation along it is free); add motions about another axis",
    )


# -- A X = X B -----------------------------------------------------------------------------


def park_axxb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """``X = hand_T_eye`` and ``Y = base_T_target`` by Park & Martin (1994).

    Parameters
    ----------
    A : array_like, shape (n, 4, 4)
        ``base_T_hand`` at each pose (robot forward kinematics), any length unit.
    B : array_like, shape (n, 4, 4)
        ``eye_T_target`` at each pose (camera extrinsics), the same unit as ``A``.

    Returns
    -------
    X : ndarray, shape (4, 4)
        ``hand_T_eye``, in the input length unit.
    Y : ndarray, shape (4, 4)
        ``base_T_target``, the chordal mean of ``A[i] @ X @ B[i]``.

    Raises
    ------
    StartError
        Bad shapes or matrices, fewer than 3 poses, or all motions about one axis.

    Notes
    -----
    Rotation (Park & Martin 1994, eqs. (10)-(12)): with ``alpha_ij = log(R_A_ij)`` and
    ``beta_ij = log(R_B_ij)`` (rotation vectors, radians), ``alpha = R_X beta`` for every
    motion, and the least-squares rotation is::

        M = sum_ij beta_ij alpha_ij^T,   R_X = (M^T M)^(-1/2) M^T,

    the orthogonal polar factor of ``M^T``, computed as ``U V^T`` from the SVD of ``M^T``
    (``OpenCV calibrateHandEyePark`` takes ``eigen(M^T M)``; the same matrix), with the
    determinant fixed to +1 in case noise makes it -1. It uses the same rotation
    information as Tsai & Lenz, weighted by the angles, so it degrades gracefully at
    small motions and has no singularity at ``R_X`` = half turn. A pair and its reverse
    give the same ``beta alpha^T``: the sum is invariant to sample order.

    Translation (eq. (16)): ``(I - R_A_ij) t_X = t_A_ij - R_X t_B_ij`` by linear least
    squares over both orders of every pair.

    References
    ----------
    F. C. Park and B. J. Martin, "Robot sensor calibration: solving AX = XB on the
    Euclidean group", IEEE Trans. Robotics and Automation 10(5), 717-721, 1994.
    """
    return _park(*_prepare_axxb(A, B, "park_axxb"))


def _park(base_T_hands: Pose, eye_T_targets: Pose, A_ijs: Pose, B_ijs: Pose) -> tuple[Pose, Pose]:
    """:func:`park_axxb` on checked poses and their relative motions."""
    method = "park_axxb"
    alphas = rotation_vector_from_matrix(A_ijs[:, :3, :3])
    betas = rotation_vector_from_matrix(B_ijs[:, :3, :3])
    Mt = alphas.T @ betas  # M^T = sum alpha beta^T
    U, s, Vt = np.linalg.svd(Mt)
    if s[1] <= RANK_TOL * s[0] or s[0] == 0.0:
        raise StartError(
            f"{method}: the rotation of X is not determined: the motions' rotation axes "
            f"span one direction (singular values of M {np.array2string(s, precision=3)}); "
            "add motions about another axis"
        )
    hand_R_eye = project_to_rotation(Mt) if s[2] <= RANK_TOL * s[0] else U @ Vt
    if np.linalg.det(hand_R_eye) < 0.0:
        hand_R_eye = project_to_rotation(Mt)
    hand_p_eye = _translation_axxb(A_ijs, B_ijs, hand_R_eye, method)
    X = transform_from_rotation_translation(hand_R_eye, hand_p_eye)
    return X, _target_from_hand_eye(base_T_hands, X, eye_T_targets)


def andreff_axxb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """``X = hand_T_eye`` and ``Y = base_T_target`` by Andreff, Horaud & Espiau (2001).

    Parameters and returns as :func:`park_axxb`.

    Raises
    ------
    StartError
        Bad shapes or matrices, fewer than 3 poses, or a rank-deficient linear system
        (motions about one axis, or no translation at all to fix the scale).

    Notes
    -----
    Andreff et al. (2001, eqs. (10), (15); OpenCV ``calibrateHandEyeAndreff``) write both
    ``R_A R_X = R_X R_B`` and ``(I - R_A) t_X + R_X t_B = t_A`` linearly in the 12
    unknowns ``x = (vec(R_X), t_X)`` (row-major ``vec``)::

        [ I_9 - R_A (x) R_B      0      ] [vec(R_X)]   [ 0  ]
        [ I_3 (x) t_B^T       I_3 - R_A ] [  t_X   ] = [ t_A],

    solved by linear least squares over all pairs, then ``R_X`` is the rotation nearest
    to the 3x3 block (eq. (15): scale to unit determinant, orthogonalise), and ``t_X`` is
    taken as solved. The rotation rows are homogeneous: only the translation rows fix
    the scale, and lengths and rotation entries are weighed against each other in one
    system, so the noisy answer depends on the length unit. Here the lengths are
    divided by their RMS over the relative motions (of ``t_A`` and ``t_B``) first and
    ``t_X`` is multiplied back after, which makes the result equivariant to the unit
    (OpenCV's is not). A pair and its reverse give the same rotation rows up to an
    orthogonal factor, but not the same translation rows: both orders are used. The
    normal equations are accumulated in closed form: ``(I - K)^T (I - K) = 2 I - K -
    K^T`` for the orthogonal ``K = R_A (x) R_B``.

    References
    ----------
    N. Andreff, R. Horaud and B. Espiau, "Robot hand-eye calibration using
    structure-from-motion", Int. J. Robotics Research 20(3), 228-248, 2001 (and "On-line
    hand-eye calibration", 3DIM 1999, which OpenCV cites).
    """
    return _andreff(*_prepare_axxb(A, B, "andreff_axxb"))


def _andreff(
    base_T_hands: Pose, eye_T_targets: Pose, A_ijs: Pose, B_ijs: Pose
) -> tuple[Pose, Pose]:
    """:func:`andreff_axxb` on checked poses and their relative motions."""
    method = "andreff_axxb"
    scale = _length_scale(A_ijs[:, :3, 3], B_ijs[:, :3, 3])
    A_ijs, B_ijs = _scaled(A_ijs, scale), _scaled(B_ijs, scale)
    R_As, t_As, R_Bs, t_Bs = A_ijs[:, :3, :3], A_ijs[:, :3, 3], B_ijs[:, :3, :3], B_ijs[:, :3, 3]
    m = len(A_ijs)
    # Rotation rows, both orders: 2 * sum (2 I - K - K^T).
    K = np.einsum("mij,mkl->ikjl", R_As, R_Bs).reshape(9, 9)  # sum over m of R_A (x) R_B
    N = np.zeros((12, 12))
    N[:9, :9] = 2.0 * (2.0 * m * np.eye(9) - K - K.T)
    # Translation rows of both orders: J = [I (x) t_B^T, I - R_A], rhs t_A.
    R_As2 = np.concatenate([R_As, np.swapaxes(R_As, 1, 2)])
    t_As2 = np.concatenate([t_As, -np.einsum("kji,kj->ki", R_As, t_As)])
    t_Bs2 = np.concatenate([t_Bs, -np.einsum("kji,kj->ki", R_Bs, t_Bs)])
    J = np.zeros((2 * m, 3, 12))
    J[:, 0, 0:3] = t_Bs2
    J[:, 1, 3:6] = t_Bs2
    J[:, 2, 6:9] = t_Bs2
    J[:, :, 9:] = np.eye(3) - R_As2
    N += np.einsum("kai,kaj->ij", J, J)
    r = np.einsum("kai,ka->i", J, t_As2)
    x = _solve_normal(
        N,
        r,
        f"{method}: the linear system is rank-deficient: the motions turn about one axis, "
        "or nothing translates (the translations fix the scale of the rotation block)",
    )
    hand_R_eye = _nearest_rotation(x[:9].reshape(3, 3), method)
    X = transform_from_rotation_translation(hand_R_eye, x[9:] * scale)
    return X, _target_from_hand_eye(base_T_hands, X, eye_T_targets)


def _nearest_rotation(M: NDArray[np.float64], method: str) -> NDArray[np.float64]:
    """Andreff's eq. (15) / OpenCV ``normalizeRotation``: the rotation nearest to ``M``
    after scaling it to determinant +1 (a negative determinant flips the sign)."""
    det = float(np.linalg.det(M))
    if not np.isfinite(det) or abs(det) < 1e-12 * max(float(np.abs(M).max()), 1e-300) ** 3:
        raise StartError(f"{method}: the solved rotation block is singular (det {det:.3g})")
    return project_to_rotation(np.sign(det) * M)


#: Levi-Civita symbol: ``cross(a, b)_i = EPS[i, j, k] a_j b_k``.
_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise cross products of (m, 3) arrays (one einsum; ``np.cross`` is slower)."""
    return np.einsum("ijk,mj,mk->mi", _EPS, a, b)


def _qmul(p: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise Hamilton products of (m, 4) quaternions ``(w, x, y, z)``."""
    pw, pv, qw, qv = p[:, :1], p[:, 1:], q[:, :1], q[:, 1:]
    w = pw * qw - np.sum(pv * qv, axis=1, keepdims=True)
    return np.concatenate([w, pw * qv + qw * pv + _cross(pv, qv)], axis=1)


def _pair_dual_quats(
    base_T_hands: Pose, eye_T_targets: Pose, A_ijs: Pose, B_ijs: Pose, scale: float
) -> tuple[NDArray[np.float64], ...]:
    """Real and dual parts ``(q, q')``, each (m, 4) ``(w, x, y, z)``, of ``A_ij`` and
    ``B_ij`` with lengths divided by ``scale``: ``q' = 1/2 (0, t) q`` (Daniilidis 1999,
    eq. (7)). The pairs' ``q`` are products of the poses' quaternions (2n conversions
    instead of n(n-1)), with the sign that makes ``w >= 0``."""
    n = len(base_T_hands)
    # (w, x, y, z) with w >= 0
    q = quat_xyzw_from_matrix(np.concatenate([base_T_hands[:, :3, :3], eye_T_targets[:, :3, :3]]))
    q = q[:, [3, 0, 1, 2]]
    conj = q * (1.0, -1.0, -1.0, -1.0)
    i, j = _pairs(n)
    out = []
    for q_ij, T_ijs in ((_qmul(conj[j], q[i]), A_ijs), (_qmul(q[n + j], conj[n + i]), B_ijs)):
        q_ij *= np.where(q_ij[:, :1] < 0.0, -1.0, 1.0)
        t = T_ijs[:, :3, 3] / scale
        w, v = q_ij[:, :1], q_ij[:, 1:]
        dual_w = -0.5 * np.sum(t * v, axis=1, keepdims=True)
        dual_v = 0.5 * (w * t + _cross(t, v))
        out += [q_ij, np.concatenate([dual_w, dual_v], axis=1)]
    return tuple(out)


def daniilidis_axxb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """``X = hand_T_eye`` and ``Y = base_T_target`` by Daniilidis (1999), dual quaternions.

    Parameters and returns as :func:`park_axxb`.

    Raises
    ------
    StartError
        Bad shapes or matrices, fewer than 3 poses, or a null space of dimension above 2
        (motions about one axis, or parallel screw axes).

    Notes
    -----
    With ``(a, a')`` and ``(b, b')`` the vector parts of the real and dual quaternions of
    ``A_ij`` and ``B_ij`` (scalar parts ``>= 0``, so that both have the same sign), and
    ``x = (q, q')`` the dual quaternion of ``X``, every motion gives six linear equations
    (Daniilidis 1999, eq. (31); OpenCV ``calibrateHandEyeDaniilidis``)::

        [ a - b    [a + b]x      0        0     ] [q ]
        [ a'- b'   [a'+ b']x   a - b   [a + b]x ] [q'] = 0.

    The stacked ``6m x 8`` matrix ``T`` has a two-dimensional null space (right singular
    vectors ``v7 = (u1, v1)``, ``v8 = (u2, v2)``); ``x = l1 v7 + l2 v8`` with ``|q| = 1``
    and ``q . q' = 0`` (eqs. (34)-(35)) is a quadratic in ``l1 / l2``, solved here as the
    isotropic direction of the 2x2 form ``[u1.v1, (u1.v2 + u2.v1)/2; ., u2.v2]`` (no
    division by its leading coefficient), keeping the root with the larger ``|q|``. It
    estimates rotation and translation together, which is why it is strong at small
    motions, and has no singularity in ``R_X``.

    The dual parts carry lengths, so the noisy null space depends on the length unit:
    the lengths are divided by their RMS over the relative motions first and the
    translation multiplied back after (OpenCV does not). A pair and its reverse give
    rows that differ by sign only: the result is invariant to sample order.

    References
    ----------
    K. Daniilidis, "Hand-eye calibration using dual quaternions", Int. J. Robotics
    Research 18(3), 286-298, 1999.
    """
    return _daniilidis(*_prepare_axxb(A, B, "daniilidis_axxb"))


def _daniilidis(
    base_T_hands: Pose, eye_T_targets: Pose, A_ijs: Pose, B_ijs: Pose
) -> tuple[Pose, Pose]:
    """:func:`daniilidis_axxb` on checked poses and their relative motions."""
    method = "daniilidis_axxb"
    scale = _length_scale(A_ijs[:, :3, 3], B_ijs[:, :3, 3])
    qa, qa_d, qb, qb_d = _pair_dual_quats(base_T_hands, eye_T_targets, A_ijs, B_ijs, scale)
    a, b, a_d, b_d = qa[:, 1:], qb[:, 1:], qa_d[:, 1:], qb_d[:, 1:]
    m = len(a)
    S = np.zeros((m, 6, 8))
    S[:, :3, 0] = a - b
    S[:, :3, 1:4] = skew(a + b)
    S[:, 3:, 0] = a_d - b_d
    S[:, 3:, 1:4] = skew(a_d + b_d)
    S[:, 3:, 4] = a - b
    S[:, 3:, 5:8] = skew(a + b)
    _, s, Vt = np.linalg.svd(S.reshape(-1, 8), full_matrices=False)
    if len(s) < 8 or s[5] <= RANK_TOL * s[0]:
        raise StartError(
            f"{method}: the motions do not determine X: the dual-quaternion system has a "
            f"null space of dimension > 2 (singular values "
            f"{np.array2string(s, precision=3)}); add motions about another axis"
        )
    v7, v8 = Vt[6], Vt[7]
    u1, w1, u2, w2 = v7[:4], v7[4:], v8[:4], v8[4:]
    # q . q' = 0 for x = l1 v7 + l2 v8: l^T Q l = 0.
    Q = np.array([[u1 @ w1, 0.5 * (u1 @ w2 + u2 @ w1)], [0.0, u2 @ w2]])
    Q[1, 0] = Q[0, 1]
    e, E = np.linalg.eigh(Q)
    if e[0] <= 0.0 <= e[1]:
        roots = [E @ np.array([np.sqrt(e[1]), sgn * np.sqrt(-e[0])]) for sgn in (1.0, -1.0)]
    else:  # noise: no exact isotropic direction; the eigenvector closest to one
        roots = [E[:, int(np.argmin(np.abs(e)))]]
    U2 = np.stack([u1, u2], axis=1)
    norms = [float(np.linalg.norm(U2 @ ell)) for ell in roots]
    ell = roots[int(np.argmax(norms))]
    x = (ell[0] * v7 + ell[1] * v8) / max(norms)
    q, q_d = x[:4], x[4:]
    q_d = q_d - (q @ q_d) * q  # exact orthogonality against rounding
    hand_R_eye = transform_from_xyz_quat_xyzw(np.zeros(3), q[[1, 2, 3, 0]])[:3, :3]
    # t = 2 q' q*: vector part.
    w, v, w_d, v_d = q[0], q[1:], q_d[0], q_d[1:]
    hand_p_eye = 2.0 * (w * v_d - w_d * v - np.cross(v_d, v)) * scale
    X = transform_from_rotation_translation(hand_R_eye, hand_p_eye)
    return X, _target_from_hand_eye(base_T_hands, X, eye_T_targets)


# -- A = X B Y -----------------------------------------------------------------------------


def shah_axyb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """``X = camera_T_hand`` and ``Y = root_T_target`` of ``A = X B Y`` by Shah (2013).

    Parameters
    ----------
    A : array_like, shape (n, 4, 4)
        ``camera_T_target`` at each pose (camera extrinsics), any length unit.
    B : array_like, shape (n, 4, 4)
        ``hand_T_root`` at each pose (inverse forward kinematics), the same unit.

    Returns
    -------
    X : ndarray, shape (4, 4)
        ``camera_T_hand`` (OpenCV's ``gripper2cam``), in the input length unit.
    Y : ndarray, shape (4, 4)
        ``root_T_target`` (the inverse of OpenCV's ``base2world``).

    Raises
    ------
    StartError
        Bad shapes or matrices, fewer than 3 poses, no distinct top singular value
        (the rotations of B do not vary), or a rank-deficient translation system.

    Notes
    -----
    Rotation (Shah 2013, eqs. (9)-(14); OpenCV ``calibrateRobotWorldHandEyeShah``): with
    row-major ``vec``, ``(R_A (x) R_B) vec(M) = vec(R_A M R_B^T)``, and
    ``R_A = R_X R_B R_Y`` gives ``R_A R_Y^T R_B^T = R_X``: every orthogonal
    ``R_A[i] (x) R_B[i]`` maps ``vec(R_Y^T)`` to ``vec(R_X)``. So the sum
    ``K = sum_i R_A[i] (x) R_B[i]`` has its largest singular value ``n`` with left and right
    singular vectors ``vec(R_X)`` and ``vec(R_Y^T)`` up to one common sign and scale;
    each block is scaled to determinant +1 and projected onto SO(3) (as OpenCV's
    ``normalizeRotation``). Lengths do not enter.

    Translation (Shah 2013, eq. (16)): ``t_A = R_X R_B t_Y + R_X t_B + t_X``, i.e.
    ``[I, R_X R_B[i]] (t_X, t_Y) = t_A[i] - R_X t_B[i]``, by linear least squares (6x6
    normal equations in closed form). OpenCV solves for ``(t_X, -R_Y^T t_Y)`` instead;
    noise-free the answers agree.

    References
    ----------
    M. Shah, "Solving the robot-world/hand-eye calibration problem using the Kronecker
    product", J. Mechanisms and Robotics 5(3), 031007, 2013.
    """
    return _shah(*_check_pair(A, B, "shah_axyb"))


def _shah(camera_T_targets: Pose, hand_T_roots: Pose) -> tuple[Pose, Pose]:
    """:func:`shah_axyb` on checked poses."""
    method = "shah_axyb"
    R_As, t_As = camera_T_targets[:, :3, :3], camera_T_targets[:, :3, 3]
    R_Bs, t_Bs = hand_T_roots[:, :3, :3], hand_T_roots[:, :3, 3]
    n = len(R_As)
    K = np.einsum("mij,mkl->ikjl", R_As, R_Bs).reshape(9, 9)
    U, s, Vt = np.linalg.svd(K)
    if s[0] - s[1] <= 1e-8 * s[0]:
        raise StartError(
            f"{method}: the rotations are not determined: the top singular value of "
            f"sum R_A (x) R_B is not distinct ({s[0]:.6g}, {s[1]:.6g}): the rotations of "
            "B barely vary; move the robot through different orientations"
        )
    x, y = U[:, 0].reshape(3, 3), Vt[0].reshape(3, 3)
    if np.linalg.det(x) < 0.0:
        x, y = -x, -y
    camera_R_hand = _nearest_rotation(x, method)
    root_R_target = _nearest_rotation(y, method).T
    # [I, R_X R_B] (t_X, t_Y) = t_A - R_X t_B, normal equations in closed form.
    G = camera_R_hand @ R_Bs  # (n, 3, 3)
    d = t_As - t_Bs @ camera_R_hand.T
    N = np.zeros((6, 6))
    N[:3, :3] = n * np.eye(3)
    N[:3, 3:] = G.sum(axis=0)
    N[3:, :3] = N[:3, 3:].T
    N[3:, 3:] = n * np.eye(3)
    r = np.concatenate([d.sum(axis=0), np.einsum("kji,kj->i", G, d)])
    t = _solve_normal(
        N,
        r,
        f"{method}: the translations are not determined: the rotations of B do not vary",
    )
    X = transform_from_rotation_translation(camera_R_hand, t[:3])
    Y = transform_from_rotation_translation(root_R_target, t[3:])
    return X, Y


def li_axyb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """``X = camera_T_hand`` and ``Y = root_T_target`` of ``A = X B Y`` by Li et al. (2010).

    Parameters, returns and raises as :func:`shah_axyb`.

    Notes
    -----
    Li, Wang & Wu (2010, eq. (19); OpenCV ``calibrateRobotWorldHandEyeLi``) write
    ``A Y^-1 = X B`` linearly in 24 unknowns: ``W = R_Y^T`` and ``R_X`` (row-major
    ``vec``), ``s = -R_Y^T t_Y`` and ``t_X``::

        [ R_A (x) I_3   -I_3 (x) R_B^T    0     0  ] [vec W  ]   [  0  ]
        [    0          -I_3 (x) t_B^T   R_A  -I_3 ] [vec R_X] = [ -t_A],
                                                    [  s    ]
                                                    [  t_X  ]

    stacked over the poses and solved by linear least squares; both 3x3 blocks are
    scaled to determinant +1 and projected onto SO(3), and the translations are taken
    as solved (``t_Y = -R_Y s``). The rotation rows are homogeneous and the translation
    rows fix the scale, so the noisy answer depends on the length unit: here the lengths
    are divided by their RMS over ``t_A`` and ``t_B`` first and the translations
    multiplied back after (OpenCV does not), which makes the result unit-equivariant.

    References
    ----------
    A. Li, L. Wang and D. Wu, "Simultaneous robot-world and hand-eye calibration using
    dual-quaternions and Kronecker product", Int. J. Physical Sciences 5(10), 1530-1536,
    2010.
    """
    return _li(*_check_pair(A, B, "li_axyb"))


def _li(camera_T_targets: Pose, hand_T_roots: Pose) -> tuple[Pose, Pose]:
    """:func:`li_axyb` on checked poses."""
    method = "li_axyb"
    scale = _length_scale(camera_T_targets[:, :3, 3], hand_T_roots[:, :3, 3])
    R_As, t_As = camera_T_targets[:, :3, :3], camera_T_targets[:, :3, 3] / scale
    R_Bs, t_Bs = hand_T_roots[:, :3, :3], hand_T_roots[:, :3, 3] / scale
    n = len(R_As)
    eye3 = np.eye(3)
    J = np.zeros((n, 12, 24))
    J[:, :9, :9] = np.einsum("mij,kl->mikjl", R_As, eye3).reshape(n, 9, 9)
    J[:, :9, 9:18] = -np.einsum("ij,mlk->mikjl", eye3, R_Bs).reshape(n, 9, 9)
    J[:, 9:, 9:18] = -np.einsum("ij,ml->mijl", eye3, t_Bs).reshape(n, 3, 9)
    J[:, 9:, 18:21] = R_As
    J[:, 9:, 21:] = -eye3
    rhs = np.zeros((n, 12))
    rhs[:, 9:] = -t_As
    sol, _, rank, sv = np.linalg.lstsq(J.reshape(-1, 24), rhs.reshape(-1), rcond=None)
    if sv[-1] <= RANK_TOL * sv[0]:
        raise StartError(
            f"{method}: the linear system is rank-deficient (rank {rank} of 24): the "
            "rotations of B barely vary, or nothing translates"
        )
    root_R_target = _nearest_rotation(sol[:9].reshape(3, 3), method).T
    camera_R_hand = _nearest_rotation(sol[9:18].reshape(3, 3), method)
    X = transform_from_rotation_translation(camera_R_hand, sol[21:] * scale)
    Y = transform_from_rotation_translation(root_R_target, -root_R_target @ sol[18:21] * scale)
    return X, Y


#: The closed forms by name, for ``A X = X B`` and ``A = X B Y``.
AXXB_STARTS: Mapping[str, Callable[[ArrayLike, ArrayLike], tuple[Pose, Pose]]] = {
    "park": park_axxb,
    "andreff": andreff_axxb,
    "daniilidis": daniilidis_axxb,
}
AXYB_STARTS: Mapping[str, Callable[[ArrayLike, ArrayLike], tuple[Pose, Pose]]] = {
    "shah": shah_axyb,
    "li": li_axyb,
}


def candidate_starts(
    A: ArrayLike, B: ArrayLike, *, problem: str = "axxb"
) -> dict[str, tuple[Pose, Pose]]:
    """Every closed form of ``problem`` that succeeds on these poses, by name.

    A method that raises :class:`StartError` is left out (logged at debug level); when
    all fail, the first method's error is raised.
    """
    cores: dict[str, Callable[..., tuple[Pose, Pose]]]
    if _methods(problem) is AXXB_STARTS:
        prepared = _prepare_axxb(A, B, "candidate_starts")
        cores = {"park": _park, "andreff": _andreff, "daniilidis": _daniilidis}
    else:
        prepared = _check_pair(A, B, "candidate_starts")
        cores = {"shah": _shah, "li": _li}
    out: dict[str, tuple[Pose, Pose]] = {}
    first: StartError | None = None
    for name, solve in cores.items():
        try:
            out[name] = solve(*prepared)
        except StartError as err:
            log.debug("candidate_starts: %s failed: %s", name, err)
            first = first or err
    if not out and first is not None:
        raise first
    return out


def _methods(problem: str) -> Mapping[str, Callable[[ArrayLike, ArrayLike], tuple[Pose, Pose]]]:
    if problem == "axxb":
        return AXXB_STARTS
    if problem == "axyb":
        return AXYB_STARTS
    raise ValueError(f"problem: expected 'axxb' or 'axyb', got {problem!r}")


@dataclass(frozen=True, slots=True)
class RankedStart:
    """One candidate start and its absolute-pose residual.

    Attributes
    ----------
    name : str
        The candidate's key in the mapping given to :func:`rank_starts`.
    X, Y : ndarray, shape (4, 4)
        The candidate, in the input length unit.
    rms_rotation_rad : float
        RMS over the poses of the rotation residual angle, radians (``A X = X B``: of
        ``Y^-1 A[i] X B[i]``; ``A = X B Y``: of ``A[i]^-1 X B[i] Y``).
    rms_translation : float
        RMS over the poses of the translation residual, input length unit
        (``|t(A[i] X B[i]) - t(Y)|`` in the base frame; ``|t(X B[i] Y) - t(A[i])|`` in the
        camera frame).
    score : float
        ``rms_rotation_rad / median + rms_translation / median``, medians over the
        candidates: unit-free, lower is better.
    """

    name: str
    X: Pose
    Y: Pose
    rms_rotation_rad: float
    rms_translation: float
    score: float


def rank_starts(
    A: ArrayLike,
    B: ArrayLike,
    starts: Mapping[str, tuple[ArrayLike, ArrayLike]],
    *,
    problem: str = "axxb",
) -> tuple[RankedStart, ...]:
    """Order candidate ``(X, Y)`` by their absolute-pose residuals, best first.

    Parameters
    ----------
    A, B : array_like, shape (n, 4, 4)
        The poses, as given to the closed forms of ``problem``.
    starts : mapping of str to (X, Y)
        Candidates, e.g. from :func:`candidate_starts`; ``X`` and ``Y`` of shape (4, 4).
    problem : {"axxb", "axyb"}, keyword-only
        ``"axxb"``: ``A[i] @ X @ B[i] = Y``; ``"axyb"``: ``A[i] = X @ B[i] @ Y``.

    Returns
    -------
    tuple of RankedStart
        Sorted by :attr:`RankedStart.score` (ties keep the mapping's order).

    Notes
    -----
    The rotation RMS (radians) and translation RMS (length) of each candidate are each
    divided by their median over the candidates and added, so neither the length unit
    nor a choice of weight between radians and lengths decides the order. A median of
    zero (all exact) is replaced by the smallest positive value, or 1.
    """
    _methods(problem)
    names = list(starts)
    if not names:
        raise ValueError("rank_starts: starts is empty: give at least one candidate (X, Y)")
    T_A, T_B = _check_pair(A, B, "rank_starts")
    Xs = check_transform(np.stack([np.asarray(starts[k][0], float) for k in names]), name="X")
    Ys = check_transform(np.stack([np.asarray(starts[k][1], float) for k in names]), name="Y")
    if problem == "axxb":
        predicted = T_A[None] @ Xs[:, None] @ T_B[None]  # (c, n, 4, 4)
        reference = np.broadcast_to(Ys[:, None], predicted.shape)
    else:
        predicted = Xs[:, None] @ T_B[None] @ Ys[:, None]
        reference = np.broadcast_to(T_A[None], predicted.shape)
    rot = rotation_angle(np.swapaxes(reference[..., :3, :3], -1, -2) @ predicted[..., :3, :3])
    trans = np.linalg.norm(predicted[..., :3, 3] - reference[..., :3, 3], axis=-1)
    rms_rot = np.sqrt(np.mean(rot**2, axis=1))
    rms_trans = np.sqrt(np.mean(trans**2, axis=1))
    score = rms_rot / _positive_median(rms_rot) + rms_trans / _positive_median(rms_trans)
    order = np.argsort(score, kind="stable")
    return tuple(
        RankedStart(
            name=names[k],
            X=Xs[k],
            Y=Ys[k],
            rms_rotation_rad=float(rms_rot[k]),
            rms_translation=float(rms_trans[k]),
            score=float(score[k]),
        )
        for k in order
    )


def _positive_median(values: NDArray[np.float64]) -> float:
    med = float(np.median(values))
    if med > 0.0:
        return med
    positive = values[values > 0.0]
    return float(positive.min()) if len(positive) else 1.0
