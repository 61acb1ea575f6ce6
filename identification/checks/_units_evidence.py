"""The evidence on a dataset's units: its motion against the nominal robot's.

:func:`unit_diagnostics` compares the data with the nominal robot under every reading of
its units (:class:`UnitHypothesis`) and returns a :class:`UnitDiagnostics`;
:func:`kinfw.identification.checks.check_units` refuses the data on it.

Motion (decisive). For pairs of samples ``(i, j)`` of one observation group, the
distance between the measured positions, ``|p_i - p_j|``, and the angle of the relative
rotation, ``angle(R_i^T R_j)``, against the same two numbers predicted by the nominal
URDF's forward kinematics at the same joint values. Both are independent of everything
the data leaves unknown: the measurement frame (a rigid change of frame keeps distances
and relative angles), a marker's orientation on its frame (it conjugates the relative
rotation), the target pose of ``target`` observations (``inv(camera_T_target_i)`` is the
camera's pose in the fixed target frame, so the pairs measure the camera's own motion);
the nominal's errors (a few mm or degrees) change them by little. Each pair's
discrepancy is relative, ``e = |a - b| / max(a, b)`` in ``[0, 1]`` (0.5, no evidence,
when both are below :data:`FLOOR_M` = 5 mm or :data:`FLOOR_RAD` = 0.05 rad), and the
*score* of a reading of the data is the mean of ``e`` over every pair and both
quantities (bounded per pair, so a few gross outliers cannot move it much). Readings
tried (:class:`UnitHypothesis`): the values as read, and every rescaling of revolute
joint values (degrees <-> radians), prismatic joint values (mm <-> m, and m or mm read
as degrees, which a ``"deg"`` file does to every joint without ``joint_units``) and
measured lengths (mm <-> m), for every joint of a kind at once and for one joint alone.
The data is refused when the values as read score worse than :data:`BAD_SCORE` (0.2) and
another reading scores less than :data:`BETTER_FACTOR` (0.75) times that: the data then
agrees with the nominal only in another unit. A reading that rescales joint values and
lengths together is reported only when it scores below :data:`BETTER_FACTOR` times each
of the two rescalings alone; otherwise the better of those (mm positions read as m are
not also blamed on a joint's unit).

The thresholds come from simulations (IIS-head one-joint-at-a-time and stage-2 targets,
6R arm poses and unknown-offset markers 18 cm off the flange, a prismatic tree; 6
seeds; nominal 5 mm / 1 deg to 40 mm / 5 deg off; noise 0.5 to 2 mm, 0.5 to 1 deg;
6 to 55 samples): good data scored at most 0.23 as read and no other reading came within
0.91 of it; degrees, mm positions or mm prismatic values read as SI scored at least 0.27
as read and the right reading at most 0.60 of that.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import inverse_transform, rotation_angle
from kinfw.measurements import Measurements, check_against_robot, robot_measurement_frames
from kinfw.model import Robot

#: Distances below this (m) count as this much in a pair's relative discrepancy.
FLOOR_M = 5e-3
#: Angles below this (rad, about 3 deg) count as this much.
FLOOR_RAD = 0.05
#: The values as read are suspect when their mean relative discrepancy exceeds this.
BAD_SCORE = 0.2
#: ... and refused when another reading scores below this fraction of theirs.
BETTER_FACTOR = 0.75
#: Observations per group used (evenly spaced in sample order), so pairs stay few.
MAX_OBSERVATIONS = 120

_DEG = math.pi / 180.0
# (SI value per value as read, what the numbers look like, how they were read)
_REVOLUTE = ((_DEG, "degrees", "radians"), (1.0 / _DEG, "radians", "degrees"))
_PRISMATIC = (
    (1e-3, "millimetres", "metres"),
    (1e3, "metres", "millimetres"),
    (1.0 / _DEG, "metres", "degrees"),
    (1e-3 / _DEG, "millimetres", "degrees"),
)
#: The readings of measured lengths tried here and by the pose-pair checks.
LENGTH_READINGS = ((1e-3, "millimetres", "metres"), (1e3, "metres", "millimetres"))


@dataclass(frozen=True, slots=True)
class UnitHypothesis:
    """One reading of the data: factors applied to the values as read.

    Attributes
    ----------
    joint_scale : dict of str to float
        SI value per value as read, per joint whose reading changes (absent: 1).
    length_scale : float
        Metres per measured length unit as read (1, 1e-3 or 1e3).
    joint_looks, length_looks : str
        What the rescaled numbers look like and how they were read, for messages
        (``"degrees read as radians"``); empty when unchanged.
    """

    joint_scale: dict[str, float]
    length_scale: float = 1.0
    joint_looks: str = ""
    length_looks: str = ""

    @property
    def is_as_read(self) -> bool:
        """True for the values as read (no rescaling)."""
        return not self.joint_scale and self.length_scale == 1.0


@dataclass(frozen=True, slots=True)
class JointValues:
    """The values of one joint against its URDF limits.

    Attributes
    ----------
    joint : str
    revolute : bool
    low, high : float
        Smallest and largest value as read (rad or m).
    lower, upper : float
        URDF limits (rad or m; infinite when unbounded).
    outside_spans : float
        How far the values reach outside the limits, in limit spans (0 inside; inf for
        limits of zero span; 0 for unbounded joints).
    """

    joint: str
    revolute: bool
    low: float
    high: float
    lower: float
    upper: float
    outside_spans: float


@dataclass(frozen=True, slots=True)
class UnitDiagnostics:
    """What the data says about its units (see the module docstring).

    Attributes
    ----------
    n_pairs : int
        Sample pairs compared (over every observation group).
    score_as_read : float
        Mean relative discrepancy (0..1) between measured and nominal motion, values as
        read.
    best : UnitHypothesis
        The reading with the lowest score (the values as read on ties).
    best_score : float
    alternative_score : float
        The lowest score of a reading other than the values as read (how clearly the
        values as read win on good data).
    length_ratio : float
        Median over pairs of measured over predicted distance under the best joint
        reading, lengths as read (about 1 in metres; about 1000 for mm read as m); NaN
        when no pair moved more than :data:`FLOOR_M` in the prediction.
    joints : tuple of JointValues
        The joints on the observed paths that the data lists.
    frames : tuple of str
        The observed frames whose motion was compared.
    """

    n_pairs: int
    score_as_read: float
    best: UnitHypothesis
    best_score: float
    alternative_score: float
    length_ratio: float
    joints: tuple[JointValues, ...]
    frames: tuple[str, ...]

    @property
    def refused(self) -> bool:
        """True when another reading explains the data much better than the values as
        read (:data:`BAD_SCORE`, :data:`BETTER_FACTOR`)."""
        return (
            not self.best.is_as_read
            and self.score_as_read > BAD_SCORE
            and self.best_score < BETTER_FACTOR * self.score_as_read
        )


@dataclass(frozen=True, slots=True)
class _Track:
    """One observation group: measured poses in a fixed frame (or in a frame ``inside``
    of the robot: then compared with the nominal relative poses), rows used."""

    frame: str
    sample: NDArray[np.int64]  # (m,)
    meas_p: NDArray[np.float64]  # (m, 3), metres as read
    meas_R: NDArray[np.float64] | None  # (m, 3, 3) or None for points
    offset: NDArray[np.float64]  # (3,) point on the frame (zero: its origin)
    inside: str | None = None  # a measured_in that is a frame of the robot


def _evenly(n: int) -> NDArray[np.int64]:
    return np.unique(np.linspace(0, n - 1, min(n, MAX_OBSERVATIONS)).round().astype(np.int64))


def _tracks(data: Measurements, nominal: Robot) -> list[_Track]:
    def inside(name: str | None) -> str | None:
        return name if name is not None and nominal.has_frame(name) else None

    tracks = []
    for g in data.poses:
        k = _evenly(len(g.sample))
        T = g.meas_T_frame[k]
        tracks.append(
            _Track(
                g.frame,
                g.sample[k],
                T[:, :3, 3],
                T[:, :3, :3],
                np.zeros(3),
                inside(g.measured_in),
            )
        )
    for t in data.targets:
        k = _evenly(len(t.sample))
        T = inverse_transform(t.camera_T_target[k])  # target_T_camera
        tracks.append(_Track(t.camera, t.sample[k], T[:, :3, 3], T[:, :3, :3], np.zeros(3)))
    for p in data.points:
        k = _evenly(len(p.sample))
        tracks.append(
            _Track(
                p.frame,
                p.sample[k],
                p.meas_p_point[k],
                None,
                np.zeros(3) if p.offset is None else p.offset,
                inside(p.measured_in),
            )
        )
    return [t for t in tracks if len(t.sample) >= 2]


def _relative(a: NDArray, b: NDArray, floor: float) -> NDArray:
    """``|a - b| / max(a, b)`` in [0, 1]; 0.5 (no evidence) when both are below ``floor``."""
    top = np.maximum(a, b)
    return np.where(top < floor, 0.5, np.abs(a - b) / np.maximum(top, floor))


def _pair_motion(
    p: NDArray, R: NDArray | None, i: NDArray, j: NDArray
) -> tuple[NDArray, NDArray | None]:
    d = np.linalg.norm(p[j] - p[i], axis=1)
    if R is None:
        return d, None
    return d, rotation_angle(np.swapaxes(R[i], 1, 2) @ R[j])


def _joint_values(nominal: Robot, names: tuple[str, ...], qs: NDArray) -> tuple[JointValues, ...]:
    lower, upper = nominal.joint_limits(names)
    out = []
    for c, name in enumerate(names):
        low, high = float(qs[:, c].min()), float(qs[:, c].max())
        span = upper[c] - lower[c]
        beyond = max(lower[c] - low, high - upper[c], 0.0)
        if not np.isfinite(span):
            spans = 0.0
        elif span <= 0.0:
            spans = math.inf if beyond > 1e-9 else 0.0
        else:
            spans = float(beyond / span)
        out.append(
            JointValues(
                name,
                nominal.joint(name).is_revolute,
                low,
                high,
                float(lower[c]),
                float(upper[c]),
                spans,
            )
        )
    return tuple(out)


def _hypotheses(revolute: list[str], prismatic: list[str]) -> list[UnitHypothesis]:
    """Every joint reading (all joints of a kind, or one joint), times every length one."""
    joint_readings: list[tuple[dict[str, float], str]] = [({}, "")]
    for joints, table in ((revolute, _REVOLUTE), (prismatic, _PRISMATIC)):
        if not joints:
            continue
        for scale, looks, read in table:
            joint_readings.append(({n: scale for n in joints}, f"{looks} read as {read}"))
            if len(joints) > 1:
                joint_readings += [({n: scale}, f"{looks} read as {read}") for n in joints]
    if revolute and prismatic:  # a file in mm and degrees read as m and rad
        for r_scale, r_looks, r_read in _REVOLUTE[:1]:
            for p_scale, p_looks, p_read in _PRISMATIC[:1]:
                joint_readings.append(
                    (
                        {**{n: r_scale for n in revolute}, **{n: p_scale for n in prismatic}},
                        f"{r_looks} and {p_looks} read as {r_read} and {p_read}",
                    )
                )
    out = []
    for scales, looks in joint_readings:
        out.append(UnitHypothesis(scales, 1.0, looks, ""))
        out += [
            UnitHypothesis(scales, s, looks, f"{lk} read as {rd}") for s, lk, rd in LENGTH_READINGS
        ]
    return out


def _simplest(hypotheses: list[UnitHypothesis], scores: NDArray, best: int) -> int:
    """The index of the reading to report: ``best``, unless it rescales both joint values
    and lengths and one of the two rescalings alone scores within :data:`BETTER_FACTOR`
    of it (then that one, the lower of the two). Lengths in mm read as m explain a
    point's motion; one joint also rescaled gains a few hundredths by chance, and
    blaming it too would send the user after a unit that is right."""
    hyp = hypotheses[best]
    if not hyp.joint_scale or hyp.length_scale == 1.0:
        return best
    simpler = [
        k
        for k, h in enumerate(hypotheses)
        if (h.joint_scale == hyp.joint_scale and h.length_scale == 1.0)
        or (not h.joint_scale and h.length_scale == hyp.length_scale)
    ]
    k = min(simpler, key=lambda k: scores[k])
    return k if scores[best] >= BETTER_FACTOR * scores[k] else best


def unit_diagnostics(nominal: Robot, data: Measurements) -> UnitDiagnostics:
    """Compare the data's motion with the nominal robot's under every unit reading.

    Parameters
    ----------
    nominal : Robot
        The nominal URDF (its geometry may be off by centimetres and degrees).
    data : Measurements
        Any mix of ``pose``, ``target`` and ``point`` observations, in SI as read.

    Returns
    -------
    UnitDiagnostics
    """
    with warnings.catch_warnings():  # limit warnings come again from the estimators
        warnings.simplefilter("ignore")
        data = check_against_robot(data, nominal)
    topo = nominal.topology(
        tuple(dict.fromkeys((*data.observed_frames, *robot_measurement_frames(data, nominal))))
    )
    listed = tuple(n for n in topo.joint_names if n in data.joint_names)
    qs = data.q_of(topo.joint_names)
    joints = _joint_values(nominal, listed, data.q_of(listed)) if listed else ()
    revolute = [n for n in listed if nominal.joint(n).is_revolute]
    prismatic = [n for n in listed if not nominal.joint(n).is_revolute]
    tracks = _tracks(data, nominal)
    pairs = [np.triu_indices(len(t.sample), k=1) for t in tracks]
    measured = [
        _pair_motion(t.meas_p, t.meas_R, i, j) for t, (i, j) in zip(tracks, pairs, strict=True)
    ]
    n_pairs = int(sum(len(i) for i, _ in pairs))
    hypotheses = _hypotheses(revolute, prismatic)
    predicted: dict[tuple[tuple[str, float], ...], list] = {}
    scores = np.empty(len(hypotheses))
    ratios = np.full(len(hypotheses), np.nan)
    for h, hyp in enumerate(hypotheses):
        key = tuple(sorted(hyp.joint_scale.items()))
        if key not in predicted:
            scale = np.array([hyp.joint_scale.get(n, 1.0) for n in topo.joint_names])
            predicted[key] = []
            for t, (i, j) in zip(tracks, pairs, strict=True):
                T = nominal.frame_poses(qs[t.sample] * scale, t.frame, topo.joint_names)
                if t.inside is not None:  # measured in a frame of the robot: relative
                    c_T = nominal.frame_poses(qs[t.sample] * scale, t.inside, topo.joint_names)
                    T = inverse_transform(c_T) @ T
                p, R = T[:, :3, :3] @ t.offset + T[:, :3, 3], T[:, :3, :3]
                predicted[key].append(_pair_motion(p, None if t.meas_R is None else R, i, j))
        sums, count, ratio = 0.0, 0, []
        for (d_m, a_m), (d_n, a_n) in zip(measured, predicted[key], strict=True):
            sums += float(np.sum(_relative(d_m * hyp.length_scale, d_n, FLOOR_M)))
            count += len(d_m)
            if a_m is not None:
                sums += float(np.sum(_relative(a_m, a_n, FLOOR_RAD)))
                count += len(a_m)
            moved = d_n > FLOOR_M
            ratio.append(d_m[moved] / d_n[moved])
        scores[h] = sums / max(count, 1)
        ratio_all = np.concatenate(ratio) if ratio else np.zeros(0)
        ratios[h] = float(np.median(ratio_all)) if len(ratio_all) else np.nan
    best = int(np.argmin(scores))  # index 0 (as read) wins ties
    if scores[best] >= scores[0]:
        best = 0
    best = _simplest(hypotheses, scores, best)
    return UnitDiagnostics(
        n_pairs,
        float(scores[0]),
        hypotheses[best],
        float(scores[best]),
        float(np.min(scores[1:])),
        float(ratios[best]),
        joints,
        tuple(dict.fromkeys(t.frame for t in tracks)),
    )
