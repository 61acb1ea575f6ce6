"""The plausibility guard's false alarms: the largest ratio of a change to the guard's
bound on the project's clean simulated data and on its real development data (issue 35):
the TIAGo recordings of FIGAROH (Vicon, eye-hand 12 and 401 samples) and
industrial_calibration's circle grid, under ``tests/data``.
A ratio above 1 would refuse the calibration; every row should stay below it.

Each row calibrates as ``kinfw calibrate`` does by default (``--params auto``) through
:func:`kinfw.verification.reporting.calibrate_and_report` and prints the largest change
and its ratio (:attr:`kinfw.identification.checks.Plausibility.largest_ratio`). The
simulated sets are what ``kinfw simulate`` writes (default errors 2 mm / 0.5 deg) and what
``benchmarks/bench_contacts.py`` and ``benchmarks/bench_cameras.py`` simulate; the demo
is ``kinfw demo``'s own data, with the bound it states for its 5 mm / 1 deg head
(``DEMO_BOUND``) and with the default.

Run: ``python benchmarks/guard_ratios.py`` (a few minutes; needs example-robot-data).
"""

from __future__ import annotations

import math
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_circles_real import detect
from kinfw import builtin_head_urdf
from kinfw.identification.checks import plausibility
from kinfw.measurements import read_measurements, write_measurements
from kinfw.model import load_robot, pose_chain_urdf
from kinfw.verification.reporting import calibrate_and_report
from tests.erd import urdf_path
from tests.kinfw.observations.test_cameras_anywhere import SETUPS, scene, setup_urdf

HEAD = str(builtin_head_urdf())
UR10 = str(urdf_path("ur_description/urdf/ur10_robot.urdf"))
TALOS = str(urdf_path("talos_data/robots/talos_full_v2.urdf"))
TIAGO = str(urdf_path("tiago_description/robots/tiago_no_hand.urdf"))
VICON = ROOT / "tests/data/tiago_figaroh/vicon_gripper3_base1.json"
FIGAROH = ROOT / "tests/data/tiago_figaroh"
EYE_HAND = (
    ("eh12", FIGAROH / "eye_hand_calibration_recorded_data_48c_hey5_12_test1.csv", 12),
    ("eh401", FIGAROH / "eye_hand_calibration_recorded_data_palhey5_401.csv", 401),
)

#: name: (URDF, ``kinfw simulate`` options)
SIMULATED = {
    "head, stage 1 poses": (HEAD, []),
    "head, stage 1 + 2 targets": (HEAD, ["--stage", "both"]),
    "head, mocap markers": (
        HEAD,
        [
            "--markers",
            "left_plate",
            "--markers",
            "right_plate:0,0.03,0.01",
            "--mocap-frame",
            "vicon",
            "--mocap-samples",
            "40",
            "--noise-mm",
            "0.5",
        ],
    ),
    "head, plane contacts": (
        HEAD,
        ["--contacts", "left_plate", "--contact-samples", "60", "--noise-mm", "0.2"],
    ),
    "UR10, mocap markers": (
        UR10,
        [
            "--markers",
            "tool0",
            "--markers",
            "tool0:0,0.05,0.02",
            "--mocap-frame",
            "vicon",
            "--mocap-samples",
            "60",
            "--noise-mm",
            "0.2",
        ],
    ),
    "UR10, plane contacts (bench_contacts)": (
        UR10,
        ["--contacts", "tool0", "--contact-samples", "120", "--noise-mm", "0.2"],
    ),
    "UR10, sphere contacts (bench_contacts)": (
        UR10,
        ["--contacts", "tool0", "--sphere", "0.6,0.2,0.3,0.05", "--contact-samples", "120"],
    ),
    "TALOS, two arms on a table (bench_contacts)": (
        TALOS,
        [
            "--contacts",
            "arm_left_7_link",
            "--contacts",
            "arm_right_7_link",
            "--contact-samples",
            "120",
            "--noise-mm",
            "0.2",
        ],
    ),
}


