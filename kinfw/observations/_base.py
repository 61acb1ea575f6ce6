"""What every observation kind provides, and the helpers the kinds share.

An observation kind is one class (:class:`ObservationKind`) that knows everything about
one ``"kind"`` of a ``kinfw-measurements`` file:

- its group dataclass (frozen, batch-first arrays, a ``sample`` index per row);
- the file edge: one observation dict -> (group key, row of SI numbers), rows -> group,
  group -> dicts (:meth:`ObservationKind.parse`, :meth:`~ObservationKind.group_from_rows`,
  :meth:`~ObservationKind.to_dicts`);
- the URDF frames it observes and which of them it pins directly (gauge);
- the unknown parameter blocks it needs (a target's pose, a marker, a point offset) with
  their closed-form start estimates (:meth:`~ObservationKind.unknowns`, the one place for
  start values);
- its residual ``measured - predicted`` as a CasADi expression
  (:meth:`~ObservationKind.residual`), in rows grouped by noise component
  (:attr:`~ObservationKind.components`: e.g. position 3 rows in m, rotation 3 rows in rad);
- how its errors read for a person (:attr:`~ObservationKind.metrics`,
  :meth:`~ObservationKind.errors`: a :class:`Metric` per noise component, named with its
  display unit, and a kind's own group summaries); verification, the reports, the
  command line and the planner loop over them;
- the same prediction in numpy, its simulation (prediction plus its noise model) and what
  the view draws of it (:meth:`~ObservationKind.predict`, :meth:`~ObservationKind.simulate`,
  :meth:`~ObservationKind.drawing`; :mod:`kinfw.observations`).

The estimation problem (:mod:`kinfw.identification.problem`), the measurement files
(:mod:`kinfw.measurements`), verification, the simulation and the view loop over the registry
(:mod:`kinfw.observations`) and never branch on a kind. Reading one observation's dict
is :mod:`kinfw.observations` (:class:`ObservationReader`, :class:`DatasetError`,
exported here too); the views of the model a kind's methods receive are
:mod:`kinfw.observations` (:class:`StartContext`, :class:`SymbolicContext`,
:func:`inverse_casadi`, exported here too).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.model import Block, BlockKey
from kinfw.observations._contexts import StartContext, SymbolicContext
from kinfw.observations._numeric import Drawing, NumericContext, gaussian_rows
from kinfw.observations._reader import ObservationReader

# -- array helpers for group dataclasses -------------------------------------------------


def frozen_array(values: ArrayLike, dtype: type) -> NDArray[Any]:
    """A read-only copy of ``values``: dataset arrays are shared, never mutated."""
    arr = np.array(values, dtype=dtype, copy=True)
    arr.flags.writeable = False
    return arr


def sample_array(values: ArrayLike, name: str) -> NDArray[np.int64]:
    """Sample indices (m,) as read-only int64, checked (integers, >= 0)."""
    arr = np.asarray(values)
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected shape (m,), got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"{name}: expected integer sample indices, got dtype {arr.dtype}")
    if arr.size and arr.min() < 0:
        raise ValueError(f"{name}: sample indices must be >= 0, got {int(arr.min())}")
    return frozen_array(arr, np.int64)


def evenly_spaced(m: int, at_most: int) -> NDArray[np.intp]:
    """At most ``at_most`` of the indices ``0 .. m-1``, evenly spread over them in order
    (first and last included): the rows a start value needs of many (a well-spread
    subsample; all ``m`` when ``m <= at_most``).

    Returns
    -------
    ndarray of intp, shape (min(m, at_most),)
        Ascending, distinct.
    """
    if m <= at_most:
        return np.arange(m)
    if at_most <= 1:
        return np.zeros(min(at_most, 1), dtype=np.intp)
    # the rounded positions of at_most evenly spaced points are distinct: spacing >= 1
    return np.round(np.linspace(0.0, m - 1.0, at_most)).astype(np.intp)


def data_array(values: ArrayLike, shape: tuple[int, ...], name: str) -> NDArray[np.float64]:
    """Finite float data of an exact shape, read-only."""
    arr = np.asarray(values, dtype=float)
    if arr.shape != shape:
        expected = "(" + ", ".join(map(str, shape)) + ("," if len(shape) == 1 else "") + ")"
        raise ValueError(f"{name}: expected shape {expected}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}: all values must be finite")
    return frozen_array(arr, np.float64)


# -- metrics, noise components, start values, pose rows ----------------------------------


@dataclass(frozen=True, slots=True)
class Metric:
    """How an error of an observation kind reads for a person: a name, a display unit and
    the factor from SI (SI inside; this is the edge: tables, reports, files).

    A metric is either a size per observation (the norm of a noise component's rows,
    summarised over a group by its mean, RMS and max; the RMS is its headline) or one
    number per group (``per_observation=False``: a kind's own summary of a group's
    errors, e.g. the tilt of a plane's contacts).

    Attributes
    ----------
    name : str
        ``"position"``, ``"rotation"``, ``"pixel"``, ``"height"``, ``"tilt"``, a kind's
        own (``"distance"``); the first word of its keys in tables and files.
    unit : str
        Display unit, e.g. ``"mm"``, ``"deg"``, ``"px"``; the last word of its keys.
    scale : float
        Display units per SI unit (1e3: m -> mm; 180 / pi: rad -> deg; 1: px).
    fmt : str
        Format spec of a value in tables (``".3f"``).
    axes : str
        Names of the rows when they are the axes of a vector (``"xyz"``, ``"uv"``): the
        per-sample error vector and the mean and std of ``|error|`` per axis are
        reported (Shih et al. 1992, Table 4); ``""`` for none.
    per_observation : bool
        A size per observation (True) or one number per group (False).

    Examples
    --------
    >>> Metric("position", "mm", 1e3).key("rms")
    'position_rms_mm'
    >>> Metric("tilt", "deg", per_observation=False).headline
    'tilt_deg'
    """

    name: str
    unit: str
    scale: float = 1.0
    fmt: str = ".3f"
    axes: str = ""
    per_observation: bool = True

    def key(self, stat: str = "") -> str:
        """``name_stat_unit`` (``"position_rms_mm"``), ``name_unit`` without ``stat``."""
        return "_".join(p for p in (self.name, stat, self.unit) if p)

    @property
    def headline(self) -> str:
        """The key of the one number a group or a fold is summed up by: the RMS over the
        observations (``"position_rms_mm"``), or the group's number (``"tilt_deg"``)."""
        return self.key("rms" if self.per_observation else "")

    def label(self, stat: str = "") -> str:
        """A table header: ``"position RMS mm"``, ``"tilt deg"``."""
        return " ".join(p for p in (self.name, stat.replace("rms", "RMS"), self.unit) if p)


#: Display of a component that names no metric, by its SI unit: (unit, scale, fmt).
_DISPLAY_OF_SI = {
    "m": ("mm", 1e3, ".3f"),
    "rad": ("deg", float(np.degrees(1.0)), ".4f"),
    "px": ("px", 1.0, ".3f"),
}


@dataclass(frozen=True, slots=True)
class NoiseComponent:
    """A set of residual rows that share one noise standard deviation.

    Attributes
    ----------
    name : str
        ``"position"``, ``"rotation"``, or a kind's own (e.g. ``"distance"``); the key of
        :class:`kinfw.identification.problem.NoiseModel`.
    rows : int
        Rows per observation.
    unit : {"m", "rad"}
        SI unit of the rows; also the fallback sigma of a noise model that does not name
        this component (its ``position`` for ``m``, ``rotation`` for ``rad``).
    sine : bool
        The rows are ``sin(angle) u`` (an orientation error): the error angle is
        ``arcsin`` of their norm.
    distribution : {"gaussian", "angle"}
        The noise model of the rows, for the robust constants and thresholds:
        ``"gaussian"``, independent N(0, sigma) rows (whitened squared norm
        ``chi2(rows)``); ``"angle"``, a rotation by an angle N(0, sqrt(3) sigma) about a
        uniformly random axis (3 rows; whitened squared norm ``3 chi2(1)``; Shih et al.
        1992, Fig. 10, as :func:`kinfw.simulation.perturb_poses` draws it).
    metric : Metric or None
        How the size of the rows (:meth:`magnitude`) reads for a person; None: named
        after the component, in mm for ``m``, deg for ``rad``, px for ``px``, else in its
        SI unit (:attr:`display`).
    """

    name: str
    rows: int
    unit: str
    sine: bool = False
    distribution: str = "gaussian"
    metric: Metric | None = None

    @property
    def display(self) -> Metric:
        """The metric of the rows' size: :attr:`metric`, or the default of the unit."""
        if self.metric is not None:
            return self.metric
        unit, scale, fmt = _DISPLAY_OF_SI.get(self.unit, (self.unit, 1.0, ".3g"))
        return Metric(self.name, unit, scale, fmt)

    def magnitude(self, rows: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per observation, the error size in SI (m, or rad as an angle): rows (m, rows)."""
        norm = np.linalg.norm(rows, axis=1)
        return np.arcsin(np.clip(norm, 0.0, 1.0)) if self.sine else norm


POSITION = NoiseComponent("position", 3, "m", metric=Metric("position", "mm", 1e3, axes="xyz"))
ROTATION = NoiseComponent(
    "rotation",
    3,
    "rad",
    sine=True,
    distribution="angle",
    metric=Metric("rotation", "deg", float(np.degrees(1.0)), ".4f"),
)


@dataclass(frozen=True, slots=True, eq=False)
class MetricErrors:
    """The errors of one observation group in one metric, SI.

    Attributes
    ----------
    metric : Metric
    values : ndarray, shape (m,) or ()
        Per observation the error's size (``metric.per_observation``), or the group's
        one number; SI (m, rad, px); NaN where it is undefined.
    vectors : ndarray, shape (m, len(metric.axes)), or None
        The signed error rows per observation when the metric has axes, SI.
    """

    metric: Metric
    values: NDArray[np.float64]
    vectors: NDArray[np.float64] | None = None

    def shown(self) -> NDArray[np.float64]:
        """:attr:`values` in the display unit."""
        return self.metric.scale * np.asarray(self.values, dtype=float)

    def summary(self) -> tuple[tuple[str, float], ...]:
        """``(key, value)`` in the display unit: mean, RMS and max over the observations
        (NaN when there is none), or the group's number."""
        v = self.shown()
        if not self.metric.per_observation:
            return ((self.metric.headline, float(v)),)
        v = v[np.isfinite(v)]
        stats = (
            (float(v.mean()), float(np.sqrt(np.mean(v**2))), float(v.max()))
            if len(v)
            else (np.nan,) * 3
        )
        return tuple(
            (self.metric.key(s), x) for s, x in zip(("mean", "rms", "max"), stats, strict=True)
        )

    def axis_stats(self) -> tuple[tuple[str, list[float]], ...]:
        """For a metric with axes, the mean and std of ``|error|`` per axis (display
        unit): ``(("abs_mean_xyz_mm", [...]), ("abs_std_xyz_mm", [...]))``; else ()."""
        if self.vectors is None or not self.metric.axes:
            return ()
        a = self.metric.scale * np.abs(self.vectors)
        suffix = f"{self.metric.axes}_{self.metric.unit}"
        return (
            (f"abs_mean_{suffix}", a.mean(axis=0).tolist()),
            (f"abs_std_{suffix}", a.std(axis=0).tolist()),
        )


def component_errors(
    components: Sequence[NoiseComponent], rows: NDArray[np.float64]
) -> tuple[MetricErrors, ...]:
    """Per noise component the size of its rows (:meth:`NoiseComponent.magnitude`) in
    its metric, from the residual rows (m, sum of rows) of a group (SI, unweighted)."""
    out, c0 = [], 0
    for c in components:
        r = rows[:, c0 : c0 + c.rows]
        metric = c.display
        out.append(MetricErrors(metric, c.magnitude(r), r if metric.axes else None))
        c0 += c.rows
    return tuple(out)


@dataclass(frozen=True, slots=True)
class UnknownRequest:
    """An unknown block a group needs, with per-sample closed-form estimates of it.

    Requests with the same key from several groups are merged: their ``estimates`` are
    concatenated and ``block`` builds the block from them (a chordal mean of poses, the
    mean of points).

    Attributes
    ----------
    key : BlockKey
    estimates : ndarray, shape (k, ...)
        Per-sample estimates of the block's value (start values).
    block : callable
        ``block(key, estimates) -> Block``.
    description : str
        Human-readable, e.g. ``"pose of target 'board' (seen by 'camera')"``.
    """

    key: BlockKey
    estimates: NDArray[np.float64]
    block: Callable[[BlockKey, NDArray[np.float64]], Block]
    description: str


def pose_residual(ca: Any, T_pred: Any, m: Any) -> Any:
    """``(p_meas - p_pred, 0.5 vee(R_pred^T R_meas - R_meas^T R_pred))``: 6 rows (m, rad).

    ``m`` is the measured pose as 12 numbers (rotation column-major, then position). The
    orientation rows are ``sin(angle) u`` in the predicted frame: smooth at zero error.
    """
    Rm = ca.reshape(m[0:9], 3, 3)
    Rp = T_pred[0:3, 0:3]
    E = Rp.T @ Rm - Rm.T @ Rp
    return ca.vertcat(m[9:12] - T_pred[0:3, 3], 0.5 * ca.vertcat(E[2, 1], E[0, 2], E[1, 0]))


def pose_rows(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """(m, 4, 4) poses as (m, 12) rows: rotation column-major, then position."""
    return np.concatenate([np.swapaxes(T[:, :3, :3], 1, 2).reshape(len(T), 9), T[:, :3, 3]], axis=1)


# -- the kind ------------------------------------------------------------------------------


class ObservationKind:
    """One kind of observation: its data, file edge, unknowns and residual.

    Subclasses set the class attributes and implement :meth:`parse`,
    :meth:`group_from_rows`, :meth:`to_dicts`, :meth:`frames`, :meth:`data` and
    :meth:`residual`; the rest has defaults. Register an instance with
    :func:`kinfw.observations.register_kind`.

    Attributes
    ----------
    name : str
        The file's ``"kind"``.
    group_type : type
        The frozen group dataclass; it has ``sample`` (m,) and the arrays of
        :attr:`row_fields`, batch first.
    row_fields : tuple of str
        Group fields with one row per observation (taken by ``subset``, merged).
    components : tuple of NoiseComponent
        Residual rows per observation, in order.
    measurements_field : str or None
        For the built-in kinds, the :class:`~kinfw.measurements.Measurements` field that
        holds their groups (``"poses"``); None for the others (held in ``others``).
    has_measured_in : bool
        Whether groups carry a ``measured_in`` frame (None: the URDF root).
    entity_field : str or None
        The group field naming what it observes besides its frame (``"plane"``,
        ``"target"``): :meth:`entity`.
    entity_min : int
        Observations of one such thing its unknown needs at least (a plane's 3
        contacts); fewer under a name close to another's is refused as a misspelling.
    """

    name: ClassVar[str]
    group_type: ClassVar[type]
    row_fields: ClassVar[tuple[str, ...]]
    components: ClassVar[tuple[NoiseComponent, ...]]
    measurements_field: ClassVar[str | None] = None
    has_measured_in: ClassVar[bool] = False
    entity_field: ClassVar[str | None] = None
    entity_min: ClassVar[int] = 1

    @property
    def rows(self) -> int:
        """Residual rows per observation."""
        return sum(c.rows for c in self.components)

    # -- file edge
    def parse(
        self, reader: ObservationReader, obs: dict[str, Any], at: str, frame: str
    ) -> tuple[tuple[tuple[str, Any], ...], list[float]]:
        """One observation dict -> (group key, row of numbers in SI).

        The key is ``((field, value), ...)``: the group's constructor arguments besides
        ``sample`` and the row fields (hashable; observations with equal keys form one
        group). ``frame`` is the already-checked ``"frame"``.
        """
        raise NotImplementedError

    #: The keys :meth:`parse_many` reads; empty: the kind's observations are read one at
    #: a time.
    bulk_keys: ClassVar[tuple[str, ...]] = ()

    #: The keys an observation of this kind may carry besides ``"kind"`` and ``"frame"``;
    #: the reader warns of any other (a misspelt optional key would be silently ignored).
    #: None (the default, for a kind that does not say): the keys :meth:`parse` reads.
    file_keys: ClassVar[tuple[str, ...] | None] = None

    def parse_many(
        self, reader: ObservationReader, observations: list[dict[str, Any]]
    ) -> NDArray[np.float64] | None:
        """The rows (m, width) :meth:`parse` returns for many observation dicts that hold
        the same values at every key but :data:`bulk_keys` (the first already parsed),
        at once; None when any fails a check (the reader then parses them one at a time,
        naming the culprit). Default None: one at a time."""
        return None

    def group_from_rows(
        self, key: tuple[tuple[str, Any], ...], sample: NDArray[np.int64], rows: NDArray[np.float64]
    ) -> Any:
        """The group of observations with one key: rows (m, width) from :meth:`parse`."""
        raise NotImplementedError

    def group_from_parsed(
        self, key: tuple[tuple[str, Any], ...], sample: NDArray[np.int64], parsed: list[Any]
    ) -> Any:
        """The group of the file observations with one key: ``parsed`` what :meth:`parse`
        returned for each (``sample`` (k,) their samples). Default: the rows stacked into
        (k, width) for :meth:`group_from_rows`; a kind whose file observation is several
        rows (an image of many points: ``pixels``) returns its own row objects from
        :meth:`parse` and builds the group here."""
        return self.group_from_rows(key, sample, np.array(parsed, dtype=float))

    def to_dicts(self, group: Any, top_measured_in: str | None) -> list[dict[str, Any]]:
        """One JSON-ready dict per row (SI), in row order; ``top_measured_in`` is the
        file's top-level ``measured_in`` (leave it out of the dicts that have it)."""
        raise NotImplementedError

    def sample_dicts(self, group: Any, top_measured_in: str | None) -> list[tuple[int, Any]]:
        """``(sample, dict)`` per file observation: what the writer lists under each
        sample. Default: :meth:`to_dicts` with each row's sample (one row, one dict)."""
        return list(zip(group.sample.tolist(), self.to_dicts(group, top_measured_in), strict=True))

    def cameras(self, group: Any) -> dict[str, Any]:
        """Camera intrinsics the group uses, by camera frame (written to the file's
        ``"cameras"`` section); none by default."""
        return {}

    def with_cameras(self, group: Any, cameras: Mapping[str, Any]) -> Any:
        """The group with the intrinsics of ``cameras`` (by frame) where it uses them."""
        return group

    def marker(self, key: tuple[tuple[str, Any], ...]) -> tuple[str, str] | None:
        """``(marker, frame)`` of a group key, for the one-frame-per-marker rule."""
        k = dict(key)
        return (k["marker"], k["frame"]) if k.get("marker") is not None else None

    def entity(self, group: Any) -> str | None:
        """The name of what the group observes besides its frame (a plane, a ball, a
        divot, a target): its field :attr:`entity_field`; None for kinds without one.
        Labels tell groups of one frame, kind and marker apart by it."""
        return None if self.entity_field is None else getattr(group, self.entity_field)

    def target_of(self, key: tuple[tuple[str, Any], ...]) -> tuple[str, str | None] | None:
        """``(target, target_frame)`` of a group key that names a target (None: fixed in
        the world), for the one-frame-per-target rule; None for kinds without targets."""
        k = dict(key)
        return (k["target"], k.get("target_frame")) if "target" in k else None

    def key(self, group: Any) -> tuple[Any, ...]:
        """Groups with equal keys observe the same thing (merged on concatenation)."""
        out = [self.name]
        for f in dataclasses.fields(group):
            if f.name == "sample" or f.name in self.row_fields:
                continue
            value = getattr(group, f.name)
            out.append(tuple(value.tolist()) if isinstance(value, np.ndarray) else value)
        return tuple(out)

    def take(self, group: Any, rows: NDArray[np.intp], sample: NDArray[np.int64]) -> Any:
        """The group restricted to some rows, with new sample indices."""
        return dataclasses.replace(
            group, sample=sample, **{f: getattr(group, f)[rows] for f in self.row_fields}
        )

    def concatenate(self, parts: Sequence[Any]) -> Any:
        """Groups of one key merged, rows sorted by sample."""
        sample = np.concatenate([g.sample for g in parts])
        order = np.argsort(sample, kind="stable")
        return dataclasses.replace(
            parts[0],
            sample=sample[order],
            **{f: np.concatenate([getattr(g, f) for g in parts])[order] for f in self.row_fields},
        )

    # -- structure
    def frames(self, group: Any) -> tuple[str, ...]:
        """URDF frames whose poses the observations depend on."""
        raise NotImplementedError

    def direct_frames(self, group: Any) -> tuple[str, ...]:
        """Frames whose own pose the observations pin (no unknown offset in between);
        an end frame observed only indirectly keeps its nominal tool transform."""
        return ()

    def measured_in(self, group: Any) -> str | None:
        """The measurement frame of a group (None: the URDF root)."""
        return getattr(group, "measured_in", None) if self.has_measured_in else None

    def relative_to(self, group: Any) -> str | None:
        """The frame the group's observations are relative to: its measurement frame
        (default, :meth:`measured_in`), or a frame of the robot when every observation
        is a relative pose between two of its frames (a camera on the robot seeing a
        board on the robot); None or an external frame: absolute."""
        return self.measured_in(group)

    def root_pose_estimates(self, group: Any, start: StartContext) -> NDArray[np.float64] | None:
        """Per-sample estimates (k, 4, 4) of ``meas_T_w`` (model frame in the group's
        measurement frame), when the group pins it alone; else None."""
        return None

    def marker_tracks(self, group: Any, start: StartContext) -> tuple[Any, ...] | None:
        """A track that places an external frame seen only through markers or points of
        unknown offset (:func:`kinfw.identification.problem.frame_from_markers`): the
        frame's start poses ``w_T_frame`` (k, 4, 4), the measured positions (k, 3), the
        known offset (3,) or None, the measured rotations (k, 3, 3) or None, and the
        unknown's block key; None when the group has no such track."""
        return None

    # -- estimation
    def unknowns(self, group: Any, start: StartContext) -> tuple[UnknownRequest, ...]:
        """The unknown blocks the group needs, with closed-form start estimates."""
        return ()

    def trained_unknowns(self, group: Any) -> tuple[BlockKey, ...]:
        """The unknowns whose calibrated value other data of the same setup are scored
        with (a fixed plane and the probe touching it), rather than fitted to those data
        again (a target or a measurement frame that may have moved: the default)."""
        return ()

    # -- errors as a person reads them
    @property
    def metrics(self) -> tuple[Metric, ...]:
        """What :meth:`errors` returns, in order: by default one metric per noise
        component (:attr:`NoiseComponent.display`)."""
        return tuple(c.display for c in self.components)

    def errors(
        self, group: Any, rows: NDArray[np.float64], model: NumericContext
    ) -> tuple[MetricErrors, ...]:
        """The group's errors in each of :attr:`metrics`, from its residual rows.

        Parameters
        ----------
        group : group dataclass
        rows : ndarray, shape (m, rows)
            ``measured - predicted`` per observation (:meth:`residual`'s rows, SI, the
            :meth:`row_weights` divided out).
        model : NumericContext
            The model the rows were predicted by (the frames' poses at the group's
            samples, the unknowns' values), for a metric that needs geometry; it may
            lack a value (:class:`~kinfw.observations.MissingValue`).

        Returns
        -------
        tuple of MetricErrors
            Default: each component's size (:func:`component_errors`).
        """
        return component_errors(self.components, rows)

    def row_weights(self, group: Any) -> NDArray[np.float64]:
        """The relative weight (m,) that :meth:`residual` multiplies each observation's
        rows by (default 1); errors reported in the measurement's units divide it out."""
        return np.ones(len(group.sample))

    def data(self, group: Any) -> NDArray[np.float64]:
        """The measured values the residual compares against, (m, width) per row."""
        raise NotImplementedError

    def residual(self, group: Any, model: SymbolicContext, m: Any) -> Any:
        """``measured - predicted`` for one observation as an SX column of
        :attr:`rows` entries (unwhitened, SI), ``m`` the SX of one :meth:`data` row.

        The graph is cached by the problem's structure, which includes :meth:`key` of
        each group: a residual may embed numbers of the group's key (a known offset),
        never of its rows (those enter through ``m``) nor start values (through
        ``model``)."""
        raise NotImplementedError

    # -- numpy prediction, simulation and drawing (kinfw.observations) -----------
    def predict(self, group: Any, model: NumericContext) -> NDArray[np.float64]:
        """What the observations would measure, (m, width) in the layout of :meth:`data`.

        The numpy twin of :meth:`residual`'s prediction, batched over ``group.sample``:
        the residual of a predicted row is zero.
        """
        raise NotImplementedError(f"kind {self.name!r} has no numpy prediction")

    def with_data(self, group: Any, rows: NDArray[np.float64]) -> Any:
        """The group with other measured values, rows (m, width) in the layout of
        :meth:`data`. Default: the one row field, reshaped."""
        if len(self.row_fields) != 1:
            raise NotImplementedError(f"kind {self.name!r}: with_data needs one row field")
        field = self.row_fields[0]
        rows = np.reshape(rows, np.shape(getattr(group, field)))
        return dataclasses.replace(group, **{field: rows})

    def simulate(
        self,
        group: Any,
        model: NumericContext,
        rng: np.random.Generator,
        sigmas: Mapping[str, float],
    ) -> Any:
        """Simulated observations: the group's rows replaced by :meth:`predict` plus the
        noise model, ``sigmas`` (SI) by noise component name.

        Default: independent N(0, sigma) rows per component, for a kind whose data rows
        are its residual rows (``measured - predicted``: a point, a distance); a kind
        with another noise model (a pose's rotation) overrides it.
        """
        predicted = self.predict(group, model)
        if predicted.shape[1] != self.rows or any(
            c.distribution != "gaussian" for c in self.components
        ):
            raise NotImplementedError(
                f"kind {self.name!r}: its noise is not Gaussian rows; it must define simulate"
            )
        return self.with_data(
            group,
            gaussian_rows(
                predicted, rng, [(float(sigmas[c.name]), c.rows) for c in self.components]
            ),
        )

    def drawing(self, group: Any, model: NumericContext) -> Drawing:
        """What the view draws of the observations (measured and predicted positions, in
        the model frame); raises :class:`~kinfw.observations.MissingValue` when
        the measured positions need a value the view does not have."""
        raise NotImplementedError(f"kind {self.name!r} has no drawing")

    def camera_frames(self, group: Any) -> tuple[str, ...]:
        """URDF frames that carry the sensor (a camera): the view draws their triads."""
        return ()
