"""Checks of a dataset: against a URDF robot, and that its joints move enough.

:func:`check_against_robot` checks joint names, observed frames and measurement frames
against the robot (and warns about joint values outside the limits);
:func:`check_joint_motion` that each joint moves through enough distinct values, but for
the joints :func:`fixed_in_experiment` finds held still where they do not matter (the
legs a humanoid stands on while its hands touch a table fixed to its foot).
"""

from __future__ import annotations

import difflib
import logging
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from kinfw.measurements._dataset import Measurements, first_uses, merge_same_key
from kinfw.observations import DatasetError, kind_of

if TYPE_CHECKING:
    from kinfw.model import Robot

logger = logging.getLogger("kinfw.measurements")

DISTINCT_TOL = 1e-9
"""Joint values closer than this (rad or m) count as one value in :func:`check_joint_motion`."""


def check_against_robot(measurements: Measurements, robot: Robot) -> Measurements:
    """Check a dataset against a URDF robot and normalise its measurement frames.

    Checks that every entry of ``joint_names`` is a movable joint of the robot, that
    every observed frame is a link or joint of the URDF whose path from the root has
    only supported joints (:meth:`Robot.movable_path`), that every payload's frame is a
    frame of the robot, and that no observation is
    measured in its own frame. A ``measured_in`` is the root link, a frame that is not
    in the URDF (external: its pose in the root is estimated), or any other frame of the
    URDF (it moves with the robot, e.g. a head camera: its path is checked like an
    observed frame's, :func:`robot_measurement_frames`). Joint values outside the
    URDF limits are warned about (one :class:`UserWarning` per joint), not rejected.

    Parameters
    ----------
    measurements : Measurements
    robot : Robot

    Returns
    -------
    Measurements
        ``measurements`` itself, or a copy in which ``measured_in`` equal to the root
        link is replaced by None (groups that then coincide are merged).

    Raises
    ------
    DatasetError
        Naming the joint (and listing the robot's movable joints), or the frame and the
        first sample that uses it; or a plane, ball or divot observed too few times to be
        placed whose name is close to one observed more often (a misspelling would be
        fitted as a thing of its own, undetermined).

    Warns
    -----
    UserWarning
        For each joint with values outside its limits: the joint, the number of samples,
        the first sample index and value, and the limits.
    """
    m = measurements
    _check_joint_names(m, robot)
    _check_entity_names(m)
    first_in = _first_measured_in(m, robot)
    _check_observed_paths(m, robot, first_in)
    _check_payload_frames(m, robot)
    _warn_limits(m, robot)
    root = robot.root_link
    if root not in first_in:
        return m
    return m.with_groups(
        merge_same_key(
            replace(g, measured_in=None) if kind_of(g).measured_in(g) == root else g
            for g in m.all_groups()
        )
    )


def _check_entity_names(m: Measurements) -> None:
    """Refuse an observed thing seen fewer times than its kind needs to place it
    (:attr:`kinfw.observations.ObservationKind.entity_min`: a plane's three contacts) whose
    name is close to another of its kind seen more often (``tabel`` beside ``table``)."""
    seen: dict[tuple[str, str], list[int]] = {}
    least: dict[str, int] = {}
    for g in m.all_groups():
        kind = kind_of(g)
        name = kind.entity(g)
        if name is not None:
            seen.setdefault((kind.name, name), []).extend(int(i) for i in g.sample)
            least[kind.name] = kind.entity_min
    for (kind, name), samples in seen.items():
        if len(samples) >= least[kind]:
            continue
        common = [n for (k, n), s in seen.items() if k == kind and len(s) >= least[kind]]
        close = difflib.get_close_matches(name, common, n=1, cutoff=0.75)
        if close:
            where = ", ".join(f"samples[{i}]" for i in sorted(samples))
            raise DatasetError(
                f"{m.source}: {kind} {name!r} is observed {len(samples)} time(s) ({where}), "
                f"{kind} {close[0]!r} {len(seen[kind, close[0]])} times: a misspelling of "
                f"{close[0]!r}? (as written, {name!r} is a {kind} of its own, which fewer "
                f"than {least[kind]} observations cannot place)"
            )


