"""The records the calibration sidecar (:mod:`kinfw.records`) and the
calibration report (:mod:`kinfw.records`) share: :class:`DataProvenance`,
:class:`ModelSummary`, :class:`GuardSummary`, :class:`NoiseSummary`,
:class:`CalibratedUnknown`, :class:`ErrorValue` and :class:`BeforeAfter`, each with
``to_dict`` / ``from_dict`` (SI inside; a field name says ``mm`` or ``deg`` where a value
in the file is not SI)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.model import PriorScale, PriorScales
from kinfw.records._doc_reader import DocReader


def read_only_array(
    value: ArrayLike, name: str, shape: tuple[int, ...] | None = None
) -> NDArray[np.float64]:
    """A read-only float copy of ``value`` for a frozen record's field.

    Parameters
    ----------
    value : array_like
    name : str
        The field, named in the error.
    shape : tuple of int, optional
        The shape required.

    Returns
    -------
    ndarray
        Not writeable.

    Raises
    ------
    ValueError
        If ``shape`` is given and ``value`` has another shape.
    """
    a = np.array(value, dtype=float)
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    a.flags.writeable = False
    return a


@dataclass(frozen=True, slots=True)
class DataProvenance:
    """The calibration data: where it came from, its size and the file's SHA-256."""

    source: str
    n_samples: int
    sha256: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "n_samples": self.n_samples, "sha256": self.sha256}

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> DataProvenance:
        doc = reader.obj(doc, at)
        return cls(
            reader.string(doc, "source", at),
            reader.integer(doc, "n_samples", at),
            reader.string(doc, "sha256", at, optional=True),
        )


@dataclass(frozen=True, slots=True)
class ModelSummary:
    """The model the refinement fitted: its parameter set and prior, and why.

    Attributes
    ----------
    parameters : tuple of str
        ``("full",)``, ``("offsets",)``, ``("frames",)``, ``("none",)`` or joint names.
    prior : PriorScales or None
        The Gaussian prior on the deviations from the nominal, one sigma per parameter
        group (:attr:`PriorScales.how`: given, or chosen from the data); None without
        a prior.
    reason : str
        ``"given"`` (by the caller, ``--params`` / ``--prior-*``) or the model choice's
        one-line reason (:class:`kinfw.verification.evaluation.ModelChoice`).
    blocks : tuple of str
        The robot blocks fitted besides the URDF, by name (``("compliance",)``; their
        values are the sidecar's ``robot_blocks``); empty for the URDF alone.
    """

    parameters: tuple[str, ...]
    prior: PriorScales | None
    reason: str
    blocks: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        """E.g. ``"full"``, ``"pan,tilt"``, ``"full, prior 3 mm / 0.3 deg"``, ``"full,
        prior offsets 0.5 deg, axes 0.05 deg"`` or ``"full + compliance"``."""
        blocks = "".join(f" + {b}" for b in self.blocks)
        if self.prior is None:
            return ",".join(self.parameters) + blocks
        return f"{','.join(self.parameters)}, {self.prior.label}{blocks}"

    def to_dict(self) -> dict[str, Any]:
        """The sidecar's ``model``: the prior as its groups (SI units) and how it was
        set."""
        prior = None
        if self.prior is not None:
            prior = {"how": self.prior.how, "scales": self.prior.to_list()}
        return {
            "parameters": list(self.parameters),
            "prior": prior,
            "reason": self.reason,
        } | ({"blocks": list(self.blocks)} if self.blocks else {})

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> ModelSummary:
        """Inverse of :meth:`to_dict`; an older sidecar's ``prior_mm`` / ``prior_deg``
        (one length and one angle sigma) read as :meth:`PriorScales.uniform`."""
        doc = reader.obj(doc, at)
        return cls(
            reader.strings(doc, "parameters", at),
            _prior_of(doc, reader, at),
            reader.string(doc, "reason", at),
            reader.strings(doc, "blocks", at) if doc.get("blocks") is not None else (),
        )


