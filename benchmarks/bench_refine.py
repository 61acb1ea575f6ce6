"""Speed of the joint nonlinear least squares (``kinfw.identification``) on the IIS-head.

Run from the repository root::

    python benchmarks/bench_refine.py              # full run, ~2.5-3.5 minutes
    python benchmarks/bench_refine.py --quick      # reduced set, under a minute
    python benchmarks/bench_refine.py --repeats 20 --seed 3

Prints plain-text tables:

1. Solvers on one problem (both stages of the head: 55 one-joint-at-a-time plate
   configurations + 30 camera views, noise 0.5 mm / 0.5 deg, noise model given), all
   started from the closed-form + hand-eye estimate on the same data:
   kinfw's Levenberg-Marquardt (:func:`kinfw.identification.refine`, and its LM loop
   alone on the prebuilt problem), CasADi ``sqpmethod`` on ``f = 0.5 |r|^2`` with a
   Gauss-Newton ``hess_lag = J^T J`` (J by CasADi AD of the MX residual, J from the
   problem's own Jacobian functions, and the AD variant expanded to SX), and ipopt with
   the exact Hessian (MX, and expanded to SX). Final cost (recomputed by
   ``problem.evaluate`` for every solver), iterations, build and solve times, the ratio
   of each solve to the LM loop measured in the same repeats, and the held-out position
   RMS of each result against the true robot.
2. The whole head calibration, stage by stage in the order of
   :func:`kinfw.identification.identify` (closed form, export, hand-eye per camera,
   refine split into problem build / LM iterations / the rest, export).
3. Scaling of ``refine`` with the number of samples (random configurations, both plates
   and both cameras observed in every sample, start = nominal slightly perturbed, no
   closed form): rows, build time, evaluation times, time per LM iteration, total, local
   log-log slopes; then a cProfile of the largest size (top functions by cumulative time,
   and any function called once per sample or more: a per-sample Python loop).

Timing: ``time.perf_counter`` around each call, warm-up calls first, garbage collection
disabled while timing (as :mod:`timeit` does), calls of one repeat timed round robin so
that ratios within a repeat see the same machine state. Calls that take seconds (the
largest sizes of section 3, the SX builds) are timed once and say so.
"""

from __future__ import annotations

import cProfile
import inspect
import pstats
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # for benchmarks.common (kinfw comes from pip install -e .)
    sys.path.insert(0, str(REPO))

import casadi as ca
import pinocchio as pin

import kinfw.identification.problem._refine as rf
from benchmarks.common import (
    format_table,
    gc_disabled,
    machine_info,
    mode_line,
    parse_repeats,
    slope,
    time_interleaved,
    wall_time_line,
)
from kinfw.geometry import average_transform
from kinfw.identification import identify, identify_closed_form, refine
from kinfw.identification.handeye import CamerasResult, calibrate_cameras
from kinfw.identification.problem import (
    NoiseModel,
    build_problem,
    estimate_unknowns,
    levenberg_marquardt,
    thresholds,
)
from kinfw.measurements import (
    Measurements,
    check_against_robot,
    check_joint_motion,
    concatenate_measurements,
)
from kinfw.model import BlockKey, Robot, cpc_from_robot, geometry_from_cpc, load_robot
from kinfw.simulation import (
    default_target_pose,
    one_joint_at_a_time,
    perturb_robot,
    random_configurations,
    simulate_at,
)
from kinfw.urdf import edit_urdf, export_urdf

HEAD_URDF = REPO / "robots" / "iis_head.urdf"
PLATES = ("left_plate", "right_plate")
CAMERAS = ("left_camera", "right_camera")
PER_JOINT = 9  # Shih et al. section 4.1: 6 x 9 + 1 = 55 configurations
N_VIEWS = 30
NOISE_M = 0.5e-3
NOISE_DEG = 0.5
# simulate() turns by N(0, sigma) about a random axis: sigma / sqrt(3) per component
# (the same conversion as `kinfw calibrate --sigma-deg`)
NOISE_MODEL = NoiseModel(NOISE_M, float(np.radians(NOISE_DEG) / np.sqrt(3.0)))
N_TEST = 200
WARMUP = 2
COST_RTOL = 1e-9

FULL_SIZES = (100, 300, 1000, 3000, 10000)
QUICK_SIZES = (100, 300, 1000)
ONCE_FROM = 3000  # sizes from here on: timed once, no warm-up (each call takes seconds)


# -- timing ------------------------------------------------------------------------------


def time_once(call: Callable[[], object]) -> tuple[float, object]:
    """Seconds of one call (gc disabled) and its result."""
    with gc_disabled():
        start = time.perf_counter()
        out = call()
        return time.perf_counter() - start, out


# -- the head case -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Case:
    """A simulated two-stage head experiment and its held-out truth."""

    truth: Robot
    data: Measurements
    test_qs: NDArray[np.float64]  # (N_TEST, J), columns in `joint_names`
    joint_names: tuple[str, ...]


