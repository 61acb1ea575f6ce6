"""The ``kinfw`` command line: the one place that wires kinfw, identification and
verification together.

Exit codes: 0 on success, 2 on bad input (one line on stderr saying what and where,
never a traceback for a user error), 1 on an unexpected internal error, 3 when ``gaze``
does not fixate or ``reach`` does not reach (:mod:`kinfw.cli_control`). Warnings (Python
warnings and logged ones) are printed once each, as one line ``kinfw CMD: warning: ...``.

Every output path is checked before any work (:func:`_check_outputs`) and every file is
written atomically (:mod:`kinfw.files`). This module imports only the standard library at
start-up, so that ``kinfw --help`` and argument errors are immediate: numpy, Pinocchio
(through :mod:`kinfw.robot`), CasADi, matplotlib and meshcat are imported by the commands.

This module holds the parser, the checks of the outputs, the warning printer and
:func:`main`; the commands themselves (``cmd_simulate``, ``cmd_verify``, ...) are in
:mod:`kinfw.cli_commands`, those that fit a model (``cmd_calibrate``, ``cmd_demo``,
``cmd_crossval``) in :mod:`kinfw.cli_fit`.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

from kinfw.cli_commands import (
    cmd_crosscheck,
    cmd_import_csv,
    cmd_reproduce,
    cmd_simulate,
    cmd_verify,
    cmd_view,
    default_sidecar_path,
)
from kinfw.cli_control import add_control_parsers
from kinfw.cli_detect import add_detect_parser, detect_inputs
from kinfw.cli_fit import cmd_calibrate, cmd_crossval, cmd_demo
from kinfw.cli_plan import add_plan_parser
from kinfw.files import check_output_dir, check_outputs

__all__ = ["main"]

log = logging.getLogger("kinfw")

#: Errors that are the user's input, not a bug: reported on one line, exit code 2.
#: ``kinfw.measurements.DatasetError``, ``kinfw.robot.RobotModelError`` and
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
            {"--out": args.out, "sidecar": default_sidecar_path(args.out), "--report": args.report},
            inputs={
                "--urdf": args.urdf,
                "data file": args.data,
                "--holdout": args.holdout,
                **cameras,
            },
        )
    elif command == "demo":
        from verification.demo import DEMO_FILES

        check_output_dir(args.out, label="--out", files=DEMO_FILES)
    elif command == "view" and args.html is not None:
        sidecar = args.sidecar or (args.calibrated and default_sidecar_path(args.calibrated))
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


# -- numbers on the command line -----------------------------------------------------------
def _number(
    kind: type,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    unit: str = "",
) -> Callable[[str], float | int]:
    """An argparse ``type``: ``kind`` (int or float) within ``[low, high]`` (``(low,
    high]`` with ``low_open``); argparse names the flag in the error."""
    if low is not None and high is not None:
        want = f"{'>' if low_open else '>='} {low:g} and <= {high:g}"
    elif low is not None:
        want = f"{'>' if low_open else '>='} {low:g}"
    else:
        want = ""
    noun = "an integer" if kind is int else "a number"
    suffix = f" {unit}" if unit else ""

    def parse(text: str) -> float | int:
        try:
            value = kind(text)
        except ValueError:
            value = None
        if (
            value is None
            or not math.isfinite(value)
            or (low is not None and (value <= low if low_open else value < low))
            or (high is not None and value > high)
        ):
            raise argparse.ArgumentTypeError(
                f"expected {' '.join(filter(None, (noun, want)))}{suffix}, got {text!r}"
            )
        return value

    parse.__name__ = kind.__name__  # argparse's own messages say "invalid int value"
    return parse


_MM = _number(float, low=0.0, unit="(mm)")
_DEG = _number(float, low=0.0, unit="(deg)")
_POSITIVE_MM = _number(float, low=0.0, low_open=True, unit="(mm)")
_POSITIVE_DEG = _number(float, low=0.0, low_open=True, unit="(deg)")
_POSITIVE_PX = _number(float, low=0.0, low_open=True, unit="(px)")
_COUNT = _number(int, low=1)
_SEED = _number(int, low=0)


def up_arg(text: str) -> list[float]:
    """``"x y z"`` (or ``x,y,z``): three finite numbers, not all zero."""
    try:
        up = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        up = []
    if len(up) != 3 or not all(map(math.isfinite, up)) or not any(up):
        raise argparse.ArgumentTypeError(
            f'expected three numbers "x y z", not all zero, got {text!r}'
        )
    return up


class _Parser(argparse.ArgumentParser):
    """Errors in one line, ``kinfw CMD: error: ...`` (exit 2), like every other error."""

    def error(self, message: str) -> NoReturn:
        self.exit(
            2, f"{self.prog}: error: {' '.join(message.split())} (see '{self.prog} --help')\n"
        )


# -- parser ------------------------------------------------------------------------------
def _add_fit_options(p: argparse.ArgumentParser) -> None:
    """Noise, robust loss and prior of the refinement (calibrate and crossval)."""
    p.add_argument(
        "--sigma-mm",
        type=_POSITIVE_MM,
        help="position noise sigma per axis, mm (default: estimated from the residuals)",
    )
    p.add_argument(
        "--sigma-deg",
        type=_POSITIVE_DEG,
        help="orientation noise: angle sigma about a random axis, deg (default: estimated)",
    )
    p.add_argument(
        "--sigma-px",
        type=_POSITIVE_PX,
        help="pixel noise sigma per image coordinate of 'pixels' observations, px "
        "(default: estimated)",
    )
    p.add_argument(
        "--loss",
        choices=("huber", "linear", "cauchy"),
        default="huber",
        help="robust loss of the refinement (default huber: gross outliers are "
        "down-weighted and listed)",
    )
    p.add_argument(
        "--prior-mm",
        type=_POSITIVE_MM,
        help="Gaussian prior on deviations from "
        "the nominal: sigma of lengths, mm (for small datasets)",
    )
    p.add_argument("--prior-deg", type=_POSITIVE_DEG, help="... and of angles, deg")


def _frame_file(text: str) -> tuple[str, Path]:
    """``FRAME=FILE`` of ``--camera``."""
    frame, sep, file = text.partition("=")
    if not sep or not frame or not file:
        raise argparse.ArgumentTypeError(f"expected FRAME=FILE, got {text!r}")
    return frame, Path(file)


def _add_camera_option(p: argparse.ArgumentParser) -> None:
    """``--camera FRAME=FILE`` (repeatable): intrinsics for ``pixels`` observations."""
    p.add_argument(
        "--camera",
        action="append",
        type=_frame_file,
        metavar="FRAME=FILE",
        help="intrinsics of the camera frame FRAME for 'pixels' observations, from a ROS "
        "camera_info / OpenCV YAML or JSON file; overrides or adds to the data file's "
        '"cameras" section (and, for verify, the sidecar\'s); a FRAME no observation uses '
        "is an error (repeatable)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="kinfw", description="Calibrate robot kinematics from measurements.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "simulate",
        help="simulate measurements of a perturbed robot",
        description="Perturb the nominal URDF into a 'true' robot and simulate "
        "its measurements: stage 1 poses of --frames, one joint at a time "
        "(Shih et al. section 4.1); stage 2 camera observations of a fixed "
        "target at random configurations.",
    )
    p.add_argument(
        "--urdf", type=Path, default=None, help="nominal URDF (default: the built-in IIS-head)"
    )
    p.add_argument("--out", type=Path, required=True, help="measurement file to write (JSON)")
    p.add_argument("--truth-out", type=Path, required=True, help="true robot URDF to write")
    p.add_argument(
        "--per-joint",
        type=_COUNT,
        default=9,
        help="stage 1 measurements per joint (default 9, as the paper)",
    )
    p.add_argument(
        "--noise-mm", type=_MM, default=0.5, help="position noise sigma per axis, mm (default 0.5)"
    )
    p.add_argument(
        "--noise-deg", type=_DEG, default=0.5, help="rotation noise angle sigma, deg (default 0.5)"
    )
    p.add_argument(
        "--stereo-mm",
        type=_MM,
        default=None,
        help="simulate the stereo rig: point noise sigma on the nine-circle "
        "plate, mm (replaces --noise-mm/--noise-deg for stage 1 poses)",
    )
    p.add_argument(
        "--error-mm",
        type=_MM,
        default=2.0,
        help="true robot: joint origin error sigma, mm (default 2)",
    )
    p.add_argument(
        "--error-deg",
        type=_DEG,
        default=0.5,
        help="true robot: joint origin and axis error sigma, deg (default 0.5)",
    )
    p.add_argument(
        "--fraction",
        type=_number(float, low=0.0, high=1.0, low_open=True),
        default=0.8,
        help="fraction of each joint range used (default 0.8)",
    )
    p.add_argument(
        "--stage",
        choices=("1", "2", "both"),
        default=None,
        help="stage 1 (one joint at a time), 2 (random configurations seen by the cameras) "
        "or both (default 1; with --pixels: both, and 1 is an error)",
    )
    p.add_argument(
        "--stage2-samples",
        type=_COUNT,
        default=30,
        help="stage 2 random configurations (default 30)",
    )
    p.add_argument("--frames", help="stage 1 frames, comma-separated (default: URDF hint)")
    p.add_argument("--cameras", help="stage 2 cameras, comma-separated (default: URDF hint)")
    p.add_argument(
        "--pixels",
        action="store_true",
        help="stage 2 as images: the corners of a fixed --board seen by each camera "
        "('pixels' observations; a corner is seen when in front of the camera, within 60 "
        "deg of its axis and 5 px inside the image; an image is dropped when the board is "
        "seen more than 70 deg from its normal, or with fewer than 4 corners, all of a "
        "chessboard's, or corners on one line; configurations where no camera sees the "
        "board are drawn again)",
    )
    p.add_argument(
        "--pixel-sigma",
        type=_number(float, low=0.0, unit="px"),
        default=0.5,
        help="with --pixels: pixel noise sigma per image coordinate, px (default 0.5)",
    )
    p.add_argument(
        "--board",
        default=None,
        help="with --pixels: the board, chessboard:COLSxROWS:SQUARE_M or "
        "charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT] (default chessboard:9x6:0.04)",
    )
    _add_camera_option(p)
    p.add_argument(
        "--plan",
        type=Path,
        default=None,
        help="a plan file (kinfw plan --out): measure at its configurations, in its order "
        "(stage 1 and stage 2), instead of one joint at a time / random",
    )
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("verify", help="errors of a URDF model against measurements")
    p.add_argument("model", type=Path, help="URDF to evaluate")
    p.add_argument("data", type=Path, help="measurement file (kinfw-measurements JSON)")
    p.add_argument(
        "--sidecar",
        type=Path,
        help="calibration sidecar (default: MODEL.kinfw.json beside the model, used when present)",
    )
    p.add_argument(
        "--no-sidecar",
        action="store_true",
        help="ignore the sidecar: fit nuisance frames to these data",
    )
    _add_camera_option(p)
    p.add_argument(
        "--json", action="store_true", help="print the report as JSON, with per-sample errors"
    )
    p.set_defaults(func=cmd_verify)

    p = sub.add_parser("calibrate", help="identify the kinematics and write a calibrated URDF")
    p.add_argument("data", type=Path, help="measurement file (kinfw-measurements JSON)")
    p.add_argument("--urdf", type=Path, required=True, help="nominal URDF")
    p.add_argument("--out", type=Path, required=True, help="calibrated URDF to write")
    p.add_argument("--report", type=Path, help="write the report (JSON) here")
    p.add_argument(
        "--method",
        choices=("refine", "closed-form"),
        default="refine",
        help="refine (default): closed form and hand-eye, then the joint "
        "nonlinear least squares; closed-form: stop after closed form and hand-eye",
    )
    p.add_argument(
        "--holdout",
        type=Path,
        help="measurement file not used for calibration; its errors go to the report and sidecar",
    )
    p.add_argument(
        "--params",
        default="auto",
        help="what to estimate: auto (default: full when there are at least 10 residual "
        "rows per parameter, else the set and prior with the lowest 5-fold held-out error "
        "among frames, offsets, full and full with a prior of 1, 3 or 10 mm), full, "
        "offsets (joint zero offsets + base and tool frames), frames (base and "
        "tool frames only), none, or a mask 'pan,tilt:l_x,...' (frames plus "
        "those joints' CPC parameters)",
    )
    _add_fit_options(p)
    _add_camera_option(p)
    p.add_argument(
        "--refine-intrinsics",
        nargs="*",
        metavar="FRAME",
        help="also estimate the intrinsics (fx fy cx cy k1 k2 p1 p2 k3) of these cameras "
        "(no FRAME: every camera with 'pixels' observations), started from the given ones; "
        "the report says which the images do not determine",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=cmd_calibrate)

    p = sub.add_parser("demo", help="simulate, calibrate and evaluate the built-in IIS-head")
    p.add_argument(
        "--out", type=Path, default=Path("demo_out"), help="output directory (default demo_out)"
    )
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument(
        "--pixels",
        action="store_true",
        help="stage 2 from images: each camera (640x480, fx = fy = 600 px) sees the corners "
        "of a fixed chessboard (pixel noise 0.5 px); calibrated on reprojection error",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser(
        "crossval",
        help="k-fold cross-validation against baselines",
        description="Held-out error of the calibration (folds by sample) next "
        "to two baselines on the same folds: the nominal geometry and 'frames "
        "only' (nominal joints; measurement frame, markers, target and tool / "
        "hand-eye frames fitted). Warns when the calibration is worse than "
        "frames only, with the likely cause.",
    )
    p.add_argument("data", type=Path, help="measurement file")
    p.add_argument("--urdf", type=Path, required=True, help="nominal URDF")
    p.add_argument("--k", type=_number(int, low=2), default=5, help="folds (default 5)")
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument(
        "--select",
        action="store_true",
        help="also try 'offsets' and pick the parameter set with the lowest held-out error, "
        "position and orientation together (each whitened by the estimated noise)",
    )
    p.add_argument(
        "--exclude-flagged",
        action="store_true",
        help="leave the observations the full-data fit rejects as gross errors out of the "
        "held-out scores (and list them)",
    )
    _add_fit_options(p)
    _add_camera_option(p)
    p.add_argument(
        "--jobs",
        type=_COUNT,
        default=1,
        help="run the fits in N worker processes (default 1: in this process)",
    )
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.set_defaults(func=cmd_crossval)

    p = sub.add_parser(
        "view",
        help="nominal and calibrated robots and measurements in 3D",
        description="Meshcat view: the nominal robot as a grey ghost, the "
        "calibrated one in colour, a sample's measured poses as triads and "
        "lines from prediction to measurement (scaled), targets and cameras. "
        "Live on 127.0.0.1, or one self-contained HTML file with --html.",
    )
    p.add_argument("nominal", type=Path, help="nominal URDF")
    p.add_argument("--calibrated", type=Path, help="calibrated URDF")
    p.add_argument("--data", type=Path, help="measurement file: draw one sample's observations")
    p.add_argument(
        "--sidecar",
        type=Path,
        help="calibration sidecar (default: CALIBRATED.kinfw.json beside --calibrated, if present)",
    )
    p.add_argument("--sample", type=_number(int), default=None, help="sample to draw (default 0)")
    p.add_argument(
        "--residual-scale",
        type=_number(float, low=0.0, low_open=True),
        default=10.0,
        help="lengthen prediction-to-measurement lines by this factor (default 10)",
    )
    p.add_argument(
        "--up",
        type=up_arg,
        help='"x y z": up direction of the root frame '
        "(default: the URDF's <kinfw up> hint, else z)",
    )
    p.add_argument(
        "--package-dir",
        action="append",
        default=[],
        help="where package:// meshes live (repeatable)",
    )
    p.add_argument("--html", type=Path, help="write a self-contained HTML file instead of serving")
    p.set_defaults(func=cmd_view)

    p = sub.add_parser(
        "reproduce",
        help="reproduce a paper's experiment in simulation (PNG)",
        description="fig11: Shih et al. Fig. 11 (positioning error vs "
        "measurements per joint and noise); table4: their Table 4 protocol; "
        "hirsh: Hirsh et al. Figs. 3-4 (A = X B Y error vs iteration); crlb: "
        "the joint refinement against the Cramer-Rao bound; robust: with 5 % "
        "gross outliers, per robust loss; gaze: fixation, triangulation and reaching "
        "with the nominal vs calibrated model, on simulated true heads and UR10s.",
    )
    p.add_argument("study", choices=("fig11", "table4", "hirsh", "crlb", "robust", "gaze"))
    p.add_argument(
        "--out",
        type=Path,
        default=Path("reproduce_out"),
        help="output directory (default reproduce_out)",
    )
    p.add_argument("--trials", type=_COUNT, default=None, help="random trials per point")
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument(
        "--jobs",
        type=_COUNT,
        default=1,
        help="run the trials in N worker processes (default 1: in this process)",
    )
    p.add_argument("--json", action="store_true", help="print the study's JSON, not tables")
    p.set_defaults(func=cmd_reproduce)

    p = sub.add_parser("crosscheck", help="check the CPC model against Pinocchio FK")
    p.add_argument("urdf", type=Path)
    p.add_argument("--frames", help="end frames, comma-separated (default: URDF hint)")
    p.add_argument("-n", type=_COUNT, default=200, help="random configurations (default 200)")
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_crosscheck)

    p = sub.add_parser(
        "import-csv",
        help="convert a FIGAROH calibration CSV into a measurement file",
        description="Read a FIGAROH-style calibration CSV (marker columns x1, y1, z1 "
        "[phix1, phiy1, phiz1], ...; one column per URDF joint) and write it as a "
        "kinfw-measurements file: per marker, points (or poses with the phi columns) "
        "of a marker of unknown offset on --frame.",
    )
    p.add_argument("csv", type=Path, help="FIGAROH CSV file")
    p.add_argument("--urdf", type=Path, required=True, help="URDF naming the joint columns")
    p.add_argument("--frame", required=True, help="URDF link or joint the markers are on")
    p.add_argument(
        "--measured-in",
        default=None,
        help="measurement frame, not in the URDF (default: the URDF root link)",
    )
    p.add_argument("--marker", default="marker", help="marker name prefix (default 'marker')")
    p.add_argument(
        "--target",
        default=None,
        help="read the 6D columns as the pose of a fixed target NAME seen by a camera on "
        "--frame (camera_T_target: a camera on the flange seeing a board; the camera's mount "
        "and the target's pose are estimated); excludes --measured-in",
    )
    p.add_argument("--length-unit", choices=("m", "mm"), default="m", help="default m")
    p.add_argument("--angle-unit", choices=("rad", "deg"), default="rad", help="default rad")
    p.add_argument("--out", type=Path, required=True, help="measurement file to write (JSON)")
    p.set_defaults(func=cmd_import_csv)

    add_detect_parser(sub, _number(int, low=4))
    add_plan_parser(sub, _number)
    add_control_parsers(sub, _number, _frame_file)
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
                from kinfw.robot import builtin_head_urdf

                args.urdf = builtin_head_urdf()
            _check_outputs(args)
            return func(args)
        except USER_ERRORS as exc:
            message = " ".join(str(exc).split())
            print(f"kinfw {args.command}: error: {message}", file=sys.stderr)
            return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
