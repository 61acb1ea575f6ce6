"""Time offset between a hand and an eye pose stream, by the most constant implied target.

:func:`best_time_offset` aligns the streams (:func:`kinfw.measurements.align_streams`)
at a grid of candidate offsets, solves the hand-eye ``hand_T_camera`` at each
(:func:`kinfw.identification.handeye.solve_axxb`), and keeps the offset at which the target's
implied pose in the robot base, ``base_T_hand @ hand_T_camera @ camera_T_target``,
spreads least
(:func:`implied_target_spread`). The offset's sign is that of
:mod:`kinfw.measurements` (added to the hand stamps).

References
----------
F. Furrer, M. Fehr, T. Novkovic, H. Sommer, I. Gilitschenski, R. Siegwart, "Evaluation of
Combined Time-Offset Estimation and Hand-Eye Calibration on Robotic Datasets", Field and
Service Robotics (FSR), 2017.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import average_transform, rotation_angle
from kinfw.identification.handeye._axxb import HandEyeError, solve_axxb
from kinfw.measurements import align_streams, check_stream

log = logging.getLogger("kinfw.measurements")  # logged as the alignment's, as before the split


def implied_target_spread(
    base_T_hands: ArrayLike, hand_T_camera: ArrayLike, camera_T_targets: ArrayLike
) -> tuple[float, float]:
    """How constant the target's implied pose in the base is: median deviations.

    Parameters
    ----------
    base_T_hands : array_like, shape (n, 4, 4)
        Pose of the hand in the base at each sample.
    hand_T_camera : array_like, shape (4, 4)
        Pose of the camera in the hand (the hand-eye transform).
    camera_T_targets : array_like, shape (n, 4, 4)
        Pose of the target in the camera at the same samples.

    Returns
    -------
    position : float
        Median distance of ``base_T_hands[i] @ hand_T_camera @ camera_T_targets[i]``'s
        positions from
        their coordinate-wise median, input length unit.
    rotation_rad : float
        Median angle of those poses' rotations from their chordal mean, radians.
    """
    base_T_targets = (
        np.asarray(base_T_hands, dtype=float)
        @ np.asarray(hand_T_camera, float)
        @ np.asarray(camera_T_targets, dtype=float)
    )
    p = base_T_targets[:, :3, 3]
    position = float(np.median(np.linalg.norm(p - np.median(p, axis=0), axis=1)))
    mean_R = average_transform(base_T_targets)[:3, :3]
    rotation = float(np.median(rotation_angle(mean_R.T @ base_T_targets[:, :3, :3])))
    return position, rotation


@dataclass(frozen=True, slots=True)
class TimeOffsetResult:
    """Time offset between a hand and an eye stream, and the fit at it.

    Attributes
    ----------
    offset_s : float
        Best offset, seconds, added to the hand stamps (:mod:`kinfw.measurements`).
    position_spread : float
        At ``offset_s``: median distance of the implied target positions in the base from
        their median (:func:`implied_target_spread`), input length unit -- the objective.
    rotation_spread_rad : float
        At ``offset_s``: median angle of the implied target rotations from their mean.
    hand_T_camera : ndarray, shape (4, 4)
        :func:`kinfw.identification.handeye.solve_axxb`'s ``hand_T_camera`` at
        ``offset_s``.
    n_pairs : int
        Hand-eye pairs (camera samples) used at ``offset_s``.
    offsets_s : ndarray, shape (k,)
        Every offset evaluated (coarse and fine grid), sorted.
    position_spreads : ndarray, shape (k,)
        The objective at each of them (inf where the hand-eye solve failed).
    """

    offset_s: float
    position_spread: float
    rotation_spread_rad: float
    hand_T_camera: NDArray[np.float64]
    n_pairs: int
    offsets_s: NDArray[np.float64]
    position_spreads: NDArray[np.float64]


def best_time_offset(
    t_hand: ArrayLike,
    base_T_hand: ArrayLike,
    t_eye: ArrayLike,
    target_T_eye: ArrayLike,
    *,
    search_s: tuple[float, float] = (-0.1, 0.1),
    coarse_step_s: float = 0.01,
    fine_step_s: float = 0.001,
    max_gap_s: float | None = 0.05,
    step: int = 1,
) -> TimeOffsetResult:
    """Time offset that makes the target's implied pose in the base most constant.

    At each candidate offset the streams are aligned (:func:`align_streams`), ``X`` is
    solved by :func:`kinfw.identification.handeye.solve_axxb`, and the objective is the median
    distance of the implied target positions
    ``base_T_hand @ hand_T_camera @ camera_T_target`` from
    their median. A coarse grid over ``search_s`` is followed by a fine grid of
    ``fine_step_s`` within one coarse step either side of the coarse minimum.

    Parameters
    ----------
    t_hand, base_T_hand, t_eye, target_T_eye : array_like
        The two streams, as for :func:`align_streams`.
    search_s : (float, float), keyword-only
        Range of offsets searched, seconds.
    coarse_step_s, fine_step_s : float, keyword-only
        Grid spacings of the two stages, seconds.
    max_gap_s : float or None, keyword-only
        As for :func:`align_streams`.
    step : int, keyword-only
        Use every ``step``-th camera sample. ``solve_axxb`` uses all O(n^2) pairs, so
        keep the pairs to a few hundred.

    Returns
    -------
    TimeOffsetResult

    Raises
    ------
    ValueError
        Malformed streams or search parameters, or no camera sample that stays inside the
        hand stream's range for every offset searched.
    HandEyeError
        The hand-eye solve failed at every offset.

    Notes
    -----
    Only camera samples that fall inside the hand stream's range for *every* offset of
    ``search_s`` are used, so that all offsets are judged on the same samples (a sample
    can still drop out at some offsets for a gap). The median makes the objective robust
    to a few bad camera poses; it is piecewise smooth, which a grid search does not mind.
    """
    t_hand, base_T_hand = check_stream(t_hand, base_T_hand, "base_T_hand")
    t_eye, target_T_eye = check_stream(t_eye, target_T_eye, "target_T_eye")
    lo, hi = (float(v) for v in search_s)
    if not (lo <= hi and coarse_step_s > 0.0 and fine_step_s > 0.0):
        raise ValueError(
            f"need search_s = (lo, hi) with lo <= hi and positive steps, got "
            f"{search_s!r}, {coarse_step_s!r}, {fine_step_s!r}"
        )
    common = (t_eye >= t_hand[0] + hi) & (t_eye <= t_hand[-1] + lo)
    if not np.any(common):
        raise ValueError(
            f"no camera sample stays within the hand stream's time range for every offset "
            f"in [{lo!r}, {hi!r}] s: camera [{float(t_eye[0])!r}, {float(t_eye[-1])!r}] s, hand "
            f"[{float(t_hand[0])!r}, {float(t_hand[-1])!r}] s"
        )
    t_eye, target_T_eye = t_eye[common], target_T_eye[common]

    evaluated: dict[float, tuple[float, float, NDArray[np.float64] | None, int]] = {}

    def evaluate(offset: float) -> float:
        offset = round(offset, 12)  # one key per grid point despite rounding of the grid
        if offset not in evaluated:
            A, B = align_streams(
                t_hand,
                base_T_hand,
                t_eye,
                target_T_eye,
                offset_s=offset,
                max_gap_s=max_gap_s,
                step=step,
            )
            try:
                hand_T_camera = solve_axxb(base_T_hands=A, camera_T_targets=B).hand_T_camera
            except HandEyeError as err:
                log.info("best_time_offset: offset %.4f s: hand-eye solve failed (%s)", offset, err)
                evaluated[offset] = (np.inf, np.inf, None, len(A))
            else:
                evaluated[offset] = (
                    *implied_target_spread(A, hand_T_camera, B),
                    hand_T_camera,
                    len(A),
                )
        return evaluated[offset][0]

    def grid(a: float, b: float, h: float) -> NDArray[np.float64]:
        return a + h * np.arange(int(np.floor((b - a) / h + 1e-9)) + 1)

    coarse = grid(lo, hi, coarse_step_s)
    best = min(coarse, key=evaluate)
    fine = grid(max(lo, best - coarse_step_s), min(hi, best + coarse_step_s), fine_step_s)
    best = min([best, *fine], key=evaluate)
    offsets = np.array(sorted(evaluated))
    spreads = np.array([evaluated[o][0] for o in offsets])
    position, rotation, hand_T_camera, n = evaluated[round(best, 12)]
    if hand_T_camera is None:  # the minimum is inf: every solve failed
        raise HandEyeError(
            f"the hand-eye solve failed at every offset in [{lo!r}, {hi!r}] s "
            f"(see the INFO log for each reason)"
        )
    return TimeOffsetResult(
        offset_s=float(round(best, 12)),
        position_spread=position,
        rotation_spread_rad=rotation,
        hand_T_camera=hand_T_camera,
        n_pairs=n,
        offsets_s=offsets,
        position_spreads=spreads,
    )
