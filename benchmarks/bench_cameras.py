"""Cameras anywhere: held-out error with the default options next to each forced
``--params`` set, per camera setup (issue 24, item 3).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_cameras.py [--sigma-px S] [--seed N]

Setups (the 6R arm of ``tests/robots.py``, true robot 2 mm / 0.5 deg off the nominal;
``tests/kinfw/observations/test_cameras_anywhere.py`` builds them): ``eye_in_hand`` (a
camera link on the flange, a board fixed in the world), ``eye_to_hand`` (a static camera
on a link fixed to the root, the board on the flange: ``target_frame``), ``stereo`` (a
static pair 12 cm apart sharing the board on the flange) and ``wrist`` (a camera on
``l5``, a world board): 30 training images and 15 held-out ones of other configurations,
an 8 x 5 board (30 mm), 640 x 480 pixels, Gaussian pixel noise (``--sigma-px``, default
0.5 px). ``import_csv_target``: a FIGAROH-style CSV of ``camera_T_board`` poses (camera on
the flange, board in the world; 50 training and 20 held-out rows, noise 1 mm and 0.2 deg
per axis) through ``kinfw import-csv --target board --frame flange --camera-frame
camera``.

Each row runs ``kinfw calibrate TRAIN --holdout HELD_OUT`` (in-process) with the default
``--params auto`` and with ``full``, ``offsets`` and ``frames``; the score is the report's
held-out RMS after calibration (pixels: the RMS of the per-point error norm |(du, dv)| in
px, scored with the board pose from training; poses: position mm / rotation deg), worst
camera first. ``expected`` for pixels is the noise floor sqrt(2) sigma (the norm of a 2-D
N(0, sigma^2) error).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import format_table

from kinfw.cli._main import main
from kinfw.measurements import write_measurements
from tests.kinfw.observations.test_cameras_anywhere import SETUPS, scene, setup_urdf

PARAMS = ("auto", "full", "offsets", "frames")


def _run(args: list[str]) -> None:
    """``kinfw`` in-process, quiet."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = main(args)
    if code != 0:
        raise RuntimeError(f"kinfw {' '.join(args)}: exit {code}")


def _calibrate(tmp: Path, train: Path, held: Path, urdf: Path, params: str) -> tuple[str, str]:
    report = tmp / f"report_{params}.json"
    args = ["calibrate", str(train), "--urdf", str(urdf), "--out", str(tmp / "cal.urdf")]
    args += ["--holdout", str(held), "--report", str(report)]
    if params != "auto":
        args += ["--params", params]
    _run(args)
    doc = json.loads(report.read_text())
    rows = doc["errors_held_out"]
    cells = []
    for r in sorted(rows, key=lambda r: -max(v for k, v in r.items() if k.startswith("after"))):
        after = {k[len("after_") :]: v for k, v in r.items() if k.startswith("after_")}
        cells.append(
            " / ".join(f"{v:.3f} {k.split('_')[-1]}" for k, v in after.items())
            + f" ({r['group'].split(' ')[0]})"
        )
    chosen = next((n for n in doc["notes"] if n.startswith("parameters:")), "")
    return "; ".join(cells), chosen.split("(")[0].replace("parameters:", "").strip()


def _pixel_setup(tmp: Path, name: str, sigma: float, seed: int) -> tuple[Path, Path, Path]:
    _, _, _, data, held_out = scene(name, 30, seed=seed, sigma_px=sigma, n_test=15)
    (tmp / "robot.urdf").write_text(setup_urdf(name))
    write_measurements(tmp / "train.json", data)
    write_measurements(tmp / "held_out.json", held_out)
    return tmp / "train.json", tmp / "held_out.json", tmp / "robot.urdf"


def _csv_setup(tmp: Path, seed: int) -> tuple[Path, Path, Path]:
    """A FIGAROH-style CSV of a flange camera's board poses, imported with --camera-frame."""
    import pinocchio as pin

    from kinfw.geometry import matrix_from_rotation_vector
    from kinfw.model import load_robot
    from kinfw.simulation import perturb_robot, random_configurations
    from tests.robots import ARM_6R

    urdf = ARM_6R.replace(
        "</robot>",
        '  <joint name="camera_joint" type="fixed">\n    <parent link="flange"/>'
        '<child link="camera"/>\n  </joint>\n  <link name="camera"/>\n</robot>',
    )
    (tmp / "robot.urdf").write_text(urdf)
    nominal = load_robot(urdf)
    rng = np.random.default_rng(seed)
    truth = load_robot(perturb_robot(nominal, rng))
    names = nominal.topology(("flange",)).joint_names
    flange_T_camera = np.eye(4)
    flange_T_camera[:3, :3] = matrix_from_rotation_vector([0.1, -0.2, 0.3])
    flange_T_camera[:3, 3] = [0.03, -0.05, 0.08]
    root_T_board = np.eye(4)
    root_T_board[:3, :3] = matrix_from_rotation_vector([3.0, 0.2, -0.1])
    root_T_board[:3, 3] = [0.6, 0.1, -0.2]
    for file, n in (("train.csv", 50), ("held_out.csv", 20)):
        qs = random_configurations(*nominal.joint_limits(names), n, rng, fraction=0.6)
        lines = [",".join(["x1", "y1", "z1", "phix1", "phiy1", "phiz1", *names])]
        for q in qs:
            T = (
                np.linalg.inv(truth.frame_poses(q, "flange", names) @ flange_T_camera)
                @ root_T_board
            )
            R = T[:3, :3] @ matrix_from_rotation_vector(rng.normal(0, np.radians(0.2), 3))
            xyz = T[:3, 3] + rng.normal(0, 1e-3, 3)
            rpy = pin.rpy.matrixToRpy(R)
            lines.append(",".join(repr(float(x)) for x in (*xyz, *rpy, *q)))
        (tmp / file).write_text("\n".join(lines) + "\n")
        out = tmp / file.replace(".csv", ".json")
        command = ["import-csv", str(tmp / file), "--urdf", str(tmp / "robot.urdf")]
        command += ["--frame", "flange", "--target", "board", "--camera-frame", "camera"]
        _run([*command, "--out", str(out)])
    return tmp / "train.json", tmp / "held_out.json", tmp / "robot.urdf"


def main_() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sigma-px", type=float, default=0.5)
    parser.add_argument("--seed", type=int, default=11)
    args = parser.parse_args()
    rows = []
    for name in (*SETUPS, "import_csv_target"):
        with tempfile.TemporaryDirectory() as d:
            tmp = Path(d)
            files = (
                _csv_setup(tmp, args.seed)
                if name == "import_csv_target"
                else _pixel_setup(tmp, name, args.sigma_px, args.seed)
            )
            for params in PARAMS:
                t0 = time.perf_counter()
                score, chosen = _calibrate(tmp, *files, params)
                label = f"auto -> {chosen}" if params == "auto" else params
                rows.append([name, label, score, f"{time.perf_counter() - t0:.1f}"])
    print(
        f"held-out error after calibration (pixel noise {args.sigma_px} px: floor "
        f"{np.sqrt(2) * args.sigma_px:.3f} px as |(du, dv)|), seed {args.seed}"
    )
    print(format_table(["setup", "--params", "held-out RMS (camera)", "s"], rows))


if __name__ == "__main__":
    main_()
