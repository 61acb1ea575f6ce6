"""Estimation: the calibration pipeline (:func:`identify`: closed form, hand-eye, joint
refinement), the CPC closed form (:func:`identify_closed_form`, Shih et al. 1992, section 4)
and the joint nonlinear least squares (:func:`refine`).

Subpackages: :mod:`kinfw.identification.problem` (the least-squares problem, solver, noise
and diagnostics), :mod:`kinfw.identification.handeye` (``A X = X B`` and ``A = X B Y``),
:mod:`kinfw.identification.checks` (units, redundancy, fit checks) and
:mod:`kinfw.identification.planning` (which configurations to measure).
"""

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
from kinfw.identification._pipeline import METHODS, Calibration, identify
from kinfw.identification.problem import (
    CHOICE_START,
    REJECT_Z,
    RefineResult,
    information_matrix,
    refine,
)

__all__ = [
    "CHOICE_START",
    "METHODS",
    "REJECT_Z",
    "Calibration",
    "ClosedFormResult",
    "JointScaleError",
    "ProtocolError",
    "RefineResult",
    "collect_frame_data",
    "geometry_at_zero",
    "identify",
    "identify_axes",
    "identify_closed_form",
    "identify_translations",
    "information_matrix",
    "one_joint_groups",
    "refine",
]
