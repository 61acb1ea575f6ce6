"""Rigid-body geometry: transforms and their conventions, the one chart of a rigid frame,
and least-squares registration of point sets.

``a_T_b`` maps coordinates in frame ``b`` to frame ``a`` (read right to left, so inner
frames cancel); quaternions are ``xyzw``; SI units inside (docs/conventions.md).
"""

from __future__ import annotations

from kinfw.geometry._chart import (
    cayley_rotation,
    chart_from_rigid,
    rigid_from_chart,
    rigid_from_chart_casadi,
    rotation_chart,
)
from kinfw.geometry._registration import (
    register_points,
)
from kinfw.geometry._transforms import (
    angle_between,
    average_transform,
    check_rotation,
    check_transform,
    inverse_transform,
    matrix_from_rotation_vector,
    project_to_rotation,
    quat_xyzw_from_matrix,
    rot_z,
    rotation_angle,
    rotation_vector_from_matrix,
    skew,
    transform_from_rotation_translation,
    transform_from_xyz_quat_xyzw,
    vee,
    xyz_quat_xyzw_from_transform,
)

__all__ = [
    "angle_between",
    "average_transform",
    "cayley_rotation",
    "chart_from_rigid",
    "check_rotation",
    "check_transform",
    "inverse_transform",
    "matrix_from_rotation_vector",
    "project_to_rotation",
    "quat_xyzw_from_matrix",
    "register_points",
    "rigid_from_chart",
    "rigid_from_chart_casadi",
    "rot_z",
    "rotation_angle",
    "rotation_chart",
    "rotation_vector_from_matrix",
    "skew",
    "transform_from_rotation_translation",
    "transform_from_xyz_quat_xyzw",
    "vee",
    "xyz_quat_xyzw_from_transform",
]
