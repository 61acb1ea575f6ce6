"""``kinfw fleet`` over many simulated robots: in one process, in a local process pool
(``--jobs 2``) and on a local Dask cluster (``--executor dask://HOST:PORT``): wall times
and whether the three wrote the same files (issue 23, goal 6).

Data (``tests/fleet_data.write_fleet``): N perturbed copies of the built-in IIS-head
(:func:`kinfw.simulate`: 2 mm / 0.5 deg joint errors, each robot its own seed), both
plates' poses at M values of each joint (one joint at a time, 0.5 mm / 0.5 deg noise),
one folder per robot with ``robot.urdf`` and ``data.json``. Each run is a whole
``kinfw fleet ROBOTS --out OUT`` process with the default options (``--params auto``:
with M = 6, 37 samples, enough residuals per parameter for ``full`` without the model
choice's cross-validation), with one BLAS thread per process (as Dask's workers run;
else the pool's processes each start a BLAS thread per core). The Dask cluster
(``distributed.LocalCluster``, W worker processes of one thread) is started before the
rounds and its start-up timed apart, as a cluster that is already up; its workers import
kinfw on their first task, inside the first round's run, and keep it.

Compared files: every calibrated URDF and ``summary.json`` byte for byte; each report
and sidecar as JSON without what says when, where and how long (``created``,
``sidecar``, ``seconds``).

The three runs go one after the other, ``--rounds`` times (the table gives each round's
wall time, the median and the speed-up of the medians over serial): other load on the
machine moves single runs a lot.

Run from the repository root: ``python benchmarks/bench_fleet.py [--robots 20]
[--per-joint 6] [--workers 2] [--rounds 3]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import format_table, machine_info, wall_time_line
from tests.fleet_data import without_run_details, write_fleet

#: One BLAS thread per process in every run, as Dask sets in its workers: with the
#: default (a thread per core in each process) the pool's processes oversubscribe the
#: cores and the comparison measures that.
ONE_BLAS_THREAD = {v: "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}


def run_fleet(robots: Path, out: Path, *extra: str) -> tuple[float, str]:
    """Wall time (s) and stdout of ``kinfw fleet ROBOTS --out OUT EXTRA...`` in a child
    process (one BLAS thread)."""
    argv = [sys.executable, "-m", "kinfw.cli", "fleet", str(robots), "--out", str(out), *extra]
    env = {**os.environ, **ONE_BLAS_THREAD}
    start = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, check=False, env=env)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} exited {done.returncode}:\n{done.stderr}")
    return seconds, done.stdout


def differences(a: Path, b: Path) -> list[str]:
    """The files of ``a`` that ``b`` lacks or holds otherwise (see the module docstring)."""
    names = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    theirs = sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    if names != theirs:
        return [f"file lists differ: {sorted(set(names) ^ set(theirs))}"]
    out = []
    for name in names:
        x, y = a / name, b / name
        if name.suffix == ".urdf" or name.name == "summary.json":
            same = x.read_bytes() == y.read_bytes()
        else:
            same = without_run_details(json.loads(x.read_text())) == without_run_details(
                json.loads(y.read_text())
            )
        if not same:
            out.append(str(name))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, default=20, help="simulated robots (default 20)")
    parser.add_argument("--per-joint", type=int, default=6, help="values per joint (default 6)")
    parser.add_argument("--workers", type=int, default=2, help="pool / cluster workers (2)")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of the three runs (3)")
    args = parser.parse_args(argv)
    import distributed
    from distributed import LocalCluster

    started = time.perf_counter()
    print(machine_info((("distributed", distributed.__version__),)))
    modes = {
        "serial (this process)": (),
        f"--jobs {args.workers} (process pool)": ("--jobs", str(args.workers)),
        f"--executor dask:// ({args.workers} workers x 1 thread)": ("--executor", "{address}"),
    }
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        write_fleet(root / "robots", args.robots, per_joint=args.per_joint)
        print(
            f"data       {args.robots} robots (IIS-head copies), {args.per_joint} values per "
            f"joint, default options (--params auto); one BLAS thread per process; "
            f"{args.rounds} rounds of the three runs, one after the other\n"
        )
        up = time.perf_counter()
        with LocalCluster(
            n_workers=args.workers, threads_per_worker=1, dashboard_address=":0"
        ) as cluster:
            up = time.perf_counter() - up
            address = cluster.scheduler_address.replace("tcp://", "dask://")
            seconds: dict[str, list[float]] = {label: [] for label in modes}
            outs: dict[str, list[Path]] = {label: [] for label in modes}
            for r in range(args.rounds):
                for k, (label, extra) in enumerate(modes.items()):
                    out = root / f"run{r}_{k}"
                    extra = tuple(a.format(address=address) for a in extra)
                    wall, text = run_fleet(root / "robots", out, *extra)
                    seconds[label].append(wall)
                    outs[label].append(out)
                    if r == 0 and k == 0:
                        table = text
        reference = outs[next(iter(modes))][0]
        serial = float(np.median(seconds[next(iter(modes))]))
        rows = []
        for label in modes:
            wrong = sorted({d for out in outs[label] for d in differences(reference, out)})
            median = float(np.median(seconds[label]))
            rows.append(
                [
                    label,
                    " ".join(f"{t:.1f}" for t in seconds[label]),
                    f"{median:.1f}",
                    f"{serial / median:.2f}",
                    ", ".join(wrong) or "yes",
                ]
            )
        header = ["run (whole kinfw fleet process)", "wall s by round", "median s", "speed-up"]
        print(format_table([*header, "same files as serial"], rows))
        print(
            f"\nDask LocalCluster start-up (not in its runs): {up:.1f} s; its workers import "
            "kinfw in round 1 and keep it"
        )
        print("\nthe serial run's summary:\n" + table)
    print(wall_time_line(started))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
