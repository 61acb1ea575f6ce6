"""Pixels against PnP poses on the same images, and the Cramér-Rao bound of the pixel path.

One trial (:func:`pixel_trial`): a true robot (the nominal with random geometric errors),
a fixed chessboard, cameras on the robot that see it at random configurations
(:func:`kinfw.simulation.pixel_views`; the exact projection plus Gaussian pixel
noise, or with ``images=True`` rendered images and ``kinfw.camera``'s corners), and the
calibration of the same detections two ways (:func:`kinfw.identification.identify`,
linear loss, noise estimated):

- ``pixels``: the joint refinement on reprojection error (``pixels`` observations);
- ``pnp``: each image's PnP pose as a ``target`` observation
  (:func:`kinfw.observations.target_observations_from_pixels`), the pose path.

The score (:func:`camera_target_errors`): the error of ``camera_T_target`` (the board in each
camera) at fresh configurations against the true robot, position (m) and rotation (rad,
the angle of ``R_est^T R_true``), mean squares over configurations and cameras.

The bound (:func:`crlb_held_out`): the least-squares problem built around the truth
(:func:`kinfw.identification.problem.build_problem` with ``start = truth``), its Fisher
information ``J^T J`` whitened by the true noise, ``C`` its (pseudo-)inverse, and the
predicted mean squares ``mean trace(G C G^T)`` with ``G`` the Jacobian (central
differences) of the held-out ``camera_T_target`` (position, and rotation vector) with
respect to the free parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from kinfw.camera import CameraIntrinsics, Chessboard
from kinfw.geometry import inverse_transform, rotation_angle
from kinfw.identification.problem import NoiseModel, build_problem
from kinfw.measurements import Measurements, concatenate_measurements
from kinfw.model import Robot, load_robot
from kinfw.observations import target_observations_from_pixels
from kinfw.simulation import (
    default_intrinsics,
    one_joint_at_a_time,
    perturb_robot,
    pixel_views,
    random_configurations,
    simulate_at,
)


@dataclass(frozen=True)
class PixelExperiment:
    """One simulated experiment with images.

    Attributes
    ----------
    nominal, truth : Robot
    data : Measurements
        The calibration data (``pixels`` of the cameras; stage 1 poses for the head).
    cameras : tuple of str
    names : tuple of str
        Joint order of ``data`` and ``q_test``.
    w_T_board : ndarray, shape (4, 4)
        The board's true pose in the root frame.
    q_test : ndarray, shape (n, k)
        Fresh configurations of the held-out score.
    noise : NoiseModel
        The true noise (``pixel`` in px; ``position``/``rotation`` of stage 1 poses).
    """

    nominal: Robot
    truth: Robot
    data: Measurements
    cameras: tuple[str, ...]
    names: tuple[str, ...]
    w_T_board: NDArray[np.float64]
    q_test: NDArray[np.float64]
    noise: NoiseModel


def head_experiment(
    nominal: Robot,
    seed: int,
    *,
    sigma_px: float = 0.5,
    board: Chessboard,
    n_images: int = 30,
    n_test: int = 100,
    noise_mm: float = 0.5,
    noise_deg: float = 0.5,
) -> PixelExperiment:
    """The IIS-head demo with stage 2 from images (as ``kinfw demo --pixels``): stage 1
    plate poses one joint at a time, stage 2 the board seen by both cameras (default
    intrinsics) at ``n_images`` random configurations where one sees it."""
    rng = np.random.default_rng(seed)
    truth = load_robot(perturb_robot(nominal, rng, origin_mm=5.0, origin_deg=1.0, axis_deg=1.0))
    plates, cameras = nominal.default_frames, nominal.default_cameras
    names = nominal.topology((*plates, *cameras)).joint_names
    lower, upper = nominal.joint_limits(names)
    noise = {"noise_m": noise_mm * 1e-3, "noise_rad": np.radians(noise_deg)}
    qs1, _ = one_joint_at_a_time(lower, upper, per_joint=9, fraction=0.8)
    stage1 = simulate_at(truth, qs1, names, frames=plates, rng=rng, **noise)
    intrinsics = {c: default_intrinsics(c) for c in cameras}
    stage2, w_T_board = pixel_views(
        truth,
        names,
        lower,
        upper,
        n_images,
        rng,
        cameras=intrinsics,
        board_p=board.points,
        sigma_px=sigma_px,
        min_corners=board.count,
    )
    q_test = random_configurations(lower, upper, n_test, rng, fraction=0.8)
    true_noise = NoiseModel(
        noise_mm * 1e-3, np.radians(noise_deg) / np.sqrt(3.0), sigmas={"pixel": sigma_px}
    )
    return PixelExperiment(
        nominal,
        truth,
        concatenate_measurements(stage1, stage2),
        tuple(cameras),
        tuple(names),
        w_T_board,
        q_test,
        true_noise,
    )


def arm_experiment(
    nominal: Robot,
    seed: int,
    *,
    camera: str,
    intrinsics: CameraIntrinsics,
    q0: NDArray[np.float64],
    board: Chessboard,
    sigma_px: float = 0.5,
    spread_rad: float = 0.35,
    distance: float = 0.6,
    n_images: int = 25,
    n_test: int = 100,
) -> PixelExperiment:
    """An arm with a flange camera ``camera`` that sees a fixed board: the board
    ``distance`` metres in front of the camera at ``q0`` (facing it), configurations
    ``q0 + U(-spread_rad, spread_rad)`` per joint where the camera sees the whole board
    (``n_images`` of them), held-out configurations from the same box; the true robot
    has 2 mm / 0.5 deg errors (:func:`kinfw.simulation.perturb_robot`)."""
    rng = np.random.default_rng(seed)
    truth = load_robot(perturb_robot(nominal, rng))
    names = tuple(nominal.topology((camera,)).joint_names)
    q0 = np.asarray(q0, dtype=float)
    lower, upper = q0 - spread_rad, q0 + spread_rad
    data, w_T_board = pixel_views(
        truth,
        names,
        lower,
        upper,
        n_images,
        rng,
        cameras={camera: intrinsics},
        board_p=board.points,
        sigma_px=sigma_px,
        fraction=1.0,
        distance=distance,
        min_corners=board.count,
    )
    q_test = random_configurations(lower, upper, n_test, rng, fraction=1.0)
    return PixelExperiment(
        nominal,
        truth,
        data,
        (camera,),
        names,
        w_T_board,
        q_test,
        NoiseModel(sigmas={"pixel": sigma_px}),
    )


def rendered_detections(
    exp: PixelExperiment, board: Chessboard, *, grey_sigma: float = 2.0, seed: int = 0
) -> tuple[PixelExperiment, float]:
    """The experiment's images rendered (:func:`kinfw.simulation.render_board`,
    grey-level noise ``grey_sigma``) and detected (:class:`kinfw.camera.Detector`):
    the ``pixels`` replaced by the detected corners (images not found dropped), and the
    detection error's RMS per coordinate (px) against the exact projection, which is
    the pixel sigma of the returned experiment's noise."""
    from kinfw.camera import Detector
    from kinfw.simulation import render_board

    rng = np.random.default_rng(seed)
    detector = Detector(board)
    groups, errors = [], []
    for g in exp.data.all_groups():
        if getattr(g, "kind", None) != "pixels":
            groups.append(g)
            continue
        samples, rows = g.images()
        c_T_b = (
            inverse_transform(exp.truth.frame_poses(exp.data.qs[samples], g.camera, exp.names))
            @ exp.w_T_board
        )
        keep, uv = [], []
        for r, T in zip(rows, c_T_b, strict=True):
            image = render_board(board, g.intrinsics, T, noise_sigma=grey_sigma, rng=rng)
            found = detector.detect(image)
            if not found.found:
                continue
            exact = g.intrinsics.project(board.points @ T[:3, :3].T + T[:3, 3])
            got = np.full((board.count, 2), np.nan)
            got[found.ids] = found.uv
            ids = g.point_id[r]
            if np.isnan(got[ids]).any():
                continue
            keep.append(r)
            uv.append(got[ids])
            errors.append((got[ids] - exact[ids]).ravel())
        rows_kept = np.concatenate(keep)
        kind_rows = {
            f: getattr(g, f)[rows_kept]
            for f in ("sample", "target_p", "point_id", "shot", "image", "sigma_px")
        }
        groups.append(replace(g, uv=np.concatenate(uv), **kind_rows))
    sigma = float(np.sqrt(np.mean(np.concatenate(errors) ** 2)))
    noise = NoiseModel(
        sigmas={**dict(exp.noise.sigmas), "pixel": sigma},
    )
    return replace(exp, data=exp.data.with_groups(groups), noise=noise), sigma


