"""Hand-eye solvers against every OpenCV method: issue 13's regimes, speed, Tabb DS1.

Run from the repository root (OpenCV is the ``bench`` extra, not a kinfw dependency:
``pip install -e '.[bench]'`` or ``pip install "opencv-python-headless>=4.10,<5"``)::

    python benchmarks/bench_handeye.py              # full run: 200 trials per regime
    python benchmarks/bench_handeye.py --quick      # a few seconds
    python benchmarks/bench_handeye.py --trials 500 --seed 3 --unit mm

Prints plain-text tables:

1. Regimes (issue 13): an independent generator (:mod:`benchmarks.handeye_regimes`; not
   kinfw's simulation) draws a random true X = hand_T_camera and Y = base_T_target,
   exact robot poses and camera poses with noise 1 deg about a random axis (N(0, 1 deg))
   + N(0, 2 mm) per axis. Regimes: well spread, 10 views; small motions (every
   relative turn <= 15 deg, 10 views; <= 30 deg; <= 15 deg with 30 views); 1 of 10
   camera poses off by a further 20 deg; X within 0.3 deg of the half turn; no noise
   (exactness). Every solver sees the same data: kinfw's ``solve_axxb`` and
   ``solve_axyb`` (through their public API) and OpenCV's ``calibrateHandEye`` (TSAI,
   PARK, HORAUD, ANDREFF, DANIILIDIS) and ``calibrateRobotWorldHandEye`` (SHAH, LI).
   Per regime and solver: median and p90 of the X rotation error (deg) and translation
   error (mm) over the trials that did not raise, raises k/N (a raise is a result),
   identity answers, median ms per solve; then the best OpenCV value of each column
   ("best CV") and kinfw / best CV.
2. Time per solve at 3, 10, 30, 100 well-spread noisy views: median over trials of the
   median of 3 round-robin calls, gc off; kinfw / fastest OpenCV method.
3. Tabb DS1 (a real robot and camera, 88 poses): every method of both problems against
   Tabb's reprojection-optimised reference, once with the lengths in millimetres (as
   published) and once in metres; the last column shows whose answer changes with the
   length unit.
4. Summary in issue 13's layout: per regime kinfw ``solve_axxb``, kinfw ``solve_axyb``,
   best OpenCV (name per column); time per solve; Tabb DS1 ratios.

Inputs are handed over in each library's own format (4x4 stacks for kinfw, contiguous
R/t stacks for OpenCV). OpenCV's log and kinfw's warnings are silenced; identity answers
and raises are counted instead.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # for benchmarks.common (kinfw comes from pip install -e .)
    sys.path.insert(0, str(REPO))


from benchmarks import handeye_regimes as hr
from benchmarks.common import (
    format_table,
    machine_info,
    wall_time_line,
)
from kinfw.geometry import inverse_transform, rotation_angle, transform_from_rotation_translation
from kinfw.identification.handeye import solve_axxb, solve_axyb

TABB_JSON = REPO / "tests" / "data" / "tabb_ds1" / "tabb_ds1_pairs.json"  # README there
TABB_A_KEY = "T_world2cam (A_i = cTw, from cali.txt)"
TABB_B_KEY = "T_base2gripper (B_i = gTb, from robot_cali.txt)"
TABB_REF_KEY = "reference_rwhe_AA_RPI"
TABB_X_KEY = "Z = cTg (gripper2cam)"  # Tabb's Z is our X of A = X B Y
TABB_YINV_KEY = "X = wTb (base2world)"  # Tabb's X is our inv(Y)
OPENCV_TEST_DEG, OPENCV_TEST_MM = 1.0, 50.0  # Calib3d_CalibrateRobotWorldHandEye.regression
FULL_TRIALS = 200
QUICK_TRIALS = 10
FULL_TIMING_TRIALS = 50
QUICK_TIMING_TRIALS = 5
QUICK_TIMING_VIEWS = (3, 10, 30)
TABB_TIMED_CALLS = 5
TABB_SLOW_S = 0.05

TSAI = cv2.CALIB_HAND_EYE_TSAI
PARK = cv2.CALIB_HAND_EYE_PARK
HORAUD = cv2.CALIB_HAND_EYE_HORAUD
ANDREFF = cv2.CALIB_HAND_EYE_ANDREFF
DANIILIDIS = cv2.CALIB_HAND_EYE_DANIILIDIS
SHAH = cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH
LI = cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI


# -- Tabb DS1 data -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Views:
    """The data every solver sees in one trial, in our conventions (metres or mm)."""

    base_T_hands: NDArray[np.float64]  # (n, 4, 4)  AX = XB's A
    cam_T_worlds: NDArray[np.float64]  # (n, 4, 4)  AX = XB's B (target = world); A = X B Y's A
    hand_T_bases: NDArray[np.float64]  # (n, 4, 4)  A = X B Y's B


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


def rt(T: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Contiguous rotation (n, 3, 3) and translation (n, 3, 1) stacks, OpenCV's input."""
    return np.ascontiguousarray(T[:, :3, :3]), np.ascontiguousarray(T[:, :3, 3:])


