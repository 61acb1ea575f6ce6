"""Hand-eye solvers on real data, held out: fit half the poses, predict the other half.

Run from the repository root (OpenCV is the ``bench`` extra, not a kinfw dependency)::

    python benchmarks/bench_handeye_real.py              # 20 random splits per dataset
    python benchmarks/bench_handeye_real.py --quick      # 4 splits, a few seconds
    python benchmarks/bench_handeye_real.py --splits 50 --seed 3

Solvers (nine, through their public API only): kinfw ``solve_axxb`` and ``solve_axyb``
and OpenCV's ``calibrateHandEye`` (TSAI, PARK, HORAUD, ANDREFF, DANIILIDIS) and
``calibrateRobotWorldHandEye`` (SHAH, LI), by the wrappers of
:mod:`benchmarks.handeye_regimes` for X. Y = ``base_T_target`` is the solver's own where it
has one (kinfw ``solve_axyb``'s ``base_T_target``, SHAH's and LI's ``base2world``
inverted); for the others it is the chordal mean of ``base_T_hand[i] X camera_T_target[i]``
over the fit half (rotation: SVD projection of the sum; translation: the mean).

Data (``tests/data/``, each folder's README gives the source, licence and conventions):

* Tabb DS1: 88 real eye-in-hand poses, mm, with Tabb's reprojection-optimised
  reference X and Y;
* ETH ASL robot arm, real and simulated: the hand stream (50 Hz) interpolated at the
  camera stamps (every 8th / 5th camera pose as shipped) by
  :func:`kinfw.measurements.align_streams`, at fixed time offsets (``ETH_OFFSET_S``,
  found by ``best_time_offset`` on master 6282c3d; fixed so that the pairs do not depend
  on the solvers benchmarked), metres;
* OpenCV's ``regression_24871``: 4 exact eye-in-hand poses with a known X.

Sections:

1. Held out (Tabb DS1, ETH real, ETH sim): ``--splits`` random halvings (seeded
   ``[seed, dataset, split]``); each solver fits X and Y on one half and predicts the
   other half's camera poses ``camera_T_target[i] = inv(X) inv(base_T_hand[i]) Y``.
   Per split the RMS over the held-out poses of the rotation angle (deg) and translation
   distance (mm) of the predicted vs the measured camera pose; the table gives the median
   and p90 over the splits, the in-sample RMS (fit half) for comparison, raises k/N (a
   raise is a result, left out of the statistics), and the median ms per solve. This
   score needs no reference: lower is better. Tabb's reference X, Y is scored on the same
   halves (not held out for it: it was fitted to every pose). The summary gives the three
   lowest medians and how often each solver predicted best within a split (paired).
2. Every solver fitted on all poses against the published reference (Tabb DS1): X and Y
   errors in deg / mm.
3. OpenCV 24871 (exact): every solver's X (and Y) error against the known answer.
4. Length unit: every solver fitted on all poses with the lengths in the file's unit and
   again in the other (m <-> mm); the change of X (deg, mm) is listed and a solver whose
   answer changes by more than ``UNIT_DEG`` / ``UNIT_MM`` is flagged.

OpenCV's log and kinfw's warnings are silenced.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # for benchmarks.common (kinfw comes from pip install -e .)
    sys.path.insert(0, str(REPO))


from benchmarks import handeye_regimes as hr
from benchmarks.bench_handeye import git_head, silence_opencv_log, solver_digests
from benchmarks.common import format_table, machine_info, wall_time_line

DATA = REPO / "tests" / "data"
TABB_JSON = DATA / "tabb_ds1" / "tabb_ds1_pairs.json"
TABB_A_KEY = "T_world2cam (A_i = cTw, from cali.txt)"
TABB_B_KEY = "T_base2gripper (B_i = gTb, from robot_cali.txt)"
TABB_REF_KEY = "reference_rwhe_AA_RPI"
TABB_Z_KEY = "Z = cTg (gripper2cam)"  # camera_T_hand
TABB_X_KEY = "X = wTb (base2world)"  # target_T_base
CV24871_JSON = DATA / "opencv_regression_24871" / "regression_24871.json"
ETH = DATA / "eth_asl_robot_arm"
ETH_FILES = {
    "real": (
        "real/robot_arm_complete_bag_color_and_ir_base_link_sr300_hinge.csv",
        "real/robot_arm_complete_bag_color_and_ir_target_ir.csv",
    ),
    "sim": ("sim/robot_arm_sim_hand.csv", "sim/robot_arm_sim_camera.csv"),
}
# Added to the hand stamps (kinfw.measurements' sign); best_time_offset's answer on the
# shipped streams at master 6282c3d (tests/data/eth_asl_robot_arm/README.md).
ETH_OFFSET_S = {"real": 0.019, "sim": -0.001}
FULL_SPLITS = 20
QUICK_SPLITS = 4
UNIT_DEG = 1e-6  # a change of X above these between m and mm is flagged
UNIT_MM = 1e-6


# -- data --------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Dataset:
    """Eye-in-hand poses in the file's length unit, and the reference where one exists."""

    name: str
    unit: str  # "m" or "mm"
    base_T_hand: NDArray[np.float64]  # (n, 4, 4) robot, OpenCV gripper2base
    camera_T_target: NDArray[np.float64]  # (n, 4, 4) camera, OpenCV target2cam
    hand_T_camera: NDArray[np.float64] | None = None  # reference X
    base_T_target: NDArray[np.float64] | None = None  # reference Y
    exact: bool = False  # the reference is the truth (noise-free data)
    note: str = ""

    @property
    def metres_per_unit(self) -> float:
        return 1e-3 if self.unit == "mm" else 1.0


