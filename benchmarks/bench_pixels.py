"""Pixels against PnP poses on the same images, and the pixel path against its
Cramér-Rao bound.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_pixels.py [--seeds N] [--images] [--sigma-px S]

Two experiments, each over N seeds (a new true robot, board views and noise per seed):

- ``head``: the IIS-head demo with stage 2 from images (``kinfw demo --pixels``): stage 1
  plate poses one joint at a time (55, 0.5 mm / 0.5 deg), stage 2 a 9 x 6 chessboard
  (40 mm squares) seen by both cameras (640 x 480, fx = fy = 600 px) at 30 random
  configurations where one of them sees the whole board; true robot 5 mm / 1 deg errors.
- ``arm``: the 6R arm of ``tests/robots.py`` with a flange camera (same intrinsics)
  seeing the same board 0.6 m away: 25 configurations within +-0.35 rad of a working
  pose where the whole board is in view; true robot 2 mm / 0.5 deg errors.

Pixels: the exact projection plus Gaussian noise (sigma ``--sigma-px``, default 0.5 px),
or with ``--images`` rendered images (``kinfw.simulation``, 2 grey levels of
noise) and ``kinfw detect``'s corners (sigma: the detections' RMS error per coordinate).

Both paths calibrate the same detections (``kinfw.identification.identify``, method
refine, linear loss, noise estimated): ``pixels`` on reprojection error, ``pnp`` on each
image's PnP pose (``cv2.solvePnP`` + LM refinement) as ``target`` observations. Score:
``camera_T_target`` (the board in each camera) at 100 fresh configurations against the
true robot, RMS position (mm) and rotation angle (deg), the RMS over the seeds
(``sqrt(mean of the per-seed mean squares)``). ``CRLB``: the bound of the pixel path's
held-out error at the known noise (``kinfw.verification.studies.crlb_held_out``), the same
RMS over seeds; ``px/CRLB`` the achieved pixel-path RMS over it.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import format_table, machine_info

from kinfw.camera import CameraIntrinsics, Chessboard
from kinfw.identification import identify
from kinfw.model import Robot, builtin_head_urdf, load_robot
from kinfw.verification.studies import (
    arm_experiment,
    crlb_held_out,
    head_experiment,
    held_out_errors,
    pose_path_data,
    rendered_detections,
    target_pose,
)
from tests.robots import ARM_6R

BOARD = Chessboard(9, 6, 0.04)
FLANGE_CAMERA = CameraIntrinsics(640, 480, 600.0, 600.0, 319.5, 239.5, name="flange")
ARM_Q0 = np.array([0.3, -0.4, 0.9, 0.2, 0.7, -0.3])


def experiment(which: str, seed: int, sigma_px: float):
    if which == "head":
        return head_experiment(
            load_robot(builtin_head_urdf()), seed, board=BOARD, sigma_px=sigma_px
        )
    return arm_experiment(
        load_robot(ARM_6R),
        seed,
        camera="flange",
        intrinsics=FLANGE_CAMERA,
        q0=ARM_Q0,
        board=BOARD,
        sigma_px=sigma_px,
    )


def trial(which: str, seed: int, sigma_px: float, images: bool) -> dict[str, tuple]:
    exp = experiment(which, seed, sigma_px)
    sigma = sigma_px
    if images:
        exp, sigma = rendered_detections(exp, BOARD, seed=seed)
    out: dict[str, tuple] = {"sigma": (sigma,)}
    for path, data in (("pixels", exp.data), ("pnp", pose_path_data(exp.data))):
        result = identify(exp.nominal, data, method="refine", loss="linear")
        robot = Robot(result.urdf_xml, f"<{path}>")
        out[path] = held_out_errors(exp, robot, target_pose(result.refined.unknowns))
    out["crlb"] = crlb_held_out(exp)[:2]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--sigma-px", type=float, default=0.5)
    parser.add_argument("--images", action="store_true", help="render and detect the images")
    args = parser.parse_args()
    print(machine_info())
    mode = "rendered images, detected corners" if args.images else "exact + Gaussian noise"
    print(f"pixels: {mode}; sigma {args.sigma_px} px; {args.seeds} seeds\n")
    rows = []
    for which in ("head", "arm"):
        start = time.perf_counter()
        trials = [trial(which, s, args.sigma_px, args.images) for s in range(args.seeds)]
        seconds = (time.perf_counter() - start) / args.seeds

        def rms(key, i, trials=trials):
            return float(np.sqrt(np.mean([t[key][i] for t in trials])))

        px_mm, px_deg = 1e3 * rms("pixels", 0), np.degrees(rms("pixels", 1))
        pnp_mm, pnp_deg = 1e3 * rms("pnp", 0), np.degrees(rms("pnp", 1))
        b_mm, b_deg = 1e3 * rms("crlb", 0), np.degrees(rms("crlb", 1))
        sigma = np.mean([t["sigma"][0] for t in trials])
        rows.append(
            [
                which,
                f"{sigma:.3f}",
                f"{px_mm:.3f} / {px_deg:.4f}",
                f"{pnp_mm:.3f} / {pnp_deg:.4f}",
                f"{px_mm / pnp_mm:.2f} / {px_deg / pnp_deg:.2f}",
                f"{b_mm:.3f} / {b_deg:.4f}",
                f"{px_mm / b_mm:.2f} / {px_deg / b_deg:.2f}",
                f"{seconds:.1f}",
            ]
        )
    print(
        format_table(
            [
                "experiment",
                "sigma px",
                "pixels mm / deg",
                "PnP mm / deg",
                "pixels/PnP",
                "CRLB mm / deg",
                "pixels/CRLB",
                "s/seed",
            ],
            rows,
        )
    )


if __name__ == "__main__":
    main()
