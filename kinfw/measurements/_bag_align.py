"""Bag streams paired in time: the joint values at each measurement's stamp, and the
measurements of a bag (:func:`measurements_from_bag`) from what
:func:`kinfw.measurements.read_bag` read (``_bag_read.py``).

Time alignment
--------------
Joint values are interpolated linearly, per joint (each joint on its own stamps, so
joints published in separate messages are read too), at ``t_meas - offset_s``: the
convention of :mod:`kinfw.measurements` streams, ``offset_s`` added to the robot's stamps
(a robot sample stamped ``t`` happened at ``t + offset_s`` on the measurement clock; a
positive offset means the measurement stamps lag, as a mocap system stamping on
arrival). :func:`kinfw.identification.handeye.best_time_offset` estimates it from
:func:`time_offset_streams` (``kinfw import-bag --time-offset auto``). A measurement is
dropped, with its reason counted (:class:`BagAlignment`), when

- ``outside``: its shifted stamp lies outside a joint's stream (no extrapolation);
- ``gap``: the two joint samples around it are more than ``max_gap_s`` apart;
- ``fast``: linear interpolation there errs by more than ``max_interpolation_error``
  (rad or m), estimated from the joint's second difference (Notes of
  :func:`joint_values_at`);
- ``moving``: with ``still_speed`` set, a joint moves faster than that (rad/s or m/s):
  to keep only the still moments of a stop-and-go recording, where a timing error
  costs nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import inverse_transform, quat_xyzw_from_matrix
from kinfw.measurements._bag_read import BagRecording, JointStates
from kinfw.measurements._dataset import Measurements
from kinfw.measurements._figaroh_csv import camera_link
from kinfw.measurements._file import measurements_from_dict
from kinfw.measurements._mounts import Mount
from kinfw.observations import DatasetError

if TYPE_CHECKING:
    from kinfw.model import Robot

#: Why a measurement was not paired with joint values, in the order they are tested.
DROP_REASONS = ("outside", "gap", "fast", "moving")


@dataclass(frozen=True, slots=True)
class BagAlignment:
    """How the measurements of a bag were paired with joint values.

    Attributes
    ----------
    offset_s : float
        Time offset added to the joint stamps, seconds (module docstring).
    n_measured : int
        Measurements in the stream.
    kept : ndarray of int, shape (k,)
        Indices of the measurements written as samples, in time order.
    dropped : dict of str to int
        Per reason of :data:`DROP_REASONS`, how many measurements were dropped for it
        (each counted once, under the first reason that applies).
    """

    offset_s: float
    n_measured: int
    kept: NDArray[np.int64]
    dropped: dict[str, int]


def joint_values_at(
    joints: JointStates,
    t_query: ArrayLike,
    *,
    max_gap_s: float | None = 0.05,
    max_interpolation_error: float | None = 1e-3,
    still_speed: float | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.str_]]:
    """Joint values interpolated linearly at some instants, and why any is unusable.

    Parameters
    ----------
    joints : JointStates
        The joint streams.
    t_query : array_like, shape (m,)
        Instants on the joints' clock, seconds from the bag's time origin.
    max_gap_s : float or None, keyword-only
        Largest span between the two joint samples around an instant.
    max_interpolation_error : float or None, keyword-only
        Largest estimated error of linear interpolation, rad or m (Notes).
    still_speed : float or None, keyword-only
        Largest joint speed, rad/s or m/s, over the span around an instant; None: any.

    Returns
    -------
    qs : ndarray, shape (m, len(joints.names))
        Joint values in the order of ``joints.names``, rad or m; NaN where unusable.
    reasons : ndarray of str, shape (m,)
        ``""`` where usable, else the first of :data:`DROP_REASONS` that applies to any
        joint.

    Notes
    -----
    Between samples ``k`` and ``k + 1`` (span ``h``, ``s = (t - t_k) / h``) the linear
    interpolant of a smooth ``q`` errs by ``s (1 - s) h^2 |q''| / 2``; ``q''`` is
    estimated by the second divided differences at ``k`` and ``k + 1`` (the larger).
    An instant equal to a stamp is exact: it is never ``gap`` nor ``fast``.
    """
    t_query = np.asarray(t_query, dtype=float)
    qs = np.full((len(t_query), len(joints.names)), np.nan)
    rank = np.zeros(len(t_query), dtype=int)  # 0: usable, else 1 + index in DROP_REASONS
    for j, (t, q) in enumerate(zip(joints.t_s, joints.qs, strict=True)):
        inside = (t_query >= t[0]) & (t_query <= t[-1])
        code = np.where(inside, 0, 1)
        k = np.clip(np.searchsorted(t, t_query, side="right") - 1, 0, len(t) - 2)
        h = t[k + 1] - t[k]
        s = np.clip((t_query - t[k]) / h, 0.0, 1.0)
        qs[:, j] = q[k] + s * (q[k + 1] - q[k])
        exact = (s == 0.0) | (s == 1.0)
        slope = np.diff(q) / np.diff(t)
        curvature = np.zeros(len(t))
        curvature[1:-1] = 2.0 * np.abs(np.diff(slope)) / (t[2:] - t[:-2])
        error = 0.5 * s * (1.0 - s) * h**2 * np.maximum(curvature[k], curvature[k + 1])
        if max_gap_s is not None:
            code = np.where((code == 0) & (h > max_gap_s) & ~exact, 2, code)
        if max_interpolation_error is not None:
            code = np.where((code == 0) & (error > max_interpolation_error), 3, code)
        if still_speed is not None:
            code = np.where((code == 0) & (np.abs(slope[k]) > still_speed), 4, code)
        rank = np.where(rank == 0, code, np.where(code, np.minimum(rank, code), rank))
    qs[rank > 0] = np.nan
    reasons = np.array(("", *DROP_REASONS))[rank]
    return qs, reasons


def time_offset_streams(
    recording: BagRecording, robot: Robot, frame: str, *, target: bool = False
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The two pose streams whose time offset
    :func:`kinfw.identification.handeye.best_time_offset` estimates.

    Parameters
    ----------
    recording : BagRecording
        A bag with a pose stream (``measured.kind == "pose"``).
    robot : Robot
        The nominal robot: its forward kinematics give the hand stream.
    frame : str
        The URDF frame the measured frame is rigidly attached to (a marker's link, or
        the camera link seeing a target).
    target : bool, keyword-only
        The poses are ``camera_T_target`` of a fixed target seen by a camera on
        ``frame``; else ``meas_T_marker`` of a marker on ``frame`` in a fixed
        measurement frame.

    Returns
    -------
    t_hand : ndarray, shape (n,)
        Stamps of the joint stream with the most samples, seconds.
    base_T_hands : ndarray, shape (n, 4, 4)
        ``root_T_frame`` by the nominal FK of the joints interpolated there, metres.
    t_eye : ndarray, shape (m,)
        The measurement stamps, seconds.
    target_T_eyes : ndarray, shape (m, 4, 4)
        The measured poses as the estimator's ``target_T_eye``: both set-ups are a
        hand-eye problem whose ``root_T_frame @ X @ inverse(target_T_eye)`` is constant
        at the right offset. A camera on ``frame`` seeing a fixed target: the inverse
        of ``camera_T_target`` (the constant is ``root_T_target``); a marker on
        ``frame`` seen from a fixed frame: ``mocap_T_marker`` itself (``X`` is
        ``frame_T_marker``, the constant ``root_T_mocap``).

    Raises
    ------
    DatasetError
        The stream has points, not poses (no hand-eye problem), or a joint that moves
        ``frame`` is not published.
    """
    measured = recording.measured
    if measured.kind != "pose":
        raise DatasetError(
            f"{recording.path}: {measured.source}: the time offset is estimated from "
            f"poses (orientations), and this stream has points; give the offset in seconds"
        )
    names = _published_joints(recording, robot, frame)
    j = max(range(len(names)), key=lambda i: len(recording.joints.t_s[i]))
    t_hand = recording.joints.t_s[j]
    qs, reasons = joint_values_at(
        recording.joints, t_hand, max_gap_s=None, max_interpolation_error=None
    )
    ok = reasons == ""
    base_T_hands = robot.frame_poses(qs[ok], frame, recording.joints.names)
    target_T_eyes = measured.parent_T_childs
    if target:
        target_T_eyes = inverse_transform(target_T_eyes)
    return t_hand[ok], base_T_hands, measured.t_s, target_T_eyes