def _check_joint_names(m: Measurements, robot: Robot) -> None:
    """Raise unless every entry of ``m.joint_names`` is a movable joint of ``robot``."""
    src = m.source
    movable = tuple(robot.joint_names)
    joint_types = {j.name: j.type for j in robot.joints}
    for c, name in enumerate(m.joint_names):
        if name in movable:
            continue
        if name in joint_types:
            raise DatasetError(
                f"{src}: joint_names[{c}]: joint {name!r} is a "
                f"{joint_types[name]} joint in {robot.source}; only movable "
                f"joints can be listed: {list(movable)}"
            )
        raise DatasetError(
            f"{src}: joint_names[{c}]: joint {name!r} is not in "
            f"{robot.source}; its movable joints are {list(movable)}"
        )


def _first_measured_in(m: Measurements, robot: Robot) -> dict[str, int]:
    """The first sample that uses each ``measured_in`` frame.

    Raises if an observation is measured in its own frame; logs a warning for a
    ``measured_in`` that is not in the URDF but close to a link's name (a typo?).
    """
    src = m.source
    first_in: dict[str, int] = {}
    for g in m.all_groups():
        kind = kind_of(g)
        frame_in = kind.measured_in(g)
        if frame_in is None or not len(g.sample):
            continue
        first = int(g.sample.min())
        first_in[frame_in] = min(first_in.get(frame_in, first), first)
        if frame_in in kind.frames(g):
            raise DatasetError(
                f"{src}: samples[{first}]: a {kind.name} observation of frame {frame_in!r} "
                f"is measured in {frame_in!r} itself; measured_in must be another frame "
                f"(the root link, an external frame, or another frame of {robot.source})"
            )
    for frame_in, i in first_in.items():
        close = (
            []
            if robot.has_frame(frame_in)
            else difflib.get_close_matches(frame_in, robot.link_names, n=1, cutoff=0.85)
        )
        if close:  # an external frame, or a typo of a robot frame?
            logger.warning(
                "%s: samples[%d]: measured_in %r is not a frame of %s: it is taken as an "
                "external frame whose pose is estimated; did you mean the robot frame %r?",
                src,
                i,
                frame_in,
                robot.source,
                close[0],
            )
    return first_in


def _check_observed_paths(m: Measurements, robot: Robot, first_in: Mapping[str, int]) -> None:
    """Raise unless every observed frame (and robot ``measured_in``) can be calibrated.

    ``first_in`` gives the first sample of each ``measured_in`` frame. Logs the joints
    on no observed path and those on a path but not in ``joint_names``.
    """
    from kinfw.model import RobotModelError

    src = m.source
    root = robot.root_link
    uses = dict(first_uses(m))
    for frame_in, i in first_in.items():
        if frame_in != root and robot.has_frame(frame_in) and frame_in not in uses:
            uses[frame_in] = (i, "measured_in")

    used: set[str] = set()
    for frame, (i, kind) in uses.items():
        if not robot.has_frame(frame):
            raise DatasetError(
                f"{src}: samples[{i}]: frame {frame!r} ({kind} observation) is "
                f"not a link or joint of {robot.source}; its links are "
                f"{list(robot.link_names)}"
            )
        try:
            used.update(robot.movable_path(frame))
        except RobotModelError as exc:
            raise DatasetError(
                f"{src}: samples[{i}]: frame {frame!r} cannot be calibrated with this URDF: {exc}"
            ) from None
    idle = [n for n in m.joint_names if n not in used]
    if idle:
        logger.info("%s: joints %s are not on the path to any observed frame; ignored", src, idle)
    movable = tuple(robot.joint_names)
    held = [n for n in movable if n in used and n not in m.joint_names]
    if held:
        logger.info(
            "%s: joints %s on observed paths are not in joint_names; held at zero", src, held
        )


