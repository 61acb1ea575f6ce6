"""Where work that fans out runs: the ``--jobs N`` / ``--executor dask://HOST:PORT``
options of every command that runs independent tasks (cross-validation folds, study
trials, the robots of a fleet), and the Dask scheduler address they name.

``--jobs N`` runs the tasks in N local worker processes; ``--executor dask://HOST:PORT``
submits them to the Dask distributed scheduler at HOST:PORT (``pip install
'kinfw[dask]'``; start one with ``dask scheduler`` and ``dask worker tcp://HOST:PORT`` on
each machine, each with kinfw installed). The two are exclusive. The executor itself is
opened by :func:`kinfw.verification.evaluation.open_executor`.

This module uses the standard library only (the command line builds its parsers at
start-up; Dask is imported only when a scheduler is used).
"""

from __future__ import annotations

import argparse
import importlib.util
from urllib.parse import urlsplit

__all__ = ["DASK_INSTALL", "add_executor_options", "dask_scheduler_address"]

#: How to install what ``--executor dask://`` needs.
DASK_INSTALL = "pip install 'kinfw[dask]'"


def dask_scheduler_address(spec: str) -> str:
    """The Dask scheduler address of ``dask://HOST:PORT``: ``tcp://HOST:PORT``.

    Parameters
    ----------
    spec : str
        ``dask://HOST:PORT`` (an IPv6 host in brackets: ``dask://[::1]:8786``).

    Returns
    -------
    str
        ``tcp://HOST:PORT``, what :class:`distributed.Client` connects to.

    Raises
    ------
    ValueError
        ``spec`` is not ``dask://HOST:PORT`` with a port in 1..65535 (the message quotes
        it).
    """
    want = f"expected dask://HOST:PORT (a Dask scheduler), got {spec!r}"
    try:
        parts = urlsplit(spec)
        port = parts.port
    except ValueError:  # a port that is not a number in 0..65535
        raise ValueError(want) from None
    if (
        parts.scheme != "dask"
        or not parts.hostname
        or not port
        or parts.username is not None
        or parts.path not in ("", "/")
        or parts.query
        or parts.fragment
    ):
        raise ValueError(want)
    return f"tcp://{parts.netloc}"


def _executor_arg(text: str) -> str:
    """``--executor``: a ``dask://HOST:PORT`` address, with Dask's distributed installed."""
    try:
        dask_scheduler_address(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if importlib.util.find_spec("distributed") is None:
        raise argparse.ArgumentTypeError(
            f"{text}: needs Dask's distributed scheduler, which is not installed: {DASK_INSTALL}"
        )
    return text


def _jobs_arg(text: str) -> int:
    """``--jobs``: a whole number >= 1."""
    try:
        jobs = int(text)
    except ValueError:
        jobs = 0
    if jobs < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return jobs


def add_executor_options(parser: argparse.ArgumentParser, *, tasks: str) -> None:
    """``--jobs N`` (default 1: in this process) or ``--executor dask://HOST:PORT``, not
    both (argparse says so): where ``tasks`` run (``"the fits"``, ``"the trials"``).

    The parsed arguments are ``args.jobs`` (int) and ``args.executor`` (the
    ``dask://`` text, or None), what :func:`kinfw.verification.evaluation.open_executor`
    takes as ``jobs`` and ``address``.
    """
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--jobs",
        type=_jobs_arg,
        default=1,
        metavar="N",
        help=f"run {tasks} in N local worker processes (default 1: in this process)",
    )
    group.add_argument(
        "--executor",
        type=_executor_arg,
        metavar="dask://HOST:PORT",
        help=f"run {tasks} as tasks of the Dask scheduler at HOST:PORT, on its workers "
        f"(each with kinfw installed; needs {DASK_INSTALL}); results as in this process",
    )
