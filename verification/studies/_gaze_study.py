"""The value of calibration when the model is used (issue 16): a simulated true robot,
calibrated from simulated measurements, then commanded with the nominal and with the
calibrated model; the errors are measured on the true robot. ``kinfw reproduce gaze``.

Head (the built-in IIS head). Each trial runs :func:`kinfw.verification.studies.run_demo` (its
true head: the nominal URDF with 5 mm / 1 deg errors; its data: stage 1 plates one joint
at a time, stage 2 both cameras seeing a fixed target, 0.5 mm / 0.5 deg noise; its
``method="refine"`` calibration) into a temporary directory and reads back
``true.urdf`` and ``calibrated.urdf``. Held-out points (:func:`head_points`): pan and
tilt uniform in the central 80 % of their ranges, the table and vergences at the middle
of theirs, the point on the mean optical axis of the nominal cameras at that
configuration, 0.5-3 m from the cameras' midpoint. Each point is fixated
(:class:`kinfw.control.GazeSolver`, from the middle configuration) by the nominal
and by the calibrated model; at each commanded ``q`` the true head gives, per camera:

- the raw angle between the true optical axis and the point
  (:func:`kinfw.control.ray_errors_rad`): it includes the head's own fixation floor
  (the IIS head cannot fixate one point with both cameras closer than ~4 m, a vertical
  disparity of 1-8 deg at 0.5-2 m that no joint removes);
- the pointing error (:func:`kinfw.verification.studies.pointing_errors_rad`): the angle
  between the direction in which the true camera sees the point and the one the model
  meant (the model's direction of the point in its camera frame at ``q``): the model's
  error alone; equal to the raw angle when the model fixates exactly;
- the triangulation error (:func:`kinfw.verification.studies.triangulation_errors_m`): the
  true rays to the point, in each camera's frame (what the cameras see), put in the root
  frame by the model's camera poses at ``q`` and intersected
  (:func:`kinfw.verification.studies.triangulate`): distance to the point.

Arm (a UR10 from Universal Robots' published DH parameters,
:func:`kinfw.verification.studies.ur10_urdf`). Each trial perturbs it as the demo does
(5 mm / 1 deg), simulates :data:`ARM_POSES` poses of ``tool0`` in random configurations
(central 80 % of the ranges) with 0.5 mm / 0.5 deg noise
(:func:`kinfw.simulation.simulate_at`), calibrates (``method="refine"``), then reaches
held-out ``tool0`` poses of the true arm (:func:`kinfw.control.reach`, starting
0.1 rad from the configuration that made the pose) with each model; the
errors are those of the true arm at the commanded ``q``.
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.model import Robot, builtin_head_urdf, load_robot
from kinfw.verification.evaluation import check_count, run_trials
from kinfw.verification.studies._common import (
    FieldsJSON,
    freeze,
    json_lists,
    run_and_print,
    study_parser,
    write_json,
)
from kinfw.verification.studies._dh_robots import ur10_urdf
from kinfw.verification.studies._gaze_metrics import pointing_errors_rad, triangulation_errors_m

#: Distance of the held-out points from the cameras' midpoint (m).
HEAD_DISTANCE_M = (0.5, 3.0)
#: Calibration poses of the arm, and their noise (mm per axis, deg).
ARM_POSES = 50
ARM_NOISE_MM = 0.5
ARM_NOISE_DEG = 0.5
#: The true robots' errors (as the demo's): origin mm, origin deg, axis deg.
TRUTH_ERRORS = {"origin_mm": 5.0, "origin_deg": 1.0, "axis_deg": 1.0}


# -- the study -----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class GazeSetup(FieldsJSON):
    """What the study ran (module docstring): trials, points and targets per trial,
    the seed, the head's cameras, the held-out distances (m), the arm's calibration
    poses and noise, the true robots' errors."""

    trials: int
    points: int
    targets: int
    seed: int
    cameras: tuple[str, ...]
    distance_min_m: float
    distance_max_m: float
    arm_poses: int
    arm_noise_mm: float
    arm_noise_deg: float
    truth_origin_mm: float
    truth_origin_deg: float
    truth_axis_deg: float