def _check_payload_frames(m: Measurements, robot: Robot) -> None:
    """Raise unless every payload's frame is a link or frame of the robot, naming the
    first sample that uses it and the robot's closest link names."""
    payloads = m.payloads
    if payloads is None:
        return
    for f, frame in enumerate(payloads.frames):
        using = np.flatnonzero(payloads.frame_index == f)
        if not len(using) or robot.has_frame(frame):
            continue
        close = difflib.get_close_matches(frame, robot.link_names, n=3, cutoff=0.6)
        links = close or list(robot.link_names)[-3:]
        raise DatasetError(
            f"{m.source}: samples[{int(using[0])}].payload.frame: {frame!r} is not a frame of "
            f"{robot.source}; {'closest' if close else 'its last'} links: "
            + ", ".join(map(repr, links))
        )


def robot_measurement_frames(measurements: Measurements, robot: Robot) -> tuple[str, ...]:
    """The ``measured_in`` frames that are frames of ``robot`` other than its root link.

    Observations in such a frame ``c`` (a camera on the robot's head) are predicted as
    ``inv(root_T_c(q)) @ root_T_frame(q)``: ``c`` is an end frame of the model like the
    observed frames. In order of first appearance, no duplicates.
    """
    root = robot.root_link
    names = (kind_of(g).measured_in(g) for g in measurements.all_groups())
    return tuple(
        dict.fromkeys(n for n in names if n is not None and n != root and robot.has_frame(n))
    )


def observed_joints(measurements: Measurements, robot: Robot) -> tuple[str, ...]:
    """The movable joints whose geometry the observations see (robot order).

    The joints on the paths from the root to the observed frames and to the robot
    frames observations are measured in; when every observation is relative to a frame
    of the robot (:meth:`~kinfw.observations.ObservationKind.relative_to`: measured in
    it, or a camera seeing a board on the robot), without the joints above each pair's
    common ancestor,
    which move both frames alike and never enter the data.
    """
    frames = (*measurements.observed_frames, *robot_measurement_frames(measurements, robot))
    names = set(robot.topology(tuple(dict.fromkeys(frames))).joint_names)
    root = robot.root_link

    def path(frame: str) -> set[str]:
        return {j.name for j in robot.path_joints(frame) if j.type != "fixed"}

    shared: set[str] | None = None
    for g in measurements.all_groups():
        kind = kind_of(g)
        inside = kind.relative_to(g)
        if inside is None or inside == root or not robot.has_frame(inside):
            return tuple(n for n in robot.joint_names if n in names)
        for f in kind.frames(g):
            common = path(f) & path(inside)
            shared = common if shared is None else shared & common
    return tuple(n for n in robot.joint_names if n in names - (shared or set()))


def _warn_limits(m: Measurements, robot: Robot) -> None:
    """One UserWarning per joint outside its limits.

    The pipeline checks the same data in every stage (closed form, refinement, each
    stage's errors), each from its own line. The warning is therefore attributed to one
    place, the call in :func:`check_against_robot` (``stacklevel=2``), not to the
    callers: Python's default filter, which shows a warning once per text and place,
    then shows it once however many stages check the data.
    """
    lower, upper = robot.joint_limits(m.joint_names)
    outside = (m.qs < lower) | (m.qs > upper)
    for c in np.flatnonzero(outside.any(axis=0)):
        name = m.joint_names[c]
        rows = np.flatnonzero(outside[:, c])
        i = int(rows[0])
        unit = "rad" if robot.joint(name).is_revolute else "m"
        warnings.warn(
            f"{m.source}: joint {name!r} is outside its URDF limits [{lower[c]:.6g}, "
            f"{upper[c]:.6g}] {unit} in {len(rows)} of {m.n_samples} samples (first: "
            f"samples[{i}], value {m.qs[i, c]:.6g} {unit})",
            UserWarning,
            stacklevel=2,
        )