def transform(R: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    return transform_from_rotation_translation(R, np.ravel(t))


def ours_axxb(v: Views) -> tuple[Callable[[], object], Callable[[object], Estimates]]:
    return (
        (lambda: solve_axxb(base_T_hands=v.base_T_hands, camera_T_targets=v.cam_T_worlds)),
        (lambda r: (r.hand_T_camera,)),
    )


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
            (
                lambda: solve_axyb(
                    camera_T_targets=v.cam_T_worlds, hand_T_bases=v.hand_T_bases, refine=refine
                )
            ),
            (lambda r: (r.camera_T_hand, r.base_T_target)),
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
    Method("OpenCV HORAUD", False, opencv_axxb(HORAUD)),
    Method("OpenCV ANDREFF", False, opencv_axxb(ANDREFF)),
    Method("OpenCV DANIILIDIS", False, opencv_axxb(DANIILIDIS)),
)
AXYB_METHODS = (
    Method("kinfw solve_axyb", True, ours_axyb(refine=True)),
    Method("kinfw refine=False", True, ours_axyb(refine=False)),
    Method("OpenCV SHAH", False, opencv_axyb(SHAH)),
    Method("OpenCV LI", False, opencv_axyb(LI)),
)


# -- Tabb DS1 runs --------------------------------------------------------------------


def errors_deg_mm(
    estimates: Estimates, truths: Estimates, metres_per_unit: float = 1.0
) -> NDArray[np.float64]:
    """Rotation angle (deg) and translation distance (mm) of each estimate from its truth."""
    out = []
    for est, true in zip(estimates, truths, strict=True):
        out.append(np.degrees(float(rotation_angle(est[:3, :3].T @ true[:3, :3]))))
        out.append(1e3 * metres_per_unit * float(np.linalg.norm(est[:3, 3] - true[:3, 3])))
    return np.array(out)


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
        "identification/handeye/_axxb.py",
        "identification/handeye/_axyb.py",
        "identification/handeye/_axyb_iteration.py",
        "identification/handeye/_axyb_refinement.py",
    ):
        path = REPO / rel
        digest = hashlib.sha256(path.read_bytes()).hexdigest()[:12] if path.exists() else "n/a"
        out.append((rel, digest))
    return out


def g(x: float) -> str:
    return "fail" if not np.isfinite(x) else f"{x:.3g}"


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


# -- sections 1, 2 and the summary: issue 13's regimes ------------------------------------


def regime_trials(regime_index: int, trials: int, seed: int) -> list[hr.Trial]:
    regime = hr.REGIMES[regime_index]
    return [
        hr.make_trial(np.random.default_rng([seed, regime_index, t]), regime) for t in range(trials)
    ]


