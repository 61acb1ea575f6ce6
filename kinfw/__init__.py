"""kinfw: calibrate robot kinematics from measurements.

The kinematics framework: a URDF robot in Pinocchio (:mod:`kinfw.robot`), rigid
transforms (:mod:`kinfw.transforms`), the tree CPC model (:mod:`kinfw.cpc`, CasADi version
in :mod:`kinfw.cpc_casadi`), measurement files (:mod:`kinfw.measurements`) and exact
calibrated-URDF export (:mod:`kinfw.urdf_export`). Estimators live in ``identification``,
checks in ``verification``; ``kinfw.cli`` wires them together.

``import kinfw`` loads neither CasADi nor meshcat; the names below are imported on
first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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
    from kinfw.robot import (
        Robot,
        RobotModelError,
        UnknownFrameError,
        builtin_head_urdf,
        load_robot,
    )
    from kinfw.urdf_export import ExportError, export_urdf, write_urdf

#: Where each public name lives. They are imported on first use (PEP 562), so that
#: ``import kinfw.cli`` (which runs this file) loads neither numpy nor Pinocchio and
#: ``kinfw --help`` starts at once.
_HOME = {
    "CPCModel": "cpc",
    "ZeroGeometry": "cpc",
    "cpc_from_robot": "cpc",
    "geometry_from_cpc": "cpc",
    "DatasetError": "measurements",
    "Measurements": "measurements",
    "PointObservations": "measurements",
    "PoseObservations": "measurements",
    "TargetObservations": "measurements",
    "read_measurements": "measurements",
    "write_measurements": "measurements",
    "Robot": "robot",
    "RobotModelError": "robot",
    "UnknownFrameError": "robot",
    "builtin_head_urdf": "robot",
    "load_robot": "robot",
    "ExportError": "urdf_export",
    "export_urdf": "urdf_export",
    "write_urdf": "urdf_export",
}

_SUBMODULES = ("cpc", "measurements", "robot", "transforms", "urdf_export")


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:  # ``import kinfw; kinfw.robot`` as before the lazy loading
        return importlib.import_module(f"kinfw.{name}")
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'kinfw' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"kinfw.{home}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_HOME})


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
