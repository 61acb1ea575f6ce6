"""The records the calibration sidecar (:mod:`kinfw.reports`) and the
calibration report (:mod:`kinfw.reports`) share: :class:`DataProvenance`,
:class:`ModelSummary`, :class:`NoiseSummary`, :class:`CalibratedUnknown` and
:class:`BeforeAfter`, each with ``to_dict`` / ``from_dict`` (SI inside; a field name says
``mm`` or ``deg`` where a value in the file is not SI)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.reports._doc_reader import DocReader

__all__ = [
    "BeforeAfter",
    "CalibratedUnknown",
    "DataProvenance",
    "ModelSummary",
    "NoiseSummary",
    "read_only_array",
]


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
    prior_m, prior_rad : float or None
        Sigmas of the Gaussian prior on the deviations from the nominal (m; rad), None
        without a prior.
    reason : str
        ``"given"`` (by the caller, ``--params`` / ``--prior-*``) or the model choice's
        one-line reason (:class:`kinfw.verification.evaluation.ModelChoice`).
    """

    parameters: tuple[str, ...]
    prior_m: float | None
    prior_rad: float | None
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameters": list(self.parameters),
            "prior_mm": None if self.prior_m is None else 1e3 * self.prior_m,
            "prior_deg": None if self.prior_rad is None else math.degrees(self.prior_rad),
            "reason": self.reason,
        }

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> ModelSummary:
        doc = reader.obj(doc, at)
        mm = reader.number(doc, "prior_mm", at, optional=True)
        deg = reader.number(doc, "prior_deg", at, optional=True)
        if (mm is None) != (deg is None):
            raise reader.fail(reader.path(at, "prior_mm"), "prior_mm and prior_deg both or neither")
        return cls(
            reader.strings(doc, "parameters", at),
            None if mm is None else 1e-3 * mm,
            None if deg is None else math.radians(deg),
            reader.string(doc, "reason", at),
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


@dataclass(frozen=True, slots=True)
class BeforeAfter:
    """One observation group's RMS errors before and after calibration (NaN rotation for
    groups without orientation)."""

    group: str
    n: int
    before_position_rms_mm: float
    after_position_rms_mm: float
    before_rotation_rms_deg: float
    after_rotation_rms_deg: float

    _KEYS: ClassVar[tuple[str, ...]] = (
        "before_position_rms_mm",
        "after_position_rms_mm",
        "before_rotation_rms_deg",
        "after_rotation_rms_deg",
    )

    def to_dict(self) -> dict[str, Any]:
        return {"group": self.group, "n": self.n, **{k: getattr(self, k) for k in self._KEYS}}

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> BeforeAfter:
        doc = reader.obj(doc, at)
        return cls(
            reader.string(doc, "group", at),
            reader.integer(doc, "n", at),
            *(reader.number(doc, k, at) for k in cls._KEYS),
        )

    @classmethod
    def rows_from(cls, docs: Any, reader: DocReader, at: str) -> tuple[BeforeAfter, ...]:
        if not isinstance(docs, list):
            raise reader.fail(at, "a list", docs)
        return tuple(cls.from_dict(d, reader, f"{at}[{k}]") for k, d in enumerate(docs))
