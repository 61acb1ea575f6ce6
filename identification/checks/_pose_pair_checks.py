"""Checks of hand-eye pose pairs before a fit (``kinfw handeye``): the quaternion order
and the length unit they were read in.

Without a robot model there is no nominal motion to compare with (``check_units``); the
pairs carry their own evidence instead.

Quaternion order (decisive). For pairs of poses ``(i, j)``, the hand's relative motion
``A = inv(base_T_hand_j) @ base_T_hand_i`` and the sensor's ``B = sensor_T_target_j @
inv(sensor_T_target_i)`` satisfy ``A X = X B`` (Tsai & Lenz 1989) with the unknown mount
``X``, whatever it is. ``X`` is fitted to every pair: its rotation by Kabsch on the
rotation vectors (``alpha = R_X beta``, Park & Martin 1994), its translation by linear
least squares on ``(R_A - I) t_X = R_X t_B - t_A``. Each pair's discrepancy is relative,
in ``[0, 1]``: the rotation ``angle(R_A^T R_X R_B R_X^T) / max(|alpha|, |beta|)`` (no
evidence when both turn less than :data:`FLOOR_RAD`) and
the translation residual over ``max(|t_A|, |t_B|)``; the *score* of a reading is their
mean over every pair (calibrate's score, :mod:`kinfw.identification.checks`). Readings
tried: the poses as read, and as if the quaternions of the hand poses, of the sensor
poses, or of both had been stored scalar first ``(w, x, y, z)`` under ``qx, qy, qz,
qw`` (with both, the rotations alone still fit some ``X``: the translations tell). The
pairs are refused, as a :class:`~kinfw.observations.DatasetError`, when the poses as read
score worse than :data:`BAD_SCORE` and another reading less
than :data:`BETTER_FACTOR` times that (calibrate's rule).

Length unit (both ways). The hand's motion (the median distance between its positions
over the pairs) and the distance from the sensor to the target (median) must lie within
:data:`PLAUSIBLE_LENGTH_M` (5 mm to 20 m) in metres as read: millimetres read as metres
put the camera hundreds of metres from the base, metres read as millimetres sub-millimetre
from it. When both lie outside and one rescaling (x1e-3 or x1e3) brings both inside,
or one lies outside while the other is plausible and a rescaling of it alone brings it
inside (a file mixing units), the pairs are refused with a
:class:`~kinfw.identification.checks.UnitError` naming the numbers and the fix.

Simulated pose pairs (the random poses of ``tests/kinfw/cli/test_cli_handeye.py``, 4
seeds, 8, 20 and 60 pairs, both setups, noise-free or 1-2 mm and 1 deg) score at most
0.04 as read; with the hand's, the sensor's or both sides' quaternions stored scalar
first they score at least 0.28 as read and the right reading at most 0.04.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import combinations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import (
    inverse_transform,
    quat_xyzw_from_matrix,
    rotation_angle,
    rotation_vector_from_matrix,
    transform_from_xyz_quat_xyzw,
)
from kinfw.identification.checks._units import UnitError
from kinfw.identification.checks._units_evidence import (
    BAD_SCORE,
    BETTER_FACTOR,
    FLOOR_RAD,
    LENGTH_READINGS,
    MAX_OBSERVATIONS,
)
from kinfw.observations import DatasetError

#: Plausible median hand motion and sensor-to-target distance of hand-eye pose pairs, m.
PLAUSIBLE_LENGTH_M = (5e-3, 20.0)
#: Pairs turning more than this (rad) give no rotation vector to fit ``R_X`` (its sign
#: is ill-defined near a half turn); they are still scored.
_HALF_TURN_RAD = 0.9 * math.pi
_SIDES = ("hand", "sensor")


@dataclass(frozen=True, slots=True)
class PosePairDiagnostics:
    """What hand-eye pose pairs say about their quaternion order and length unit (see
    the module docstring).

    Attributes
    ----------
    n_pairs : int
        Pairs of poses compared.
    motion_score : float
        Mean relative discrepancy (0..1) of ``A X = X B`` (rotations and translations), as
        read.
    reordered : tuple of str
        The sides (``"hand"``, ``"sensor"``) whose quaternions read scalar first explain
        the poses best; empty when the poses as read do.
    reordered_score : float
        The score of that reading.
    hand_motion_m : float
        Median distance between the hand's positions over the pairs, metres as read.
    view_distance_m : float
        Median distance from the sensor to the target, metres as read.
    """

    n_pairs: int
    motion_score: float
    reordered: tuple[str, ...]
    reordered_score: float
    hand_motion_m: float
    view_distance_m: float


def _reordered(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """The poses as if their quaternions' ``(x, y, z, w)`` had been ``(w, x, y, z)``."""
    q = quat_xyzw_from_matrix(T[:, :3, :3])
    return transform_from_xyz_quat_xyzw(T[:, :3, 3], q[:, [1, 2, 3, 0]])


