"""Speed of the closed-form CPC identification on the IIS-head, with its accuracy alongside.

Run from the repository root::

    python benchmarks/bench_closed_form.py              # full run, under ~2 minutes
    python benchmarks/bench_closed_form.py --quick      # reduced set, a few seconds
    python benchmarks/bench_closed_form.py --repeats 50 --seed 3

Prints plain-text tables:

1. :func:`kinfw.identification.identify_closed_form` on the paper's protocol (Shih
   et al. 1992, section 4.1: nine values per joint, 6 x 9 + 1 = 55 configurations, both
   plates): median and IQR over the repeats, and a per-step breakdown obtained by calling
   the module's public step functions in the order ``identify_closed_form`` calls them
   (the module is not edited; the step-wise model is checked against the whole call).
2. Growth with the values per joint ``M``: samples, Step 1 pairs, median time, time per
   sample, Step 1 / Step 2 times, local log-log slopes, and the held-out position error of
   the identified model (so speed and accuracy are read together).
3. Ratios measured back to back in the same repeat on the same data: closed form over one
   vectorised CPC forward-kinematics evaluation of the dataset, and over Pinocchio FK of
   the dataset (a Python loop over samples). Absolute times depend on the machine; the
   ratios are the portable numbers.

Timing: ``time.perf_counter`` around each call, warm-up calls first, garbage collection
disabled while timing (as :mod:`timeit` does).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # for benchmarks.common (kinfw comes from pip install -e .)
    sys.path.insert(0, str(REPO))

import pinocchio as pin

import kinfw.identification._closed_form as cf
from benchmarks.common import (
    Timings,
    format_table,
    gc_disabled,
    machine_info,
    mode_line,
    parse_repeats,
    slope,
    time_interleaved,
    wall_time_line,
)
from kinfw.identification import one_joint_groups
from kinfw.measurements import Measurements, check_against_robot
from kinfw.model import CPCModel, Robot, cpc_from_geometry, cpc_from_robot, load_robot
from kinfw.simulation import one_joint_at_a_time, perturb_robot, random_configurations, simulate_at

HEAD_URDF = REPO / "robots" / "iis_head.urdf"
FRAMES = ("left_plate", "right_plate")
PAPER_PER_JOINT = 9
NOISE_M = 0.5e-3
NOISE_RAD = 0.01
N_TEST = 200
WARMUP = 3

FULL_PER_JOINT = (2, 3, 5, 9, 15, 25, 50, 100, 200)
QUICK_PER_JOINT = (2, 9, 50)
FULL_RATIO_PER_JOINT = (9, 50, 200)
QUICK_RATIO_PER_JOINT = (9,)
FULL_TRIALS = 10
QUICK_TRIALS = 2

STEP_NAMES = (
    "check_against_robot",
    "collect_frame_data",
    "identify_axes (axes, eqs. 33-35, 52)",
    "identify_translations (translations, eqs. 58-64)",
    "geometry_at_zero",
    "cpc_from_geometry (Step 3)",
)


# -- timing ------------------------------------------------------------------------------


def closed_form_by_steps(
    robot: Robot, measurements: Measurements
) -> tuple[CPCModel, NDArray[np.float64]]:
    """``identify_closed_form(robot, measurements).model``, timing each step.

    Calls the step functions of :mod:`kinfw.identification` in the order
    ``identify_closed_form`` does. Returns the model and the seconds per step, shape
    ``(len(STEP_NAMES),)``.
    """
    ticks = [time.perf_counter()]
    measurements = check_against_robot(measurements, robot)
    ticks.append(time.perf_counter())
    topo, q0, data, _sizes = cf.collect_frame_data(robot, measurements, None)
    ticks.append(time.perf_counter())
    axes, _residual, scale = cf.identify_axes(topo, data, measurements.source)
    ticks.append(time.perf_counter())
    w_T_e_q0, points, directions, p_scale, _rms = cf.identify_translations(
        topo, data, q0, axes, measurements.source
    )
    prismatic = ~np.array(topo.revolute)
    axes[prismatic] = directions[prismatic]
    scale[prismatic] = p_scale[prismatic]
    ticks.append(time.perf_counter())
    geometry = cf.geometry_at_zero(topo, axes, points, w_T_e_q0, q0)
    ticks.append(time.perf_counter())
    model = cpc_from_geometry(geometry)
    ticks.append(time.perf_counter())
    return model, np.diff(ticks)


def time_steps(
    robot: Robot, datasets: Sequence[Measurements], repeats: int
) -> NDArray[np.float64] | None:
    """Seconds per step of :func:`closed_form_by_steps`, round robin over ``datasets``.

    Returns an array of shape (len(datasets), len(STEP_NAMES), repeats), or None with a
    note printed when the step functions no longer match the calls above (the
    module's internals are free to change; the whole-call timings still hold).
    """
    try:
        closed_form_by_steps(robot, datasets[0])
    except (AttributeError, TypeError, ValueError) as exc:
        print(
            f"[per-step breakdown unavailable: kinfw.identification internals "
            f"changed ({type(exc).__name__}: {exc})]"
        )
        return None
    for _ in range(WARMUP):
        for measurements in datasets:
            closed_form_by_steps(robot, measurements)
    seconds = np.empty((len(datasets), len(STEP_NAMES), repeats))
    with gc_disabled():
        for r in range(repeats):
            for k, measurements in enumerate(datasets):
                seconds[k, :, r] = closed_form_by_steps(robot, measurements)[1]
    return seconds


# -- data --------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Case:
    """One simulated experiment: true robot, one-joint-at-a-time data, held-out configs."""

    truth: Robot
    joint_names: tuple[str, ...]
    qs: NDArray[np.float64]  # (n, J) training configurations, rad / m
    measurements: Measurements
    test_qs: NDArray[np.float64]  # (N_TEST, J)
    w_T_test_frames: NDArray[np.float64]  # (N_TEST, E, 4, 4) true poses, metres


def make_case(nominal: Robot, per_joint: int, rng: np.random.Generator) -> Case:
    """A perturbed true head, its noisy protocol data and noise-free held-out poses."""
    truth = load_robot(perturb_robot(nominal, rng))
    names = truth.topology(FRAMES).joint_names
    lower, upper = truth.joint_limits(names)
    qs, _moved = one_joint_at_a_time(lower, upper, per_joint=per_joint)
    measurements = simulate_at(
        truth, qs, names, frames=FRAMES, rng=rng, noise_m=NOISE_M, noise_rad=NOISE_RAD
    )
    test_qs = random_configurations(lower, upper, N_TEST, rng)
    w_T_test = np.stack([truth.frame_poses(test_qs, f, names) for f in FRAMES], axis=1)
    return Case(truth, names, qs, measurements, test_qs, w_T_test)


def held_out_error_mm(model: CPCModel, case: Case) -> float:
    """Mean position error norm (mm) of ``model`` over the held-out configs and frames.

    Against the true robot's Pinocchio FK without noise: the error of the identified
    model itself, not of a noisy measurement of it.
    """
    if model.topology.joint_names != case.joint_names or model.topology.frames != FRAMES:
        raise ValueError(
            f"model topology {model.topology.joint_names} / "
            f"{model.topology.frames} does not match the case's"
        )
    w_T_frames = model.frame_poses(case.test_qs)
    dp = w_T_frames[..., :3, 3] - case.w_T_test_frames[..., :3, 3]
    return 1e3 * float(np.linalg.norm(dp, axis=-1).mean())


def step1_pairs(nominal: Robot, case: Case) -> int:
    """Rotation pairs Step 1 stacks: per revolute joint and end frame below it, every pair
    of the samples where only that joint moved or none did (its group)."""
    topo = nominal.topology(FRAMES)
    _q0, moved = one_joint_groups(case.qs, case.joint_names, "<benchmark>")
    total = 0
    for j in np.flatnonzero(topo.revolute):
        rows = int(np.sum((moved == j) | (moved == -1)))
        total += sum(rows * (rows - 1) // 2 for f in topo.frames if j in topo.chain(f))
    return total


# -- sections ----------------------------------------------------------------------------


def section_paper_protocol(nominal: Robot, case: Case, repeats: int) -> None:
    print(
        f"\n1. Closed form on the paper's protocol: {PAPER_PER_JOINT} values per joint, "
        f"{len(case.qs)} configurations x {len(FRAMES)} plates, {repeats} repeats"
    )
    (whole,) = time_interleaved(
        [lambda: cf.identify_closed_form(nominal, case.measurements)], repeats, warmup=WARMUP
    )
    model_whole = cf.identify_closed_form(nominal, case.measurements).model
    rows = []
    steps = time_steps(nominal, [case.measurements], repeats)
    if steps is not None:
        steps = steps[0]
        total = Timings(steps.sum(axis=0))
        rows = [
            [
                name,
                f"{Timings(s).median_ms:.3f}",
                f"{Timings(s).iqr_ms:.3f}",
                f"{100 * np.median(s) / np.median(total.seconds):.1f}",
            ]
            for name, s in zip(STEP_NAMES, steps, strict=True)
        ]
        rows.append(["sum of steps", f"{total.median_ms:.3f}", f"{total.iqr_ms:.3f}", "100.0"])
    rows.append(
        ["identify_closed_form (whole call)", f"{whole.median_ms:.3f}", f"{whole.iqr_ms:.3f}", ""]
    )
    print(format_table(["step", "median ms", "IQR ms", "% of sum"], rows))
    if steps is not None:
        model_steps, _ = closed_form_by_steps(nominal, case.measurements)
        same = all(
            np.allclose(getattr(model_steps, a), getattr(model_whole, a), rtol=0.0, atol=1e-12)
            for a in ("b", "beta", "l", "sign", "tool_T")
        )
        print(
            "Per-step times: kinfw.identification's steps collect_frame_data, "
            "identify_axes,\nidentify_translations, geometry_at_zero and "
            "kinfw.model.cpc_from_geometry called in identify_closed_form's order\n"
            "(identify_translations row includes the prismatic fix-up). Step-wise model == "
            "whole-call\nmodel (atol 1e-12): "
            f"{same}."
        )
    print(
        f"Held-out position error of this estimate: {held_out_error_mm(model_whole, case):.3f}"
        f" mm (mean over {N_TEST} random configurations x {len(FRAMES)} plates)."
    )


def section_growth(
    nominal: Robot, per_joints: Sequence[int], repeats: int, trials: int, seed: int
) -> None:
    print(
        f"\n2. Growth with values per joint M ({repeats} repeats; held-out error: mean "
        f"over {trials} true robots,\n   each {N_TEST} random test configurations x "
        f"{len(FRAMES)} plates vs noise-free truth;\n   training noise sigma "
        f"{1e3 * NOISE_M:g} mm per axis, {NOISE_RAD:g} rad rotation)"
    )
    cases = []
    for m in per_joints:
        rng = np.random.default_rng([seed, m])
        cases.append([make_case(nominal, m, rng) for _ in range(trials)])
    first = [c[0] for c in cases]  # the timed dataset of each M
    wholes = time_interleaved(
        [lambda c=c: cf.identify_closed_form(nominal, c.measurements) for c in first],
        repeats,
        warmup=WARMUP,
    )
    steps = time_steps(nominal, [c.measurements for c in first], repeats)
    steps_ms = (
        np.full((len(first), len(STEP_NAMES)), np.nan)
        if steps is None
        else 1e3 * np.median(steps, axis=2)
    )
    n_samples = [len(c.qs) for c in first]
    medians = [w.median_ms for w in wholes]
    step1, step2 = steps_ms[:, 2], steps_ms[:, 3]
    rows, nominal_mm = [], []
    for k, (m, trial_cases, whole) in enumerate(zip(per_joints, cases, wholes, strict=True)):
        errors = [
            held_out_error_mm(cf.identify_closed_form(nominal, c.measurements).model, c)
            for c in trial_cases
        ]
        nominal_mm += [held_out_error_mm(cpc_from_robot(nominal, FRAMES), c) for c in trial_cases]
        local = "" if k == 0 else f"{slope(n_samples[k - 1 : k + 1], medians[k - 1 : k + 1]):.2f}"
        sd = np.std(errors, ddof=1) if trials > 1 else np.nan
        pairs = step1_pairs(nominal, first[k])
        rows.append(
            [
                f"{m}",
                f"{n_samples[k]}",
                f"{pairs}",
                f"{whole.median_ms:.2f}",
                f"{whole.iqr_ms:.2f}",
                f"{1e3 * whole.median_ms / n_samples[k]:.1f}",
                f"{step1[k]:.2f}",
                f"{1e3 * step1[k] / pairs:.2f}",
                f"{step2[k]:.2f}",
                local,
                f"{np.mean(errors):.3f}",
                f"{sd:.3f}",
            ]
        )
    print(
        format_table(
            [
                "M",
                "samples",
                "S1 pairs",
                "median ms",
                "IQR ms",
                "us/sample",
                "step1 ms",
                "us/pair",
                "step2 ms",
                "slope",
                "held-out mm",
                "sd mm",
            ],
            rows,
        )
    )
    print(
        f"samples = {len(first[0].joint_names)} M + 1 configurations, each measuring both "
        "plates.\nS1 pairs = rotation pairs Step 1 stacks: per revolute joint and per frame "
        "below it, every\npair of its M + 1 group samples (its M values and q0), C(M+1, 2): "
        "O(M^2) per joint.\nstep1/step2 ms = medians of the per-step timing; us/pair = step1 "
        "time per S1 pair.\nslope = local d log(time) / d log(samples); sd mm = across true "
        "robots."
    )
    large = [k for k, m in enumerate(per_joints) if m >= 25]
    if len(large) >= 2:
        pick = [n_samples[k] for k in large]
        fits = [
            f"{label} ~ samples^{slope(pick, [ys[k] for k in large]):.2f}"
            for label, ys in (("total", medians), ("step1", step1), ("step2", step2))
        ]
        print(f"Observed log-log fit over M >= 25: {', '.join(fits)}.")
    print(f"Nominal (uncalibrated) URDF on the same test sets: {np.mean(nominal_mm):.3f} mm.")


def section_ratios(nominal: Robot, per_joints: Sequence[int], repeats: int, seed: int) -> None:
    print(
        f"\n3. Ratios on the same data in the same run ({repeats} repeats; in each repeat "
        "the four calls\n   of every M are timed back to back; ratio = median over repeats "
        "of the per-repeat ratio)"
    )
    cases = [make_case(nominal, m, np.random.default_rng([seed, m])) for m in per_joints]
    calls: list[Callable[[], object]] = []
    for case in cases:
        truth_model = cpc_from_robot(case.truth, FRAMES)
        calls += [
            lambda c=case: cf.identify_closed_form(nominal, c.measurements),
            lambda c=case, t=truth_model: t.frame_poses(c.qs),
            lambda c=case: cpc_from_robot(c.truth, FRAMES).frame_poses(c.qs),
            lambda c=case: [c.truth.frame_poses(c.qs, f, c.joint_names) for f in FRAMES],
        ]
    timings = time_interleaved(calls, repeats, warmup=WARMUP)
    rows = []
    for k, (m, case) in enumerate(zip(per_joints, cases, strict=True)):
        closed, cpc_fk, cpc_build_fk, pin_fk = timings[4 * k : 4 * k + 4]

        def ratio(other: Timings, closed: Timings = closed) -> str:
            return f"{np.median(closed.seconds / other.seconds):.1f}"

        rows.append(
            [
                f"{m}",
                f"{len(case.qs)}",
                f"{closed.median_ms:.3f}",
                f"{cpc_fk.median_ms:.3f}",
                f"{cpc_build_fk.median_ms:.3f}",
                f"{pin_fk.median_ms:.3f}",
                ratio(cpc_fk),
                ratio(cpc_build_fk),
                ratio(pin_fk),
            ]
        )
    print(
        format_table(
            [
                "M",
                "samples",
                "CF ms",
                "CPC FK ms",
                "CPC+build ms",
                "Pin FK ms",
                "CF/CPC FK",
                "CF/CPC+build",
                "CF/Pin FK",
            ],
            rows,
        )
    )
    print(
        "CF = identify_closed_form(nominal, data).\n"
        "CPC FK = model.frame_poses(qs), model = cpc_from_robot(truth, frames) built "
        "beforehand\n  (numpy, vectorised over samples, both frames in one call).\n"
        "CPC+build = cpc_from_robot(truth, frames).frame_poses(qs), construction included.\n"
        "Pin FK = truth.frame_poses(qs, frame, names) per frame (Pinocchio, a Python loop "
        "over samples)."
    )


def main(argv: Sequence[str] | None = None) -> int:
    args, repeats = parse_repeats(
        argv,
        __doc__.splitlines()[0],
        full=30,
        quick=5,
        quick_help=f"M in {QUICK_PER_JOINT}, ratios at M = {QUICK_RATIO_PER_JOINT}, "
        f"{QUICK_TRIALS} accuracy trials",
    )
    per_joints = QUICK_PER_JOINT if args.quick else FULL_PER_JOINT
    ratio_per_joints = QUICK_RATIO_PER_JOINT if args.quick else FULL_RATIO_PER_JOINT
    trials = QUICK_TRIALS if args.quick else FULL_TRIALS

    started = time.perf_counter()
    print("kinfw closed-form benchmark (IIS-head, frames " + ", ".join(FRAMES) + ")")
    print(machine_info([("pinocchio", pin.__version__)]))
    print(mode_line(args, repeats, WARMUP))
    nominal = load_robot(HEAD_URDF)
    paper = make_case(nominal, PAPER_PER_JOINT, np.random.default_rng([args.seed, PAPER_PER_JOINT]))
    section_paper_protocol(nominal, paper, repeats)
    section_growth(nominal, per_joints, repeats, trials, args.seed)
    section_ratios(nominal, ratio_per_joints, repeats, args.seed)
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
