"""Speed a user feels: the command line, this tree against a baseline git ref.

``python benchmarks/bench_speed.py [--baseline REF] [--repeats R] [--quick]``

Times, as separate processes, ``kinfw --help``, ``python -c "import kinfw.cli"``,
``kinfw demo`` and ``kinfw crossval`` on the demo's data (85 samples, 5 folds, three
parameter sets), once with this tree's code and once with the code of ``REF`` (default
``2f87e10``, before issue 10), interleaved run by run (the machine is noisy: both see the
same load). The baseline is ``git archive REF`` unpacked into a temporary directory, with
``kinfw/urdf`` linked to its top-level ``urdf/`` (the mapping pyproject makes when
installing) and that directory first on ``PYTHONPATH``; the header shows the files each
side really imports. Both trees are byte-compiled first so that neither pays for it.

Columns: median wall time over the repeats (s), the CPU time of the process (user +
system, s; less sensitive to other load than the wall time) and the baseline / current
ratio of the wall times.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO, format_table, machine_info, time_interleaved, wall_time_line

#: Issue 10's goals, seconds of wall time.
GOALS = {
    "kinfw --help": 0.3,
    "import kinfw.cli": None,
    "kinfw demo": 3.0,
    "kinfw crossval (demo data)": 10.0,
}

#: ``python -c`` text that runs the ``kinfw`` console script's entry point.
ENTRY = "import sys; from kinfw.cli import main; sys.exit(main())"


def baseline_tree(ref: str, into: Path) -> Path:
    """``git archive ref`` of the repository unpacked into ``into``, with ``kinfw/urdf``
    linked to ``urdf/`` as the installed package has it."""
    archive = subprocess.run(
        ["git", "-C", str(REPO), "archive", "--format=tar", ref], check=True, capture_output=True
    ).stdout
    with tarfile.open(fileobj=BytesIO(archive)) as tar:
        tar.extractall(into, filter="data")
    link = into / "kinfw" / "urdf"
    if not link.exists():
        link.symlink_to(into / "urdf", target_is_directory=True)
    return into


def environment(tree: Path) -> dict[str, str]:
    """The environment that makes ``python`` import ``tree``'s code first."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(tree), *filter(None, [env.get("PYTHONPATH")])])
    return env


def imported_files(env: dict[str, str], cwd: Path) -> str:
    """Where ``kinfw.cli``, the built-in URDF, ``kinfw.identification`` and
    ``kinfw.verification.evaluation`` come from."""
    code = (
        "import kinfw.cli, kinfw.model as k, kinfw.identification as r, "
        "kinfw.verification.evaluation as c; "
        "print(kinfw.cli._main.__file__, k.builtin_head_urdf(), "
        "r.__file__, c.__file__)"
    )
    return subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=cwd, check=True, capture_output=True, text=True
    ).stdout.strip()


class Run:
    """One command line in one tree; each call runs it and records the child's CPU time."""

    def __init__(self, argv: list[str], env: dict[str, str], cwd: Path) -> None:
        self.argv, self.env, self.cwd = argv, env, cwd
        self.cpu: list[float] = []

    def __call__(self) -> None:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(
            [sys.executable, *self.argv],
            env=self.env,
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
        default="2f87e10",
        help="git ref to compare with (default 2f87e10, before issue 10)",
    )
    parser.add_argument(
        "--repeats", type=int, default=3, help="timed runs per command and tree (default 3)"
    )
    parser.add_argument(
        "--quick", action="store_true", help="one run of the demo and of crossval (the slow ones)"
    )
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats: expected at least 1")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="kinfw-bench-speed-") as tmp:
        tmp = Path(tmp)
        base = baseline_tree(args.baseline, tmp / "baseline")
        trees = {"current": REPO, "baseline": base}
        envs = {name: environment(tree) for name, tree in trees.items()}
        for tree in trees.values():
            subprocess.run(
                [sys.executable, "-m", "compileall", "-q", "-x", r"\.venv", str(tree)],
                check=True,
                stdout=subprocess.DEVNULL,
            )
        # cwd outside both trees: ``python -c`` puts the working directory first on sys.path
        where = {name: imported_files(env, tmp) for name, env in envs.items()}
        for name, tree in trees.items():  # each side must run its own code
            if not all(path.startswith(str(tree)) for path in where[name].split()):
                raise SystemExit(
                    f"bench_speed: the {name} tree imports code from elsewhere: {where[name]}"
                )
        # the crossval data: the current tree's demo output, the same file for both sides
        data_dir = tmp / "demo_data"
        subprocess.run(
            [sys.executable, "-c", ENTRY, "demo", "--out", str(data_dir)],
            env=envs["current"],
            cwd=tmp,
            check=True,
            stdout=subprocess.DEVNULL,
        )
        head = REPO / "urdf" / "iis_head.urdf"
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
        print(
            machine_info(
                code=[
                    ("current", str(REPO)),
                    ("baseline", f"{args.baseline} (git archive in {base})"),
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
            f"mode       repeats {args.repeats}{quick}, runs interleaved current/baseline, "
            "wall time of the whole process"
        )
        rows = []
        for label, command in commands.items():
            slow = label.startswith(("kinfw demo", "kinfw crossval"))
            repeats = 1 if (args.quick and slow) else args.repeats
            runs = [Run(command, envs[name], tmp) for name in trees]
            timings = time_interleaved(runs, repeats, warmup=0 if slow else 1)
            current, baseline = (t.median_ms / 1e3 for t in timings)
            cpu = [float(np.median(r.cpu[-repeats:])) for r in runs]
            goal = GOALS[label]
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
                f"{args.baseline} s",
                "ratio",
                "current CPU s",
                f"{args.baseline} CPU s",
                "goal (wall)",
            ],
            rows,
        )
    )
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
