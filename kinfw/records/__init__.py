"""The files a calibration leaves, typed: the report (``report.json``,
:class:`CalibrationReport`) and the sidecar beside the calibrated URDF
(``CALIBRATED.kinfw.json``, :class:`CalibrationFile`), with readers that name the file and
key of every error.
"""

from __future__ import annotations

from kinfw.records._doc_reader import (
    CalibrationFileError,
    DocReader,
)
from kinfw.records._joint_model import (
    joint_model_doc,
    joint_model_path,
    joint_model_text,
)
from kinfw.records._records import (
    BeforeAfter,
    CalibratedUnknown,
    DataProvenance,
    ErrorValue,
    GuardSummary,
    ModelSummary,
    NoiseSummary,
    RobotBlockRecord,
    headline,
)
from kinfw.records._refine import (
    Correlation,
    DownweightedRow,
    IdentifiabilitySummary,
    NotIdentifiable,
    ParameterRow,
    RefineSection,
    RejectedRow,
)
from kinfw.records._report import (
    CalibrationReport,
    GroupErrorSummary,
    StageErrors,
    before_after,
    read_report,
    write_report,
)
from kinfw.records._reprojection import (
    CameraReprojection,
    ImageReprojection,
    ReprojectionSection,
)
from kinfw.records._sidecar import (
    CalibrationSidecar,
    read_sidecar,
    write_sidecar,
)
from kinfw.records._stages import (
    CameraMount,
    ClosedFormSection,
    ExportSection,
    HandEyeSection,
    KinematicValue,
    TargetEstimate,
)

__all__ = [
    "BeforeAfter",
    "CalibratedUnknown",
    "CalibrationFileError",
    "CalibrationReport",
    "CalibrationSidecar",
    "CameraMount",
    "CameraReprojection",
    "ClosedFormSection",
    "Correlation",
    "DataProvenance",
    "DocReader",
    "DownweightedRow",
    "ErrorValue",
    "ExportSection",
    "GroupErrorSummary",
    "GuardSummary",
    "HandEyeSection",
    "IdentifiabilitySummary",
    "ImageReprojection",
    "KinematicValue",
    "ModelSummary",
    "NoiseSummary",
    "NotIdentifiable",
    "ParameterRow",
    "RefineSection",
    "RejectedRow",
    "ReprojectionSection",
    "RobotBlockRecord",
    "StageErrors",
    "TargetEstimate",
    "before_after",
    "headline",
    "joint_model_doc",
    "joint_model_path",
    "joint_model_text",
    "read_report",
    "read_sidecar",
    "write_report",
    "write_sidecar",
]