def _distinct(values: np.ndarray) -> np.ndarray:
    """The distinct values (sorted) of one joint's column: closer than
    :data:`DISTINCT_TOL` count as one."""
    values = np.sort(values) + 0.0  # + 0.0 turns -0.0 into 0.0 for the messages
    if not len(values):
        return values
    return values[np.concatenate(([True], np.diff(values) >= DISTINCT_TOL))]


def fixed_in_experiment(
    measurements: Measurements, robot: Robot, *, min_distinct: int = 2
) -> tuple[str, ...]:
    """The joints held still where that loses nothing but their own parameters (robot
    order).

    A frame of the robot that observations are relative to (a plane fixed to the foot a
    humanoid stands on: ``measured_in``) hangs from the common ancestor of it and the
    observed frames by a branch of joints that carry no observed frame (the leg). When
    every such joint moves through fewer than ``min_distinct`` values and every
    observation relative to that frame touches something of unknown pose fixed in it (a
    plane, a ball, a point: :meth:`~kinfw.observations.ObservationKind.trained_unknowns`),
    the branch is one constant transform the unknown absorbs: those joints are fixed in
    this experiment, their parameters are not identifiable from these data (the
    calibration keeps them at the nominal) and their stillness is no error. A still
    joint on an observed frame's path, or on a branch to a frame whose observations pin
    it (a head camera measuring points), is needed: :func:`check_joint_motion` refuses
    it.

    Parameters
    ----------
    measurements : Measurements
    robot : Robot
    min_distinct : int, optional
        As in :func:`check_joint_motion`.
    """
    root = robot.root_link

    def path(frame: str) -> set[str]:
        return {j.name for j in robot.path_joints(frame) if j.type != "fixed"}

    needed: set[str] = set()
    branches: dict[str, set[str]] = {}
    absorbed: dict[str, bool] = {}
    for g in measurements.all_groups():
        kind = kind_of(g)
        on_probe = set().union(*(path(f) for f in kind.frames(g)))
        needed |= on_probe
        inside = kind.relative_to(g)
        if inside is None or inside == root or not robot.has_frame(inside):
            continue
        branches.setdefault(inside, set()).update(path(inside) - on_probe)
        absorbed[inside] = absorbed.get(inside, True) and bool(kind.trained_unknowns(g))
    qs = measurements.q_of(robot.joint_names)
    still = {
        name for c, name in enumerate(robot.joint_names) if len(_distinct(qs[:, c])) < min_distinct
    }
    fixed: set[str] = set()
    for inside, branch in branches.items():
        branch -= needed
        if absorbed[inside] and branch and branch <= still:
            fixed |= branch
    return tuple(n for n in robot.joint_names if n in fixed)


def check_joint_motion(
    measurements: Measurements,
    joint_names: Sequence[str],
    *,
    min_distinct: int = 2,
    fixed: Sequence[str] = (),
) -> None:
    """Check that each joint moves through enough distinct values to be identified.

    Parameters
    ----------
    measurements : Measurements
    joint_names : sequence of str
        Joints to check (e.g. the movable joints on the paths to the observed frames). A
        joint not in ``measurements.joint_names`` is held at zero: one value.
    min_distinct : int, optional
        Number of distinct values needed per joint (values closer than
        :data:`DISTINCT_TOL` = 1e-9 rad or m count as one).
    fixed : sequence of str, optional
        Joints fixed in this experiment (:func:`fixed_in_experiment`): held still where
        only their own parameters are lost, so not checked.

    Raises
    ------
    DatasetError
        Naming every other joint with too few values, how many distinct values it has
        and how many are needed.
    """
    if isinstance(joint_names, str):
        raise TypeError("check_joint_motion: joint_names must be a sequence of names, not a string")
    if min_distinct < 1:
        raise ValueError(f"check_joint_motion: min_distinct must be >= 1, got {min_distinct}")
    m = measurements
    joint_names = [n for n in joint_names if n not in set(fixed)]
    qs = m.q_of(joint_names)
    problems = []
    for c, name in enumerate(joint_names):
        distinct = _distinct(qs[:, c])
        if len(distinct) >= min_distinct:
            continue
        shown = ", ".join(f"{v:.6g}" for v in distinct[:5]) + (", ..." if len(distinct) > 5 else "")
        held = "" if name in m.joint_names else " (not in joint_names, so held at zero)"
        plural = "" if len(distinct) == 1 else "s"
        problems.append(
            f"joint {name!r}{held} moves through {len(distinct)} distinct value{plural}"
            f"{f' ({shown})' if shown else ''} in {m.n_samples} samples; at least "
            f"{min_distinct} are needed to identify it"
        )
    if problems:
        raise DatasetError(f"{m.source}: " + "; ".join(problems))


