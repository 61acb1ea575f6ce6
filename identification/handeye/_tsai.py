"""Tsai & Lenz's rotation of the hand-eye transform ``A X = X B``, with its safeguards.

The start of :func:`kinfw.identification.handeye.solve_axxb`: :func:`tsai_rotation` solves
Tsai & Lenz (1989, eqs. 12 and 14) for ``hand_R_eye`` over the relative motions, leaving
out and re-signing motions near a half turn and re-solving about a first estimate that
turns by more than :data:`PRE_ROTATE_ABOVE_RAD`; :func:`largest_line_angle` measures the
spread of the motion axes (about one axis: the rotation is not determined).
"""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import matrix_from_rotation_vector, rotation_angle, skew

# The solver's logger: its messages are filtered as kinfw.identification.handeye's.
log = logging.getLogger("kinfw.identification.handeye")

#: Motions whose rotation axes all lie within this angle of each other are "about one axis".
PARALLEL_AXES_RAD = np.radians(1.0)
#: Above this rotation angle of X, Tsai's parameter tan(theta/2) u is re-solved in a
#: pre-rotated frame (it is infinite at pi).
PRE_ROTATE_ABOVE_RAD = np.radians(150.0)
#: Relative motions this close to a half turn have a quaternion sign that noise can flip.
HALF_TURN_BAND_RAD = np.radians(3.0)
#: Relative singular value below which Tsai's rotation system is taken as rank-deficient.
_RANK_TOL = 1e-10
#: The axis spread is reported exactly unless it is within this of pi/2 (its maximum).
_SPREAD_ATOL = 1e-3


def largest_line_angle(axes: NDArray[np.float64]) -> float:
    """Largest angle between the lines spanned by unit vectors (m, 3), radians.

    Exact (to ~1e-8 rad, the precision of ``arccos`` near 1), except that a value within
    ``_SPREAD_ATOL`` of pi/2, the largest possible, is returned as found. With ``d`` the
    angle between lines (a metric) and ``r`` the axes' principal direction, a lower bound
    ``L`` comes from two farthest-point sweeps; a pair farther apart than ``L`` has
    ``d(a, r) + d(b, r) > L``, so only axes with ``d(a, r) > L - max d(., r)`` are
    compared pairwise (in blocks of rows). That keeps the O(m^2) part small both for
    nearly parallel axes and for widely spread ones.

    Parameters
    ----------
    axes : ndarray, shape (m, 3)
        Unit vectors (rotation axes); a vector and its opposite span the same line.

    Returns
    -------
    float
        The largest angle between two of the lines, radians, in [0, pi/2].
    """
    r = np.linalg.eigh(axes.T @ axes)[1][:, -1]
    to_r = _line_angles(axes, r)
    lower = 0.0
    k = int(np.argmax(to_r))
    for _ in range(2):
        sweep = _line_angles(axes, axes[k])
        k = int(np.argmax(sweep))
        lower = max(lower, float(sweep[k]))
    if lower >= np.pi / 2 - _SPREAD_ATOL:
        return lower
    candidates = axes[to_r >= lower - to_r.max() - 1e-7]
    rows = max(1, (1 << 22) // len(candidates))
    smallest = min(
        float(np.abs(candidates[k : k + rows] @ candidates.T).min())
        for k in range(0, len(candidates), rows)
    )
    return max(lower, float(np.arccos(min(smallest, 1.0))))


def _line_angles(axes: NDArray[np.float64], axis: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angles in [0, pi/2] between the lines of unit vectors (m, 3) and of ``axis``."""
    return np.arccos(np.minimum(np.abs(axes @ axis), 1.0))


def tsai_rotation(
    rotvecs_A: NDArray[np.float64], rotvecs_B: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``hand_R_eye`` by Tsai & Lenz with the half-turn safeguards; and the final system's
    singular values (see :func:`kinfw.identification.handeye.solve_axxb`, Notes).

    Parameters
    ----------
    rotvecs_A : ndarray, shape (m, 3)
        Rotation vectors of the hand's relative motions ``A_ij``, in the hand frame, rad.
    rotvecs_B : ndarray, shape (m, 3)
        Rotation vectors of the same motions seen by the eye, ``B_ij``, in the eye frame,
        rad.

    Returns
    -------
    hand_R_eye : ndarray, shape (3, 3)
        The rotation of ``X``.
    singular_values : ndarray, shape (3,)
        Singular values of Tsai's stacked rotation system as finally solved, descending.
    """
    P_As, P_Bs = _modified_rodrigues(rotvecs_A), _modified_rodrigues(rotvecs_B)
    half_turn = np.linalg.norm(rotvecs_A, axis=1) > np.pi - HALF_TURN_BAND_RAD
    first = ~half_turn
    if np.any(half_turn) and (
        not np.any(first)
        or largest_line_angle(
            rotvecs_A[first] / np.linalg.norm(rotvecs_A[first], axis=1, keepdims=True)
        )
        < PARALLEL_AXES_RAD
    ):
        first = np.ones_like(half_turn)
    R0, singular_values = _solve_tsai(P_As[first], P_Bs[first])
    if not np.any(half_turn) and rotation_angle(R0) <= PRE_ROTATE_ABOVE_RAD:
        return R0, singular_values  # the first estimate is final
    # Signs of the half-turn motions: the ones that agree with the first estimate.
    flip = half_turn & (np.einsum("ki,ij,kj->k", P_As, R0, P_Bs) < 0.0)
    P_Bs = np.where(flip[:, None], -P_Bs, P_Bs)
    if rotation_angle(R0) <= PRE_ROTATE_ABOVE_RAD:
        R0 = np.eye(3)
    else:
        log.debug(
            "X turns by %.1f deg: re-solving about the first estimate",
            np.degrees(rotation_angle(R0)),
        )
    R_prime, singular_values = _solve_tsai(P_As, P_Bs @ R0.T)
    return R_prime @ R0, singular_values


def _modified_rodrigues(rotvecs: NDArray[np.float64]) -> NDArray[np.float64]:
    """Tsai's ``P = 2 sin(theta/2) u`` from rotation vectors ``theta u`` (m, 3)."""
    theta = np.linalg.norm(rotvecs, axis=1, keepdims=True)
    return np.sinc(theta / (2.0 * np.pi)) * rotvecs  # sinc(x) = sin(pi x) / (pi x)


def _solve_tsai(
    P_As: NDArray[np.float64], P_Bs: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Solve ``skew(P_A + P_B) P'_X = P_B - P_A`` (Tsai & Lenz eq. 12) by least squares.

    Returns the rotation by ``2 atan(|P'_X|)`` about ``P'_X`` (eq. 14), or the half turn
    about the null vector when the stacked system has lost rank (X turns by pi), and the
    stacked system's singular values.
    """
    M = skew(P_As + P_Bs).reshape(-1, 3)
    U, s, Vt = np.linalg.svd(M, full_matrices=False)
    if s[-1] <= _RANK_TOL * s[0]:
        return matrix_from_rotation_vector(np.pi * Vt[-1]), s
    P_prime = Vt.T @ ((U.T @ (P_Bs - P_As).reshape(-1)) / s)
    tan_half = np.linalg.norm(P_prime)
    if tan_half == 0.0:
        return np.eye(3), s
    return matrix_from_rotation_vector(2.0 * np.arctan(tan_half) * P_prime / tan_half), s
