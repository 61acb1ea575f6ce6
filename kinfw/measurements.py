"""Measurement files (``kinfw-measurements``, version 1, JSON): read, validate, write.

A measurement file lists samples; each sample is one robot configuration ``q`` and the
observations made in it::

    {
      "format": "kinfw-measurements", "version": 1,
      "units": {"length": "mm", "angle": "deg"},
      "joint_names": ["pan", "tilt"],
      "measured_in": "mocap",
      "samples": [
        {"q": [10.0, -5.0],
         "observations": [
           {"frame": "left_plate", "kind": "pose",
            "xyz": [100.0, 200.0, 1400.0], "quat_xyzw": [0, 0, 0.7071067811865476,
                                                         0.7071067811865476]},
           {"frame": "left_camera", "kind": "target", "target": "checkerboard",
            "xyz": [0.0, 50.0, 800.0], "quat_xyzw": [0, 0, 0, 1]},
           {"frame": "flange", "kind": "point", "xyz": [310.0, 5.0, 920.0],
            "offset": [0.0, 0.0, 25.0], "measured_in": "tracker"}
         ]}
      ]
    }

Observation kinds
-----------------
``"pose"``
    ``xyz`` and ``quat_xyzw`` (scalar last) of URDF frame ``frame`` in the measurement
    frame: ``meas_T_frame``. With ``"marker": "name"`` the pose is that of a rigid marker
    on ``frame`` whose pose in ``frame`` is unknown (one unknown per marker name).
``"target"``
    ``xyz`` and ``quat_xyzw`` of a fixed target seen by the camera frame ``frame`` on the
    robot: ``camera_T_target``. The optional ``"target"`` names the target (default
    ``"target"``); the target's pose in the world is unknown. ``marker``, ``offset`` and
    ``measured_in`` are not allowed on target observations.
``"point"``
    ``xyz`` only (no ``quat_xyzw``) of a point rigidly attached to ``frame``, in the
    measurement frame: ``meas_p_point``. ``"offset": [x, y, z]`` gives its position in
    ``frame`` when it is known; without it the offset is estimated. ``"marker"`` names a
    marker whose offset is unknown, so ``marker`` and ``offset`` exclude each other.

The measurement frame is the URDF root link unless ``"measured_in"`` names another frame
(one that is *not* in the URDF, whose pose in the root link is then estimated). A
top-level ``measured_in`` is the default for every ``pose`` and ``point`` observation
of the file; an observation may override it (name the root link to measure in the root).

Units
-----
``"units"`` is required: ``"length"`` is ``"m"`` or ``"mm"``, ``"angle"`` is ``"rad"`` or
``"deg"``. The reader converts to SI: ``xyz`` and ``offset`` by the length unit, and
*every* joint value by the angle unit (the file does not say which joints are
prismatic; in a ``"rad"`` file prismatic values are therefore read as metres). A file
with prismatic joints in millimetres, or mixed units, gives the optional top-level
``"joint_units"``: one of ``"m"``, ``"mm"``, ``"rad"``, ``"deg"`` per entry of
``joint_names``, which then wins over ``units.angle``. The writer always writes SI,
``{"length": "m", "angle": "rad"}``, with floats written by ``repr`` (exact round trip).

Rules
-----
``joint_names`` (non-empty, distinct) may list only the joints that moved; the others are
held at zero (:meth:`Measurements.q_of`). Every sample has ``q`` (one finite number per
joint) and a non-empty ``observations`` list. Quaternions must have a norm within 1e-3
of 1 and are renormalised (a file whose norms are off by more than 1e-6, as when written
with 4 or 5 decimals, gets one warning saying how many and by how much). A marker name
belongs to one frame. Extra keys are
allowed and ignored; ``null`` for an optional key is the same as leaving it out. Every
problem raises :class:`DatasetError` naming the file, the key path
(``samples[7].observations[1].quat_xyzw``) and what was expected.

Observations are grouped (:class:`PoseObservations`, :class:`TargetObservations`,
:class:`PointObservations`, or the group of any kind registered in
:mod:`kinfw.observations`) in first-seen order; each group holds arrays with the batch
axis first and the sample index of every row. Parsing, writing, subsetting and merging
go through the registry: each kind's class reads and writes its own observations.
:func:`check_against_robot` checks a dataset against a URDF, :func:`check_joint_motion`
that the joints move enough to be identified.
"""

