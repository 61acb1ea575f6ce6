"""Rehearsal data: a perturbed "true" robot, measurement protocols (one joint at a time,
random configurations, contacts with a plane), simulated observations of every kind with
Fig. 10 noise of Shih et al. (1992), rendered board images, and planted outliers.
"""

from __future__ import annotations

from kinfw.simulation._board_images import (
    render_board,
    true_corners,
)
from kinfw.simulation._contacts import (
    contact_configurations,
)
from kinfw.simulation._images import (
    CAMERA_FILE,
    JOINTS_FILE,
    write_board_images,
)
from kinfw.simulation._measurements import (
    SimulatedMeasurements,
    SimulatedProbe,
    simulate_measurements,
)
from kinfw.simulation._outliers import (
    plant_outliers,
)
from kinfw.simulation._perturb import (
    one_joint_at_a_time,
    perturb_robot,
    random_configurations,
)
from kinfw.simulation._pixels import (
    DEFAULT_BOARD,
    DEFAULT_CAMERA,
    board_pose_facing,
    default_intrinsics,
    pixel_views,
    simulate_pixels,
    visible_points,
)
from kinfw.simulation._simulate import (
    default_target_pose,
    nine_circle_plate,
    perturb_poses,
    simulate_at,
    stereo_measure,
)

__all__ = [
    "CAMERA_FILE",
    "DEFAULT_BOARD",
    "DEFAULT_CAMERA",
    "JOINTS_FILE",
    "SimulatedMeasurements",
    "SimulatedProbe",
    "board_pose_facing",
    "contact_configurations",
    "default_intrinsics",
    "default_target_pose",
    "nine_circle_plate",
    "one_joint_at_a_time",
    "perturb_poses",
    "perturb_robot",
    "pixel_views",
    "plant_outliers",
    "random_configurations",
    "render_board",
    "simulate_at",
    "simulate_measurements",
    "simulate_pixels",
    "stereo_measure",
    "true_corners",
    "visible_points",
    "write_board_images",
]