def _motion_score(A: NDArray[np.float64], B: NDArray[np.float64], i: NDArray, j: NDArray) -> float:
    """Mean relative discrepancy of ``A X = X B`` over the pairs ``(i, j)`` of the poses
    ``A`` (the hand's, as the solver takes them) and ``B`` (the sensor's), both (n, 4, 4),
    for the best single ``X``: its rotation by Kabsch on the rotation vectors, its
    translation by linear least squares; rotation and translation equations count one
    each."""
    TA = inverse_transform(A[j]) @ A[i]
    TB = B[j] @ inverse_transform(B[i])
    RA, RB = TA[:, :3, :3], TB[:, :3, :3]
    alpha, beta = rotation_vector_from_matrix(RA), rotation_vector_from_matrix(RB)
    a, b = np.linalg.norm(alpha, axis=1), np.linalg.norm(beta, axis=1)
    top = np.maximum(a, b)
    moved = top > FLOOR_RAD
    if not moved.any():
        return 0.5  # no evidence
    fit = moved & (a < _HALF_TURN_RAD) & (b < _HALF_TURN_RAD)
    U, _, Vt = np.linalg.svd(beta[fit].T @ alpha[fit])
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R_X = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T  # alpha = R_X beta
    off = rotation_angle(np.swapaxes(RA[moved], 1, 2) @ R_X @ RB[moved] @ R_X.T)
    e_rot = np.minimum(1.0, off / top[moved])
    # (R_A - I) t_X = R_X t_B - t_A
    tA, tB = TA[moved, :3, 3], TB[moved, :3, 3] @ R_X.T
    M = (RA[moved] - np.eye(3)).reshape(-1, 3)
    t_X = np.linalg.lstsq(M, (tB - tA).reshape(-1), rcond=None)[0]
    r = np.linalg.norm(np.einsum("kab,b->ka", RA[moved] - np.eye(3), t_X) - tB + tA, axis=1)
    size = np.maximum(np.linalg.norm(tA, axis=1), np.linalg.norm(tB, axis=1))
    floor = max(1e-3 * float(np.median(size)), 1e-300)
    e_trans = np.where(size < floor, 0.5, np.minimum(1.0, r / np.maximum(size, floor)))
    return float(np.mean(np.concatenate([e_rot, e_trans])))


def _metres(value: float) -> str:
    return f"{value:.3g} m" if value >= 0.1 else f"{value * 1e3:.3g} mm"


def _plausible(value: float) -> bool:
    low, high = PLAUSIBLE_LENGTH_M
    return bool(low <= value <= high)


def _check_lengths(motion: float, view: float, source: str) -> None:
    """Refuse lengths in another unit than read (the module docstring)."""
    if _plausible(motion) and _plausible(view):
        return
    low, high = PLAUSIBLE_LENGTH_M
    seen = f"hand motion {_metres(motion)}, target {_metres(view)} from the sensor"
    why = f"(medians over the pairs as read; plausible: {low * 1e3:g} mm to {high:g} m)"
    for scale, looks, read in LENGTH_READINGS:
        fits = (_plausible(motion * scale), _plausible(view * scale))
        if all(fits):
            unit = "mm" if scale < 1.0 else "m"
            raise UnitError(
                f"{source}: positions look like {looks} read as {read} ({seen}): read them "
                f"in {unit} (kinfw handeye --unit {unit})\n{why}; or convert the numbers"
            )
        for side, ok, other in (("hand", fits[0], view), ("sensor", fits[1], motion)):
            if ok and _plausible(other) and not _plausible(other * scale):
                raise UnitError(
                    f"{source}: the {side} positions look like {looks} read as {read}, the "
                    f"others not ({seen}): convert them\n{why}"
                )


