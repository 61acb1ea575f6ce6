"""Fixations measured by Pinocchio's forward kinematics, not by the solver (shared by the
gaze tests and the front door's)."""

import numpy as np

from kinfw.control import ray_errors_rad
from kinfw.model import Robot

CAMERAS = ("left_camera", "right_camera")


def camera_poses(robot: Robot, q, cameras=CAMERAS) -> np.ndarray:
    """root_T_cameras (n_cameras, 4, 4) by Pinocchio FK."""
    return np.stack([robot.frame_poses(q, c) for c in cameras])


def fk_errors_rad(robot: Robot, q, point, rays=None, cameras=CAMERAS) -> np.ndarray:
    """Angle between each camera's ray and the point, measured by FK (not by the solver)."""
    rays = np.tile([0.0, 0.0, 1.0], (len(cameras), 1)) if rays is None else rays
    return ray_errors_rad(camera_poses(robot, q, cameras), rays, point)


def axes_intersection(root_T_cameras: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Closest point of two optical axes: (midpoint, distances along each axis, gap m)."""
    c0, c1 = root_T_cameras[:, :3, 3]
    d0, d1 = root_T_cameras[:, :3, 2]
    t = np.linalg.lstsq(np.column_stack([d0, -d1]), c1 - c0, rcond=None)[0]
    p0, p1 = c0 + t[0] * d0, c1 + t[1] * d1
    return 0.5 * (p0 + p1), t, float(np.linalg.norm(p0 - p1))


def ideal_fixation_points(robot: Robot, n: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """(q, point): random in-range configurations of IDEAL_HEAD and the point where both
    optical axes meet, in front of both cameras within 0.2 - 5 m."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        q = np.array(
            [
                rng.uniform(0.0, 0.5),  # slide
                rng.uniform(-1.8, 1.8),  # pan
                rng.uniform(-0.9, 0.9),  # tilt
                rng.uniform(-0.65, -0.02),  # vergence_left: turns right, towards the other
                rng.uniform(0.02, 0.65),  # vergence_right
            ]
        )
        point, t, gap = axes_intersection(camera_poses(robot, q))
        assert gap < 1e-12  # the axes are coplanar by construction: they meet
        if np.all((t > 0.2) & (t < 5.0)):
            out.append((q, point))
    return out


# -- exact geometry: the ideal head ----------------------------------------------------
