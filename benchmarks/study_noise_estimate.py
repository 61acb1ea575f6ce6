"""Bias of the estimated measurement noise of ``refine``, per robust loss, on demo data.

Run from the repository root::

    python benchmarks/study_noise_estimate.py                  # 30 seeds, ~1 minute
    python benchmarks/study_noise_estimate.py --seeds 10 --outliers 0.05

Data as ``kinfw demo``: the IIS-head with 5 mm / 1 deg errors, stage 1 plates one joint
at a time (9 values per joint), stage 2 both cameras on a fixed target in 30 random
configurations, noise 0.5 mm per position component and a rotation by an angle
N(0, 0.5 deg) about a uniformly random axis (:func:`kinfw.simulation.perturb_poses`),
so the true orientation sigma per component is 0.5 / sqrt(3) = 0.289 deg. With
``--outliers f`` a fraction ``f`` of the pose and target observations is moved by 20 mm
and turned by 10 deg (:func:`kinfw.simulation.plant_outliers`). ``refine`` starts from
the nominal and estimates the noise (no ``noise`` given), once per loss.

Prints, per loss, the estimated sigmas averaged over the seeds, their ratio to the truth
and the standard deviation of that ratio over the seeds.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # study the code next to this script, installed or not
    sys.path.insert(0, str(REPO))

from benchmarks.common import format_table
from kinfw.identification import refine
from kinfw.identification.problem import LOSSES
from kinfw.measurements import Measurements, concatenate_measurements
from kinfw.model import Robot, builtin_head_urdf, load_robot
from kinfw.simulation import (
    default_target_pose,
    one_joint_at_a_time,
    perturb_robot,
    plant_outliers,
    random_configurations,
    simulate_at,
)

NOISE_M, NOISE_RAD = 0.5e-3, np.radians(0.5)


def demo_data(seed: int, outliers: float) -> tuple[Robot, Measurements]:
    """The nominal head and a ``kinfw demo`` dataset of a perturbed one."""
    nominal = load_robot(builtin_head_urdf())
    rng = np.random.default_rng(seed)
    truth = load_robot(perturb_robot(nominal, rng, origin_mm=5.0, origin_deg=1.0, axis_deg=1.0))
    plates, cameras = nominal.default_frames, nominal.default_cameras
    names = nominal.topology((*plates, *cameras)).joint_names
    lower, upper = nominal.joint_limits(names)
    noise = {"noise_m": NOISE_M, "noise_rad": NOISE_RAD}
    qs1, _ = one_joint_at_a_time(lower, upper, per_joint=9, fraction=0.8)
    qs2 = random_configurations(lower, upper, 30, rng, fraction=0.8)
    w_T_target = default_target_pose(truth, qs2, names, cameras)
    data = concatenate_measurements(
        simulate_at(truth, qs1, names, frames=plates, rng=rng, **noise),
        simulate_at(truth, qs2, names, cameras=cameras, rng=rng, w_T_target=w_T_target, **noise),
    )
    if outliers > 0.0:
        data, _ = plant_outliers(
            data, rng, fraction=outliers, distance_m=0.02, angle_rad=np.radians(10.0)
        )
    return nominal, data


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=30, help="datasets (default 30)")
    parser.add_argument(
        "--outliers", type=float, default=0.0, help="fraction of gross outliers (default 0)"
    )
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    sigmas = {loss: [] for loss in LOSSES}
    for seed in range(args.seeds):
        nominal, data = demo_data(seed, args.outliers)
        for loss in LOSSES:
            noise = refine(nominal, data, loss=loss).noise
            sigmas[loss].append(
                (noise.position_m / NOISE_M, noise.rotation_rad / (NOISE_RAD / np.sqrt(3.0)))
            )
    rows = []
    for loss, ratios in sigmas.items():
        r = np.array(ratios)
        mean, sd = r.mean(axis=0), r.std(axis=0, ddof=1) if len(r) > 1 else np.zeros(2)
        rows.append(
            [
                loss,
                f"{1e3 * NOISE_M * mean[0]:.4f}",
                f"{mean[0]:.3f}",
                f"{sd[0]:.3f}",
                f"{np.degrees(NOISE_RAD) / np.sqrt(3.0) * mean[1]:.4f}",
                f"{mean[1]:.3f}",
                f"{sd[1]:.3f}",
            ]
        )
    print(
        f"estimated noise of refine on kinfw-demo data, {args.seeds} seeds, "
        f"{args.outliers:.0%} gross outliers; truth 0.5 mm per axis, "
        f"{np.degrees(NOISE_RAD) / np.sqrt(3.0):.4f} deg per orientation component"
    )
    print(format_table(["loss", "position mm", "ratio", "sd", "rotation deg", "ratio", "sd"], rows))
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
