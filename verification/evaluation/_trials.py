"""Random trials, in this process or as tasks of any executor, with progress.

Cross-validation folds and the studies' trials are independent tasks: :func:`run_trials`
runs them serially or submits them to a :class:`concurrent.futures.Executor` (a process
pool from :func:`executor_for_jobs`, or Dask's or Ray's executor) and returns the results
in order either way, telling :mod:`kinfw.progress` as they finish.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from typing import TypeVar

from kinfw import progress

__all__ = ["check_count", "executor_for_jobs", "run_trials"]

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
    name: str = "trials",
) -> list[R]:
    """``[trial(*a) for a in args]``: in this process (``executor`` None) or submitted as
    tasks to any :class:`concurrent.futures.Executor` (a process pool, Dask's or Ray's
    executor); the results come back in the order of ``args`` either way.

    With an executor, ``trial`` must be a module-level function and ``args`` picklable
    (a :class:`kinfw.model.Robot` pickles as its URDF text). The trials are a
    :func:`kinfw.progress.task` called ``name``, a step as each finishes.
    """
    with progress.task(name, total=len(args), unit="") as bar:
        if executor is None:
            out = []
            for a in args:
                out.append(trial(*a))
                bar.advance()
            return out
        futures = [executor.submit(trial, *a) for a in args]
        for _ in as_completed(futures):
            bar.advance()
        return [f.result() for f in futures]


def executor_for_jobs(jobs: int) -> Executor | None:
    """None (run in this process) for ``jobs <= 1``, else a process pool of ``jobs``
    workers (``ValueError`` for ``jobs < 1``)."""
    jobs = check_count(jobs, "--jobs", 1)
    return None if jobs == 1 else ProcessPoolExecutor(max_workers=jobs)