def _row(name: str, urdf: str, data_path: Path) -> str:
    nominal, data = load_robot(urdf), read_measurements(data_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            result = calibrate_and_report(nominal, data)
        except ValueError as exc:
            return f"| {name} | refused before the guard: {str(exc).splitlines()[0][:90]} | | |"
    v = result.plausibility
    top = v.changes[0].text() if v.changes else "nothing changed"
    return f"| {name} | {result.model.label} | {v.bound_text()} | {v.largest_ratio:.3g} | {top} |"


def _talos_in_the_foot() -> str:
    """TALOS standing on its left foot, one hand's probe on a table fixed in the foot
    (``measured_in``), as ``tests/identification/test_foot_plane.py`` simulates it."""
    import numpy as np

    from kinfw.simulation import perturb_robot
    from tests.contacts import two_arm_contacts
    from tests.identification.test_foot_plane import FOOT, JOINTS, STANCE, _table_in_foot

    urdf = str(urdf_path("talos_data/robots/talos_reduced.urdf"))
    nominal, rng = load_robot(urdf), np.random.default_rng(1)
    truth = load_robot(perturb_robot(nominal, rng, joints=JOINTS))
    offsets = {"arm_left_7_link": np.array([0.01, 0.02, -0.2])}
    data = two_arm_contacts(
        truth,
        _table_in_foot(truth),
        offsets,
        60,
        rng,
        measured_in=FOOT,
        joint_names=JOINTS,
        fixed=STANCE,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = calibrate_and_report(nominal, data)
    v = result.plausibility
    return (
        f"| TALOS, one hand on a table fixed in the stance foot | {result.model.label} | "
        f"{v.bound_text()} | {v.largest_ratio:.3g} | {v.changes[0].text()} |"
    )


def main() -> None:
    print("| data | model chosen | bound | largest ratio | largest change |")
    print("|---|---|---|---:|---|")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for k, (name, (urdf, options)) in enumerate(SIMULATED.items()):
            out = work / f"{k}.json"
            argv = [sys.executable, "-m", "kinfw.cli", "-q", "simulate", "--urdf", urdf]
            argv += [*options, "--out", str(out), "--truth-out", str(work / f"{k}_true.urdf")]
            proc = subprocess.run(argv, capture_output=True, text=True)
            if proc.returncode:
                print(f"| {name} | simulate failed: {proc.stderr.strip()[:100]} | | | |")
                continue
            print(_row(name, urdf, out), flush=True)
        print(_row("TIAGo Vicon (FIGAROH, real)", TIAGO, VICON), flush=True)
        for name, csv, n in EYE_HAND:
            out = work / f"{name}.json"
            argv = [sys.executable, "-m", "kinfw.cli", "-q", "import-csv", str(csv), "--urdf"]
            argv += [TIAGO, "--frame", "arm_7_link", "--measured-in", "xtion_rgb_optical_frame"]
            subprocess.run([*argv, "--out", str(out)], check=True, capture_output=True)
            print(_row(f"TIAGo eye-hand, {n} samples (FIGAROH, real)", TIAGO, out), flush=True)
        chain = work / "chain.urdf"
        chain.write_text(pose_chain_urdf(camera="camera_optical", hand="tool0", base="base_link"))
        circles = detect(ROOT / "tests/data/industrial_calibration_circles", work)
        print(_row("industrial_calibration circle grid (real)", str(chain), circles), flush=True)
        print(_talos_in_the_foot(), flush=True)
        for name in SETUPS:  # benchmarks/bench_cameras.py's scenes, its seed 11, 0.5 px
            _, _, _, data, _ = scene(name, 30, seed=11, sigma_px=0.5, n_test=15)
            (work / f"{name}.urdf").write_text(setup_urdf(name))
            write_measurements(work / f"{name}.json", data)
            label = f"cameras, {name} (bench_cameras)"
            print(_row(label, str(work / f"{name}.urdf"), work / f"{name}.json"), flush=True)
        from kinfw.verification.studies import run_demo

        guard = run_demo(work / "demo").report.guard  # the bound it states for its head
        print(
            f"| kinfw demo (its own bound) | full | {1e3 * guard.bound_m:.3g} mm / "
            f"{math.degrees(guard.bound_rad):.3g} deg | {guard.largest_ratio:.3g} | "
            f"{guard.largest} |"
        )
        v = plausibility(load_robot(HEAD), load_robot(work / "demo" / "calibrated.urdf"), None)
        print(
            f"| kinfw demo (default bound) | full | {v.bound_text()} | "
            f"{v.largest_ratio:.3g} | {v.changes[0].text()} |"
        )


if __name__ == "__main__":
    main()
