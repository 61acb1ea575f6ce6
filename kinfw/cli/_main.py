"""The ``kinfw`` command line: the one place that wires kinfw, identification and
verification together.

Exit codes: 0 on success, 2 on bad input (one line on stderr saying what and where,
then the message's details, if it has any, on indented lines; never a traceback for a
user error), 1 on an unexpected internal error, 3 when ``gaze``
does not fixate, ``reach`` does not reach or a robot of ``fleet`` fails
(:mod:`kinfw.cli`). Warnings (Python warnings and logged ones) are printed once each, as
one line ``kinfw CMD: warning: ...``. Progress goes to stderr from the first second
(:mod:`kinfw.progress`): a tqdm bar on a terminal, plain lines when stderr is piped,
nothing with ``-q``; ``-v`` adds the logged information (what each stage found).

Every output path is checked before any work (each command's ``check_outputs``) and every file is
written atomically (:mod:`kinfw.files`). This module imports only the standard library at
start-up, so that ``kinfw --help`` and argument errors are immediate: numpy, Pinocchio
(through :mod:`kinfw.model`), CasADi, matplotlib and meshcat are imported by the commands.

This module holds the top-level parser, the checks of the outputs, the warning printer
and :func:`main`. Each command's sub-parser is defined beside the command: ``simulate``
in ``_simulate.py``; ``verify``, ``view``, ``reproduce``, ``crosscheck`` and
``import-csv`` in ``_commands.py``; ``calibrate``, ``demo`` and ``crossval`` in
``_fit_parser.py`` (commands in ``_fit.py``); ``fleet``, ``detect``, ``plan``, ``gaze`` and
``reach`` in ``_fleet.py``, ``_detect.py``, ``_plan.py``, ``_gaze.py`` and ``_reach.py``.
``import-bag`` is in ``_bag.py``.
The argument types they share are in ``_args.py``, the ``--jobs`` / ``--executor``
options in :mod:`kinfw.executors`.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from kinfw import progress
from kinfw.cli._bag import add_import_bag_parser
from kinfw.cli._commands import (
    add_crosscheck_parser,
    add_import_csv_parser,
    add_reproduce_parser,
    add_verify_parser,
    add_view_parser,
)
from kinfw.cli._detect import add_detect_parser
from kinfw.cli._export import add_export_parser
from kinfw.cli._fit_parser import add_fit_parsers
from kinfw.cli._fleet import add_fleet_parser
from kinfw.cli._gaze import add_gaze_parser
from kinfw.cli._handeye import add_handeye_parser
from kinfw.cli._plan import add_plan_parser
from kinfw.cli._pose_chain import add_pose_chain_parser
from kinfw.cli._reach import add_reach_parser
from kinfw.cli._simulate import add_simulate_parser

log = logging.getLogger("kinfw")

#: Errors that are the user's input, not a bug: reported on one line, exit code 2.
#: ``kinfw.measurements.DatasetError``, ``kinfw.model.RobotModelError`` and
#: ``kinfw.files.OutputPathError`` are ValueErrors (caught here without importing them).
USER_ERRORS = (ValueError, OSError)
#: Exit codes as a shell reports a process ended by SIGINT (Ctrl-C) or SIGPIPE (the
#: reader of its output left): 128 + the signal's number.
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141


def _silence_stdout() -> None:
    """Point stdout at /dev/null: the reader is gone, and the interpreter's last flush
    at exit would raise again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # no file descriptor (a test's captured stdout)
        pass