def pose_path_data(data: Measurements) -> Measurements:
    """The data with every ``pixels`` group replaced by its images' PnP poses (``target``
    observations of the same target)."""
    groups = [
        target_observations_from_pixels(g) if getattr(g, "kind", None) == "pixels" else g
        for g in data.all_groups()
    ]
    return data.with_groups(groups)


def target_pose(unknowns, name: str = "board") -> NDArray[np.float64]:
    """``root_T_target`` of the target ``name`` among a calibration's unknowns."""
    for u in unknowns:
        if u.kind == "target" and u.name == name:
            return np.asarray(u.value, dtype=float)
    raise KeyError(f"no target {name!r} among the unknowns")


def camera_target_errors(
    exp: PixelExperiment, robot: Robot, root_T_board: NDArray[np.float64]
) -> tuple[float, float]:
    """Mean squares of the held-out ``camera_T_target`` errors of a calibration
    (``robot`` and its board pose) against the truth: position (m^2), rotation angle
    (rad^2), over ``exp.q_test`` and the cameras."""
    dp, dr = [], []
    for c in exp.cameras:
        est = inverse_transform(robot.frame_poses(exp.q_test, c, exp.names)) @ root_T_board
        true = inverse_transform(exp.truth.frame_poses(exp.q_test, c, exp.names)) @ exp.w_T_board
        dp.append(np.sum((est[:, :3, 3] - true[:, :3, 3]) ** 2, axis=1))
        dr.append(rotation_angle(np.swapaxes(est[:, :3, :3], -1, -2) @ true[:, :3, :3]) ** 2)
    return float(np.mean(np.concatenate(dp))), float(np.mean(np.concatenate(dr)))