def _need(path: Path) -> Path:
    if not path.is_file():
        sys.exit(f"bench_handeye_real.py: {path}: data missing (it ships in tests/data/)")
    return path


def load_tabb() -> Dataset:
    data = json.loads(_need(TABB_JSON).read_text())
    ref = data[TABB_REF_KEY]
    return Dataset(
        "Tabb DS1",
        "mm",
        hr.inv(np.array(data[TABB_B_KEY], dtype=float)),
        np.array(data[TABB_A_KEY], dtype=float),
        hand_T_camera=hr.inv(np.array(ref[TABB_Z_KEY], dtype=float)),
        base_T_target=hr.inv(np.array(ref[TABB_X_KEY], dtype=float)),
        note="reference: Tabb's AA_RPI (reprojection error), an estimate itself",
    )


def load_eth(which: str) -> Dataset:
    from kinfw.measurements import align_streams, read_pose_csv

    hand_csv, eye_csv = (_need(ETH / f) for f in ETH_FILES[which])
    t_hand, base_T_hand = read_pose_csv(hand_csv)
    t_eye, target_T_eye = read_pose_csv(eye_csv)
    A, B = align_streams(t_hand, base_T_hand, t_eye, target_T_eye, offset_s=ETH_OFFSET_S[which])
    return Dataset(
        f"ETH {which}", "m", A, B, note=f"time offset {ETH_OFFSET_S[which]:+.3f} s, no reference"
    )


def load_24871() -> Dataset:
    d = json.loads(_need(CV24871_JSON).read_text())
    base_T_hand = hr.pose(np.array(d["R_gripper2base"]), np.reshape(d["t_gripper2base"], (-1, 3)))
    camera_T_target = hr.pose(np.array(d["R_target2cam"]), np.reshape(d["t_target2cam"], (-1, 3)))
    X = np.array(d["T_cam2gripper_true"], dtype=float)
    return Dataset(
        "OpenCV 24871",
        "m",
        base_T_hand,
        camera_T_target,
        hand_T_camera=X,
        base_T_target=chordal_mean(base_T_hand @ X @ camera_T_target),
        exact=True,
        note="exact (noise-free)",
    )


