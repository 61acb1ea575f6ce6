"""Using a calibration: fixating points with a head's cameras (:func:`fixate`,
:class:`GazeSolver`) and reaching poses or points with any frame (:func:`reach`), both by
bounded Gauss-Newton on Pinocchio's exact kinematics of any URDF, nominal or calibrated.
"""

from kinfw.control._gaze import (
    FIXATED_RAD,
    Fixation,
    GazeSolver,
    camera_points,
    fixate,
    ray_errors_rad,
)
from kinfw.control._reach import (
    REACHED_M,
    REACHED_RAD,
    Reach,
    reach,
)
from kinfw.control._solver import (
    BoundedSolution,
    Residual,
    middle_configuration,
    nearest_turn,
    solve_weak_directions,
)

"""Using a calibration: fixating points with a head's cameras (:mod:`.gaze`) and reaching
poses or points with any frame (:mod:`.reach`), both by bounded Gauss-Newton on
Pinocchio's exact kinematics (:mod:`.solver`)."""

__all__ = [
    "FIXATED_RAD",
    "REACHED_M",
    "REACHED_RAD",
    "BoundedSolution",
    "Fixation",
    "GazeSolver",
    "Reach",
    "Residual",
    "camera_points",
    "fixate",
    "middle_configuration",
    "nearest_turn",
    "ray_errors_rad",
    "reach",
    "solve_weak_directions",
]