from __future__ import annotations

import json
import logging
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.files import write_text_atomic
from kinfw.observations import kind_named, kind_of, kinds
from kinfw.observations.base import (
    DatasetError,
    ObservationReader,
    describe,
    frozen_array,
)
from kinfw.observations.point import PointObservations
from kinfw.observations.pose import QUAT_NORM_TOL, QUAT_ROUNDED_TOL, PoseObservations
from kinfw.observations.target import TargetObservations

if TYPE_CHECKING:
    from kinfw.robot import Robot

__all__ = [
    "FORMAT",
    "QUAT_NORM_TOL",
    "QUAT_ROUNDED_TOL",
    "SUPPORTED_VERSIONS",
    "DatasetError",
    "Measurements",
    "PointObservations",
    "PoseObservations",
    "TargetObservations",
    "check_against_robot",
    "check_joint_motion",
    "concatenate_measurements",
    "measurements_from_dict",
    "measurements_to_dict",
    "read_measurements",
    "write_measurements",
]

logger = logging.getLogger(__name__)

FORMAT = "kinfw-measurements"
SUPPORTED_VERSIONS = (1,)
DISTINCT_TOL = 1e-9
"""Joint values closer than this (rad or m) count as one value in :func:`check_joint_motion`."""

_LENGTH_UNITS = ("m", "mm")
_ANGLE_UNITS = ("rad", "deg")
_JOINT_UNITS = ("m", "mm", "rad", "deg")


