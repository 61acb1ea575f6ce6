"""TODO face."""

from __future__ import annotations

from kinfw.identification._closed_form import (
    ClosedFormResult,
    JointScaleError,
    ProtocolError,
    collect_frame_data,
    geometry_at_zero,
    identify_axes,
    identify_closed_form,
    identify_translations,
    one_joint_groups,
)
from kinfw.identification._pipeline import METHODS, Calibration, calibrate
from kinfw.identification._refine import REJECT_Z, information_matrix, refine
from kinfw.identification._refine_result import RefineResult

__all__ = [
    "METHODS",
    "REJECT_Z",
    "Calibration",
    "ClosedFormResult",
    "JointScaleError",
    "ProtocolError",
    "RefineResult",
    "calibrate",
    "collect_frame_data",
    "geometry_at_zero",
    "identify_axes",
    "identify_closed_form",
    "identify_translations",
    "information_matrix",
    "one_joint_groups",
    "refine",
]
