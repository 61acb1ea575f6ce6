"""The calibration report (``report.json``, format ``kinfw-calibration-report`` v1), typed.

:func:`kinfw.verification.reporting.calibration_report` builds a :class:`CalibrationReport` from
the pipeline's result; ``kinfw calibrate`` prints from its fields and writes
:meth:`CalibrationReport.to_dict` (``--report``, ``--json``); :meth:`~CalibrationReport.
from_dict` reads one back. SI inside the library, mm and deg where the field name says
so (the report is for people). Parameter units come from the parameter blocks
(:attr:`kinfw.identification.RefineResult.parameter_units`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

from kinfw.files import json_text, write_text_atomic
from kinfw.records._doc_reader import CalibrationFileError, DocReader
from kinfw.records._records import BeforeAfter, DataProvenance, ErrorValue, GuardSummary, headline
from kinfw.records._refine import (
    RefineSection,
)
from kinfw.records._reprojection import ReprojectionSection
from kinfw.records._stages import (
    ClosedFormSection,
    ExportSection,
    HandEyeSection,
)


def _rows(cls, doc: dict, key: str, r: DocReader, at: str) -> tuple:
    path = r.path(at, key)
    return tuple(cls.from_dict(d, r, f"{path}[{k}]") for k, d in enumerate(r.items(doc, key, at)))


# -- errors -----------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class GroupErrorSummary:
    """Errors of a model on one observation group (see
    :meth:`kinfw.verification.evaluation.GroupErrors.summary`), in the metrics of its kind:
    per metric its mean, RMS and max over the observations (or a group metric's value)
    in the display unit (``position_mean_mm``, ``rotation_rms_deg``, ``pixel_max_px``,
    ``height_rms_mm``, ``tilt_deg``); for a metric with axes the mean and std of
    ``|error|`` per axis (``abs_mean_xyz_mm``, Shih et al. Table 4; None in the file when
    undefined). ``entity`` names what the group observes (its plane, ball, divot or
    target) when another group of the same frame, kind and marker observes something
    else (one probe on a table and a wall), else None."""

    frame: str
    kind: str
    marker: str | None
    n: int
    values: tuple[ErrorValue, ...]
    axes: tuple[tuple[str, tuple[float, ...] | None], ...] = ()
    entity: str | None = None

    @property
    def group(self) -> str:
        """The report's label: ``"frame (kind)"``, ``"frame [marker] (kind)"``,
        ``"frame [marker] (kind entity)"`` (one per group)."""
        marker = f" [{self.marker}]" if self.marker else ""
        entity = f" {self.entity}" if self.entity else ""
        return f"{self.frame}{marker} ({self.kind}{entity})"

    @property
    def headlines(self) -> tuple[ErrorValue, ...]:
        """Per metric its headline: the RMS, or a group metric's value."""
        return tuple(v for v in self.values if v.is_headline)

    def rms(self, name: str) -> float | None:
        """The headline in the metric ``name``, None if the group has none."""
        v = headline(self.values, name)
        return None if v is None else v.value

    def unavailable(self) -> GroupErrorSummary:
        """The same group with every number NaN (errors not available)."""
        return replace(
            self,
            values=tuple(v.with_value(math.nan) for v in self.values),
            axes=tuple((k, None) for k, _ in self.axes),
        )

    @classmethod
    def of(
        cls,
        frame: str,
        kind: str,
        marker: str | None,
        summary: Mapping[str, Any],
        entity: str | None = None,
    ) -> GroupErrorSummary:
        """From ``n`` and the keys of a summary (``name_stat_unit`` numbers, per-axis
        lists or None)."""
        values, axes = [], []
        for key, v in summary.items():
            if key == "n":
                continue
            if v is None or isinstance(v, list | tuple):
                axes.append((key, None if v is None else tuple(float(x) for x in v)))
            else:
                values.append(ErrorValue.from_key(key, float(v)))
        return cls(frame, kind, marker, int(summary["n"]), tuple(values), tuple(axes), entity)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready; a per-axis array that does not apply (NaN) is null."""
        return {
            "frame": self.frame,
            "kind": self.kind,
            "marker": self.marker,
            **({} if self.entity is None else {"entity": self.entity}),
            "n": self.n,
            **{v.key: v.value for v in self.values},
            **{
                k: None if a is None or any(math.isnan(x) for x in a) else list(a)
                for k, a in self.axes
            },
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> GroupErrorSummary:
        doc = r.obj(doc, at)
        summary: dict[str, Any] = {"n": r.integer(doc, "n", at)}
        for key in doc:
            if key in ("frame", "kind", "marker", "entity", "n"):
                continue
            if key.startswith("abs_"):  # per axis: a list, or null
                value = r.value(doc, key, at)
                summary[key] = None if value is None else r.array(value, r.path(at, key)).tolist()
            else:
                summary[key] = r.number(doc, key, at)
        return cls.of(
            r.string(doc, "frame", at),
            r.string(doc, "kind", at),
            r.string(doc, "marker", at, optional=True),
            summary,
            r.string(doc, "entity", at, optional=True),
        )


def before_after(
    before: tuple[GroupErrorSummary, ...], after: tuple[GroupErrorSummary, ...]
) -> tuple[BeforeAfter, ...]:
    """Per group: each metric's headline (RMS, or a group metric's value) before and
    after (matched by group label)."""
    after_of = {g.group: g for g in after}
    return tuple(
        BeforeAfter(g.group, g.n, g.headlines, after_of[g.group].headlines) for g in before
    )


@dataclass(frozen=True, slots=True)
class StageErrors:
    """Per observation group after one stage (``"nominal"``, ``"closed form"``,
    ``"hand-eye"``, ``"refine"``) the headline of its kind's first metric: a pose's
    position RMS (mm), an image point's pixel RMS (px), a plane contact's height RMS (mm).

    Attributes
    ----------
    stage : str
    rms : tuple of (str, ErrorValue)
        ``(group label, headline)``.
    """

    stage: str
    rms: tuple[tuple[str, ErrorValue], ...]

    @classmethod
    def of(cls, stage: str, errors: tuple[GroupErrorSummary, ...]) -> StageErrors:
        return cls(stage, tuple((g.group, g.headlines[0]) for g in errors if g.headlines))


def _stages_to_dict(
    stages: tuple[StageErrors, ...], suffix: str
) -> dict[str, dict[str, dict[str, float]]]:
    """Per headline key (``position_rms_mm``) the key ``key + suffix`` holding per stage
    the groups with that headline: ``{"position_rms_mm_by_stage": {stage: {group:
    value}}}``."""
    keys = dict.fromkeys(v.key for s in stages for _, v in s.rms)
    return {
        key + suffix: {s.stage: {g: v.value for g, v in s.rms if v.key == key} for s in stages}
        for key in keys
    }


def _stages_from(doc: dict, suffix: str, r: DocReader) -> tuple[StageErrors, ...] | None:
    """Read :func:`_stages_to_dict`'s keys ending in ``suffix`` (none: None)."""
    rows: dict[str, list[tuple[str, ErrorValue]]] = {}
    for key in doc:
        if not key.endswith(suffix) or (suffix == _BY_STAGE and key.endswith(_TRUTH)):
            continue
        headline_key = key[: -len(suffix)]
        for stage, groups in r.obj(doc[key], key).items():
            at = f"{key}.{stage}"
            groups = r.obj(groups, at)
            rows.setdefault(stage, []).extend(
                (g, ErrorValue.from_key(headline_key, r.number(groups, g, at))) for g in groups
            )
    return tuple(StageErrors(s, tuple(v)) for s, v in rows.items()) if rows else None


