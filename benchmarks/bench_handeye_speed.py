"""Time per solve of kinfw's hand-eye solvers against OpenCV's AX = XB methods.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_handeye_speed.py

Milliseconds per solve at 3, 10, 30 and 100 views: the median over 5 trials (regime 0 of
``handeye_regimes``: well spread motions, 1 deg + 2 mm camera noise) of the best of 3
repeats. Single-threaded; on a loaded machine the numbers move by ~30 %.
"""

import contextlib
import logging
import sys
import timeit
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import handeye_regimes as hr

from kinfw.identification.handeye import solve_axxb, solve_axyb


def main() -> None:
    import cv2

    logging.disable(logging.CRITICAL)
    methods = {
        k: getattr(cv2, "CALIB_HAND_EYE_" + k)
        for k in ("TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS")
    }
    for n in (3, 10, 30, 100):
        times: dict[str, list[float]] = {k: [] for k in ("axxb", "axyb", *methods)}
        for t in range(5):
            tr = hr.make_trial(np.random.default_rng([0, 100, n, t]), hr.REGIMES[0], n_views=n)
            A, C = tr.base_T_hand, tr.camera_T_target
            A_inv = np.linalg.inv(A)
            R_g, t_g = list(A[:, :3, :3]), list(A[:, :3, 3])
            R_c, t_c = list(C[:, :3, :3]), list(C[:, :3, 3])
            calls = {
                "axxb": lambda A=A, C=C: solve_axxb(base_T_hands=A, camera_T_targets=C),
                "axyb": lambda C=C, A_inv=A_inv: solve_axyb(camera_T_targets=C, hand_T_bases=A_inv),
            }
            for k, m in methods.items():
                calls[k] = lambda m=m, a=(R_g, t_g, R_c, t_c): cv2.calibrateHandEye(*a, method=m)
            for k, call in calls.items():
                with contextlib.suppress(Exception):  # timing only: bench_handeye counts
                    call()
                number = 2 if n == 100 else 10
                best = min(timeit.repeat(call, number=number, repeat=3)) / number
                times[k].append(best)
        med = {k: 1e3 * float(np.median(v)) for k, v in times.items()}
        fastest = min(methods, key=lambda k: med[k])
        print(
            f"n={n:3d}  solve_axxb {med['axxb']:.3f}  solve_axyb {med['axyb']:.3f}  "
            f"cv TSAI {med['TSAI']:.3f}  fastest cv {fastest} {med[fastest]:.3f}  (ms)",
            flush=True,
        )


if __name__ == "__main__":
    main()
