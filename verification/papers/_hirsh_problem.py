"""The simulated problem of Hirsh, DeSouza & Kak (2001), section 5: ``A[i] = X B[i] Y``.

A true pair, ``n`` hand poses and the exact camera calibrations (:func:`random_problem`,
steps 1-3 of :mod:`kinfw.verification.papers`), the paper's rotation noise
(:func:`rotations_about_random_axes`, :func:`rotate_about_random_axes`) and its error
measure (:func:`quaternion_angle`).

References
----------
R. L. Hirsh, G. N. DeSouza, A. C. Kak, "An iterative approach to the hand-eye and
base-world calibration problem", ICRA 2001, section 5.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import (
    check_transform,
    inverse_transform,
    matrix_from_rotation_vector,
    quat_xyzw_from_matrix,
    transform_from_rotation_translation,
    transform_from_xyz_quat_xyzw,
)
from kinfw.verification.evaluation import check_count

#: Half-widths of the cubes the true translations are drawn from, metres.
_X_TRANSLATION_M = 0.1


_Y_TRANSLATION_M = 1.0


def rotations_about_random_axes(
    rng: np.random.Generator, n: int, angle_rad: float
) -> NDArray[np.float64]:
    """``n`` rotations by exactly ``angle_rad`` about uniformly random axes, (n, 3, 3).

    The axes are normalised standard normal vectors (isotropic on the sphere), one per
    rotation, drawn from ``rng``.
    """
    angle_rad = float(angle_rad)
    if not (np.isfinite(angle_rad) and 0.0 <= angle_rad <= np.pi):
        raise ValueError(f"angle_rad: expected a finite angle in [0, pi], got {angle_rad}")
    n = check_count(n, "n", 0)
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    return matrix_from_rotation_vector(angle_rad * axes)


def rotate_about_random_axes(
    a_T_bs: ArrayLike, rng: np.random.Generator, angle_rad: float
) -> NDArray[np.float64]:
    """Noise of the paper's Fig. 4: each pose turned by ``angle_rad`` about its own axis.

    Parameters
    ----------
    a_T_bs : array_like, shape (n, 4, 4)
        Poses, e.g. the camera calibrations ``c_i_T_w``.
    rng : numpy.random.Generator
    angle_rad : float
        Rotation noise, radians: every pose is off by exactly this angle.

    Returns
    -------
    ndarray, shape (n, 4, 4)
        ``[a_R_b dR, a_p_b]``: the rotation about a uniformly random axis in frame b, so the
        translation is unchanged (the paper perturbs only the angles).
    """
    T = check_transform(a_T_bs, "a_T_bs")
    if T.ndim != 3:
        raise ValueError(f"a_T_bs: expected shape (n, 4, 4), got {T.shape}")
    dR = rotations_about_random_axes(rng, len(T), angle_rad)
    return transform_from_rotation_translation(T[:, :3, :3] @ dR, T[:, :3, 3])


def quaternion_angle(a_R_bs: ArrayLike, a_R_b_true: ArrayLike) -> NDArray[np.float64]:
    """The paper's error measure (section 5): angle between quaternions, radians.

    Parameters
    ----------
    a_R_bs : array_like, shape (..., 3, 3)
        Estimated rotations.
    a_R_b_true : array_like, shape (3, 3) or (..., 3, 3)
        The expected rotation.

    Returns
    -------
    ndarray, shape (...)
        ``2 acos(|<q, q_true>|)`` in [0, pi]: the rotation angle of ``R_true^T R``,
        evaluated as ``4 atan2(|q - q_true|, |q + q_true|)`` with the signs aligned, which
        stays accurate to rounding near 0 (module docstring).
    """
    q = quat_xyzw_from_matrix(a_R_bs)
    q_true = np.broadcast_to(quat_xyzw_from_matrix(a_R_b_true), q.shape)
    q = np.where(np.sum(q * q_true, axis=-1, keepdims=True) < 0.0, -q, q)
    return 4.0 * np.arctan2(
        np.linalg.norm(q - q_true, axis=-1), np.linalg.norm(q + q_true, axis=-1)
    )


def _random_rotations(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    """``n`` uniformly distributed (Haar) rotations, (n, 3, 3)."""
    quat_xyzw = rng.normal(size=(n, 4))
    return transform_from_xyz_quat_xyzw(np.zeros(3), quat_xyzw)[:, :3, :3]


@dataclass(frozen=True, slots=True)
class SimulatedProblem:
    """One simulated calibration: ``A[i] = X B[i] Y`` exactly (before noise)."""

    c_T_e: NDArray[np.float64]  # X
    b_T_w: NDArray[np.float64]  # Y
    e_T_bs: NDArray[np.float64]  # B, (n, 4, 4)
    c_T_ws: NDArray[np.float64]  # A, (n, 4, 4)


def random_problem(
    rng: np.random.Generator,
    views: int,
    *,
    hand_rotation_deg: float = 180.0,
    hand_translation_m: float = 0.5,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The paper's test program (section 5): a true pair and ``views`` exact calibrations.

    Parameters
    ----------
    rng : numpy.random.Generator
    views : int
        Number of hand poses (camera calibrations), >= 3.
    hand_rotation_deg : float, optional
        Largest rotation angle of a hand pose ``b_T_e[i]``, degrees (angles uniform in
        ``[0, hand_rotation_deg]``, axes uniformly random).
    hand_translation_m : float, optional
        Half-width of the cube the hand positions are drawn from, metres.

    Returns
    -------
    X, Y : ndarray, shape (4, 4)
        True hand-eye ``c_T_e`` and base-world ``b_T_w`` (module docstring, step 1).
    B : ndarray, shape (views, 4, 4)
        ``e_i_T_b``, the inverses of the hand poses.
    A : ndarray, shape (views, 4, 4)
        ``c_i_T_w = X @ B[i] @ Y``, noise-free.
    """
    p = draw_problem(
        rng, views, hand_rotation_deg=hand_rotation_deg, hand_translation_m=hand_translation_m
    )
    return p.c_T_e, p.b_T_w, p.e_T_bs, p.c_T_ws


