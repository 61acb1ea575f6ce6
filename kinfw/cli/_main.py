"""The ``kinfw`` command line: the one place that wires kinfw, identification and
verification together.

Exit codes: 0 on success, 2 on bad input (one line on stderr saying what and where,
never a traceback for a user error), 1 on an unexpected internal error, 3 when ``gaze``
does not fixate or ``reach`` does not reach (:mod:`kinfw.cli`). Warnings (Python
warnings and logged ones) are printed once each, as one line ``kinfw CMD: warning: ...``.

Every output path is checked before any work (:func:`_check_outputs`) and every file is
written atomically (:mod:`kinfw.files`). This module imports only the standard library at
start-up, so that ``kinfw --help`` and argument errors are immediate: numpy, Pinocchio
(through :mod:`kinfw.model`), CasADi, matplotlib and meshcat are imported by the commands.

This module holds the top-level parser, the checks of the outputs, the warning printer
and :func:`main`. Each command's sub-parser is defined beside the command: ``simulate``
in ``_simulate.py``; ``verify``, ``view``, ``reproduce``, ``crosscheck`` and
``import-csv`` in ``_commands.py``; ``calibrate``, ``demo`` and ``crossval`` in
``_fit_parser.py`` (commands in ``_fit.py``); ``detect``, ``plan``, ``gaze`` and ``reach``
in ``_detect.py``, ``_plan.py``, ``_gaze.py`` and ``_reach.py``. The argument types they
share are in ``_args.py``.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

from kinfw.cli._args import number
from kinfw.cli._commands import (
    add_crosscheck_parser,
    add_import_csv_parser,
    add_reproduce_parser,
    add_verify_parser,
    add_view_parser,
)
from kinfw.cli._detect import add_detect_parser, detect_inputs
from kinfw.cli._fit_parser import add_fit_parsers
from kinfw.cli._gaze import add_gaze_parser
from kinfw.cli._plan import add_plan_parser
from kinfw.cli._reach import add_reach_parser
from kinfw.cli._simulate import add_simulate_parser
from kinfw.files import check_output_dir, check_outputs, sidecar_path

__all__ = ["main"]

log = logging.getLogger("kinfw")

#: Errors that are the user's input, not a bug: reported on one line, exit code 2.
#: ``kinfw.measurements.DatasetError``, ``kinfw.model.RobotModelError`` and
#: ``kinfw.files.OutputPathError`` are ValueErrors (caught here without importing them).
USER_ERRORS = (ValueError, OSError)


# -- outputs -----------------------------------------------------------------------------
def _camera_inputs(args: argparse.Namespace) -> dict[str, Path]:
    """The ``--camera FRAME=FILE`` files, keyed ``--camera FRAME=`` (for the message)."""
    given = getattr(args, "camera", None)
    if not isinstance(given, list):  # detect's --camera is one file, checked by detect_inputs
        return {}
    return {f"--camera {frame}=": file for frame, file in given}


def _check_outputs(args: argparse.Namespace) -> None:
    """Check every output path of the command before any work: its directory exists and
    is writable, it is not a directory, no two outputs are one file, and no output is an
    input (``--urdf``, the data file, ``--holdout``, ``--camera`` files; symlinks
    resolved). Raises :class:`kinfw.files.OutputPathError` naming both options and the
    path."""
    command = args.command
    cameras = _camera_inputs(args)
    if command == "simulate":
        check_outputs(
            {"--out": args.out, "--truth-out": args.truth_out},
            inputs={"--urdf": args.urdf, "--plan": args.plan, **cameras},
        )
    elif command == "calibrate":
        check_outputs(
            {"--out": args.out, "sidecar": sidecar_path(args.out), "--report": args.report},
            inputs={
                "--urdf": args.urdf,
                "data file": args.data,
                "--holdout": args.holdout,
                **cameras,
            },
        )
    elif command == "demo":
        from kinfw.verification.studies import DEMO_FILES

        check_output_dir(args.out, label="--out", files=DEMO_FILES)
    elif command == "view" and args.html is not None:
        sidecar = args.sidecar or (args.calibrated and sidecar_path(args.calibrated))
        check_outputs(
            {"--html": args.html},
            inputs={
                "nominal": args.nominal,
                "--calibrated": args.calibrated,
                "--data": args.data,
                "sidecar": sidecar,
            },
        )
    elif command == "reproduce":
        check_output_dir(args.out, label="--out")
    elif command == "import-csv":
        check_outputs({"--out": args.out}, inputs={"--urdf": args.urdf, "csv": args.csv})
    elif command == "plan":
        check_outputs(
            {"--out": args.out, "--plot": args.plot},
            inputs={"--urdf": args.urdf, "--pool": args.pool},
        )
    elif command == "detect":
        check_outputs({"--out": args.out}, inputs=detect_inputs(args))
    elif command == "gaze" and args.html is not None:
        check_outputs({"--html": args.html}, inputs={"model": args.model, **cameras})
    elif command == "reach" and args.html is not None:
        check_outputs({"--html": args.html}, inputs={"model": args.model})


class _Parser(argparse.ArgumentParser):
    """Errors in one line, ``kinfw CMD: error: ...`` (exit 2), like every other error."""

    def error(self, message: str) -> NoReturn:
        self.exit(
            2, f"{self.prog}: error: {' '.join(message.split())} (see '{self.prog} --help')\n"
        )


# -- parser -------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    """The ``kinfw`` parser: one sub-command per command, each defined beside its command."""
    parser = _Parser(prog="kinfw", description="Calibrate robot kinematics from measurements.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_simulate_parser(sub)
    add_verify_parser(sub)
    add_fit_parsers(sub)
    add_view_parser(sub)
    add_reproduce_parser(sub)
    add_crosscheck_parser(sub)
    add_import_csv_parser(sub)
    add_detect_parser(sub, number(int, low=4))
    add_plan_parser(sub, number)
    add_gaze_parser(sub)
    add_reach_parser(sub)
    return parser


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
            print(f"kinfw {self.command}: warning: {text}", file=sys.stderr, flush=True)

    def showwarning(self, message, category, filename, lineno, file=None, line=None) -> None:
        """Replacement of :func:`warnings.showwarning` (same signature)."""
        self.warn(message)

    def emit(self, record: logging.LogRecord) -> None:
        try:
            if record.levelno >= logging.WARNING:
                self.warn(record.getMessage())
            else:
                print(
                    f"{record.levelname} {record.name}: {record.getMessage()}",
                    file=sys.stderr,
                    flush=True,
                )
        except Exception:
            self.handleError(record)


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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``kinfw`` command; returns the exit code (also for ``--help``,
    0, and for an argument error, 2, which argparse signals with SystemExit)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    func: Callable[[argparse.Namespace], int] = args.func
    with _warnings_printed_once(args.command, args.verbose):
        try:
            if getattr(args, "urdf", "") is None:
                from kinfw.model import builtin_head_urdf

                args.urdf = builtin_head_urdf()
            _check_outputs(args)
            return func(args)
        except USER_ERRORS as exc:
            message = " ".join(str(exc).split())
            print(f"kinfw {args.command}: error: {message}", file=sys.stderr)
            return 2
