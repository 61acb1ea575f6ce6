"""Simulated calibration data: the experiments of Shih et al. (1992), section 6.

The pieces of the paper's Fig. 10 simulation, over any URDF robot:

- a "true" robot: the nominal URDF with random geometric errors
  (:func:`perturb_robot`);
- measurement protocols: one joint at a time, as section 4.1 requires
  (:func:`one_joint_at_a_time`), and random configurations for held-out tests
  (:func:`random_configurations`);
- measurement noise: a translation error per axis plus a rotation about a random axis
  (:func:`perturb_poses`), or the stereo rig itself, noisy 3D circle centres of the
  nine-circle plate registered with Arun's method (:func:`stereo_measure`);
- a measurement dataset built from the true robot's forward kinematics (Pinocchio)
  (:func:`simulate`).

Every random draw comes from a ``numpy.random.Generator`` passed in by the caller; no
global random state is used, so a seed reproduces a study exactly.

:func:`perturb_robot`, :func:`one_joint_at_a_time` and :func:`random_configurations`
live in :mod:`verification.perturb` and are re-exported here (most callers import them
from this module).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.blocks import BlockKey
from kinfw.camera_model import CameraIntrinsics
from kinfw.measurements import (
    Measurements,
    PointObservations,
    PoseObservations,
    TargetObservations,
)
from kinfw.observations import kind_of
from kinfw.observations.numeric import (
    MissingValue,
    NumericContext,
    perturb_transforms,
)
from kinfw.observations.point import offset_key
from kinfw.registration import register_points
from kinfw.robot import Robot
from kinfw.transforms import (
    check_transform,
    inverse_transform,
    transform_from_rotation_translation,
)
from verification.perturb import (
    check_sigma,
    one_joint_at_a_time,
    perturb_robot,
    random_configurations,
)

__all__ = [
    "DEFAULT_BOARD",
    "DEFAULT_CAMERA",
    "board_pose_facing",
    "default_intrinsics",
    "default_target_pose",
    "nine_circle_plate",
    "one_joint_at_a_time",
    "perturb_poses",
    "perturb_robot",
    "pixel_views",
    "random_configurations",
    "simulate",
    "simulate_pixels",
    "stereo_measure",
    "visible_points",
]


# -- measurement noise and the stereo rig ----------------------------------------------


def perturb_poses(
    a_T_bs: ArrayLike, rng: np.random.Generator, sigma_m: float, sigma_rad: float
) -> NDArray[np.float64]:
    """Noisy copies of poses, as the simulation of Shih et al. (1992), Fig. 10.

    Parameters
    ----------
    a_T_bs : array_like, shape (n, 4, 4) or (4, 4)
        True poses of frame b in frame a, metres.
    rng : numpy.random.Generator
    sigma_m : float
        Standard deviation of each translation component, metres.
    sigma_rad : float
        Standard deviation of the rotation error angle, radians.

    Returns
    -------
    ndarray, same shape as ``a_T_bs``
        ``[a_R_b dR, a_p_b + dp]`` with ``dp ~ N(0, sigma_m^2 I)`` in frame a and ``dR``
        a rotation by an angle ``N(0, sigma_rad)`` about a uniformly random axis (in
        frame b, the measured frame).

    Notes
    -----
    Because the axis is isotropic, ``a_R_b dR`` has the same distribution as
    ``dR' a_R_b`` (noise in frame a); the rotation error angle ``|N(0, sigma_rad)|`` has
    RMS ``sigma_rad`` whichever side it is applied on.
    """
    a_T_bs = check_transform(a_T_bs, name="a_T_bs")
    sigma_m = check_sigma(sigma_m, "sigma_m")
    sigma_rad = check_sigma(sigma_rad, "sigma_rad")
    single = a_T_bs.ndim == 2
    out = perturb_transforms(a_T_bs.reshape(-1, 4, 4), rng, sigma_m, sigma_rad)
    return out[0] if single else out


def nine_circle_plate(spacing: float = 0.02) -> NDArray[np.float64]:
    """Centres of the nine circles of the end-effector calibration plate (paper's Fig. 7).

    Parameters
    ----------
    spacing : float, optional
        Distance between neighbouring circle centres, metres.

    Returns
    -------
    plate_p_circles : ndarray, shape (9, 3)
        A 3 x 3 grid in the plate's xy plane (z = 0), row by row; the plate frame's
        origin is the central circle (row 4), as in the paper.
    """
    spacing = float(spacing)
    if not (np.isfinite(spacing) and spacing > 0.0):
        raise ValueError(f"spacing: expected a positive distance, got {spacing}")
    y, x = np.meshgrid([-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0], indexing="ij")
    return spacing * np.stack([x.ravel(), y.ravel(), np.zeros(9)], axis=-1)


def stereo_measure(
    meas_T_plates: ArrayLike,
    rng: np.random.Generator,
    sigma_point_m: float,
    plate: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Plate poses as the stereo rig of stage 1 measures them (Shih et al. section 3).

    The rig triangulates each circle centre with an error ``N(0, sigma_point_m^2 I)``;
    the pose follows by registering the measured centres with their positions on the
    plate (:func:`identification.registration.register_points`, eqs. (16)-(22)).

    Parameters
    ----------
    meas_T_plates : array_like, shape (n, 4, 4) or (4, 4)
        True poses of the plates in the rig frame, metres.
    rng : numpy.random.Generator
    sigma_point_m : float
        Standard deviation of each coordinate of each measured circle centre, metres.
    plate : array_like, shape (N, 3), optional
        Circle centres in the plate frame (metres); default :func:`nine_circle_plate`.

    Returns
    -------
    ndarray, same shape as ``meas_T_plates``
        Measured plate poses in the rig frame.
    """
    meas_T_plates = check_transform(meas_T_plates, name="meas_T_plates")
    sigma_point_m = check_sigma(sigma_point_m, "sigma_point_m")
    plate_p = nine_circle_plate() if plate is None else np.asarray(plate, dtype=float)
    meas_p = (
        np.einsum("...ij,kj->...ki", meas_T_plates[..., :3, :3], plate_p)
        + meas_T_plates[..., None, :3, 3]
    )
    meas_p = meas_p + rng.normal(0.0, sigma_point_m, size=meas_p.shape)
    return register_points(plate_p, meas_p)


# -- datasets --------------------------------------------------------------------------


def default_target_pose(
    robot: Robot,
    qs: ArrayLike,
    joint_names: Sequence[str] | None,
    cameras: Sequence[str],
    distance: float = 0.8,
) -> NDArray[np.float64]:
    """A plausible fixed target pose in front of the cameras, ``w_T_target``.

    The target's origin is the mean camera position (over all samples and cameras) plus
    ``distance`` along the mean optical axis (camera z); its z axis points back at the
    cameras (minus that mean axis), its x axis is the mean camera x axis made
    perpendicular to it. ``w`` is the robot's root link.

    Parameters
    ----------
    robot : Robot
    qs : array_like, shape (n, k)
        Joint values (rad, m), columns in ``joint_names`` order.
    joint_names : sequence of str or None
        Column order of ``qs``; None for :attr:`Robot.joint_names`.
    cameras : sequence of str
        Camera frames (URDF links; optical axis = z).
    distance : float, optional
        Metres in front of the cameras.

    Returns
    -------
    w_T_target : ndarray, shape (4, 4)
    """
    if isinstance(cameras, str) or not len(cameras):
        raise ValueError("default_target_pose: give a sequence of at least one camera frame")
    names = None if joint_names is None else tuple(joint_names)
    qs2 = np.atleast_2d(np.asarray(qs, dtype=float))
    w_T_cams = np.concatenate([robot.frame_poses(qs2, c, names) for c in cameras])
    mean_z = w_T_cams[:, :3, 2].mean(axis=0)
    if np.linalg.norm(mean_z) < 1e-6:
        raise ValueError(
            "default_target_pose: the cameras' optical axes average to zero; give w_T_target"
        )
    mean_z /= np.linalg.norm(mean_z)
    z = -mean_z
    x = w_T_cams[:, :3, 0].mean(axis=0)
    x -= (x @ z) * z
    if np.linalg.norm(x) < 1e-6:  # any direction perpendicular to z
        x = np.cross(z, np.eye(3)[np.argmin(np.abs(z))])
    x /= np.linalg.norm(x)
    w_R_target = np.stack([x, np.cross(z, x), z], axis=-1)
    w_p_target = w_T_cams[:, :3, 3].mean(axis=0) + float(distance) * mean_z
    return transform_from_rotation_translation(w_R_target, w_p_target)


def simulate(
    robot: Robot,
    qs: ArrayLike,
    joint_names: Sequence[str] | None,
    *,
    frames: Iterable[str] = (),
    cameras: Iterable[str] = (),
    markers: Iterable[tuple[Any, ...]] = (),
    rng: np.random.Generator,
    noise_m: float = 0.0,
    noise_rad: float = 0.0,
    stereo_sigma_m: float | None = None,
    w_T_target: ArrayLike | None = None,
    groups: Iterable[Any] = (),
    unknowns: Mapping[BlockKey, ArrayLike] | None = None,
    sigmas: Mapping[str, float] | None = None,
) -> Measurements:
    """A measurement dataset of ``robot`` (the truth) in configurations ``qs``.

    Forward kinematics is Pinocchio's (:meth:`Robot.frame_poses`), in the robot's root
    link ``w``, the default measurement frame. Every group is simulated by its kind
    (:meth:`kinfw.observations.base.ObservationKind.simulate`: its numpy prediction plus
    its noise model), in order: poses, targets, points, then ``groups``.

    Parameters
    ----------
    robot : Robot
        The true robot (e.g. ``load_robot(perturb_robot(nominal, rng))``).
    qs : array_like, shape (n, k)
        Joint values (rad, m), columns in ``joint_names`` order.
    joint_names : sequence of str or None
        Column order of ``qs``; None for :attr:`Robot.joint_names`. Unlisted joints are
        held at zero.
    frames : iterable of str
        Frames whose pose ``w_T_frame`` is measured (``pose`` observations).
    cameras : iterable of str
        Camera frames that observe the fixed target (``target`` observations,
        ``camera_T_target = inv(w_T_camera) @ w_T_target``).
    markers : iterable of tuples
        Points on the robot (``point`` observations of ``w_p_point``): ``(frame,
        offset)`` with the point's position ``offset`` (3,) in ``frame`` (metres), given
        in the dataset as known; or ``(frame, offset, name)``, a named marker whose
        offset is left out of the dataset (unknown, to be estimated).
    rng : numpy.random.Generator
        Source of all noise.
    noise_m : float, optional
        Standard deviation of each position component of poses, targets and points,
        metres; also of any noise component in metres of another kind.
    noise_rad : float, optional
        Standard deviation of the rotation error angle of poses and targets, radians
        (see :func:`perturb_poses`); also of any noise component in radians.
    stereo_sigma_m : float, optional
        If given, poses are measured by the simulated stereo rig instead
        (:func:`stereo_measure` with this point noise, metres); ``noise_m`` and
        ``noise_rad`` then apply to targets and points only.
    w_T_target : array_like, shape (4, 4), optional
        Pose of the target in ``w``; default :func:`default_target_pose`.
    groups : iterable of observation groups, optional
        Groups of any registered kind (e.g. a kind added by an application), used as
        templates: what is observed and at which samples (indices into ``qs``); their
        measured values are replaced by simulated ones.
    unknowns : mapping of BlockKey to array_like, optional
        True values of the unknown blocks the ``groups`` need (a marker's pose (4, 4),
        a point (3,), ...), in ``w``.
    sigmas : mapping of str to float, optional
        Standard deviation per noise component name (``"position"``, ``"rotation"``, a
        kind's own), SI; a component not named takes ``noise_m`` (unit m) or
        ``noise_rad`` (unit rad), or no noise (another unit: ``"pixel"`` in px).

    Returns
    -------
    Measurements
        One pose group per frame, one target group per camera, one point group per
        marker, each with every sample, and the simulated ``groups``; ``source`` is
        ``"<simulated>"``.
    """
    frames, cameras, markers = tuple(frames), tuple(cameras), tuple(markers)
    groups = tuple(groups)
    for name, value in (("frames", frames), ("cameras", cameras)):
        if any(not isinstance(v, str) for v in value):
            raise TypeError(f"simulate: {name} must be a sequence of frame names")
    if not (frames or cameras or markers or groups):
        raise ValueError("simulate: nothing to observe; give frames, cameras, markers or groups")
    names = tuple(robot.joint_names if joint_names is None else joint_names)
    qs = np.atleast_2d(np.asarray(qs, dtype=float))
    noise_m = check_sigma(noise_m, "noise_m")
    noise_rad = check_sigma(noise_rad, "noise_rad")
    sigmas = {str(k): check_sigma(v, f"sigmas[{k!r}]") for k, v in (sigmas or {}).items()}
    sample = np.arange(len(qs))
    values = {k: np.asarray(v, dtype=float) for k, v in (unknowns or {}).items()}

    # templates: what is observed, at which samples (the kinds fill in the values)
    templates: list[Any] = [
        PoseObservations(
            frame=frame, sample=sample, meas_T_frame=np.tile(np.eye(4), (len(qs), 1, 1))
        )
        for frame in frames
    ]
    if cameras:
        values[BlockKey("target", "target")] = (
            default_target_pose(robot, qs, names, cameras)
            if w_T_target is None
            else check_transform(w_T_target, name="w_T_target")
        )
        templates += [
            TargetObservations(
                camera=camera, sample=sample, camera_T_target=np.tile(np.eye(4), (len(qs), 1, 1))
            )
            for camera in cameras
        ]
    for marker in markers:
        frame, offset, name = _marker_spec(marker)
        if name is not None:
            values[offset_key(frame, name)] = offset
        templates.append(
            PointObservations(
                frame=frame,
                sample=sample,
                meas_p_point=np.zeros((len(qs), 3)),
                offset=offset if name is None else None,
                marker=name,
            )
        )
    for g in groups:
        kind_of(g)  # a registered kind's group, else TypeError
        if len(g.sample) and g.sample.max() >= len(qs):
            raise ValueError(
                f"simulate: groups: {g!r} refers to sample "
                f"{int(g.sample.max())}, but qs has {len(qs)} rows"
            )
    truth = NumericContext.from_robot(robot, qs, names, values)

    out = []
    for g in (*templates, *groups):
        kind = kind_of(g)
        try:
            if stereo_sigma_m is not None and isinstance(g, PoseObservations):
                predicted = kind.with_data(g, kind.predict(g, truth))
                out.append(
                    replace(
                        g, meas_T_frame=stereo_measure(predicted.meas_T_frame, rng, stereo_sigma_m)
                    )
                )
                continue
            default = {"m": noise_m, "rad": noise_rad}
            noise = {c.name: sigmas.get(c.name, default.get(c.unit, 0.0)) for c in kind.components}
            out.append(kind.simulate(g, truth, rng, noise))
        except MissingValue as exc:
            raise ValueError(
                f"simulate: {g!r} needs the true value of {exc.key}; give it in unknowns"
            ) from None
    return Measurements(joint_names=names, qs=qs, source="<simulated>").with_groups(out)


def _marker_spec(marker: Sequence[Any]) -> tuple[str, NDArray[np.float64], str | None]:
    """``(frame, offset (3,), name or None)`` of a marker given as a 2- or 3-tuple."""
    if isinstance(marker, str) or len(marker) not in (2, 3):
        raise ValueError(
            f"markers: expected (frame, offset) or (frame, offset, name), got {marker!r}"
        )
    frame, offset = marker[0], np.asarray(marker[1], dtype=float)
    name = marker[2] if len(marker) == 3 else None
    if offset.shape != (3,) or not np.isfinite(offset).all():
        raise ValueError(
            f"markers: offset of a marker on {frame!r}: expected 3 finite "
            f"numbers, got {marker[1]!r}"
        )
    return str(frame), offset, name


# -- pixels: a board seen by cameras on the robot -------------------------------------

#: Default intrinsics of a simulated camera with none given: a plausible 640 x 480 VGA
#: camera with a ~56 deg horizontal field of view (fx = fy = 600 px), principal point at
#: the image centre, no distortion.
DEFAULT_CAMERA = CameraIntrinsics(640, 480, 600.0, 600.0, 319.5, 239.5, name="simulated")
#: Default board of ``kinfw simulate --pixels``: 9 x 6 inner corners, 40 mm squares.
DEFAULT_BOARD = "chessboard:9x6:0.04"
#: A point is seen when it is in front of the camera, within this angle of the optical
#: axis and at least :data:`VIEW_MARGIN_PX` inside the image.
MAX_POINT_ANGLE_DEG = 60.0
VIEW_MARGIN_PX = 5.0
#: A whole image is dropped when the line of sight to the board's centre makes more than
#: this angle with the board's normal (a board seen edge-on, or from behind) ...
MAX_BOARD_ANGLE_DEG = 70.0
#: ... or when fewer than this many of its corners are seen (PnP needs 4; a chessboard,
#: which OpenCV finds only whole, needs all of them: ``min_corners=board.count``) ...
MIN_CORNERS = 4
#: ... or when the seen corners are (nearly) on one line: the second singular value of
#: their centred positions is below this fraction of the first.
MIN_SPREAD = 0.1


def default_intrinsics(camera: str) -> CameraIntrinsics:
    """:data:`DEFAULT_CAMERA` named after the camera frame ``camera``."""
    return replace(DEFAULT_CAMERA, name=str(camera))


def board_pose_facing(
    robot: Robot,
    q: ArrayLike,
    joint_names: Sequence[str] | None,
    cameras: Sequence[str],
    board_p: ArrayLike,
    distance: float = 0.8,
) -> NDArray[np.float64]:
    """A board pose ``w_T_board`` in front of the cameras at one configuration ``q``.

    The centre of the board's points is ``distance`` metres along the cameras' mean
    optical axis (z) from their mean position; the board's z axis is that axis (a
    :mod:`kinfw.boards` board's z points away from the camera that sees its printed face),
    its x axis the mean camera x axis made perpendicular to it.

    Parameters
    ----------
    robot : Robot
    q : array_like, shape (k,)
        Joint values in ``joint_names`` order (rad, m).
    joint_names : sequence of str or None
    cameras : sequence of str
        Camera optical frames (z forward, x right, y down).
    board_p : array_like, shape (m, 3)
        The board's points in its frame, metres.
    distance : float
        Metres.

    Returns
    -------
    w_T_board : ndarray, shape (4, 4)
    """
    board_p = np.asarray(board_p, dtype=float)
    w_T_centre = default_target_pose(robot, np.atleast_2d(q), joint_names, cameras, distance)
    # default_target_pose's z points back at the cameras: turn about x (z -> -z, y -> -y)
    w_T_centre = w_T_centre @ np.diag([1.0, -1.0, -1.0, 1.0])
    return w_T_centre @ transform_from_rotation_translation(np.eye(3), -board_p.mean(axis=0))


def visible_points(
    intrinsics: CameraIntrinsics,
    camera_T_board: ArrayLike,
    board_p: ArrayLike,
    *,
    margin_px: float = VIEW_MARGIN_PX,
    max_point_angle_deg: float = MAX_POINT_ANGLE_DEG,
    max_board_angle_deg: float = MAX_BOARD_ANGLE_DEG,
    min_corners: int = MIN_CORNERS,
) -> NDArray[np.bool_]:
    """Which board points each image sees.

    A point is seen when :meth:`~kinfw.camera_model.CameraIntrinsics.in_view` says so
    (in front of the camera, within ``max_point_angle_deg`` of the optical axis, inside
    the image at least ``margin_px`` from its border). An image sees nothing when the
    line of sight from the camera to the centre of the board's points makes more than
    ``max_board_angle_deg`` with the board's normal (edge-on, or seen from behind: the
    printed face is the one whose normal, board -z, points at the camera), or when it
    sees fewer than ``min_corners`` points, or its seen points are nearly on one line
    (:data:`MIN_SPREAD`).

    Parameters
    ----------
    intrinsics : CameraIntrinsics
    camera_T_board : array_like, shape (n, 4, 4)
        Board poses in the camera's optical frame, metres.
    board_p : array_like, shape (m, 3)
        Board points in the board frame, metres.

    Returns
    -------
    ndarray of bool, shape (n, m)
    """
    c_T_b = np.asarray(camera_T_board, dtype=float).reshape(-1, 4, 4)
    board_p = np.asarray(board_p, dtype=float)
    c_p = np.einsum("nij,kj->nki", c_T_b[:, :3, :3], board_p) + c_T_b[:, None, :3, 3]
    seen = intrinsics.in_view(c_p, margin_px=margin_px, max_angle_deg=max_point_angle_deg)
    centre = c_T_b[:, :3, :3] @ board_p.mean(axis=0) + c_T_b[:, :3, 3]
    sight = centre / np.linalg.norm(centre, axis=1, keepdims=True)
    # the printed face looks along board -z: towards the camera when sight . z_board > 0
    cos_angle = np.einsum("ni,ni->n", sight, c_T_b[:, :3, 2])
    facing = cos_angle >= np.cos(np.radians(max_board_angle_deg))
    keep = facing & (seen.sum(axis=1) >= max(int(min_corners), 3))
    for i in np.flatnonzero(keep):  # PnP needs points off one line
        p = board_p[seen[i]] - board_p[seen[i]].mean(axis=0)
        sv = np.linalg.svd(p, compute_uv=False)
        keep[i] = sv[1] > MIN_SPREAD * sv[0]
    return seen & keep[:, None]


def simulate_pixels(
    robot: Robot,
    qs: ArrayLike,
    joint_names: Sequence[str] | None,
    *,
    cameras: Mapping[str, CameraIntrinsics],
    board_p: ArrayLike,
    w_T_board: ArrayLike,
    rng: np.random.Generator,
    sigma_px: float = 0.0,
    target: str = "board",
    point_ids: ArrayLike | None = None,
    **visibility: float,
) -> tuple[Measurements, NDArray[np.int64]]:
    """``pixels`` observations of a fixed board by cameras on the robot.

    Each camera's image of the board at each configuration: the board's points seen
    (:func:`visible_points`), projected through the true robot by the ``pixels`` kind
    (:meth:`kinfw.observations.pixels.PixelKind.simulate`), plus independent Gaussian
    noise ``N(0, sigma_px^2)`` on each pixel coordinate.

    Parameters
    ----------
    robot : Robot
        The true robot.
    qs : array_like, shape (n, k)
        Joint values (rad, m) in ``joint_names`` order.
    joint_names : sequence of str or None
    cameras : mapping of str to CameraIntrinsics
        Camera optical frames and their intrinsics.
    board_p : array_like, shape (m, 3)
        The board's points in its frame, metres.
    w_T_board : array_like, shape (4, 4)
        The board's true pose in the root frame ``w``.
    rng : numpy.random.Generator
    sigma_px : float
        Pixel noise per coordinate, px.
    target : str
        The board's target name.
    point_ids : array_like of int, shape (m,), optional
        The points' ids (default ``0 .. m-1``).
    **visibility
        ``margin_px``, ``max_point_angle_deg``, ``max_board_angle_deg``,
        ``min_corners`` of :func:`visible_points`.

    Returns
    -------
    data : Measurements
        Only the configurations where at least one camera sees the board (images
        labelled ``"<camera>_<sample>"``), with the cameras' intrinsics.
    kept : ndarray of int64
        Row of ``qs`` of each of ``data``'s samples.
    """
    from kinfw.observations.pixels import PixelObservations

    names = tuple(robot.joint_names if joint_names is None else joint_names)
    qs = np.atleast_2d(np.asarray(qs, dtype=float))
    board_p = np.asarray(board_p, dtype=float)
    w_T_board = check_transform(w_T_board, name="w_T_board")
    sigma_px = check_sigma(sigma_px, "sigma_px")
    ids = np.arange(len(board_p)) if point_ids is None else np.asarray(point_ids, np.int64)
    masks = {
        camera: visible_points(
            intr,
            inverse_transform(robot.frame_poses(qs, camera, names)) @ w_T_board,
            board_p,
            **visibility,
        )
        for camera, intr in cameras.items()
    }
    kept = np.flatnonzero(np.any([m.any(axis=1) for m in masks.values()], axis=0))
    if not len(kept):
        raise ValueError(
            f"simulate_pixels: no camera ({', '.join(cameras)}) sees the board at any of "
            f"the {len(qs)} configurations"
        )
    templates = []
    for camera, mask in masks.items():
        mask = mask[kept]
        sample, point = np.nonzero(mask)
        if not len(sample):
            continue
        templates.append(
            PixelObservations(
                camera=camera,
                intrinsics=cameras[camera],
                sample=sample,
                uv=np.zeros((len(sample), 2)),
                target_p=board_p[point],
                point_id=ids[point],
                shot=np.zeros(len(sample), np.int64),
                image=np.array([f"{camera}_{int(kept[s]):03d}" for s in sample], dtype=object),
                sigma_px=np.full(len(sample), np.nan),
                target=target,
            )
        )
    data = simulate(
        robot,
        qs[kept],
        names,
        groups=templates,
        unknowns={BlockKey("target", target): w_T_board},
        rng=rng,
        sigmas={"pixel": sigma_px},
    )
    return data.with_cameras(dict(cameras)), kept


def pixel_views(
    robot: Robot,
    joint_names: Sequence[str],
    lower: ArrayLike,
    upper: ArrayLike,
    n: int,
    rng: np.random.Generator,
    *,
    cameras: Mapping[str, CameraIntrinsics],
    board_p: ArrayLike,
    sigma_px: float,
    fraction: float = 0.8,
    w_T_board: ArrayLike | None = None,
    target: str = "board",
    distance: float = 0.8,
    max_rounds: int = 50,
    min_corners: int = MIN_CORNERS,
) -> tuple[Measurements, NDArray[np.float64]]:
    """``n`` random configurations at which some camera sees a fixed board, and the
    images (:func:`simulate_pixels`).

    Configurations are drawn by :func:`random_configurations` (``fraction`` of each
    joint range), ``2 n`` at a time, and kept when at least one camera sees the board
    (:func:`visible_points`), in draw order, until ``n`` are kept.

    Parameters
    ----------
    robot : Robot
        The true robot.
    joint_names : sequence of str
    lower, upper : array_like, shape (k,)
        Joint limits in ``joint_names`` order.
    n : int
        Configurations wanted.
    rng : numpy.random.Generator
    cameras : mapping of str to CameraIntrinsics
    board_p : array_like, shape (m, 3)
        The board's points in its frame, metres.
    sigma_px : float
        Pixel noise per coordinate, px.
    fraction : float
    w_T_board : array_like, shape (4, 4), optional
        The board's pose; default :func:`board_pose_facing` at the middle of the
        joint ranges, ``distance`` metres away.
    min_corners : int
        Fewest corners an image must see (:func:`visible_points`).

    Returns
    -------
    data : Measurements
    w_T_board : ndarray, shape (4, 4)

    Raises
    ------
    ValueError
        When fewer than ``n`` of ``2 n max_rounds`` draws see the board.
    """
    names = tuple(joint_names)
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    board_p = np.asarray(board_p, dtype=float)
    if w_T_board is None:
        w_T_board = board_pose_facing(
            robot, 0.5 * (lower + upper), names, tuple(cameras), board_p, distance
        )
    w_T_board = check_transform(w_T_board, name="w_T_board")
    found: list[NDArray[np.float64]] = []
    count = 0
    for _ in range(max_rounds):
        qs = random_configurations(lower, upper, 2 * n, rng, fraction=fraction)
        seen = np.zeros(len(qs), bool)
        for camera, intr in cameras.items():
            c_T_b = inverse_transform(robot.frame_poses(qs, camera, names)) @ w_T_board
            seen |= visible_points(intr, c_T_b, board_p, min_corners=min_corners).any(axis=1)
        found.append(qs[seen])
        count += int(seen.sum())
        if count >= n:
            break
    else:
        raise ValueError(
            f"pixel_views: the cameras {list(cameras)} see the board in only {count} of "
            f"{2 * n * max_rounds} random configurations; {n} wanted"
        )
    qs = np.concatenate(found)[:n]
    data, _ = simulate_pixels(
        robot,
        qs,
        names,
        cameras=cameras,
        board_p=board_p,
        w_T_board=w_T_board,
        rng=rng,
        sigma_px=sigma_px,
        target=target,
        min_corners=min_corners,
    )
    return data, w_T_board