_BY_STAGE = "_by_stage"
_TRUTH = "_vs_truth_held_out_by_stage"
_KEPT = "_by_stage_without_rejected"


# -- the report -------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class CalibrationReport:
    """Everything a user needs to trust (or not) a calibration.

    Attributes
    ----------
    created, method, nominal_urdf : str
        ISO 8601 date (UTC), ``"refine"`` or ``"closed-form"``, the nominal URDF's source.
    data : DataProvenance
    notes : tuple of str
        Stages skipped and why.
    errors_in_sample : tuple of BeforeAfter
        On the calibration data (optimistic).
    rms_by_stage : tuple of StageErrors
        ``"nominal"`` and each stage, on the calibration data.
    rms_by_stage_without_rejected : tuple of StageErrors or None
        The same without the observations the refinement rejected (for image points,
        without the images of the samples that hold one), when it rejected some: the
        errors the fit was made on (a rejected 67 mm sample makes 12.04 -> 11.60 mm of
        the whole look like no gain).
    errors_before, errors_after : tuple of GroupErrorSummary
        Of the nominal and calibrated URDF on the calibration data.
    kinematics, hand_eye, refine, export : section or None
        The stages that ran.
    errors_held_out : tuple of BeforeAfter or None
        On held-out data (the honest accuracy), when given.
    sidecar : str or None
        Path of the sidecar written with the calibrated URDF (set by the command line).
    errors_vs_truth_held_out, rms_vs_truth_held_out_by_stage : optional
        Against the noise-free true robot, in a simulation (``kinfw demo``).
    reprojection : ReprojectionSection or None
        Reprojection errors (px) of ``pixels`` observations per camera and image, the
        worst images named, against the calibration.
    reprojection_held_out : ReprojectionSection or None
        The same on held-out images (``kinfw demo --pixels``: fresh configurations).
    guard : GuardSummary or None
        The plausibility guard's bound and outcome (absent in reports written before it).

    In the file, the stage tables are one key per headline metric: the groups whose
    first metric is a position under ``position_rms_mm_by_stage``, image points under
    ``pixel_rms_px_by_stage``, plane contacts under ``height_rms_mm_by_stage``, a
    registered kind's under its own (``distance_rms_mm_by_stage``); the same with
    ``_vs_truth_held_out_by_stage`` and ``_by_stage_without_rejected``.
    """

    created: str
    method: str
    nominal_urdf: str
    data: DataProvenance
    notes: tuple[str, ...]
    errors_in_sample: tuple[BeforeAfter, ...]
    rms_by_stage: tuple[StageErrors, ...]
    errors_before: tuple[GroupErrorSummary, ...]
    errors_after: tuple[GroupErrorSummary, ...]
    kinematics: ClosedFormSection | None = None
    hand_eye: HandEyeSection | None = None
    refine: RefineSection | None = None
    export: ExportSection | None = None
    errors_held_out: tuple[BeforeAfter, ...] | None = None
    sidecar: str | None = None
    errors_vs_truth_held_out: tuple[BeforeAfter, ...] | None = None
    rms_vs_truth_held_out_by_stage: tuple[StageErrors, ...] | None = None
    reprojection: ReprojectionSection | None = None
    reprojection_held_out: ReprojectionSection | None = None
    rms_by_stage_without_rejected: tuple[StageErrors, ...] | None = None
    guard: GuardSummary | None = None

    FORMAT: ClassVar[str] = "kinfw-calibration-report"
    VERSION: ClassVar[int] = 1

    def to_dict(self) -> dict[str, Any]:
        """The JSON document (``kinfw-calibration-report`` v1); optional sections only
        when present."""
        doc: dict[str, Any] = {
            "format": self.FORMAT,
            "version": self.VERSION,
            "created": self.created,
            "method": self.method,
            "nominal_urdf": self.nominal_urdf,
            "data": self.data.to_dict(),
            "notes": list(self.notes),
            "errors_in_sample": [row.to_dict() for row in self.errors_in_sample],
            **_stages_to_dict(self.rms_by_stage, _BY_STAGE),
            "errors_before": {g.group: g.to_dict() for g in self.errors_before},
            "errors_after": {g.group: g.to_dict() for g in self.errors_after},
        }
        for key, section in (
            ("kinematics", self.kinematics),
            ("hand_eye", self.hand_eye),
            ("refine", self.refine),
            ("export", self.export),
        ):
            if section is not None:
                doc[key] = section.to_dict()
        if self.errors_held_out is not None:
            doc["errors_held_out"] = [row.to_dict() for row in self.errors_held_out]
        if self.sidecar is not None:
            doc["sidecar"] = self.sidecar
        if self.errors_vs_truth_held_out is not None:
            doc["errors_vs_truth_held_out"] = [r.to_dict() for r in self.errors_vs_truth_held_out]
        if self.rms_vs_truth_held_out_by_stage is not None:
            doc.update(_stages_to_dict(self.rms_vs_truth_held_out_by_stage, _TRUTH))
        if self.reprojection is not None:
            doc["reprojection_px"] = self.reprojection.to_dict()
        if self.reprojection_held_out is not None:
            doc["reprojection_px_held_out"] = self.reprojection_held_out.to_dict()
        if self.rms_by_stage_without_rejected is not None:
            doc.update(_stages_to_dict(self.rms_by_stage_without_rejected, _KEPT))
        if self.guard is not None:
            doc["guard"] = self.guard.to_dict()
        return doc

    @classmethod
    def from_dict(cls, doc: Any, source: str = "<memory>") -> CalibrationReport:
        """Read a parsed report. Raises :class:`kinfw.records.
        CalibrationFileError` naming ``source`` and the key."""
        r = DocReader(source)
        doc = r.header(doc, cls.FORMAT, cls.VERSION)

        def errors(key: str) -> tuple[GroupErrorSummary, ...]:
            groups = r.obj(r.value(doc, key, ""), key)
            return tuple(
                GroupErrorSummary.from_dict(g, r, f"{key}[{k!r}]") for k, g in groups.items()
            )

        def section(key: str, kind: Any) -> Any:
            return kind.from_dict(doc[key], r, key) if key in doc else None

        def rows(key: str) -> tuple[BeforeAfter, ...] | None:
            return BeforeAfter.rows_from(doc[key], r, key) if key in doc else None

        return cls(
            r.string(doc, "created", ""),
            r.string(doc, "method", ""),
            r.string(doc, "nominal_urdf", ""),
            DataProvenance.from_dict(r.value(doc, "data", ""), r, "data"),
            r.strings(doc, "notes", ""),
            rows("errors_in_sample") or (),
            _stages_from(doc, _BY_STAGE, r) or (),
            errors("errors_before"),
            errors("errors_after"),
            section("kinematics", ClosedFormSection),
            section("hand_eye", HandEyeSection),
            section("refine", RefineSection),
            section("export", ExportSection),
            rows("errors_held_out"),
            r.string(doc, "sidecar", "", optional=True),
            rows("errors_vs_truth_held_out"),
            _stages_from(doc, _TRUTH, r),
            section("reprojection_px", ReprojectionSection),
            section("reprojection_px_held_out", ReprojectionSection),
            _stages_from(doc, _KEPT, r),
            section("guard", GuardSummary),
        )


def read_report(path: str | Path) -> CalibrationReport:
    """Read a calibration report (``kinfw calibrate --report``); errors name the file
    and the key (:class:`kinfw.records.CalibrationFileError`)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise CalibrationFileError(
            f"{path}: not JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None
    return CalibrationReport.from_dict(doc, str(path))


def write_report(path: str | Path, report: CalibrationReport) -> Path:
    """Write ``report`` as indented JSON, atomically."""
    return write_text_atomic(path, json_text(report.to_dict()) + "\n")
