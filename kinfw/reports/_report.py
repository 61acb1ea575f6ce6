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
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from kinfw.files import json_text, write_text_atomic
from kinfw.reports._doc_reader import CalibrationFileError, DocReader
from kinfw.reports._records import BeforeAfter, DataProvenance
from kinfw.reports._refine import (
    Correlation,
    DownweightedRow,
    IdentifiabilitySummary,
    NotIdentifiable,
    ParameterRow,
    RefineSection,
    RejectedRow,
)
from kinfw.reports._reprojection import ReprojectionSection
from kinfw.reports._stages import (
    CameraMount,
    ClosedFormSection,
    ExportSection,
    HandEyeSection,
    KinematicValue,
    TargetEstimate,
)

__all__ = [
    "CalibrationReport",
    "CameraMount",
    "ClosedFormSection",
    "Correlation",
    "DownweightedRow",
    "ExportSection",
    "GroupErrorSummary",
    "HandEyeSection",
    "IdentifiabilitySummary",
    "KinematicValue",
    "NotIdentifiable",
    "ParameterRow",
    "RefineSection",
    "RejectedRow",
    "StageErrors",
    "TargetEstimate",
    "read_report",
    "write_report",
]


def _rows(cls, doc: dict, key: str, r: DocReader, at: str) -> tuple:
    path = r.path(at, key)
    return tuple(cls.from_dict(d, r, f"{path}[{k}]") for k, d in enumerate(r.items(doc, key, at)))


