"""Is the target the size it was said to be? One scale factor of a camera's board poses.

A board of the wrong size given to the pose estimation (a ChArUco square of 0.043 m for
0.034) scales every translation of ``camera_T_target`` by the same factor and leaves the
rotations alone. Images alone cannot tell (the same reprojection error), and a fit that
takes the poses as given absorbs the factor into the camera mount and the board's pose
(148 mm of mount on an eye-in-hand arm). The robot's own lengths can tell: with the
camera on or beside an arm, the translations the camera reports must follow the
robot's motion at the robot's scale.

:func:`target_scale` estimates that factor per camera and target by linear least
squares (:func:`kinfw.identification.handeye.translation_scale`): for observation ``i``,
the target's position in the root

    root_p_Pc(q_i) + root_R_Pc(q_i) u + s root_R_C(q_i) t_i = root_p_Pb(q_i) + root_R_Pb(q_i) v

with ``Pc`` the link after the last movable joint of the camera's path (the root for a
static camera), ``u`` the camera's position in it, ``Pb`` the same for the target's frame
(the root for a fixed target), ``v`` the target's position in it, ``t_i`` the measured
translation and ``s`` the factor: the true translation is ``s t_i``, so a board stated
larger than it is reads ``s < 1``. Unknowns ``(u, v, s)``, 7 of them, linear once the
rotations are known: ``root_R_C`` from the calibrated robot (rotations do not depend on
the board's size), the links' poses from the nominal robot, whose lengths are the scale
reference (a full calibration's link lengths could scale with the board: all lengths
times one factor is a symmetry of poses of an unknown board). The standard deviation
is the least squares' (residual variance times ``(A^T A)^-1``), so the nominal's errors
are counted as noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinfw.identification.handeye import translation_scale
from kinfw.measurements import Measurements
from kinfw.model import Robot
from kinfw.observations import PixelObservations, target_observations_from_pixels

#: A target's scale is named off only beyond this fraction: the nominal robot's lengths,
#: the scale reference, are known to a few millimetres over a metre, and its joints'
#: errors bias the estimate by about a percent (2 mm / 0.5 deg: 0.4 %).
SCALE_FLOOR = 0.03
#: ... and beyond this many of its standard deviations.
SCALE_Z = 4.0
#: Fewest observations for which the factor is estimated.
MIN_OBSERVATIONS = 3


@dataclass(frozen=True, slots=True)
class TargetScale:
    """The scale factor of one camera's poses of one target (:func:`target_scale`).

    Attributes
    ----------
    camera, target : str
        The camera frame and the target's name.
    scale : float
        ``s``: the true translations are ``s`` times the measured ones (a board stated
        larger than it is: ``s < 1``).
    sigma : float
        Its standard deviation.
    n : int
        Observations used.
    spacing_m : float or None
        For image points, the smallest distance between two of the board's points as
        given (its square), metres; None for poses.
    """

    camera: str
    target: str
    scale: float
    sigma: float
    n: int
    spacing_m: float | None = None

    @property
    def off(self) -> bool:
        """``|s - 1|`` beyond :data:`SCALE_Z` sigma and :data:`SCALE_FLOOR`."""
        return abs(self.scale - 1.0) > max(SCALE_Z * self.sigma, SCALE_FLOOR)

    def message(self) -> str:
        """One line naming the camera, the target and the factor with its sigma."""
        square = (
            f"its square {self.scale:.3g} times the one given to the pose estimation"
            if self.spacing_m is None
            else f"its points {self.spacing_m:.3g} m apart given, "
            f"{self.scale * self.spacing_m:.2g} m"
        )
        return (
            f"target {self.target!r} seen by {self.camera!r} looks {self.scale:.3g} times "
            f"its stated size (+- {self.sigma:.2g}, {self.n} poses): was {square}?\n"
            "The robot's lengths are the reference: the camera's translations follow its "
            "motion at that scale only; the calibration took the poses as given and "
            "absorbed the factor into the camera mount and the target's pose."
        )


def _moving_link(robot: Robot, frame: str | None) -> str:
    """The child link of the last movable joint on ``frame``'s path (the root for None
    or a frame no joint moves)."""
    if frame is None:
        return robot.root_link
    movable = [j for j in robot.path_joints(frame) if j.type != "fixed"]
    return movable[-1].child if movable else robot.root_link


def target_scale(
    nominal: Robot, calibrated: Robot, measurements: Measurements
) -> tuple[TargetScale, ...]:
    """The scale factor of each camera's target poses that the robot's motion
    determines (module docstring), per ``target`` group of ``measurements`` and per
    ``pixels`` group (its images' PnP poses:
    :func:`kinfw.observations.target_observations_from_pixels`; the factor is then the
    board points' scale).

    Parameters
    ----------
    nominal : Robot
        The nominal robot: its links' poses (the lengths that fix the scale).
    calibrated : Robot
        The calibrated robot: the cameras' orientations.
    measurements : Measurements
        The calibration data.

    Returns
    -------
    tuple of TargetScale
        One per group whose system determines the factor (at least
        :data:`MIN_OBSERVATIONS` poses, moving the camera or the target, rotations
        spread enough); none for a static camera watching a fixed target.
    """
    out = []
    names = measurements.joint_names
    images = measurements.groups("pixels")
    spacings = [None] * len(measurements.groups("target")) + [_spacing(g) for g in images]
    poses = [*measurements.groups("target"), *map(target_observations_from_pixels, images)]
    for group, spacing in zip(poses, spacings, strict=True):
        frames = [f for f in (group.camera, group.target_frame) if f is not None]
        if not all(nominal.has_frame(f) and calibrated.has_frame(f) for f in frames):
            continue  # a mount the nominal lacks (kinfw.measurements.mounted_robot adds it)
        camera_link = _moving_link(nominal, group.camera)
        target_link = _moving_link(nominal, group.target_frame)
        n = len(group.sample)
        if n < MIN_OBSERVATIONS or camera_link == target_link:
            continue
        qs = measurements.qs[group.sample]
        scale = translation_scale(
            base_T_links=nominal.frame_poses(qs, camera_link, names),
            base_R_cameras=calibrated.frame_poses(qs, group.camera, names)[:, :3, :3],
            camera_p_targets=group.camera_T_target[:, :3, 3],
            base_T_target_links=nominal.frame_poses(qs, target_link, names),
        )
        if scale is not None:
            out.append(TargetScale(group.camera, group.target, *scale, n, spacing))
    return tuple(out)


def _spacing(group: PixelObservations) -> float:
    """The smallest distance between two distinct points of a board (its square, for a
    chessboard's or ChArUco's corners), metres."""
    points = np.unique(np.round(group.target_p, 12), axis=0)
    d = np.linalg.norm(points[:, None] - points[None], axis=-1)
    return float(np.min(d[d > 0.0])) if len(points) > 1 else float("nan")