def _published_joints(recording: BagRecording, robot: Robot, frame: str) -> tuple[str, ...]:
    """The joints read (the URDF's published joints), once every joint that moves
    ``frame`` is checked to be among them (an unpublished one would be held at zero)."""
    missing = [n for n in robot.movable_path(frame) if n not in recording.joints.names]
    if missing:
        raise DatasetError(
            f"{recording.path}: joints {missing} move {frame!r} but are not on "
            f"{recording.joints.topic} (it has {list(recording.joints.names)})"
        )
    return recording.joints.names


def measurements_from_bag(
    recording: BagRecording,
    *,
    robot: Robot,
    frame: str,
    offset_s: float = 0.0,
    marker: str | None = None,
    measured_in: str | None = None,
    target: str | None = None,
    camera_frame: str | None = None,
    max_gap_s: float | None = 0.05,
    max_interpolation_error: float | None = 1e-3,
    still_speed: float | None = None,
) -> tuple[Measurements, BagAlignment]:
    """One sample per usable measurement of a bag, the joints interpolated at its stamp.

    Parameters
    ----------
    recording : BagRecording
        What :func:`read_bag` read.
    robot : Robot
        The URDF robot.
    frame : str
        URDF frame the measured frame is on: the frame itself (a pose of the frame), a
        marker on it (``marker``), or the link carrying the camera (``target``).
    offset_s : float, keyword-only
        Added to the joint stamps, seconds (module docstring).
    marker : str, optional, keyword-only
        The measured poses or points are of a marker of unknown pose (offset) on
        ``frame``. Without it a pose is that of ``frame`` itself, a point has an unknown
        offset.
    measured_in : str, optional, keyword-only
        Measurement frame (not in the URDF; its pose is estimated). Default: the
        stream's frame (``header.frame_id``, the TF parent) unless it is the URDF root
        link or empty (then the root link).
    target : str, optional, keyword-only
        Read the poses as ``camera_T_target`` of a fixed target of that name seen by a
        camera (``target`` observations); needs ``camera_frame``; excludes ``marker``
        and ``measured_in``.
    camera_frame : str, optional, keyword-only
        With ``target``: the camera's own URDF link, fixed to ``frame`` (as for
        :func:`kinfw.measurements.measurements_from_figaroh_csv`).
    max_gap_s, max_interpolation_error, still_speed : float or None, keyword-only
        The drop rules (module docstring, :func:`joint_values_at`).

    Returns
    -------
    measurements : Measurements
        Joint values in SI; one observation per sample.
    alignment : BagAlignment
        Which measurements were kept and why the others were dropped.

    Raises
    ------
    DatasetError
        Naming the bag: a joint that moves ``frame`` not published, a stream frame that
        is a URDF frame other than the root link, ``target`` on points, no measurement
        within the joint states' time range after the offset (both ranges given), every
        measurement dropped (the counts).
    ValueError
        ``target`` with ``marker`` or ``measured_in``.
    """
    path, measured = recording.path, recording.measured
    names = _published_joints(recording, robot, frame)
    common: dict[str, Any] = {"frame": frame}
    mounts: dict[str, Mount] = {}
    if target is not None:
        if marker is not None or measured_in is not None:
            raise ValueError("target excludes marker and measured_in: the camera measures")
        if measured.kind != "pose":
            raise DatasetError(f"{path}: {measured.source}: a target needs poses, got points")
        link = camera_link(path, robot, frame, camera_frame)
        mounts = {camera_frame: link} if isinstance(link, Mount) else {}
        common = {"frame": camera_frame, "target": target}
        kind = "target"
    else:
        kind = measured.kind
        if marker is not None:
            common["marker"] = marker
        measured_in = _measurement_frame(recording, robot, measured_in)
        if measured_in is not None:
            common["measured_in"] = measured_in
    qs, alignment = align_stamps(
        path,
        measured.source,
        recording.joints,
        measured.t_s,
        offset_s,
        max_gap_s=max_gap_s,
        max_interpolation_error=max_interpolation_error,
        still_speed=still_speed,
    )
    kept = alignment.kept
    xyz = measured.parent_T_childs[kept, :3, 3]
    quats = quat_xyzw_from_matrix(measured.parent_T_childs[kept, :3, :3])
    observations = [
        {**common, "kind": kind, "xyz": p}
        if kind == "point"
        else {**common, "kind": kind, "xyz": p, "quat_xyzw": o}
        for p, o in zip(xyz.tolist(), quats.tolist(), strict=True)
    ]
    doc = {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "m", "angle": "rad"},
        "joint_names": list(names),
        "samples": [
            {"q": q, "observations": [obs]}
            for q, obs in zip(qs[kept].tolist(), observations, strict=True)
        ],
    }
    return measurements_from_dict(doc, source=str(path)).with_mounts(mounts), alignment


