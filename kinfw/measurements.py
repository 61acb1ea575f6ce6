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
:class:`PointObservations`) in first-seen order; each group holds arrays with the batch
axis first and the sample index of every row. :func:`check_against_robot` checks a
dataset against a URDF, :func:`check_joint_motion` that the joints move enough to be
identified.
"""

from __future__ import annotations

import json
import logging
import math
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.files import write_text_atomic
from kinfw.transforms import (
    check_transform,
    transform_from_xyz_quat_xyzw,
    xyz_quat_xyzw_from_transform,
)

if TYPE_CHECKING:
    from kinfw.robot import Robot

__all__ = [
    "FORMAT",
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
QUAT_NORM_TOL = 1e-3
"""Largest accepted ``| |quat_xyzw| - 1 |`` in a file (quaternions written with 4 or 5
decimals are off by up to a few 1e-5); accepted quaternions are renormalised."""
QUAT_ROUNDED_TOL = 1e-6
"""Beyond this ``| |quat_xyzw| - 1 |`` (and within :data:`QUAT_NORM_TOL`) the reader warns,
once per file, that it renormalised rounded quaternions."""
DISTINCT_TOL = 1e-9
"""Joint values closer than this (rad or m) count as one value in :func:`check_joint_motion`."""

_KINDS = ("pose", "target", "point")
_LENGTH_UNITS = ("m", "mm")
_ANGLE_UNITS = ("rad", "deg")
_JOINT_UNITS = ("m", "mm", "rad", "deg")
_DEFAULT_TARGET = "target"


class DatasetError(ValueError):
    """A measurement file or dataset that cannot be used.

    The message names the file (``Measurements.source``), the sample index and key path
    when relevant (``samples[7].observations[1].quat_xyzw``) and what was expected.
    """


# -- array helpers ---------------------------------------------------------------------


def _frozen(values: ArrayLike, dtype: type) -> NDArray[Any]:
    """A read-only copy of ``values``: dataset arrays are shared, never mutated."""
    arr = np.array(values, dtype=dtype, copy=True)
    arr.flags.writeable = False
    return arr


def _sample_array(values: ArrayLike, name: str) -> NDArray[np.int64]:
    arr = np.asarray(values)
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected shape (m,), got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"{name}: expected integer sample indices, got dtype {arr.dtype}")
    if arr.size and arr.min() < 0:
        raise ValueError(f"{name}: sample indices must be >= 0, got {int(arr.min())}")
    return _frozen(arr, np.int64)


def _data_array(values: ArrayLike, shape: tuple[int, ...], name: str) -> NDArray[np.float64]:
    arr = np.asarray(values, dtype=float)
    if arr.shape != shape:
        expected = "(" + ", ".join(map(str, shape)) + ("," if len(shape) == 1 else "") + ")"
        raise ValueError(f"{name}: expected shape {expected}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}: all values must be finite")
    return _frozen(arr, np.float64)


# -- observation groups ----------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class PoseObservations:
    """All ``pose`` observations that share ``(frame, marker, measured_in)``.

    Attributes
    ----------
    frame : str
        URDF frame (link or joint) the pose belongs to.
    sample : ndarray of int64, shape (m,)
        Index into :attr:`Measurements.qs` of each observation's sample.
    meas_T_frame : ndarray, shape (m, 4, 4)
        Pose of ``frame`` (or of its marker) in the measurement frame, metres.
    marker : str or None
        Name of a rigid marker on ``frame`` whose pose in ``frame`` is unknown; None when
        ``frame`` itself is measured.
    measured_in : str or None
        Measurement frame; None is the URDF root link.
    """

    frame: str
    sample: NDArray[np.int64]
    meas_T_frame: NDArray[np.float64]
    marker: str | None = None
    measured_in: str | None = None

    def __post_init__(self) -> None:
        name = f"PoseObservations(frame={self.frame!r})"
        sample = _sample_array(self.sample, f"{name}.sample")
        T = _data_array(self.meas_T_frame, (len(sample), 4, 4), f"{name}.meas_T_frame")
        check_transform(T, name=f"{name}.meas_T_frame")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(self, "meas_T_frame", T)

    def __repr__(self) -> str:
        return (f"PoseObservations(frame={self.frame!r}, marker={self.marker!r}, "
                f"measured_in={self.measured_in!r}, m={len(self.sample)})")

    def _take(self, rows: NDArray[np.intp], sample: NDArray[np.int64]) -> PoseObservations:
        return replace(self, sample=sample, meas_T_frame=self.meas_T_frame[rows])

    @property
    def _key(self) -> tuple[Any, ...]:
        return ("pose", self.frame, self.marker, self.measured_in)


@dataclass(frozen=True, slots=True, eq=False)
class TargetObservations:
    """All ``target`` observations of one fixed target by one camera frame.

    Attributes
    ----------
    camera : str
        URDF camera frame on the robot (the file's ``"frame"``).
    sample : ndarray of int64, shape (m,)
        Index into :attr:`Measurements.qs` of each observation's sample.
    camera_T_target : ndarray, shape (m, 4, 4)
        Pose of the target in the camera frame (camera extrinsic calibration), metres.
    target : str
        Name of the fixed target (file key ``"target"``, default ``"target"``); its pose
        in the world is unknown.
    """

    camera: str
    sample: NDArray[np.int64]
    camera_T_target: NDArray[np.float64]
    target: str = _DEFAULT_TARGET

    def __post_init__(self) -> None:
        name = f"TargetObservations(camera={self.camera!r})"
        sample = _sample_array(self.sample, f"{name}.sample")
        T = _data_array(self.camera_T_target, (len(sample), 4, 4), f"{name}.camera_T_target")
        check_transform(T, name=f"{name}.camera_T_target")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(self, "camera_T_target", T)

    def __repr__(self) -> str:
        return (f"TargetObservations(camera={self.camera!r}, target={self.target!r}, "
                f"m={len(self.sample)})")

    def _take(self, rows: NDArray[np.intp], sample: NDArray[np.int64]) -> TargetObservations:
        return replace(self, sample=sample, camera_T_target=self.camera_T_target[rows])

    @property
    def _key(self) -> tuple[Any, ...]:
        return ("target", self.camera, self.target)


@dataclass(frozen=True, slots=True, eq=False)
class PointObservations:
    """All ``point`` observations that share ``(frame, marker, measured_in, offset)``.

    Attributes
    ----------
    frame : str
        URDF frame the point is rigidly attached to.
    sample : ndarray of int64, shape (m,)
        Index into :attr:`Measurements.qs` of each observation's sample.
    meas_p_point : ndarray, shape (m, 3)
        Position of the point in the measurement frame, metres.
    offset : ndarray, shape (3,), or None
        ``frame_p_point``, the point in ``frame`` (metres), when the file gives it; None
        when it is unknown and estimated.
    marker : str or None
        Name of the marker (its offset is unknown; excludes ``offset``).
    measured_in : str or None
        Measurement frame; None is the URDF root link.
    """

    frame: str
    sample: NDArray[np.int64]
    meas_p_point: NDArray[np.float64]
    offset: NDArray[np.float64] | None = None
    marker: str | None = None
    measured_in: str | None = None

    def __post_init__(self) -> None:
        name = f"PointObservations(frame={self.frame!r})"
        sample = _sample_array(self.sample, f"{name}.sample")
        p = _data_array(self.meas_p_point, (len(sample), 3), f"{name}.meas_p_point")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(self, "meas_p_point", p)
        if self.offset is not None:
            offset = _data_array(self.offset, (3,), f"{name}.offset")
            object.__setattr__(self, "offset", offset)

    def __repr__(self) -> str:
        offset = None if self.offset is None else self.offset.tolist()
        return (f"PointObservations(frame={self.frame!r}, marker={self.marker!r}, "
                f"measured_in={self.measured_in!r}, offset={offset}, m={len(self.sample)})")

    def _take(self, rows: NDArray[np.intp], sample: NDArray[np.int64]) -> PointObservations:
        return replace(self, sample=sample, meas_p_point=self.meas_p_point[rows])

    @property
    def _key(self) -> tuple[Any, ...]:
        offset = None if self.offset is None else tuple(self.offset.tolist())
        return ("point", self.frame, self.marker, self.measured_in, offset)


_Group = PoseObservations | TargetObservations | PointObservations


def _group_frame(group: _Group) -> str:
    return group.camera if isinstance(group, TargetObservations) else group.frame


def _group_kind(group: _Group) -> str:
    return group._key[0]


# -- the dataset -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class Measurements:
    """A calibration dataset: joint values per sample and the observations made.

    Arrays are read-only; methods return new datasets.

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
    """

    joint_names: tuple[str, ...]
    qs: NDArray[np.float64]
    poses: tuple[PoseObservations, ...] = ()
    targets: tuple[TargetObservations, ...] = ()
    points: tuple[PointObservations, ...] = ()
    source: str = "<memory>"

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
        object.__setattr__(self, "qs", _frozen(qs, np.float64))
        n = qs.shape[0]
        for attr, cls in (("poses", PoseObservations), ("targets", TargetObservations),
                          ("points", PointObservations)):
            groups = tuple(getattr(self, attr))
            for g in groups:
                if not isinstance(g, cls):
                    raise DatasetError(f"{src}: {attr}: expected {cls.__name__}, got "
                                       f"{type(g).__name__}")
                if len(g.sample) and g.sample.max() >= n:
                    raise DatasetError(
                        f"{src}: {attr}: {g!r} refers to sample {int(g.sample.max())}, "
                        f"but there are {n} samples"
                    )
            object.__setattr__(self, attr, groups)

    def __repr__(self) -> str:
        return (f"Measurements(source={self.source!r}, n_samples={self.n_samples}, "
                f"joint_names={list(self.joint_names)}, poses={list(self.poses)}, "
                f"targets={list(self.targets)}, points={list(self.points)})")

    def _groups(self) -> Iterator[_Group]:
        yield from self.poses
        yield from self.targets
        yield from self.points

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

        def select(group: _Group) -> _Group | None:
            # Each row of the group appears once per occurrence of its sample in `sel`.
            left = np.searchsorted(sorted_sel, group.sample, side="left")
            counts = np.searchsorted(sorted_sel, group.sample, side="right") - left
            if not counts.any():
                return None
            rows = np.repeat(np.arange(len(group.sample)), counts)
            starts = np.repeat(np.cumsum(counts) - counts, counts)
            new = order[np.repeat(left, counts) + np.arange(len(rows)) - starts]
            by_sample = np.lexsort((rows, new))
            return group._take(rows[by_sample], new[by_sample].astype(np.int64))

        def kept(groups: tuple[_Group, ...]) -> tuple[Any, ...]:
            return tuple(g for g in map(select, groups) if g is not None)

        return replace(self, qs=self.qs[sel], poses=kept(self.poses),
                       targets=kept(self.targets), points=kept(self.points))

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
        entries.append((first, rank, _group_frame(g), _group_kind(g)))
    out: dict[str, tuple[int, str]] = {}
    for first, _, frame, kind in sorted(entries):
        out.setdefault(frame, (first, kind))
    return out


# -- reading ---------------------------------------------------------------------------

_MISSING = object()


def _describe(value: Any) -> str:
    """A short description of a JSON value for 'got ...' in messages."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return repr(value if len(value) <= 40 else value[:37] + "...")
    if isinstance(value, list):
        return f"a list of {len(value)} items"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


class _Parser:
    """Validation helpers that raise :class:`DatasetError` naming the file and key path."""

    def __init__(self, source: str) -> None:
        self.source = source

    def error(self, where: str, what: str) -> DatasetError:
        return DatasetError(f"{self.source}: {where}: {what}" if where else
                            f"{self.source}: {what}")

    def get(self, obj: dict[str, Any], key: str, where: str, expected: str) -> Any:
        """A required key; JSON null is an error too."""
        value = obj.get(key)
        if value is None:
            state = "missing" if key not in obj else "null"
            raise self.error(_join(where, key), f"{state}; expected {expected}")
        return value

    def string(self, value: Any, where: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.error(where, f"expected a non-empty string, got {_describe(value)}")
        return value

    def choice(self, value: Any, where: str, choices: tuple[str, ...]) -> str:
        if not isinstance(value, str) or value not in choices:
            options = ", ".join(repr(c) for c in choices)
            raise self.error(where, f"expected one of {options}, got {_describe(value)}")
        return value

    def numbers(self, value: Any, n: int, where: str, what: str = "") -> list[float]:
        """A list of ``n`` finite numbers, as floats."""
        what = f" ({what})" if what else ""
        if not isinstance(value, list):
            raise self.error(where, f"expected a list of {n} numbers{what}, "
                                    f"got {_describe(value)}")
        if len(value) != n:
            raise self.error(where, f"expected {n} numbers{what}, got {len(value)}")
        out = []
        for k, x in enumerate(value):
            ok = isinstance(x, (int, float)) and not isinstance(x, bool)
            try:
                ok = ok and math.isfinite(float(x))
            except OverflowError:  # an integer too large for a float
                ok = False
            if not ok:
                raise self.error(f"{where}[{k}]", f"expected a finite number, got {_describe(x)}")
            out.append(float(x))
        return out

    def list_of(self, value: Any, where: str, what: str) -> list[Any]:
        if not isinstance(value, list) or not value:
            raise self.error(where, f"expected a non-empty list of {what}, got {_describe(value)}")
        return value

    def obj(self, value: Any, where: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(where, f"expected an object, got {_describe(value)}")
        return value


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _length_to_si(value: float, unit: str) -> float:
    return value / 1000.0 if unit == "mm" else value


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
    p = _Parser(source)
    if not isinstance(doc, dict):
        raise p.error("", f"expected a JSON object at the top level, got {_describe(doc)}")
    fmt = p.get(doc, "format", "", f"{FORMAT!r}")
    if fmt != FORMAT:
        raise p.error("format", f"expected {FORMAT!r}, got {_describe(fmt)}")
    version = p.get(doc, "version", "", "1")
    if isinstance(version, bool) or version not in SUPPORTED_VERSIONS:
        supported = ", ".join(map(str, SUPPORTED_VERSIONS))
        raise p.error("version", f"unsupported version {_describe(version)}; this reader "
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
            got = f"{len(raw_units)}" if isinstance(raw_units, list) else _describe(raw_units)
            raise p.error("joint_units", f"expected a list of {k} units (one per joint_names "
                                         f"entry), got {got}")
        joint_units = [p.choice(u, f"joint_units[{c}]", _JOINT_UNITS)
                       for c, u in enumerate(raw_units)]
    default_measured_in = None
    if doc.get("measured_in") is not None:
        default_measured_in = p.string(doc["measured_in"], "measured_in")

    samples = p.list_of(p.get(doc, "samples", "", "a list of samples"), "samples", "samples")
    q_rows: list[list[float]] = []
    # One entry per observation, flat; arrays are built once per group at the end.
    obs_group: list[int] = []
    obs_sample: list[int] = []
    obs_index: list[int] = []
    xyz_rows: list[list[float]] = []
    quat_rows: list[list[float]] = []
    oriented: list[bool] = []
    group_of_key: dict[tuple[Any, ...], int] = {}
    marker_home: dict[str, tuple[str, str]] = {}  # marker -> (frame, where first seen)
    no_quat = [0.0, 0.0, 0.0, 1.0]

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
            key, xyz, quat = _parse_observation(p, obs, at_obs, length_unit,
                                                default_measured_in)
            marker = key[2] if key[0] in ("pose", "point") else None
            if marker is not None:
                home = marker_home.setdefault(marker, (key[1], at_obs))
                if home[0] != key[1]:
                    raise p.error(f"{at_obs}.marker",
                                  f"marker {marker!r} is on frame {key[1]!r} here but on "
                                  f"frame {home[0]!r} in {home[1]}; a marker is rigidly "
                                  "attached to one frame")
            obs_group.append(group_of_key.setdefault(key, len(group_of_key)))
            obs_sample.append(i)
            obs_index.append(j)
            xyz_rows.append(xyz)
            quat_rows.append(no_quat if quat is None else quat)
            oriented.append(quat is not None)

    qs = _columns_to_si(np.array(q_rows, dtype=float).reshape(len(q_rows), k), joint_units)
    xyzs = np.array(xyz_rows, dtype=float)
    if length_unit == "mm":
        xyzs = xyzs / 1000.0
    quats = np.array(quat_rows, dtype=float)
    norms = np.linalg.norm(quats, axis=1)
    off = np.abs(norms - 1.0)
    bad = np.array(oriented, dtype=bool) & ~(off <= QUAT_NORM_TOL)
    if bad.any():
        r = int(np.argmax(bad))
        raise p.error(
            f"samples[{obs_sample[r]}].observations[{obs_index[r]}].quat_xyzw",
            f"quaternion norm is {norms[r]:.9g}; expected a unit quaternion [x, y, z, w] "
            f"(norm within {QUAT_NORM_TOL:g} of 1)",
        )
    rounded = np.array(oriented, dtype=bool) & (off > QUAT_ROUNDED_TOL)
    if rounded.any():
        warnings.warn(
            f"{source}: {int(rounded.sum())} of {sum(oriented)} quaternions had norms off "
            f"by up to {off[rounded].max():.2g} (rounded?); renormalised",
            UserWarning,
            stacklevel=2,
        )
    a_T_bs = transform_from_xyz_quat_xyzw(xyzs, quats / norms[:, None])

    group_ids = np.array(obs_group)
    rows_of_group = np.split(np.argsort(group_ids, kind="stable"),
                             np.cumsum(np.bincount(group_ids))[:-1])
    sample_ids = np.array(obs_sample, dtype=np.int64)
    poses, targets, points = [], [], []
    for key, rows in zip(group_of_key, rows_of_group, strict=True):
        kind, frame = key[0], key[1]
        if kind == "pose":
            poses.append(PoseObservations(frame, sample_ids[rows], a_T_bs[rows],
                                          marker=key[2], measured_in=key[3]))
        elif kind == "target":
            targets.append(TargetObservations(frame, sample_ids[rows], a_T_bs[rows],
                                              target=key[2]))
        else:
            points.append(PointObservations(frame, sample_ids[rows], xyzs[rows],
                                            offset=key[4],
                                            marker=key[2], measured_in=key[3]))
    out = Measurements(joint_names, qs, tuple(poses), tuple(targets), tuple(points),
                       source=source)
    logger.debug("%s: %d samples, %d observations in %d groups", source, out.n_samples,
                 len(obs_group), len(group_of_key))
    return out


def _parse_observation(
    p: _Parser, obs: dict[str, Any], at: str, length_unit: str, default_measured_in: str | None
) -> tuple[tuple[Any, ...], list[float], list[float] | None]:
    """Validate one observation; return its group key, xyz (file unit) and quat or None."""
    frame = p.string(p.get(obs, "frame", at, "the name of a URDF frame"), f"{at}.frame")
    kind = p.choice(p.get(obs, "kind", at, "'pose', 'target' or 'point'"), f"{at}.kind", _KINDS)
    xyz = p.numbers(p.get(obs, "xyz", at, "3 numbers [x, y, z]"), 3, f"{at}.xyz")

    def optional_string(key: str) -> str | None:
        value = obs.get(key)
        return None if value is None else p.string(value, f"{at}.{key}")

    def not_allowed(key: str, why: str) -> None:
        if obs.get(key) is not None:
            raise p.error(f"{at}.{key}", f"not allowed on a {kind!r} observation ({why})")

    if kind == "target":
        not_allowed("marker", "the target's pose in the world is the unknown; a camera frame "
                              "has no marker")
        not_allowed("measured_in", "the pose is measured in the camera frame")
        not_allowed("offset", "offset belongs to 'point' observations")
    else:
        not_allowed("target", "only 'target' observations name a target")

    if kind == "point":
        not_allowed("quat_xyzw", "a point has a position only; use kind 'pose' for a pose")
        offset = None
        if obs.get("offset") is not None:
            offset = tuple(_length_to_si(x, length_unit)
                           for x in p.numbers(obs["offset"], 3, f"{at}.offset"))
        marker = optional_string("marker")
        if marker is not None and offset is not None:
            raise p.error(f"{at}.offset", f"an offset and a marker ({marker!r}) exclude each "
                                          "other: a marker's offset is unknown and estimated; "
                                          "drop the marker to use a known offset")
        measured_in = optional_string("measured_in") or default_measured_in
        return ("point", frame, marker, measured_in, offset), xyz, None

    quat = p.numbers(p.get(obs, "quat_xyzw", at, "4 numbers [x, y, z, w] (scalar last)"), 4,
                     f"{at}.quat_xyzw", "[x, y, z, w], scalar last")
    if kind == "target":
        target = optional_string("target") or _DEFAULT_TARGET
        return ("target", frame, target), xyz, quat
    not_allowed("offset", "offset belongs to 'point' observations")
    marker = optional_string("marker")
    measured_in = optional_string("measured_in") or default_measured_in
    return ("pose", frame, marker, measured_in), xyz, quat


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
    frames_in = {g.measured_in for g in (*m.poses, *m.points)}
    top_measured_in = next(iter(frames_in)) if len(frames_in) == 1 else None

    def extras(**optional: Any) -> dict[str, Any]:
        return {key: value for key, value in optional.items() if value is not None}

    def measured_in(group: PoseObservations | PointObservations) -> str | None:
        return None if group.measured_in == top_measured_in else group.measured_in

    for g in m.poses:
        more = extras(marker=g.marker, measured_in=measured_in(g))
        xyzs, quats = xyz_quat_xyzw_from_transform(g.meas_T_frame)
        for s, xyz, quat in zip(g.sample.tolist(), xyzs.tolist(), quats.tolist(), strict=True):
            per_sample[s].append({"frame": g.frame, "kind": "pose", "xyz": xyz,
                                  "quat_xyzw": quat, **more})
    for g in m.targets:
        more = extras(target=None if g.target == _DEFAULT_TARGET else g.target)
        xyzs, quats = xyz_quat_xyzw_from_transform(g.camera_T_target)
        for s, xyz, quat in zip(g.sample.tolist(), xyzs.tolist(), quats.tolist(), strict=True):
            per_sample[s].append({"frame": g.camera, "kind": "target", "xyz": xyz,
                                  "quat_xyzw": quat, **more})
    for g in m.points:
        more = extras(offset=None if g.offset is None else g.offset.tolist(), marker=g.marker,
                      measured_in=measured_in(g))
        for s, xyz in zip(g.sample.tolist(), g.meas_p_point.tolist(), strict=True):
            per_sample[s].append({"frame": g.frame, "kind": "point", "xyz": xyz, **more})

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
    for g in (*m.poses, *m.points):
        if g.measured_in is not None and len(g.sample):
            first = int(g.sample.min())
            first_in[g.measured_in] = min(first_in.get(g.measured_in, first), first)
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
    return replace(m, poses=_merged(m.poses, root), points=_merged(m.points, root))


_DATA_FIELD = {PoseObservations: "meas_T_frame", TargetObservations: "camera_T_target",
               PointObservations: "meas_p_point"}


def _merge_same_key(groups: Iterable[_Group]) -> tuple[Any, ...]:
    """Merge groups with equal keys (frame, kind, marker...), rows sorted by sample."""
    by_key: dict[tuple[Any, ...], list[Any]] = {}
    for g in groups:
        by_key.setdefault(g._key, []).append(g)
    out = []
    for parts in by_key.values():
        if len(parts) == 1:
            out.append(parts[0])
            continue
        field = _DATA_FIELD[type(parts[0])]
        sample = np.concatenate([g.sample for g in parts])
        order = np.argsort(sample, kind="stable")
        data = np.concatenate([getattr(g, field) for g in parts])
        out.append(replace(parts[0], sample=sample[order], **{field: data[order]}))
    return tuple(out)


def _merged(groups: tuple[Any, ...], root: str) -> tuple[Any, ...]:
    """Groups with ``measured_in == root`` set to None, merging groups that coincide."""
    return _merge_same_key(
        replace(g, measured_in=None) if g.measured_in == root else g for g in groups)


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

    def shifted(attr: str) -> tuple[Any, ...]:
        return _merge_same_key(replace(g, sample=g.sample + off)
                               for p, off in zip(parts, offsets, strict=True)
                               for g in getattr(p, attr))

    return Measurements(
        joint_names=names,
        qs=np.concatenate([p.q_of(names) for p in parts]),
        poses=shifted("poses"),
        targets=shifted("targets"),
        points=shifted("points"),
        source=" + ".join(dict.fromkeys(p.source for p in parts)),
    )


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