# -- errors -----------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class GroupErrorSummary:
    """Errors of a model on one observation group (see
    :meth:`kinfw.verification.evaluation.GroupErrors.summary`): position norm mean, RMS and max
    (mm), rotation mean, RMS and max (deg, NaN without orientation), and the mean and
    std of ``|error|`` per axis x, y, z (mm, Shih et al. Table 4); for image points
    (``pixels``: positions NaN, the per-axis arrays null in the file) the RMS and max
    pixel error (px)."""

    frame: str
    kind: str
    marker: str | None
    n: int
    position_mean_mm: float
    position_rms_mm: float
    position_max_mm: float
    rotation_mean_deg: float
    rotation_rms_deg: float
    rotation_max_deg: float
    abs_mean_xyz_mm: tuple[float, float, float]
    abs_std_xyz_mm: tuple[float, float, float]
    pixel_rms_px: float | None = None
    pixel_max_px: float | None = None

    _NUMBERS: ClassVar[tuple[str, ...]] = (
        "position_mean_mm",
        "position_rms_mm",
        "position_max_mm",
        "rotation_mean_deg",
        "rotation_rms_deg",
        "rotation_max_deg",
    )

    def __post_init__(self) -> None:
        for key in ("abs_mean_xyz_mm", "abs_std_xyz_mm"):
            object.__setattr__(self, key, tuple(float(v) for v in getattr(self, key)))

    @property
    def group(self) -> str:
        """The report's label: ``"frame (kind)"``, ``"frame [marker] (kind)"``."""
        marker = f" [{self.marker}]" if self.marker else ""
        return f"{self.frame}{marker} ({self.kind})"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready; a per-axis array that does not apply (NaN: image points) is null."""
        pixels = (
            {}
            if self.pixel_rms_px is None
            else {"pixel_rms_px": self.pixel_rms_px, "pixel_max_px": self.pixel_max_px}
        )
        return {
            "frame": self.frame,
            "kind": self.kind,
            "marker": self.marker,
            "n": self.n,
            **{k: getattr(self, k) for k in self._NUMBERS},
            **{
                k: None if any(math.isnan(v) for v in getattr(self, k)) else list(getattr(self, k))
                for k in ("abs_mean_xyz_mm", "abs_std_xyz_mm")
            },
            **pixels,
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> GroupErrorSummary:
        doc = r.obj(doc, at)

        def xyz(k: str) -> tuple[float, ...]:
            value = r.value(doc, k, at, optional=True)
            if value is None:
                return (math.nan,) * 3
            return tuple(r.array(value, r.path(at, k), (3,)).tolist())

        return cls(
            r.string(doc, "frame", at),
            r.string(doc, "kind", at),
            r.string(doc, "marker", at, optional=True),
            r.integer(doc, "n", at),
            *(r.number(doc, k, at) for k in cls._NUMBERS),
            xyz("abs_mean_xyz_mm"),
            xyz("abs_std_xyz_mm"),
            r.number(doc, "pixel_rms_px", at, optional=True),
            r.number(doc, "pixel_max_px", at, optional=True),
        )


def before_after(
    before: tuple[GroupErrorSummary, ...], after: tuple[GroupErrorSummary, ...]
) -> tuple[BeforeAfter, ...]:
    """Per group: RMS position (mm) and rotation (deg) before and after (matched by
    group label)."""
    after_of = {g.group: g for g in after}
    return tuple(
        BeforeAfter(
            g.group,
            g.n,
            g.position_rms_mm,
            after_of[g.group].position_rms_mm,
            g.rotation_rms_deg,
            after_of[g.group].rotation_rms_deg,
        )
        for g in before
    )


@dataclass(frozen=True, slots=True)
class StageErrors:
    """Position RMS (mm) per observation group after one stage (``"nominal"``,
    ``"closed form"``, ``"hand-eye"``, ``"refine"``)."""

    stage: str
    position_rms_mm: tuple[tuple[str, float], ...]

    @classmethod
    def of(cls, stage: str, errors: tuple[GroupErrorSummary, ...]) -> StageErrors:
        """Per group its position RMS (mm); image points (``pixels``) their pixel RMS,
        labelled ``"... [px]"``."""
        return cls(
            stage,
            tuple(
                (g.group, g.position_rms_mm)
                if g.pixel_rms_px is None
                else (f"{g.group} [px]", g.pixel_rms_px)
                for g in errors
            ),
        )


_PX = " [px]"


def _stages_to_dict(
    stages: tuple[StageErrors, ...], *, pixels: bool = False
) -> dict[str, dict[str, float]]:
    """Per stage the mm groups, or with ``pixels`` the px groups (labels without the
    ``" [px]"``): the two go to keys with their unit."""
    return {
        s.stage: {
            (g[: -len(_PX)] if pixels else g): v
            for g, v in s.position_rms_mm
            if g.endswith(_PX) == pixels
        }
        for s in stages
    }


def _stages_from(
    doc: dict, key: str, r: DocReader, pixel_key: str | None = None
) -> tuple[StageErrors, ...]:
    """Read :func:`_stages_to_dict`'s mm groups of ``key`` and px groups of
    ``pixel_key`` (optional; older files had px groups in ``key``, labelled ``[px]``)."""
    stages = r.obj(r.value(doc, key, ""), key)
    pixel = r.obj(doc[pixel_key], pixel_key) if pixel_key and pixel_key in doc else {}
    out = []
    for stage, groups in stages.items():
        at = f"{key}.{stage}"
        groups = r.obj(groups, at)
        rows = [(g, r.number(groups, g, at)) for g in groups]
        if stage in pixel:
            p_at = f"{pixel_key}.{stage}"
            p_groups = r.obj(pixel[stage], p_at)
            rows += [(g + _PX, r.number(p_groups, g, p_at)) for g in p_groups]
        out.append(StageErrors(stage, tuple(rows)))
    return tuple(out)


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
    position_rms_by_stage : tuple of StageErrors
        ``"nominal"`` and each stage, on the calibration data.
    errors_before, errors_after : tuple of GroupErrorSummary
        Of the nominal and calibrated URDF on the calibration data.
    kinematics, hand_eye, refine, export : section or None
        The stages that ran.
    errors_held_out : tuple of BeforeAfter or None
        On held-out data (the honest accuracy), when given.
    sidecar : str or None
        Path of the sidecar written with the calibrated URDF (set by the command line).
    errors_vs_truth_held_out, position_rms_vs_truth_held_out_by_stage : optional
        Against the noise-free true robot, in a simulation (``kinfw demo``).
    reprojection : ReprojectionSection or None
        Reprojection errors (px) of ``pixels`` observations per camera and image, the
        worst images named, against the calibration.
    reprojection_held_out : ReprojectionSection or None
        The same on held-out images (``kinfw demo --pixels``: fresh configurations).

    In the file, the stage tables' image groups (labelled ``"... [px]"`` in
    :attr:`position_rms_by_stage`) are under ``pixel_rms_px_by_stage``, the others
    under ``position_rms_mm_by_stage``.
    """

    created: str
    method: str
    nominal_urdf: str
    data: DataProvenance
    notes: tuple[str, ...]
    errors_in_sample: tuple[BeforeAfter, ...]
    position_rms_by_stage: tuple[StageErrors, ...]
    errors_before: tuple[GroupErrorSummary, ...]
    errors_after: tuple[GroupErrorSummary, ...]
    kinematics: ClosedFormSection | None = None
    hand_eye: HandEyeSection | None = None
    refine: RefineSection | None = None
    export: ExportSection | None = None
    errors_held_out: tuple[BeforeAfter, ...] | None = None
    sidecar: str | None = None
    errors_vs_truth_held_out: tuple[BeforeAfter, ...] | None = None
    position_rms_vs_truth_held_out_by_stage: tuple[StageErrors, ...] | None = None
    reprojection: ReprojectionSection | None = None
    reprojection_held_out: ReprojectionSection | None = None

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
            "position_rms_mm_by_stage": _stages_to_dict(self.position_rms_by_stage),
            **(
                {"pixel_rms_px_by_stage": px}
                if any((px := _stages_to_dict(self.position_rms_by_stage, pixels=True)).values())
                else {}
            ),
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
        if self.position_rms_vs_truth_held_out_by_stage is not None:
            doc["position_rms_mm_vs_truth_held_out_by_stage"] = _stages_to_dict(
                self.position_rms_vs_truth_held_out_by_stage
            )
        if self.reprojection is not None:
            doc["reprojection_px"] = self.reprojection.to_dict()
        if self.reprojection_held_out is not None:
            doc["reprojection_px_held_out"] = self.reprojection_held_out.to_dict()
        return doc

    @classmethod
    def from_dict(cls, doc: Any, source: str = "<memory>") -> CalibrationReport:
        """Read a parsed report. Raises :class:`kinfw.reports.
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

        truth_key = "position_rms_mm_vs_truth_held_out_by_stage"
        return cls(
            r.string(doc, "created", ""),
            r.string(doc, "method", ""),
            r.string(doc, "nominal_urdf", ""),
            DataProvenance.from_dict(r.value(doc, "data", ""), r, "data"),
            r.strings(doc, "notes", ""),
            rows("errors_in_sample") or (),
            _stages_from(doc, "position_rms_mm_by_stage", r, "pixel_rms_px_by_stage"),
            errors("errors_before"),
            errors("errors_after"),
            section("kinematics", ClosedFormSection),
            section("hand_eye", HandEyeSection),
            section("refine", RefineSection),
            section("export", ExportSection),
            rows("errors_held_out"),
            r.string(doc, "sidecar", "", optional=True),
            rows("errors_vs_truth_held_out"),
            _stages_from(doc, truth_key, r) if truth_key in doc else None,
            section("reprojection_px", ReprojectionSection),
            section("reprojection_px_held_out", ReprojectionSection),
        )


def read_report(path: str | Path) -> CalibrationReport:
    """Read a calibration report (``kinfw calibrate --report``); errors name the file
    and the key (:class:`kinfw.reports.CalibrationFileError`)."""
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