def make_head_case(nominal: Robot, seed: int) -> Case:
    """/tmp/ref.py's experiment: stage 1 (plates, one joint at a time), stage 2 (cameras)."""
    rng = np.random.default_rng([seed, 1])
    truth = load_robot(perturb_robot(nominal, rng, origin_mm=5.0, origin_deg=1.0, axis_deg=1.0))
    names = nominal.topology(PLATES + CAMERAS).joint_names
    lower, upper = nominal.joint_limits(names)
    qs1, _ = one_joint_at_a_time(lower, upper, per_joint=PER_JOINT)
    qs2 = random_configurations(lower, upper, N_VIEWS, rng, fraction=0.8)
    w_T_target = default_target_pose(truth, qs2, names, CAMERAS)
    noise = {"noise_m": NOISE_M, "noise_rad": np.radians(NOISE_DEG)}
    data = concatenate_measurements(
        simulate_at(truth, qs1, names, frames=PLATES, rng=rng, **noise),
        simulate_at(truth, qs2, names, cameras=CAMERAS, rng=rng, w_T_target=w_T_target, **noise),
    )
    test_qs = random_configurations(lower, upper, N_TEST, rng, fraction=0.8)
    return Case(truth, data, test_qs, names)


def held_out_rms_mm(model, case: Case, frames: Sequence[str] = PLATES + CAMERAS) -> float:
    """Position RMS (mm) of a CPC model against the true robot's Pinocchio FK, over the
    held-out configurations and ``frames``."""
    qs = case.test_qs[:, [case.joint_names.index(n) for n in model.topology.joint_names]]
    dp = [
        model.frame_poses(qs, f)[:, :3, 3]
        - case.truth.frame_poses(case.test_qs, f, case.joint_names)[:, :3, 3]
        for f in frames
    ]
    return 1e3 * float(np.sqrt(np.mean(np.concatenate(dp) ** 2) * 3.0))


def truth_and_start(nominal: Robot, rng: np.random.Generator) -> tuple[Robot, Robot]:
    """A true head (nominal perturbed, :func:`perturb_robot`'s defaults) and a start near
    the nominal (perturbed by 0.5 mm, 0.1 deg), drawn from ``rng`` in that order."""
    truth = load_robot(perturb_robot(nominal, rng))
    start = load_robot(perturb_robot(nominal, rng, origin_mm=0.5, origin_deg=0.1, axis_deg=0.1))
    return truth, start


def robot_rms_mm(robot: Robot, case: Case, frames: Sequence[str]) -> float:
    """As :func:`held_out_rms_mm` for a URDF (Pinocchio FK of both)."""
    dp = [
        robot.frame_poses(case.test_qs, f, case.joint_names)[:, :3, 3]
        - case.truth.frame_poses(case.test_qs, f, case.joint_names)[:, :3, 3]
        for f in frames
    ]
    return 1e3 * float(np.sqrt(np.mean(np.concatenate(dp) ** 2) * 3.0))


# -- the pipeline, step by step ----------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Stages:
    """Intermediate results of calibrate()'s steps, inputs of the timed calls."""

    stage1_xml: str
    cameras: CamerasResult
    start_xml: str
    targets: dict[str, NDArray[np.float64]]


def run_stages(nominal: Robot, data: Measurements) -> Stages:
    """Closed form, export, hand-eye and the camera-mount edit, as calibrate() runs them."""
    closed = identify_closed_form(nominal, data)
    stage1_xml = export_urdf(nominal, closed.geometry).urdf_xml
    cameras = calibrate_cameras(Robot(stage1_xml, nominal.source), data)
    start_xml = edit_urdf(stage1_xml, joint_origins=camera_mounts(cameras))
    return Stages(stage1_xml, cameras, start_xml, dict(cameras.root_T_targets))


def camera_mounts(cameras: CamerasResult) -> dict[str, NDArray[np.float64]]:
    mounts: dict[str, list[NDArray[np.float64]]] = {}
    for c in cameras.cameras:
        mounts.setdefault(c.joint, []).append(c.hand_T_camera)
    return {joint: average_transform(np.stack(poses)) for joint, poses in mounts.items()}


def lm_only(
    problem, noise: NoiseModel, max_iterations: int = 100
) -> tuple[NDArray[np.float64], int, bool]:
    """refine()'s Levenberg-Marquardt loop on a prebuilt problem, least squares (the
    robust-loss thresholds are not used by the linear loss)."""
    return levenberg_marquardt(
        lambda v, jac: problem.evaluate(v, noise, jac),
        np.zeros(problem.n_parameters),
        problem.free,
        problem.obs_sizes,
        "linear",
        thresholds(problem.obs_components, 2.33),
        max_iterations,
    )


def cost_at(problem, x: NDArray[np.float64], noise: NoiseModel) -> float:
    r, _ = problem.evaluate(x, noise, False)
    return 0.5 * float(r @ r)


# -- CasADi solvers ----------------------------------------------------------------------


def gn_hessian_ad(problem, noise: NoiseModel, x_free, r, lam_f):
    """``lam_f J^T J`` with J = CasADi AD of the MX residual."""
    J = ca.jacobian(r, x_free)
    return lam_f * (J.T @ J)


def gn_hessian_maps(problem, noise: NoiseModel, x_free, r, lam_f):
    """``lam_f J^T J`` from the problem's own mapped Jacobian functions (the ones LM uses).

    Each group's Jacobian map returns ``[J_1 | J_2 | ... | J_m]`` (rows x m P);
    ``reshape(Jg^T, P, m rows)`` lists every residual row's gradient as a column, so the
    group's ``J^T J`` is ``A A^T``.
    """
    x = problem.full_x(x_free)
    P, free = problem.n_parameters, np.flatnonzero(problem.free).tolist()
    H = 0
    for g in problem.groups:
        m = len(g.sample)
        Jg = ca.diag(ca.DM(1.0 / g.row_sigma(noise))) @ g.jacobian(ca.DM(g.qs), ca.DM(g.data), x)
        A = ca.reshape(Jg.T, P, m * g.rows)[free, :]
        H = H + A @ A.T
    return lam_f * H


