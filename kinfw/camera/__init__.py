"""Cameras and boards: intrinsics (pinhole with OpenCV's distortion), the boards' point
models (chessboard, ChArUco, circle grids, AprilTag grids) and their detection in images,
numbered by the board (OpenCV, imported when used).
"""

from __future__ import annotations

from kinfw.camera._boards import (
    APRILTAG_FAMILIES,
    AprilGrid,
    Board,
    BoardError,
    Charuco,
    Chessboard,
    CircleGrid,
    parse_board,
)
from kinfw.camera._detect import (
    Detection,
    Detector,
    read_gray,
)
from kinfw.camera._intrinsics import (
    PARAMETER_NAMES,
    CameraError,
    CameraIntrinsics,
    intrinsics_from_dict,
    project_normalized,
    read_camera,
)

__all__ = [
    "APRILTAG_FAMILIES",
    "PARAMETER_NAMES",
    "AprilGrid",
    "Board",
    "BoardError",
    "CameraError",
    "CameraIntrinsics",
    "Charuco",
    "Chessboard",
    "CircleGrid",
    "Detection",
    "Detector",
    "intrinsics_from_dict",
    "parse_board",
    "project_normalized",
    "read_camera",
    "read_gray",
]
