"""Closed-form hand-eye starts (kinfw.identification.handeye) against OpenCV's same methods.

Run from the repository root with the ``bench`` extra installed::

    python benchmarks/bench_handeye_starts.py            # 200 trials, ~1 minute
    python benchmarks/bench_handeye_starts.py --trials 50

Synthetic data (metres), the generator of
``tests/identification/handeye/test_handeye_starts.py``: a random
``hand_T_eye`` (rotation uniform, translation N(0, 5 cm) per axis), a reference hand pose
with the target 0.6 m along the camera's z axis, hand poses = reference turned by
U(0, max_deg) about a random axis and shifted U(-0.25, 0.25) m per axis; camera poses with
noise: a rotation by exactly 1 deg about a random axis and N(0, 2 mm) per axis.
"small" is max_deg = 7.5 (relative motions <= 15 deg), "spread" is max_deg = 75.

Prints, per regime and method, the median / 90th percentile of the X rotation error (deg)
and translation error (mm), ours and OpenCV's, then the median time per call at 3, 10, 30
and 100 views (``time.perf_counter``, warmed up, GC disabled).
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests")]

import cv2
from test_handeye_starts import ALL, AXYB_NAMES, _axyb, _errors, _opencv, _scene


def accuracy(trials: int, n: int, max_deg: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    errs = {k: [] for k in ALL}
    for _ in range(trials):
        X, Y, A, B = _scene(rng, n, max_deg=max_deg, noise=(1.0, 2.0))
        Xp, _, Ap, Bp = _axyb(X, Y, A, B)
        for name, solve in ALL.items():
            truth, a, b = (Xp, Ap, Bp) if name in AXYB_NAMES else (X, A, B)
            ours = _errors(solve(a, b)[0], truth)
            cv = _errors(_opencv(cv2, name, a, b)[0], truth)
            errs[name].append(ours + cv)
    print(f"\n{n} views, hand turned <= {max_deg} deg, {trials} trials: X error median / p90")
    head = ("ours deg", "OpenCV deg", "ours mm", "OpenCV mm")
    print(f"{'method':11s} " + " ".join(f"{h:>14s}" for h in head))
    for name, v in errs.items():
        v = np.array(v)
        cols = [
            f"{np.median(v[:, k]) * f:6.3g} / {np.percentile(v[:, k], 90) * f:5.3g}"
            for k, f in ((0, 1), (2, 1), (1, 1e3), (3, 1e3))
        ]
        print(f"{name:11s} " + " ".join(f"{c:>14s}" for c in cols))


def _time(fn, args, reps: int) -> float:
    for _ in range(3):
        fn(*args)
    gc.disable()
    try:
        ts = []
        for _ in range(reps):
            t0 = time.perf_counter()
            fn(*args)
            ts.append(time.perf_counter() - t0)
    finally:
        gc.enable()
    return float(np.median(ts))


def _raw_opencv(name: str):
    """OpenCV's call alone, inputs prepared outside (R and t stacks)."""
    if name in AXYB_NAMES:
        method = getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{name.upper()}")
        return lambda *a: cv2.calibrateRobotWorldHandEye(*a, method=method)
    method = getattr(cv2, f"CALIB_HAND_EYE_{name.upper()}")
    return lambda *a: cv2.calibrateHandEye(*a, method=method)


def timing(seed: int) -> None:
    print("\nmedian time per call, ms (ours / OpenCV), well-spread data")
    views = (3, 10, 30, 100)
    print(f"{'method':11s} " + " ".join(f"{f'{n} views':>16s}" for n in views))
    rng = np.random.default_rng(seed)
    data = {n: _scene(rng, n, max_deg=75.0, noise=(1.0, 2.0)) for n in views}
    for name, solve in ALL.items():
        cells = []
        for n in views:
            X, Y, A, B = data[n]
            if name in AXYB_NAMES:
                _, _, A, B = _axyb(X, Y, A, B)
            A, B = np.ascontiguousarray(A), np.ascontiguousarray(B)
            reps = 200 if n <= 30 else 30
            ours = _time(solve, (A, B), reps)
            cv_args = tuple(np.ascontiguousarray(x) for x in (A[:, :3, :3], A[:, :3, 3]))
            cv_args += tuple(np.ascontiguousarray(x) for x in (B[:, :3, :3], B[:, :3, 3]))
            cv = _time(_raw_opencv(name), cv_args, reps)
            cells.append(f"{ours * 1e3:6.3f} / {cv * 1e3:6.3f}")
        print(f"{name:11s} " + " ".join(f"{c:>16s}" for c in cells))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--trials", type=int, default=200)
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args()
    for n, max_deg in ((10, 7.5), (30, 7.5), (10, 75.0), (3, 75.0)):
        accuracy(args.trials, n, max_deg, args.seed)
    timing(args.seed)


if __name__ == "__main__":
    main()
