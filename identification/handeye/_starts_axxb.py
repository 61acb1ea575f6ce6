"""Closed forms of hand-eye ``A X = X B``: Park & Martin (1994), Andreff, Horaud &
Espiau (2001) and Daniilidis (1999), vectorised.

``A[i] = base_T_hand`` (forward kinematics), ``B[i] = camera_T_target`` (camera
extrinsics); ``X = hand_T_camera`` and ``Y = base_T_target = A[i] @ X @ B[i]`` for all ``i``
(the conventions of :func:`kinfw.identification.handeye.solve_axxb`). The closed forms use the
relative motions of every pair ``i < j``::

    A_ij X = X B_ij,   A_ij = inv(A[j]) @ A[i],   B_ij = B[j] @ inv(B[i])

(OpenCV's ``calibrateHandEye`` builds the same ``Hgij``, ``Hcij``), and ``Y`` is then
the average of ``A[i] @ X @ B[i]`` on SE(3) (chordal L2 mean). Every method returns
``(X, Y)`` as ``(4, 4)`` arrays in the input length unit, or raises
:class:`~kinfw.identification.handeye.StartError` when its system cannot determine the
answer.

Length unit. Park and Daniilidis' rotation do not use lengths. Andreff's and Daniilidis'
systems put lengths and rotation entries in one linear system, so their noisy solutions
depend on the length unit (OpenCV's change by up to 135 deg between m and mm, issue 13):
here the lengths are divided by the RMS length of the relative motions before the solve
and the translations multiplied back after, which makes every method exactly
equivariant to the unit.

Sample order. Sums over unordered pairs are invariant to the order of the samples when a
pair and its reverse give the same equations up to an orthogonal factor (Park's ``M``,
Andreff's rotation rows, Daniilidis' rows). Where they do not (the translation rows of
Park and Andreff), both orders of every pair are used, as in ``solve_axxb``.

:func:`kinfw.identification.handeye.candidate_starts` runs them all on one
:func:`prepare_axxb`, through the one registry of starts,
:data:`kinfw.identification.handeye.START_METHODS`.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import (
    average_transform,
    inverse_transform,
    project_to_rotation,
    quat_xyzw_from_matrix,
    rotation_vector_from_matrix,
    skew,
    transform_from_rotation_translation,
    transform_from_xyz_quat_xyzw,
)
from kinfw.identification.handeye._checks import (
    RANK_TOL,
    StartError,
    check_start_poses,
    length_scale,
    nearest_rotation,
    solve_normal,
)

Pose = NDArray[np.float64]


@lru_cache(maxsize=64)
def _pairs(n: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices ``i < j`` of every unordered pair of ``n`` poses (cached: read-only)."""
    i, j = np.triu_indices(n, 1)
    i.flags.writeable = j.flags.writeable = False
    return i, j


def prepare_axxb(A: ArrayLike, B: ArrayLike, method: str) -> tuple[Pose, Pose, Pose, Pose]:
    """Checked poses ``A`` (``base_T_hand``), ``B`` (``camera_T_target``), each (n, 4, 4),
    and their relative motions ``A_ij = inv(A[j]) A[i]``, ``B_ij = B[j] inv(B[i])``, each
    (n (n - 1) / 2, 4, 4) over the pairs ``i < j``: the arguments of
    closed forms' cores (:data:`kinfw.identification.handeye.START_METHODS`). Errors as
    :class:`StartError` prefixed with ``method``."""
    base_T_hands, camera_T_targets = check_start_poses(A, B, method)
    return base_T_hands, camera_T_targets, *_relative_motions(base_T_hands, camera_T_targets)


def _relative_motions(base_T_hands: Pose, camera_T_targets: Pose) -> tuple[Pose, Pose]:
    """``A_ij = inv(A[j]) A[i]`` and ``B_ij = B[j] inv(B[i])`` for every pair ``i < j``."""
    i, j = _pairs(len(base_T_hands))
    A_inv = inverse_transform(base_T_hands)
    B_inv = inverse_transform(camera_T_targets)
    return A_inv[j] @ base_T_hands[i], camera_T_targets[j] @ B_inv[i]


