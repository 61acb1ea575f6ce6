"""Checks around a fit: the data's units against the nominal robot (and hand-eye pose
pairs' units and quaternion order against their own motion), enough residual rows for
the free parameters, whether what is left after the fit is noise, whether a camera's
target is the size it was said to be, and whether what the fit changed in the URDF is
plausible (:func:`plausibility`).
"""

from __future__ import annotations

from kinfw.identification.checks._fit_checks import (
    PLAUSIBLE_NOISE_M,
    PLAUSIBLE_NOISE_RAD,
    ROUNDING_RMS,
    STRUCTURE_R2,
    ResidualStructure,
    fit_warnings,
    implausible_noise,
    residual_structure,
    stated_noise,
    stated_noise_limit,
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
    root_measured,
    stance_links,
)
from kinfw.identification.checks._pose_pair_checks import (
    PLAUSIBLE_LENGTH_M,
    PosePairDiagnostics,
    check_pose_pair_data,
)
from kinfw.identification.checks._redundancy import (
    MIN_DOF_PER_KIND,
    InsufficientDataError,
    Redundancy,
    check_redundancy,
    redundancy,
)
from kinfw.identification.checks._scale import SCALE_FLOOR, SCALE_Z, TargetScale, target_scale
from kinfw.identification.checks._units import (
    UnitError,
    check_fit,
    check_joint_scale,
    check_units,
    median_residuals,
)
from kinfw.identification.checks._units_evidence import (
    BAD_SCORE,
    BETTER_FACTOR,
    FLOOR_M,
    FLOOR_RAD,
    JointValues,
    UnitDiagnostics,
    UnitHypothesis,
    unit_diagnostics,
)

__all__ = [
    "BAD_SCORE",
    "BETTER_FACTOR",
    "FLOOR_M",
    "FLOOR_RAD",
    "MIN_DOF_PER_KIND",
    "PLAUSIBLE_LENGTH_M",
    "PLAUSIBLE_NOISE_M",
    "PLAUSIBLE_NOISE_RAD",
    "ROUNDING_RMS",
    "SCALE_FLOOR",
    "SCALE_Z",
    "STRUCTURE_R2",
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
    "root_measured",
    "stance_links",
    "stated_noise",
    "stated_noise_limit",
    "target_scale",
    "unit_diagnostics",
]
