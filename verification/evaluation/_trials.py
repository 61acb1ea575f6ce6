"""Random trials, in this process or as tasks of any executor, with progress.

Cross-validation folds and the studies' trials are independent tasks: :func:`run_trials`
runs them serially or submits them to a :class:`concurrent.futures.Executor` (a process
pool from :func:`executor_for_jobs`, or Dask's or Ray's executor) and returns the results
in order either way.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from typing import Any, TypeVar

__all__ = ["Progress", "check_count", "executor_for_jobs", "run_trials", "stderr_progress"]

#: ``progress(done, total)``, called by a study after each trial.
Progress = Callable[[int, int], Any]

R = TypeVar("R")


def check_count(value: int, name: str, least: int) -> int:
    """``value`` as an int, or ``ValueError`` naming ``name`` if it is not a whole number
    ``>= least``."""
    if int(value) != value or int(value) < least:
        raise ValueError(f"{name}: expected an integer >= {least}, got {value}")
    return int(value)


def run_trials(
    trial: Callable[..., R],
    args: Sequence[tuple],
    *,
    executor: Executor | None = None,
    progress: Progress | None = None,
) -> list[R]:
    """``[trial(*a) for a in args]``: in this process (``executor`` None) or submitted as
    tasks to any :class:`concurrent.futures.Executor` (a process pool, Dask's or Ray's
    executor); the results come back in the order of ``args`` either way.

    With an executor, ``trial`` must be a module-level function and ``args`` picklable
    (a :class:`kinfw.model.Robot` pickles as its URDF text). ``progress(done, total)`` is
    called as trials finish.
    """
    total = len(args)
    if executor is None:
        out = []
        for i, a in enumerate(args):
            out.append(trial(*a))
            if progress is not None:
                progress(i + 1, total)
        return out
    futures = [executor.submit(trial, *a) for a in args]
    for done, _ in enumerate(as_completed(futures), 1):
        if progress is not None:
            progress(done, total)
    return [f.result() for f in futures]


def executor_for_jobs(jobs: int) -> Executor | None:
    """None (run in this process) for ``jobs <= 1``, else a process pool of ``jobs``
    workers (``ValueError`` for ``jobs < 1``)."""
    jobs = check_count(jobs, "--jobs", 1)
    return None if jobs == 1 else ProcessPoolExecutor(max_workers=jobs)


def stderr_progress(done: int, total: int) -> None:
    """A :data:`Progress` that keeps ``done/total trials`` on one line of stderr."""
    sys.stderr.write(f"\r{done}/{total} trials")
    if done == total:
        sys.stderr.write("\n")
    sys.stderr.flush()