def _scaled(T: Pose, s: float) -> Pose:
    """Poses with their translations divided by ``s``."""
    out = T.copy()
    out[..., :3, 3] /= s
    return out


def _target_from_hand_eye(base_T_hands: Pose, hand_T_camera: Pose, camera_T_targets: Pose) -> Pose:
    """``Y = base_T_target``: chordal L2 mean of ``A[i] @ X @ B[i]`` over the poses."""
    return average_transform(base_T_hands @ hand_T_camera @ camera_T_targets)


def _translation_axxb(
    A_ijs: Pose, B_ijs: Pose, hand_R_camera: NDArray[np.float64], method: str
) -> NDArray[np.float64]:
    """``t_X`` from ``(I - R_A) t_X = t_A - R_X t_B`` over both orders of every pair.

    Tsai & Lenz 1989 eq. (15) / Park & Martin 1994 eq. (16): linear least squares, solved
    by the 3x3 normal equations. ``(I - R_A)^T (I - R_A) = 2 I - R_A - R_A^T`` is the same
    for a motion and its inverse; the right-hand sides add.
    """
    R_As, t_As, R_Bs, t_Bs = A_ijs[:, :3, :3], A_ijs[:, :3, 3], B_ijs[:, :3, :3], B_ijs[:, :3, 3]
    C = np.eye(3) - R_As
    d = t_As - t_Bs @ hand_R_camera.T
    # Reverse motions: R_A^T, -R_A^T t_A, -R_B^T t_B.
    C_rev = np.eye(3) - np.swapaxes(R_As, 1, 2)
    d_rev = -np.einsum("kji,kj->ki", R_As, t_As) + np.einsum(
        "ij,kli,kl->kj", hand_R_camera.T, R_Bs, t_Bs
    )
    N = 2.0 * np.einsum("kji,kjl->il", C, C)
    r = np.einsum("kji,kj->i", C, d) + np.einsum("kji,kj->i", C_rev, d_rev)
    return solve_normal(
        N,
        r,
        f"{method}: the translation of X is not determined: all motions turn about one "
        "axis (the translation along it is free); add motions about another axis",
    )


def park_axxb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """``X = hand_T_camera`` and ``Y = base_T_target`` by Park & Martin (1994).

    Parameters
    ----------
    A : array_like, shape (n, 4, 4)
        ``base_T_hand`` at each pose (robot forward kinematics), any length unit.
    B : array_like, shape (n, 4, 4)
        ``camera_T_target`` at each pose (camera extrinsics), the same unit as ``A``.

    Returns
    -------
    X : ndarray, shape (4, 4)
        ``hand_T_camera``, in the input length unit.
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
    return park_prepared(*prepare_axxb(A, B, "park_axxb"))


def park_prepared(
    base_T_hands: Pose, camera_T_targets: Pose, A_ijs: Pose, B_ijs: Pose
) -> tuple[Pose, Pose]:
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
    hand_R_camera = project_to_rotation(Mt) if s[2] <= RANK_TOL * s[0] else U @ Vt
    if np.linalg.det(hand_R_camera) < 0.0:
        hand_R_camera = project_to_rotation(Mt)
    hand_p_camera = _translation_axxb(A_ijs, B_ijs, hand_R_camera, method)
    X = transform_from_rotation_translation(hand_R_camera, hand_p_camera)
    return X, _target_from_hand_eye(base_T_hands, X, camera_T_targets)


def andreff_axxb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """``X = hand_T_camera`` and ``Y = base_T_target`` by Andreff, Horaud & Espiau (2001).

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
    return andreff_prepared(*prepare_axxb(A, B, "andreff_axxb"))


def andreff_prepared(
    base_T_hands: Pose, camera_T_targets: Pose, A_ijs: Pose, B_ijs: Pose
) -> tuple[Pose, Pose]:
    """:func:`andreff_axxb` on checked poses and their relative motions."""
    method = "andreff_axxb"
    scale = length_scale(A_ijs[:, :3, 3], B_ijs[:, :3, 3])
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
    x = solve_normal(
        N,
        r,
        f"{method}: the linear system is rank-deficient: the motions turn about one axis, "
        "or nothing translates (the translations fix the scale of the rotation block)",
    )
    hand_R_camera = nearest_rotation(x[:9].reshape(3, 3), method)
    X = transform_from_rotation_translation(hand_R_camera, x[9:] * scale)
    return X, _target_from_hand_eye(base_T_hands, X, camera_T_targets)


