"""Real eye-in-hand images of a circle grid: held-out pixels with the default options next
to each forced parameter set (issue 24's development data).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_circles_real.py [--data DIR] [--k K]

Data: ros-industrial/industrial_calibration's ``examples/data/test_set_10x10`` (Apache-2.0;
15 images of a 10 x 10 "modified circle grid", 25.4 mm pitch, a larger origin dot, seen
by a Kinect on an industrial arm's wrist; the nominal intrinsics fx = fy = 550 px, no
distortion, uncalibrated), as ``tests/data/industrial_calibration_circles`` holds it
(its README gives the provenance). No joint angles were logged, only the flange poses;
they are written as the six-joint chain of ``kinfw pose-chain`` (x, y, z prismatic, then
yaw, pitch, roll about z, y, x: ``base_T_tool0 = Trans(x, y, z) Rz Ry Rx``), exact by
construction, with the camera's optical frame on a fixed joint of ``tool0`` (identity
start).
The right model is then the camera mount and the board pose alone ("frames"), and the
chain's URDF says so (``<kinfw exact>``): "offsets" and "full" leave its joints as
written, so every set is "frames" there (before, they fitted the uncalibrated
intrinsics' error into the chain).

Steps, each printed: ``kinfw detect`` (in-process) with
``circles:10x10:0.0254:0.01:0.02`` (the origin dot read, no ``--allow-symmetric``);
then k-fold cross-validation by image (seed 0): per fold ``identify`` on the training
images with ``frames``, ``offsets``, ``full``, ``frames`` with the intrinsics refined
(``--refine-intrinsics``, what ``kinfw calibrate``'s warning on these images advises: the
nominal values are not the camera's) and the default (``choose_parameters`` on the
training images, then its fit), and the held-out images' reprojection error (RMS of the
per-point error norm |(du, dv)|, px) with the board pose (and intrinsics) from training.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from benchmarks.common import format_table, machine_info, wall_time_line

DATA = REPO / "tests" / "data" / "industrial_calibration_circles"
BOARD = "circles:10x10:0.0254:0.01:0.02"
SETS = ("frames", "offsets", "full")


def joint_rows(flange_csv: Path) -> list[dict[str, str]]:
    """Per image its joint values on the pose chain
    (:func:`kinfw.model.pose_chain_joint_values`)."""
    from kinfw.geometry import transform_from_xyz_quat_xyzw
    from kinfw.model import POSE_CHAIN_JOINTS, pose_chain_joint_values

    with flange_csv.open(newline="") as f:
        rows = list(csv.DictReader(f))
    base_T_tool0 = np.stack(
        [
            transform_from_xyz_quat_xyzw(
                [float(r[k]) for k in "xyz"], [float(r[k]) for k in ("qx", "qy", "qz", "qw")]
            )
            for r in rows
        ]
    )
    q = pose_chain_joint_values(base_T_tool0)
    return [
        {
            "image": r["image"],
            **{n: repr(float(v)) for n, v in zip(POSE_CHAIN_JOINTS, qi, strict=True)},
        }
        for r, qi in zip(rows, q, strict=True)
    ]


def detect(data_dir: Path, tmp: Path) -> Path:
    """``kinfw detect`` on the images: the measurement file."""
    from kinfw.cli._main import main

    rows = joint_rows(data_dir / "flange_poses.csv")
    joints = tmp / "joints.csv"
    with joints.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    out = tmp / "circles.json"
    images = [str(data_dir / "images" / r["image"]) for r in rows]
    args = ["detect", *images, "--board", BOARD, "--joints", str(joints)]
    args += ["--camera", str(data_dir / "camera.yaml"), "--frame", "camera_optical"]
    said = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(said):
        code = main([*args, "--out", str(out)])
    if code != 0:
        raise SystemExit(f"kinfw detect failed (exit {code}): {said.getvalue()[-500:]}")
    return out


def pixel_errors(nominal, fit, test) -> np.ndarray:
    """Each held-out image's reprojection error (the kind's "pixel" metric), px."""
    from kinfw.verification.evaluation import fitted_unknowns, held_out_errors

    held = held_out_errors(nominal, fit.urdf_xml, fitted_unknowns(fit), test)
    return np.concatenate([np.ravel(g.of("pixel").shown()) for g in held.groups])


def _rms(values: np.ndarray) -> float:
    """RMS of the finite values (NaN when a set was refused on some fold)."""
    return float(np.sqrt(np.mean(np.square(values))))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA, help=f"data folder ({DATA})")
    parser.add_argument("--k", type=int, default=5, help="folds (5)")
    args = parser.parse_args(argv)
    if not (args.data / "flange_poses.csv").is_file():
        print(f"bench_circles_real: no flange_poses.csv in {args.data}", file=sys.stderr)
        return 2
    from kinfw.identification import identify
    from kinfw.measurements import read_measurements
    from kinfw.model import load_robot, pose_chain_urdf
    from kinfw.verification.evaluation import choose_parameters

    started = time.perf_counter()
    print(machine_info())
    with tempfile.TemporaryDirectory() as tmp:
        urdf = Path(tmp, "chain.urdf")
        urdf.write_text(pose_chain_urdf(camera="camera_optical", hand="tool0", base="base_link"))
        nominal = load_robot(urdf)
        data = read_measurements(detect(args.data, Path(tmp)))
    print(f"\n{data.n_samples} images detected ({BOARD}); {args.k}-fold by image, seed 0")
    order = np.random.default_rng(0).permutation(data.n_samples)
    folds = [np.sort(f) for f in np.array_split(order, args.k)]
    refined = "frames, intrinsics refined"
    errors = {name: [] for name in (*SETS, refined, "default (--params auto)")}
    picks, refusals = [], []
    warnings.simplefilter("ignore")  # the fits' data warnings; the benchmark reads numbers
    for test_ids in folds:
        train = data.subset(np.setdiff1d(np.arange(data.n_samples), test_ids))
        test = data.subset(test_ids)
        for name in SETS:
            try:
                fit = identify(nominal, train, parameters=name)
            except ValueError as refused:  # too little data for the set: said, not scored
                errors[name].append(np.full(len(test_ids), np.nan))
                refusals.append(f"{name} on fold {len(picks)}: {str(refused)[:160]}...")
                continue
            errors[name].append(pixel_errors(nominal, fit, test))
        fit = identify(nominal, train, parameters="frames", refine_intrinsics=True)
        errors[refined].append(pixel_errors(nominal, fit, test))
        choice = choose_parameters(nominal, train)
        fit = choice.fit or identify(
            nominal, train, parameters=choice.parameters, prior=choice.prior
        )
        errors["default (--params auto)"].append(pixel_errors(nominal, fit, test))
        picks.append(choice.label)
    rows = [
        [
            name,
            f"{_rms(np.concatenate(v)):.2f}",
            " ".join(f"{_rms(e):.2f}" for e in v),
        ]
        for name, v in errors.items()
    ]
    print(format_table(["model", "held-out px (all images)", "per fold"], rows))
    print("default's pick per fold: " + "; ".join(picks))
    print("\n".join(f"refused: {r}" for r in refusals))
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
