"""Cameras and boards: intrinsics (pinhole with OpenCV's distortion), the boards' point
models (chessboard, ChArUco) and corner detection numbered by the board (OpenCV, imported
when used).
"""

from __future__ import annotations

from kinfw.camera._boards import DEFAULT_DICTIONARY, BoardError, Charuco, Chessboard, parse_board
from kinfw.camera._detect import Detection, Detector, read_gray
from kinfw.camera._intrinsics import (
    PARAMETER_NAMES,
    CameraError,
    CameraIntrinsics,
    intrinsics_from_dict,
    project_normalized,
    read_camera,
)

__all__ = [
    "DEFAULT_DICTIONARY",
    "PARAMETER_NAMES",
    "BoardError",
    "CameraError",
    "CameraIntrinsics",
    "Charuco",
    "Chessboard",
    "Detection",
    "Detector",
    "intrinsics_from_dict",
    "parse_board",
    "project_normalized",
    "read_camera",
    "read_gray",
]
