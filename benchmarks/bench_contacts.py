"""Contacts: held-out error with the default options next to each forced ``--params`` set,
per contact setup (issue 24, items 1 and 2), on simulated data.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_contacts.py [--noise-mm S] [--seed N]

Every setup is made by ``kinfw simulate`` (a true robot 2 mm / 0.5 deg off the nominal
URDF of example-robot-data, a probe of unknown offset on the named link, ``--noise-mm``
per contact, default 0.1 mm) and split by sample, alternately, into training and
held-out halves (so each probe and contact is in both):

- ``ur10_plane``: a UR10, a probe on ``tool0`` touching a table (``--plane``'s default,
  normal to the root's z), 60 training / 60 held-out contacts (1 row each: about one row
  per parameter of the full set);
- ``ur10_plane_400``: the same with 400 / 100 (enough rows for the full set);
- ``ur10_sphere``: the probe on a ball of known radius (5 cm, centre unknown), 60 / 60;
- ``ur10_point``: the probe placed on a divot in many orientations (3 rows each), 60 / 60;
- ``talos_table``: TALOS's two arms (``arm_left_7_link``, ``arm_right_7_link``) touching
  one table, 60 / 60 contacts per arm, fitted jointly (torso shared).

Each row runs ``kinfw calibrate TRAIN --holdout HELD_OUT`` (in-process) with the default
``--params auto`` and with ``full``, ``offsets`` and ``frames``; the score is the report's
held-out RMS after calibration in each kind's own metric (plane: the distance to the
trained plane, mm; sphere: the distance to the trained ball's surface, mm; divot: the
placement error, mm), worst group first, with the plane's tilt where it has one. A
refused set prints the start of its refusal. The noise floor of a one-row contact is the
noise itself (plus the parameters' share: ``sigma sqrt(1 + p / n)``).
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

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # for benchmarks.common and tests.erd
    sys.path.insert(0, str(REPO))

from benchmarks.common import format_table, machine_info, wall_time_line
from kinfw.cli._main import main
from tests.erd import urdf_path

PARAMS = ("auto", "full", "offsets", "frames")
UR10 = "ur_description/urdf/ur10_robot.urdf"
TALOS = "talos_data/robots/talos_full_v2.urdf"

#: name: (URDF in example-robot-data, ``kinfw simulate`` contact options, contacts)
SETUPS = {
    "ur10_plane": (UR10, ["--contacts", "tool0"], 120),
    "ur10_plane_400": (UR10, ["--contacts", "tool0"], 500),
    "ur10_sphere": (UR10, ["--contacts", "tool0", "--sphere", "0.6,0.2,0.3,0.05"], 120),
    "ur10_point": (UR10, ["--contacts", "tool0:0,0,0.05", "--point", "0.6,0.2,0.3"], 120),
    "talos_table": (
        TALOS,
        ["--contacts", "arm_left_7_link", "--contacts", "arm_right_7_link"],
        120,
    ),
}


def _run(args: list[str]) -> tuple[int, str]:
    """``kinfw -q ARGS`` in-process: the exit code and what it said on stderr."""
    said = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(said):
        code = main(["-q", *args])
    return code, said.getvalue()


def simulate(tmp: Path, name: str, noise_mm: float, seed: int) -> tuple[Path, Path, Path]:
    """The setup's training and held-out files (alternate samples) and its URDF."""
    urdf, options, n = SETUPS[name]
    urdf = str(urdf_path(urdf))
    argv = ["simulate", "--urdf", urdf, *options, "--contact-samples", str(n)]
    argv += ["--noise-mm", str(noise_mm), "--seed", str(seed)]
    code, said = _run([*argv, "--out", str(tmp / "all.json"), "--truth-out", str(tmp / "t.urdf")])
    if code != 0:
        raise SystemExit(f"kinfw simulate {name}: exit {code}: {said[-400:]}")
    doc = json.loads((tmp / "all.json").read_text())
    held = 100 if n > 200 else None  # the large set: 100 held out, the rest trained
    for part, samples in (
        ("train", doc["samples"][0::2] if held is None else doc["samples"][held:]),
        ("held", doc["samples"][1::2] if held is None else doc["samples"][:held]),
    ):
        (tmp / f"{part}.json").write_text(json.dumps({**doc, "samples": samples}))
    return tmp / "train.json", tmp / "held.json", Path(urdf)


def calibrate(tmp: Path, train: Path, held: Path, urdf: Path, params: str) -> tuple[str, str]:
    """The held-out errors after calibrating with ``params`` (or the refusal), and the
    set the default chose."""
    report = tmp / f"report_{params}.json"
    args = ["calibrate", str(train), "--urdf", str(urdf), "--out", str(tmp / "cal.urdf")]
    args += ["--holdout", str(held), "--report", str(report)]
    if params != "auto":
        args += ["--params", params]
    code, said = _run(args)
    if code != 0:
        return "refused: " + said.split("error: ", 1)[-1].split(":", 2)[-1][:70].strip(), ""
    doc = json.loads(report.read_text())
    cells = []
    for row in sorted(
        doc["errors_held_out"],
        key=lambda r: -max(v for k, v in r.items() if k.startswith("after")),
    ):
        after = {k[len("after_") :]: v for k, v in row.items() if k.startswith("after_")}
        cells.append(" / ".join(f"{v:.3f} {k.split('_')[-1]}" for k, v in after.items()))
    chosen = next((n for n in doc["notes"] if n.startswith("parameters:")), "")
    return "; ".join(cells), chosen.split("(")[0].replace("parameters:", "").strip()


def main_(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--noise-mm", type=float, default=0.1)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--setups", nargs="*", choices=list(SETUPS), default=list(SETUPS))
    args = parser.parse_args(argv)
    started = time.perf_counter()
    print(machine_info())
    rows = []
    for name in args.setups:
        with tempfile.TemporaryDirectory() as d:
            tmp = Path(d)
            files = simulate(tmp, name, args.noise_mm, args.seed)
            for params in PARAMS:
                t0 = time.perf_counter()
                score, chosen = calibrate(tmp, *files, params)
                label = f"auto -> {chosen}" if params == "auto" else params
                rows.append([name, label, score, f"{time.perf_counter() - t0:.1f}"])
                print(f"  {name} {label}: {score}", file=sys.stderr)
    print(f"\nheld-out RMS after calibration, contact noise {args.noise_mm} mm, seed {args.seed}")
    print(format_table(["setup", "--params", "held-out RMS (worst group first)", "s"], rows))
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    raise SystemExit(main_())