# -- the dataset -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class Measurements:
    """A calibration dataset: joint values per sample and the observations made.

    Arrays are read-only; methods return new datasets. Observation groups are held per
    kind (:mod:`kinfw.observations`): :meth:`groups` gives those of one kind,
    :meth:`all_groups` every group. The built-in kinds keep their own fields
    (``poses``, ``targets``, ``points``: the closed form and the camera steps read poses
    and targets only); groups of any other registered kind are in ``others``.

    Attributes
    ----------
    joint_names : tuple of str
        Joints whose values are recorded (columns of ``qs``); others are held at zero.
    qs : ndarray, shape (n, k)
        Joint values of each sample in SI (rad for revolute, m for prismatic joints),
        columns in ``joint_names`` order.
    poses : tuple of PoseObservations
        ``pose`` observation groups, first-seen order.
    targets : tuple of TargetObservations
        ``target`` observation groups, first-seen order.
    points : tuple of PointObservations
        ``point`` observation groups, first-seen order.
    source : str
        File path (or ``"<memory>"``) used in messages.
    others : tuple
        Groups of registered kinds other than the three built-in ones, first-seen order.
    """

    joint_names: tuple[str, ...]
    qs: NDArray[np.float64]
    poses: tuple[PoseObservations, ...] = ()
    targets: tuple[TargetObservations, ...] = ()
    points: tuple[PointObservations, ...] = ()
    source: str = "<memory>"
    others: tuple[Any, ...] = ()

    def __post_init__(self) -> None:
        src = self.source
        names = tuple(self.joint_names)
        if isinstance(self.joint_names, str) or not all(isinstance(n, str) for n in names):
            raise DatasetError(f"{src}: joint_names: expected a sequence of strings")
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            raise DatasetError(f"{src}: joint_names: joint {dup!r} is listed twice")
        qs = np.asarray(self.qs, dtype=float)
        if qs.ndim != 2 or qs.shape[1] != len(names):
            raise DatasetError(
                f"{src}: qs: expected shape (n, {len(names)}) (one column per joint name), "
                f"got {qs.shape}"
            )
        if not np.isfinite(qs).all():
            raise DatasetError(f"{src}: qs: all joint values must be finite")
        object.__setattr__(self, "joint_names", names)
        object.__setattr__(self, "qs", frozen_array(qs, np.float64))
        n = qs.shape[0]
        for attr, cls in (("poses", PoseObservations), ("targets", TargetObservations),
                          ("points", PointObservations), ("others", None)):
            groups = tuple(getattr(self, attr))
            for g in groups:
                if cls is not None and not isinstance(g, cls):
                    raise DatasetError(f"{src}: {attr}: expected {cls.__name__}, got "
                                       f"{type(g).__name__}")
                if cls is None:
                    try:
                        kind = kind_of(g)
                    except TypeError as exc:
                        raise DatasetError(f"{src}: others: {exc}") from None
                    if kind.measurements_field is not None:
                        raise DatasetError(f"{src}: others: {kind.name!r} groups belong in "
                                           f"{kind.measurements_field}")
                if len(g.sample) and g.sample.max() >= n:
                    raise DatasetError(
                        f"{src}: {attr}: {g!r} refers to sample {int(g.sample.max())}, "
                        f"but there are {n} samples"
                    )
            object.__setattr__(self, attr, groups)

    def __repr__(self) -> str:
        others = f", others={list(self.others)}" if self.others else ""
        return (f"Measurements(source={self.source!r}, n_samples={self.n_samples}, "
                f"joint_names={list(self.joint_names)}, poses={list(self.poses)}, "
                f"targets={list(self.targets)}, points={list(self.points)}{others})")

    def groups(self, kind: str) -> tuple[Any, ...]:
        """The observation groups of one kind (by its file name, e.g. ``"pose"``)."""
        field = kind_named(kind).measurements_field
        if field is not None:
            return getattr(self, field)
        return tuple(g for g in self.others if g.kind == kind)

    def all_groups(self) -> Iterator[Any]:
        """Every observation group, kind by kind in registry order."""
        for kind in kinds():
            yield from self.groups(kind.name)

    def with_groups(self, groups: Sequence[Any], **changes: Any) -> Measurements:
        """The dataset with other observation groups (of any registered kinds), and
        other ``changes`` of its fields (e.g. ``qs``)."""
        by_field: dict[str, list[Any]] = {"poses": [], "targets": [], "points": [],
                                          "others": []}
        for g in groups:
            by_field[kind_of(g).measurements_field or "others"].append(g)
        return replace(self, **{k: tuple(v) for k, v in by_field.items()}, **changes)

    def _groups(self) -> Iterator[Any]:
        return self.all_groups()

    @property
    def n_samples(self) -> int:
        """Number of samples ``n`` (rows of :attr:`qs`)."""
        return int(self.qs.shape[0])

    @property
    def observed_frames(self) -> tuple[str, ...]:
        """Every URDF frame named by an observation (``frame`` or ``camera``), no duplicates.

        Ordered by first use: by the first sample that observes the frame, then poses
        before targets before points, then group order. ``measured_in`` frames and marker
        and target names are not included.
        """
        return tuple(_first_uses(self))

    def subset(self, samples: ArrayLike) -> Measurements:
        """The dataset restricted to some samples, renumbered in the order given.

        Parameters
        ----------
        samples : array_like of int, shape (p,), or of bool, shape (n,)
            Sample indices to keep (new sample ``i`` is old sample ``samples[i]``; an
            index may repeat, e.g. for a bootstrap), or a boolean mask over the samples.

        Returns
        -------
        Measurements
            ``qs`` of shape ``(p, k)``; every group keeps the observations of the kept
            samples, with renumbered indices sorted ascending; groups left empty are
            dropped.
        """
        sel = np.asarray(samples)
        n = self.n_samples
        if sel.dtype == bool:
            if sel.shape != (n,):
                raise ValueError(f"{self.source}: subset: a boolean mask needs shape ({n},), "
                                 f"got {sel.shape}")
            sel = np.flatnonzero(sel)
        if sel.size == 0:
            sel = sel.astype(np.int64)
        if sel.ndim != 1 or not np.issubdtype(sel.dtype, np.integer):
            raise ValueError(f"{self.source}: subset: expected a 1-D array of sample indices, "
                             f"got shape {sel.shape}, dtype {sel.dtype}")
        if sel.size and (sel.min() < 0 or sel.max() >= n):
            bad = int(sel[(sel < 0) | (sel >= n)][0])
            raise IndexError(f"{self.source}: subset: sample index {bad} is out of range "
                             f"for {n} samples")
        order = np.argsort(sel, kind="stable")
        sorted_sel = sel[order]

        def select(group: Any) -> Any:
            # Each row of the group appears once per occurrence of its sample in `sel`.
            left = np.searchsorted(sorted_sel, group.sample, side="left")
            counts = np.searchsorted(sorted_sel, group.sample, side="right") - left
            if not counts.any():
                return None
            rows = np.repeat(np.arange(len(group.sample)), counts)
            starts = np.repeat(np.cumsum(counts) - counts, counts)
            new = order[np.repeat(left, counts) + np.arange(len(rows)) - starts]
            by_sample = np.lexsort((rows, new))
            return kind_of(group).take(group, rows[by_sample],
                                       new[by_sample].astype(np.int64))

        kept = [g for g in map(select, self.all_groups()) if g is not None]
        return self.with_groups(kept, qs=self.qs[sel])

    def q_of(self, joint_names: Sequence[str]) -> NDArray[np.float64]:
        """Joint values with columns in another order.

        Parameters
        ----------
        joint_names : sequence of str
            Wanted column order (e.g. a model's joints).

        Returns
        -------
        ndarray, shape (n, len(joint_names))
            SI joint values; a joint not in :attr:`joint_names` is held at zero.
        """
        if isinstance(joint_names, str):
            raise TypeError("q_of: joint_names must be a sequence of names, not a string")
        column = {name: c for c, name in enumerate(self.joint_names)}
        out = np.zeros((self.n_samples, len(joint_names)))
        for c, name in enumerate(joint_names):
            if name in column:
                out[:, c] = self.qs[:, column[name]]
        return out