def in_unit(d: Dataset, unit: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The dataset's poses with the lengths in ``unit``."""
    scale = d.metres_per_unit / (1e-3 if unit == "mm" else 1.0)
    A, B = d.base_T_hand.copy(), d.camera_T_target.copy()
    A[:, :3, 3] *= scale
    B[:, :3, 3] *= scale
    return A, B


# -- solvers -----------------------------------------------------------------------------


def chordal_mean(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """Chordal L2 mean of poses (n, 4, 4): SVD projection of the rotations' sum, mean
    translation."""
    U, _, Vt = np.linalg.svd(T[:, :3, :3].sum(axis=0))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    return hr.pose(R, T[:, :3, 3].mean(axis=0))


XY = tuple[NDArray[np.float64], NDArray[np.float64]]  # hand_T_camera, base_T_target
Fit = Callable[[NDArray[np.float64], NDArray[np.float64]], Callable[[], XY]]


def _y_by_mean(solver: hr.Solver) -> Fit:
    """X from a :mod:`handeye_regimes` wrapper, Y the chordal mean over the fit poses."""

    def prepare(base_T_hand, camera_T_target):
        call = solver.prepare(base_T_hand, camera_T_target)

        def fit() -> XY:
            X = call()
            return X, chordal_mean(base_T_hand @ X @ camera_T_target)

        return fit

    return prepare


def _kinfw_axyb(base_T_hand, camera_T_target):
    from kinfw.identification.handeye import solve_axyb

    hand_T_base = hr.inv(base_T_hand)

    def fit() -> XY:
        r = solve_axyb(camera_T_targets=camera_T_target, hand_T_bases=hand_T_base)
        return hr.inv(r.camera_T_hand), r.base_T_target

    return fit


def _cv_rwhe(method_name: str) -> Fit:
    def prepare(base_T_hand, camera_T_target):
        method = getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{method_name}")
        hand_T_base = hr.inv(base_T_hand)
        args = {
            "R_world2cam": np.ascontiguousarray(camera_T_target[:, :3, :3]),
            "t_world2cam": np.ascontiguousarray(camera_T_target[:, :3, 3:]),
            "R_base2gripper": np.ascontiguousarray(hand_T_base[:, :3, :3]),
            "t_base2gripper": np.ascontiguousarray(hand_T_base[:, :3, 3:]),
        }

        def fit() -> XY:
            R_b2w, t_b2w, R_g2c, t_g2c = cv2.calibrateRobotWorldHandEye(**args, method=method)
            # gripper2cam = camera_T_hand, base2world = target_T_base
            return hr.inv(hr.pose(R_g2c, np.ravel(t_g2c))), hr.inv(hr.pose(R_b2w, np.ravel(t_b2w)))

        return fit

    return prepare


@dataclass(frozen=True, slots=True)
class Solver:
    name: str
    fit: Fit
    own_y: bool  # Y from the solver itself (else the chordal mean)


def solvers() -> list[Solver]:
    """The nine solvers, in :data:`handeye_regimes.SOLVERS`' order."""
    out = []
    for s in hr.SOLVERS:
        if s.name == "kinfw solve_axyb":
            out.append(Solver(s.name, _kinfw_axyb, True))
        elif s.name in ("SHAH", "LI"):
            out.append(Solver(s.name, _cv_rwhe(s.name), True))
        else:
            out.append(Solver(s.name, _y_by_mean(s), False))
    return out


@dataclass(slots=True)
class Outcome:
    """One solve: X, Y (None if it raised or returned non-finite numbers), seconds, the
    failure message."""

    X: NDArray[np.float64] | None
    Y: NDArray[np.float64] | None
    seconds: float
    message: str = ""


def run(solver: Solver, base_T_hand, camera_T_target) -> Outcome:
    fit = solver.fit(base_T_hand, camera_T_target)
    start = time.perf_counter()
    try:
        X, Y = fit()
    except hr.kinfw_errors() as exc:  # a documented refusal
        return Outcome(None, None, time.perf_counter() - start, _one_line(exc))
    except Exception as exc:  # OpenCV's errors, or a kinfw failure (flagged '!')
        return Outcome(None, None, time.perf_counter() - start, "! " + _one_line(exc))
    seconds = time.perf_counter() - start
    if not (np.isfinite(X).all() and np.isfinite(Y).all()):
        return Outcome(None, None, seconds, "non-finite result")
    return Outcome(X, Y, seconds)


def _one_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0] if lines else ''}"[:120]


