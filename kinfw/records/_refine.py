"""The joint refinement's section of a calibration report (:mod:`kinfw.records`):
:class:`RefineSection` and its rows (parameters, identifiability, down-weighted and
rejected observations), typed frozen dataclasses with ``to_dict`` / ``from_dict`` (the
``refine`` key of ``report.json``, format ``kinfw-calibration-report`` v1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from kinfw.records._doc_reader import DocReader
from kinfw.records._records import CalibratedUnknown, ErrorValue, NoiseSummary
from kinfw.records._stages import KinematicValue


@dataclass(frozen=True, slots=True)
class ParameterRow:
    """One parameter of the joint least squares: its unit (from its block), whether it
    was fixed, its change from the start and its standard deviation (None if fixed)."""

    owner: str
    field: str
    unit: str
    fixed: bool
    delta_from_start: float
    std: float | None

    def to_dict(self) -> dict[str, Any]:
        return {
            "owner": self.owner,
            "field": self.field,
            "unit": self.unit,
            "fixed": self.fixed,
            "delta_from_start": self.delta_from_start,
            "std": self.std,
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> ParameterRow:
        doc = r.obj(doc, at)
        return cls(
            r.string(doc, "owner", at),
            r.string(doc, "field", at),
            r.string(doc, "unit", at),
            r.boolean(doc, "fixed", at),
            r.number(doc, "delta_from_start", at),
            r.number(doc, "std", at, optional=True),
        )


@dataclass(frozen=True, slots=True)
class NotIdentifiable:
    """Parameters (``"owner:field"``) the data does not determine, and why."""

    parameters: tuple[str, ...]
    why: str

    def to_dict(self) -> dict[str, Any]:
        return {"parameters": list(self.parameters), "why": self.why}

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> NotIdentifiable:
        doc = r.obj(doc, at)
        return cls(r.strings(doc, "parameters", at), r.string(doc, "why", at))


@dataclass(frozen=True, slots=True)
class Correlation:
    """Two parameters whose estimates correlate beyond 0.9."""

    a: str
    b: str
    rho: float

    def to_dict(self) -> dict[str, Any]:
        return {"a": self.a, "b": self.b, "rho": self.rho}

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> Correlation:
        doc = r.obj(doc, at)
        return cls(r.string(doc, "a", at), r.string(doc, "b", at), r.number(doc, "rho", at))


@dataclass(frozen=True, slots=True)
class IdentifiabilitySummary:
    """Rank, condition number and Borm & Menq's O1 (None when undefined or infinite),
    the parameters the data does not determine and the strong correlations."""

    rank: int
    n_parameters: int
    condition: float | None
    observability_o1: float | None
    not_identifiable: tuple[NotIdentifiable, ...]
    correlations: tuple[Correlation, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "rank": self.rank,
            "n_parameters": self.n_parameters,
            "condition": self.condition,
            "observability_O1": self.observability_o1,
            "not_identifiable": [n.to_dict() for n in self.not_identifiable],
            "correlations_above_0.9": [c.to_dict() for c in self.correlations],
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> IdentifiabilitySummary:
        doc = r.obj(doc, at)
        return cls(
            r.integer(doc, "rank", at),
            r.integer(doc, "n_parameters", at),
            r.number(doc, "condition", at, optional=True),
            r.number(doc, "observability_O1", at, optional=True),
            r.rows(NotIdentifiable, doc, "not_identifiable", at),
            r.rows(Correlation, doc, "correlations_above_0.9", at),
        )


def _observation_dict(row: Any) -> dict[str, Any]:
    """The fields a down-weighted and a rejected observation share, in file order."""
    return {
        "sample": row.sample,
        "kind": row.kind,
        "frame": row.frame,
        "marker": row.marker,
        **{v.key: v.value for v in row.residuals},
        **({} if row.where is None else {"where": row.where}),
    }


def _residual(row: Any, name: str) -> float | None:
    return next((v.value for v in row.residuals if v.name == name), None)


def _observation_fields(doc: Any, r: DocReader, at: str) -> dict[str, Any]:
    """Those shared fields read back: ``*_residual_*`` keys are the residuals."""
    return {
        "sample": r.integer(doc, "sample", at),
        "kind": r.string(doc, "kind", at),
        "frame": r.string(doc, "frame", at),
        "marker": r.string(doc, "marker", at, optional=True),
        "residuals": tuple(
            ErrorValue.from_key(k, r.number(doc, k, at))
            for k in doc
            if k.count("_") >= 2 and k.split("_")[-2] == "residual"
        ),
        "where": r.string(doc, "where", at, optional=True),
    }


@dataclass(frozen=True, slots=True)
class DownweightedRow:
    """An observation the robust loss down-weighted: ``sample`` (index into the data
    file's samples, from 0), kind, frame (camera for targets), marker, the size of its
    residual in each per-observation metric of its kind (``position_residual_mm``,
    ``rotation_residual_deg``, ``pixel_residual_px``, ``height_residual_mm``, ...) and
    the weight it got (1 = full); ``where`` in the sample (an image's corner) or None."""

    sample: int
    kind: str
    frame: str
    marker: str | None
    residuals: tuple[ErrorValue, ...]
    weight: float
    where: str | None = None

    def residual(self, name: str) -> float | None:
        """The residual's size in the metric ``name`` (display unit), None if none."""
        return _residual(self, name)

    def to_dict(self) -> dict[str, Any]:
        return {**_observation_dict(self), "weight": self.weight}

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> DownweightedRow:
        doc = r.obj(doc, at)
        return cls(**_observation_fields(doc, r, at), weight=r.number(doc, "weight", at))


@dataclass(frozen=True, slots=True)
class RejectedRow:
    """An observation excluded from the fit as a gross error
    (:class:`kinfw.identification.problem.RejectedObservation`): ``sample`` (index into
    the data file's samples, from 0), kind, frame (camera for targets), marker, the size
    of its residual against the calibration in each per-observation metric of its kind
    (as :class:`DownweightedRow`), how far beyond the rejection threshold its
    whitened norm was (``excess``, > 1), and whether clean data reach that far
    (``clean_tail``: the 0.1 % of clean observations beyond the threshold, within their
    expected count; False, a gross error; in the file only when true)."""

    sample: int
    kind: str
    frame: str
    marker: str | None
    residuals: tuple[ErrorValue, ...]
    excess: float
    where: str | None = None
    clean_tail: bool = False

    def residual(self, name: str) -> float | None:
        """The residual's size in the metric ``name`` (display unit), None if none."""
        return _residual(self, name)

    def to_dict(self) -> dict[str, Any]:
        # written when true: a report before it reads and writes back byte for byte
        tail = {"clean_tail": True} if self.clean_tail else {}
        return {**_observation_dict(self), "excess": self.excess, **tail}

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> RejectedRow:
        doc = r.obj(doc, at)
        return cls(
            **_observation_fields(doc, r, at),
            excess=r.number(doc, "excess", at),
            clean_tail="clean_tail" in doc and r.boolean(doc, "clean_tail", at),
        )


@dataclass(frozen=True, slots=True)
class RefineSection:
    """The joint least squares (:class:`kinfw.identification.RefineResult`) as reported."""

    loss: str
    noise: NoiseSummary
    reduced_chi_square: float
    iterations: int
    converged: bool
    seconds: float
    model_frame: str | None
    parameters: tuple[ParameterRow, ...]
    kinematics: tuple[KinematicValue, ...]
    unknowns: tuple[CalibratedUnknown, ...]
    identifiability: IdentifiabilitySummary
    downweighted: tuple[DownweightedRow, ...]
    #: None: a report written before rejection existed (the keys are then not written)
    rejected: tuple[RejectedRow, ...] | None = ()
    rejection_note: str | None = None

    METHOD: ClassVar[str] = (
        "joint nonlinear least squares (CasADi residuals and Jacobians, "
        "Levenberg-Marquardt), residuals whitened by the noise below"
    )
    PARAMETERS_NOTE: ClassVar[str] = (
        "delta_from_start and std in the parameter's unit (rad, m or unitless); fixed: not "
        "estimated (held at the start, delta_from_start 0, std null)"
    )
    DOWNWEIGHTED_NOTE: ClassVar[str] = (
        "observations beyond the robust loss's threshold, the worst (lowest weight) first; "
        "sample is the index into the data file's samples (from 0)"
    )
    REJECTED_NOTE: ClassVar[str] = (
        "observations beyond the 99.9 % quantile of the clean residual norm under the "
        "estimated noise, excluded and the problem refitted without them (not in the fit "
        "nor the noise estimate); clean_tail: as far as clean data reach (0.1 % of clean "
        "observations are beyond it, within their expected count), else a gross error; "
        "the worst (largest excess over the threshold) first; residuals against the "
        "calibrated model"
    )

    @property
    def n_fixed(self) -> int:
        return sum(p.fixed for p in self.parameters)

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.METHOD,
            "loss": self.loss,
            "noise": self.noise.to_dict(),
            "reduced_chi_square": self.reduced_chi_square,
            "iterations": self.iterations,
            "converged": self.converged,
            "seconds": self.seconds,
            "model_frame": self.model_frame,
            "parameters_note": self.PARAMETERS_NOTE,
            "parameters": [p.to_dict() for p in self.parameters],
            "kinematics": [k.to_dict() for k in self.kinematics],
            "unknowns": [u.to_dict() for u in self.unknowns],
            "identifiability": self.identifiability.to_dict(),
            "downweighted_note": self.DOWNWEIGHTED_NOTE,
            "downweighted": [d.to_dict() for d in self.downweighted],
            **(
                {}
                if self.rejected is None
                else {
                    "rejected_note": self.REJECTED_NOTE,
                    "rejected": [d.to_dict() for d in self.rejected],
                    "rejection_note": self.rejection_note,
                }
            ),
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> RefineSection:
        doc = r.obj(doc, at)
        return cls(
            r.string(doc, "loss", at),
            NoiseSummary.from_dict(r.value(doc, "noise", at), r, r.path(at, "noise")),
            r.number(doc, "reduced_chi_square", at),
            r.integer(doc, "iterations", at),
            r.boolean(doc, "converged", at),
            r.number(doc, "seconds", at),
            r.string(doc, "model_frame", at, optional=True),
            r.rows(ParameterRow, doc, "parameters", at),
            r.rows(KinematicValue, doc, "kinematics", at),
            r.rows(CalibratedUnknown, doc, "unknowns", at),
            IdentifiabilitySummary.from_dict(
                r.value(doc, "identifiability", at), r, r.path(at, "identifiability")
            ),
            r.rows(DownweightedRow, doc, "downweighted", at),
            None  # a report written before rejection existed
            if "rejected" not in doc
            else r.rows(RejectedRow, doc, "rejected", at),
            r.string(doc, "rejection_note", at, optional=True),
        )