def _first_uses(measurements: Measurements) -> dict[str, tuple[int, str]]:
    """Observed frame -> (first sample index, kind), ordered by first use."""
    entries = []
    for rank, g in enumerate(measurements._groups()):
        first = int(g.sample.min()) if len(g.sample) else measurements.n_samples
        entries += [(first, rank, frame, g.kind) for frame in kind_of(g).frames(g)]
    out: dict[str, tuple[int, str]] = {}
    for first, _, frame, kind in sorted(entries):
        out.setdefault(frame, (first, kind))
    return out


# -- reading ---------------------------------------------------------------------------

def _columns_to_si(qs: NDArray[np.float64], units: Sequence[str]) -> NDArray[np.float64]:
    out = qs.copy()
    for c, unit in enumerate(units):
        if unit == "mm":
            out[:, c] = qs[:, c] / 1000.0
        elif unit == "deg":
            out[:, c] = np.deg2rad(qs[:, c])
    return out


def read_measurements(path: str | Path) -> Measurements:
    """Read a ``kinfw-measurements`` JSON file (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    Measurements
        In SI units, with ``source`` set to ``str(path)``.

    Raises
    ------
    DatasetError
        When the file cannot be read, is not valid JSON (the message gives line and
        column) or breaks a rule of the format (the message gives the key path).
    """
    path = Path(path)
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DatasetError(f"{source}: measurement file not found") from None
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{source}: not a UTF-8 text file ({exc.reason} at byte "
                           f"{exc.start})") from None
    except OSError as exc:
        raise DatasetError(f"{source}: cannot read measurement file ({exc.strerror})") from None
    if not text.strip():
        raise DatasetError(f"{source}: the file is empty; expected a {FORMAT} JSON document")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{source}: invalid JSON at line {exc.lineno}, column {exc.colno}: "
                           f"{exc.msg}") from None
    return measurements_from_dict(doc, source=source)