#: Levi-Civita symbol: ``cross(a, b)_i = EPS[i, j, k] a_j b_k``.
_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise cross products of (m, 3) arrays (one einsum; ``np.cross`` is slower)."""
    return np.einsum("ijk,mj,mk->mi", _EPS, a, b)


def _quat_wxyz_multiply(p: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise Hamilton products of (m, 4) quaternions scalar first, ``(w, x, y, z)``:
    Daniilidis' layout, used only inside :func:`daniilidis_axxb` (the package's
    quaternions are scalar last)."""
    pw, pv, qw, qv = p[:, :1], p[:, 1:], q[:, :1], q[:, 1:]
    w = pw * qw - np.sum(pv * qv, axis=1, keepdims=True)
    return np.concatenate([w, pw * qv + qw * pv + _cross(pv, qv)], axis=1)


def _pair_dual_quats_wxyz(
    base_T_hands: Pose, camera_T_targets: Pose, A_ijs: Pose, B_ijs: Pose, scale: float
) -> tuple[NDArray[np.float64], ...]:
    """Real and dual parts ``(q, q')``, each (m, 4) ``(w, x, y, z)``, of ``A_ij`` and
    ``B_ij`` with lengths divided by ``scale``: ``q' = 1/2 (0, t) q`` (Daniilidis 1999,
    eq. (7)). The pairs' ``q`` are products of the poses' quaternions (2n conversions
    instead of n(n-1)), with the sign that makes ``w >= 0``."""
    n = len(base_T_hands)
    # (w, x, y, z) with w >= 0
    q = quat_xyzw_from_matrix(
        np.concatenate([base_T_hands[:, :3, :3], camera_T_targets[:, :3, :3]])
    )
    q = q[:, [3, 0, 1, 2]]
    conj = q * (1.0, -1.0, -1.0, -1.0)
    i, j = _pairs(n)
    out = []
    for q_ij, T_ijs in (
        (_quat_wxyz_multiply(conj[j], q[i]), A_ijs),
        (_quat_wxyz_multiply(q[n + j], conj[n + i]), B_ijs),
    ):
        q_ij *= np.where(q_ij[:, :1] < 0.0, -1.0, 1.0)
        t = T_ijs[:, :3, 3] / scale
        w, v = q_ij[:, :1], q_ij[:, 1:]
        dual_w = -0.5 * np.sum(t * v, axis=1, keepdims=True)
        dual_v = 0.5 * (w * t + _cross(t, v))
        out += [q_ij, np.concatenate([dual_w, dual_v], axis=1)]
    return tuple(out)


def daniilidis_axxb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """``X = hand_T_camera`` and ``Y = base_T_target`` by Daniilidis (1999), dual quaternions.

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
    return daniilidis_prepared(*prepare_axxb(A, B, "daniilidis_axxb"))


def daniilidis_prepared(
    base_T_hands: Pose, camera_T_targets: Pose, A_ijs: Pose, B_ijs: Pose
) -> tuple[Pose, Pose]:
    """:func:`daniilidis_axxb` on checked poses and their relative motions."""
    method = "daniilidis_axxb"
    scale = length_scale(A_ijs[:, :3, 3], B_ijs[:, :3, 3])
    qa, qa_d, qb, qb_d = _pair_dual_quats_wxyz(base_T_hands, camera_T_targets, A_ijs, B_ijs, scale)
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
    # wxyz -> xyzw at the boundary of the Daniilidis code
    hand_R_camera = transform_from_xyz_quat_xyzw(np.zeros(3), q[[1, 2, 3, 0]])[:3, :3]
    # t = 2 q' q*: vector part.
    w, v, w_d, v_d = q[0], q[1:], q_d[0], q_d[1:]
    hand_p_camera = 2.0 * (w * v_d - w_d * v - np.cross(v_d, v)) * scale
    X = transform_from_rotation_translation(hand_R_camera, hand_p_camera)
    return X, _target_from_hand_eye(base_T_hands, X, camera_T_targets)
