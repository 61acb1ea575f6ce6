"""Stage 2 of Shih et al. (section 5): the cameras' hand-eye transforms and the target pose.

Each camera ``c`` on the robot observes a target fixed in the world at several
configurations; with the kinematics known (stage 1, or a trusted nominal URDF), every
observation is one equation of the hand-eye convention of
:mod:`kinfw.identification.handeye` with the URDF root as the base (Hirsh et al.'s
``A = X B Y``; Shih et al. eq. 68):

    camera_T_target(q_i) = camera_T_hand  @  hand_T_root(q_i)  @  root_T_target
           A_i           =       X        @        B_i         @        Y

where ``hand`` is the URDF link the camera's fixed joint hangs from (for the IIS-head, the
plate: the paper's "camera mount coordinate system"; the root for a static camera),
solved by :func:`kinfw.identification.handeye.solve_axyb` with
``base_T_hands = root_T_hand(q_i)``. A target on the robot (eye-to-hand: a board on the
flange, ``target_frame``) is the same equation with that frame as the base:
``B_i = hand_T_root(q_i) @ root_T_frame(q_i)``, ``Y = frame_T_target``.
The camera's fixed joint origin ``hand_T_camera`` is what the calibrated URDF changes;
``root_T_target`` (the solver's ``base_T_target``) is the target's pose in the
measurement frame, which belongs in the report, not the URDF.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import average_transform, inverse_transform, rotation_angle
from kinfw.identification.handeye._axyb import solve_axyb
from kinfw.identification.handeye._result import AXYBResult
from kinfw.identification.handeye._uncertainty import Verdict
from kinfw.measurements import Measurements, target_views
from kinfw.model import Robot
from kinfw.observations import DatasetError, TargetObservations


@dataclass(frozen=True, slots=True)
class CameraCalibration:
    """The hand-eye result of one camera.

    Attributes
    ----------
    camera, target : str
        Camera frame and target name.
    joint, hand : str
        The camera's fixed joint and the link it hangs from.
    hand_T_camera : ndarray, shape (4, 4)
        Identified pose of the camera in the hand link (the new joint origin), metres.
    root_T_target : ndarray, shape (4, 4)
        Identified pose of the target in the measurement frame (in its ``target_frame``
        for a target on the robot), from this camera alone.
    n_views : int
    solver : AXYBResult
        The solver's record (iterations, restarts, residuals, verdict).
    """

    camera: str
    target: str
    joint: str
    hand: str
    hand_T_camera: NDArray[np.float64]
    root_T_target: NDArray[np.float64]
    n_views: int
    solver: AXYBResult


@dataclass(frozen=True, slots=True)
class CamerasResult:
    """Stage 2 for every camera.

    Attributes
    ----------
    cameras : tuple of CameraCalibration
    root_T_targets : tuple of (target, ndarray (4, 4)) pairs
        Per target, the chordal mean of the cameras' estimates of its pose in the
        measurement frame.
    target_spread : tuple of (target, position_m, rotation_rad)
        Per target, the largest distance between any camera's estimate and the mean:
        cameras that see the same target must agree on where it is.
    """

    cameras: tuple[CameraCalibration, ...]
    root_T_targets: tuple[tuple[str, NDArray[np.float64]], ...]
    target_spread: tuple[tuple[str, float, float], ...]


def camera_mount(robot: Robot, camera: str) -> tuple[str, str]:
    """The fixed joint into ``camera`` and the link it hangs from.

    Raises
    ------
    DatasetError
        If ``camera`` is the root link or the child of a movable joint (then there is no
        fixed mount to calibrate).
    """
    path = robot.path_joints(camera)
    if not path or path[-1].type != "fixed" or path[-1].child != camera:
        raise DatasetError(
            f"{robot.source}: camera frame {camera!r} must be a link attached by a fixed "
            "joint (its mount) to the robot; give the camera its own link and fixed joint"
        )
    return path[-1].name, path[-1].parent


def _check_relative_motion(robot: Robot, group: TargetObservations) -> None:
    """Refuse a camera and a target that no joint moves relative to each other.

    Raises
    ------
    DatasetError
        Naming the target and the ``target_frame`` key (a static camera
        watching a board on the robot: the board is on a link, not fixed in the world).
    """
    target_frame = robot.root_link if group.target_frame is None else group.target_frame
    between = set(robot.movable_path(group.camera)) ^ set(robot.movable_path(target_frame))
    if not between:
        where = "fixed in the world" if group.target_frame is None else f"on {target_frame!r}"
        raise DatasetError(
            f"target {group.target!r} ({where}) does not move relative to the camera: no "
            "joint lies between them. If the board rides on "
            'the robot (a static camera, eye-to-hand), give its observations "target_frame": '
            "the URDF link it is fixed to (e.g. the flange)"
        )


def _solve_one(
    robot: Robot, group: TargetObservations, measurements: Measurements, rng: np.random.Generator
) -> CameraCalibration:
    joint, hand = camera_mount(robot, group.camera)
    _check_relative_motion(robot, group)
    qs = measurements.qs[group.sample]
    names = measurements.joint_names
    # the solver's base is where the target is fixed: the root, or its target_frame
    base_T_hands = robot.frame_poses(qs, hand, names).reshape(-1, 4, 4)
    if group.target_frame is not None:
        root_T_bases = robot.frame_poses(qs, group.target_frame, names).reshape(-1, 4, 4)
        base_T_hands = inverse_transform(root_T_bases) @ base_T_hands
    result = solve_axyb(camera_T_targets=group.camera_T_target, base_T_hands=base_T_hands, rng=rng)
    if result.verdict is not Verdict.DETERMINED:
        warnings.warn(
            f"camera {group.camera!r}: hand-eye {result.verdict_message} (lengths in m); "
            f"add views with larger rotations about different axes",
            UserWarning,
            stacklevel=3,
        )
    return CameraCalibration(
        camera=group.camera,
        target=group.target,
        joint=joint,
        hand=hand,
        hand_T_camera=result.hand_T_camera,
        root_T_target=result.base_T_target,
        n_views=len(group.sample),
        solver=result,
    )


def calibrate_cameras(
    robot: Robot, measurements: Measurements, *, rng: np.random.Generator | None = None
) -> CamerasResult:
    """Hand-eye transform of every camera with ``target`` observations, and the targets.

    Parameters
    ----------
    robot : Robot
        Kinematics to trust (the stage-1 calibrated URDF, or the nominal one).
    measurements : Measurements
        ``target`` observations (``camera_T_target``) and ``pixels`` observations (their
        images' PnP poses, :func:`kinfw.measurements.target_views`); other kinds are ignored.
    rng : numpy.random.Generator, optional
        For the solver's random restarts (reproducible by default).

    Raises
    ------
    DatasetError
        No target or pixel observations, or a camera without a fixed mount; the solver's
        :class:`kinfw.identification.handeye.AXYBError` (a ``ValueError``) for too few or
        degenerate views, naming the camera.
    """
    views = target_views(measurements)
    if not views:
        raise DatasetError(
            f"{measurements.source}: no 'target' or 'pixels' observations for stage 2"
        )
    rng = np.random.default_rng(0) if rng is None else rng
    cameras = []
    for group in views:
        try:
            cameras.append(_solve_one(robot, group, measurements, rng))
        except ValueError as exc:
            raise type(exc)(f"{measurements.source}: camera {group.camera!r}: {exc}") from None
    poses, spread = [], []
    for target in dict.fromkeys(c.target for c in cameras):
        estimates = np.stack([c.root_T_target for c in cameras if c.target == target])
        mean = average_transform(estimates)
        poses.append((target, mean))
        spread.append(
            (
                target,
                float(np.linalg.norm(estimates[:, :3, 3] - mean[:3, 3], axis=1).max()),
                float(rotation_angle(mean[:3, :3].T @ estimates[:, :3, :3]).max()),
            )
        )
    return CamerasResult(tuple(cameras), tuple(poses), tuple(spread))
