"""A whole simulated calibration experiment, as ``kinfw simulate`` and
:func:`kinfw.simulate` make it: the nominal robot perturbed into a "true" one, then its
measurements (stage 1: poses of frames, one joint at a time; stage 2: camera observations
of a fixed target, or images of a board, at random configurations; or both stages at
given configurations, a plan's).

Every random draw comes from one generator seeded by ``seed``, in a fixed order (the
truth, stage 1, stage 2), so a seed reproduces the experiment exactly.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.camera import Board, CameraIntrinsics, parse_board
from kinfw.measurements import Measurements, concatenate_measurements
from kinfw.model import Robot, check_robot, load_robot
from kinfw.simulation._perturb import one_joint_at_a_time, perturb_robot, random_configurations
from kinfw.simulation._pixels import (
    DEFAULT_BOARD,
    MIN_CORNERS,
    board_pose_facing,
    default_intrinsics,
    pixel_views,
    simulate_pixels,
)
from kinfw.simulation._simulate import default_target_pose, simulate

__all__ = ["SimulatedMeasurements", "simulate_measurements"]


@dataclass(frozen=True, slots=True, eq=False)
class SimulatedMeasurements:
    """The true robot and its simulated measurements (:func:`simulate_measurements`).

    Attributes
    ----------
    truth_xml : str
        The true robot's URDF (the nominal with random errors of its joint origins and
        axes; every float written with ``repr``).
    truth : Robot
        The same, loaded.
    data : Measurements
        The measurements: stage 1 then stage 2.
    joint_names : tuple of str
        The joints on the paths to the frames and cameras (the order of
        ``configurations``).
    frames, cameras : tuple of str
        Stage 1 frames and stage 2 cameras simulated (empty for a stage not simulated).
    board : str or None
        With ``pixels``: the board's spec (:func:`kinfw.camera.parse_board`).
    default_cameras : tuple of str
        With ``pixels``: the cameras given no intrinsics, simulated with
        :func:`kinfw.simulation.default_intrinsics`.
    """

    truth_xml: str
    truth: Robot
    data: Measurements
    joint_names: tuple[str, ...]
    frames: tuple[str, ...]
    cameras: tuple[str, ...]
    board: str | None = None
    default_cameras: tuple[str, ...] = ()


def _observed(
    nominal: Robot,
    stages: tuple[int, ...],
    frames: Sequence[str] | None,
    cameras: Sequence[str] | None,
) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The stage 1 frames and stage 2 cameras: the given ones, else the URDF's hints,
    for the stages simulated; ValueError when a stage has none."""
    out = []
    for stage, given, hint, name in (
        (1, frames, nominal.default_frames, "frames"),
        (2, cameras, nominal.default_cameras, "cameras"),
    ):
        chosen = () if stage not in stages else tuple(hint if given is None else given)
        if stage in stages and not chosen:
            raise ValueError(
                f"{nominal.source}: give the stage {stage} {name}; this URDF has no "
                f'<kinfw {name}="..."/> hint. Links: {", ".join(nominal.link_names)}'
            )
        out.append(chosen)
    return out[0], out[1]


def _stage2(
    truth: Robot,
    cameras: tuple[str, ...],
    names: tuple[str, ...],
    limits: tuple[NDArray[np.float64], NDArray[np.float64]],
    rng: np.random.Generator,
    planned: NDArray[np.float64] | None,
    *,
    noise: dict[str, float],
    board: Board | None,
    intrinsics: dict[str, CameraIntrinsics],
    pixel_sigma: float,
    stage2_samples: int,
    fraction: float,
) -> Measurements:
    """Stage 2: ``cameras`` see a fixed target (its pose, ``camera_T_target``), or with a
    ``board`` the board's points in images (cameras with ``intrinsics``), at the
    ``planned`` configurations, else at random ones within ``limits`` (``(lower,
    upper)``); images where no camera sees the board are dropped (planned) or drawn
    again (random)."""
    lower, upper = limits
    if board is None:
        qs = planned
        if qs is None:
            qs = random_configurations(lower, upper, stage2_samples, rng, fraction=fraction)
        w_T_target = default_target_pose(truth, qs, names, cameras)
        return simulate(truth, qs, names, cameras=cameras, rng=rng, w_T_target=w_T_target, **noise)
    min_corners = MIN_CORNERS if board.partial else board.count
    if planned is not None:
        w_T_board = board_pose_facing(truth, 0.5 * (lower + upper), names, cameras, board.points)
        data, _ = simulate_pixels(
            truth,
            planned,
            names,
            cameras=intrinsics,
            board_p=board.points,
            w_T_board=w_T_board,
            rng=rng,
            sigma_px=pixel_sigma,
            min_corners=min_corners,
        )
        return data
    data, _ = pixel_views(
        truth,
        names,
        lower,
        upper,
        stage2_samples,
        rng,
        cameras=intrinsics,
        board_p=board.points,
        sigma_px=pixel_sigma,
        fraction=fraction,
        min_corners=min_corners,
    )
    return data