#: Arrays of :class:`GazeStudy` (the dtype of each when read back).
_ARRAYS = (
    "distance_m",
    "axis_rad",
    "pointing_rad",
    "model_error_rad",
    "triangulation_m",
    "fixation_s",
    "arm_position_m",
    "arm_rotation_rad",
    "arm_reached",
)


@dataclass(frozen=True, slots=True)
class GazeStudy:
    """Errors on the true robots when commanded with the nominal (index 0 of the model
    axis) and the calibrated (index 1) model. T trials, P points, C cameras, A targets.

    Attributes
    ----------
    setup : GazeSetup
    distance_m : ndarray, shape (T, P)
        Distance of each held-out point from the cameras' midpoint (m).
    axis_rad : ndarray, shape (T, P, 2, C)
        Raw angle between each true optical axis and the point (rad).
    pointing_rad : ndarray, shape (T, P, 2, C)
        Pointing error (rad, :func:`pointing_errors_rad`).
    model_error_rad : ndarray, shape (T, P, 2, C)
        The remaining angle by the model itself (``Fixation.error_rad``): the fixation
        floor of the head's geometry.
    triangulation_m : ndarray, shape (T, P, 2)
        Triangulation error (m, :func:`triangulation_errors_m`).
    fixation_s : ndarray, shape (T, P)
        Wall time of the calibrated model's ``GazeSolver.fixate`` (s).
    arm_position_m, arm_rotation_rad : ndarray, shape (T, A, 2)
        The true arm's tool0 error at the reached configuration (m, rad).
    arm_reached : ndarray of bool, shape (T, A, 2)
        The model reached the pose (by itself).
    """

    setup: GazeSetup
    distance_m: NDArray[np.float64]
    axis_rad: NDArray[np.float64]
    pointing_rad: NDArray[np.float64]
    model_error_rad: NDArray[np.float64]
    triangulation_m: NDArray[np.float64]
    fixation_s: NDArray[np.float64]
    arm_position_m: NDArray[np.float64]
    arm_rotation_rad: NDArray[np.float64]
    arm_reached: NDArray[np.bool_]

    def summary(self) -> dict[str, Any]:
        """Median and p95 of every error, nominal and calibrated, per camera where it
        applies; in deg, mm and ms."""
        deg, out = np.degrees, {}

        def stats(values: NDArray) -> dict[str, float]:
            v = values.ravel()
            return {"median": float(np.median(v)), "p95": float(np.percentile(v, 95))}

        for m, model in enumerate(("nominal", "calibrated")):
            row: dict[str, Any] = {}
            for c, camera in enumerate(self.setup.cameras):
                row[camera] = {
                    "axis_deg": stats(deg(self.axis_rad[:, :, m, c])),
                    "pointing_deg": stats(deg(self.pointing_rad[:, :, m, c])),
                }
            row["pointing_deg_all_cameras"] = stats(deg(self.pointing_rad[:, :, m]))
            row["triangulation_mm"] = stats(1e3 * self.triangulation_m[:, :, m])
            row["arm_position_mm"] = stats(1e3 * self.arm_position_m[:, :, m])
            row["arm_rotation_deg"] = stats(deg(self.arm_rotation_rad[:, :, m]))
            row["arm_reached_fraction"] = float(np.mean(self.arm_reached[:, :, m]))
            out[model] = row
        out["head_fixation_floor_deg"] = stats(deg(self.model_error_rad[:, :, 1]))
        out["fixation_ms_calibrated"] = stats(1e3 * self.fixation_s)
        return out

    def to_dict(self) -> dict[str, Any]:
        """Strict JSON: the set-up, the summary, then every array."""
        return {
            "setup": self.setup.to_dict(),
            "summary": self.summary(),
            **json_lists(self, _ARRAYS, strict=True),
        }


