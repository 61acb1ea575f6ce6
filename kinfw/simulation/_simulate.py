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
  (:func:`simulate_at`); images of a board in pixels are :mod:`kinfw.simulation`.

Every random draw comes from a ``numpy.random.Generator`` passed in by the caller; no
global random state is used, so a seed reproduces a study exactly.

:func:`perturb_robot`, :func:`one_joint_at_a_time` and :func:`random_configurations`
live in :mod:`kinfw.simulation` and are re-exported here (most callers import them
from this module).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import check_transform, register_points, transform_from_rotation_translation
from kinfw.measurements import Measurements
from kinfw.model import BlockKey, Robot
from kinfw.observations import (
    MissingValue,
    NumericContext,
    PointObservations,
    PoseObservations,
    TargetObservations,
    kind_of,
    offset_key,
    perturb_transforms,
)
from kinfw.simulation._perturb import (
    check_sigma,
)

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
    w_p_target = w_T_cams[:, :3, 3].mean(axis=0) + float(distance) * mean_z
    return frame_from_z_and_x(-mean_z, w_T_cams[:, :3, 0].mean(axis=0), w_p_target)


def frame_from_z_and_x(
    z: NDArray[np.float64], x: NDArray[np.float64], origin: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The frame at ``origin`` with z along ``z`` and x along ``x`` made perpendicular
    to it (any perpendicular when ``x`` is parallel to ``z``)."""
    z = z / np.linalg.norm(z)
    x = x - (x @ z) * z
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, np.eye(3)[np.argmin(np.abs(z))])
    x = x / np.linalg.norm(x)
    return transform_from_rotation_translation(np.column_stack([x, np.cross(z, x), z]), origin)


def simulate_at(
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
    (:meth:`kinfw.observations.ObservationKind.simulate`: its numpy prediction plus
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
    values = {k: np.asarray(v, dtype=float) for k, v in (unknowns or {}).items()}
    templates = _templates(robot, qs, names, frames, cameras, markers, w_T_target, values)
    _check_groups(groups, len(qs))
    truth = NumericContext.from_robot(robot, qs, names, values)
    default = {"m": noise_m, "rad": noise_rad}
    out = [
        _simulate_group(g, truth, rng, stereo_sigma_m, sigmas, default)
        for g in (*templates, *groups)
    ]
    return Measurements(joint_names=names, qs=qs, source="<simulated>").with_groups(out)


def _templates(
    robot: Robot,
    qs: NDArray[np.float64],
    names: tuple[str, ...],
    frames: tuple[str, ...],
    cameras: tuple[str, ...],
    markers: tuple[tuple[Any, ...], ...],
    w_T_target: ArrayLike | None,
    values: dict[BlockKey, NDArray[np.float64]],
) -> list[Any]:
    """Groups saying what is observed at every sample (the kinds fill in the values).

    Adds the true target pose and the unknown marker offsets to ``values``.
    """
    sample = np.arange(len(qs))
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
    return templates


def _check_groups(groups: tuple[Any, ...], n: int) -> None:
    """Raise unless every group is of a registered kind and its samples are among ``n``."""
    for g in groups:
        kind_of(g)  # a registered kind's group, else TypeError
        if len(g.sample) and g.sample.max() >= n:
            raise ValueError(
                f"simulate: groups: {g!r} refers to sample "
                f"{int(g.sample.max())}, but qs has {n} rows"
            )


def _simulate_group(
    g: Any,
    truth: NumericContext,
    rng: np.random.Generator,
    stereo_sigma_m: float | None,
    sigmas: Mapping[str, float],
    default: Mapping[str, float],
) -> Any:
    """Group ``g`` with simulated measurements (stereo rig for poses if ``stereo_sigma_m``).

    Each noise component takes ``sigmas[name]``, else ``default[unit]``, else 0.
    """
    kind = kind_of(g)
    try:
        if stereo_sigma_m is not None and isinstance(g, PoseObservations):
            predicted = kind.with_data(g, kind.predict(g, truth))
            return replace(
                g, meas_T_frame=stereo_measure(predicted.meas_T_frame, rng, stereo_sigma_m)
            )
        noise = {c.name: sigmas.get(c.name, default.get(c.unit, 0.0)) for c in kind.components}
        return kind.simulate(g, truth, rng, noise)
    except MissingValue as exc:
        raise ValueError(
            f"simulate: {g!r} needs the true value of {exc.key}; give it in unknowns"
        ) from None


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