def draw_problem(
    rng: np.random.Generator, views: int, *, hand_rotation_deg: float, hand_translation_m: float
) -> SimulatedProblem:
    """:func:`random_problem` as a :class:`SimulatedProblem` (the same draws)."""
    views = check_count(views, "views", 3)
    if not (np.isfinite(hand_rotation_deg) and 0.0 < hand_rotation_deg <= 180.0):
        raise ValueError(f"hand_rotation_deg: expected 0 < angle <= 180, got {hand_rotation_deg}")
    if not (np.isfinite(hand_translation_m) and hand_translation_m >= 0.0):
        raise ValueError(
            f"hand_translation_m: expected a finite length >= 0, got {hand_translation_m}"
        )
    R_true = _random_rotations(rng, 2)
    c_T_e = transform_from_rotation_translation(
        R_true[0], rng.uniform(-_X_TRANSLATION_M, _X_TRANSLATION_M, 3)
    )
    b_T_w = transform_from_rotation_translation(
        R_true[1], rng.uniform(-_Y_TRANSLATION_M, _Y_TRANSLATION_M, 3)
    )
    axes = rng.normal(size=(views, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    angles = rng.uniform(0.0, np.radians(hand_rotation_deg), views)
    b_T_es = transform_from_rotation_translation(
        matrix_from_rotation_vector(angles[:, None] * axes),
        rng.uniform(-hand_translation_m, hand_translation_m, (views, 3)),
    )
    e_T_bs = inverse_transform(b_T_es)
    return SimulatedProblem(c_T_e=c_T_e, b_T_w=b_T_w, e_T_bs=e_T_bs, c_T_ws=c_T_e @ e_T_bs @ b_T_w)
