"""The commands of the ``kinfw`` command line that do not fit a model (the parser and
:func:`kinfw.cli.main` are in :mod:`kinfw.cli`; ``calibrate``, ``demo`` and ``crossval``
are in :mod:`kinfw.cli_fit`), and the helpers both command modules share.

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
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from kinfw.files import json_text, write_text_atomic

if TYPE_CHECKING:
    from kinfw.robot import Robot

__all__ = [
    "accuracy_table",
    "cmd_crosscheck",
    "cmd_import_csv",
    "cmd_reproduce",
    "cmd_simulate",
    "cmd_verify",
    "cmd_view",
    "default_sidecar_path",
    "format_table",
    "frames_arg",
    "progress_printer",
]

log = logging.getLogger("kinfw")


def progress_printer():
    """Progress lines on stderr when a person is watching (a terminal, or --verbose)."""
    if sys.stderr.isatty() or log.isEnabledFor(logging.INFO):
        return lambda message: print(f"  {message}", file=sys.stderr, flush=True)
    return None


def frames_arg(
    value: str | None, default: tuple[str, ...], flag: str, robot: Robot
) -> tuple[str, ...]:
    """The frames of a ``--frames`` / ``--cameras`` option (comma- or space-separated),
    else the URDF hint ``default``; ValueError naming ``flag`` and the links when
    neither is there."""
    if value:
        return tuple(v for v in value.replace(",", " ").split() if v)
    if default:
        return default
    raise ValueError(
        f"{robot.source}: give {flag} (comma-separated frame names); this URDF has no "
        f'<kinfw frames="..." cameras="..."/> hint. Links: {", ".join(robot.link_names)}'
    )


# -- kinfw simulate ----------------------------------------------------------------------
def _simulate_pixels(args, truth, cameras, names, lower, upper, rng, planned=None):
    """Stage 2 of ``kinfw simulate --pixels``: images of a fixed board by ``cameras``."""
    from kinfw.boards import Chessboard, parse_board
    from kinfw.camera_model import CameraError, read_camera
    from verification.simulate_pixels import (
        DEFAULT_BOARD,
        MIN_CORNERS,
        board_pose_facing,
        default_intrinsics,
        pixel_views,
        simulate_pixels,
    )

    board = parse_board(args.board or DEFAULT_BOARD)
    given = {}
    for frame, file in args.camera or ():
        if frame not in cameras:
            raise ValueError(
                f"--camera {frame}={file}: {frame!r} is not a stage 2 camera "
                f"(cameras: {', '.join(cameras)})"
            )
        try:
            given[frame] = read_camera(file)
        except CameraError as exc:
            raise ValueError(f"--camera {frame}={file}: {exc}") from None
    intrinsics = {c: given.get(c) or default_intrinsics(c) for c in cameras}
    min_corners = board.count if isinstance(board, Chessboard) else MIN_CORNERS
    if planned is not None:  # the plan's configurations; those where no camera sees dropped
        w_T_board = board_pose_facing(truth, 0.5 * (lower + upper), names, cameras, board.points)
        data, _ = simulate_pixels(
            truth,
            planned,
            names,
            cameras=intrinsics,
            board_p=board.points,
            w_T_board=w_T_board,
            rng=rng,
            sigma_px=args.pixel_sigma,
            min_corners=min_corners,
        )
        args.board_spec = board.spec()
        args.default_cameras = sorted(set(cameras) - set(given))
        return data
    data, _ = pixel_views(
        truth,
        names,
        lower,
        upper,
        args.stage2_samples,
        rng,
        cameras=intrinsics,
        board_p=board.points,
        sigma_px=args.pixel_sigma,
        fraction=args.fraction,
        min_corners=min_corners,
    )
    args.board_spec = board.spec()
    args.default_cameras = sorted(set(cameras) - set(given))
    return data


def _pixel_summary(data, args) -> dict:
    """The board and the images and corners per camera of ``--pixels`` data."""
    return {
        "board": args.board_spec,
        "sigma_px": args.pixel_sigma,
        "cameras": [
            {
                "camera": g.camera,
                "images": len(g.images()[0]),
                "points": len(g.sample),
                "default": g.camera in args.default_cameras,
            }
            for g in data.groups("pixels")
        ],
    }


def cmd_simulate(args: argparse.Namespace) -> int:
    import numpy as np

    from kinfw.measurements import concatenate_measurements, write_measurements
    from kinfw.robot import load_robot
    from verification.simulate import (
        default_target_pose,
        one_joint_at_a_time,
        perturb_robot,
        random_configurations,
        simulate,
    )

    nominal = load_robot(args.urdf)
    rng = np.random.default_rng(args.seed)
    if args.stage is None:  # --pixels are stage 2 images: with the stage 1 poses by default
        args.stage = "both" if args.pixels else "1"
    elif args.pixels and args.stage == "1":
        raise ValueError(
            "--pixels --stage 1: --pixels makes stage 2 images; give --stage 2 or both "
            "(the default with --pixels)"
        )
    stages = {"1": (1,), "2": (2,), "both": (1, 2)}[args.stage]
    frames = (
        frames_arg(args.frames, nominal.default_frames, "--frames", nominal) if 1 in stages else ()
    )
    cameras = (
        frames_arg(args.cameras, nominal.default_cameras, "--cameras", nominal)
        if 2 in stages
        else ()
    )
    truth_xml = perturb_robot(
        nominal, rng, origin_mm=args.error_mm, origin_deg=args.error_deg, axis_deg=args.error_deg
    )
    truth = load_robot(truth_xml)
    names = nominal.topology((*frames, *cameras)).joint_names
    lower, upper = nominal.joint_limits(names)
    noise = {"noise_m": args.noise_mm * 1e-3, "noise_rad": np.radians(args.noise_deg)}
    if args.stereo_mm is not None:
        noise["stereo_sigma_m"] = args.stereo_mm * 1e-3
    planned = _plan_qs(args.plan, names) if args.plan is not None else None
    parts = []
    if frames and planned is not None:
        parts.append(simulate(truth, planned, names, frames=frames, rng=rng, **noise))
    elif frames:
        qs, _ = one_joint_at_a_time(lower, upper, per_joint=args.per_joint, fraction=args.fraction)
        parts.append(simulate(truth, qs, names, frames=frames, rng=rng, **noise))
    if cameras and args.pixels:
        parts.append(_simulate_pixels(args, truth, cameras, names, lower, upper, rng, planned))
    elif cameras:
        qs = (
            planned
            if planned is not None
            else random_configurations(
                lower, upper, args.stage2_samples, rng, fraction=args.fraction
            )
        )
        w_T_target = default_target_pose(truth, qs, names, cameras)
        parts.append(
            simulate(truth, qs, names, cameras=cameras, rng=rng, w_T_target=w_T_target, **noise)
        )
    data = concatenate_measurements(*parts)
    write_measurements(args.out, data)
    write_text_atomic(args.truth_out, truth_xml)
    pixels = _pixel_summary(data, args) if args.pixels and cameras else None
    if args.json:
        print(
            json.dumps(
                {
                    "pixels": pixels,
                    "data": str(args.out),
                    "truth": str(args.truth_out),
                    "n_samples": data.n_samples,
                    "frames": list(data.observed_frames),
                    "noise_mm": args.noise_mm,
                    "noise_deg": args.noise_deg,
                    "stereo_mm": args.stereo_mm,
                    "error_mm": args.error_mm,
                    "error_deg": args.error_deg,
                    "seed": args.seed,
                },
                indent=2,
            )
        )
        return 0
    poses = bool(frames) or (bool(cameras) and not args.pixels)
    print(
        f"wrote {args.out}: {data.n_samples} samples of {', '.join(data.observed_frames)}"
        + (
            f" (noise {args.noise_mm} mm, {args.noise_deg} deg"
            + (f", stereo rig {args.stereo_mm} mm per point" if args.stereo_mm is not None else "")
            + ")"
            if poses
            else ""
        )
    )
    if pixels is not None:
        print(
            f"  stage 2 as images of {pixels['board']} (pixel noise {args.pixel_sigma:g} px): "
            + "; ".join(
                f"{c['camera']}: {c['images']} images, {c['points']} corners"
                + (" (default intrinsics: 640x480, fx = fy = 600 px)" if c["default"] else "")
                for c in pixels["cameras"]
            )
        )
    print(
        f"wrote {args.truth_out}: the true robot (nominal with errors of "
        f"{args.error_mm} mm / {args.error_deg} deg, seed {args.seed})"
    )
    return 0


def _plan_qs(path: Path, names: Sequence[str]) -> Any:
    """The configurations of a plan file in ``names`` order (every joint named)."""
    from verification.plan import read_plan

    plan_names, qs = read_plan(path)
    missing = [j for j in names if j not in plan_names]
    if missing:
        raise ValueError(f'{path}: "joint_names": missing the joints {missing}')
    return qs[:, [plan_names.index(j) for j in names]]


# -- kinfw verify ------------------------------------------------------------------------
def format_table(rows: Sequence[Sequence[str]], header: Sequence[str]) -> str:
    """Plain-text table: the header and the rows, each column right-aligned."""
    widths = [max(len(str(r[k])) for r in (header, *rows)) for k in range(len(header))]
    lines = ["  ".join(str(h).rjust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(str(c).rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(lines)


def accuracy_table(report_dict: dict) -> str:
    """Plain-text table of :meth:`verification.accuracy.AccuracyReport.to_dict`."""
    rows = []
    has_px = any("pixel_rms_px" in g for g in report_dict["groups"])

    def num(value, fmt: str) -> str:  # an undefined number (NaN, null) is "-"
        return "-" if value is None or value != value else format(value, fmt)

    for g in report_dict["groups"]:
        mu, sd = g["abs_mean_xyz_mm"], g["abs_std_xyz_mm"]
        table4 = " ".join(
            f"{m:.3f}/{s:.3f}" for m, s in zip(mu, sd, strict=True) if m == m and s == s
        )
        rows.append(
            [
                g["frame"] + (f" [{g['marker']}]" if g["marker"] else ""),
                g["kind"],
                g["n"],
                num(g["position_mean_mm"], ".3f"),
                num(g["position_rms_mm"], ".3f"),
                num(g["position_max_mm"], ".3f"),
                num(g["rotation_rms_deg"], ".4f"),
                num(g["rotation_max_deg"], ".4f"),
                table4 or "-",
                *([f"{g['pixel_rms_px']:.3g}"] if "pixel_rms_px" in g else ["-"] * has_px),
            ]
        )
    header = [
        "frame",
        "kind",
        "n",
        "pos mean mm",
        "pos RMS mm",
        "pos max mm",
        "rot RMS deg",
        "rot max deg",
        "|e| x y z mean/std mm (Table 4)",
        *(["pixel RMS px"] if has_px else []),
    ]
    return format_table(rows, header)


def read_data(path: Path, args: argparse.Namespace) -> Any:
    """The measurement file ``path`` with the intrinsics of ``--camera FRAME=FILE``
    (override or add to its ``"cameras"`` section)."""
    from kinfw.camera_model import CameraError, read_camera
    from kinfw.measurements import DatasetError, read_measurements

    cameras = {}
    given = getattr(args, "camera", None) or ()
    for frame, file in given:
        try:
            cameras[frame] = read_camera(file)
        except CameraError as exc:
            raise DatasetError(f"--camera {frame}={file}: {exc}") from None
    data = read_measurements(path, cameras=cameras)
    used = list(dict.fromkeys(g.camera for g in data.groups("pixels")))
    for frame, file in given:
        if frame not in used:
            has = (
                f"the camera frames of its 'pixels' observations: {', '.join(used)}"
                if used
                else "it has no 'pixels' observations"
            )
            raise DatasetError(
                f"--camera {frame}={file}: no observation of {path} uses camera frame "
                f"{frame!r} ({has})"
            )
    return data


def cmd_verify(args: argparse.Namespace) -> int:
    from kinfw.calibration_file import read_sidecar
    from kinfw.robot import load_robot
    from verification.accuracy import evaluate_model

    robot = load_robot(args.model)
    data = read_data(args.data, args)
    sidecar_path = args.sidecar or default_sidecar_path(args.model)
    sidecar = None
    if Path(sidecar_path).is_file() and not args.no_sidecar:
        sidecar = read_sidecar(sidecar_path)
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
    used = str(sidecar_path) if sidecar is not None else None
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


def default_sidecar_path(out: Path) -> Path:
    """Where the calibration sidecar of the calibrated URDF ``out`` goes."""
    return Path(out).with_suffix(".kinfw.json")


# -- kinfw view --------------------------------------------------------------------------
def cmd_view(args: argparse.Namespace) -> int:

    from kinfw.calibration_file import read_sidecar
    from kinfw.robot import load_robot
    from kinfw.view import OfflineWindow, scene, targets_from_sidecar, write_html

    if args.sample is not None and args.data is None:
        raise ValueError(f"--sample {args.sample}: give --data, the measurements to draw")
    nominal = load_robot(args.nominal)
    calibrated = load_robot(args.calibrated) if args.calibrated else None
    data = read_data(args.data, args) if args.data else None
    if args.sample is not None and not 0 <= args.sample < data.n_samples:
        raise ValueError(
            f"--sample {args.sample}: out of range, {args.data} has "
            f"{data.n_samples} samples (give 0 to {data.n_samples - 1})"
        )
    sidecar_path = args.sidecar
    if sidecar_path is None and args.calibrated:
        guess = Path(args.calibrated).with_suffix(".kinfw.json")
        sidecar_path = guess if guess.is_file() else None
    extra = {}
    if sidecar_path is not None:
        sidecar = read_sidecar(sidecar_path)
        extra = {"targets": targets_from_sidecar(sidecar), "meas_T_root": sidecar.w_T_root}
    up = args.up
    vis = scene(
        nominal,
        calibrated,
        data,
        sample=args.sample,
        residual_scale=args.residual_scale,
        up=up,
        package_dirs=tuple(args.package_dir),
        window=OfflineWindow() if args.html else None,
        **extra,
    )
    if args.html:
        path = write_html(vis, args.html)
        print(
            f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB, self-contained: open it in "
            "any browser, no network needed)"
        )
        return 0
    print(f"meshcat is serving the scene at {vis.url()} (127.0.0.1); press Enter to stop")
    with contextlib.suppress(EOFError, KeyboardInterrupt):
        input()
    return 0


# -- kinfw reproduce ---------------------------------------------------------------------
def cmd_reproduce(args: argparse.Namespace) -> int:
    import contextlib
    import io

    from verification import gaze_study, head_studies, hirsh_figures, shih_figures

    argv = ["--out", str(args.out), "--seed", str(args.seed), "--jobs", str(args.jobs)]
    if args.trials is not None:
        argv += ["--trials", str(args.trials)]
    if args.study == "hirsh":
        run, written = (lambda: hirsh_figures.main(argv)), "hirsh.json"
    elif args.study == "gaze":
        run, written = (lambda: gaze_study.main(argv)), "gaze.json"
    elif args.study in ("crlb", "robust"):
        run, written = (lambda: head_studies.main([args.study, *argv])), f"{args.study}.json"
    else:
        run, written = (lambda: shih_figures.main([args.study, *argv])), f"{args.study}.json"
    if not args.json:
        return run()
    with contextlib.redirect_stdout(io.StringIO()):
        code = run()
    print((Path(args.out) / written).read_text(encoding="utf-8"))
    return code


# -- kinfw crosscheck --------------------------------------------------------------------
def cmd_crosscheck(args: argparse.Namespace) -> int:
    import numpy as np

    from kinfw.robot import load_robot
    from verification.crosscheck import crosscheck_cpc

    robot = load_robot(args.urdf)
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


# -- kinfw import-csv --------------------------------------------------------------------
def cmd_import_csv(args: argparse.Namespace) -> int:
    """``kinfw import-csv``: a FIGAROH calibration CSV to a measurement file."""
    from kinfw.figaroh_csv import measurements_from_figaroh_csv
    from kinfw.measurements import check_against_robot, write_measurements
    from kinfw.robot import load_robot

    robot = load_robot(args.urdf)
    measurements = measurements_from_figaroh_csv(
        args.csv,
        robot=robot,
        frame=args.frame,
        measured_in=args.measured_in,
        marker=args.marker,
        length_unit=args.length_unit,
        angle_unit=args.angle_unit,
        target=args.target,
    )
    check_against_robot(measurements, robot)
    write_measurements(args.out, measurements)
    kinds = ", ".join(
        f"{len(g.sample)} {type(g).kind} of {getattr(g, 'marker', None) or g.target!r}"
        for g in measurements.all_groups()
    )
    print(
        f"wrote {args.out}: {measurements.n_samples} samples, joints "
        f"{', '.join(measurements.joint_names)}; {kinds} on {args.frame!r}"
    )
    return 0
