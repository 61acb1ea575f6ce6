"""Checks around a fit: the data's units against the nominal robot, enough residual rows
for the free parameters, whether what is left after the fit is noise, and whether what
the fit changed in the URDF is plausible (:func:`plausibility`).
"""

from __future__ import annotations

from kinfw.identification.checks._fit_checks import (
    CHI2_LIMIT,
    PLAUSIBLE_NOISE_M,
    PLAUSIBLE_NOISE_RAD,
    ROUNDING_RMS,
    STRUCTURE_R2,
    ResidualStructure,
    fit_warnings,
    implausible_noise,
    residual_structure,
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
from kinfw.identification.checks._redundancy import (
    MIN_DOF_PER_KIND,
    InsufficientDataError,
    Redundancy,
    check_redundancy,
    redundancy,
)
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
    "CHI2_LIMIT",
    "FLOOR_M",
    "FLOOR_RAD",
    "MIN_DOF_PER_KIND",
    "PLAUSIBLE_NOISE_M",
    "PLAUSIBLE_NOISE_RAD",
    "ROUNDING_RMS",
    "STRUCTURE_R2",
    "ChangeBound",
    "ImplausibleCalibrationError",
    "InsufficientDataError",
    "JointValues",
    "LargeChange",
    "Plausibility",
    "Redundancy",
    "ResidualStructure",
    "UnitDiagnostics",
    "UnitError",
    "UnitHypothesis",
    "check_fit",
    "check_joint_scale",
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
    "unit_diagnostics",
]