def _check_setup(
    H: NDArray, S: NDArray, setup: str, source: str, score: float, i: NDArray, j: NDArray
) -> None:
    """Refuse pairs that fit ``A X = X B`` as read only in the other setup (eye-to-hand
    pairs read as eye-in-hand: the hand's poses enter inverted), naming it; ``score`` is
    the setup's own, as read."""
    if score <= BAD_SCORE:
        return
    other = "eye-in-hand" if setup == "eye-to-hand" else "eye-to-hand"
    A = inverse_transform(H) if other == "eye-to-hand" else H
    fits = _motion_score(A, S, i, j)
    if fits < BETTER_FACTOR * score and fits <= BAD_SCORE:
        raise DatasetError(
            f"{source}: the pose pairs look {other}, read as {setup}: give --setup {other}\n"
            f"as {other}, the poses fit A X = X B (mean relative discrepancy {fits:.2g}; "
            f"as {setup} {score:.2g})"
        )


def check_pose_pair_data(
    base_T_hands: ArrayLike,
    sensor_T_targets: ArrayLike,
    *,
    setup: str = "eye-in-hand",
    source: str = "pose pairs",
    unit: str = "m",
    quaternions: Sequence[str] = _SIDES,
) -> PosePairDiagnostics:
    """Refuse hand-eye pose pairs whose quaternions were stored in the other order or
    whose lengths are in another unit than read (the module docstring).

    Parameters
    ----------
    base_T_hands : array_like, shape (n, 4, 4)
        Pose of the hand in the robot's base, metres as read.
    sensor_T_targets : array_like, shape (n, 4, 4)
        Pose of the target in the sensor, metres as read.
    setup : {"eye-in-hand", "eye-to-hand"}
    source : str
        The file, for messages.
    unit : str
        The unit the file was read in (``"m"``, ``"mm"``), for messages.
    quaternions : sequence of str
        The sides read from quaternions (``"hand"``, ``"sensor"``): those whose order
        can be wrong (none for 4x4 matrices).

    Returns
    -------
    PosePairDiagnostics
        The evidence, when the pairs pass.

    Raises
    ------
    DatasetError
        The poses fit ``A X = X B`` only in the other setup (naming it), or only with
        some quaternions read scalar first (naming the sides, the scores and the fix).
    UnitError
        The lengths look like millimetres read as metres, or the reverse, or mix the two
        (naming the medians and the fix).
    """
    H = np.asarray(base_T_hands, dtype=float)
    S = np.asarray(sensor_T_targets, dtype=float)
    k = np.unique(np.linspace(0, len(H) - 1, min(len(H), MAX_OBSERVATIONS)).round().astype(int))
    H, S = H[k], S[k]
    i, j = np.triu_indices(len(H), k=1)
    readings = [
        sides
        for r in range(len(quaternions) + 1)
        for sides in combinations([s for s in _SIDES if s in quaternions], r)
    ]
    scores = []
    for sides in readings:
        h = _reordered(H) if "hand" in sides else H
        s = _reordered(S) if "sensor" in sides else S
        A = inverse_transform(h) if setup == "eye-to-hand" else h
        scores.append(_motion_score(A, s, i, j))
    best = int(np.argmin(scores))
    _check_setup(H, S, setup, source, scores[0], i, j)
    if best and scores[0] > BAD_SCORE and scores[best] < BETTER_FACTOR * scores[0]:
        sides = " and ".join(readings[best])
        raise DatasetError(
            f"{source}: quaternions look scalar-first (w, x, y, z) under qx..qw headers "
            f"({sides} poses): reorder them to qx, qy, qz, qw (scalar last)\n"
            f"read so, the poses fit A X = X B (mean relative discrepancy "
            f"{scores[best]:.2g}; as read {scores[0]:.2g})"
        )
    motion = float(np.median(np.linalg.norm(H[j, :3, 3] - H[i, :3, 3], axis=1)))
    view = float(np.median(np.linalg.norm(S[:, :3, 3], axis=1)))
    _check_lengths(motion, view, f"{source} (read in {unit})")
    return PosePairDiagnostics(
        len(i), float(scores[0]), tuple(readings[best]), float(scores[best]), motion, view
    )