QP_QUIET = {"print_iter": False, "print_header": False, "print_info": False, "error_on_fail": False}


def build_sqp(problem, noise: NoiseModel, hessian: Callable, *, expand: bool):
    x_free, r = problem.casadi_residual(noise)
    lam_f, lam_g, p = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", 0), ca.MX.sym("p", 0)
    hess = ca.Function(
        "hess_gn", [x_free, p, lam_f, lam_g], [hessian(problem, noise, x_free, r, lam_f)]
    )
    if expand:
        hess = hess.expand()
    return ca.nlpsol(
        "sqp",
        "sqpmethod",
        {"x": x_free, "f": 0.5 * ca.dot(r, r)},
        {
            "hess_lag": hess,
            "expand": expand,
            "qpsol": "qrqp",
            "qpsol_options": QP_QUIET,
            "print_time": False,
            "print_header": False,
            "print_iteration": False,
            "print_status": False,
        },
    )


def build_ipopt(problem, noise: NoiseModel, *, expand: bool):
    x_free, r = problem.casadi_residual(noise)
    return ca.nlpsol(
        "ipopt",
        "ipopt",
        {"x": x_free, "f": 0.5 * ca.dot(r, r)},
        {"expand": expand, "print_time": False, "ipopt": {"print_level": 0, "sb": "yes"}},
    )


@dataclass(frozen=True, slots=True)
class Solver:
    label: str
    build: Callable[[], object]  # () -> nlpsol, or None for LM
    once: bool  # build timed once (slow) rather than over repeats
    quick: bool  # included in --quick


# -- output ------------------------------------------------------------------------------


def blas_probe_ms() -> float:
    """Median time of the SVD refine() does for its covariance, on the section-1 size."""
    a = np.random.default_rng(0).normal(size=(1020, 50))
    return time_interleaved([lambda: np.linalg.svd(a, full_matrices=False)], 15, warmup=WARMUP)[
        0
    ].median_ms


def ms(seconds: float) -> str:
    return f"{1e3 * seconds:.1f}"


# -- sections ----------------------------------------------------------------------------