def measurements_from_dict(doc: dict[str, Any], source: str = "<memory>") -> Measurements:
    """Validate a parsed ``kinfw-measurements`` document and convert it to SI.

    Parameters
    ----------
    doc : dict
        The JSON document (as from ``json.load``).
    source : str, optional
        Name of the file, for messages.

    Returns
    -------
    Measurements

    Raises
    ------
    DatasetError
        Naming ``source``, the key path and what was expected.
    """
    p = ObservationReader(source)
    if not isinstance(doc, dict):
        raise p.error("", f"expected a JSON object at the top level, got {describe(doc)}")
    fmt = p.get(doc, "format", "", f"{FORMAT!r}")
    if fmt != FORMAT:
        raise p.error("format", f"expected {FORMAT!r}, got {describe(fmt)}")
    version = p.get(doc, "version", "", "1")
    if isinstance(version, bool) or version not in SUPPORTED_VERSIONS:
        supported = ", ".join(map(str, SUPPORTED_VERSIONS))
        raise p.error("version", f"unsupported version {describe(version)}; this reader "
                                 f"supports version {supported}")
    units = p.obj(p.get(doc, "units", "", '{"length": "m" or "mm", "angle": "rad" or "deg"}'),
                  "units")
    length_unit = p.choice(p.get(units, "length", "units", '"m" or "mm"'), "units.length",
                           _LENGTH_UNITS)
    angle_unit = p.choice(p.get(units, "angle", "units", '"rad" or "deg"'), "units.angle",
                          _ANGLE_UNITS)

    raw_names = p.list_of(p.get(doc, "joint_names", "", "a list of joint names"), "joint_names",
                          "joint names")
    joint_names = tuple(p.string(x, f"joint_names[{c}]") for c, x in enumerate(raw_names))
    seen: dict[str, int] = {}
    for c, name in enumerate(joint_names):
        if name in seen:
            raise p.error(f"joint_names[{c}]", f"joint {name!r} is already joint_names"
                                               f"[{seen[name]}]; names must be distinct")
        seen[name] = c
    k = len(joint_names)
    joint_units: Sequence[str] = (angle_unit,) * k
    if doc.get("joint_units") is not None:
        raw_units = doc["joint_units"]
        if not isinstance(raw_units, list) or len(raw_units) != k:
            got = f"{len(raw_units)}" if isinstance(raw_units, list) else describe(raw_units)
            raise p.error("joint_units", f"expected a list of {k} units (one per joint_names "
                                         f"entry), got {got}")
        joint_units = [p.choice(u, f"joint_units[{c}]", _JOINT_UNITS)
                       for c, u in enumerate(raw_units)]
    default_measured_in = None
    if doc.get("measured_in") is not None:
        default_measured_in = p.string(doc["measured_in"], "measured_in")

    samples = p.list_of(p.get(doc, "samples", "", "a list of samples"), "samples", "samples")
    reader = ObservationReader(source, length_unit, default_measured_in)
    names = tuple(k.name for k in kinds())
    expected_kind = (", ".join(repr(n) for n in names[:-1]) + f" or {names[-1]!r}"
                     if len(names) > 1 else repr(names[0]))
    q_rows: list[list[float]] = []
    # One entry per observation, flat; arrays are built once per group at the end.
    obs_group: list[int] = []
    obs_sample: list[int] = []
    rows: list[list[float]] = []
    group_of_key: dict[tuple[Any, ...], int] = {}
    marker_home: dict[str, tuple[str, str]] = {}  # marker -> (frame, where first seen)

    for i, raw_sample in enumerate(samples):
        at = f"samples[{i}]"
        sample = p.obj(raw_sample, at)
        q_rows.append(p.numbers(p.get(sample, "q", at, f"a list of {k} joint values"),
                                k, f"{at}.q", "one per joint_names entry"))
        observations = p.list_of(
            p.get(sample, "observations", at, "a non-empty list of observations"),
            f"{at}.observations", "observations")
        for j, raw_obs in enumerate(observations):
            at_obs = f"{at}.observations[{j}]"
            obs = p.obj(raw_obs, at_obs)
            frame = p.string(p.get(obs, "frame", at_obs, "the name of a URDF frame"),
                             f"{at_obs}.frame")
            kind = kind_named(p.choice(p.get(obs, "kind", at_obs, expected_kind),
                                       f"{at_obs}.kind", names))
            key, row = kind.parse(reader, obs, at_obs, frame)
            marker = kind.marker(key)
            if marker is not None:
                home = marker_home.setdefault(marker[0], (marker[1], at_obs))
                if home[0] != marker[1]:
                    raise p.error(f"{at_obs}.marker",
                                  f"marker {marker[0]!r} is on frame {marker[1]!r} here but "
                                  f"on frame {home[0]!r} in {home[1]}; a marker is rigidly "
                                  "attached to one frame")
            obs_group.append(group_of_key.setdefault((kind.name, key), len(group_of_key)))
            obs_sample.append(i)
            rows.append(row)

    qs = _columns_to_si(np.array(q_rows, dtype=float).reshape(len(q_rows), k), joint_units)
    if reader.rounded:
        warnings.warn(
            f"{source}: {len(reader.rounded)} of {reader.quaternions} quaternions had norms "
            f"off by up to {max(reader.rounded):.2g} (rounded?); renormalised",
            UserWarning,
            stacklevel=2,
        )
    group_ids = np.array(obs_group)
    rows_of_group = np.split(np.argsort(group_ids, kind="stable"),
                             np.cumsum(np.bincount(group_ids))[:-1])
    sample_ids = np.array(obs_sample, dtype=np.int64)
    groups = []
    for (kind_name, key), members in zip(group_of_key, rows_of_group, strict=True):
        data = np.array([rows[r] for r in members], dtype=float)
        groups.append(kind_named(kind_name).group_from_rows(key, sample_ids[members], data))
    out = Measurements(joint_names, qs, source=source).with_groups(groups)
    logger.debug("%s: %d samples, %d observations in %d groups", source, out.n_samples,
                 len(obs_group), len(group_of_key))
    return out


