"""TODO face."""

from __future__ import annotations

from kinfw.urdf._edit import SAME_TOL, ExportError, edit_urdf
from kinfw.urdf._export import ExportResult, export_urdf, write_urdf

__all__ = [
    "SAME_TOL",
    "ExportError",
    "ExportResult",
    "edit_urdf",
    "export_urdf",
    "write_urdf",
]
