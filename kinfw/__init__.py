"""kinfw: calibrate robot kinematics from measurements.

The kinematics framework: a URDF robot in Pinocchio (:mod:`kinfw.robot`), rigid
transforms (:mod:`kinfw.transforms`), the tree CPC model (:mod:`kinfw.cpc`, CasADi version
in :mod:`kinfw.cpc_casadi`), measurement files (:mod:`kinfw.measurements`) and exact
calibrated-URDF export (:mod:`kinfw.urdf_export`). Estimators live in ``identification``,
checks in ``verification``; ``kinfw.cli`` wires them together.

``import kinfw`` loads neither CasADi nor meshcat.
"""

from kinfw.cpc import CPCModel, ZeroGeometry, cpc_from_robot, geometry_from_cpc
from kinfw.measurements import (
    DatasetError,
    Measurements,
    PointObservations,
    PoseObservations,
    TargetObservations,
    read_measurements,
    write_measurements,
)
from kinfw.robot import Robot, RobotModelError, UnknownFrameError, builtin_head_urdf, load_robot
from kinfw.urdf_export import ExportError, export_urdf, write_urdf

__all__ = [
    "CPCModel",
    "DatasetError",
    "ExportError",
    "Measurements",
    "PointObservations",
    "PoseObservations",
    "Robot",
    "RobotModelError",
    "TargetObservations",
    "UnknownFrameError",
    "ZeroGeometry",
    "builtin_head_urdf",
    "cpc_from_robot",
    "export_urdf",
    "geometry_from_cpc",
    "load_robot",
    "read_measurements",
    "write_measurements",
    "write_urdf",
]