def simulate_measurements(
    nominal: Robot,
    *,
    stages: tuple[int, ...] | None = None,
    frames: Sequence[str] | None = None,
    cameras: Sequence[str] | None = None,
    per_joint: int = 9,
    stage2_samples: int = 30,
    fraction: float = 0.8,
    noise_m: float = 5e-4,
    noise_rad: float = float(np.radians(0.5)),
    stereo_sigma_m: float | None = None,
    error_mm: float = 2.0,
    error_deg: float = 0.5,
    pixels: bool = False,
    pixel_sigma: float = 0.5,
    board: str | None = None,
    intrinsics: Mapping[str, CameraIntrinsics] | None = None,
    configurations: ArrayLike | None = None,
    seed: int = 0,
) -> SimulatedMeasurements:
    """Perturb ``nominal`` into a true robot and simulate its measurements, as
    ``kinfw simulate`` does (the same defaults): :func:`kinfw.simulate`.

    Parameters
    ----------
    nominal : Robot
        The nominal robot (:func:`kinfw.load_robot`).
    stages : tuple of int, optional
        ``(1,)``, ``(2,)`` or ``(1, 2)``; default ``(1,)``, with ``pixels`` ``(1, 2)``.
    frames, cameras : sequence of str, optional
        Stage 1 frames and stage 2 camera frames; default the URDF's ``<kinfw>`` hints.
    per_joint : int
        Stage 1: values per joint, one joint at a time (Shih et al. section 4.1).
    stage2_samples : int
        Stage 2: random configurations.
    fraction : float
        The centred fraction of each joint range used.
    noise_m, noise_rad : float
        Pose noise: sigma per axis (m) and of the angle about a random axis (rad).
    stereo_sigma_m : float, optional
        Simulate the stereo rig instead for stage 1: point noise on the nine-circle
        plate (m).
    error_mm, error_deg : float
        The true robot's errors: joint origins (mm; deg) and axes (deg), sigmas
        (:func:`kinfw.simulation.perturb_robot`).
    pixels : bool
        Stage 2 as images of ``board`` (``pixels`` observations) with pixel noise
        ``pixel_sigma`` (px) per image coordinate.
    board : str, optional
        With ``pixels``: the board spec (default :data:`DEFAULT_BOARD`).
    intrinsics : mapping of str to CameraIntrinsics, optional
        With ``pixels``: per camera; default :func:`default_intrinsics`.
    configurations : array_like, shape (n, J), optional
        Measure both stages at these configurations, in order (a plan's), columns in
        the order of ``nominal.topology(frames + cameras).joint_names``
        (:attr:`SimulatedMeasurements.joint_names`), rad/m; default one joint at a time
        (stage 1) and random (stage 2).
    seed : int
        Seeds the one generator of every draw.

    Returns
    -------
    SimulatedMeasurements

    Raises
    ------
    TypeError
        ``nominal`` is not a Robot (naming it).
    ValueError
        ``pixels`` without stage 2, a stage with no frames or cameras, intrinsics of a
        frame that is not a stage 2 camera.
    """
    nominal = check_robot(nominal, "nominal")
    stages = ((1, 2) if pixels else (1,)) if stages is None else tuple(stages)
    if pixels and 2 not in stages:
        raise ValueError(f"pixels: stage 2 makes the images; got stages {stages}")
    frames, cameras = _observed(nominal, stages, frames, cameras)
    given = dict(intrinsics or {})
    if set(given) - set(cameras):
        raise ValueError(
            f"intrinsics of {sorted(set(given) - set(cameras))}: not stage 2 cameras "
            f"(cameras: {', '.join(cameras)})"
        )
    rng = np.random.default_rng(seed)
    truth_xml = perturb_robot(
        nominal, rng, origin_mm=error_mm, origin_deg=error_deg, axis_deg=error_deg
    )
    truth = load_robot(truth_xml)
    names = nominal.topology((*frames, *cameras)).joint_names
    lower, upper = nominal.joint_limits(names)
    noise = {"noise_m": noise_m, "noise_rad": noise_rad}
    if stereo_sigma_m is not None:
        noise["stereo_sigma_m"] = stereo_sigma_m
    planned = None if configurations is None else np.asarray(configurations, dtype=float)
    parts = []
    if frames:
        qs = planned
        if qs is None:
            qs, _ = one_joint_at_a_time(lower, upper, per_joint=per_joint, fraction=fraction)
        parts.append(simulate(truth, qs, names, frames=frames, rng=rng, **noise))
    shown = parse_board(board or DEFAULT_BOARD) if cameras and pixels else None
    if cameras:
        parts.append(
            _stage2(
                truth,
                cameras,
                names,
                (lower, upper),
                rng,
                planned,
                noise=noise,
                board=shown,
                intrinsics={c: given.get(c) or default_intrinsics(c) for c in cameras},
                pixel_sigma=pixel_sigma,
                stage2_samples=stage2_samples,
                fraction=fraction,
            )
        )
    return SimulatedMeasurements(
        truth_xml,
        truth,
        concatenate_measurements(*parts),
        names,
        frames,
        cameras,
        board=None if shown is None else shown.spec(),
        default_cameras=tuple(sorted(set(cameras) - set(given))) if shown is not None else (),
    )