def section_regimes(trials: int, seed: int, metres_per_unit: float) -> list[list[hr.Column]]:
    """Print one table per regime; return the columns (per regime, per solver)."""
    unit = "m" if metres_per_unit == 1.0 else "mm"
    print(
        f"\n1. Regimes of issue 13: {trials} trials each, lengths handed over in {unit}; "
        f"errors of X = hand_T_camera\n   (A = X B Y solvers: inverse of camera_T_hand). "
        "Median and p90 over the trials that did not raise;\n   raises = exceptions or "
        "non-finite answers (k/N); ident = answers equal to the identity\n   (OpenCV's "
        "silent failure); ms med = one call per trial, median. best CV = the best OpenCV "
        "value\n   of the column (method abbreviated); x/best = kinfw over best CV (< 1: "
        "kinfw better)."
    )
    results = []
    for i, regime in enumerate(hr.REGIMES):
        cols = hr.run_regime(
            regime, regime_trials(i, trials, seed), metres_per_unit=metres_per_unit
        )
        results.append(cols)
        motion = (
            "any orientation"
            if regime.motion_deg >= 360
            else f"relative turns <= {regime.motion_deg:g} deg"
        )
        print(f"\n1.{i + 1} {regime.label} ({regime.n_views} views, {motion})")
        print(format_table(hr.REGIME_HEADERS, hr.regime_rows(hr.SOLVERS, cols, trials)))
        for s, c in zip(hr.SOLVERS, cols, strict=True):
            for count, example in c.messages.values():
                print(f"  {s.name} raised {count}x, e.g. {example[:140]}")
    return results


def section_timing(
    trials: int, views_list: Sequence[int], seed: int, metres_per_unit: float
) -> list[tuple[int, NDArray[np.float64]]]:
    """Print the time per solve at each number of views; return (n, seconds per solver)."""
    print(
        f"\n2. Time per solve, well spread noisy views, {trials} trials per size (median "
        "over trials of the\n   median of 3 round-robin calls after a warm-up, gc off); "
        "x/fastest = kinfw over the fastest OpenCV\n   method at that size."
    )
    spread = hr.REGIMES[0]
    out = []
    rows = []
    theirs = [j for j, s in enumerate(hr.SOLVERS) if not s.ours]
    for n in views_list:
        data = [
            hr.make_trial(np.random.default_rng([seed, 100, n, t]), spread, n_views=n)
            for t in range(trials)
        ]
        seconds = hr.time_solvers(data, metres_per_unit=metres_per_unit)
        out.append((n, seconds))
        fastest = min(theirs, key=lambda j: seconds[j])
        rows.append(
            [
                f"{n}",
                *(f"{1e3 * x:.3f}" for x in seconds),
                hr.SOLVERS[fastest].name,
                *(
                    f"{seconds[j] / seconds[fastest]:.2f}"
                    for j, s in enumerate(hr.SOLVERS)
                    if s.ours
                ),
            ]
        )
    ours = [s.name.split()[-1] for s in hr.SOLVERS if s.ours]
    print(
        format_table(
            [
                "views",
                *(f"{s.name.replace('kinfw ', '')} ms" for s in hr.SOLVERS),
                "fastest CV",
                *(f"{o}/fastest" for o in ours),
            ],
            rows,
        )
    )
    return out


