"""Speed a user feels: the command line, this tree against a baseline.

``python benchmarks/bench_speed.py [--baseline REF_OR_DIR] [--repeats R] [--quick]
[--samples N]``

Times, as separate processes, ``kinfw --help``, ``python -c "import kinfw.cli"``,
``kinfw demo``, ``kinfw crossval`` on the demo's data (85 samples, 5 folds, three
parameter sets) and ``kinfw calibrate`` with default options on N = 10,000 samples
(``--samples``; 0 leaves them out) of the data of ``bench_memory.py``: UR10 mocap points,
UR10 tool poses and the IIS head's poses; once with this tree's code and once with the
baseline's, interleaved run by run (the machine is noisy: both see the same load). The
baseline is a checkout directory (e.g. ``git worktree add --detach /tmp/base <parent>``)
or a git ref (``git archive REF`` unpacked into a temporary directory; default ``main``);
each child points the editable install's package map at its tree
(:func:`benchmarks.common.repo_prelude`), and the header shows the files each side really
imports. Both trees are byte-compiled first so that neither pays for it.

Columns: median wall time over the repeats (s; the calibrations run once each), the CPU
time of the process (user + system, s; less sensitive to other load than the wall time)
and the baseline / current ratio of the wall times.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_memory import write_data
from benchmarks.common import (
    REPO,
    format_table,
    machine_info,
    repo_prelude,
    time_interleaved,
    wall_time_line,
)

#: Issue 10's goals, seconds of wall time.
GOALS = {
    "kinfw --help": 0.3,
    "import kinfw.cli": None,
    "kinfw demo": 3.0,
    "kinfw crossval (demo data)": 10.0,
    "kinfw calibrate": 5.0,  # issue 23, at 10,000 samples
}

#: The datasets of ``bench_memory.py`` timed at ``--samples``.
CALIBRATE_DATA = ("ur10-points", "ur10-poses", "head-poses")

#: ``python -c`` text that runs the ``kinfw`` console script's entry point.
ENTRY = "import sys; from kinfw.cli import main; sys.exit(main(sys.argv[1:]))"


def baseline_tree(ref: str, into: Path) -> Path:
    """The baseline's tree: ``ref`` itself when it is a directory, else ``git archive
    ref`` of the repository unpacked into ``into``."""
    if Path(ref).is_dir():
        return Path(ref).resolve()
    archive = subprocess.run(
        ["git", "-C", str(REPO), "archive", "--format=tar", ref], check=True, capture_output=True
    ).stdout
    with tarfile.open(fileobj=BytesIO(archive)) as tar:
        tar.extractall(into, filter="data")
    return into


def imported_files(tree: Path, cwd: Path) -> str:
    """Where ``kinfw.cli``, the built-in URDF, ``kinfw.identification`` and
    ``kinfw.verification.evaluation`` come from in a child running ``tree``'s code."""
    code = repo_prelude(tree) + (
        "import kinfw.cli, kinfw.model as k, kinfw.identification as r, "
        "kinfw.verification.evaluation as c; "
        "print(kinfw.cli._main.__file__, k.builtin_head_urdf(), "
        "r.__file__, c.__file__)"
    )
    return subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, check=True, capture_output=True, text=True
    ).stdout.strip()