# -- writing ---------------------------------------------------------------------------


def measurements_to_dict(measurements: Measurements) -> dict[str, Any]:
    """A ``kinfw-measurements`` version 1 document of a dataset, in SI units.

    Observations of a sample are listed group by group (poses, targets, points). When
    every pose and point group has the same non-root ``measured_in`` it is written once
    at the top level.

    Parameters
    ----------
    measurements : Measurements

    Returns
    -------
    dict
        JSON-ready (plain lists, floats and strings).

    Raises
    ------
    DatasetError
        If the dataset has no samples or a sample has no observations (the file
        could not be read back).
    """
    m = measurements
    if m.n_samples == 0:
        raise DatasetError(f"{m.source}: cannot write a dataset with no samples")
    per_sample: list[list[dict[str, Any]]] = [[] for _ in range(m.n_samples)]
    frames_in = {kind_of(g).measured_in(g) for g in m.all_groups() if kind_of(g).has_measured_in}
    top_measured_in = next(iter(frames_in)) if len(frames_in) == 1 else None
    for g in m.all_groups():
        for s, obs in zip(g.sample.tolist(), kind_of(g).to_dicts(g, top_measured_in),
                          strict=True):
            per_sample[s].append(obs)

    empty = [i for i, obs in enumerate(per_sample) if not obs]
    if empty:
        raise DatasetError(f"{m.source}: samples[{empty[0]}]: has no observations; every "
                           "sample of a file needs at least one (use subset() to drop it)")
    doc: dict[str, Any] = {
        "format": FORMAT,
        "version": SUPPORTED_VERSIONS[-1],
        "units": {"length": "m", "angle": "rad"},
        "joint_names": list(m.joint_names),
    }
    if top_measured_in is not None:
        doc["measured_in"] = top_measured_in
    doc["samples"] = [{"q": q, "observations": obs}
                      for q, obs in zip(m.qs.tolist(), per_sample, strict=True)]
    return doc