def _prior_of(doc: dict, reader: DocReader, at: str) -> PriorScales | None:
    """The prior of a sidecar's ``model`` (:meth:`ModelSummary.from_dict`)."""
    if doc.get("prior") is not None:
        prior = reader.obj(doc["prior"], reader.path(at, "prior"))
        where = reader.path(at, "prior")
        scales = []
        for i, e in enumerate(reader.items(prior, "scales", where)):
            e_at = reader.path(reader.path(where, "scales"), i)
            e = reader.obj(e, e_at)
            try:
                scales.append(
                    PriorScale(
                        reader.string(e, "group", e_at),
                        reader.string(e, "unit", e_at),
                        reader.number(e, "sigma", e_at),
                    )
                )
            except ValueError:
                raise reader.fail(reader.path(e_at, "sigma"), "a positive sigma") from None
        return PriorScales(tuple(scales), reader.string(prior, "how", where))
    mm = reader.number(doc, "prior_mm", at, optional=True)
    deg = reader.number(doc, "prior_deg", at, optional=True)
    if (mm is None) != (deg is None):
        raise reader.fail(reader.path(at, "prior_mm"), "prior_mm and prior_deg both or neither")
    return None if mm is None else PriorScales.uniform(1e-3 * mm, math.radians(deg))


@dataclass(frozen=True, slots=True)
class RobotBlockRecord:
    """One calibrated robot block of the model spec (``--model``): what the URDF cannot
    hold, recorded so that verify, reach, view and export re-apply it.

    Attributes
    ----------
    spec : str
        The spec text that rebuilds the block (``"compliance:j1,j2"``,
        ``"gear-scale:tilt"``, ``"coupling:j3=-1*j2"``: :func:`kinfw.model.block_from_spec`).
    names : tuple of str
        Per entry ``owner:field`` (``"j2:compliance"``).
    units : tuple of str
        Per entry (``"rad/Nm"``, ``"unitless"``...).
    values, std : ndarray, shape (size,)
        The estimate and its standard deviation (0 for an entry held fixed), in the units.
    """

    spec: str
    names: tuple[str, ...]
    units: tuple[str, ...]
    values: NDArray[np.float64]
    std: NDArray[np.float64]

    def __post_init__(self) -> None:
        n = len(self.names)
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "units", tuple(self.units))
        object.__setattr__(self, "values", read_only_array(self.values, "values", (n,)))
        object.__setattr__(self, "std", read_only_array(self.std, "std", (n,)))

    def to_dict(self) -> dict[str, Any]:
        return {
            "block": self.spec,
            "names": list(self.names),
            "units": list(self.units),
            "values": self.values.tolist(),
            "std": self.std.tolist(),
        }

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> RobotBlockRecord:
        doc = reader.obj(doc, at)
        names = reader.strings(doc, "names", at)
        shape = (len(names),)
        return cls(
            reader.string(doc, "block", at),
            names,
            reader.strings(doc, "units", at),
            reader.array(reader.value(doc, "values", at), reader.path(at, "values"), shape),
            reader.array(reader.value(doc, "std", at), reader.path(at, "std"), shape),
        )


@dataclass(frozen=True, slots=True)
class GuardSummary:
    """The plausibility guard's outcome on a written calibration
    (:func:`kinfw.identification.checks.plausibility`).

    Attributes
    ----------
    bound_m, bound_rad : float
        The bound on a joint origin's, a mount's or the root's move (m) and turn (rad).
    why : str
        How the bound was set (the prior, the floor, the robot's size, or given).
    prior_bounds : str
        What the chosen prior bounds (the CPC parameters' deviations, not the URDF's
        origins), or that there was none.
    largest : str or None
        The change of the largest ratio, in words; None when nothing changed.
    largest_ratio : float
        Its ratio to the bound (beyond it above 1).
    beyond : tuple of str
        The changes beyond the bound, in words, largest first.
    allowed : bool
        They were written knowingly (``--allow-large-changes``).
    """

    bound_m: float
    bound_rad: float
    why: str
    prior_bounds: str
    largest: str | None
    largest_ratio: float
    beyond: tuple[str, ...] = ()
    allowed: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {
            "bound_mm": 1e3 * self.bound_m,
            "bound_deg": math.degrees(self.bound_rad),
            "why": self.why,
            "prior_bounds": self.prior_bounds,
            "largest": self.largest,
            "largest_ratio": self.largest_ratio,
            "beyond": list(self.beyond),
            "large_changes_allowed": self.allowed,
        }

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> GuardSummary:
        doc = reader.obj(doc, at)
        return cls(
            1e-3 * reader.number(doc, "bound_mm", at),
            math.radians(reader.number(doc, "bound_deg", at)),
            reader.string(doc, "why", at),
            reader.string(doc, "prior_bounds", at),
            reader.string(doc, "largest", at, optional=True),
            reader.number(doc, "largest_ratio", at),
            reader.strings(doc, "beyond", at),
            reader.boolean(doc, "large_changes_allowed", at),
        )


