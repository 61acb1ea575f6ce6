"""The parsers of the ``kinfw`` commands that fit a model: ``calibrate``, ``demo`` and
``crossval`` (the commands are in :mod:`kinfw.cli`), with the refinement's options
they share and the calibration's options ``fleet`` shares.

Like :mod:`kinfw.cli`, this module imports only the standard library at start-up.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinfw.cli._args import (
    POSITIVE_DEG,
    POSITIVE_MM,
    POSITIVE_PX,
    SEED,
    add_camera_option,
    add_keep_duplicates_option,
    add_model_option,
    add_mount_option,
    add_xacro_option,
    camera_inputs,
    number,
    prior_scale_arg,
)
from kinfw.cli._fit import cmd_calibrate, cmd_crossval, cmd_demo
from kinfw.executors import add_executor_options
from kinfw.files import check_output_dir, check_outputs, sidecar_path


def _add_fit_options(p: argparse.ArgumentParser) -> None:
    """Noise, robust loss and prior of the refinement (calibrate and crossval)."""
    p.add_argument(
        "--sigma-mm",
        type=POSITIVE_MM,
        help="position noise sigma per axis, mm (default: estimated from the residuals)",
    )
    p.add_argument(
        "--sigma-deg",
        type=POSITIVE_DEG,
        help="orientation noise: angle sigma about a random axis, deg (default: estimated)",
    )
    p.add_argument(
        "--sigma-px",
        type=POSITIVE_PX,
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
        type=POSITIVE_MM,
        help="Gaussian prior on the joints' deviations from the nominal (base and tool "
        "frames stay free): sigma of lengths, mm (for small datasets)",
    )
    p.add_argument("--prior-deg", type=POSITIVE_DEG, help="... and of angles, deg")
    p.add_argument(
        "--prior",
        action="append",
        type=prior_scale_arg,
        metavar="GROUP=VALUE",
        help="a prior's sigma for one parameter group (repeatable; over --prior-mm/-deg): "
        "offsets, axes, positions, base, tools, intrinsics or a --model block's name, "
        "e.g. offsets=0.5deg positions=0.2mm; with --params auto no prior is then chosen",
    )
    add_keep_duplicates_option(p)


def add_fit_parsers(sub: argparse._SubParsersAction) -> None:
    """The ``calibrate``, ``demo`` and ``crossval`` sub-commands."""
    _add_calibrate_parser(sub)
    _add_demo_parser(sub)
    _add_crossval_parser(sub)


def _add_calibrate_parser(sub: argparse._SubParsersAction) -> None:
    """The ``calibrate`` sub-command."""
    p = sub.add_parser("calibrate", help="identify the kinematics and write a calibrated URDF")
    p.add_argument("data", type=Path, help="measurement file (kinfw-measurements JSON)")
    p.add_argument("--urdf", type=Path, required=True, help="nominal URDF")
    add_xacro_option(p)
    p.add_argument("--out", type=Path, required=True, help="calibrated URDF to write")
    p.add_argument("--report", type=Path, help="write the report (JSON) here")
    p.add_argument(
        "--holdout",
        type=Path,
        help="measurement file not used for calibration; its errors go to the report and sidecar",
    )
    add_calibration_options(p)
    add_mount_option(p)
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=cmd_calibrate, check_outputs=check_calibrate_outputs)


def add_calibration_options(p: argparse.ArgumentParser) -> None:
    """How ``calibrate`` (and ``fleet``, for each robot) calibrates: ``--method``,
    ``--params``, noise, loss and prior, ``--camera``, ``--refine-intrinsics``
    (:func:`kinfw.cli._fit.calibration_options` reads them)."""
    p.add_argument(
        "--method",
        choices=("refine", "closed-form"),
        default="refine",
        help="refine (default): closed form and hand-eye, then the joint "
        "nonlinear least squares; closed-form: stop after closed form and hand-eye",
    )
    p.add_argument(
        "--params",
        default="auto",
        help="what to estimate: auto (default: full when there are at least 10 residual "
        "rows per parameter, else the set and prior with the lowest leave-one-out held-out error "
        "among frames, offsets, full and full under a prior by parameter group chosen from "
        "the data), full, "
        "offsets (joint zero offsets + base and tool frames), frames (base and "
        "tool frames only), none, or a mask 'pan,tilt:l_x,...' (frames plus "
        "those joints' CPC parameters)",
    )
    _add_fit_options(p)
    add_camera_option(p)
    p.add_argument(
        "--refine-intrinsics",
        nargs="*",
        metavar="FRAME",
        help="also estimate the intrinsics (fx fy cx cy k1 k2 p1 p2 k3) of these cameras "
        "(no FRAME: every camera with 'pixels' observations), started from the given ones; "
        "the report says which the images do not determine",
    )
    add_guard_options(p)
    add_model_option(p)


def add_guard_options(p: argparse.ArgumentParser, *, writes: bool = True) -> None:
    """The plausibility guard: ``--max-change-mm``, ``--max-change-deg``
    (:func:`kinfw.cli._fit.change_bound` reads them) and, for a command that writes a
    calibration (``writes``), ``--allow-large-changes``."""
    if writes:
        p.add_argument(
            "--allow-large-changes",
            action="store_true",
            help="write the calibration even when a joint, a mount or a stance link's pose "
            "changed beyond the plausibility bound (the larger of 5 x the prior and 20 mm "
            "/ 2 deg, a move never above 5 %% of the robot's size); the report says so",
        )
    p.add_argument(
        "--max-change-mm",
        type=POSITIVE_MM,
        help="the plausibility bound on a move, mm (replaces the rule above)",
    )
    p.add_argument(
        "--max-change-deg",
        type=POSITIVE_DEG,
        help="the plausibility bound on a turn, deg (replaces the rule above)",
    )


def _add_demo_parser(sub: argparse._SubParsersAction) -> None:
    """The ``demo`` sub-command."""
    p = sub.add_parser("demo", help="simulate, calibrate and evaluate the built-in IIS-head")
    p.add_argument(
        "--out", type=Path, default=Path("demo_out"), help="output directory (default demo_out)"
    )
    p.add_argument("--seed", type=SEED, default=0)
    p.add_argument(
        "--pixels",
        action="store_true",
        help="stage 2 from images: each camera (640x480, fx = fy = 600 px) sees the corners "
        "of a fixed chessboard (pixel noise 0.5 px); calibrated on reprojection error",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=cmd_demo, check_outputs=check_demo_outputs)


def _add_crossval_parser(sub: argparse._SubParsersAction) -> None:
    """The ``crossval`` sub-command."""
    p = sub.add_parser(
        "crossval",
        help="k-fold cross-validation against baselines",
        description="Held-out error of the calibration (folds by sample): the full "
        "parameter set and the default (what kinfw calibrate fits with its default "
        "options: the model choice made on each training fold), next to two baselines on "
        "the same folds: the nominal geometry and 'frames only' (nominal joints; "
        "measurement frame, markers, target and tool / hand-eye frames fitted). Warns "
        "when the full calibration is worse than frames only, with the likely cause.",
    )
    p.add_argument("data", type=Path, help="measurement file")
    p.add_argument("--urdf", type=Path, required=True, help="nominal URDF")
    add_xacro_option(p)
    p.add_argument("--k", type=number(int, low=2), default=5, help="folds (default 5)")
    p.add_argument("--seed", type=SEED, default=0)
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
    add_camera_option(p)
    add_mount_option(p)
    add_guard_options(p, writes=False)
    add_model_option(p)
    add_executor_options(p, tasks="the fits (folds x parameter sets)")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.set_defaults(func=cmd_crossval)


def check_calibrate_outputs(args: argparse.Namespace) -> None:
    """``kinfw calibrate``'s outputs (URDF, its sidecar, report), checked before any work."""
    check_outputs(
        {"--out": args.out, "sidecar": sidecar_path(args.out), "--report": args.report},
        inputs={
            "--urdf": args.urdf,
            "data file": args.data,
            "--holdout": args.holdout,
            **camera_inputs(args),
        },
    )


def check_demo_outputs(args: argparse.Namespace) -> None:
    """``kinfw demo``'s output directory and the files it will hold."""
    from kinfw.verification.studies import DEMO_FILES

    check_output_dir(args.out, label="--out", files=DEMO_FILES)