class _Parser(argparse.ArgumentParser):
    """Errors in one line, ``kinfw CMD: error: ...`` (exit 2), like every other error.

    Options are never abbreviated: ``handeye --camera c=cam.yaml`` (calibrate's option,
    not handeye's) was read as ``--camera-frame`` and failed with a misleading error.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        self.exit(
            2, f"{self.prog}: error: {' '.join(message.split())} (see '{self.prog} --help')\n"
        )


# -- parser -------------------------------------------------------------------------------
#: The commands, in the order ``kinfw --help`` lists them: each adds its sub-parser, whose
#: defaults name the command (``func``) and, if it writes files, the check of its outputs
#: before any work (``check_outputs``). A new command is a module and one entry here.
COMMANDS: tuple[Callable[[Any], None], ...] = (
    add_simulate_parser,
    add_verify_parser,
    add_fit_parsers,
    add_fleet_parser,
    add_view_parser,
    add_reproduce_parser,
    add_crosscheck_parser,
    add_import_csv_parser,
    add_import_bag_parser,
    add_detect_parser,
    add_plan_parser,
    add_gaze_parser,
    add_reach_parser,
    add_handeye_parser,
    add_pose_chain_parser,
    add_export_parser,
)


def build_parser(
    commands: Sequence[Callable[[Any], None]] = COMMANDS,
) -> argparse.ArgumentParser:
    """The ``kinfw`` parser: one sub-command per entry of ``commands``, each defined
    beside its command."""
    parser = _Parser(prog="kinfw", description="Calibrate robot kinematics from measurements.")
    talk = parser.add_mutually_exclusive_group()
    talk.add_argument("-v", "--verbose", action="store_true", help="also log what each stage found")
    talk.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="no progress on stderr (warnings and errors still)",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add_parser in commands:
        add_parser(sub)
    return parser


def _error_lines(exc: BaseException) -> str:
    """The message's first line, then each later line (its details: a file's SHA-256,
    the evidence of a check) indented by two spaces; whitespace inside a line collapsed."""
    first, *details = str(exc).strip().split("\n")
    return "\n".join(
        [" ".join(first.split()), *("  " + " ".join(d.split()) for d in details if d.strip())]
    )


# -- warnings ----------------------------------------------------------------------------
class _WarningPrinter(logging.Handler):
    """Prints Python warnings and logged warnings (and, with --verbose, logged info) on
    stderr, each distinct warning once, as ``kinfw CMD: warning: ...``."""

    def __init__(self, command: str) -> None:
        super().__init__()
        self.command = command
        self.seen: set[str] = set()

    def warn(self, message: object) -> None:
        text = " ".join(str(message).split())
        if text not in self.seen:
            self.seen.add(text)
            progress.write(f"kinfw {self.command}: warning: {text}")

    def showwarning(self, message, category, filename, lineno, file=None, line=None) -> None:
        """Replacement of :func:`warnings.showwarning` (same signature)."""
        self.warn(message)

    def emit(self, record: logging.LogRecord) -> None:
        try:
            if record.levelno >= logging.WARNING:
                self.warn(record.getMessage())
            else:
                progress.write(f"{record.levelname} {record.name}: {record.getMessage()}")
        except Exception:
            self.handleError(record)


#: Environment variables that set the BLAS threads: when one is set, the user's count holds.
BLAS_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@contextlib.contextmanager
def _one_blas_thread():
    """One BLAS thread while a command runs, unless the environment sets the count
    (:data:`BLAS_THREAD_VARIABLES`).

    kinfw's matrices are tall and thin (residual rows x parameters): a second BLAS thread
    gains little on them, and on a machine busy with other work its threads' waiting
    costs more than it gains (``kinfw calibrate`` of 10,000 mocap points on two shared
    cores: 2-3x the wall time with OpenBLAS's default threads)."""
    if any(os.environ.get(name) for name in BLAS_THREAD_VARIABLES):
        yield
        return
    import numpy  # noqa: F401  (loads the BLAS library that threadpoolctl limits)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield


@contextlib.contextmanager
def _warnings_printed_once(command: str, verbose: bool):
    """Route warnings and logging to a :class:`_WarningPrinter` while the command runs."""
    printer = _WarningPrinter(command)
    root = logging.getLogger()
    level = root.level
    root.addHandler(printer)
    root.setLevel(logging.INFO if verbose else logging.WARNING)
    try:
        with warnings.catch_warnings():
            if not sys.warnoptions:  # -W / PYTHONWARNINGS win
                warnings.simplefilter("always")  # the printer keeps one of each
                # a library's deprecation notice (pyzmq under meshcat) is not the user's
                warnings.simplefilter("ignore", DeprecationWarning)
                warnings.simplefilter("ignore", PendingDeprecationWarning)
            warnings.showwarning = printer.showwarning
            yield printer
    finally:
        root.removeHandler(printer)
        root.setLevel(level)


def main(
    argv: Sequence[str] | None = None, *, commands: Sequence[Callable[[Any], None]] = COMMANDS
) -> int:
    """Entry point of the ``kinfw`` command; returns the exit code (also for ``--help``,
    0, and for an argument error, 2, which argparse signals with SystemExit).
    ``commands``: :data:`COMMANDS`, or more (a test's own command)."""
    parser = build_parser(commands)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    func: Callable[[argparse.Namespace], int] = args.func
    # progress on stderr (kinfw.progress): a bar on a terminal, lines when piped, none -q
    shown = progress.Reporter() if args.quiet else progress.stderr_reporter()
    with _warnings_printed_once(args.command, args.verbose), progress.reporting(shown):
        try:
            if getattr(args, "urdf", "") is None:
                from kinfw.model import builtin_head_urdf

                args.urdf = builtin_head_urdf()
            check = getattr(args, "check_outputs", None)
            if check is not None:  # every output path, before any work
                check(args)
            with _one_blas_thread():
                code = func(args)
            sys.stdout.flush()  # a closed pipe shows here, not at the interpreter's exit
            return code
        except BrokenPipeError:  # the reader left (``kinfw reach --json | head``)
            _silence_stdout()
            return EXIT_BROKEN_PIPE
        except USER_ERRORS as exc:
            print(f"kinfw {args.command}: error: {_error_lines(exc)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:  # outputs are written atomically: none is half-written
            lead = "\n" if sys.stderr.isatty() else ""  # below a progress bar
            print(f"{lead}kinfw {args.command}: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
