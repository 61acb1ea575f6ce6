"""Checks around a fit: the data's units against the nominal robot (and hand-eye pose
pairs' units and quaternion order against their own motion), enough residual rows for
the free parameters, whether what is left after the fit is noise, whether a camera's
target is the size it was said to be, and whether what the fit changed in the URDF is
plausible (:func:`plausibility`).
"""

from __future__ import annotations

from kinfw.identification.checks._fit_checks import (
    ResidualStructure,
    fit_warnings,
    implausible_noise,
    residual_structure,
    stated_noise,
)
from kinfw.identification.checks._plausibility import (
    ChangeBound,
    ImplausibleCalibrationError,
    LargeChange,
    Plausibility,
    fit_plausibility,
    mount_plausibility,
    plausibility,
    robot_size,
)
from kinfw.identification.checks._pose_pair_checks import (
    PosePairDiagnostics,
    check_pose_pair_data,
)
from kinfw.identification.checks._redundancy import (
    InsufficientDataError,
    Redundancy,
    check_redundancy,
    redundancy,
)
from kinfw.identification.checks._scale import (
    SCALE_FLOOR,
    TargetScale,
    target_scale,
)
from kinfw.identification.checks._units import (
    UnitError,
    check_fit,
    check_joint_scale,
    check_units,
    median_residuals,
)
from kinfw.identification.checks._units_evidence import (
    JointValues,
    UnitDiagnostics,
    UnitHypothesis,
    unit_diagnostics,
)

__all__ = [
    "SCALE_FLOOR",
    "ChangeBound",
    "ImplausibleCalibrationError",
    "InsufficientDataError",
    "JointValues",
    "LargeChange",
    "Plausibility",
    "PosePairDiagnostics",
    "Redundancy",
    "ResidualStructure",
    "TargetScale",
    "UnitDiagnostics",
    "UnitError",
    "UnitHypothesis",
    "check_fit",
    "check_joint_scale",
    "check_pose_pair_data",
    "check_redundancy",
    "check_units",
    "fit_plausibility",
    "fit_warnings",
    "implausible_noise",
    "median_residuals",
    "mount_plausibility",
    "plausibility",
    "redundancy",
    "residual_structure",
    "robot_size",
    "stated_noise",
    "target_scale",
    "unit_diagnostics",
]
