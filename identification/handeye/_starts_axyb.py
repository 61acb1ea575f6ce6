"""Closed forms of robot-world and hand-eye ``A = X B Y``: Shah (2013) and Li, Wang &
Wu (2010), vectorised.

``A[i] = camera_T_target``, ``B[i] = hand_T_base``; ``X = camera_T_hand``,
``Y = base_T_target`` with ``A[i] = X @ B[i] @ Y`` (the conventions of
:func:`kinfw.identification.handeye.solve_axyb`). OpenCV's ``calibrateRobotWorldHandEye`` returns
``gripper2cam = X`` and ``base2world = inv(Y)``. Every method returns ``(X, Y)`` as
``(4, 4)`` arrays in the input length unit, or raises
:class:`~kinfw.identification.handeye.StartError` when its system cannot determine the
answer.

Length unit. Shah's rotation does not use lengths. Li's system puts lengths and rotation
entries in one linear system, so its noisy solution depends on the length unit: here the
lengths are divided by their RMS before the solve and the translations multiplied back
after, which makes it exactly equivariant to the unit (OpenCV's is not).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import transform_from_rotation_translation
from kinfw.identification.handeye._checks import (
    RANK_TOL,
    StartError,
    check_start_poses,
    length_scale,
    nearest_rotation,
    solve_normal,
)

Pose = NDArray[np.float64]


def shah_axyb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """``X = camera_T_hand`` and ``Y = base_T_target`` of ``A = X B Y`` by Shah (2013).

    Parameters
    ----------
    A : array_like, shape (n, 4, 4)
        ``camera_T_target`` at each pose (camera extrinsics), any length unit.
    B : array_like, shape (n, 4, 4)
        ``hand_T_base`` at each pose (inverse forward kinematics), the same unit.

    Returns
    -------
    X : ndarray, shape (4, 4)
        ``camera_T_hand`` (OpenCV's ``gripper2cam``), in the input length unit.
    Y : ndarray, shape (4, 4)
        ``base_T_target`` (the inverse of OpenCV's ``base2world``).

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
    return shah_checked(*check_start_poses(A, B, "shah_axyb"))


def shah_checked(camera_T_targets: Pose, hand_T_bases: Pose) -> tuple[Pose, Pose]:
    """:func:`shah_axyb` on checked poses."""
    method = "shah_axyb"
    R_As, t_As = camera_T_targets[:, :3, :3], camera_T_targets[:, :3, 3]
    R_Bs, t_Bs = hand_T_bases[:, :3, :3], hand_T_bases[:, :3, 3]
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
    camera_R_hand = nearest_rotation(x, method)
    base_R_target = nearest_rotation(y, method).T
    # [I, R_X R_B] (t_X, t_Y) = t_A - R_X t_B, normal equations in closed form.
    G = camera_R_hand @ R_Bs  # (n, 3, 3)
    d = t_As - t_Bs @ camera_R_hand.T
    N = np.zeros((6, 6))
    N[:3, :3] = n * np.eye(3)
    N[:3, 3:] = G.sum(axis=0)
    N[3:, :3] = N[:3, 3:].T
    N[3:, 3:] = n * np.eye(3)
    r = np.concatenate([d.sum(axis=0), np.einsum("kji,kj->i", G, d)])
    t = solve_normal(
        N,
        r,
        f"{method}: the translations are not determined: the rotations of B do not vary",
    )
    X = transform_from_rotation_translation(camera_R_hand, t[:3])
    Y = transform_from_rotation_translation(base_R_target, t[3:])
    return X, Y


def li_axyb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """``X = camera_T_hand`` and ``Y = base_T_target`` of ``A = X B Y`` by Li et al. (2010).

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
    return li_checked(*check_start_poses(A, B, "li_axyb"))


def li_checked(camera_T_targets: Pose, hand_T_bases: Pose) -> tuple[Pose, Pose]:
    """:func:`li_axyb` on checked poses."""
    method = "li_axyb"
    scale = length_scale(camera_T_targets[:, :3, 3], hand_T_bases[:, :3, 3])
    R_As, t_As = camera_T_targets[:, :3, :3], camera_T_targets[:, :3, 3] / scale
    R_Bs, t_Bs = hand_T_bases[:, :3, :3], hand_T_bases[:, :3, 3] / scale
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
    base_R_target = nearest_rotation(sol[:9].reshape(3, 3), method).T
    camera_R_hand = nearest_rotation(sol[9:18].reshape(3, 3), method)
    X = transform_from_rotation_translation(camera_R_hand, sol[21:] * scale)
    Y = transform_from_rotation_translation(base_R_target, -base_R_target @ sol[18:21] * scale)
    return X, Y
