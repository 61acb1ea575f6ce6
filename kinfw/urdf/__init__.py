"""Writing a calibrated model back into the robot's own URDF text: every tag kept, joint
origins and axes changed on measured paths, link frames re-expressed so nothing attached
moves (:func:`export_urdf`, :func:`write_urdf`, :func:`edit_urdf`); new links on fixed
joints (:func:`add_fixed_links`).
"""

from __future__ import annotations

from kinfw.urdf._edit import SAME_TOL, ExportError, add_fixed_links, edit_urdf
from kinfw.urdf._export import ExportResult, export_urdf, write_urdf

__all__ = [
    "SAME_TOL",
    "ExportError",
    "ExportResult",
    "add_fixed_links",
    "edit_urdf",
    "export_urdf",
    "write_urdf",
]
