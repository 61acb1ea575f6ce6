"""A calibration's report and sidecar built from the pipeline's results, the calibration
workflow that makes them (:func:`calibrate_and_report`: model choice, pipeline, report;
its result writes the URDF and sidecar together), the same for a fleet of robots
(:func:`calibrate_fleet`: a calibrated URDF and report per robot, a summary), and the
errors-by-stage figure.
"""

from __future__ import annotations

from kinfw.verification.reporting._calibrate import (
    CalibrationResult,
    IntrinsicsEvidence,
    calibrate_and_report,
)
from kinfw.verification.reporting._fleet import (
    FLEET_SUMMARY,
    FleetMember,
    FleetResult,
    FleetRow,
    calibrate_fleet,
    fleet_members,
)
from kinfw.verification.reporting._report import (
    before_after_rows,
    calibration_report,
    errors_by_group,
    robot_block_records,
    sidecar,
)
from kinfw.verification.reporting._sections import (
    refine_section,
)
from kinfw.verification.reporting._stage_plot import (
    plot_stage_errors,
)

__all__ = [
    "FLEET_SUMMARY",
    "CalibrationResult",
    "FleetMember",
    "FleetResult",
    "FleetRow",
    "IntrinsicsEvidence",
    "before_after_rows",
    "calibrate_and_report",
    "calibrate_fleet",
    "calibration_report",
    "errors_by_group",
    "fleet_members",
    "plot_stage_errors",
    "refine_section",
    "robot_block_records",
    "sidecar",
]