#: Two samples (or pose pairs) whose numbers all agree within this, relative to the
#: larger magnitude (at least 1 SI unit: 1e-12 m, 1e-12 rad), are one measurement
#: recorded twice (:func:`duplicate_samples`).
DUPLICATE_RTOL = 1e-12
#: Duplicates a warning names one by one; the rest are counted.
SHOWN_DUPLICATES = 5


def equal_row_pairs(
    values: np.ndarray, *, rtol: float = DUPLICATE_RTOL
) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of rows of ``values`` (n, k) equal entry by entry within ``rtol``
    relative (to the larger magnitude, at least 1; NaN equals NaN): ``(earlier, later)``
    index arrays.

    The rows are sorted by a fixed random projection, so only rows whose projections are
    within the tolerance are compared (n log n for distinct rows, whatever the columns)."""
    v = np.asarray(values, dtype=float).reshape(len(values), -1)
    nan = np.isnan(v)
    if nan.any():  # NaN (no value, e.g. no per-point sigma) equals NaN
        v = np.concatenate([np.where(nan, 0.0, v), nan.astype(float)], axis=1)
    n = len(v)
    if n < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    w = np.abs(np.random.default_rng(0).normal(size=v.shape[1])) + 0.5
    key = v @ w
    order = np.argsort(key, kind="stable")
    s, key = v[order], key[order]
    scale = np.maximum(np.abs(s), 1.0)
    key_tol = rtol * float(w @ scale.max(axis=0)) * (1.0 + 1e-6)
    earlier, later = [], []
    for d in range(1, n):
        near = key[d:] - key[:-d] <= key_tol
        if not near.any():
            break
        k = np.flatnonzero(near)
        tol = rtol * np.maximum(scale[k], scale[k + d])
        k = k[np.all(np.abs(s[k + d] - s[k]) <= tol, axis=1)]
        earlier.append(np.minimum(order[k], order[k + d]))
        later.append(np.maximum(order[k], order[k + d]))
    if not earlier:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(earlier).astype(np.int64), np.concatenate(later).astype(np.int64)


def first_copies(earlier: np.ndarray, later: np.ndarray) -> np.ndarray:
    """``(d, 2)`` rows ``[duplicate, its first copy]`` of equal pairs ``(earlier,
    later)``, sorted by the duplicate."""
    if not len(later):
        return np.zeros((0, 2), np.int64)
    order = np.lexsort((earlier, later))
    later, earlier = later[order], earlier[order]
    first = np.r_[True, later[1:] != later[:-1]]
    return np.stack([later[first], earlier[first]], axis=1).astype(np.int64)


def _rows_equal(a: np.ndarray, b: np.ndarray, rtol: float) -> bool:
    if a.shape != b.shape:
        return False
    if np.issubdtype(a.dtype, np.number) and np.issubdtype(b.dtype, np.number):
        a, b = a.astype(float), b.astype(float)
        close = np.abs(a - b) <= rtol * np.maximum(np.maximum(abs(a), abs(b)), 1.0)
        return bool(np.all(close | (np.isnan(a) & np.isnan(b))))
    return bool(np.array_equal(a, b))


def _sample_columns(group, n: int) -> np.ndarray:
    """The per-row fields of a group with one row per sample as columns over the ``n``
    samples: numbers as they are, other values (names) as integer codes, and a column
    that is 1 where the sample has a row (absent rows are zeros)."""
    columns = [np.zeros((n, 1))]
    columns[0][group.sample, 0] = 1.0
    for field in kind_of(group).row_fields:
        a = np.asarray(getattr(group, field))
        if not np.issubdtype(a.dtype, np.number):
            a = np.unique(a.astype(str), return_inverse=True)[1] + 1.0
        a = a.reshape(len(a), -1).astype(float)
        block = np.zeros((n, a.shape[1]))
        block[group.sample] = a
        columns.append(block)
    return np.concatenate(columns, axis=1)


def duplicate_samples(measurements: Measurements, *, rtol: float = DUPLICATE_RTOL) -> np.ndarray:
    """The samples that repeat an earlier one: equal joint values and, in every
    observation group, the same observations (every per-row field, numbers within
    ``rtol`` relative, at least 1 SI unit: :data:`DUPLICATE_RTOL`).

    Returns
    -------
    ndarray of int, shape (d, 2)
        Rows ``[sample, earlier]``: each duplicate sample and the first sample it
        repeats, sorted by the duplicate."""
    n = measurements.n_samples
    single, multiple = [], []
    for g in measurements.all_groups():
        (single if len(np.unique(g.sample)) == len(g.sample) else multiple).append(g)
    rows = np.concatenate([measurements.qs, *(_sample_columns(g, n) for g in single)], axis=1)
    earlier, later = equal_row_pairs(rows, rtol=rtol)
    if not len(later) or not multiple:
        return first_copies(earlier, later)
    tables = []  # groups with several rows per sample (a board's points): compared row-wise
    for g in multiple:
        order = np.argsort(g.sample, kind="stable")
        bounds = np.searchsorted(g.sample[order], np.arange(n + 1))
        fields = [np.asarray(getattr(g, f)) for f in kind_of(g).row_fields]
        tables.append((order, bounds, fields))

    def same(i: int, j: int) -> bool:
        for order, bounds, fields in tables:
            ri, rj = order[bounds[i] : bounds[i + 1]], order[bounds[j] : bounds[j + 1]]
            if len(ri) != len(rj) or not all(_rows_equal(f[ri], f[rj], rtol) for f in fields):
                return False
        return True

    keep = np.array([same(int(i), int(j)) for i, j in zip(earlier, later, strict=True)])
    return first_copies(earlier[keep], later[keep])


def duplicates_warning(source: str, duplicates: np.ndarray, n: int, what: str) -> str:
    """The warning that ``duplicates`` (rows ``[duplicate, first copy]``) of the ``n``
    ``what`` (``"samples"``, ``"pose pairs"``) of ``source`` were dropped."""
    shown = ", ".join(f"{int(d)} (= {int(e)})" for d, e in duplicates[:SHOWN_DUPLICATES])
    more = len(duplicates) - SHOWN_DUPLICATES
    return (
        f"{source}: {len(duplicates)} of the {n} {what} repeat an earlier one: "
        f"{shown}{f' and {more} more' if more > 0 else ''}; each is counted once (dropped, "
        f"the later {what} renumbered)\n"
        f"(equal to {DUPLICATE_RTOL:g} relative: recorded or concatenated twice? "
        "--keep-duplicates / keep_duplicates=True keeps them, and every sigma shrinks)"
    )


def drop_duplicate_samples(measurements: Measurements, *, stacklevel: int = 2) -> Measurements:
    """``measurements`` without the samples that repeat an earlier one
    (:func:`duplicate_samples`), with one ``UserWarning`` naming them (a few shown, the
    rest counted); unchanged, and silent, when there are none. A sample recorded twice
    would count twice in the fit and shrink every sigma by 1/sqrt(2)."""
    duplicates = duplicate_samples(measurements)
    if not len(duplicates):
        return measurements
    warnings.warn(
        duplicates_warning(measurements.source, duplicates, measurements.n_samples, "samples"),
        UserWarning,
        stacklevel=stacklevel,
    )
    keep = np.ones(measurements.n_samples, dtype=bool)
    keep[duplicates[:, 0]] = False
    return measurements.subset(keep)
