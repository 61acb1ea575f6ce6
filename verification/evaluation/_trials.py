"""Random trials, in this process or as tasks of any executor, with progress.

Cross-validation folds, the studies' trials and a fleet's robots are independent tasks:
:func:`run_trials` runs them serially or submits them to a
:class:`concurrent.futures.Executor` (a process pool from :func:`executor_for_jobs`, a
Dask scheduler's from :func:`open_executor`, or Ray's) and returns the results in order
either way, telling :mod:`kinfw.progress` as they finish.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from typing import TypeVar

from kinfw import progress
from kinfw.executors import DASK_INSTALL, dask_scheduler_address

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


@contextlib.contextmanager
def open_executor(
    jobs: int = 1, address: str | None = None, *, connect_timeout_s: float = 10.0
) -> Iterator[Executor | None]:
    """The executor of ``--jobs N`` or ``--executor dask://HOST:PORT``
    (:func:`kinfw.executors.add_executor_options`), shut down when the block ends.

    Parameters
    ----------
    jobs : int
        Local worker processes (:func:`executor_for_jobs`); 1: None, the tasks run in
        this process.
    address : str, optional
        ``dask://HOST:PORT``: the executor of a :class:`distributed.Client` connected to
        the Dask scheduler there (Dask is imported only then). Its workers need kinfw
        installed; the tasks' arguments and results travel pickled (a
        :class:`kinfw.model.Robot` as its URDF text), so they need no shared files.
    connect_timeout_s : float
        How long to wait for the scheduler to answer, s.

    Yields
    ------
    concurrent.futures.Executor or None
        For :func:`run_trials` and every ``executor=`` argument.

    Raises
    ------
    ValueError
        Both ``jobs > 1`` and ``address``; ``jobs < 1``; ``address`` not
        ``dask://HOST:PORT``.
    ImportError
        ``address`` given without Dask's distributed installed (the message gives the
        fix).
    OSError
        No scheduler answered at ``address`` within ``connect_timeout_s`` (the message
        names it).
    """
    if address is None:
        pool = executor_for_jobs(jobs)
        try:
            yield pool
        finally:
            if pool is not None:
                pool.shutdown()
        return
    if check_count(jobs, "jobs", 1) > 1:
        raise ValueError(
            f"give jobs (local processes) or a Dask scheduler address, not both "
            f"(jobs={jobs}, address={address!r})"
        )
    scheduler = dask_scheduler_address(address)
    try:
        from distributed import Client
    except ImportError:
        raise ImportError(
            f"{address}: needs Dask's distributed scheduler, which is not installed: {DASK_INSTALL}"
        ) from None
    try:
        client = Client(scheduler, timeout=connect_timeout_s)
    except OSError as exc:
        raise OSError(
            f"{address}: no Dask scheduler answered at {scheduler} within "
            f"{connect_timeout_s:g} s ({exc}); start one with 'dask scheduler' and "
            "workers with 'dask worker ADDRESS'"
        ) from None
    # pure=False: the tasks are not hashed for de-duplication (robots and data can be large)
    executor = client.get_executor(pure=False)
    try:
        yield executor
    finally:
        executor.shutdown()
        client.close()