@dataclass(frozen=True, slots=True)
class NoiseSummary:
    """The noise that whitened the residuals: one sigma per noise component.

    Attributes
    ----------
    sigmas : tuple of (str, float)
        ``(component, sigma)`` in SI (m, or rad per small-angle orientation component),
        as :class:`kinfw.identification.problem.NoiseModel`.
    estimated : bool
        True when estimated from the residuals rather than given.
    """

    sigmas: tuple[tuple[str, float], ...]
    estimated: bool

    NOTE: ClassVar[str] = (
        "weights: 1/sigma^2 per position component (mm) and per small-angle orientation "
        "component (an angle sigma of s about a random axis is s/sqrt(3) per component)"
    )

    def of(self, name: str) -> float | None:
        """The sigma of a component (SI), None when the calibration has no such rows."""
        return dict(self.sigmas).get(name)

    @property
    def position_sigma_mm(self) -> float | None:
        sigma = self.of("position")
        return None if sigma is None else 1e3 * sigma

    @property
    def rotation_sigma_deg_per_component(self) -> float | None:
        sigma = self.of("rotation")
        return None if sigma is None else float(np.degrees(sigma))

    def to_dict(self) -> dict[str, Any]:
        return {
            "position_sigma_mm": self.position_sigma_mm,
            "rotation_sigma_deg_per_component": self.rotation_sigma_deg_per_component,
            "estimated": self.estimated,
            "sigma_per_component": dict(self.sigmas),
            "note": self.NOTE,
        }

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> NoiseSummary:
        doc = reader.obj(doc, at)
        estimated = reader.boolean(doc, "estimated", at)
        per = reader.value(doc, "sigma_per_component", at, optional=True)
        if per is not None:
            per_at = reader.path(at, "sigma_per_component")
            per = reader.obj(per, per_at)
            return cls(tuple((k, reader.number(per, k, per_at)) for k in per), estimated)
        # older files: the two built-in components only, in mm and deg
        mm = reader.number(doc, "position_sigma_mm", at)
        deg = reader.number(doc, "rotation_sigma_deg_per_component", at)
        return cls((("position", 1e-3 * mm), ("rotation", math.radians(deg))), estimated)


@dataclass(frozen=True, slots=True, eq=False)
class CalibratedUnknown:
    """A rigid frame or point the calibration estimated besides the kinematics.

    Attributes
    ----------
    kind : str
        Parameter block kind: ``"target"`` (value ``root_T_target``), ``"frame"``
        (``meas_T_root`` of an external measurement frame), ``"marker"``
        (``frame_T_marker``), ``"offset"`` (``frame_p_point``, name ``frame:marker``),
        or a new observation kind's own.
    name : str
    value : ndarray, shape (4, 4) or (3,)
        The estimate, metres.
    """

    kind: str
    name: str
    value: NDArray[np.float64]

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "value", read_only_array(self.value, f"unknown {self.kind}:{self.name}")
        )

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "name": self.name, "value": self.value.tolist()}

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> CalibratedUnknown:
        doc = reader.obj(doc, at)
        return cls(
            reader.string(doc, "kind", at),
            reader.string(doc, "name", at),
            reader.array(reader.value(doc, "value", at), reader.path(at, "value")),
        )


#: The statistics an error key may name between the metric and the unit.
STATS = ("mean", "rms", "max", "residual")


