"""Time alignment of asynchronous pose streams for hand-eye calibration.

A robot logs ``base_T_hand`` at its own rate and a camera tracks a target at another; the
two streams share a clock but not their stamps (ETH ASL's robot-arm datasets: robot
50 Hz, camera ~30 Hz). Hand-eye calibration needs *pairs* taken at one instant, so the
hand stream is interpolated at the camera stamps -- linearly in position, by SLERP in
rotation -- after shifting it by a time offset between the two clocks, which
:func:`kinfw.identification.handeye.best_time_offset` estimates as the offset that makes the
target's implied pose in the robot base the most constant. (Furrer et al. 2017 instead
cross-correlate the two streams' angular speeds, which needs no hand-eye model; the
criterion here uses the model and so scores the offset by what calibration needs.)

Time-offset convention
----------------------
``offset_s`` is added to the hand stream's stamps: a hand sample stamped ``t`` is taken
to have happened at ``t + offset_s`` on the camera's clock. The hand pose paired with a
camera sample stamped ``t_eye`` is therefore the hand stream interpolated at
``t_eye - offset_s``. This is the sign of ETH's ``compute_aligned_poses`` (it adds the
offset to the stamps of the hand stream). A positive offset means the camera's stamps lag
the robot's (e.g. images stamped on arrival, after exposure and transfer): on ETH's real
robot-arm data the best offset is about +0.02 s.

File format (:func:`read_pose_csv`)
-----------------------------------
ETH ASL ``hand_eye_calibration`` CSV: no header, one pose per line,
``t [s], x [m], y [m], z [m], q_x, q_y, q_z, q_w`` -- a Hamilton unit quaternion, scalar
last (kinfw's ``quat_xyzw``). Each line is ``a_T_b``, the pose of frame ``b`` in frame
``a`` (hand in base: ``base_T_hand``; eye in the target/world: ``target_T_eye``).

References
----------
F. Furrer, M. Fehr, T. Novkovic, H. Sommer, I. Gilitschenski, R. Siegwart, "Evaluation of
Combined Time-Offset Estimation and Hand-Eye Calibration on Robotic Datasets", Field and
Service Robotics (FSR), 2017.
K. Shoemake, "Animating rotation with quaternion curves", SIGGRAPH 1985 (SLERP).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import (
    check_transform,
    inverse_transform,
    matrix_from_rotation_vector,
    rotation_vector_from_matrix,
    transform_from_rotation_translation,
    transform_from_xyz_quat_xyzw,
)
from kinfw.observations import QUAT_NORM_TOL, DatasetError

log = logging.getLogger(__name__)

_N_COLUMNS = 8
_COLUMNS = "t, x, y, z, qx, qy, qz, qw"


# ------------------------------------------------------------------------------ reading


def read_pose_csv(
    path: str | Path, *, quat_norm_tol: float = QUAT_NORM_TOL
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Read a time-stamped pose stream in the ETH ASL CSV format.

    Parameters
    ----------
    path : str or Path
        CSV file without header, one pose per line:
        ``t [s], x [m], y [m], z [m], q_x, q_y, q_z, q_w`` (Hamilton, scalar last).
        Blank lines are skipped.
    quat_norm_tol : float, keyword-only
        Largest accepted ``| |q| - 1 |``; accepted quaternions are renormalised.

    Returns
    -------
    t : ndarray, shape (n,)
        Stamps in seconds, strictly increasing.
    a_T_bs : ndarray, shape (n, 4, 4)
        Pose of the stream's frame ``b`` in its reference frame ``a`` at each stamp, metres.

    Raises
    ------
    DatasetError
        The file is missing or empty, a line does not hold 8 finite numbers or a unit
        quaternion (the message gives ``file:line``), or two lines share a stamp but not
        their pose (the message gives both lines).

    Notes
    -----
    Lines out of time order are sorted (stable) and exact duplicates -- the same stamp
    and the same pose, as ETH's simulated hand stream has -- are dropped; both are noted
    in the log at INFO level.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise DatasetError(f"{path}: cannot read pose stream ({err})") from err
    rows: list[list[float]] = []
    line_numbers: list[int] = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        fields = line.split(",")
        if len(fields) != _N_COLUMNS:
            raise DatasetError(
                f"{path}:{number}: expected {_N_COLUMNS} comma-separated "
                f"numbers ({_COLUMNS}), got {len(fields)}: {line.strip()!r}"
            )
        try:
            values = [float(f) for f in fields]
        except ValueError as err:
            raise DatasetError(
                f"{path}:{number}: not a number ({err}); expected {_COLUMNS}: {line.strip()!r}"
            ) from None
        if not np.isfinite(values).all():
            raise DatasetError(f"{path}:{number}: all values must be finite, got {line.strip()!r}")
        norm = float(np.linalg.norm(values[4:]))
        if abs(norm - 1.0) > quat_norm_tol:
            raise DatasetError(
                f"{path}:{number}: quaternion (qx, qy, qz, qw) = "
                f"{values[4:]} has norm {norm:.9g}, expected 1 within "
                f"{quat_norm_tol:g}"
            )
        rows.append(values)
        line_numbers.append(number)
    if not rows:
        raise DatasetError(f"{path}: no poses (expected lines of {_COLUMNS})")
    data = np.array(rows)
    lines = np.array(line_numbers)

    backward = int(np.count_nonzero(np.diff(data[:, 0]) < 0.0))
    if backward:
        order = np.argsort(data[:, 0], kind="stable")
        data, lines = data[order], lines[order]
        log.info("%s: %d lines are out of time order; sorted by stamp", path, backward)
    same = np.flatnonzero(np.diff(data[:, 0]) == 0.0)
    if same.size:
        differ = np.any(data[same, 1:] != data[same + 1, 1:], axis=1)
        if np.any(differ):
            k = same[np.argmax(differ)]
            raise DatasetError(
                f"{path}: lines {lines[k]} and {lines[k + 1]} share the stamp "
                f"{float(data[k, 0])!r} but give different poses; a stream "
                f"needs one pose per stamp"
            )
        keep = np.ones(len(data), dtype=bool)
        keep[same + 1] = False
        data = data[keep]
        log.info("%s: dropped %d exact duplicate lines (same stamp and pose)", path, same.size)
    return data[:, 0].copy(), transform_from_xyz_quat_xyzw(data[:, 1:4], data[:, 4:])


# ------------------------------------------------------------------------ interpolation


def check_stream(
    t: ArrayLike, a_T_bs: ArrayLike, name: str
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Validate a stream: stamps (n,) finite and strictly increasing, poses (n, 4, 4).

    Parameters
    ----------
    t : array_like, shape (n,)
        Stamps, seconds.
    a_T_bs : array_like, shape (n, 4, 4)
        Pose of ``b`` in ``a`` at each stamp, rigid transforms.
    name : str
        Name of the poses in error messages.

    Returns
    -------
    t : ndarray, shape (n,)
    a_T_bs : ndarray, shape (n, 4, 4)

    Raises
    ------
    ValueError
        Naming ``name``: a wrong shape, a stamp not finite or not strictly increasing
        (with the two stamps), or a pose that is not a rigid transform.
    """
    t = np.asarray(t, dtype=float)
    T = np.asarray(a_T_bs, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"{name}: stamps must have shape (n,), got {t.shape}")
    if T.ndim != 3 or T.shape[1:] != (4, 4) or len(T) != len(t):
        raise ValueError(
            f"{name}: poses must have shape ({len(t)}, 4, 4) to match the stamps, got {T.shape}"
        )
    if not np.isfinite(t).all():
        raise ValueError(f"{name}: stamps must be finite")
    steps = np.diff(t)
    if np.any(steps <= 0.0):
        k = int(np.argmax(steps <= 0.0))
        raise ValueError(
            f"{name}: stamps must be strictly increasing; t[{k}] = "
            f"{float(t[k])!r} and t[{k + 1}] = {float(t[k + 1])!r} (sort and drop "
            f"duplicates first, as read_pose_csv does)"
        )
    return t, check_transform(T, name=name)


