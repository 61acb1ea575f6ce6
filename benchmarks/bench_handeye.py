"""Hand-eye solvers against OpenCV: accuracy and speed on the same data, side by side.

Run from the repository root (OpenCV is the ``bench`` extra, not a kinfw dependency:
``pip install -e '.[bench]'`` or ``pip install "opencv-python-headless>=4.10,<5"``)::

    python benchmarks/bench_handeye.py              # full run, under ~3 minutes
    python benchmarks/bench_handeye.py --quick      # reduced set, a few seconds
    python benchmarks/bench_handeye.py --trials 300 --seed 3

Prints plain-text tables:

1. AX = XB (hand-eye; the robot-world transform plays no part):
   :func:`identification.handeye.solve_axxb` against OpenCV's ``calibrateHandEye`` with
   Tsai, Park and Daniilidis. Per noise setting and number of views: rotation (deg) and
   translation (mm) error of X = hand_T_eye, median and IQR over the trials, median time
   per solve, OpenCV's silent identity answers and the failures (an exception or a
   non-finite result). A small-motion probe follows (relative rotations < 16 deg, where
   OpenCV's Tsai answers the identity with only a log line; OpenCV documents no limit).
2. A = X B Y (robot-world and hand-eye): :func:`identification.axb.solve_axyb` refined
   (``refine=True``) and the paper's pure iteration (``refine=False``) against
   ``calibrateRobotWorldHandEye`` with Shah and Li: errors of X = cam_T_hand and
   Y = base_T_world, time per solve. ``--subset-trials`` runs the pure iteration, which
   can be slow when it does not converge, on the first trials only.
3. Tabb DS1 (a real robot and camera, 88 poses): every method of both problems against
   Tabb's reprojection-optimised reference, once with the lengths in millimetres (as
   published) and once in metres; the last column shows whose answer changes with the
   length unit.
4. Summary per setting: our median error over the best OpenCV median error of the same
   column (on the trials our method ran), and our time over the fastest OpenCV method's
   time in the same trial (median of the per-trial ratios); < 1 means kinfw is better.
   Every loss is then printed with its numbers and the count of trials in which kinfw
   was nonetheless closer to the truth than that OpenCV method.

Synthetic data, one draw per trial, shared by every solver and by both problems (metres):
true hand_T_cam with a uniformly random rotation and a translation N(0, 5 cm) per axis;
a reference hand pose with the camera looking at the target origin 0.6 m in front of it;
robot poses base_T_hand = reference rotated by U(0, 75 deg) about a uniformly random axis
and shifted by U(-0.25, 0.25) m per axis; exact robot poses; camera poses
cam_T_world = inv(hand_T_cam) inv(base_T_hand) base_T_world made noisy with
:func:`verification.simulate.perturb_poses` (rotation by N(0, sigma) about a random axis,
translation N(0, sigma_t) per axis). The views n = 3, 5, 10, 30 are the first n poses of
one set of 30, and every noise level draws from the same seed (per trial and n), so the
levels differ only in scale.

Timing: ``time.perf_counter`` around each call, after warm-up rounds, garbage collection
disabled while timing; in every trial the methods are called round robin on the same
data, and a trial's time is the median of its timed calls (a call slower than 5 ms is
timed once and warmed up once). Inputs are handed over in each
library's own format, prepared outside the timed call (4x4 stacks for kinfw, contiguous
R/t stacks for OpenCV). OpenCV's log is silenced; identity answers are counted instead.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import re
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # benchmark the code next to this script, installed or not
    sys.path.insert(0, str(REPO))

try:
    import cv2
except ImportError as err:  # pragma: no cover - the message is the point
    sys.exit(
        'bench_handeye.py needs OpenCV 4: pip install "opencv-python-headless>=4.10,<5" '
        f"(the 'bench' extra of kinfw; wheels before 4.10 do not load with NumPy 2): {err}"
    )

from benchmarks.common import (  # noqa: E402
    format_table,
    gc_disabled,
    machine_info,
    wall_time_line,
)
from identification.axb import solve_axyb  # noqa: E402
from identification.handeye import solve_axxb  # noqa: E402
from kinfw.transforms import (  # noqa: E402
    inverse_transform,
    matrix_from_rotation_vector,
    rotation_angle,
    transform_from_rotation_translation,
    transform_from_xyz_quat_xyzw,
)
from verification.simulate import perturb_poses  # noqa: E402

TABB_JSON = REPO / "tests" / "data" / "tabb_ds1" / "tabb_ds1_pairs.json"  # README there
TABB_A_KEY = "T_world2cam (A_i = cTw, from cali.txt)"
TABB_B_KEY = "T_base2gripper (B_i = gTb, from robot_cali.txt)"
TABB_REF_KEY = "reference_rwhe_AA_RPI"
TABB_X_KEY = "Z = cTg (gripper2cam)"  # Tabb's Z is our X of A = X B Y
TABB_YINV_KEY = "X = wTb (base2world)"  # Tabb's X is our inv(Y)
OPENCV_TEST_DEG, OPENCV_TEST_MM = 1.0, 50.0  # Calib3d_CalibrateRobotWorldHandEye.regression

FULL_VIEWS = (3, 5, 10, 30)
QUICK_VIEWS = (3, 10)
FULL_TRIALS = 100
QUICK_TRIALS = 5
# (rotation sigma deg, translation sigma mm per axis) on the camera poses
NOISE_LEVELS = ((0.0, 0.0), (0.5, 1.0), (1.0, 2.0))
MAX_ROTATION_DEG = 75.0  # robot poses: reference rotated by U(0, this) about a random axis
HALF_SHIFT_M = 0.25  # robot poses: reference shifted by U(-this, this) per axis
TARGET_DISTANCE_M = 0.6  # target origin in front of the camera at the reference pose
HAND_CAM_SIGMA_M = 0.05  # true hand_T_cam translation, N(0, this) per axis
SMALL_MOTION_DEG = 8.0  # probe: pairwise relative rotations < 16 deg
SMALL_MOTION_VIEWS = 10
TIMED_CALLS = 3
WARMUP = 3
SLOW_S = 5e-3  # a call slower than this is timed once per trial, warmed up once
TABB_TIMED_CALLS = 5
TABB_SLOW_S = 0.05
EXACT_DEG, EXACT_MM = 1e-9, 1e-6  # below these an error is rounding: no ratio is printed
IDENTITY_ATOL = 1e-12

TSAI = cv2.CALIB_HAND_EYE_TSAI
PARK = cv2.CALIB_HAND_EYE_PARK
DANIILIDIS = cv2.CALIB_HAND_EYE_DANIILIDIS
SHAH = cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH
LI = cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI


# -- data --------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Scene:
    """One true setup and its robot poses (metres); camera poses come noisy from ``views``."""

    hand_T_cam: NDArray[np.float64]  # (4, 4) truth of AX = XB's X
    base_T_world: NDArray[np.float64]  # (4, 4) truth of A = X B Y's Y
    base_T_hands: NDArray[np.float64]  # (N, 4, 4) exact robot poses
    seed: tuple[int, ...]  # of the camera-pose noise


@dataclass(frozen=True, slots=True)
class Views:
    """The data every solver sees in one trial, in our conventions (metres or mm)."""

    base_T_hands: NDArray[np.float64]  # (n, 4, 4)  AX = XB's A
    cam_T_worlds: NDArray[np.float64]  # (n, 4, 4)  AX = XB's B (target = world); A = X B Y's A
    hand_T_bases: NDArray[np.float64]  # (n, 4, 4)  A = X B Y's B


def random_rotations(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    """``n`` uniformly distributed rotations (normalised Gaussian quaternions), (n, 3, 3)."""
    return transform_from_xyz_quat_xyzw(np.zeros((n, 3)), rng.normal(size=(n, 4)))[:, :3, :3]


def make_scene(
    rng: np.random.Generator, n: int, max_rotation_deg: float, seed: tuple[int, ...]
) -> Scene:
    """A random true setup seen from ``n`` robot poses (see the module docstring)."""
    rotations = random_rotations(rng, 3)
    hand_T_cam = transform_from_rotation_translation(
        rotations[0], rng.normal(0.0, HAND_CAM_SIGMA_M, 3)
    )
    base_T_hand0 = transform_from_rotation_translation(
        rotations[1], np.array([0.5, 0.0, 0.4]) + rng.normal(0.0, 0.05, 3)
    )
    cam0_T_world = transform_from_rotation_translation(
        rotations[2], np.array([0.0, 0.0, TARGET_DISTANCE_M])
    )
    base_T_world = base_T_hand0 @ hand_T_cam @ cam0_T_world
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.radians(rng.uniform(0.0, max_rotation_deg, n))
    hand0_R_hands = matrix_from_rotation_vector(axes * angles[:, None])
    base_T_hands = transform_from_rotation_translation(
        base_T_hand0[:3, :3] @ hand0_R_hands,
        base_T_hand0[:3, 3] + rng.uniform(-HALF_SHIFT_M, HALF_SHIFT_M, (n, 3)),
    )
    return Scene(hand_T_cam, base_T_world, base_T_hands, seed)


def views(scene: Scene, n: int, noise: tuple[float, float]) -> Views:
    """The first ``n`` poses of ``scene`` with camera poses noisy by (deg, mm per axis)."""
    base_T_hands = scene.base_T_hands[:n]
    cam_T_worlds = (
        inverse_transform(scene.hand_T_cam) @ inverse_transform(base_T_hands) @ scene.base_T_world
    )
    noisy = perturb_poses(
        cam_T_worlds, np.random.default_rng([*scene.seed, n]), 1e-3 * noise[1], np.radians(noise[0])
    )
    return Views(base_T_hands, noisy, inverse_transform(base_T_hands))


def scaled(v: Views, metres_per_unit: float) -> Views:
    """``v`` with every length divided by ``metres_per_unit``."""

    def s(T: NDArray[np.float64]) -> NDArray[np.float64]:
        out = T.copy()
        out[:, :3, 3] /= metres_per_unit
        return out

    return Views(s(v.base_T_hands), s(v.cam_T_worlds), s(v.hand_T_bases))


# -- methods -----------------------------------------------------------------------------

# prepare(views) -> (call, read): call() is timed, read(call()) gives the estimates as 4x4
# transforms in our conventions: (hand_T_eye,) for AX = XB, (cam_T_hand, base_T_world) for
# A = X B Y.
Estimates = tuple[NDArray[np.float64], ...]
Prepare = Callable[[Views], tuple[Callable[[], object], Callable[[object], Estimates]]]


@dataclass(frozen=True, slots=True)
class Method:
    name: str
    ours: bool
    prepare: Prepare
    subset: bool = False  # run on the first --subset-trials trials only (slow)


def rt(T: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Contiguous rotation (n, 3, 3) and translation (n, 3, 1) stacks, OpenCV's input."""
    return np.ascontiguousarray(T[:, :3, :3]), np.ascontiguousarray(T[:, :3, 3:])