@dataclass(frozen=True, slots=True)
class ErrorValue:
    """One number of an error in a metric's display unit, keyed ``name_stat_unit``
    (``position_rms_mm``; ``tilt_deg`` without a statistic): what the files write for
    every metric of every observation kind (:class:`kinfw.observations.Metric`).

    Attributes
    ----------
    name : str
        The metric (``"position"``, ``"rotation"``, ``"pixel"``, ``"height"``,
        ``"tilt"``, a registered kind's own).
    unit : str
        Its display unit (``"mm"``, ``"deg"``, ``"px"``).
    stat : str
        One of :data:`STATS`, or ``""`` for a group's one number.
    value : float
        NaN when undefined (null in the file).
    """

    name: str
    unit: str
    stat: str
    value: float

    @property
    def key(self) -> str:
        return "_".join(p for p in (self.name, self.stat, self.unit) if p)

    @property
    def is_headline(self) -> bool:
        """The number a group is summed up by: its RMS, or a group metric's value."""
        return self.stat in ("rms", "")

    def label(self) -> str:
        """A table header: ``"position RMS mm"``, ``"tilt deg"``."""
        stat = {"rms": "RMS", "residual": ""}.get(self.stat, self.stat)
        return " ".join(p for p in (self.name, stat, self.unit) if p)

    def with_value(self, value: float) -> ErrorValue:
        return ErrorValue(self.name, self.unit, self.stat, value)

    @classmethod
    def from_key(cls, key: str, value: float) -> ErrorValue:
        """Split ``name_stat_unit`` (or ``name_unit``); the name may hold ``_``."""
        parts = key.split("_")
        if len(parts) < 2:
            raise ValueError(f"{key!r}: expected name_unit or name_stat_unit")
        if len(parts) > 2 and parts[-2] in STATS:
            return cls("_".join(parts[:-2]), parts[-1], parts[-2], value)
        return cls("_".join(parts[:-1]), parts[-1], "", value)


def headline(values: Sequence[ErrorValue], name: str | None = None) -> ErrorValue | None:
    """The headline (:attr:`ErrorValue.is_headline`) of the metric ``name`` among
    ``values``, or of the first metric; None if there is none."""
    return next((v for v in values if v.is_headline and (name is None or v.name == name)), None)


@dataclass(frozen=True, slots=True)
class BeforeAfter:
    """One observation group's errors before and after calibration: per metric of its
    kind its headline (RMS over the group's observations, or a group metric's value) in
    the display unit (``before_position_rms_mm``, ``after_position_rms_mm``, ...)."""

    group: str
    n: int
    before: tuple[ErrorValue, ...]
    after: tuple[ErrorValue, ...]

    def of(self, name: str) -> tuple[float, float] | None:
        """``(before, after)`` in the metric ``name``, None if the group has none."""
        b, a = headline(self.before, name), headline(self.after, name)
        return None if b is None or a is None else (b.value, a.value)

    def to_dict(self) -> dict[str, Any]:
        doc: dict[str, Any] = {"group": self.group, "n": self.n}
        for b, a in zip(self.before, self.after, strict=True):
            doc[f"before_{b.key}"] = b.value
            doc[f"after_{a.key}"] = a.value
        return doc

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> BeforeAfter:
        doc = reader.obj(doc, at)
        before, after = [], []
        for key in doc:
            for prefix, out in (("before_", before), ("after_", after)):
                if key.startswith(prefix):
                    value = reader.number(doc, key, at)
                    out.append(ErrorValue.from_key(key[len(prefix) :], value))
        if [v.key for v in before] != [v.key for v in after]:
            raise reader.fail(at, "a before_ and an after_ key for each error")
        return cls(
            reader.string(doc, "group", at),
            reader.integer(doc, "n", at),
            tuple(before),
            tuple(after),
        )

    @classmethod
    def rows_from(cls, docs: Any, reader: DocReader, at: str) -> tuple[BeforeAfter, ...]:
        if not isinstance(docs, list):
            raise reader.fail(at, "a list", docs)
        return tuple(cls.from_dict(d, reader, f"{at}[{k}]") for k, d in enumerate(docs))
