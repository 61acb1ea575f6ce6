"""``kinfw fleet``: calibrate many robots' datasets at once, with ``kinfw calibrate``'s
options (:func:`kinfw.verification.reporting.calibrate_fleet`), locally or on a Dask
scheduler's workers.

Like the other command modules, only the standard library is imported at start-up.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from kinfw.cli._args import add_mount_option, read_data
from kinfw.cli._fit import calibration_options
from kinfw.cli._fit_parser import add_calibration_options
from kinfw.cli._tables import format_table, metric_format, number
from kinfw.executors import add_executor_options
from kinfw.files import check_output_dir, json_text

if TYPE_CHECKING:
    from kinfw.verification.reporting import FleetResult

#: Exit code when some robot of the fleet failed (the others are written).
EXIT_FAILED = 3


def add_fleet_parser(sub: argparse._SubParsersAction) -> None:
    """The ``fleet`` sub-command."""
    p = sub.add_parser(
        "fleet",
        help="calibrate many robots: a calibrated URDF and report per robot, a summary",
        description="Calibrate each robot's measurement file as 'kinfw calibrate' does, with "
        "the same options. A robot is a measurement file; its nominal URDF is --urdf, else "
        "the one *.urdf beside the file (a folder per robot: robots/NAME/robot.urdf and "
        "robots/NAME/data.json); it is named after the file, or after its folder when "
        "the files share a name. Writes OUT/NAME/calibrated.urdf (+ its sidecar) and "
        "OUT/NAME/report.json per robot and OUT/summary.json, and prints the summary. A "
        f"robot whose data is bad fails alone; the exit code is then {EXIT_FAILED}.",
    )
    p.add_argument(
        "data",
        nargs="+",
        help="measurement files, glob patterns of them (quoted: 'robots/*/data.json'), or "
        "folders holding one folder per robot (each with one *.json measurement file)",
    )
    p.add_argument(
        "--urdf",
        dest="fleet_urdf",  # not args.urdf: main reads a None one as the built-in head
        type=Path,
        metavar="NOMINAL.urdf",
        help="the nominal URDF of every robot (default: the one *.urdf beside each "
        "measurement file)",
    )
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        help="output folder: NAME/calibrated.urdf (+ sidecar) and NAME/report.json per "
        "robot, summary.json",
    )
    add_calibration_options(p)
    add_mount_option(p)
    add_executor_options(p, tasks="the robots' calibrations")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=cmd_fleet, check_outputs=check_fleet_outputs)


def check_fleet_outputs(args: argparse.Namespace) -> None:
    """The output folder of ``kinfw fleet`` and its summary, checked before any work."""
    from kinfw.verification.reporting import FLEET_SUMMARY

    check_output_dir(args.out, label="--out", files=(FLEET_SUMMARY,))


def cmd_fleet(args: argparse.Namespace) -> int:
    from kinfw.verification.evaluation import open_executor
    from kinfw.verification.reporting import calibrate_fleet, fleet_members

    members = fleet_members(args.data, urdf=args.fleet_urdf)
    options = calibration_options(args)
    with open_executor(args.jobs, args.executor) as executor:
        fleet = calibrate_fleet(
            members,
            args.out,
            read=lambda path: read_data(path, args),  # with --camera, as calibrate reads
            executor=executor,
            **options,
        )
    if args.json:
        print(json_text(fleet.to_dict()))
    else:
        _print_fleet(fleet)
    return EXIT_FAILED if fleet.failed else 0


def _print_fleet(fleet: FleetResult) -> None:
    """The summary table (in-sample RMS before/after per metric, over each robot's
    observation groups), each robot's warnings, each failure's reason, and the files
    written."""
    from kinfw.verification.reporting import FLEET_SUMMARY

    metrics = list({b.key: b for r in fleet.rows for b, _ in r.rms}.values())
    header = ["robot", "samples", "parameters"]
    for m in metrics:
        header += [f"before {m.label()}", f"after {m.label()}"]
    rows = []
    for r in fleet.rows:
        pairs = {b.key: (b.value, a.value) for b, a in r.rms}
        cells = [r.name, number(r.n_samples, "d"), r.model.label if r.model else "-"]
        for m in metrics:
            fmt = metric_format(m.name, m.unit)
            cells += [number(v, fmt) for v in pairs.get(m.key, (None, None))]
        rows.append([*cells, "ok" if r.ok else "FAILED"])
    done = len(fleet.rows) - len(fleet.failed)
    print(f"calibrated {done} of {len(fleet.rows)} robots (RMS on each one's calibration data):")
    print(format_table(rows, [*header, "status"]))
    for r in fleet.rows:
        for warning in r.warnings:
            print(f"{r.name}: warning: {warning}")
    for r in fleet.failed:
        print(f"{r.name}: failed: {r.error}")
    out = Path(fleet.out_dir)
    print(
        f"wrote {out}/NAME/calibrated.urdf (+ sidecar) and {out}/NAME/report.json for "
        f"{done} robots, and {out / FLEET_SUMMARY}"
    )