def align_stamps(
    path: Path,
    source: str,
    joints: JointStates,
    t_s: NDArray[np.float64],
    offset_s: float,
    **rules: float | None,
) -> tuple[NDArray[np.float64], BagAlignment]:
    """Joint values at stamps ``t_s`` of ``source`` (:func:`joint_values_at` with
    ``rules``) and the alignment; raises when no stamp overlaps the joint states or
    every one is dropped."""
    t_query = t_s - offset_s
    t_joints = np.concatenate([t[[0, -1]] for t in joints.t_s])
    lo, hi = float(np.max(t_joints[0::2])), float(np.min(t_joints[1::2]))
    if not np.any((t_query >= lo) & (t_query <= hi)):
        raise DatasetError(
            f"{path}: no measurement of {source} ([{t_s[0]:.3f}, {t_s[-1]:.3f}] s) lies "
            f"within the joint states' time range [{lo:.3f}, {hi:.3f}] s shifted by the "
            f"offset {offset_s:+.4f} s (seconds from the bag's start); are both stamped on "
            f"one clock?"
        )
    qs, reasons = joint_values_at(joints, t_query, **rules)
    kept = np.flatnonzero(reasons == "")
    dropped = {r: int(np.count_nonzero(reasons == r)) for r in DROP_REASONS}
    if not kept.size:
        raise DatasetError(
            f"{path}: every measurement of {source} was dropped: "
            + ", ".join(f"{n} {r}" for r, n in dropped.items())
        )
    return qs, BagAlignment(float(offset_s), len(t_s), kept, dropped)


def _measurement_frame(
    recording: BagRecording, robot: Robot, measured_in: str | None
) -> str | None:
    """The ``measured_in`` of pose and point observations (see
    :func:`measurements_from_bag`)."""
    if measured_in is not None:
        return measured_in
    parent = recording.measured.parent.lstrip("/")
    if not parent or parent == robot.root_link:
        return None
    if robot.has_frame(parent):
        raise DatasetError(
            f"{recording.path}: {recording.measured.source} is measured in {parent!r}, a "
            f"frame of the URDF other than its root link {robot.root_link!r}; give the "
            f"measurement frame with --measured-in (measured_in=)"
        )
    return parent