def print_issue_summary(
    regimes: Sequence[list[hr.Column]],
    timing: Sequence[tuple[int, NDArray[np.float64]]],
    trials: int,
) -> None:
    """The final table in issue 13's layout, then kinfw / best CV ratios per regime."""
    ours = [j for j, s in enumerate(hr.SOLVERS) if s.ours]
    theirs = [j for j, s in enumerate(hr.SOLVERS) if not s.ours]
    print(
        f"\n4. Summary in issue 13's layout ({trials} trials per regime): X rotation "
        "error deg median (p90) /\n   translation mm median (p90); raises k/N when "
        "nonzero; best OpenCV = best value per column\n   with its method (p90 and mm "
        "may come from other methods than the median)."
    )
    rows = []
    for regime, cols in zip(hr.REGIMES, regimes, strict=True):
        rows.append(
            [
                regime.label,
                *(hr.summary_cell(cols[j], trials) for j in ours),
                hr.summary_best_cell(hr.SOLVERS, cols),
            ]
        )
    for n, seconds in timing:
        fastest = sorted(theirs, key=lambda j: seconds[j])
        rows.append(
            [
                f"time per solve, {n} views",
                *(f"{1e3 * seconds[j]:.3f} ms" for j in ours),
                ", ".join(f"{1e3 * seconds[j]:.3f} ms ({hr.SOLVERS[j].name})" for j in fastest[:2]),
            ]
        )
    heads = ["regime", *(f"kinfw `{hr.SOLVERS[j].name.split()[-1]}`" for j in ours), "best OpenCV"]
    print("| " + " | ".join(heads) + " |\n|" + "---|" * len(heads))  # markdown, as the issue
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print(
        "\nkinfw / best OpenCV per column (< 1: kinfw better; '-' = raised in every trial; "
        "'~0' = both\nat rounding level)"
    )
    rows = []
    for regime, cols in zip(hr.REGIMES, regimes, strict=True):
        best = hr.best_cv(hr.SOLVERS, cols)
        for j in ours:
            st = cols[j].stats()
            rows.append(
                [
                    regime.label if j == ours[0] else "",
                    hr.SOLVERS[j].name.split()[-1],
                    *(
                        hr.ratio(x, b, k)
                        for k, (x, (b, _)) in enumerate(zip(st, best, strict=True))
                    ),
                    f"{cols[j].raises}/{trials}",
                ]
            )
    for n, seconds in timing:
        t_best = min(seconds[j] for j in theirs)
        for j in ours:
            rows.append(
                [
                    f"time, {n} views" if j == ours[0] else "",
                    hr.SOLVERS[j].name.split()[-1],
                    f"time {seconds[j] / t_best:.2f}",
                    "",
                    "",
                    "",
                    "",
                ]
            )
    print(format_table(["regime", "kinfw", *hr.STAT_NAMES, "raises"], rows))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--trials",
        type=int,
        default=None,
        help=f"trials per regime (default {FULL_TRIALS}, or {QUICK_TRIALS} with --quick)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"{QUICK_TRIALS} trials per regime, timing at {QUICK_TIMING_VIEWS} views",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw")
    parser.add_argument(
        "--unit",
        choices=("m", "mm"),
        default="m",
        help="length unit handed to every solver in sections 1 and 2 (default m)",
    )
    parser.add_argument("--no-tabb", action="store_true", help="skip section 3 (Tabb DS1)")
    args = parser.parse_args(argv)
    trials = (
        args.trials if args.trials is not None else (QUICK_TRIALS if args.quick else FULL_TRIALS)
    )
    if trials < 1:
        parser.error("--trials: expected at least 1")
    timing_trials = min(trials, QUICK_TIMING_TRIALS if args.quick else FULL_TIMING_TRIALS)
    timing_views = QUICK_TIMING_VIEWS if args.quick else hr.TIMING_VIEWS
    metres_per_unit = 1.0 if args.unit == "m" else 1e-3
    silence_opencv_log()
    logging.getLogger("identification").setLevel(logging.ERROR)

    started = time.perf_counter()
    print(
        "kinfw hand-eye benchmark: solve_axxb / solve_axyb (kinfw.identification.handeye) vs OpenCV"
    )
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
        f"mode       {'quick' if args.quick else 'full'}, trials {trials} per regime, "
        f"timing {timing_trials} trials at {timing_views} views, seed {args.seed}, "
        f"lengths in {args.unit}"
    )
    print(
        f"data       independent generator (benchmarks/handeye_regimes.py): camera noise "
        f"N(0, {hr.NOISE_ROT_DEG:g} deg) about\n           a random axis + N(0, "
        f"{hr.NOISE_MM:g} mm) per axis; robot poses exact, shifted U(+-{hr.HALF_SHIFT_M:g} m) "
        f"per axis;\n           target {hr.TARGET_DISTANCE_M:g} m in front of the camera "
        "at the reference pose"
    )
    regimes = section_regimes(trials, args.seed, metres_per_unit)
    timing = section_timing(timing_trials, timing_views, args.seed, metres_per_unit)
    losses: dict[str, list[str]] = {}
    if not args.no_tabb:
        tabb = section_tabb()
        print_tabb_summary(tabb, losses)
    print_issue_summary(regimes, timing, trials)
    losses = {k: v for k, v in losses.items() if v}
    if losses:
        print(f"\nTabb DS1: where kinfw is farther from Tabb's reference ({len(losses)} cases):")
        for head, items in losses.items():
            print(f"  {head}")
            for item in items:
                print(f"      {item}")
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