def interpolate_poses(
    t: ArrayLike, a_T_bs: ArrayLike, t_query: ArrayLike, *, max_gap_s: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Poses of a stream at other instants: linear in position, SLERP in rotation.

    Parameters
    ----------
    t : array_like, shape (n,)
        Stamps of the stream in seconds, strictly increasing, n >= 2.
    a_T_bs : array_like, shape (n, 4, 4)
        Pose of ``b`` in ``a`` at each stamp.
    t_query : array_like, shape (...)
        Instants to interpolate at, seconds, all within ``[t[0], t[-1]]``.
    max_gap_s : float or None, keyword-only
        Queries that fall strictly between two samples more than ``max_gap_s`` apart are
        masked: interpolating across a gap in the stream guesses a motion no one saw.
        None: no gap is masked.

    Returns
    -------
    a_T_bs : ndarray, shape (..., 4, 4)
        The interpolated poses; masked queries are NaN so they cannot be used unnoticed.
    valid : ndarray of bool, shape (...)
        False where a query was masked for a gap.

    Raises
    ------
    ValueError
        Malformed stream (shapes, non-increasing stamps, not rigid transforms) or query
        times outside the stream's range (the message gives how many and the range).
        Queries outside the range are refused rather than masked: extrapolation is never
        wanted, and queries that miss the range usually mean a wrong clock or unit;
        trim them first (:func:`align_streams` does).

    Notes
    -----
    With the bracketing samples ``k, k + 1`` and ``s = (t_q - t_k) / (t_{k+1} - t_k)``::

        p(t_q) = p_k + s (p_{k+1} - p_k)
        R(t_q) = R_k exp(s log(R_k^T R_{k+1}))

    the geodesic (SLERP) between the two rotations, which is exact for a rotation about a
    fixed axis at a constant rate. It takes the shorter way round, so samples must be
    less than a half turn apart. A query equal to a stamp returns that sample exactly.
    """
    t, T = check_stream(t, a_T_bs, "a_T_bs")
    if len(t) < 2:
        raise ValueError(f"a_T_bs: interpolation needs at least 2 samples, got {len(t)}")
    if max_gap_s is not None and not max_gap_s > 0.0:
        raise ValueError(f"max_gap_s must be positive or None, got {max_gap_s!r}")
    t_query = np.asarray(t_query, dtype=float)
    tq = t_query.reshape(-1)
    outside = ~((tq >= t[0]) & (tq <= t[-1]))  # NaN counts as outside
    if np.any(outside):
        raise ValueError(
            f"{int(np.count_nonzero(outside))} of {tq.size} query times lie "
            f"outside the stream's time range [{float(t[0])!r}, {float(t[-1])!r}] "
            f"s (or are not finite); interpolation does not extrapolate: trim the "
            f"queries"
        )
    k = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, len(t) - 2)
    dt = t[k + 1] - t[k]
    s = (tq - t[k]) / dt
    R0, R1 = T[k, :3, :3], T[k + 1, :3, :3]
    p0, p1 = T[k, :3, 3], T[k + 1, :3, 3]
    steps = rotation_vector_from_matrix(np.swapaxes(R0, 1, 2) @ R1)
    R = R0 @ matrix_from_rotation_vector(s[:, None] * steps)
    p = p0 + s[:, None] * (p1 - p0)
    out = transform_from_rotation_translation(R, p)
    out = np.where((s == 1.0)[:, None, None], T[k + 1], out)
    valid = np.ones(tq.shape, dtype=bool)
    if max_gap_s is not None:
        valid = (dt <= max_gap_s) | (s == 0.0) | (s == 1.0)
        out[~valid] = np.nan
    return out.reshape(*t_query.shape, 4, 4), valid.reshape(t_query.shape)


# ---------------------------------------------------------------------------- alignment


def align_streams(
    t_hand: ArrayLike,
    base_T_hand: ArrayLike,
    t_eye: ArrayLike,
    target_T_eye: ArrayLike,
    *,
    offset_s: float = 0.0,
    max_gap_s: float | None = 0.05,
    step: int = 1,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Hand-eye pairs at the camera stamps, the hand stream interpolated there.

    Parameters
    ----------
    t_hand : array_like, shape (n,)
        Stamps of the hand stream, seconds, strictly increasing.
    base_T_hand : array_like, shape (n, 4, 4)
        Pose of the hand in the robot base (OpenCV ``gripper2base``), metres.
    t_eye : array_like, shape (m,)
        Stamps of the camera stream, seconds, strictly increasing.
    target_T_eye : array_like, shape (m, 4, 4)
        Pose of the eye (camera) in the target frame, metres (the inverse of OpenCV's
        ``target2cam``).
    offset_s : float, keyword-only
        Added to the hand stamps (module docstring): camera sample ``t_eye`` is paired
        with the hand stream at ``t_eye - offset_s``.
    max_gap_s : float or None, keyword-only
        Camera samples whose hand pose would be interpolated across a gap in the hand
        stream longer than this are dropped (:func:`interpolate_poses`).
    step : int, keyword-only
        Use every ``step``-th camera sample (``t_eye[::step]``), before any is dropped.

    Returns
    -------
    base_T_hands : ndarray, shape (k, 4, 4)
        Interpolated pose of the hand in the base at each camera sample kept.
    eye_T_targets : ndarray, shape (k, 4, 4)
        Pose of the target in the eye at the same samples (OpenCV ``target2cam``): the
        ``A`` and ``B`` of :func:`kinfw.identification.handeye.solve_axxb`.

    Raises
    ------
    ValueError
        Malformed streams, ``step < 1``, or no camera sample inside the (shifted) hand
        stream's time range (the message gives both ranges).

    Notes
    -----
    Camera samples outside the shifted hand stream's range are dropped, not
    extrapolated; the counts of dropped samples are logged at INFO level.
    """
    t_hand, base_T_hand = check_stream(t_hand, base_T_hand, "base_T_hand")
    t_eye, target_T_eye = check_stream(t_eye, target_T_eye, "target_T_eye")
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 1:
        raise ValueError(f"step must be a positive integer, got {step!r}")
    t_eye, target_T_eye = t_eye[::step], target_T_eye[::step]
    t_query = t_eye - offset_s
    inside = (t_query >= t_hand[0]) & (t_query <= t_hand[-1])
    if not np.any(inside):
        raise ValueError(
            f"no camera sample lies within the hand stream's time range: camera "
            f"[{float(t_eye[0])!r}, {float(t_eye[-1])!r}] s, hand [{float(t_hand[0])!r}, "
            f"{float(t_hand[-1])!r}] s shifted by offset_s = {float(offset_s)!r} s; are both "
            f"stamps on one clock and in seconds?"
        )
    base_T_hands, valid = interpolate_poses(
        t_hand, base_T_hand, t_query[inside], max_gap_s=max_gap_s
    )
    eye_T_targets = inverse_transform(target_T_eye[inside])
    n_outside = int(np.count_nonzero(~inside))
    n_gap = int(np.count_nonzero(~valid))
    if n_outside or n_gap:
        log.info(
            "align_streams: kept %d of %d camera samples (%d outside the hand stream's "
            "range, %d across a gap > %s s)",
            int(np.count_nonzero(valid)),
            len(t_eye),
            n_outside,
            n_gap,
            max_gap_s,
        )
    return base_T_hands[valid], eye_T_targets[valid]
