"""The ``kinfw`` commands that check or show a model and convert data, without fitting one:
``verify``, ``view``, ``reproduce``, ``crosscheck`` and ``import-csv``, each its parser
(``add_<name>_parser``) and its command (``cmd_<name>``).

Each ``cmd_<name>(args)`` runs ``kinfw <name>`` on the parsed arguments and returns the
exit code; user errors are raised (ValueError, OSError) and reported by
:func:`kinfw.cli.main`. Like :mod:`kinfw.cli`, this module imports only the standard
library at start-up: numpy, Pinocchio, CasADi, matplotlib and meshcat are imported
inside the commands.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
from pathlib import Path

from kinfw.cli._args import (
    COUNT,
    SEED,
    add_camera_option,
    add_keep_duplicates_option,
    add_mount_option,
    add_package_dir_option,
    add_payload_options,
    add_xacro_option,
    frames_arg,
    load_model,
    mounted_model,
    number,
    read_data,
    up_arg,
    with_payload,
)
from kinfw.cli._tables import accuracy_table
from kinfw.executors import add_executor_options
from kinfw.files import check_output_dir, check_outputs, json_text, sidecar_path


# -- kinfw verify -----------------------------------------------------------------------
def add_verify_parser(sub: argparse._SubParsersAction) -> None:
    """The ``verify`` sub-command."""
    p = sub.add_parser("verify", help="errors of a URDF model against measurements")
    p.add_argument("model", type=Path, help="URDF to evaluate")
    add_xacro_option(p)
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
    add_camera_option(p)
    add_mount_option(p)
    add_keep_duplicates_option(p)
    p.add_argument(
        "--json", action="store_true", help="print the report as JSON, with per-sample errors"
    )
    p.set_defaults(func=cmd_verify)


def cmd_verify(args: argparse.Namespace) -> int:
    from kinfw.records import read_sidecar
    from kinfw.verification.evaluation import evaluate_model

    robot = load_model(args.model, args)
    data = read_data(args.data, args)
    robot = mounted_model(robot, data)
    sidecar_file = args.sidecar or sidecar_path(args.model)
    sidecar = None
    if Path(sidecar_file).is_file() and not args.no_sidecar:
        sidecar = read_sidecar(sidecar_file)
        if Path(args.model).is_file():  # not a URDF on stdin
            sidecar = sidecar.check_urdf(args.model)
        if sidecar.robot_blocks:  # what the URDF cannot hold: compliance, gear scales...
            robot = robot.with_spec(sidecar.spec())
    elif args.sidecar:
        raise OSError(f"{args.sidecar}: sidecar not found")
    overridden = []
    if sidecar is not None:  # --camera given explicitly wins over the sidecar's intrinsics
        given = {frame for frame, _ in args.camera or ()}
        overridden = [
            u.name for u in sidecar.unknowns if u.kind == "intrinsics" and u.name in given
        ]
        sidecar = dataclasses.replace(
            sidecar,
            unknowns=tuple(
                u
                for u in sidecar.unknowns
                if (u.kind, u.name) not in {("intrinsics", f) for f in overridden}
            ),
        )
    report = evaluate_model(robot, data, sidecar=sidecar)
    used = str(sidecar_file) if sidecar is not None else None
    if args.json:
        print(
            json_text(
                {
                    "model": str(args.model),
                    "data": str(args.data),
                    "sidecar": used,
                    "intrinsics_from_camera_option": overridden,
                    **report.to_dict(per_sample=True),
                },
                indent=2,
            )
        )
        return 0
    print(
        f"errors of {args.model} against {args.data} ({data.n_samples} samples; "
        "measured minus predicted)"
    )
    if used:
        print(
            f"using the calibration sidecar {used} (measurement frame, targets, markers "
            "as calibrated, not refitted)"
        )
    print(accuracy_table(report.to_dict()))
    for frame in overridden:
        file = next(f for c, f in args.camera if c == frame)
        print(
            f"note: intrinsics of camera {frame!r} from --camera {frame}={file}, not the sidecar's"
        )
    for note in report.fitted:
        print(f"note: fitted from the data: {note}")
    return 0


# -- kinfw view -------------------------------------------------------------------------
def add_view_parser(sub: argparse._SubParsersAction) -> None:
    """The ``view`` sub-command."""
    p = sub.add_parser(
        "view",
        help="nominal and calibrated robots and measurements in 3D",
        description="Meshcat view: the nominal robot as a grey ghost, the "
        "calibrated one in colour, a sample's measured poses as triads and "
        "lines from prediction to measurement (scaled), targets and cameras. "
        "Live on 127.0.0.1, or one self-contained HTML file with --html.",
    )
    p.add_argument("nominal", type=Path, help="nominal URDF")
    add_xacro_option(p)
    p.add_argument("--calibrated", type=Path, help="calibrated URDF")
    p.add_argument("--data", type=Path, help="measurement file: draw one sample's observations")
    p.add_argument(
        "--sidecar",
        type=Path,
        help="calibration sidecar (default: CALIBRATED.kinfw.json beside --calibrated, if present)",
    )
    p.add_argument("--sample", type=number(int), default=None, help="sample to draw (default 0)")
    p.add_argument(
        "--residual-scale",
        type=number(float, low=0.0, low_open=True),
        default=10.0,
        help="lengthen prediction-to-measurement lines by this factor (default 10)",
    )
    p.add_argument(
        "--up",
        type=up_arg,
        help='"x y z": up direction of the root frame '
        "(default: the URDF's <kinfw up> hint, else z)",
    )
    add_package_dir_option(p)
    p.add_argument("--html", type=Path, help="write a self-contained HTML file instead of serving")
    p.set_defaults(func=cmd_view, check_outputs=check_view_outputs)


def cmd_view(args: argparse.Namespace) -> int:
    from kinfw.view import show

    if args.sample is not None and args.data is None:
        raise ValueError(f"--sample {args.sample}: give --data, the measurements to draw")
    nominal = load_model(args.nominal, args)
    calibrated = load_model(args.calibrated, args) if args.calibrated else None
    data = read_data(args.data, args) if args.data else None
    if data is not None:  # frames the data mount on the robot: drawn on the nominal too
        nominal = mounted_model(nominal, data)
    if args.sample is not None and not 0 <= args.sample < data.n_samples:
        raise ValueError(
            f"--sample {args.sample}: out of range, {args.data} has "
            f"{data.n_samples} samples (give 0 to {data.n_samples - 1})"
        )
    shown = show(
        nominal,
        calibrated,
        data,
        sidecar=args.sidecar,
        sample=args.sample,
        residual_scale=args.residual_scale,
        up=args.up,
        package_dirs=tuple(args.package_dir),
        html=args.html,
    )
    if args.html:
        print(
            f"wrote {shown} ({shown.stat().st_size / 1e6:.1f} MB, self-contained: open it in "
            "any browser, no network needed)"
        )
        return 0
    print(f"meshcat is serving the scene at {shown.url()} (127.0.0.1); press Enter to stop")
    with contextlib.suppress(EOFError, KeyboardInterrupt):
        input()
    return 0


# -- kinfw reproduce --------------------------------------------------------------------
def add_reproduce_parser(sub: argparse._SubParsersAction) -> None:
    """The ``reproduce`` sub-command."""
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
    p.add_argument("--trials", type=COUNT, default=None, help="random trials per point")
    p.add_argument("--seed", type=SEED, default=0)
    add_executor_options(p, tasks="the trials")
    p.add_argument("--json", action="store_true", help="print the study's JSON, not tables")
    p.set_defaults(func=cmd_reproduce, check_outputs=check_reproduce_outputs)


def cmd_reproduce(args: argparse.Namespace) -> int:
    import contextlib
    import io

    from kinfw.verification.papers import hirsh_figures_main, shih_figures_main
    from kinfw.verification.studies import gaze_study_main, head_studies_main

    where = ["--jobs", str(args.jobs)] if args.executor is None else ["--executor", args.executor]
    argv = ["--out", str(args.out), "--seed", str(args.seed), *where]
    if args.trials is not None:
        argv += ["--trials", str(args.trials)]
    if args.study == "hirsh":
        run, written = (lambda: hirsh_figures_main(argv)), "hirsh.json"
    elif args.study == "gaze":
        run, written = (lambda: gaze_study_main(argv)), "gaze.json"
    elif args.study in ("crlb", "robust"):
        run, written = (lambda: head_studies_main([args.study, *argv])), f"{args.study}.json"
    else:
        run, written = (lambda: shih_figures_main([args.study, *argv])), f"{args.study}.json"
    if not args.json:
        return run()
    with contextlib.redirect_stdout(io.StringIO()):
        code = run()
    print((Path(args.out) / written).read_text(encoding="utf-8"))
    return code


# -- kinfw crosscheck -------------------------------------------------------------------
def add_crosscheck_parser(sub: argparse._SubParsersAction) -> None:
    """The ``crosscheck`` sub-command."""
    p = sub.add_parser("crosscheck", help="check the CPC model against Pinocchio FK")
    p.add_argument("urdf", type=Path)
    p.add_argument("--frames", help="end frames, comma-separated (default: URDF hint)")
    p.add_argument("-n", type=COUNT, default=200, help="random configurations (default 200)")
    p.add_argument("--seed", type=SEED, default=0)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_crosscheck)


def cmd_crosscheck(args: argparse.Namespace) -> int:
    import numpy as np

    from kinfw.verification.evaluation import crosscheck_cpc

    robot = load_model(args.urdf, args)
    frames = frames_arg(
        args.frames, (*robot.default_frames, *robot.default_cameras), "--frames", robot
    )
    result = crosscheck_cpc(robot, frames, n=args.n, rng=np.random.default_rng(args.seed))
    if args.json:
        print(
            json.dumps(
                {
                    "urdf": str(args.urdf),
                    "frames": list(result.frames),
                    "n_configurations": result.n_configurations,
                    "numpy_position_m": result.numpy_position_m,
                    "numpy_rotation_rad": result.numpy_rotation_rad,
                    "casadi_position_m": result.casadi_position_m,
                    "casadi_rotation_rad": result.casadi_rotation_rad,
                    "passed": result.passed(),
                },
                indent=2,
            )
        )
    else:
        print(
            f"CPC vs Pinocchio FK of {args.urdf}, {result.n_configurations} random "
            f"configurations, frames {', '.join(result.frames)}"
        )
        print(
            f"  numpy : max position {result.numpy_position_m:.2e} m, "
            f"rotation {result.numpy_rotation_rad:.2e} rad"
        )
        print(
            f"  CasADi: max position {result.casadi_position_m:.2e} m, "
            f"rotation {result.casadi_rotation_rad:.2e} rad"
        )
        print("  passed (< 1e-12)" if result.passed() else "  FAILED (>= 1e-12)")
    return 0 if result.passed() else 1


# -- kinfw import-csv -------------------------------------------------------------------
def add_import_csv_parser(sub: argparse._SubParsersAction) -> None:
    """The ``import-csv`` sub-command."""
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
    add_xacro_option(p)
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
        "and the target's pose are estimated); needs --camera-frame; excludes --measured-in",
    )
    p.add_argument(
        "--camera-frame",
        default=None,
        help="with --target: the camera's own URDF link, on a fixed joint to --frame; its "
        "joint origin (the mount) is calibrated, --frame keeps its own. A name the URDF "
        'lacks is written as a mount on --frame ("mounts" in the file): calibrate adds the '
        "link and its fixed joint, and exports them",
    )
    p.add_argument("--length-unit", choices=("m", "mm"), default="m", help="default m")
    p.add_argument("--angle-unit", choices=("rad", "deg"), default="rad", help="default rad")
    add_payload_options(p, com_unit="in the --length-unit")
    p.add_argument("--out", type=Path, required=True, help="measurement file to write (JSON)")
    add_keep_duplicates_option(p)
    p.set_defaults(func=cmd_import_csv, check_outputs=check_import_csv_outputs)


def cmd_import_csv(args: argparse.Namespace) -> int:
    """``kinfw import-csv``: a FIGAROH calibration CSV to a measurement file."""
    from kinfw.measurements import (
        check_against_robot,
        drop_duplicate_samples,
        measurements_from_figaroh_csv,
        mounted_robot,
        write_measurements,
    )

    robot = load_model(args.urdf, args)
    measurements = measurements_from_figaroh_csv(
        args.csv,
        robot=robot,
        frame=args.frame,
        measured_in=args.measured_in,
        marker=args.marker,
        length_unit=args.length_unit,
        angle_unit=args.angle_unit,
        target=args.target,
        camera_frame=args.camera_frame,
    )
    measurements = with_payload(measurements, args, args.length_unit)
    check_against_robot(measurements, mounted_robot(robot, measurements.mounts))
    if not args.keep_duplicates:
        measurements = drop_duplicate_samples(measurements)
    write_measurements(args.out, measurements)
    kinds = ", ".join(
        f"{len(g.sample)} {type(g).kind} of {getattr(g, 'marker', None) or g.target!r}"
        for g in measurements.all_groups()
    )
    print(
        f"wrote {args.out}: {measurements.n_samples} samples, joints "
        f"{', '.join(measurements.joint_names)}; {kinds} on "
        f"{args.camera_frame if args.target is not None else args.frame!r}"
    )
    for name, mount in measurements.mounts.items():
        print(
            f"{name!r} is not in {args.urdf}: the file mounts it on {mount.parent!r} "
            "(calibrate adds it as a link on a fixed joint, calibrates and exports its origin)"
        )
    return 0


def check_view_outputs(args: argparse.Namespace) -> None:
    """``kinfw view --html``'s scene file, never one of the models, data or sidecar."""
    if args.html is None:
        return
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


def check_reproduce_outputs(args: argparse.Namespace) -> None:
    """``kinfw reproduce``'s output directory."""
    check_output_dir(args.out, label="--out")


def check_import_csv_outputs(args: argparse.Namespace) -> None:
    """``kinfw import-csv``'s measurement file, never the URDF or the CSV."""
    check_outputs({"--out": args.out}, inputs={"--urdf": args.urdf, "csv": args.csv})