def _camera_T_targets(problem, x, exp: PixelExperiment) -> NDArray[np.float64]:
    """(cameras, n, 6): held-out ``camera_T_target`` at chart coordinates ``x``: the
    position and the rotation vector of ``R_true^T R`` (``R_true`` at ``x = 0``)."""
    model = problem.model_at(x)
    order = [exp.names.index(j) for j in model.topology.joint_names]
    q = exp.q_test[:, order]
    root_T_board = next(
        u.value for u in problem.unknowns_at(x) if u.kind == "target" and u.name == "board"
    )
    return np.stack(
        [inverse_transform(model.frame_poses(q, c)) @ root_T_board for c in exp.cameras]
    )


def _rotvec(R: NDArray[np.float64]) -> NDArray[np.float64]:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(*R.shape[:-2], 3)


def crlb_held_out(
    exp: PixelExperiment, step: float = 1e-7
) -> tuple[float, float, NDArray[np.float64], NDArray[np.float64]]:
    """The Cramér-Rao bound of the held-out ``camera_T_target`` error (module
    docstring).

    Returns
    -------
    position_ms : float
        Predicted mean square position error, m^2.
    rotation_ms : float
        Predicted mean square rotation angle, rad^2.
    covariance : ndarray, shape (cameras, n, 6, 6)
        Bound of each held-out pose's error (position m, rotation vector rad).
    truth : ndarray, shape (cameras, n, 4, 4)
        The true held-out ``camera_T_target`` (the chart's origin).
    """
    problem = build_problem(exp.truth, exp.data, start=exp.truth, targets={"board": exp.w_T_board})
    _, J = problem.evaluate(np.zeros(problem.n_parameters), exp.noise, True)
    free = np.flatnonzero(problem.free)
    info = J[:, free].T @ J[:, free]
    d = np.sqrt(np.clip(np.diag(info), 1e-300, None))
    C = np.linalg.pinv(info / np.outer(d, d), rcond=1e-12, hermitian=True) / np.outer(d, d)
    T0 = _camera_T_targets(problem, np.zeros(problem.n_parameters), exp)
    G = np.empty((*T0.shape[:2], 6, len(free)))
    for k, j in enumerate(free):
        e = np.zeros(problem.n_parameters)
        e[j] = step
        Tp, Tm = _camera_T_targets(problem, e, exp), _camera_T_targets(problem, -e, exp)
        G[..., :3, k] = (Tp[..., :3, 3] - Tm[..., :3, 3]) / (2 * step)
        R0t = np.swapaxes(T0[..., :3, :3], -1, -2)
        G[..., 3:, k] = (_rotvec(R0t @ Tp[..., :3, :3]) - _rotvec(R0t @ Tm[..., :3, :3])) / (
            2 * step
        )
    cov = G @ C @ np.swapaxes(G, -1, -2)
    position_ms = float(np.trace(cov[..., :3, :3], axis1=-2, axis2=-1).mean())
    rotation_ms = float(np.trace(cov[..., 3:, 3:], axis1=-2, axis2=-1).mean())
    return position_ms, rotation_ms, cov, T0


def pose_errors(estimate: NDArray[np.float64], truth: NDArray[np.float64]) -> NDArray[np.float64]:
    """(..., 6): position error (m) and rotation vector of ``R_true^T R_est`` (rad)."""
    R = np.swapaxes(truth[..., :3, :3], -1, -2) @ estimate[..., :3, :3]
    return np.concatenate([estimate[..., :3, 3] - truth[..., :3, 3], _rotvec(R)], axis=-1)