def transform(R: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    return transform_from_rotation_translation(R, np.ravel(t))


def ours_axxb(v: Views) -> tuple[Callable[[], object], Callable[[object], Estimates]]:
    return (lambda: solve_axxb(v.base_T_hands, v.cam_T_worlds)), (lambda r: (r.hand_T_camera,))


def opencv_axxb(method: int) -> Prepare:
    def prepare(v: Views) -> tuple[Callable[[], object], Callable[[object], Estimates]]:
        R_gripper2base, t_gripper2base = rt(v.base_T_hands)
        R_target2cam, t_target2cam = rt(v.cam_T_worlds)

        def call() -> object:
            return cv2.calibrateHandEye(
                R_gripper2base=R_gripper2base,
                t_gripper2base=t_gripper2base,
                R_target2cam=R_target2cam,
                t_target2cam=t_target2cam,
                method=method,
            )

        return call, lambda out: (transform(*out),)  # cam2gripper = hand_T_eye

    return prepare


def ours_axyb(refine: bool) -> Prepare:
    def prepare(v: Views) -> tuple[Callable[[], object], Callable[[object], Estimates]]:
        return (
            (lambda: solve_axyb(v.cam_T_worlds, v.hand_T_bases, refine=refine)),
            (lambda r: (r.camera_T_hand, r.root_T_target)),
        )

    return prepare


def opencv_axyb(method: int) -> Prepare:
    def prepare(v: Views) -> tuple[Callable[[], object], Callable[[object], Estimates]]:
        R_world2cam, t_world2cam = rt(v.cam_T_worlds)
        R_base2gripper, t_base2gripper = rt(v.hand_T_bases)

        def call() -> object:
            return cv2.calibrateRobotWorldHandEye(
                R_world2cam=R_world2cam,
                t_world2cam=t_world2cam,
                R_base2gripper=R_base2gripper,
                t_base2gripper=t_base2gripper,
                method=method,
            )

        def read(out: object) -> Estimates:
            R_base2world, t_base2world, R_gripper2cam, t_gripper2cam = out  # type: ignore[misc]
            # base2world = world_T_base = inv(Y); gripper2cam = cam_T_hand = X
            return (
                transform(R_gripper2cam, t_gripper2cam),
                inverse_transform(transform(R_base2world, t_base2world)),
            )

        return call, read

    return prepare


AXXB_METHODS = (
    Method("kinfw solve_axxb", True, ours_axxb),
    Method("OpenCV TSAI", False, opencv_axxb(TSAI)),
    Method("OpenCV PARK", False, opencv_axxb(PARK)),
    Method("OpenCV DANIILIDIS", False, opencv_axxb(DANIILIDIS)),
)
AXYB_METHODS = (
    Method("kinfw solve_axyb", True, ours_axyb(refine=True)),
    Method("kinfw refine=False", True, ours_axyb(refine=False), subset=True),
    Method("OpenCV SHAH", False, opencv_axyb(SHAH)),
    Method("OpenCV LI", False, opencv_axyb(LI)),
)


# -- running -----------------------------------------------------------------------------


@dataclass(slots=True)
class Outcome:
    """One method over the trials of one setting: errors (trials, 2 per transform) in deg
    and mm and seconds per solve (trials,), NaN where it failed or was not run; counts of
    runs, identity answers, answers flagged ``converged=False``, failures."""

    errors: NDArray[np.float64]
    seconds: NDArray[np.float64]
    runs: int = 0
    identity: int = 0
    unconverged: int = 0
    failed: int = 0
    messages: dict[str, list] = field(default_factory=dict)  # kind -> [count, example]

    def add_failure(self, msg: str) -> None:
        """Count a failure under its message with the numbers masked; keep one example."""
        kind = re.sub(r"\d[\d.e+-]*", "#", msg)
        self.failed += 1
        self.messages.setdefault(kind, [0, msg])[0] += 1


def errors_deg_mm(
    estimates: Estimates, truths: Estimates, metres_per_unit: float = 1.0
) -> NDArray[np.float64]:
    """Rotation angle (deg) and translation distance (mm) of each estimate from its truth."""
    out = []
    for est, true in zip(estimates, truths, strict=True):
        out.append(np.degrees(float(rotation_angle(est[:3, :3].T @ true[:3, :3]))))
        out.append(1e3 * metres_per_unit * float(np.linalg.norm(est[:3, 3] - true[:3, 3])))
    return np.array(out)


def is_identity(T: NDArray[np.float64]) -> bool:
    return bool(np.abs(T - np.eye(4)).max() < IDENTITY_ATOL)


def timed(call: Callable[[], object]) -> tuple[float, object, BaseException | None]:
    start = time.perf_counter()
    try:
        result = call()
    except Exception as exc:  # a refusal or a failure; counted, not fatal
        return time.perf_counter() - start, None, exc
    return time.perf_counter() - start, result, None


def read_result(
    read: Callable[[object], Estimates], result: object, exc: BaseException | None
) -> tuple[Estimates | None, str | None]:
    """The estimates of one call, or None and a one-line message when it failed."""
    estimates = None
    if exc is None:
        try:
            estimates = read(result)
        except Exception as read_exc:
            exc = read_exc
    if exc is None and estimates is not None and not all(np.isfinite(e).all() for e in estimates):
        exc = FloatingPointError("non-finite result")
    if exc is not None or estimates is None:
        return None, f"{type(exc).__name__}: {str(exc).strip().splitlines()[0]}"
    return estimates, None


def run_setting(
    methods: Sequence[Method],
    trials: Sequence[Views],
    truths: Sequence[Estimates],
    *,
    subset_trials: int,
    metres_per_unit: float = 1.0,
    timed_calls: int = TIMED_CALLS,
) -> list[Outcome]:
    """Every method on every trial (``subset`` methods on the first ``subset_trials``),
    round robin within a trial, after warm-up calls on the first trial.

    A method whose first call of a trial takes longer than ``SLOW_S`` is timed by that
    call alone; the others are called ``timed_calls`` times and their median is kept.
    """
    k = 2 * len(truths[0])
    outcomes = [
        Outcome(np.full((len(trials), k), np.nan), np.full(len(trials), np.nan)) for _ in methods
    ]
    prepared = [[m.prepare(v) for m in methods] for v in trials]
    for call, _read in prepared[0]:
        if timed(call)[0] < SLOW_S:
            for _ in range(WARMUP - 1):
                timed(call)
    with gc_disabled():
        for t, (calls, truth) in enumerate(zip(prepared, truths, strict=True)):
            active = [j for j, m in enumerate(methods) if not m.subset or t < subset_trials]
            seconds: list[list[float]] = [[] for _ in methods]
            results: list[tuple[object, BaseException | None]] = [(None, None)] * len(methods)
            for r in range(timed_calls):
                for j in active:
                    if r > 0 and seconds[j][0] >= SLOW_S:
                        continue
                    s, result, exc = timed(calls[j][0])
                    seconds[j].append(s)
                    results[j] = (result, exc)
            for j in active:
                out = outcomes[j]
                out.runs += 1
                out.seconds[t] = np.median(seconds[j])
                result, exc = results[j]
                estimates, msg = read_result(calls[j][1], result, exc)
                if estimates is None:
                    out.add_failure(str(msg))
                    continue
                out.identity += int(is_identity(estimates[0]))
                out.unconverged += int(not getattr(result, "converged", True))
                out.errors[t] = errors_deg_mm(estimates, truth, metres_per_unit)
    return outcomes


# -- output ------------------------------------------------------------------------------


def git_head() -> str:
    try:
        out = subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        )
    except (OSError, subprocess.SubprocessError):
        return "n/a"
    return out.stdout.strip()


