"""Plumbing shared by the benchmark scripts: timing, the machine header, plain tables.

Timing follows :mod:`timeit`: ``time.perf_counter`` around each call, warm-up calls
first, garbage collection disabled while timing; calls of one repeat are timed round
robin so that ratios within a repeat see the same machine state. The header names the
interpreter, the libraries, the machine, the BLAS thread variables and the load average
(other load skews absolute times), then the benchmarked code.
"""

from __future__ import annotations

import argparse
import gc
import os
import platform
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "REPO",
    "Timings",
    "format_table",
    "gc_disabled",
    "load_average",
    "machine_info",
    "mode_line",
    "parse_repeats",
    "repo_prelude",
    "slope",
    "time_interleaved",
    "wall_time_line",
]

#: The repository the benchmarks run on (the code next to the scripts).
REPO = Path(__file__).resolve().parents[1]


def repo_prelude(repo: Path) -> str:
    """Python source that makes a child import ``repo``'s kinfw (a checkout of this
    repository): it points the editable install's package map (``kinfw``,
    ``kinfw.identification``, ``kinfw.verification``, ``kinfw.robots``) at ``repo``. Run
    it first in the child (``python -c PRELUDE + code``); it imports nothing itself."""
    return (
        "import sys as _sys\n"
        "from pathlib import Path as _Path\n"
        "for _m in list(_sys.modules.values()):\n"
        "    _map = getattr(_m, 'MAPPING', None)\n"
        "    if isinstance(_map, dict) and 'kinfw' in _map:\n"
        "        _old = str(_Path(_map['kinfw']).parent)\n"
        f"        _map.update({{k: {str(repo)!r} + v[len(_old):] for k, v in _map.items()}})\n"
    )


# -- timing ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Timings:
    """Repeated wall-clock times of one operation, seconds, shape (repeats,)."""

    seconds: NDArray[np.float64]

    @property
    def median_ms(self) -> float:
        return 1e3 * float(np.median(self.seconds))

    @property
    def iqr_ms(self) -> float:
        q25, q75 = np.percentile(self.seconds, [25.0, 75.0])
        return 1e3 * float(q75 - q25)


@contextmanager
def gc_disabled() -> Iterator[None]:
    """Garbage collection off inside the block, restored after (if it was on)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def time_interleaved(
    calls: Sequence[Callable[[], object]], repeats: int, *, warmup: int
) -> list[Timings]:
    """Time each call ``repeats`` times, round robin, after ``warmup`` untimed rounds.

    Round robin puts the calls of one repeat next to each other in time, so a ratio of
    two calls within a repeat sees the same machine state.
    """
    for _ in range(warmup):
        for call in calls:
            call()
    seconds = np.empty((len(calls), repeats))
    with gc_disabled():
        for r in range(repeats):
            for k, call in enumerate(calls):
                start = time.perf_counter()
                call()
                seconds[k, r] = time.perf_counter() - start
    return [Timings(s) for s in seconds]


def slope(x: Sequence[float], y: Sequence[float]) -> float:
    """Least-squares slope of log y against log x."""
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


# -- command line ------------------------------------------------------------------------


def parse_repeats(
    argv: Sequence[str] | None, description: str, *, quick_help: str, full: int, quick: int
) -> tuple[argparse.Namespace, int]:
    """The command line of a benchmark timed in repeats, ``[--repeats R] [--quick]
    [--seed S]``: the arguments and the repeats, ``R`` or by default ``full`` (``quick``
    with ``--quick``); exits with a usage error when they are below 1."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument(
        "--repeats",
        type=int,
        default=None,
        help=f"timed repeats per measurement (default {full}, or {quick} with --quick)",
    )
    parser.add_argument("--quick", action="store_true", help=quick_help)
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw")
    args = parser.parse_args(argv)
    repeats = args.repeats if args.repeats is not None else (quick if args.quick else full)
    if repeats < 1:
        parser.error("--repeats: expected at least 1")
    return args, repeats


def mode_line(args: argparse.Namespace, repeats: int, warmup: int) -> str:
    """The header line after :func:`machine_info` of a :func:`parse_repeats` benchmark."""
    return (
        f"mode       {'quick' if args.quick else 'full'}, repeats {repeats}, "
        f"warm-up {warmup}, seed {args.seed}, gc disabled while timing"
    )


# -- output ------------------------------------------------------------------------------


def format_table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """Right-aligned plain-text table (first column left-aligned)."""
    widths = [max(len(h), *(len(r[k]) for r in rows)) for k, h in enumerate(headers)]

    def line(cells: Sequence[str]) -> str:
        return "  ".join(
            c.ljust(w) if k == 0 else c.rjust(w)
            for k, (c, w) in enumerate(zip(cells, widths, strict=True))
        )

    return "\n".join([line(headers), line(["-" * w for w in widths]), *map(line, rows)])


def load_average() -> str:
    """The 1, 5 and 15 minute load averages, or "n/a" where the OS has none."""
    return "n/a" if not hasattr(os, "getloadavg") else " ".join(f"{x:.2f}" for x in os.getloadavg())


def machine_info(
    libraries: Sequence[tuple[str, str]] = (),
    *,
    probes: Sequence[tuple[str, str]] = (),
    code: Sequence[tuple[str, str]] = (("kinfw", str(REPO)),),
) -> str:
    """The header of a benchmark's output, one ``label  value`` line each.

    Python and numpy, then ``libraries`` (name, version); platform, processor, CPUs,
    the BLAS thread variables and the load average; then ``probes`` (label, a measured
    value) and ``code``, the benchmarked code (default: the repository's path).
    """
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else "n/a"
    threads = (
        ", ".join(
            f"{v}={os.environ[v]}"
            for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
            if v in os.environ
        )
        or "not set"
    )
    return "\n".join(
        f"{label:<10} {value}"
        for label, value in [
            ("python", f"{platform.python_version()} ({platform.python_implementation()})"),
            ("numpy", np.__version__),
            *libraries,
            ("platform", platform.platform()),
            ("processor", platform.processor() or platform.machine()),
            ("CPUs", f"{os.cpu_count()} (usable by this process: {affinity})"),
            ("BLAS env", threads),
            ("load avg", f"{load_average()} (1, 5, 15 min; other load skews absolute times)"),
            *probes,
            *code,
        ]
    )


def wall_time_line(started: float) -> str:
    """The last line of a benchmark: wall time since ``started`` (``time.perf_counter``)
    and the load average now."""
    return (
        f"\ntotal benchmark wall time {time.perf_counter() - started:.1f} s, "
        f"load avg now {load_average()}"
    )
