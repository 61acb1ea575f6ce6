"""kinfw: calibrate robot kinematics from measurements.

The kinematics framework: a URDF robot in Pinocchio (:mod:`kinfw.model`), rigid
transforms (:mod:`kinfw.geometry`), the tree CPC model (:mod:`kinfw.model`, CasADi version
in :mod:`kinfw.model`), measurement files (:mod:`kinfw.measurements`) and exact
calibrated-URDF export (:mod:`kinfw.urdf`). Estimators live in ``identification``,
checks in ``verification``; ``kinfw.cli`` wires them together.

``import kinfw`` loads neither CasADi nor meshcat; the names below are imported on
first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from kinfw.measurements import Measurements, read_measurements, write_measurements
    from kinfw.model import (
        CPCModel,
        Robot,
        RobotModelError,
        UnknownFrameError,
        ZeroGeometry,
        builtin_head_urdf,
        cpc_from_robot,
        geometry_from_cpc,
        load_robot,
    )
    from kinfw.observations import (
        DatasetError,
        PointObservations,
        PoseObservations,
        TargetObservations,
    )
    from kinfw.urdf import ExportError, export_urdf, write_urdf

#: Where each public name lives. They are imported on first use (PEP 562), so that
#: ``import kinfw.cli`` (which runs this file) loads neither numpy nor Pinocchio and
#: ``kinfw --help`` starts at once.
_HOME = {
    "CPCModel": "model",
    "ZeroGeometry": "model",
    "cpc_from_robot": "model",
    "geometry_from_cpc": "model",
    "DatasetError": "observations",
    "Measurements": "measurements",
    "PointObservations": "observations",
    "PoseObservations": "observations",
    "TargetObservations": "observations",
    "read_measurements": "measurements",
    "write_measurements": "measurements",
    "Robot": "model",
    "RobotModelError": "model",
    "UnknownFrameError": "model",
    "builtin_head_urdf": "model",
    "load_robot": "model",
    "ExportError": "urdf",
    "export_urdf": "urdf",
    "write_urdf": "urdf",
}

_SUBMODULES = ("geometry", "measurements", "model", "urdf")


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:  # ``import kinfw; kinfw.model`` as before the lazy loading
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