def solver_digests() -> list[tuple[str, str]]:
    """Short content hashes of the benchmarked modules (they may be uncommitted)."""
    out = []
    for rel in (
        "identification/handeye.py",
        "identification/axb.py",
        "identification/axb_iteration.py",
        "identification/axb_refinement.py",
    ):
        path = REPO / rel
        digest = hashlib.sha256(path.read_bytes()).hexdigest()[:12] if path.exists() else "n/a"
        out.append((rel, digest))
    return out


def g(x: float) -> str:
    return "fail" if not np.isfinite(x) else f"{x:.3g}"


def medians(out: Outcome, trials: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
    """Median of each error column over the trials (of ``trials``, a mask) that ran and did
    not fail; NaN if none."""
    ok = ~np.isnan(out.errors[:, 0]) & (True if trials is None else trials)
    return np.median(out.errors[ok], axis=0) if ok.any() else np.full(out.errors.shape[1], np.nan)


def iqrs(out: Outcome) -> NDArray[np.float64]:
    ok = ~np.isnan(out.errors[:, 0])
    if not ok.any():
        return np.full(out.errors.shape[1], np.nan)
    q25, q75 = np.percentile(out.errors[ok], [25.0, 75.0], axis=0)
    return q75 - q25


def best_opencv(
    methods: Sequence[Method], outcomes: Sequence[Outcome], trials: NDArray[np.bool_] | None = None
) -> tuple[NDArray[np.int_], int]:
    """Index of the OpenCV method with the lowest median in each error column, and of the
    fastest one (median time), over ``trials`` (a mask; default all)."""
    theirs = [j for j, m in enumerate(methods) if not m.ours]
    med = np.array([medians(outcomes[j], trials) for j in theirs])
    med = np.where(np.isnan(med), np.inf, med)
    mask = np.ones(len(outcomes[0].seconds), bool) if trials is None else trials
    times = [np.nanmedian(outcomes[j].seconds[mask]) for j in theirs]
    return np.array(theirs)[np.argmin(med, axis=0)], theirs[int(np.argmin(times))]


def setting_rows(n: int, methods: Sequence[Method], outcomes: Sequence[Outcome]) -> list[list[str]]:
    best_err, best_time = best_opencv(methods, outcomes)
    rows = []
    for j, (m, out) in enumerate(zip(methods, outcomes, strict=True)):
        med, iqr = medians(out), iqrs(out)
        cells = [f"{n}" if j == 0 else "", m.name]
        for c in range(len(med)):
            star = "*" if best_err[c] == j else ""
            cells += [g(med[c]) + star, g(iqr[c])]
        us = 1e6 * float(np.nanmedian(out.seconds))
        cells += [
            f"{us:.1f}" + ("*" if best_time == j else ""),
            f"{out.identity}",
            f"{out.unconverged}",
            f"{out.failed}",
            f"{out.runs}",
        ]
        rows.append(cells)
    return rows


def print_notes(
    methods: Sequence[Method], per_n: Sequence[Sequence[Outcome]], views_list: Sequence[int]
) -> None:
    for n, outcomes in zip(views_list, per_n, strict=True):
        for m, out in zip(methods, outcomes, strict=True):
            for count, example in out.messages.values():
                print(f"  n={n}: {m.name} failed {count}x, e.g. {example[:150]}")


def error_headers(names: Sequence[str]) -> list[str]:
    heads = []
    for name in names:
        heads += [f"{name} rot deg", "IQR", f"{name} mm", "IQR"]
    return heads


COUNT_HEADERS = ["us/solve", "ident", "unconv", "fail", "runs"]
COUNT_NOTE = (
    "ident = answers equal to the identity (OpenCV's silent failure); unconv = "
    "answers flagged\nconverged=False; fail = exceptions or non-finite answers "
    "(excluded from the medians);\nruns = trials run."
)


# -- sections ----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Summary:
    problem: str
    noise: tuple[float, float]
    n: int
    method: str
    columns: tuple[str, ...]
    ours: NDArray[np.float64]  # median errors
    best: NDArray[np.float64]  # best OpenCV median error per column
    best_names: tuple[str, ...]
    wins: tuple[str, ...]  # per column: trials where ours < that best method, "k of m"
    time_ratio: float  # median over trials of ours / fastest OpenCV, same trial
    fastest: str


def summarise(
    problem: str,
    noise: tuple[float, float],
    n: int,
    methods: Sequence[Method],
    outcomes: Sequence[Outcome],
    columns: tuple[str, ...],
) -> list[Summary]:
    out = []
    for m, o in zip(methods, outcomes, strict=True):
        if m.ours:
            run = ~np.isnan(o.seconds)  # compare on the trials this method ran
            best_err, best_time = best_opencv(methods, outcomes, run)
            best = np.array([medians(outcomes[j], run)[c] for c, j in enumerate(best_err)])
            wins = []
            for c, j in enumerate(best_err):
                both = ~np.isnan(o.errors[:, c]) & ~np.isnan(outcomes[j].errors[:, c])
                lower = int(np.sum(o.errors[both, c] < outcomes[j].errors[both, c]))
                wins.append(f"{lower} of {int(both.sum())}")
            ratio = float(np.nanmedian(o.seconds / outcomes[best_time].seconds))
            out.append(
                Summary(
                    problem,
                    noise,
                    n,
                    m.name,
                    columns,
                    medians(o),
                    best,
                    tuple(methods[j].name for j in best_err),
                    tuple(wins),
                    ratio,
                    methods[best_time].name,
                )
            )
    return out


def noise_label(noise: tuple[float, float]) -> str:
    return "no noise" if noise == (0.0, 0.0) else f"{noise[0]:g} deg + {noise[1]:g} mm/axis"


def section_synthetic(
    title: str,
    problem: str,
    methods: Sequence[Method],
    scenes: Sequence[Scene],
    views_list: Sequence[int],
    noises: Sequence[tuple[float, float]],
    truths: Callable[[Scene], Estimates],
    names: Sequence[str],
    subset_trials: int,
) -> list[Summary]:
    print(f"\n{title}")
    slow = [m.name for m in methods if m.subset]
    if slow and subset_trials < len(scenes):
        print(
            f"   ({', '.join(slow)}: first {subset_trials} trials only, see --subset-trials; "
            "its ratios\n   and win counts use those trials)"
        )
    summaries = []
    for noise in noises:
        per_n = []
        rows: list[list[str]] = []
        for n in views_list:
            trials = [views(s, n, noise) for s in scenes]
            outcomes = run_setting(
                methods, trials, [truths(s) for s in scenes], subset_trials=subset_trials
            )
            per_n.append(outcomes)
            rows += setting_rows(n, methods, outcomes)
            summaries += summarise(
                problem,
                noise,
                n,
                methods,
                outcomes,
                tuple(f"{x} {u}" for x in names for u in ("rot", "mm")),
            )
        print(
            f"\n{problem}, camera-pose noise {noise_label(noise)}, {len(scenes)} trials "
            "(median, IQR over trials; * = best OpenCV method in the column)"
        )
        print(format_table(["n", "method", *error_headers(names), *COUNT_HEADERS], rows))
        print_notes(methods, per_n, views_list)
    print(COUNT_NOTE)
    return summaries


def section_small_motion(trials: int, seed: int) -> list[Summary]:
    print(
        f"\n1b. AX = XB with small motions: {SMALL_MOTION_VIEWS} poses rotated "
        f"U(0, {SMALL_MOTION_DEG:g} deg) from the reference\n    (every relative "
        f"rotation < {2 * SMALL_MOTION_DEG:g} deg), {trials} trials"
    )
    scenes = [
        make_scene(
            np.random.default_rng([seed, 1, t]), SMALL_MOTION_VIEWS, SMALL_MOTION_DEG, (seed, 1, t)
        )
        for t in range(trials)
    ]
    rows: list[list[str]] = []
    notes = []
    summaries = []
    for noise in NOISE_LEVELS:
        outcomes = run_setting(
            AXXB_METHODS,
            [views(s, SMALL_MOTION_VIEWS, noise) for s in scenes],
            [(s.hand_T_cam,) for s in scenes],
            subset_trials=trials,
        )
        summaries += summarise(
            "AX = XB, small motions",
            noise,
            SMALL_MOTION_VIEWS,
            AXXB_METHODS,
            outcomes,
            ("X rot", "X mm"),
        )
        for j, r in enumerate(setting_rows(SMALL_MOTION_VIEWS, AXXB_METHODS, outcomes)):
            rows.append([noise_label(noise) if j == 0 else "", *r[1:]])
        notes.append((noise, outcomes))
    print(format_table(["noise", "method", *error_headers(["X"]), *COUNT_HEADERS], rows))
    for noise, outcomes in notes:
        for m, out in zip(AXXB_METHODS, outcomes, strict=True):
            for count, example in out.messages.values():
                print(f"  {noise_label(noise)}: {m.name} failed {count}x, e.g. {example[:150]}")
    print(COUNT_NOTE)
    return summaries


def load_tabb() -> tuple[Views, Estimates, Estimates]:
    """Tabb DS1 in our conventions (mm), the A = X B Y reference (cam_T_hand, base_T_world)
    and the AX = XB reference (hand_T_eye,)."""
    if not TABB_JSON.is_file():
        sys.exit(
            f"bench_handeye.py: {TABB_JSON}: Tabb DS1 data missing (it ships with the "
            f"repository in tests/data/tabb_ds1/)"
        )
    data = json.loads(TABB_JSON.read_text())
    cam_T_worlds = np.array(data[TABB_A_KEY], dtype=float)
    hand_T_bases = np.array(data[TABB_B_KEY], dtype=float)
    ref = data[TABB_REF_KEY]
    cam_T_hand = np.array(ref[TABB_X_KEY], dtype=float)
    base_T_world = inverse_transform(np.array(ref[TABB_YINV_KEY], dtype=float))
    v = Views(inverse_transform(hand_T_bases), cam_T_worlds, hand_T_bases)
    return v, (cam_T_hand, base_T_world), (inverse_transform(cam_T_hand),)


TabbRun = tuple[Method, str, NDArray[np.float64] | str, float, Estimates | None, bool]


def tabb_runs(methods: Sequence[Method], v_mm: Views, reference_mm: Estimates) -> list[TabbRun]:
    """Each method on the mm data and on the same data in metres: errors against the
    reference in deg/mm (or the failure message), us per solve, estimates in mm, and
    whether the answer is flagged ``converged=False``.

    One warm-up call, then ``TABB_TIMED_CALLS`` timed calls (one if the warm-up call took
    longer than ``TABB_SLOW_S``); the median is kept.
    """
    runs: list[TabbRun] = []
    for unit, metres_per_unit in (("mm", 1e-3), ("m", 1.0)):
        v = v_mm if unit == "mm" else scaled(v_mm, 1e3)
        for m in methods:
            call, read = m.prepare(v)
            first = timed(call)[0]
            seconds = []
            for _ in range(TABB_TIMED_CALLS if first < TABB_SLOW_S else 1):
                s, result, exc = timed(call)
                seconds.append(s)
            us = 1e6 * float(np.median(seconds))
            estimates, msg = read_result(read, result, exc)
            if estimates is None:
                runs.append((m, unit, str(msg), us, None, False))
                continue
            est_mm = tuple(
                transform(e[:3, :3], e[:3, 3] * metres_per_unit * 1e3) for e in estimates
            )
            runs.append(
                (
                    m,
                    unit,
                    errors_deg_mm(est_mm, reference_mm, 1e-3),
                    us,
                    est_mm,
                    not getattr(result, "converged", True),
                )
            )
    return runs


def silence_opencv_log() -> None:
    """Silence OpenCV's own log (identity answers are counted instead).

    The call moved within 4.x: ``cv2.utils.logging.setLogLevel`` in some wheels (4.14),
    only ``cv2.setLogLevel`` without level constants in others (4.12); 0 is
    ``LOG_LEVEL_SILENT``. With neither, OpenCV keeps logging.
    """
    utils_logging = getattr(getattr(cv2, "utils", None), "logging", None)
    if hasattr(utils_logging, "setLogLevel"):
        utils_logging.setLogLevel(getattr(utils_logging, "LOG_LEVEL_SILENT", 0))
    elif hasattr(cv2, "setLogLevel"):
        cv2.setLogLevel(getattr(cv2, "LOG_LEVEL_SILENT", 0))


TabbRow = tuple[str, Method, str, tuple[str, ...], NDArray[np.float64]]


def section_tabb() -> list[TabbRow]:
    """Print the Tabb DS1 tables; return (problem, method, unit, columns, errors) rows."""
    print(
        f"\n3. Real data: Tabb DS1 ({TABB_JSON.parent.name}), 88 poses, against Tabb's "
        "reference\n   (reprojection-optimised, AA_RPI; itself an estimate). Lengths "
        "given in mm (as published)\n   and in m (the same numbers / 1000); errors "
        "always in mm. 'm vs mm' = how far the\n   m-input answer (converted to mm) lies "
        "from the mm-input answer: nonzero = depends on the unit.\n   'OpenCV test' = "
        f"within the tolerance of OpenCV's own regression test on this data\n   "
        f"(< {OPENCV_TEST_DEG:g} deg and < {OPENCV_TEST_MM:g} mm on every transform)."
    )
    v_mm, ref_axyb, ref_axxb = load_tabb()
    collected: list[TabbRow] = []
    for problem, methods, reference, names in (
        ("AX = XB: X = hand_T_eye (vs inv(Tabb's Z))", AXXB_METHODS, ref_axxb, ["X"]),
        (
            "A = X B Y: X = cam_T_hand (vs Tabb's Z), inv(Y) = base2world (vs Tabb's X)",
            AXYB_METHODS,
            ref_axyb,
            ["X", "inv(Y)"],
        ),
    ):
        runs = tabb_runs(methods, v_mm, reference)
        by_key = {(r[0].name, r[1]): r[4] for r in runs}
        rows = []
        for m, unit, err, us, est, unconverged in runs:
            if isinstance(err, str) or est is None:
                rows.append(
                    [m.name, unit, *(["fail"] * 2 * len(names)), "", f"{us:.0f}", "", str(err)[:60]]
                )
                continue
            if names[-1] == "inv(Y)":  # compare base2world as OpenCV's test does
                err = err.copy()
                err[2:] = errors_deg_mm(
                    (inverse_transform(est[1]),), (inverse_transform(reference[1]),), 1e-3
                )
            collected.append(
                (
                    problem.split(":")[0],
                    m,
                    unit,
                    tuple(f"{x} {u}" for x in names for u in ("rot", "mm")),
                    err,
                )
            )
            mm_est = by_key.get((m.name, "mm"))
            if unit == "m" and mm_est is not None:
                diff = errors_deg_mm(est, mm_est, 1e-3)
                vs = f"{diff[0::2].max():.2g} deg / {diff[1::2].max():.2g} mm"
            else:
                vs = ""
            ok = bool(np.all(err[0::2] < OPENCV_TEST_DEG) and np.all(err[1::2] < OPENCV_TEST_MM))
            rows.append(
                [
                    m.name,
                    unit,
                    *(g(x) for x in err),
                    vs,
                    f"{us:.0f}",
                    "pass" if ok else "FAIL",
                    "converged=False" if unconverged else "",
                ]
            )
        heads = []
        for name in names:
            heads += [f"{name} rot deg", f"{name} mm"]
        print(f"\n{problem}")
        print(
            format_table(
                ["method", "lengths", *heads, "m vs mm", "us/solve", "OpenCV test", "note"], rows
            )
        )
    return collected


def ratio_cell(ours: float, best: float, floor: float) -> str:
    """``ours / best`` as text; '~0' when both are rounding-level, the raw value when
    only one is."""
    if not np.isfinite(ours):
        return "fail"
    if not np.isfinite(best):
        return "no OpenCV"
    if ours < floor and best < floor:
        return "~0"
    if best < floor:
        return f"{ours:.2g} vs ~0"
    if ours < floor:
        return f"~0 vs {best:.2g}"
    return f"{ours / best:.2f}"


def print_tabb_summary(tabb: Sequence[TabbRow], losses: dict[str, list[str]]) -> None:
    """Ratios to the best OpenCV method on Tabb DS1, per problem and length unit."""
    all_columns = list(dict.fromkeys(c for r in tabb for c in r[3]))
    rows = []
    for problem in dict.fromkeys(r[0] for r in tabb):
        for unit in ("mm", "m"):
            group = [r for r in tabb if r[0] == problem and r[2] == unit]
            theirs = [r for r in group if not r[1].ours]
            if not theirs:
                continue
            for r in (r for r in group if r[1].ours):
                cells = {}
                for c, col in enumerate(r[3]):
                    best = min(theirs, key=lambda t, c=c: t[4][c])
                    ours, best_c = r[4][c], best[4][c]
                    cells[col] = f"{ours / best_c:.2f}"
                    if ours > best_c:
                        u = "deg" if col.endswith("rot") else "mm"
                        losses.setdefault(
                            f"Tabb DS1, {problem}, lengths in {unit}, {r[1].name}:", []
                        ).append(
                            f"{col} error {ours:.3g} {u} vs {best[1].name} "
                            f"{best_c:.3g} {u} (x{ours / best_c:.2f})"
                        )
                rows.append(
                    [problem, unit, r[1].name, *(cells.get(col, "") for col in all_columns)]
                )
    print(
        "\nTabb DS1: kinfw error / best OpenCV error (same column, same length unit) "
        "against Tabb's\nreference, which is an estimate too: lower = closer to Tabb's "
        "answer, not necessarily to the truth"
    )
    print(format_table(["problem", "lengths", "kinfw", *(f"{c} ratio" for c in all_columns)], rows))


def print_summary(summaries: Sequence[Summary], tabb: Sequence[TabbRow]) -> None:
    print(
        "\n4. Summary: kinfw median error / best OpenCV median error in the same column, "
        "and kinfw time /\n   fastest OpenCV time in the same trial (median over trials). "
        "< 1 = kinfw better.\n   '~0' = both errors at rounding level (< "
        f"{EXACT_DEG:g} deg, < {EXACT_MM:g} mm), no ratio; 'a vs ~0' = only one is."
    )
    losses: dict[str, list[str]] = {}
    for problem in dict.fromkeys(s.problem for s in summaries):
        group = [s for s in summaries if s.problem == problem]
        columns = group[0].columns
        rows = []
        for s in group:
            cells = [noise_label(s.noise), f"{s.n}", s.method]
            lost = losses.setdefault(f"{problem}, {noise_label(s.noise)}, n={s.n}, {s.method}:", [])
            for c, col in enumerate(columns):
                floor = EXACT_DEG if col.endswith("rot") else EXACT_MM
                ours, best = s.ours[c], s.best[c]
                cells.append(ratio_cell(ours, best, floor))
                if np.isfinite(ours) and ours >= floor and not best >= ours:
                    unit = "deg" if col.endswith("rot") else "mm"
                    shown = "~0 (rounding)" if best < floor else f"{best:.3g} {unit}"
                    times = f"x{ours / best:.2f}; " if best >= floor else ""
                    lost.append(
                        f"{col} error {ours:.3g} {unit} vs {s.best_names[c]} "
                        f"{shown} ({times}kinfw lower in {s.wins[c]} trials)"
                    )
            cells.append(f"{s.time_ratio:.2f}")
            cells.append(s.fastest.replace("OpenCV ", ""))
            if s.time_ratio > 1.0:
                lost.append(f"time x{s.time_ratio:.2f} of {s.fastest}")
            rows.append(cells)
        print(f"\n{problem}")
        print(
            format_table(
                ["noise", "n", "kinfw", *(f"{c} ratio" for c in columns), "time ratio", "fastest"],
                rows,
            )
        )
    print_tabb_summary(tabb, losses)
    losses = {k: v for k, v in losses.items() if v}
    print(
        f"\nWhere kinfw loses (median error above the best OpenCV median, or slower than "
        f"the fastest; {len(losses)} cases):"
    )
    for head, items in losses.items():
        print(f"  {head}")
        for item in items:
            print(f"      {item}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--trials",
        type=int,
        default=None,
        help=f"random setups per setting (default {FULL_TRIALS}, or {QUICK_TRIALS} with --quick)",
    )
    parser.add_argument(
        "--quick", action="store_true", help=f"views {QUICK_VIEWS} only, {QUICK_TRIALS} trials"
    )
    parser.add_argument(
        "--subset-trials",
        type=int,
        default=None,
        help="run the pure paper iteration (refine=False), which can be slow, "
        "on the first M trials only (default: all)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw")
    args = parser.parse_args(argv)
    trials = (
        args.trials if args.trials is not None else (QUICK_TRIALS if args.quick else FULL_TRIALS)
    )
    if trials < 1:
        parser.error("--trials: expected at least 1")
    subset_trials = min(trials, trials if args.subset_trials is None else args.subset_trials)
    if subset_trials < 1:
        parser.error("--subset-trials: expected at least 1")
    views_list = QUICK_VIEWS if args.quick else FULL_VIEWS
    silence_opencv_log()
    logging.getLogger("identification").setLevel(logging.ERROR)

    started = time.perf_counter()
    print("kinfw hand-eye benchmark: identification.handeye / identification.axb vs OpenCV")
    print(
        machine_info(
            [("opencv", f"{cv2.__version__} (threads {cv2.getNumThreads()})")],
            code=[
                ("kinfw", f"{REPO} (git {git_head()})"),
                *(("solver", f"{path} sha256 {digest}") for path, digest in solver_digests()),
            ],
        )
    )
    print(
        f"mode       {'quick' if args.quick else 'full'}, trials {trials} (refine=False: "
        f"{subset_trials}), views {views_list}, seed {args.seed}"
    )
    print(
        f"timing     per trial median of {TIMED_CALLS} calls (1 call if slower than "
        f"{1e3 * SLOW_S:g} ms), warm-up {WARMUP} calls\n           (1 if slow), gc "
        "disabled while timing; OpenCV's log and kinfw's warnings silenced\n           "
        "(identity answers and converged=False are counted instead)"
    )
    print(
        f"data       robot poses: reference rotated U(0, {MAX_ROTATION_DEG:g} deg) about "
        f"random axes, shifted U(+-{HALF_SHIFT_M:g} m)/axis;\n           target "
        f"{TARGET_DISTANCE_M:g} m in front of the reference camera; noise on the camera "
        "poses only\n           (rotation N(0, sigma) about a random axis, translation "
        "N(0, sigma_t) per axis):\n           " + ", ".join(noise_label(nz) for nz in NOISE_LEVELS)
    )
    scenes = [
        make_scene(
            np.random.default_rng([args.seed, 0, t]),
            max(FULL_VIEWS),
            MAX_ROTATION_DEG,
            (args.seed, 0, t),
        )
        for t in range(trials)
    ]
    summaries = section_synthetic(
        "1. AX = XB (eye-in-hand): X = hand_T_eye; A = base_T_hand, B = cam_T_target",
        "AX = XB",
        AXXB_METHODS,
        scenes,
        views_list,
        NOISE_LEVELS,
        lambda s: (s.hand_T_cam,),
        ["X"],
        subset_trials,
    )
    summaries += section_small_motion(trials, args.seed)
    summaries += section_synthetic(
        "2. A = X B Y: A = cam_T_world, B = hand_T_base, X = cam_T_hand, Y = base_T_world",
        "A = X B Y",
        AXYB_METHODS,
        scenes,
        views_list,
        NOISE_LEVELS,
        lambda s: (inverse_transform(s.hand_T_cam), s.base_T_world),
        ["X", "Y"],
        subset_trials,
    )
    tabb = section_tabb()
    print_summary(summaries, tabb)
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