def head_points(
    nominal: Robot, n: int, rng: np.random.Generator, cameras: tuple[str, ...]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Held-out points in front of the head (module docstring).

    Returns
    -------
    root_p_points : ndarray, shape (n, 3)
        Root frame (m).
    distance_m : ndarray, shape (n,)
        From the cameras' midpoint (m).
    """
    from kinfw.control import middle_configuration
    from kinfw.simulation import random_configurations

    lower, upper = nominal.joint_limits()
    qs = np.tile(middle_configuration(nominal), (n, 1))
    aim = [nominal.joint_names.index(j) for j in ("pan", "tilt")]
    qs[:, aim] = random_configurations(lower[aim], upper[aim], n, rng, fraction=0.8)
    root_T = np.stack([nominal.frame_poses(qs, c) for c in cameras], axis=1)  # (n, C, 4, 4)
    axis = root_T[:, :, :3, 2].sum(axis=1)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    distance_m = rng.uniform(*HEAD_DISTANCE_M, size=n)
    return root_T[:, :, :3, 3].mean(axis=1) + distance_m[:, None] * axis, distance_m


def _head_trial(demo_seed: int, n_points: int, point_seed: int) -> dict[str, NDArray]:
    """One head trial (module docstring): the arrays of :class:`GazeStudy` for it."""
    from kinfw.control import GazeSolver, middle_configuration, ray_errors_rad
    from kinfw.verification.studies._demo import run_demo

    nominal = load_robot(builtin_head_urdf())
    cameras = nominal.default_cameras
    with tempfile.TemporaryDirectory(prefix="kinfw-gaze-") as tmp:
        demo = run_demo(tmp, seed=demo_seed)
        truth = load_robot(demo.file("true.urdf"))
        calibrated = load_robot(demo.file("calibrated.urdf"))
    points, distance = head_points(nominal, n_points, np.random.default_rng(point_seed), cameras)
    q_start = middle_configuration(nominal)
    qs = np.empty((2, n_points, len(nominal.joint_names)))
    model_error = np.empty((n_points, 2, len(cameras)))
    seconds = np.empty(n_points)
    for m, model in enumerate((nominal, calibrated)):
        solver = GazeSolver(model, cameras)
        for i, point in enumerate(points):
            start = time.perf_counter()
            fixation = solver.fixate(point, q_start=q_start)
            if m == 1:
                seconds[i] = time.perf_counter() - start
            qs[m, i], model_error[i, m] = fixation.q, fixation.error_rad

    def poses(robot: Robot, q: NDArray) -> NDArray:  # (P, C, 4, 4)
        return np.stack([robot.frame_poses(q, c) for c in cameras], axis=1)

    axis, pointing, triangulation = [], [], []
    for m, model in enumerate((nominal, calibrated)):
        true_T, model_T = poses(truth, qs[m]), poses(model, qs[m])
        rays = np.tile([0.0, 0.0, 1.0], (len(cameras), 1))
        axis.append(ray_errors_rad(true_T, rays, points[:, None, :]))
        pointing.append(pointing_errors_rad(model_T, true_T, points[:, None, :]))
        triangulation.append(triangulation_errors_m(model_T, true_T, points))
    return {
        "distance_m": distance,
        "axis_rad": np.stack(axis, axis=1),
        "pointing_rad": np.stack(pointing, axis=1),
        "model_error_rad": model_error,
        "triangulation_m": np.stack(triangulation, axis=1),
        "fixation_s": seconds,
    }


def _arm_trial(seed: int, n_targets: int) -> dict[str, NDArray]:
    """One arm trial (module docstring): the arm arrays of :class:`GazeStudy`."""
    from kinfw.control import reach
    from kinfw.identification import identify
    from kinfw.simulation import perturb_robot, random_configurations, simulate_at

    rng = np.random.default_rng(seed)
    nominal = Robot(ur10_urdf(), "<ur10>")
    truth = Robot(perturb_robot(nominal, rng, **TRUTH_ERRORS), "<true ur10>")
    lower, upper = nominal.joint_limits()
    qs = random_configurations(lower, upper, ARM_POSES, rng, fraction=0.8)
    noise = {"noise_m": ARM_NOISE_MM * 1e-3, "noise_rad": math.radians(ARM_NOISE_DEG)}
    data = simulate_at(truth, qs, None, frames=("tool0",), rng=rng, **noise)
    calibrated = Robot(identify(nominal, data, method="refine").urdf_xml, "<calibrated ur10>")
    q_targets = random_configurations(lower, upper, n_targets, rng, fraction=0.8)
    root_T_targets = truth.frame_poses(q_targets, "tool0")
    q_starts = q_targets + rng.normal(0.0, 0.1, size=q_targets.shape)
    position = np.empty((n_targets, 2))
    rotation = np.empty((n_targets, 2))
    reached = np.empty((n_targets, 2), dtype=bool)
    for m, model in enumerate((nominal, calibrated)):
        q = np.empty_like(q_targets)
        for i in range(n_targets):
            result = reach(model, "tool0", root_T_targets[i], q_start=q_starts[i])
            q[i], reached[i, m] = result.q, result.reached
        root_T_tool = truth.frame_poses(q, "tool0")
        position[:, m] = np.linalg.norm(root_T_tool[:, :3, 3] - root_T_targets[:, :3, 3], axis=1)
        relative = np.einsum("nji,njk->nik", root_T_targets[:, :3, :3], root_T_tool[:, :3, :3])
        cos = np.clip(0.5 * (np.trace(relative, axis1=1, axis2=2) - 1.0), -1.0, 1.0)
        rotation[:, m] = np.arccos(cos)
    return {"arm_position_m": position, "arm_rotation_rad": rotation, "arm_reached": reached}


def _trial(seed: int, n_points: int, n_targets: int) -> dict[str, NDArray]:
    """Head and arm of one trial; ``seed`` seeds both."""
    demo_seed, point_seed, arm_seed = np.random.SeedSequence(seed).generate_state(3)
    return {
        **_head_trial(int(demo_seed), n_points, int(point_seed)),
        **_arm_trial(int(arm_seed), n_targets),
    }


def gaze_study(
    *,
    trials: int = 10,
    points: int = 100,
    targets: int = 50,
    seed: int = 0,
    executor: Executor | None = None,
) -> GazeStudy:
    """Run the study (module docstring): ``trials`` true heads and arms, ``points``
    held-out points per head and ``targets`` held-out poses per arm.

    Trials run in this process, or as tasks of ``executor``
    (:func:`kinfw.verification.evaluation.run_trials`, which tells :mod:`kinfw.progress`).
    """
    trials = check_count(trials, "trials", 1)
    points = check_count(points, "points", 1)
    targets = check_count(targets, "targets", 1)
    seeds = np.random.SeedSequence(seed).generate_state(trials)
    args = [(int(s), points, targets) for s in seeds]
    results = run_trials(_trial, args, executor=executor)
    arrays = {name: np.stack([r[name] for r in results]) for name in _ARRAYS}
    freeze(*arrays.values())
    setup = GazeSetup(
        trials=trials,
        points=points,
        targets=targets,
        seed=seed,
        cameras=load_robot(builtin_head_urdf()).default_cameras,
        distance_min_m=HEAD_DISTANCE_M[0],
        distance_max_m=HEAD_DISTANCE_M[1],
        arm_poses=ARM_POSES,
        arm_noise_mm=ARM_NOISE_MM,
        arm_noise_deg=ARM_NOISE_DEG,
        truth_origin_mm=TRUTH_ERRORS["origin_mm"],
        truth_origin_deg=TRUTH_ERRORS["origin_deg"],
        truth_axis_deg=TRUTH_ERRORS["axis_deg"],
    )
    return GazeStudy(setup=setup, **arrays)


def count_noun(n: int, noun: str) -> str:
    """``"1 true UR10"``, ``"10 true UR10s"``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def format_gaze(study: GazeStudy) -> str:
    """Markdown table of the study: median / p95 per error, nominal vs calibrated."""
    s, summary = study.setup, study.summary()

    def cell(model: str, *keys: str) -> str:
        value = summary[model]
        for key in keys:
            value = value[key]
        return f"{value['median']:.3g} / {value['p95']:.3g}"

    rows = [(f"{c}: optical axis to point (deg)", (c, "axis_deg")) for c in s.cameras] + [
        (f"{c}: pointing error (deg)", (c, "pointing_deg")) for c in s.cameras
    ]
    rows += [
        ("triangulation error (mm)", ("triangulation_mm",)),
        ("UR10 reach: position error (mm)", ("arm_position_mm",)),
        ("UR10 reach: rotation error (deg)", ("arm_rotation_deg",)),
    ]
    floor, timing = summary["head_fixation_floor_deg"], summary["fixation_ms_calibrated"]
    lines = [
        f"Using the calibration: {count_noun(s.trials, 'true IIS head')} (demo data, refine) "
        f"x {s.points} held-out points at {s.distance_min_m:g}-{s.distance_max_m:g} m; "
        f"{count_noun(s.trials, 'true UR10')} ({s.arm_poses} tool0 poses, "
        f"{s.arm_noise_mm:g} mm / {s.arm_noise_deg:g} deg) x {s.targets} held-out poses. "
        "Errors on the true robot, median / p95.",
        "",
        "| error on the true robot | nominal model | calibrated model |",
        "|---|---:|---:|",
    ]
    lines += [
        f"| {label} | {cell('nominal', *k)} | {cell('calibrated', *k)} |" for label, k in rows
    ]
    lines += [
        "",
        f"Head fixation floor (the calibrated model's own remaining angle, both cameras): "
        f"median {floor['median']:.3g} deg, p95 {floor['p95']:.3g} deg.",
        f"Calibrated GazeSolver.fixate: median {timing['median']:.3g} ms, "
        f"p95 {timing['p95']:.3g} ms per point.",
        "UR10 poses reached by the model itself: nominal "
        f"{100 * summary['nominal']['arm_reached_fraction']:.0f} %, calibrated "
        f"{100 * summary['calibrated']['arm_reached_fraction']:.0f} %.",
    ]
    return "\n".join(lines)


def run_gaze(out_dir: str | Path, **kwargs: Any) -> GazeStudy:
    """Run :func:`gaze_study` (``kwargs``) and write ``gaze.png`` and ``gaze.json`` (strict
    JSON) into ``out_dir``."""
    from kinfw.verification.studies._gaze_plots import plot_gaze

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    study = gaze_study(**kwargs)
    plot_gaze(study, out / "gaze.png")
    write_json(out / "gaze.json", study.to_dict(), allow_nan=False)
    return study


def gaze_study_main(argv: Sequence[str] | None = None) -> int:
    """``kinfw reproduce gaze --out DIR [--trials N] [--seed S] [--jobs J | --executor
    dask://HOST:PORT]``: run the study, write ``gaze.png`` and ``gaze.json``, print the
    table."""
    args = study_parser(
        "kinfw reproduce gaze",
        "The value of calibration in use: a head fixating and an arm reaching with the "
        "nominal vs the calibrated model, errors on the simulated true robot.",
        trials_help="true heads and arms (default 10)",
    ).parse_args(argv)
    kwargs: dict[str, Any] = {"seed": args.seed}
    if args.trials is not None:
        kwargs["trials"] = args.trials
    return run_and_print(
        "gaze",
        lambda **kw: format_gaze(run_gaze(args.out, **kw)),
        kwargs,
        (args.out / "gaze.png", args.out / "gaze.json"),
        args,
    )