def _dumps(doc: dict[str, Any]) -> str:
    """JSON text with one sample's ``q`` and one observation per line."""
    def dump(value: Any) -> str:
        return json.dumps(value, allow_nan=False, ensure_ascii=False)

    lines = [f"  {dump(key)}: {dump(value)}" for key, value in doc.items() if key != "samples"]
    samples = []
    for sample in doc["samples"]:
        extra = "".join(f", {dump(key)}: {dump(value)}" for key, value in sample.items()
                        if key not in ("q", "observations"))
        observations = ",\n".join(f"      {dump(obs)}" for obs in sample["observations"])
        samples.append(f'    {{"q": {dump(sample["q"])}{extra}, "observations": [\n'
                       f"{observations}\n    ]}}")
    lines.append('  "samples": [\n' + ",\n".join(samples) + "\n  ]")
    return "{\n" + ",\n".join(lines) + "\n}\n"


def write_measurements(path: str | Path, measurements: Measurements) -> None:
    """Write a dataset as a ``kinfw-measurements`` version 1 file in SI units.

    Floats are written with ``repr``, so :func:`read_measurements` gives back ``qs``,
    positions and offsets exactly and transforms to rounding (~1e-16). The file is
    written to a temporary file beside it and then renamed
    (:func:`kinfw.files.write_text_atomic`), so a failed write leaves no half file and
    the previous file, if any, intact.

    Parameters
    ----------
    path : str or Path
        Destination file.
    measurements : Measurements
        The dataset (see :func:`measurements_to_dict` for what cannot be written).
    """
    path = Path(path)
    write_text_atomic(path, _dumps(measurements_to_dict(measurements)))
    logger.debug("wrote %d samples to %s", measurements.n_samples, path)


# -- checks ----------------------------------------------------------------------------


def check_against_robot(measurements: Measurements, robot: Robot) -> Measurements:
    """Check a dataset against a URDF robot and normalise its measurement frames.

    Checks that every entry of ``joint_names`` is a movable joint of the robot, that
    every observed frame is a link or joint of the URDF whose path from the root has
    only supported joints (:meth:`Robot.movable_path`), and that every ``measured_in`` is
    either the root link or a frame that is not in the URDF. Joint values outside the
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
        first sample that uses it.

    Warns
    -----
    UserWarning
        For each joint with values outside its limits: the joint, the number of samples,
        the first sample index and value, and the limits.
    """
    from kinfw.robot import RobotModelError  # kinfw.robot loads Pinocchio

    m = measurements
    src = m.source
    movable = tuple(robot.joint_names)
    joint_types = {j.name: j.type for j in robot.joints}
    for c, name in enumerate(m.joint_names):
        if name in movable:
            continue
        if name in joint_types:
            raise DatasetError(f"{src}: joint_names[{c}]: joint {name!r} is a "
                               f"{joint_types[name]} joint in {robot.source}; only movable "
                               f"joints can be listed: {list(movable)}")
        raise DatasetError(f"{src}: joint_names[{c}]: joint {name!r} is not in "
                           f"{robot.source}; its movable joints are {list(movable)}")

    used: set[str] = set()
    for frame, (i, kind) in _first_uses(m).items():
        if not robot.has_frame(frame):
            raise DatasetError(f"{src}: samples[{i}]: frame {frame!r} ({kind} observation) is "
                               f"not a link or joint of {robot.source}; its links are "
                               f"{list(robot.link_names)}")
        try:
            used.update(robot.movable_path(frame))
        except RobotModelError as exc:
            raise DatasetError(f"{src}: samples[{i}]: frame {frame!r} cannot be calibrated "
                               f"with this URDF: {exc}") from None
    idle = [n for n in m.joint_names if n not in used]
    if idle:
        logger.info("%s: joints %s are not on the path to any observed frame; ignored",
                    src, idle)
    held = [n for n in movable if n in used and n not in m.joint_names]
    if held:
        logger.info("%s: joints %s on observed paths are not in joint_names; held at zero",
                    src, held)

    root = robot.root_link
    first_in: dict[str, int] = {}
    for g in m.all_groups():
        frame_in = kind_of(g).measured_in(g)
        if frame_in is not None and len(g.sample):
            first = int(g.sample.min())
            first_in[frame_in] = min(first_in.get(frame_in, first), first)
    for frame_in, i in first_in.items():
        if frame_in != root and robot.has_frame(frame_in):
            raise DatasetError(
                f"{src}: samples[{i}]: measured_in {frame_in!r} is a frame of "
                f"{robot.source} but not its root link {root!r}; measurements are expressed "
                f"either in the root link (omit measured_in) or in an external frame that is "
                f"not in the URDF (its pose in the root is then estimated). Express the data "
                f"in {root!r}, or rename the external frame"
            )

    _warn_limits(m, robot)
    if root not in first_in:
        return m
    return m.with_groups(_merge_same_key(
        replace(g, measured_in=None) if kind_of(g).measured_in(g) == root else g
        for g in m.all_groups()))


