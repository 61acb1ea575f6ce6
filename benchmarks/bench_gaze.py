"""Fixation and reaching with a model (issue 16): kinfw's `GazeSolver` / `reach` against
the damped least squares of Pinocchio's inverse kinematics example, on the same residual.

1. Fixation on the built-in IIS head, nominal and a perturbed head
   (``kinfw.simulation.perturb_robot``, 2 mm / 0.5 deg per joint: a "calibrated-like"
   model). Seeded points in front of the head: directions within 25 deg of the mean
   optical axis at the middle configuration, from the cameras' midpoint; 90 % at
   0.5-3 m, 10 % at 3.8-4.2 m. Methods, each from the middle configuration:

   - ``GazeSolver.fixate`` (prepared once) and ``fixate()`` (builds the solver per point);
   - the closed-form start alone (``aim``: one sweep, no Gauss-Newton);
   - the baseline: Pinocchio's CLIK example (``doc/b-examples/i-inverse-kinematics``):
     ``dx = -J^T (J J^T + damp I)^-1 r``, ``x += dt dx``, damp 1e-6, dt 0.1 or 1 (a full
     step), up to 1000 iterations, on the same residual (kinfw's stereographic
     coordinates of each camera's ray error and their exact Jacobian), no closed-form
     start. Written here, not in the library. Two additions to the example: the joint
     values are clipped to the limits after each step (the library respects them too),
     and it stops when a step is below 1e-12 (else it would spend 1000 iterations on
     every point that cannot be fixated exactly).

   Error: the larger of the two cameras' angles between optical axis and point, by the
   model (deg); "fixated": both below 1e-6 rad. The nominal IIS head cannot fixate most
   points nearer than ~4 m exactly (its right camera sits 150 mm higher up the vergence
   axis: a vertical disparity no joint removes; ``kinfw.control``): the error there
   is the closest achievable fixation's, and a method is judged by how close it gets.

2. Reaching on the UR10 (example-robot-data, ``tool0``) and the 6R arm of
   ``tests/robots.py`` (``flange``, tilted axes, one continuous joint): poses of seeded
   random in-range configurations (forward kinematics, so reachable). kinfw ``reach``
   (50 seeded restarts) against the CLIK example on the frame's pose (error
   ``log6(frame^-1 target)``, LOCAL, Jacobian ``-Jlog6 J``), damp 1e-6, dt 0.1 or 1, up
   to 1000 iterations per start, stopping at ``|err| < 1e-7`` or a step below 1e-12,
   with the same number of random restarts drawn the same way (uniform within the
   limits, +-pi where unbounded). Reached: position within 1e-6 m and rotation within
   1e-6 rad (kinfw's test), for every method.

Times are wall-clock per call (``time.perf_counter``, gc off, after a warm-up); the
ratios compare methods on the same points in the same run. Run from the repository root:
``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_gaze.py [--points N] [--poses N]
[--seed S] [--quick]``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # for benchmarks.common (kinfw comes from pip install -e .)
    sys.path.insert(0, str(REPO))

import pinocchio as pin

from benchmarks.common import gc_disabled, machine_info, wall_time_line
from kinfw.control import (
    FIXATED_RAD,
    REACHED_M,
    REACHED_RAD,
    GazeSolver,
    fixate,
    middle_configuration,
    reach,
)
from kinfw.control._gaze import _GazeResidual
from kinfw.model import Robot, load_robot
from kinfw.simulation import perturb_robot
from tests.robots import ARM_6R, HEAD_URDF

#: The CLIK example's fixed damping and iteration cap; its steps dt.
DAMP = 1e-6
IT_MAX = 1000
DTS = (0.1, 1.0)
CONE_DEG = 25.0
RESTARTS = 50


@dataclass(frozen=True, slots=True)
class Run:
    """One method on the points ``index``: per-point seconds, iterations, errors."""

    index: NDArray[np.intp]  # the points (poses) it ran on
    seconds: NDArray[np.float64]
    cpu_seconds: NDArray[np.float64]
    iterations: NDArray[np.float64]
    error: NDArray[np.float64]  # the worse camera (gaze) or position m (reach)
    ok: NDArray[np.bool_]
    extra: NDArray[np.float64]  # free joints at a limit (gaze), starts used (reach)


def markdown(headers: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def ms(seconds: NDArray[np.float64], q: float) -> float:
    return 1e3 * float(np.percentile(seconds, q))


def timed(calls: list[Callable[[], object]], warmup: int = 20) -> tuple[NDArray, list[tuple]]:
    """Each call once, timed alone (gc off) after ``warmup`` untimed calls of the first
    ones; returns the wall-clock and CPU seconds (shape (n,) each) and the results. On a
    loaded machine the wall-clock tail includes time the process waited for a core."""
    for call in calls[:warmup]:
        call()
    seconds, cpu_seconds, results = np.empty(len(calls)), np.empty(len(calls)), []
    with gc_disabled():
        for k, call in enumerate(calls):
            start, cpu_start = time.perf_counter(), time.process_time()
            results.append(call())
            seconds[k] = time.perf_counter() - start
            cpu_seconds[k] = time.process_time() - cpu_start
    return seconds, cpu_seconds, results


# -- fixation ------------------------------------------------------------------------------


def head_points(robot: Robot, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """``n`` points (root frame, m) in a 25 deg cone about the mean optical axis at the
    middle configuration, from the cameras' midpoint: 90 % at 0.5-3 m, 10 % at 3.8-4.2 m."""
    q = middle_configuration(robot)
    root_T_cameras = np.array([robot.frame_poses(q, c) for c in robot.default_cameras])
    centres, axes = root_T_cameras[:, :3, 3], root_T_cameras[:, :3, 2]
    forward = axes.sum(axis=0) / np.linalg.norm(axes.sum(axis=0))
    helper = np.array([1.0, 0.0, 0.0]) if abs(forward[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    side = np.cross(forward, helper)
    side /= np.linalg.norm(side)
    up = np.cross(forward, side)
    cos_cone = math.cos(math.radians(CONE_DEG))
    cos_t = rng.uniform(cos_cone, 1.0, n)  # uniform over the spherical cap
    sin_t = np.sqrt(1.0 - cos_t**2)
    phi = rng.uniform(0.0, 2.0 * math.pi, n)
    directions = (
        cos_t[:, None] * forward
        + (sin_t * np.cos(phi))[:, None] * side
        + (sin_t * np.sin(phi))[:, None] * up
    )
    far = np.arange(n) >= n - n // 10
    distances = np.where(far, rng.uniform(3.8, 4.2, n), rng.uniform(0.5, 3.0, n))
    return centres.mean(axis=0) + distances[:, None] * directions


def camera_errors(residual: _GazeResidual, x: NDArray[np.float64]) -> float:
    """The worse camera's angle (rad) at ``x`` (inf where undefined)."""
    r, _ = residual(x, False)
    if r is None:
        return math.inf
    return float(np.max(2.0 * np.arctan(0.5 * np.linalg.norm(r.reshape(-1, 2), axis=1))))


def clik_fixation(residual: _GazeResidual, x: NDArray, lower: NDArray, upper: NDArray, dt: float):
    """Pinocchio's CLIK example on the gaze residual (module docstring): (x, iterations)."""
    for iteration in range(1, IT_MAX + 1):
        r, jac = residual(x, True)
        if r is None:  # stepped behind a camera: the residual is undefined
            return x, iteration
        if np.max(2.0 * np.arctan(0.5 * np.linalg.norm(r.reshape(-1, 2), axis=1))) < FIXATED_RAD:
            return x, iteration
        v = -jac.T @ np.linalg.solve(jac @ jac.T + DAMP * np.eye(len(r)), r)
        x_new = np.clip(x + dt * v, lower, upper)
        if np.max(np.abs(x_new - x)) < 1e-12:
            return x_new, iteration
        x = x_new
    return x, IT_MAX


def gaze_runs(
    robot: Robot, points: NDArray[np.float64], subset: NDArray[np.intp]
) -> dict[str, Run]:
    """Every method on the IIS head; the CLIK baselines on ``points[subset]`` only."""
    solver = GazeSolver(robot)
    q0 = solver.q_middle
    configuration0 = robot.pin_configurations(q0)[0]
    rays = np.tile([0.0, 0.0, 1.0], (len(solver.cameras), 1))
    x0 = np.clip(q0[solver.free_columns], solver.lower, solver.upper)

    def residual(p):
        return _GazeResidual(solver, rays, p, configuration0)

    def limits(x):
        return float(np.sum((x <= solver.lower) | (x >= solver.upper)))

    def aim(p):
        res = residual(p)
        return res, res.aim(x0)

    def clik(p, dt):
        res = residual(p)
        return res, *clik_fixation(res, x0, solver.lower, solver.upper, dt)

    runs: dict[str, Run] = {}
    every = np.arange(len(points))
    for name, call in (
        ("kinfw GazeSolver.fixate", solver.fixate),
        ("kinfw fixate() (solver built per point)", lambda p: fixate(robot, p)),
    ):
        seconds, cpu, fixations = timed([lambda p=p, call=call: call(p) for p in points])
        runs[name] = Run(
            every,
            seconds,
            cpu,
            np.array([f.iterations for f in fixations], dtype=float),
            np.array([f.error_rad.max() for f in fixations]),
            np.array([f.fixated for f in fixations]),
            np.array([len(f.at_limits) for f in fixations], dtype=float),
        )
    seconds, cpu, starts = timed([lambda p=p: aim(p) for p in points])
    errors = np.array([camera_errors(res, x) for res, x in starts])
    at_limits = np.array([limits(x) for _, x in starts])
    runs["closed-form start alone (aim)"] = Run(
        every, seconds, cpu, np.zeros(len(points)), errors, errors < FIXATED_RAD, at_limits
    )
    for dt in DTS:
        seconds, cpu, results = timed([lambda p=p, dt=dt: clik(p, dt) for p in points[subset]])
        errors = np.array([camera_errors(res, x) for res, x, _ in results])
        runs[f"CLIK damp 1e-6, dt {dt:g}"] = Run(
            subset,
            seconds,
            cpu,
            np.array([it for _, _, it in results], dtype=float),
            errors,
            errors < FIXATED_RAD,
            np.array([limits(x) for _, x, _ in results]),
        )
    return runs


def gaze_table(runs: dict[str, Run]) -> str:
    reference = runs["kinfw GazeSolver.fixate"]
    rows = []
    for name, run in runs.items():
        finite = np.isfinite(run.error)
        error_deg = np.degrees(run.error)
        ref_seconds, ref_error = reference.seconds[run.index], reference.error[run.index]
        rows.append(
            [
                f"{name} ({len(run.index)} points)",
                f"{ms(run.seconds, 50):.3f}",
                f"{ms(run.seconds, 95):.3f}",
                f"{ms(run.cpu_seconds, 50):.3f} / {ms(run.cpu_seconds, 95):.3f}",
                f"{np.median(run.seconds) / np.median(ref_seconds):.2f}",
                f"{np.median(run.iterations):.0f} / {np.max(run.iterations):.0f}",
                f"{run.ok.mean():.1%}",
                f"{np.mean(run.extra > 0):.1%} / {np.mean(run.extra == 4):.1%}",
                f"{np.median(error_deg):.3g}",
                f"{np.percentile(error_deg, 95):.3g}",
                f"{np.median(run.error / ref_error):.3g}"
                if finite.all()
                else f"{np.median(run.error[finite] / ref_error[finite]):.3g} "
                f"({(~finite).sum()} undefined)",
            ]
        )
    headers = [
        "method",
        "ms median",
        "ms p95",
        "CPU ms median / p95",
        "time / kinfw (same points, medians)",
        "iterations median / max",
        "fixated",
        "a joint / all 4 at a limit",
        "error deg median",
        "error deg p95",
        "error / kinfw (median of per-point ratios)",
    ]
    return markdown(headers, rows)


def band_table(points: NDArray, centre: NDArray, runs_by_model: dict[str, dict[str, Run]]) -> str:
    distances = np.linalg.norm(points - centre, axis=1)
    bands = [(0.5, 1.0), (1.0, 2.0), (2.0, 3.0), (3.8, 4.2)]
    rows = []
    for model, runs in runs_by_model.items():
        run, start = runs["kinfw GazeSolver.fixate"], runs["closed-form start alone (aim)"]
        clik = runs[f"CLIK damp 1e-6, dt {DTS[0]:g}"]
        for lo, hi in bands:
            inside = (distances >= lo) & (distances < hi)
            clik_inside = inside[clik.index]
            rows.append(
                [
                    model,
                    f"{lo:g}-{hi:g} m",
                    f"{inside.sum()}",
                    f"{run.ok[inside].mean():.1%}",
                    f"{np.degrees(np.median(run.error[inside])):.3g}",
                    f"{np.degrees(np.percentile(run.error[inside], 95)):.3g}",
                    f"{np.degrees(np.median(start.error[inside])):.3g}",
                    f"{np.degrees(np.median(clik.error[clik_inside])):.3g} "
                    f"({clik.ok[clik_inside].mean():.0%} of {clik_inside.sum()} fixated)",
                ]
            )
    headers = [
        "model",
        "distance",
        "points",
        "fixated",
        "kinfw error deg median",
        "p95",
        "aim alone error deg median",
        f"CLIK dt {DTS[0]:g} error deg median (subset)",
    ]
    return markdown(headers, rows)


# -- reaching ------------------------------------------------------------------------------


def random_x(rng: np.random.Generator, lower: NDArray, upper: NDArray) -> NDArray:
    return rng.uniform(
        np.where(np.isfinite(lower), lower, -math.pi), np.where(np.isfinite(upper), upper, math.pi)
    )


def clik_reach(robot: Robot, frame_id: int, target: pin.SE3, starts: list[NDArray], dt: float):
    """Pinocchio's CLIK example on a frame's pose, one start after another until one
    reaches (module docstring): (configuration, starts used, iterations)."""
    model, data = robot.model, robot.model.createData()
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    total = 0
    best = (math.inf, None)
    for used, start in enumerate(starts, 1):
        configuration = start.copy()
        for _ in range(IT_MAX):
            total += 1
            pin.forwardKinematics(model, data, configuration)
            frame_M_target = pin.updateFramePlacement(model, data, frame_id).actInv(target)
            err = pin.log6(frame_M_target).vector
            if np.linalg.norm(err) < 1e-7:
                break
            jac = pin.computeFrameJacobian(model, data, configuration, frame_id, pin.LOCAL)
            jac = -pin.Jlog6(frame_M_target.inverse()) @ jac
            v = -jac.T @ np.linalg.solve(jac @ jac.T + DAMP * np.eye(6), err)
            new = np.clip(pin.integrate(model, configuration, dt * v), lower, upper)
            if np.max(np.abs(new - configuration)) < 1e-12:
                break
            configuration = new
        position, rotation = pose_errors(model, data, configuration, frame_id, target)
        if position <= REACHED_M and rotation <= REACHED_RAD:
            return configuration, used, total
        cost = position**2 + (0.1 * rotation) ** 2
        if cost < best[0]:
            best = (cost, configuration)
    return best[1], len(starts), total


def pose_errors(model, data, configuration, frame_id, target: pin.SE3) -> tuple[float, float]:
    pin.forwardKinematics(model, data, configuration)
    M = pin.updateFramePlacement(model, data, frame_id)
    position = float(np.linalg.norm(M.translation - target.translation))
    rotation = float(np.linalg.norm(pin.log3(target.rotation.T @ M.rotation)))
    return position, rotation


def reach_runs(
    robot: Robot, frame: str, n: int, n_baseline: int, rng: np.random.Generator
) -> dict[str, Run]:
    """kinfw ``reach`` on ``n`` random reachable poses, the CLIK baselines on the first
    ``n_baseline`` of them."""
    free = robot.movable_path(frame)
    lower, upper = robot.joint_limits(free)
    qs = np.array([random_x(rng, lower, upper) for _ in range(n)])
    root_T_targets = robot.frame_poses(qs, frame, free)
    frame_id = robot.frame_id(frame)
    model, data = robot.model, robot.model.createData()
    runs: dict[str, Run] = {}
    seconds, cpu, results = timed(
        [lambda T=T: reach(robot, frame, T, restarts=RESTARTS) for T in root_T_targets]
    )
    runs[f"kinfw reach ({RESTARTS} restarts)"] = Run(
        np.arange(n),
        seconds,
        cpu,
        np.zeros(n),
        np.array([r.position_error_m for r in results]),
        np.array([r.reached for r in results]),
        np.array([r.starts for r in results], dtype=float),
    )
    # the baseline's starts: the middle configuration, then RESTARTS uniform draws (seeded per pose)
    middle = robot.pin_configurations(middle_configuration(robot))[0]
    start_sets = []
    subset = np.arange(min(n, n_baseline))
    for k in subset:
        draws = np.random.default_rng([k, 1])
        start_sets.append(
            [middle]
            + [
                robot.pin_configurations(random_x(draws, lower, upper)[None])[0]
                for _ in range(RESTARTS)
            ]
        )
    targets = [pin.SE3(T[:3, :3], T[:3, 3]) for T in root_T_targets[subset]]
    for dt in DTS:
        seconds, cpu, results = timed(
            [
                lambda t=t, s=s, dt=dt: clik_reach(robot, frame_id, t, s, dt)
                for t, s in zip(targets, start_sets, strict=True)
            ]
        )
        errors = np.array(
            [
                pose_errors(model, data, c, frame_id, t)
                for (c, _, _), t in zip(results, targets, strict=True)
            ]
        )
        runs[f"CLIK damp 1e-6, dt {dt:g}, {RESTARTS} restarts"] = Run(
            subset,
            seconds,
            cpu,
            np.array([it for _, _, it in results], dtype=float),
            errors[:, 0],
            (errors[:, 0] <= REACHED_M) & (errors[:, 1] <= REACHED_RAD),
            np.array([used for _, used, _ in results], dtype=float),
        )
    return runs


def reach_table(runs: dict[str, Run]) -> str:
    reference = runs[f"kinfw reach ({RESTARTS} restarts)"]
    rows = []
    for name, run in runs.items():
        rows.append(
            [
                f"{name} ({len(run.index)} poses)",
                f"{run.ok.mean():.1%} (kinfw {reference.ok[run.index].mean():.1%})",
                f"{ms(run.seconds, 50):.2f}",
                f"{ms(run.seconds, 95):.2f}",
                f"{np.median(run.seconds) / np.median(reference.seconds[run.index]):.2f}",
                f"{np.mean(run.extra):.2f} / {np.max(run.extra):.0f}",
                f"{np.median(run.iterations):.0f}" if run.iterations.any() else "-",
                f"{np.median(run.error[run.ok]) * 1e3:.2g}" if run.ok.any() else "-",
            ]
        )
    headers = [
        "method",
        "reached (kinfw, same poses)",
        "ms median",
        "ms p95",
        "time / kinfw (same poses, medians)",
        "starts mean / max",
        "CLIK iterations median",
        "position error mm (reached, median)",
    ]
    return markdown(headers, rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=None, help="head points (1000; quick 100)")
    parser.add_argument("--poses", type=int, default=None, help="poses per arm (500; quick 50)")
    parser.add_argument(
        "--baseline", type=int, default=None, help="points / poses for CLIK (200; quick 50)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw")
    parser.add_argument("--quick", action="store_true", help="fewer points and poses")
    args = parser.parse_args(argv)
    n_points = args.points or (100 if args.quick else 1000)
    n_poses = args.poses or (50 if args.quick else 500)
    n_baseline = args.baseline or (50 if args.quick else 200)
    if n_points < 10 or n_poses < 1 or n_baseline < 1:
        parser.error("--points: at least 10; --poses, --baseline: at least 1")
    started = time.perf_counter()
    print(machine_info([("pinocchio", pin.__version__)]))
    print(f"command    {' '.join(['python', *sys.argv])}")
    print(
        f"mode       points {n_points}, poses {n_poses}, CLIK baseline on {n_baseline} of "
        f"them, seed {args.seed}, gc off while timing"
    )

    rng = np.random.default_rng(args.seed)
    nominal = load_robot(HEAD_URDF)
    perturbed = load_robot(perturb_robot(nominal, rng))
    points = head_points(nominal, n_points, rng)
    q = middle_configuration(nominal)
    centre = np.mean([nominal.frame_poses(q, c)[:3, 3] for c in nominal.default_cameras], axis=0)
    # the baselines' points: evenly spread over the list (the far points are its last 10 %)
    subset = np.unique(np.linspace(0, n_points - 1, min(n_points, n_baseline)).round().astype(int))
    runs_by_model = {}
    for model, robot in (("nominal", nominal), ("perturbed (2 mm / 0.5 deg)", perturbed)):
        print(f"\n## 1. Fixation, IIS head, {model} model: {n_points} points\n")
        runs_by_model[model] = gaze_runs(robot, points, subset)
        print(gaze_table(runs_by_model[model]))
        sys.stdout.flush()
    print("\n### Fixation error by distance (worse camera, deg)\n")
    print(band_table(points, centre, runs_by_model))

    arms = [("6R arm (tests/robots.py)", ARM_6R, "flange")]
    try:
        from tests.erd import urdf_path

        arms.insert(0, ("UR10", urdf_path("ur_description/urdf/ur10_robot.urdf"), "tool0"))
    except FileNotFoundError as error:
        print(f"\n(UR10 skipped: {error})")
    for name, urdf, frame in arms:
        print(f"\n## 2. Reach, {name}, frame {frame}: {n_poses} random reachable poses\n")
        print(reach_table(reach_runs(load_robot(urdf), frame, n_poses, n_baseline, rng)))
        sys.stdout.flush()
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