# -- scores ------------------------------------------------------------------------------


def angles_deg(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation angles (n,) of rotations (n, 3, 3), deg (atan2: accurate near 0 and 180)."""
    skew = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], 1)
    return np.degrees(
        np.arctan2(np.linalg.norm(skew, axis=1) / 2.0, (np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0)
    )


def prediction_rms(X, Y, base_T_hand, camera_T_target, mm_per_unit: float) -> tuple[float, float]:
    """RMS rotation (deg) and translation (mm) error of the predicted camera poses
    ``inv(X) inv(base_T_hand[i]) Y`` against the measured ``camera_T_target[i]``."""
    pred = hr.inv(X) @ hr.inv(base_T_hand) @ Y
    rot = angles_deg(np.swapaxes(pred[:, :3, :3], 1, 2) @ camera_T_target[:, :3, :3])
    mm = mm_per_unit * np.linalg.norm(pred[:, :3, 3] - camera_T_target[:, :3, 3], axis=1)
    return float(np.sqrt(np.mean(rot**2))), float(np.sqrt(np.mean(mm**2)))


def pose_error(est, true, mm_per_unit: float) -> tuple[float, float]:
    """Rotation angle (deg) and translation distance (mm) of ``est`` from ``true``."""
    return hr.errors_deg_mm(est, true, mm_per_unit)


def fmt(x: float) -> str:
    return "-" if not np.isfinite(x) else f"{x:.3g}"


@dataclass(slots=True)
class HeldOut:
    """One solver over the splits of one dataset: (splits, 4) held-out rot/mm and in-sample
    rot/mm RMS, NaN where it raised; seconds per solve; failure messages by count."""

    scores: NDArray[np.float64]
    seconds: list[float] = field(default_factory=list)
    messages: dict[str, int] = field(default_factory=dict)

    @property
    def raises(self) -> int:
        return sum(self.messages.values())


def split_indices(n: int, seed: int, dataset: int, split: int) -> tuple[NDArray, NDArray]:
    """A random halving of ``range(n)``: (fit, held out), seeded [seed, dataset, split]."""
    perm = np.random.default_rng([seed, dataset, split]).permutation(n)
    return np.sort(perm[: n // 2]), np.sort(perm[n // 2 :])


def held_out(
    d: Dataset, index: int, slvs: Sequence[Solver], splits: int, seed: int, unit: str
) -> list[HeldOut]:
    """Every solver on every split of ``d``, the lengths handed over in ``unit``."""
    A, B = in_unit(d, unit)
    mm = 1e3 if unit == "m" else 1.0
    out = [HeldOut(np.full((splits, 4), np.nan)) for _ in slvs]
    for k in range(splits):
        fit, test = split_indices(len(A), seed, index, k)
        for s, h in zip(slvs, out, strict=True):
            o = run(s, A[fit], B[fit])
            h.seconds.append(o.seconds)
            if o.X is None:
                h.messages[o.message] = h.messages.get(o.message, 0) + 1
                continue
            h.scores[k] = (
                *prediction_rms(o.X, o.Y, A[test], B[test], mm),
                *prediction_rms(o.X, o.Y, A[fit], B[fit], mm),
            )
    return out


def _median_p90(x: NDArray[np.float64]) -> tuple[float, float]:
    x = x[np.isfinite(x)]
    return (np.nan, np.nan) if not len(x) else (float(np.median(x)), float(np.percentile(x, 90)))


HELD_HEADERS = [
    "solver",
    "Y",
    "deg med",
    "deg p90",
    "mm med",
    "mm p90",
    "fit deg",
    "fit mm",
    "deg med'",
    "mm med'",
    "raises",
    "ms med",
]


def held_out_rows(
    d: Dataset,
    slvs: Sequence[Solver],
    cols: Sequence[HeldOut],
    other: Sequence[HeldOut],
    splits: int,
) -> list[list[str]]:
    """Per solver: held-out and in-sample statistics in the file's unit (``cols``), the
    held-out medians with the lengths in the other unit (``other``), raises in both."""
    rows = []
    for s, h, o in zip(slvs, cols, other, strict=True):
        rd, rp = _median_p90(h.scores[:, 0])
        md, mp = _median_p90(h.scores[:, 1])
        rows.append(
            [
                s.name,
                "own" if s.own_y else "mean",
                fmt(rd),
                fmt(rp),
                fmt(md),
                fmt(mp),
                fmt(_median_p90(h.scores[:, 2])[0]),
                fmt(_median_p90(h.scores[:, 3])[0]),
                fmt(_median_p90(o.scores[:, 0])[0]),
                fmt(_median_p90(o.scores[:, 1])[0]),
                f"{h.raises}+{o.raises}/{2 * splits}",
                f"{1e3 * np.median(h.seconds):.2f}",
            ]
        )
    return rows


def reference_row(d: Dataset, index: int, splits: int, seed: int) -> list[str]:
    """The published reference X, Y scored on the same halves as the solvers (not held
    out for it: it was fitted to every pose)."""
    A, B, mm = d.base_T_hand, d.camera_T_target, 1e3 * d.metres_per_unit
    scores = np.empty((splits, 4))
    for k in range(splits):
        fit, test = split_indices(len(A), seed, index, k)
        scores[k] = (
            *prediction_rms(d.hand_T_camera, d.base_T_target, A[test], B[test], mm),
            *prediction_rms(d.hand_T_camera, d.base_T_target, A[fit], B[fit], mm),
        )
    rd, rp = _median_p90(scores[:, 0])
    md, mp = _median_p90(scores[:, 1])
    return [
        "reference (fit on all)",
        "ref",
        *map(fmt, (rd, rp, md, mp, np.median(scores[:, 2]), np.median(scores[:, 3]))),
        *[""] * 4,
    ]


def best_by(slvs: Sequence[Solver], cols: Sequence[HeldOut], k: int) -> str:
    med = [_median_p90(h.scores[:, k])[0] for h in cols]
    med = [np.inf if not np.isfinite(m) else m for m in med]
    order = np.argsort(med, kind="stable")
    return ", ".join(f"{slvs[j].name} {fmt(med[j])}" for j in order[:3])


def split_wins(slvs: Sequence[Solver], cols: Sequence[HeldOut], k: int) -> str:
    """Which solver has the lowest held-out error ``k`` per split (a paired comparison;
    a split where a solver raised counts as a loss for it): the counts, most first."""
    scores = np.stack([h.scores[:, k] for h in cols], axis=1)  # (splits, solvers)
    ok = np.isfinite(scores).any(axis=1)
    winners = np.argmin(np.where(np.isfinite(scores[ok]), scores[ok], np.inf), axis=1)
    counts = np.bincount(winners, minlength=len(slvs))
    order = np.argsort(-counts, kind="stable")
    return ", ".join(f"{slvs[j].name} {counts[j]}" for j in order if counts[j])


# -- full fits: reference, exact case, length unit ---------------------------------------


def full_fits(d: Dataset, slvs: Sequence[Solver], unit: str) -> list[Outcome]:
    A, B = in_unit(d, unit)
    return [run(s, A, B) for s in slvs]


def reference_rows(
    d: Dataset, slvs: Sequence[Solver], outs: Sequence[Outcome], unit: str
) -> list[list[str]]:
    """X and Y of each solver (fitted on all poses, lengths in ``unit``) vs the reference."""
    mm = 1e3 if unit == "m" else 1.0
    ref_X = in_unit_T(d.hand_T_camera, d, unit)
    ref_Y = in_unit_T(d.base_T_target, d, unit)
    rows = []
    for s, o in zip(slvs, outs, strict=True):
        if o.X is None:
            rows.append([s.name, "raises", "", "", "", o.message[:60]])
            continue
        ex, ey = pose_error(o.X, ref_X, mm), pose_error(o.Y, ref_Y, mm)
        rows.append([s.name, fmt(ex[0]), fmt(ex[1]), fmt(ey[0]), fmt(ey[1]), ""])
    return rows


def in_unit_T(T: NDArray[np.float64], d: Dataset, unit: str) -> NDArray[np.float64]:
    out = T.copy()
    out[:3, 3] *= d.metres_per_unit / (1e-3 if unit == "mm" else 1.0)
    return out


def unit_rows(
    d: Dataset, slvs: Sequence[Solver], file_fits: Sequence[Outcome], other_fits, other: str
) -> list[list[str]]:
    """Change of X between the file's unit and ``other`` (compared in mm)."""
    to_mm_file = 1e3 * d.metres_per_unit
    to_mm_other = 1e3 if other == "m" else 1.0
    rows = []
    for s, a, b in zip(slvs, file_fits, other_fits, strict=True):
        if a.X is None or b.X is None:
            state = f"{'raises' if a.X is None else 'ok'} / {'raises' if b.X is None else 'ok'}"
            rows.append([d.name, s.name, "-", "-", state])
            continue
        Xa, Xb = a.X.copy(), b.X.copy()
        Xa[:3, 3] *= to_mm_file
        Xb[:3, 3] *= to_mm_other
        deg, mm = pose_error(Xa, Xb, 1.0)
        flag = "CHANGES" if deg > UNIT_DEG or mm > UNIT_MM else "same"
        rows.append([d.name, s.name, f"{deg:.2g}", f"{mm:.2g}", flag])
    return rows


# -- main --------------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--splits",
        type=int,
        default=None,
        help=f"random halvings per dataset (default {FULL_SPLITS}, or {QUICK_SPLITS} with --quick)",
    )
    parser.add_argument("--quick", action="store_true", help=f"{QUICK_SPLITS} splits")
    parser.add_argument("--seed", type=int, default=0, help="seed of the splits")
    args = parser.parse_args(argv)
    splits = (
        args.splits if args.splits is not None else (QUICK_SPLITS if args.quick else FULL_SPLITS)
    )
    if splits < 1:
        parser.error("--splits: expected at least 1")
    silence_opencv_log()
    logging.getLogger("identification").setLevel(logging.ERROR)
    logging.getLogger("verification").setLevel(logging.ERROR)

    started = time.perf_counter()
    print("kinfw hand-eye on real data, held out: kinfw.identification.handeye / .axb vs OpenCV")
    print(
        machine_info(
            [("opencv", f"{cv2.__version__} (threads {cv2.getNumThreads()})")],
            code=[
                ("kinfw", f"{REPO} (git {git_head()})"),
                *(("solver", f"{path} sha256 {digest}") for path, digest in solver_digests()),
            ],
        )
    )
    print(f"mode       {'quick' if args.quick else 'full'}, {splits} splits, seed {args.seed}")
    slvs = solvers()
    real = [load_tabb(), load_eth("real"), load_eth("sim")]
    exact = load_24871()

    print(
        "\n1. Held out: fit X, Y on a random half, predict the other half's camera poses "
        "inv(X) inv(base_T_hand) Y;\n   RMS error over the held-out poses per split, "
        f"median / p90 over {splits} splits (fit deg/mm: in-sample RMS, median;\n"
        "   deg med', mm med': held-out medians with the lengths handed over in the other "
        "unit, m <-> mm; raises: file's unit + other).\n"
        "   Y: own = the solver's, mean = chordal mean of base_T_hand X camera_T_target "
        "over the fit half."
    )
    summary = []
    for i, d in enumerate(real):
        other = "m" if d.unit == "mm" else "mm"
        cols = held_out(d, i, slvs, splits, args.seed, d.unit)
        other_cols = held_out(d, i, slvs, splits, args.seed, other)
        print(
            f"\n{d.name}: {len(d.base_T_hand)} poses, fit {len(d.base_T_hand) // 2}, "
            f"lengths in {d.unit}; {d.note}"
        )
        rows = held_out_rows(d, slvs, cols, other_cols, splits)
        if d.hand_T_camera is not None and d.base_T_target is not None:
            rows.append(reference_row(d, i, splits, args.seed))
        print(format_table(HELD_HEADERS, rows))
        for s, h, o in zip(slvs, cols, other_cols, strict=True):
            for unit, col in ((d.unit, h), (other, o)):
                for msg, count in col.messages.items():
                    print(f"   {s.name} ({unit}) raised {count}x: {msg}")
        summary.append([d.name, "median", best_by(slvs, cols, 0), best_by(slvs, cols, 1)])
        summary.append(["", "split wins", split_wins(slvs, cols, 0), split_wins(slvs, cols, 1)])

    print(
        "\n   Best held out, lengths in the file's unit: the lowest three medians, and how "
        "often each solver\n   predicted best within a split (same split, paired)"
    )
    print(format_table(["dataset", "", "rotation, deg", "translation, mm"], summary))

    tabb = real[0]
    print(
        "\n2. Tabb DS1, every solver fitted on all 88 poses against Tabb's reference "
        "(AA_RPI, itself an estimate):\n   X = hand_T_camera vs inv(Z), Y = base_T_target "
        "vs inv(X_Tabb); lengths in mm (as published)"
    )
    tabb_fits = {u: full_fits(tabb, slvs, u) for u in ("mm", "m")}
    print(
        format_table(
            ["solver", "X deg", "X mm", "Y deg", "Y mm", "failure"],
            reference_rows(tabb, slvs, tabb_fits["mm"], "mm"),
        )
    )

    print(
        "\n3. OpenCV regression_24871 (4 exact views): error against the known X "
        "(and Y = the exact chain's)"
    )
    exact_fits = {u: full_fits(exact, slvs, u) for u in ("m", "mm")}
    for unit in ("m", "mm"):
        print(f"\n   lengths in {unit}{' (as in the file)' if unit == exact.unit else ''}")
        print(
            format_table(
                ["solver", "X deg", "X mm", "Y deg", "Y mm", "failure"],
                reference_rows(exact, slvs, exact_fits[unit], unit),
            )
        )

    print(
        "\n4. Length unit: every solver fitted on all poses in the file's unit and in the "
        f"other; change of X\n   (deg, mm); CHANGES above {UNIT_DEG:g} deg or {UNIT_MM:g} mm"
    )
    rows = []
    for d in (*real, exact):
        other = "m" if d.unit == "mm" else "mm"
        fits = (
            tabb_fits
            if d is tabb
            else exact_fits
            if d is exact
            else {u: full_fits(d, slvs, u) for u in ("m", "mm")}
        )
        rows += unit_rows(d, slvs, fits[d.unit], fits[other], other)
    print(format_table(["dataset", "solver", "X deg", "X mm", f"{'m vs mm'}"], rows))
    changes = sorted({r[1] for r in rows if r[4] == "CHANGES"})
    print(f"\n   answer changes with the length unit: {', '.join(changes) or 'none'}")
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