def section_solvers(nominal: Robot, case: Case, stages: Stages, repeats: int, quick: bool) -> None:
    data, noise = case.data, NOISE_MODEL
    start = Robot(stages.start_xml, nominal.source)
    targets = stages.targets
    build_times = time_interleaved(
        [lambda: build_problem(nominal, data, start=start, targets=targets)], repeats, warmup=WARMUP
    )[0]
    problem = build_problem(nominal, data, start=start, targets=targets)
    n_rows = sum(m * rows for m, rows in problem.obs_sizes)
    n_free = int(problem.free.sum())
    print(
        f"\n1. Solvers on one problem: the head, both stages ({len(data.poses)} plate pose "
        f"groups over 55 configurations,\n   {len(data.targets)} camera target groups "
        f"over {N_VIEWS} views), {n_rows} residual rows x {n_free} free parameters;\n   "
        f"noise {1e3 * NOISE_M:g} mm / {NOISE_DEG:g} deg, noise model given "
        f"(sigma_p {1e3 * noise.position_m:g} mm, sigma_r {noise.rotation_rad:.4g} rad per "
        "component);\n   same start for all: closed form + hand-eye "
        f"(pipeline steps); {repeats} repeats, round robin"
    )

    solvers = [
        Solver(
            "sqpmethod GN, J by AD of MX r",
            lambda: build_sqp(problem, noise, gn_hessian_ad, expand=False),
            False,
            True,
        ),
        Solver(
            "sqpmethod GN, J from problem maps",
            lambda: build_sqp(problem, noise, gn_hessian_maps, expand=False),
            False,
            True,
        ),
        Solver(
            "sqpmethod GN, J by AD, expand (SX)",
            lambda: build_sqp(problem, noise, gn_hessian_ad, expand=True),
            True,
            False,
        ),
        Solver(
            "ipopt exact Hessian (MX)",
            lambda: build_ipopt(problem, noise, expand=False),
            True,
            True,
        ),
        Solver(
            "ipopt exact Hessian, expand (SX)",
            lambda: build_ipopt(problem, noise, expand=True),
            True,
            False,
        ),
    ]
    solvers = [s for s in solvers if s.quick or not quick]
    built, builds = [], []
    for s in solvers:
        if s.once:
            seconds, nlp = time_once(s.build)
            builds.append(f"{ms(seconds)} (once)")
        else:
            t = time_interleaved([s.build], max(3, repeats // 3), warmup=1)[0]
            nlp = s.build()
            builds.append(f"{t.median_ms:.1f}")
        built.append(nlp)

    x_free0 = np.zeros(n_free)
    calls: list[Callable[[], object]] = [
        lambda: lm_only(problem, noise),
        lambda: refine(nominal, data, start=start, targets=targets, noise=noise),
        *[lambda nlp=nlp: nlp(x0=x_free0) for nlp in built],
    ]
    timings = time_interleaved(calls, repeats, warmup=WARMUP)
    lm_times = timings[0]

    x_lm, lm_its, lm_ok = lm_only(problem, noise)
    result = refine(nominal, data, start=start, targets=targets, noise=noise)
    cost_lm = cost_at(problem, x_lm, noise)
    rms_lm = held_out_rms_mm(problem.model_at(x_lm), case)
    rows = [
        [
            "LM loop (prebuilt problem)",
            f"{cost_lm:.10g}",
            "0 (ref)",
            f"{lm_its}",
            "converged" if lm_ok else "not converged",
            f"{build_times.median_ms:.1f}",
            f"{lm_times.median_ms:.1f}",
            f"{lm_times.iqr_ms:.1f}",
            "1.00",
            f"{rms_lm:.4f}",
            "0",
        ],
        [
            "refine() whole call",
            f"{result.cost:.10g}",
            f"{result.cost / cost_lm - 1.0:.1e}",
            f"{result.iterations}",
            "converged" if result.converged else "not converged",
            "(incl.)",
            f"{timings[1].median_ms:.1f}",
            f"{timings[1].iqr_ms:.1f}",
            f"{np.median(timings[1].seconds / lm_times.seconds):.2f}",
            f"{held_out_rms_mm(result.model, case):.4f}",
            f"{np.abs(result.estimate - x_lm).max():.1e}",
        ],
    ]
    disagree = []
    for s, nlp, build, t in zip(solvers, built, builds, timings[2:], strict=True):
        sol = nlp(x0=x_free0)
        stats = nlp.stats()
        x = np.zeros(problem.n_parameters)
        x[problem.free] = np.asarray(sol["x"]).ravel()
        cost = cost_at(problem, x, noise)
        rel = cost / cost_lm - 1.0
        if abs(rel) > COST_RTOL:
            disagree.append(s.label)
        rows.append(
            [
                s.label,
                f"{cost:.10g}",
                f"{rel:.1e}",
                f"{stats['iter_count']}",
                stats["return_status"],
                build,
                f"{t.median_ms:.1f}",
                f"{t.iqr_ms:.1f}",
                f"{np.median(t.seconds / lm_times.seconds):.2f}",
                f"{held_out_rms_mm(problem.model_at(x), case):.4f}",
                f"{np.abs(x - x_lm).max():.1e}",
            ]
        )
    print(
        format_table(
            [
                "solver",
                "final cost",
                "rel. to LM",
                "iters",
                "status",
                "build ms",
                "solve ms",
                "IQR ms",
                "solve/LM",
                "held-out mm",
                "max|x-x_LM|",
            ],
            rows,
        )
    )
    print(
        "final cost = 0.5 |r|^2 of the whitened residuals, recomputed with "
        "problem.evaluate at each\n  solver's x; rel. to LM = cost / cost_LM - 1 "
        f"(agreement wanted within {COST_RTOL:g}).\n"
        "build ms: LM = build_problem (CasADi residual/Jacobian maps included); CasADi "
        "solvers =\n  casadi_residual + nlpsol construction on top of build_problem "
        "(SX builds timed once).\nsolve/LM = median over repeats of (solve time / LM-loop "
        "time in the same repeat); < 1 = faster.\nheld-out mm = position RMS of the "
        f"result vs the true robot, {N_TEST} configurations x 4 frames.\n"
        "max|x-x_LM| = largest difference of chart coordinates (rad, m) from the LM "
        "result.\nsqpmethod: qpsol qrqp, default tolerances; ipopt: default tol 1e-8."
    )
    if disagree:
        print(
            f"WARNING: final cost differs from LM's by more than {COST_RTOL:g} "
            f"(relative): {', '.join(disagree)}"
        )
    fastest = min(range(len(built)), key=lambda k: timings[2 + k].median_ms)
    ratio = np.median(timings[2 + fastest].seconds / lm_times.seconds)
    print(
        f"Fastest CasADi solver: {solvers[fastest].label}, {ratio:.2f} x the LM loop's "
        f"time\n  ({'LM faster' if ratio > 1 else 'CasADi faster'} by "
        f"{max(ratio, 1 / ratio):.2f}x, same run; both from the same start to the same "
        "cost)."
    )
    sqp_maps = built[1]
    sqp_maps(x0=x_free0)
    st = sqp_maps.stats()
    parts = {k[len("t_wall_") :]: v for k, v in st.items() if k.startswith("t_wall_") and v > 0}
    print(
        "Inside sqpmethod (J from problem maps), last solve: "
        + ", ".join(f"{k} {1e3 * v:.1f} ms" for k, v in parts.items())
    )


def section_rank_deficient(nominal: Robot, seed: int) -> None:
    """The same solvers when the data leaves directions undetermined (a joint held still)."""
    rng = np.random.default_rng([seed, 2])
    truth, start = truth_and_start(nominal, rng)
    names = nominal.topology(PLATES + CAMERAS).joint_names
    lower, upper = nominal.joint_limits(names)
    still = "vergence_left"
    qs = random_configurations(lower, upper, 200, rng, fraction=0.8)
    qs[:, names.index(still)] = 0.5 * (lower + upper)[names.index(still)]
    data = simulate_at(
        truth,
        qs,
        names,
        frames=PLATES,
        cameras=CAMERAS,
        rng=rng,
        noise_m=NOISE_M,
        noise_rad=np.radians(NOISE_DEG),
    )
    noise = NOISE_MODEL
    problem = build_problem(nominal, data, start=start)
    result = refine(nominal, data, start=start, noise=noise)
    ident = result.identifiability
    print(
        f"\n1b. Rank-deficient problem: 200 random configurations with {still} held still "
        f"(rank {ident.rank} of\n    {ident.n_parameters}: {len(ident.unidentifiable)} "
        "directions the data does not determine); same solver settings, one solve each"
    )
    t_lm, (x_lm, its, ok) = time_once(lambda: lm_only(problem, noise))
    cost_lm = cost_at(problem, x_lm, noise)
    rows = [
        [
            "LM loop (prebuilt problem)",
            f"{its}",
            "converged" if ok else "not converged",
            "0 (ref)",
            f"{np.abs(x_lm).max():.1e}",
            "0",
            ms(t_lm),
        ]
    ]
    x_free0 = np.zeros(int(problem.free.sum()))
    for label, make in (
        (
            "sqpmethod GN, J from problem maps",
            lambda: build_sqp(problem, noise, gn_hessian_maps, expand=False),
        ),
        ("ipopt exact Hessian (MX)", lambda: build_ipopt(problem, noise, expand=False)),
    ):
        nlp = make()
        seconds, sol = time_once(lambda nlp=nlp: nlp(x0=x_free0))
        stats = nlp.stats()
        x = np.zeros(problem.n_parameters)
        x[problem.free] = np.asarray(sol["x"]).ravel()
        rows.append(
            [
                label,
                f"{stats['iter_count']}",
                stats["return_status"],
                f"{cost_at(problem, x, noise) / cost_lm - 1.0:.1e}",
                f"{np.abs(x).max():.1e}",
                f"{np.abs(x - x_lm).max():.1e}",
                ms(seconds),
            ]
        )
    print(
        format_table(
            ["solver", "iters", "status", "cost rel. to LM", "max|x|", "max|x-x_LM|", "solve ms"],
            rows,
        )
    )
    print(
        "max|x| = largest move from the start (chart coordinates, rad or m). LM takes "
        "minimum-norm steps\n(no component along undetermined directions); the others "
        "may wander along them at equal cost."
    )


def section_pipeline(nominal: Robot, case: Case, stages: Stages, repeats: int) -> None:
    data, noise = case.data, NOISE_MODEL
    print(
        f"\n2. Whole head calibration, step by step in calibrate()'s order ({repeats} "
        "repeats, medians;\n   noise model given; data as in section 1)"
    )
    start = Robot(stages.start_xml, nominal.source)
    targets = stages.targets
    observed = data.observed_frames
    joint_names = nominal.topology(observed).joint_names
    result = refine(nominal, data, start=start, targets=targets, noise=noise)
    problem = build_problem(nominal, data, start=start, targets=targets)

    def numpy_prep():  # build_problem's numpy part, before any CasADi symbol
        m = check_against_robot(data, nominal)
        model0 = cpc_from_robot(start, m.observed_frames)
        q_all = m.q_of(model0.topology.joint_names)
        given = {BlockKey("target", n): T for n, T in targets.items()}
        return estimate_unknowns(m, list(m.all_groups()), model0, q_all, None, given)

    prep: Callable[[], object] | None = numpy_prep
    try:
        numpy_prep()
    except (AttributeError, TypeError, ValueError) as exc:
        print(
            f"[numpy/CasADi split of build_problem unavailable (refine internals changed): "
            f"{type(exc).__name__}: {exc}]"
        )
        prep = None

    per_camera = [
        (g.camera, replace(data, poses=(), points=(), targets=(g,))) for g in data.targets
    ]
    stage1 = Robot(stages.stage1_xml, nominal.source)
    # (label, top-level step?, call); indented rows are parts of the step above
    steps: list[tuple[str, bool, Callable[[], object]]] = [
        ("closed form: identify_closed_form", True, lambda: identify_closed_form(nominal, data)),
        (
            "closed form + export_urdf",
            False,
            lambda: export_urdf(nominal, identify_closed_form(nominal, data).geometry),
        ),
        ("hand-eye: Robot(stage-1 URDF)", True, lambda: Robot(stages.stage1_xml, nominal.source)),
        ("hand-eye: calibrate_cameras (all)", True, lambda: calibrate_cameras(stage1, data)),
        *[
            (f"  {cam} alone", False, lambda d=d: calibrate_cameras(stage1, d))
            for cam, d in per_camera
        ],
        (
            "hand-eye: edit_urdf (camera mounts)",
            True,
            lambda: edit_urdf(stages.stage1_xml, joint_origins=camera_mounts(stages.cameras)),
        ),
        ("refine: check_joint_motion", True, lambda: check_joint_motion(data, joint_names)),
        ("refine: Robot(start URDF)", True, lambda: Robot(stages.start_xml, nominal.source)),
        (
            "refine: refine() whole call",
            True,
            lambda: refine(nominal, data, start=start, targets=targets, noise=noise),
        ),
        (
            "  build_problem",
            False,
            lambda: build_problem(nominal, data, start=start, targets=targets),
        ),
        *(
            [("    numpy prep (check, cpc_from_robot, start extras)", False, prep)]
            if prep is not None
            else []
        ),
        ("  LM iterations (prebuilt problem)", False, lambda: lm_only(problem, noise)),
        (
            "export: geometry_from_cpc + export_urdf",
            True,
            lambda: export_urdf(
                nominal,
                geometry_from_cpc(result.model),
                root_is_measurement_frame=result.model_frame is None,
            ),
        ),
    ]
    timings = dict(
        zip(
            [label for label, _, _ in steps],
            time_interleaved([call for _, _, call in steps], repeats, warmup=WARMUP),
            strict=True,
        )
    )
    med = {label: t.median_ms for label, t in timings.items()}
    iqr = {label: t.iqr_ms for label, t in timings.items()}
    # derived rows: differences of medians
    med["closed form: export_urdf"] = (
        med.pop("closed form + export_urdf") - med["closed form: identify_closed_form"]
    )
    iqr["closed form: export_urdf"] = float("nan")
    order = [label for label, _, _ in steps if label != "closed form + export_urdf"]
    order.insert(1, "closed form: export_urdf")
    top = {label for label, is_top, _ in steps if is_top} | {"closed form: export_urdf"}
    if prep is not None:
        key = "    CasADi construction (build_problem - numpy prep)"
        med[key] = (
            med["  build_problem"] - med["    numpy prep (check, cpc_from_robot, start extras)"]
        )
        order.insert(order.index("  LM iterations (prebuilt problem)"), key)
    key = "  rest: covariance, identifiability, residuals"
    med[key] = (
        med["refine: refine() whole call"]
        - med["  build_problem"]
        - med["  LM iterations (prebuilt problem)"]
    )
    order.insert(order.index("  LM iterations (prebuilt problem)") + 1, key)
    total = sum(med[label] for label in order if label in top)
    rows = [
        [
            label,
            f"{med[label]:.2f}",
            f"{iqr[label]:.2f}" if np.isfinite(iqr.get(label, np.nan)) else "",
            f"{100 * med[label] / total:.1f}",
        ]
        for label in order
    ]
    rows.append(["sum of the top-level steps", f"{total:.2f}", "", "100.0"])
    whole = None
    params = inspect.signature(identify).parameters
    if "noise" in params and "method" in params:
        whole = time_interleaved(
            [lambda: identify(nominal, data, noise=noise)], max(3, repeats // 2), warmup=1
        )[0]
        rows.append(
            [
                "calibrate(nominal, data, noise=...) whole call",
                f"{whole.median_ms:.2f}",
                f"{whole.iqr_ms:.2f}",
                f"{100 * whole.median_ms / total:.1f}",
            ]
        )
    print(format_table(["step", "median ms", "IQR ms", "% of sum"], rows))
    print(
        "Indented rows are parts of the step above (not added to the sum); per-camera "
        "rows run\ncalibrate_cameras on a dataset holding that camera's target group "
        "only. Rows without an IQR\nare differences of medians: export_urdf after the "
        "closed form = (closed form + export) -\nclosed form; CasADi construction = "
        "build_problem - numpy prep; rest = refine() - build_problem\n- LM iterations."
    )
    if whole is None:
        print(
            "[calibrate() has no method/noise arguments in this checkout: whole-call row skipped]"
        )
    cal_rms = [
        ("nominal URDF", robot_rms_mm(nominal, case, PLATES), robot_rms_mm(nominal, case, CAMERAS)),
        (
            "after closed form",
            robot_rms_mm(stage1, case, PLATES),
            robot_rms_mm(stage1, case, CAMERAS),
        ),
        ("after hand-eye", robot_rms_mm(start, case, PLATES), robot_rms_mm(start, case, CAMERAS)),
        (
            "after refine",
            held_out_rms_mm(result.model, case, PLATES),
            held_out_rms_mm(result.model, case, CAMERAS),
        ),
    ]
    print(
        format_table(
            ["held-out position RMS", "plates mm", "cameras mm"],
            [[s, f"{p:.4f}", f"{c:.4f}"] for s, p, c in cal_rms],
        )
    )
    print(
        f"refine: {problem.n_parameters} parameters, "
        f"{sum(m * r for m, r in problem.obs_sizes)} rows, {result.iterations} LM "
        f"iterations, sigma_hat^2 {result.sigma_hat2:.3f}, rank "
        f"{result.identifiability.rank}/{result.identifiability.n_parameters}."
    )


def jacobian_breakdown(problem, noise: NoiseModel) -> tuple[float, float, float]:
    """Seconds of one ``evaluate(x, with_jacobian=True)`` split into the CasADi calls of
    the residual and Jacobian maps, their DM -> numpy conversion, and the numpy
    reshaping/concatenation (the rest), using the problem's groups (private fields)."""
    x = np.zeros(problem.n_parameters)
    t_call = t_conv = 0.0
    start = time.perf_counter()
    problem.evaluate(x, noise, True)
    whole = time.perf_counter() - start
    for g in problem.groups:
        for f in (g.residual, g.jacobian):
            t0 = time.perf_counter()
            out = f(g.qs, g.data, x)
            t1 = time.perf_counter()
            np.array(out)
            t2 = time.perf_counter()
            t_call += t1 - t0
            t_conv += t2 - t1
    return t_call, t_conv, max(whole - t_call - t_conv, 0.0)


def short_name(func: tuple[str, int, str]) -> str:
    path, line, name = func
    if path == "~":
        return name
    p = Path(path)
    try:
        path = str(p.relative_to(REPO))
    except ValueError:
        path = p.name
    return f"{path}:{line}({name})"


def section_scaling(nominal: Robot, sizes: Sequence[int], repeats: int, seed: int) -> None:
    rng = np.random.default_rng([seed, 3])
    truth, start = truth_and_start(nominal, rng)
    names = nominal.topology(PLATES + CAMERAS).joint_names
    lower, upper = nominal.joint_limits(names)
    qs = random_configurations(lower, upper, max(sizes), rng, fraction=0.8)
    data = simulate_at(
        truth,
        qs,
        names,
        frames=PLATES,
        cameras=CAMERAS,
        rng=rng,
        noise_m=NOISE_M,
        noise_rad=np.radians(NOISE_DEG),
    )
    noise = NOISE_MODEL
    print(
        f"\n3. Scaling with the number of samples: random configurations (80% of each "
        "range), both plates\n   and both cameras observed in every sample (24 rows per "
        "sample); truth = nominal perturbed\n   (2 mm, 0.5 deg), start = nominal "
        "perturbed (0.5 mm, 0.1 deg), targets estimated, no closed form;\n   "
        f"refine(nominal, data, start=start, noise=...); medians of {repeats} repeats "
        f"below 1000 samples,\n   of {max(1, repeats // 3)} from 1000, one call from "
        f"{ONCE_FROM}"
    )
    rows, totals, per_iter = [], [], []
    profile = None
    small_n = sizes[0]
    small_stats, _, _ = profiled_refine(nominal, data.subset(np.arange(small_n)), start, noise)
    for k, n in enumerate(sizes):
        subset = data.subset(np.arange(n))
        once = n >= ONCE_FROM
        last = k == len(sizes) - 1
        reps, warm = (
            (1, 0) if once else (repeats, WARMUP) if n < 1000 else (max(1, repeats // 3), 1)
        )
        build = time_interleaved(
            [lambda d=subset: build_problem(nominal, d, start=start)], reps, warmup=warm
        )[0]
        problem = build_problem(nominal, subset, start=start)
        x0 = np.zeros(problem.n_parameters)
        n_rows = sum(m * r for m, r in problem.obs_sizes)
        t_r, t_rj = time_interleaved(
            [
                lambda p=problem, x=x0: p.evaluate(x, noise, False),
                lambda p=problem, x=x0: p.evaluate(x, noise, True),
            ],
            reps,
            warmup=0 if once else 1,
        )
        t_call, t_conv, t_rest = jacobian_breakdown(problem, noise)
        if last:  # one profiled refine() call gives the total and the LM share
            stats, total_s, result = profiled_refine(nominal, subset, start, noise)
            lm_s = sum(v[3] for f, v in stats.stats.items() if f[2] == "levenberg_marquardt")
            its = result.iterations
            profile = (n, stats, total_s, small_n, small_stats)
        else:
            kept: dict[str, object] = {}

            def lm_call(p=problem, kept=kept):
                kept["lm"] = lm_only(p, noise)

            def refine_call(d=subset, kept=kept):
                kept["refine"] = refine(nominal, d, start=start, noise=noise)

            lm, whole = time_interleaved([lm_call, refine_call], reps, warmup=0 if once else 1)
            lm_s, total_s = float(np.median(lm.seconds)), float(np.median(whole.seconds))
            its, result = kept["lm"][1], kept["refine"]
        totals.append(total_s)
        per_iter.append(lm_s / max(its, 1))
        local = "" if k == 0 else f"{slope(sizes[k - 1 : k + 1], totals[k - 1 : k + 1]):.2f}"
        local_it = "" if k == 0 else f"{slope(sizes[k - 1 : k + 1], per_iter[k - 1 : k + 1]):.2f}"
        rows.append(
            [
                f"{n}",
                f"{n_rows}",
                f"{problem.n_parameters}",
                f"{build.median_ms:.1f}",
                f"{t_r.median_ms:.1f}",
                f"{t_rj.median_ms:.1f}",
                ms(t_call),
                ms(t_conv),
                ms(t_rest),
                f"{its}",
                ms(lm_s),
                ms(lm_s / max(its, 1)),
                ms(total_s),
                f"{1e6 * total_s / n_rows:.1f}",
                local,
                local_it,
                f"{result.sigma_hat2:.3f}",
            ]
        )
    print(
        format_table(
            [
                "samples",
                "rows",
                "P",
                "build ms",
                "r ms",
                "r+J ms",
                " casadi",
                " DM->np",
                " numpy",
                "LM its",
                "LM ms",
                "ms/iter",
                "total ms",
                "us/row",
                "slope",
                "slope/it",
                "s2",
            ],
            rows,
        )
    )
    print(
        "build = build_problem; r, r+J = one problem.evaluate without / with the Jacobian; "
        "casadi,\nDM->np, numpy = one r+J evaluation split into the CasADi map calls, "
        "converting their DM\noutputs to numpy, and the rest of evaluate (reshape, "
        "transpose, concatenate), measured once;\nLM = the Levenberg-Marquardt loop on "
        "the prebuilt problem (largest size: its cumulative time\nin the profiled "
        "refine() call); total = refine() whole call (largest size: the profiled call);\n"
        "slope, slope/it = local d log(time) / d log(samples) of total and of ms/iter; "
        "s2 = sigma_hat^2\n(about 1 when the fit matches the noise model)."
    )
    big = [k for k, n in enumerate(sizes) if n >= 1000]
    if len(big) >= 2:
        pick = [sizes[k] for k in big]
        print(
            f"Observed log-log fit over samples >= 1000: total ~ samples^"
            f"{slope(pick, [totals[k] for k in big]):.2f}, per LM iteration ~ samples^"
            f"{slope(pick, [per_iter[k] for k in big]):.2f} (1.00 = linear)."
        )
    if profile is not None:
        report_profile(*profile)


def profiled_refine(
    nominal: Robot, data: Measurements, start: Robot, noise: NoiseModel
) -> tuple[pstats.Stats, float, rf.RefineResult]:
    """One ``refine`` call under cProfile: its statistics, wall seconds and result."""
    profiler = cProfile.Profile()
    t0 = time.perf_counter()
    profiler.enable()
    result = refine(nominal, data, start=start, noise=noise)
    profiler.disable()
    return pstats.Stats(profiler), time.perf_counter() - t0, result


def report_profile(
    n: int, stats: pstats.Stats, total_s: float, small_n: int, small_stats: pstats.Stats
) -> None:
    entries = sorted(stats.stats.items(), key=lambda kv: kv[1][3], reverse=True)
    print(
        f"\ncProfile of refine() at {n} samples ({total_s:.1f} s wall, profiled): top 5 "
        "below refine() by cumulative time"
    )
    top = [
        (f, v)
        for f, v in entries
        if f[2] != "refine" and "cProfile" not in f[0] and f[2] != "<built-in method builtins.exec>"
    ][:5]
    print(
        format_table(
            ["function", "ncalls", "tottime s", "cumtime s", "% of refine"],
            [
                [
                    short_name(f),
                    f"{v[1]}",
                    f"{v[2]:.2f}",
                    f"{v[3]:.2f}",
                    f"{100 * v[3] / total_s:.0f}",
                ]
                for f, v in top
            ],
        )
    )

    def cum(name: str) -> float:
        return sum(v[3] for f, v in stats.stats.items() if f[2] == name)

    shares = [
        ("build_problem", cum("build_problem")),
        ("levenberg_marquardt", cum("levenberg_marquardt")),
        (
            "  casadi Function calls (all)",
            sum(v[2] for f, v in stats.stats.items() if "Function_call" in f[2]),
        ),
        (
            "  DM -> numpy conversion (all)",
            sum(v[3] for f, v in stats.stats.items() if "DM_full" in f[2]),
        ),
        ("covariance_and_identifiability", cum("covariance_and_identifiability")),
    ]
    print(
        "Where the time goes: "
        + "; ".join(f"{name.strip()} {s:.2f} s ({100 * s / total_s:.0f}%)" for name, s in shares)
    )
    # a per-sample Python loop: a function whose call count grows with the samples
    small = {f: v[1] for f, v in small_stats.stats.items()}
    grows = [
        (f, v[1], small.get(f, 0))
        for f, v in entries
        if v[1] - small.get(f, 0) >= 0.5 * (n - small_n)
    ]
    if grows:
        print(
            f"Functions whose call count grows with the samples ({small_n} -> {n}): a "
            "per-sample Python loop:"
        )
        for f, calls, calls_small in grows:
            print(f"  {short_name(f)}: {calls_small} -> {calls} calls")
    else:
        growth = max(entries, key=lambda kv: kv[1][1] - small.get(kv[0], 0))
        print(
            f"Per-sample loop check: no function's call count grows with the samples "
            f"({small_n} -> {n} samples;\n  largest growth {short_name(growth[0])}: "
            f"{small.get(growth[0], 0)} -> {growth[1][1]} calls; "
            f"{sum(small.values())} -> {sum(v[1] for _, v in entries)} calls in all)."
        )


def main(argv: Sequence[str] | None = None) -> int:
    args, repeats = parse_repeats(
        argv,
        __doc__.splitlines()[0],
        full=9,
        quick=3,
        quick_help=f"samples {QUICK_SIZES}, no SX-expanded CasADi solvers",
    )
    sizes = QUICK_SIZES if args.quick else FULL_SIZES

    started = time.perf_counter()
    print(
        "kinfw refine benchmark (IIS-head: plates "
        + ", ".join(PLATES)
        + "; cameras "
        + ", ".join(CAMERAS)
        + ")"
    )
    print(
        machine_info(
            [("pinocchio", pin.__version__), ("casadi", ca.__version__)],
            probes=[
                (
                    "BLAS probe",
                    f"{blas_probe_ms():.2f} ms median for np.linalg.svd of a 1020 x 50 "
                    "matrix (~1.5 ms on one\n           core here; far more = BLAS threads "
                    "fighting other load: OPENBLAS_NUM_THREADS=1)",
                )
            ],
        )
    )
    print(mode_line(args, repeats, WARMUP))
    nominal = load_robot(HEAD_URDF)
    case = make_head_case(nominal, args.seed)
    stages = run_stages(nominal, case.data)
    section_solvers(nominal, case, stages, repeats, args.quick)
    section_rank_deficient(nominal, args.seed)
    section_pipeline(nominal, case, stages, repeats)
    section_scaling(nominal, sizes, repeats, args.seed)
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
