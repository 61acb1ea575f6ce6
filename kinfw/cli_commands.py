"""The commands of the ``kinfw`` command line (the parser and :func:`kinfw.cli.main` are
in :mod:`kinfw.cli`).

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
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from kinfw.files import write_text_atomic

if TYPE_CHECKING:
    from kinfw.calibration_file import BeforeAfter
    from kinfw.calibration_report import RefineSection, StageErrors
    from kinfw.robot import Robot

__all__ = [
    "accuracy_table",
    "cmd_calibrate",
    "cmd_crosscheck",
    "cmd_crossval",
    "cmd_demo",
    "cmd_import_csv",
    "cmd_reproduce",
    "cmd_simulate",
    "cmd_verify",
    "cmd_view",
    "default_sidecar_path",
]

log = logging.getLogger("kinfw")


def _progress_printer():
    """Progress lines on stderr when a person is watching (a terminal, or --verbose)."""
    if sys.stderr.isatty() or log.isEnabledFor(logging.INFO):
        return lambda message: print(f"  {message}", file=sys.stderr, flush=True)
    return None


def _frames_arg(
    value: str | None, default: tuple[str, ...], flag: str, robot: Robot
) -> tuple[str, ...]:
    if value:
        return tuple(v for v in value.replace(",", " ").split() if v)
    if default:
        return default
    raise ValueError(
        f"{robot.source}: give {flag} (comma-separated frame names); this URDF has no "
        f'<kinfw frames="..." cameras="..."/> hint. Links: {", ".join(robot.link_names)}'
    )


# -- kinfw simulate ----------------------------------------------------------------------
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
    stages = {"1": (1,), "2": (2,), "both": (1, 2)}[args.stage]
    frames = (
        _frames_arg(args.frames, nominal.default_frames, "--frames", nominal) if 1 in stages else ()
    )
    cameras = (
        _frames_arg(args.cameras, nominal.default_cameras, "--cameras", nominal)
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
    parts = []
    if frames:
        qs, _ = one_joint_at_a_time(lower, upper, per_joint=args.per_joint, fraction=args.fraction)
        parts.append(simulate(truth, qs, names, frames=frames, rng=rng, **noise))
    if cameras:
        qs = random_configurations(lower, upper, args.stage2_samples, rng, fraction=args.fraction)
        w_T_target = default_target_pose(truth, qs, names, cameras)
        parts.append(
            simulate(truth, qs, names, cameras=cameras, rng=rng, w_T_target=w_T_target, **noise)
        )
    data = concatenate_measurements(*parts)
    write_measurements(args.out, data)
    write_text_atomic(args.truth_out, truth_xml)
    if args.json:
        print(
            json.dumps(
                {
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
    print(
        f"wrote {args.out}: {data.n_samples} samples of {', '.join(data.observed_frames)} "
        f"(noise {args.noise_mm} mm, {args.noise_deg} deg"
        + (f", stereo rig {args.stereo_mm} mm per point" if args.stereo_mm is not None else "")
        + ")"
    )
    print(
        f"wrote {args.truth_out}: the true robot (nominal with errors of "
        f"{args.error_mm} mm / {args.error_deg} deg, seed {args.seed})"
    )
    return 0


# -- kinfw verify ------------------------------------------------------------------------
def _format_table(rows: Sequence[Sequence[str]], header: Sequence[str]) -> str:
    widths = [max(len(str(r[k])) for r in (header, *rows)) for k in range(len(header))]
    lines = ["  ".join(str(h).rjust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(str(c).rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(lines)


def accuracy_table(report_dict: dict) -> str:
    """Plain-text table of :meth:`verification.accuracy.AccuracyReport.to_dict`."""
    rows = []
    for g in report_dict["groups"]:
        mu, sd = g["abs_mean_xyz_mm"], g["abs_std_xyz_mm"]
        rows.append(
            [
                g["frame"] + (f" [{g['marker']}]" if g["marker"] else ""),
                g["kind"],
                g["n"],
                f"{g['position_mean_mm']:.3f}",
                f"{g['position_rms_mm']:.3f}",
                f"{g['position_max_mm']:.3f}",
                f"{g['rotation_rms_deg']:.4f}",
                f"{g['rotation_max_deg']:.4f}",
                " ".join(f"{m:.3f}/{s:.3f}" for m, s in zip(mu, sd, strict=True)),
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
    ]
    return _format_table(rows, header)


def cmd_verify(args: argparse.Namespace) -> int:
    from kinfw.calibration_file import read_sidecar
    from kinfw.measurements import read_measurements
    from kinfw.robot import load_robot
    from verification.accuracy import evaluate_model

    robot = load_robot(args.model)
    data = read_measurements(args.data)
    sidecar_path = args.sidecar or default_sidecar_path(args.model)
    sidecar = None
    if Path(sidecar_path).is_file() and not args.no_sidecar:
        sidecar = read_sidecar(sidecar_path)
    elif args.sidecar:
        raise OSError(f"{args.sidecar}: sidecar not found")
    report = evaluate_model(robot, data, sidecar=sidecar)
    used = str(sidecar_path) if sidecar is not None else None
    if args.json:
        print(
            json.dumps(
                {
                    "model": str(args.model),
                    "data": str(args.data),
                    "sidecar": used,
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
    for note in report.fitted:
        print(f"note: fitted from the data: {note}")
    return 0


# -- kinfw calibrate ---------------------------------------------------------------------
def _before_after_table(rows: Sequence[BeforeAfter]) -> str:
    return _format_table(
        [
            [
                r.group,
                r.n,
                f"{r.before_position_rms_mm:.3f}",
                f"{r.after_position_rms_mm:.3f}",
                f"{r.before_rotation_rms_deg:.4f}",
                f"{r.after_rotation_rms_deg:.4f}",
            ]
            for r in rows
        ],
        ["frame", "n", "before RMS mm", "after RMS mm", "before RMS deg", "after RMS deg"],
    )


def _stage_table(stages: Sequence[StageErrors]) -> str:
    rms = {s.stage: dict(s.position_rms_mm) for s in stages}
    groups = [g for g, _ in stages[0].position_rms_mm]
    return _format_table(
        [[g, *(f"{rms[s.stage][g]:.3f}" for s in stages)] for g in groups],
        ["position RMS mm", *rms],
    )


def _params_arg(text: str) -> str | tuple[str, ...]:
    """``full``, ``offsets``, ``frames``, ``none``, or a comma-separated mask."""
    if text in ("full", "offsets", "frames", "none"):
        return text
    return tuple(t for t in text.replace(" ", "").split(",") if t)


def _prior_arg(args: argparse.Namespace):
    if args.prior_mm is None and args.prior_deg is None:
        return None
    if args.prior_mm is None or args.prior_deg is None:
        raise ValueError("give both --prior-mm and --prior-deg")
    return args.prior_mm * 1e-3, math.radians(args.prior_deg)


def _noise_arg(args: argparse.Namespace):
    from identification.refine import NoiseModel

    if args.sigma_mm is None and args.sigma_deg is None:
        return None
    if args.sigma_mm is None or args.sigma_deg is None:
        raise ValueError(
            "give both --sigma-mm and --sigma-deg, or neither (then the noise "
            "is estimated from the residuals)"
        )
    # an angle sigma about a random axis is sigma / sqrt(3) per orientation component
    return NoiseModel(args.sigma_mm * 1e-3, math.radians(args.sigma_deg) / math.sqrt(3.0))


def default_sidecar_path(out: Path) -> Path:
    """Where the calibration sidecar of the calibrated URDF ``out`` goes."""
    return Path(out).with_suffix(".kinfw.json")


def cmd_calibrate(args: argparse.Namespace) -> int:
    from kinfw.calibration_report import write_report
    from kinfw.measurements import read_measurements
    from kinfw.robot import load_robot
    from verification.report import calibrate_to_files

    nominal = load_robot(args.urdf)
    data = read_measurements(args.data)
    held_out = read_measurements(args.holdout) if args.holdout else None
    noise, prior = _noise_arg(args), _prior_arg(args)
    choice = None
    parameters = "full" if args.params == "auto" else _params_arg(args.params)
    if args.params == "auto" and args.method == "refine":
        from verification.model_choice import choose_parameters

        choice = choose_parameters(nominal, data, noise=noise, loss=args.loss, prior=prior)
        parameters, prior = choice.parameters, choice.prior
    report, _ = calibrate_to_files(
        nominal,
        data,
        args.out,
        method=args.method,
        noise=noise,
        loss=args.loss,
        parameters=parameters,
        prior=prior,
        data_path=args.data,
        held_out=held_out,
        progress=_progress_printer(),
    )
    if choice is not None:  # the choice goes to the report's notes
        report = dataclasses.replace(
            report, notes=(*report.notes, f"parameters: {choice.label} ({choice.reason})")
        )
    if args.report:
        write_report(args.report, report)
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
        return 0
    print(
        f"calibrated {args.urdf} with {args.method} from {args.data} "
        f"({data.n_samples} samples) -> {args.out} (+ {report.sidecar})"
    )
    for note in report.notes:
        print(f"note: {note}")
    if choice is not None and choice.candidates:
        print(f"model choice: {choice.k}-fold held-out error of each candidate:")
        print(_choice_table(choice))
    print("position RMS on the calibration data after each stage (in-sample):")
    print(_stage_table(report.position_rms_by_stage))
    if report.refine is not None:
        _print_refine(report.refine, has_report=bool(args.report))
    if report.errors_held_out is not None:
        print("held-out errors:")
        print(_before_after_table(report.errors_held_out))
    if args.report:
        print(f"report: {args.report}")
    return 0


def _choice_table(choice) -> str:
    """The candidates of a model choice with their held-out scores, the chosen marked."""
    head = f"  {'candidate':<32} {'whitened':>9} {'pos mm':>8} {'rot deg':>8}"
    rows = [head]
    for c in choice.candidates:
        mark = " <- chosen" if (c.parameters, c.prior) == (choice.parameters, choice.prior) else ""
        rot = "-" if math.isnan(c.rotation_rms_deg) else f"{c.rotation_rms_deg:.3g}"
        rows.append(f"  {c.label:<32} {c.whitened:>9.3g} {c.position_rms_mm:>8.3g} {rot:>8}{mark}")
    return "\n".join(rows)


def _sigma(value: float | None, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def _print_refine(ref: RefineSection, *, has_report: bool) -> None:
    """The refinement's summary: noise, fit, rank, fixed and unidentifiable parameters,
    the worst down-weighted observations."""
    ident = ref.identifiability
    if ident.condition is not None:
        condition = f"condition {ident.condition:.3g}"
    else:  # null in the report: no free parameters, or a rank-deficient problem
        condition = "condition undefined" if not ident.n_parameters else "condition inf"
    noise = ref.noise
    print(
        f"refine: noise sigma {_sigma(noise.position_sigma_mm, '.3g')} mm, "
        f"{_sigma(noise.rotation_sigma_deg_per_component, '.3g')} deg per component "
        f"({'estimated' if noise.estimated else 'given'}); reduced chi-square "
        f"{ref.reduced_chi_square:.3g}; rank {ident.rank}/{ident.n_parameters}, " + condition
    )
    print(
        f"  parameters: {len(ref.parameters) - ref.n_fixed} estimated, {ref.n_fixed} fixed "
        "(not estimated; std null in the report)"
    )
    for item in ident.not_identifiable:
        print(f"  not identifiable: {', '.join(item.parameters)}: {item.why}")
    for row in ref.rejected or ():
        where = row.frame + (f" marker {row.marker}" if row.marker else "")
        sizes = [
            f"{v:.3g} {unit}"
            for v, unit in ((row.position_residual_mm, "mm"), (row.rotation_residual_deg, "deg"))
            if v is not None
        ]
        print(
            f"  rejected as a gross error: samples[{row.sample}] {where} ({row.kind}): "
            f"residual {', '.join(sizes)}, {row.excess:.3g} x the threshold (refitted without it)"
        )
    if ref.rejection_note:
        print(f"  warning: {ref.rejection_note}")
    down = ref.downweighted
    if down:
        print(f"  {len(down)} observations down-weighted by the {ref.loss} loss, worst first:")
    for row in down[:5]:
        where = row.frame + (f" marker {row.marker}" if row.marker else "")
        rotation = (
            "" if row.rotation_residual_deg is None else f", {row.rotation_residual_deg:.3g} deg"
        )
        print(
            f"    samples[{row.sample}] {where} ({row.kind}): residual "
            f"{row.position_residual_mm:.3g} mm{rotation}, weight {row.weight:.2g}"
        )
    if len(down) > 5:
        print(
            f"    ... and {len(down) - 5} more "
            f"({'see the report' if has_report else 'write them with --report'})"
        )


# -- kinfw demo --------------------------------------------------------------------------
def cmd_demo(args: argparse.Namespace) -> int:
    from verification.demo import NOISE_DEG, NOISE_MM, run_demo

    demo = run_demo(args.out, seed=args.seed, progress=_progress_printer())
    report = demo.report
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
        return 0
    out = demo.out
    print("kinfw demo: the IIS-head experiment of Shih et al. (1992) in simulation")
    print(
        f"  true robot = built-in URDF with 5 mm / 1 deg errors (seed {args.seed}); stage 1: "
        f"{demo.n_stage1} one-joint-at-a-time configurations (9 per joint), plate poses from "
        "the stereo rig; stage 2: both cameras see a fixed target in 30 random "
        f"configurations; noise sigma {NOISE_MM:g} mm / {NOISE_DEG:g} deg; closed form, "
        "A = X B Y, then the joint least squares; 100 held-out configurations"
    )
    print("\nheld-out position RMS against the true robot (noise-free), mm, after each stage:")
    print(_stage_table(report.position_rms_vs_truth_held_out_by_stage))
    print("\nheld-out errors against noisy measurements (targets: camera_T_target):")
    print(_before_after_table(report.errors_held_out))
    noise = report.refine.noise
    print(
        f"\nestimated noise: {noise.position_sigma_mm:.3f} mm per axis, "
        f"{noise.rotation_sigma_deg_per_component:.3f} deg per orientation "
        f"component (true: {NOISE_MM:g} mm, {NOISE_DEG / math.sqrt(3.0):.3f} deg)"
    )
    print(
        f"wrote {out / 'calibrated.urdf'} (+ {report.sidecar}), {out / 'report.json'} "
        f"and the data ({out / 'data.json'}, {out / 'held_out.json'}, {out / 'true.urdf'})"
    )
    print(
        f"plot: {out / 'errors.png'}; 3D view (nominal grey, calibrated blue, residuals x30): "
        f"{out / 'scene.html'} (open in any browser, no network needed)"
    )
    return 0


# -- kinfw crossval ----------------------------------------------------------------------
def cmd_crossval(args: argparse.Namespace) -> int:
    import numpy as np

    from kinfw.measurements import read_measurements
    from kinfw.robot import load_robot
    from verification.crossval import BASELINES, crossvalidate
    from verification.studies import executor_for_jobs

    nominal = load_robot(args.urdf)
    data = read_measurements(args.data)
    sets = ("none", "frames", "offsets", "full") if args.select else BASELINES
    prior = _prior_arg(args)
    watch = _progress_printer()
    executor = executor_for_jobs(args.jobs)
    try:
        cv = crossvalidate(
            nominal,
            data,
            k=args.k,
            seed=args.seed,
            sets=sets,
            select=args.select,
            noise=_noise_arg(args),
            loss=args.loss,
            prior=prior,
            executor=executor,
            progress=(lambda d, t: watch(f"{d}/{t} fits")) if watch else None,
            exclude_flagged=args.exclude_flagged,
        )
    finally:
        if executor is not None:
            executor.shutdown()
    if args.json:
        print(json.dumps(cv.to_dict(), indent=2))
        return 0
    label = {
        "none": "nominal",
        "frames": "frames only",
        "offsets": "offsets+frames",
        "full": "calibrated",
    }
    print(
        f"{args.k}-fold cross-validation of {args.data} ({data.n_samples} samples, folds "
        f"by sample, seed {args.seed}): held-out RMS, position mm / orientation deg"
    )

    def cell(position_mm: float, rotation_deg: float) -> str:
        rot = "-" if np.isnan(rotation_deg) else f"{rotation_deg:.3f}"
        return f"{position_mm:.3f} / {rot}"

    rows = []
    for fold in range(args.k):
        row = [fold, next(s.n_test for s in cv.scores if s.fold == fold)]
        for p in sets:
            sc = next(s for s in cv.scores if s.fold == fold and s.parameters == p)
            row.append(cell(sc.position_rms_mm, sc.rotation_rms_deg))
        rows.append(row)
    rows.append(["mean", "", *(cell(cv.mean(p), cv.mean(p, "rotation_rms_deg")) for p in sets)])
    print(_format_table(rows, ["fold", "n test", *(label[p] for p in sets)]))
    if args.exclude_flagged:
        print(
            f"excluded from scoring: {len(cv.excluded)} observations the full-data fit "
            f"rejected as gross errors" + (":" if cv.excluded else "")
        )
        for sample, kind, frame, marker in cv.excluded:
            where = frame + (f" marker {marker}" if marker else "")
            print(f"  samples[{sample}] {where} ({kind})")
    for warning in cv.warnings:
        print(f"warning: {warning}")
    if cv.selected:
        sp, sr = cv.noise
        print(
            f"selected: {label[cv.selected]} ({cv.selected!r}), the lowest mean held-out "
            f"error whitened by the noise ({sp * 1e3:.3g} mm, {np.degrees(sr):.3g} deg per "
            f"component): {cv.mean(cv.selected):.3f} mm / "
            f"{cv.mean(cv.selected, 'rotation_rms_deg'):.3f} deg, whitened "
            f"{cv.whitened(cv.selected):.3g}"
        )
    return 0


# -- kinfw view --------------------------------------------------------------------------
def cmd_view(args: argparse.Namespace) -> int:

    from kinfw.calibration_file import read_sidecar
    from kinfw.measurements import read_measurements
    from kinfw.robot import load_robot
    from kinfw.view import OfflineWindow, scene, targets_from_sidecar, write_html

    if args.sample is not None and args.data is None:
        raise ValueError(f"--sample {args.sample}: give --data, the measurements to draw")
    nominal = load_robot(args.nominal)
    calibrated = load_robot(args.calibrated) if args.calibrated else None
    data = read_measurements(args.data) if args.data else None
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

    from verification import head_studies, hirsh_figures, shih_figures

    argv = ["--out", str(args.out), "--seed", str(args.seed), "--jobs", str(args.jobs)]
    if args.trials is not None:
        argv += ["--trials", str(args.trials)]
    if args.study == "hirsh":
        run, written = (lambda: hirsh_figures.main(argv)), "hirsh.json"
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
    frames = _frames_arg(
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
    )
    check_against_robot(measurements, robot)
    write_measurements(args.out, measurements)
    kinds = ", ".join(
        f"{len(g.sample)} {type(g).kind} of {g.marker!r}" for g in measurements.all_groups()
    )
    print(
        f"wrote {args.out}: {measurements.n_samples} samples, joints "
        f"{', '.join(measurements.joint_names)}; {kinds} on {args.frame!r}"
    )
    return 0