def _merge_same_key(groups: Iterable[Any]) -> tuple[Any, ...]:
    """Merge groups with equal keys (kind, frame, marker...), rows sorted by sample."""
    by_key: dict[tuple[Any, ...], list[Any]] = {}
    for g in groups:
        by_key.setdefault(kind_of(g).key(g), []).append(g)
    return tuple(parts[0] if len(parts) == 1 else kind_of(parts[0]).concatenate(parts)
                 for parts in by_key.values())


def concatenate_measurements(*parts: Measurements) -> Measurements:
    """One dataset holding the samples of ``parts`` in order.

    The joint names are united (first-seen order); a joint that a part does not list is
    held at zero in its samples. Groups that observe the same thing (same frame, kind,
    marker, offset and measurement frame) are merged. The source is the parts' sources
    joined by ``" + "``.
    """
    if not parts:
        raise ValueError("concatenate_measurements: give at least one dataset")
    names = tuple(dict.fromkeys(n for p in parts for n in p.joint_names))
    offsets = np.cumsum([0, *(p.n_samples for p in parts[:-1])])

    groups = _merge_same_key(replace(g, sample=g.sample + off)
                             for p, off in zip(parts, offsets, strict=True)
                             for g in p.all_groups())
    return Measurements(names, np.zeros((0, len(names)))).with_groups(
        groups, qs=np.concatenate([p.q_of(names) for p in parts]),
        source=" + ".join(dict.fromkeys(p.source for p in parts)))


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


def check_joint_motion(measurements: Measurements, joint_names: Sequence[str], *,
                       min_distinct: int = 2) -> None:
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

    Raises
    ------
    DatasetError
        Naming every joint with too few values, how many distinct values it has and
        how many are needed.
    """
    if isinstance(joint_names, str):
        raise TypeError("check_joint_motion: joint_names must be a sequence of names, "
                        "not a string")
    if min_distinct < 1:
        raise ValueError(f"check_joint_motion: min_distinct must be >= 1, got {min_distinct}")
    m = measurements
    qs = m.q_of(joint_names)
    problems = []
    for c, name in enumerate(joint_names):
        values = np.sort(qs[:, c]) + 0.0  # + 0.0 turns -0.0 into 0.0 for the message
        distinct = values[np.concatenate(([True], np.diff(values) >= DISTINCT_TOL))] \
            if len(values) else values
        if len(distinct) >= min_distinct:
            continue
        shown = ", ".join(f"{v:.6g}" for v in distinct[:5]) + (", ..." if len(distinct) > 5
                                                               else "")
        held = "" if name in m.joint_names else " (not in joint_names, so held at zero)"
        plural = "" if len(distinct) == 1 else "s"
        problems.append(
            f"joint {name!r}{held} moves through {len(distinct)} distinct value{plural}"
            f"{f' ({shown})' if shown else ''} in {m.n_samples} samples; at least "
            f"{min_distinct} are needed to identify it"
        )
    if problems:
        raise DatasetError(f"{m.source}: " + "; ".join(problems))
