"""The plausibility guard's false alarms: the largest ratio of a change to the guard's
bound on the project's clean simulated data and on its real development data (issue 35).
A ratio above 1 would refuse the calibration; every row should stay below it.

Each row calibrates as ``kinfw calibrate`` does by default (``--params auto``) through
:func:`kinfw.verification.reporting.calibrate_and_report` and prints the largest change
and its ratio (:attr:`kinfw.identification.checks.Plausibility.largest_ratio`). The
simulated sets are what ``kinfw simulate`` writes (default errors 2 mm / 0.5 deg) and what
``benchmarks/bench_contacts.py`` simulates; the demo is ``kinfw demo``'s own data, with
the bound it states for its 5 mm / 1 deg head (``DEMO_BOUND``) and with the default.

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

from kinfw import builtin_head_urdf
from kinfw.identification.checks import plausibility
from kinfw.measurements import read_measurements
from kinfw.model import load_robot
from kinfw.verification.reporting import calibrate_and_report
from tests.erd import urdf_path

HEAD = str(builtin_head_urdf())
UR10 = str(urdf_path("ur_description/urdf/ur10_robot.urdf"))
TALOS = str(urdf_path("talos_data/robots/talos_full_v2.urdf"))
TIAGO = str(urdf_path("tiago_description/robots/tiago_no_hand.urdf"))
VICON = ROOT / "tests/data/tiago_figaroh/vicon_gripper3_base1.json"

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
    "TALOS, one arm on a table measured in the foot": (
        TALOS,
        [
            "--contacts",
            "arm_left_7_link",
            "--plane-frame",
            "leg_left_6_link",
            "--plane",
            "0,0,1,-0.9",
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