class Run:
    """One command line in one tree; each call runs it and records the child's CPU time."""

    def __init__(self, argv: list[str], tree: Path, cwd: Path) -> None:
        # ``-c CODE args``: CODE runs after the prelude that selects the tree's code
        self.argv = [argv[0], repo_prelude(tree) + argv[1], *argv[2:]]
        self.cwd = cwd
        self.cpu: list[float] = []

    def __call__(self) -> None:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(
            [sys.executable, *self.argv],
            cwd=self.cwd,
            check=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        self.cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--baseline",
        default="main",
        help="checkout directory or git ref to compare with (default main)",
    )
    parser.add_argument(
        "--repeats", type=int, default=3, help="timed runs per command and tree (default 3)"
    )
    parser.add_argument(
        "--quick", action="store_true", help="one run of the demo and of crossval (the slow ones)"
    )
    parser.add_argument(
        "--samples",
        type=int,
        default=10_000,
        help="samples of the kinfw calibrate rows (default 10000; 0: none)",
    )
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats: expected at least 1")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="kinfw-bench-speed-") as tmp:
        tmp = Path(tmp)
        base = baseline_tree(args.baseline, tmp / "baseline")
        trees = {"current": REPO, "baseline": base}
        for tree in trees.values():
            subprocess.run(
                [sys.executable, "-m", "compileall", "-q", "-x", r"\.venv", str(tree)],
                check=True,
                stdout=subprocess.DEVNULL,
            )
        # cwd outside both trees: ``python -c`` puts the working directory first on sys.path
        where = {name: imported_files(tree, tmp) for name, tree in trees.items()}
        for name, tree in trees.items():  # each side must run its own code
            if not all(path.startswith(str(tree)) for path in where[name].split()):
                raise SystemExit(
                    f"bench_speed: the {name} tree imports code from elsewhere: {where[name]}"
                )
        # the crossval data: the current tree's demo output, the same file for both sides
        data_dir = tmp / "demo_data"
        subprocess.run(
            [sys.executable, "-c", repo_prelude(REPO) + ENTRY, "demo", "--out", str(data_dir)],
            cwd=tmp,
            check=True,
            stdout=subprocess.DEVNULL,
        )
        head = REPO / "robots" / "iis_head.urdf"
        commands = {
            "kinfw --help": ["-c", ENTRY, "--help"],
            "import kinfw.cli": ["-c", "import kinfw.cli"],
            "kinfw demo": ["-c", ENTRY, "demo", "--out", str(tmp / "demo_out")],
            "kinfw crossval (demo data)": [
                "-c",
                ENTRY,
                "crossval",
                str(data_dir / "data.json"),
                "--urdf",
                str(head),
            ],
        }
        if args.samples > 0:
            files = write_data(tmp, args.samples, CALIBRATE_DATA)
            for name, (urdf, data) in files.items():
                commands[f"kinfw calibrate ({name} {args.samples})"] = [
                    "-c",
                    ENTRY,
                    "calibrate",
                    str(data),
                    "--urdf",
                    str(urdf),
                    "--out",
                    str(tmp / f"{name}.urdf"),
                ]
        print(
            machine_info(
                code=[
                    ("current", str(REPO)),
                    ("baseline", f"{args.baseline} ({base})"),
                    ("imports", ""),
                    *[
                        (f"  {name}", path)
                        for name, paths in where.items()
                        for path in paths.split()
                    ],
                ]
            )
        )
        quick = " (1 for demo and crossval: --quick)" if args.quick else ""
        print(
            f"mode       repeats {args.repeats}{quick}, calibrations once, runs interleaved "
            "current/baseline, wall time of the whole process"
        )
        rows = []
        for label, command in commands.items():
            calibrate = label.startswith("kinfw calibrate")
            slow = calibrate or label.startswith(("kinfw demo", "kinfw crossval"))
            repeats = 1 if (args.quick and slow) or calibrate else args.repeats
            runs = [Run(command, tree, tmp) for tree in trees.values()]
            timings = time_interleaved(runs, repeats, warmup=0 if slow else 1)
            current, baseline = (t.median_ms / 1e3 for t in timings)
            cpu = [float(np.median(r.cpu[-repeats:])) for r in runs]
            goal = GOALS["kinfw calibrate" if calibrate else label]
            rows.append(
                [
                    label,
                    f"{current:.2f}",
                    f"{baseline:.2f}",
                    f"{baseline / current:.1f}x",
                    f"{cpu[0]:.2f}",
                    f"{cpu[1]:.2f}",
                    "-"
                    if goal is None
                    else f"< {goal:g} s" + (" ok" if current < goal else " missed"),
                ]
            )
            print(f"  {label}: current {current:.2f} s, baseline {baseline:.2f} s", file=sys.stderr)
    print()
    print(
        format_table(
            [
                "command",
                "current s",
                "baseline s",
                "ratio",
                "current CPU s",
                "baseline CPU s",
                "goal (wall)",
            ],
            rows,
        )
    )
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
