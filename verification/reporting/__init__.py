"""TODO face."""

from __future__ import annotations

from kinfw.verification.reporting._calibrate import CalibrationResult, calibrate_and_report
from kinfw.verification.reporting._report import (
    before_after_rows,
    calibration_report,
    errors_by_group,
    file_sha256,
    sidecar,
    sidecar_path,
)
from kinfw.verification.reporting._sections import (
    calibrated_unknowns,
    closed_form_section,
    downweighted_rows,
    hand_eye_section,
    noise_summary,
    refine_section,
    rejected_rows,
)
from kinfw.verification.reporting._stage_plot import plot_stage_errors

__all__ = [
    "CalibrationResult",
    "before_after_rows",
    "calibrate_and_report",
    "calibrated_unknowns",
    "calibration_report",
    "closed_form_section",
    "downweighted_rows",
    "errors_by_group",
    "file_sha256",
    "hand_eye_section",
    "noise_summary",
    "plot_stage_errors",
    "refine_section",
    "rejected_rows",
    "sidecar",
    "sidecar_path",
]
