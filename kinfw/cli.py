"""The ``kinfw`` command line: the one place that wires kinfw, identification and
verification together.

Exit codes: 0 on success, 2 on bad input (one line on stderr saying what and where,
never a traceback for a user error), 1 on an unexpected internal error. Warnings (Python
warnings and logged ones) are printed once each, as one line ``kinfw CMD: warning: ...``.

Every output path is checked before any work (:func:`_check_outputs`) and every file is
written atomically (:mod:`kinfw.files`). This module imports only the standard library at
start-up, so that ``kinfw --help`` and argument errors are immediate: numpy, Pinocchio
(through :mod:`kinfw.robot`), CasADi, matplotlib and meshcat are imported by the commands.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import math
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from kinfw.files import check_output_dir, check_outputs, write_text_atomic

if TYPE_CHECKING:
    from kinfw.calibration_file import BeforeAfter
    from kinfw.calibration_report import RefineSection, StageErrors
    from kinfw.robot import Robot

__all__ = ["main"]

log = logging.getLogger("kinfw")

#: Errors that are the user's input, not a bug: reported on one line, exit code 2.
#: ``kinfw.measurements.DatasetError``, ``kinfw.robot.RobotModelError`` and
#: ``kinfw.files.OutputPathError`` are ValueErrors (caught here without importing them).
USER_ERRORS = (ValueError, OSError)


def _progress_printer():
    """Progress lines on stderr when a person is watching (a terminal, or --verbose)."""
    if sys.stderr.isatty() or log.isEnabledFor(logging.INFO):
        return lambda message: print(f"  {message}", file=sys.stderr, flush=True)
    return None


def _frames_arg(value: str | None, default: tuple[str, ...], flag: str, robot: Robot
                ) -> tuple[str, ...]:
    if value:
        return tuple(v for v in value.replace(",", " ").split() if v)
    if default:
        return default
    raise ValueError(
        f"{robot.source}: give {flag} (comma-separated frame names); this URDF has no "
        f'<kinfw frames="..." cameras="..."/> hint. Links: {", ".join(robot.link_names)}')


# -- kinfw simulate ----------------------------------------------------------------------
def _cmd_simulate(args: argparse.Namespace) -> int:
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
    frames = _frames_arg(args.frames, nominal.default_frames, "--frames", nominal) \
        if 1 in stages else ()
    cameras = _frames_arg(args.cameras, nominal.default_cameras, "--cameras", nominal) \
        if 2 in stages else ()
    truth_xml = perturb_robot(nominal, rng, origin_mm=args.error_mm, origin_deg=args.error_deg,
                              axis_deg=args.error_deg)
    truth = load_robot(truth_xml)
    names = nominal.topology((*frames, *cameras)).joint_names
    lower, upper = nominal.joint_limits(names)
    noise = {"noise_m": args.noise_mm * 1e-3, "noise_rad": np.radians(args.noise_deg)}
    if args.stereo_mm is not None:
        noise["stereo_sigma_m"] = args.stereo_mm * 1e-3
    parts = []
    if frames:
        qs, _ = one_joint_at_a_time(lower, upper, per_joint=args.per_joint,
                                    fraction=args.fraction)
        parts.append(simulate(truth, qs, names, frames=frames, rng=rng, **noise))
    if cameras:
        qs = random_configurations(lower, upper, args.stage2_samples, rng,
                                   fraction=args.fraction)
        w_T_target = default_target_pose(truth, qs, names, cameras)
        parts.append(simulate(truth, qs, names, cameras=cameras, rng=rng,
                              w_T_target=w_T_target, **noise))
    data = concatenate_measurements(*parts)
    write_measurements(args.out, data)
    write_text_atomic(args.truth_out, truth_xml)
    if args.json:
        print(json.dumps({"data": str(args.out), "truth": str(args.truth_out),
                          "n_samples": data.n_samples, "frames": list(data.observed_frames),
                          "noise_mm": args.noise_mm, "noise_deg": args.noise_deg,
                          "stereo_mm": args.stereo_mm, "error_mm": args.error_mm,
                          "error_deg": args.error_deg, "seed": args.seed}, indent=2))
        return 0
    print(f"wrote {args.out}: {data.n_samples} samples of {', '.join(data.observed_frames)} "
          f"(noise {args.noise_mm} mm, {args.noise_deg} deg"
          + (f", stereo rig {args.stereo_mm} mm per point" if args.stereo_mm is not None else "")
          + ")")
    print(f"wrote {args.truth_out}: the true robot (nominal with errors of "
          f"{args.error_mm} mm / {args.error_deg} deg, seed {args.seed})")
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
        rows.append([
            g["frame"] + (f" [{g['marker']}]" if g["marker"] else ""), g["kind"], g["n"],
            f"{g['position_mean_mm']:.3f}", f"{g['position_rms_mm']:.3f}",
            f"{g['position_max_mm']:.3f}", f"{g['rotation_rms_deg']:.4f}",
            f"{g['rotation_max_deg']:.4f}",
            " ".join(f"{m:.3f}/{s:.3f}" for m, s in zip(mu, sd, strict=True)),
        ])
    header = ["frame", "kind", "n", "pos mean mm", "pos RMS mm", "pos max mm",
              "rot RMS deg", "rot max deg", "|e| x y z mean/std mm (Table 4)"]
    return _format_table(rows, header)


def _cmd_verify(args: argparse.Namespace) -> int:
    from kinfw.calibration_file import read_sidecar
    from kinfw.measurements import read_measurements
    from kinfw.robot import load_robot
    from verification.accuracy import evaluate_model

    robot = load_robot(args.model)
    data = read_measurements(args.data)
    sidecar_path = args.sidecar or _sidecar_path(args.model)
    sidecar = None
    if Path(sidecar_path).is_file() and not args.no_sidecar:
        sidecar = read_sidecar(sidecar_path)
    elif args.sidecar:
        raise OSError(f"{args.sidecar}: sidecar not found")
    report = evaluate_model(robot, data, sidecar=sidecar)
    used = str(sidecar_path) if sidecar is not None else None
    if args.json:
        print(json.dumps({"model": str(args.model), "data": str(args.data), "sidecar": used,
                          **report.to_dict(per_sample=True)}, indent=2))
        return 0
    print(f"errors of {args.model} against {args.data} ({data.n_samples} samples; "
          "measured minus predicted)")
    if used:
        print(f"using the calibration sidecar {used} (measurement frame, targets, markers "
              "as calibrated, not refitted)")
    print(accuracy_table(report.to_dict()))
    for note in report.fitted:
        print(f"note: fitted from the data: {note}")
    return 0


# -- kinfw calibrate ---------------------------------------------------------------------
def _before_after_table(rows: Sequence[BeforeAfter]) -> str:
    return _format_table(
        [[r.group, r.n, f"{r.before_position_rms_mm:.3f}", f"{r.after_position_rms_mm:.3f}",
          f"{r.before_rotation_rms_deg:.4f}", f"{r.after_rotation_rms_deg:.4f}"]
         for r in rows],
        ["frame", "n", "before RMS mm", "after RMS mm", "before RMS deg", "after RMS deg"])


def _stage_table(stages: Sequence[StageErrors]) -> str:
    rms = {s.stage: dict(s.position_rms_mm) for s in stages}
    groups = [g for g, _ in stages[0].position_rms_mm]
    return _format_table([[g, *(f"{rms[s.stage][g]:.3f}" for s in stages)] for g in groups],
                         ["position RMS mm", *rms])


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
        raise ValueError("give both --sigma-mm and --sigma-deg, or neither (then the noise "
                         "is estimated from the residuals)")
    # an angle sigma about a random axis is sigma / sqrt(3) per orientation component
    return NoiseModel(args.sigma_mm * 1e-3, math.radians(args.sigma_deg) / math.sqrt(3.0))


def _sidecar_path(out: Path) -> Path:
    """Where the calibration sidecar of the calibrated URDF ``out`` goes."""
    return Path(out).with_suffix(".kinfw.json")


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from kinfw.calibration_report import write_report
    from kinfw.measurements import read_measurements
    from kinfw.robot import load_robot
    from verification.report import calibrate_to_files

    nominal = load_robot(args.urdf)
    data = read_measurements(args.data)
    held_out = read_measurements(args.holdout) if args.holdout else None
    report, _ = calibrate_to_files(nominal, data, args.out, method=args.method,
                                   noise=_noise_arg(args), loss=args.loss,
                                   parameters=_params_arg(args.params),
                                   prior=_prior_arg(args), data_path=args.data,
                                   held_out=held_out, progress=_progress_printer())
    if args.report:
        write_report(args.report, report)
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
        return 0
    print(f"calibrated {args.urdf} with {args.method} from {args.data} "
          f"({data.n_samples} samples) -> {args.out} (+ {report.sidecar})")
    for note in report.notes:
        print(f"note: {note}")
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
    print(f"refine: noise sigma {_sigma(noise.position_sigma_mm, '.3g')} mm, "
          f"{_sigma(noise.rotation_sigma_deg_per_component, '.3g')} deg per component "
          f"({'estimated' if noise.estimated else 'given'}); reduced chi-square "
          f"{ref.reduced_chi_square:.3g}; rank {ident.rank}/{ident.n_parameters}, "
          + condition)
    print(f"  parameters: {len(ref.parameters) - ref.n_fixed} estimated, {ref.n_fixed} fixed "
          "(not estimated; std null in the report)")
    for item in ident.not_identifiable:
        print(f"  not identifiable: {', '.join(item.parameters)}: {item.why}")
    down = ref.downweighted
    if down:
        print(f"  {len(down)} observations down-weighted by the {ref.loss} loss, "
              "worst first:")
    for row in down[:5]:
        where = row.frame + (f" marker {row.marker}" if row.marker else "")
        rotation = ("" if row.rotation_residual_deg is None
                    else f", {row.rotation_residual_deg:.3g} deg")
        print(f"    samples[{row.sample}] {where} ({row.kind}): residual "
              f"{row.position_residual_mm:.3g} mm{rotation}, weight {row.weight:.2g}")
    if len(down) > 5:
        print(f"    ... and {len(down) - 5} more "
              f"({'see the report' if has_report else 'write them with --report'})")


# -- kinfw demo --------------------------------------------------------------------------
def _cmd_demo(args: argparse.Namespace) -> int:
    from verification.demo import NOISE_DEG, NOISE_MM, run_demo

    demo = run_demo(args.out, seed=args.seed, progress=_progress_printer())
    report = demo.report
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
        return 0
    out = demo.out
    print("kinfw demo: the IIS-head experiment of Shih et al. (1992) in simulation")
    print(f"  true robot = built-in URDF with 5 mm / 1 deg errors (seed {args.seed}); stage 1: "
          f"{demo.n_stage1} one-joint-at-a-time configurations (9 per joint), plate poses from "
          "the stereo rig; stage 2: both cameras see a fixed target in 30 random "
          f"configurations; noise sigma {NOISE_MM:g} mm / {NOISE_DEG:g} deg; closed form, "
          "A = X B Y, then the joint least squares; 100 held-out configurations")
    print("\nheld-out position RMS against the true robot (noise-free), mm, after each stage:")
    print(_stage_table(report.position_rms_vs_truth_held_out_by_stage))
    print("\nheld-out errors against noisy measurements (targets: camera_T_target):")
    print(_before_after_table(report.errors_held_out))
    noise = report.refine.noise
    print(f"\nestimated noise: {noise.position_sigma_mm:.3f} mm per axis, "
          f"{noise.rotation_sigma_deg_per_component:.3f} deg per orientation "
          f"component (true: {NOISE_MM:g} mm, {NOISE_DEG / math.sqrt(3.0):.3f} deg)")
    print(f"wrote {out / 'calibrated.urdf'} (+ {report.sidecar}), {out / 'report.json'} "
          f"and the data ({out / 'data.json'}, {out / 'held_out.json'}, {out / 'true.urdf'})")
    print(f"plot: {out / 'errors.png'}; 3D view (nominal grey, calibrated blue, residuals x30): "
          f"{out / 'scene.html'} (open in any browser, no network needed)")
    return 0


# -- kinfw crossval ----------------------------------------------------------------------
def _cmd_crossval(args: argparse.Namespace) -> int:
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
        cv = crossvalidate(nominal, data, k=args.k, seed=args.seed, sets=sets,
                           select=args.select, noise=_noise_arg(args), loss=args.loss,
                           prior=prior, executor=executor,
                           progress=(lambda d, t: watch(f"{d}/{t} fits")) if watch else None)
    finally:
        if executor is not None:
            executor.shutdown()
    if args.json:
        print(json.dumps(cv.to_dict(), indent=2))
        return 0
    label = {"none": "nominal", "frames": "frames only", "offsets": "offsets+frames",
             "full": "calibrated"}
    print(f"{args.k}-fold cross-validation of {args.data} ({data.n_samples} samples, folds "
          f"by sample, seed {args.seed}): held-out RMS, position mm / orientation deg")
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
    rows.append(["mean", "", *(cell(cv.mean(p), cv.mean(p, "rotation_rms_deg"))
                               for p in sets)])
    print(_format_table(rows, ["fold", "n test", *(label[p] for p in sets)]))
    for warning in cv.warnings:
        print(f"warning: {warning}")
    if cv.selected:
        print(f"selected: {label[cv.selected]} ({cv.selected!r}), the lowest mean held-out "
              f"position error ({cv.mean(cv.selected):.3f} mm)")
    return 0


# -- kinfw view --------------------------------------------------------------------------
def _cmd_view(args: argparse.Namespace) -> int:

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
        raise ValueError(f"--sample {args.sample}: out of range, {args.data} has "
                         f"{data.n_samples} samples (give 0 to {data.n_samples - 1})")
    sidecar_path = args.sidecar
    if sidecar_path is None and args.calibrated:
        guess = Path(args.calibrated).with_suffix(".kinfw.json")
        sidecar_path = guess if guess.is_file() else None
    extra = {}
    if sidecar_path is not None:
        sidecar = read_sidecar(sidecar_path)
        extra = {"targets": targets_from_sidecar(sidecar), "meas_T_root": sidecar.w_T_root}
    up = args.up
    vis = scene(nominal, calibrated, data, sample=args.sample, residual_scale=args.residual_scale,
                up=up, package_dirs=tuple(args.package_dir),
                window=OfflineWindow() if args.html else None, **extra)
    if args.html:
        path = write_html(vis, args.html)
        print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB, self-contained: open it in "
              "any browser, no network needed)")
        return 0
    print(f"meshcat is serving the scene at {vis.url()} (127.0.0.1); press Enter to stop")
    with contextlib.suppress(EOFError, KeyboardInterrupt):
        input()
    return 0


# -- kinfw reproduce ---------------------------------------------------------------------
def _cmd_reproduce(args: argparse.Namespace) -> int:
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
        run, written = (lambda: shih_figures.main([args.study, *argv])), \
            f"{args.study}.json"
    if not args.json:
        return run()
    with contextlib.redirect_stdout(io.StringIO()):
        code = run()
    print((Path(args.out) / written).read_text(encoding="utf-8"))
    return code


# -- kinfw crosscheck --------------------------------------------------------------------
def _cmd_crosscheck(args: argparse.Namespace) -> int:
    import numpy as np

    from kinfw.robot import load_robot
    from verification.crosscheck import crosscheck_cpc

    robot = load_robot(args.urdf)
    frames = _frames_arg(args.frames, (*robot.default_frames, *robot.default_cameras),
                         "--frames", robot)
    result = crosscheck_cpc(robot, frames, n=args.n, rng=np.random.default_rng(args.seed))
    if args.json:
        print(json.dumps({"urdf": str(args.urdf), "frames": list(result.frames),
                          "n_configurations": result.n_configurations,
                          "numpy_position_m": result.numpy_position_m,
                          "numpy_rotation_rad": result.numpy_rotation_rad,
                          "casadi_position_m": result.casadi_position_m,
                          "casadi_rotation_rad": result.casadi_rotation_rad,
                          "passed": result.passed()}, indent=2))
    else:
        print(f"CPC vs Pinocchio FK of {args.urdf}, {result.n_configurations} random "
              f"configurations, frames {', '.join(result.frames)}")
        print(f"  numpy : max position {result.numpy_position_m:.2e} m, "
              f"rotation {result.numpy_rotation_rad:.2e} rad")
        print(f"  CasADi: max position {result.casadi_position_m:.2e} m, "
              f"rotation {result.casadi_rotation_rad:.2e} rad")
        print("  passed (< 1e-12)" if result.passed() else "  FAILED (>= 1e-12)")
    return 0 if result.passed() else 1


# -- outputs -----------------------------------------------------------------------------
def _check_outputs(args: argparse.Namespace) -> None:
    """Check every output path of the command before any work: its directory exists and
    is writable, it is not a directory, no two outputs are one file, and no output is an
    input (symlinks resolved). Raises :class:`kinfw.files.OutputPathError`."""
    command = args.command
    if command == "simulate":
        check_outputs({"--out": args.out, "--truth-out": args.truth_out},
                      inputs={"--urdf": args.urdf})
    elif command == "calibrate":
        check_outputs({"--out": args.out, "sidecar": _sidecar_path(args.out),
                       "--report": args.report},
                      inputs={"--urdf": args.urdf, "data file": args.data,
                              "--holdout": args.holdout})
    elif command == "demo":
        from verification.demo import DEMO_FILES

        check_output_dir(args.out, label="--out", files=DEMO_FILES)
    elif command == "view" and args.html is not None:
        sidecar = args.sidecar or (args.calibrated and _sidecar_path(args.calibrated))
        check_outputs({"--html": args.html},
                      inputs={"nominal": args.nominal, "--calibrated": args.calibrated,
                              "--data": args.data, "sidecar": sidecar})
    elif command == "reproduce":
        check_output_dir(args.out, label="--out")


# -- numbers on the command line -----------------------------------------------------------
def _number(kind: type, *, low: float | None = None, high: float | None = None,
            low_open: bool = False, unit: str = "") -> Callable[[str], float | int]:
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
        if (value is None or not math.isfinite(value)
                or (low is not None and (value <= low if low_open else value < low))
                or (high is not None and value > high)):
            raise argparse.ArgumentTypeError(f"expected {' '.join(filter(None, (noun, want)))}"
                                             f"{suffix}, got {text!r}")
        return value

    parse.__name__ = kind.__name__  # argparse's own messages say "invalid int value"
    return parse


_MM = _number(float, low=0.0, unit="(mm)")
_DEG = _number(float, low=0.0, unit="(deg)")
_POSITIVE_MM = _number(float, low=0.0, low_open=True, unit="(mm)")
_POSITIVE_DEG = _number(float, low=0.0, low_open=True, unit="(deg)")
_COUNT = _number(int, low=1)
_SEED = _number(int, low=0)


def _up_arg(text: str) -> list[float]:
    """``"x y z"`` (or ``x,y,z``): three finite numbers, not all zero."""
    try:
        up = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        up = []
    if len(up) != 3 or not all(map(math.isfinite, up)) or not any(up):
        raise argparse.ArgumentTypeError(f'expected three numbers "x y z", not all zero, '
                                         f"got {text!r}")
    return up


class _Parser(argparse.ArgumentParser):
    """Errors in one line, ``kinfw CMD: error: ...`` (exit 2), like every other error."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see "
                     f"'{self.prog} --help')\n")


# -- parser ------------------------------------------------------------------------------
def _add_fit_options(p: argparse.ArgumentParser) -> None:
    """Noise, robust loss and prior of the refinement (calibrate and crossval)."""
    p.add_argument("--sigma-mm", type=_POSITIVE_MM, help="position noise sigma per axis, mm "
                   "(default: estimated from the residuals)")
    p.add_argument("--sigma-deg", type=_POSITIVE_DEG, help="orientation noise: angle sigma "
                   "about a random axis, deg (default: estimated)")
    p.add_argument("--loss", choices=("huber", "linear", "cauchy"), default="huber",
                   help="robust loss of the refinement (default huber: gross outliers are "
                   "down-weighted and listed)")
    p.add_argument("--prior-mm", type=_POSITIVE_MM, help="Gaussian prior on deviations from "
                   "the nominal: sigma of lengths, mm (for small datasets)")
    p.add_argument("--prior-deg", type=_POSITIVE_DEG, help="... and of angles, deg")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="kinfw", description="Calibrate robot kinematics from measurements.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("simulate", help="simulate measurements of a perturbed robot",
                       description="Perturb the nominal URDF into a 'true' robot and simulate "
                       "its measurements: stage 1 poses of --frames, one joint at a time "
                       "(Shih et al. section 4.1); stage 2 camera observations of a fixed "
                       "target at random configurations.")
    p.add_argument("--urdf", type=Path, default=None,
                   help="nominal URDF (default: the built-in IIS-head)")
    p.add_argument("--out", type=Path, required=True, help="measurement file to write (JSON)")
    p.add_argument("--truth-out", type=Path, required=True, help="true robot URDF to write")
    p.add_argument("--per-joint", type=_COUNT, default=9,
                   help="stage 1 measurements per joint (default 9, as the paper)")
    p.add_argument("--noise-mm", type=_MM, default=0.5,
                   help="position noise sigma per axis, mm (default 0.5)")
    p.add_argument("--noise-deg", type=_DEG, default=0.5,
                   help="rotation noise angle sigma, deg (default 0.5)")
    p.add_argument("--stereo-mm", type=_MM, default=None,
                   help="simulate the stereo rig: point noise sigma on the nine-circle "
                   "plate, mm (replaces --noise-mm/--noise-deg for stage 1 poses)")
    p.add_argument("--error-mm", type=_MM, default=2.0,
                   help="true robot: joint origin error sigma, mm (default 2)")
    p.add_argument("--error-deg", type=_DEG, default=0.5,
                   help="true robot: joint origin and axis error sigma, deg (default 0.5)")
    p.add_argument("--fraction", type=_number(float, low=0.0, high=1.0, low_open=True),
                   default=0.8,
                   help="fraction of each joint range used (default 0.8)")
    p.add_argument("--stage", choices=("1", "2", "both"), default="1")
    p.add_argument("--stage2-samples", type=_COUNT, default=30,
                   help="stage 2 random configurations (default 30)")
    p.add_argument("--frames", help="stage 1 frames, comma-separated (default: URDF hint)")
    p.add_argument("--cameras", help="stage 2 cameras, comma-separated (default: URDF hint)")
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("verify", help="errors of a URDF model against measurements")
    p.add_argument("model", type=Path, help="URDF to evaluate")
    p.add_argument("data", type=Path, help="measurement file (kinfw-measurements JSON)")
    p.add_argument("--sidecar", type=Path, help="calibration sidecar (default: "
                   "MODEL.kinfw.json beside the model, used when present)")
    p.add_argument("--no-sidecar", action="store_true",
                   help="ignore the sidecar: fit nuisance frames to these data")
    p.add_argument("--json", action="store_true",
                   help="print the report as JSON, with per-sample errors")
    p.set_defaults(func=_cmd_verify)

    p = sub.add_parser("calibrate", help="identify the kinematics and write a calibrated URDF")
    p.add_argument("data", type=Path, help="measurement file (kinfw-measurements JSON)")
    p.add_argument("--urdf", type=Path, required=True, help="nominal URDF")
    p.add_argument("--out", type=Path, required=True, help="calibrated URDF to write")
    p.add_argument("--report", type=Path, help="write the report (JSON) here")
    p.add_argument("--method", choices=("refine", "closed-form"), default="refine",
                   help="refine (default): closed form and hand-eye, then the joint "
                   "nonlinear least squares; closed-form: stop after closed form and hand-eye")
    p.add_argument("--holdout", type=Path, help="measurement file not used for calibration; "
                   "its errors go to the report and sidecar")
    p.add_argument("--params", default="full", help="what to estimate: full (default), "
                   "offsets (joint zero offsets + base and tool frames), frames (base and "
                   "tool frames only), none, or a mask 'pan,tilt:l_x,...' (frames plus "
                   "those joints' CPC parameters)")
    _add_fit_options(p)
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("demo", help="simulate, calibrate and evaluate the built-in IIS-head")
    p.add_argument("--out", type=Path, default=Path("demo_out"),
                   help="output directory (default demo_out)")
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("crossval", help="k-fold cross-validation against baselines",
                       description="Held-out error of the calibration (folds by sample) next "
                       "to two baselines on the same folds: the nominal geometry and 'frames "
                       "only' (nominal joints; measurement frame, markers, target and tool / "
                       "hand-eye frames fitted). Warns when the calibration is worse than "
                       "frames only, with the likely cause.")
    p.add_argument("data", type=Path, help="measurement file")
    p.add_argument("--urdf", type=Path, required=True, help="nominal URDF")
    p.add_argument("--k", type=_number(int, low=2), default=5, help="folds (default 5)")
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument("--select", action="store_true", help="also try 'offsets' and pick the "
                   "parameter set with the lowest held-out error")
    _add_fit_options(p)
    p.add_argument("--jobs", type=_COUNT, default=1, help="run the fits in N worker processes "
                   "(default 1: in this process)")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.set_defaults(func=_cmd_crossval)

    p = sub.add_parser("view", help="nominal and calibrated robots and measurements in 3D",
                       description="Meshcat view: the nominal robot as a grey ghost, the "
                       "calibrated one in colour, a sample's measured poses as triads and "
                       "lines from prediction to measurement (scaled), targets and cameras. "
                       "Live on 127.0.0.1, or one self-contained HTML file with --html.")
    p.add_argument("nominal", type=Path, help="nominal URDF")
    p.add_argument("--calibrated", type=Path, help="calibrated URDF")
    p.add_argument("--data", type=Path, help="measurement file: draw one sample's observations")
    p.add_argument("--sidecar", type=Path, help="calibration sidecar (default: "
                   "CALIBRATED.kinfw.json beside --calibrated, if present)")
    p.add_argument("--sample", type=_number(int), default=None,
                   help="sample to draw (default 0)")
    p.add_argument("--residual-scale", type=_number(float, low=0.0, low_open=True),
                   default=10.0,
                   help="lengthen prediction-to-measurement lines by this factor (default 10)")
    p.add_argument("--up", type=_up_arg, help='"x y z": up direction of the root frame '
                   "(default: the URDF's <kinfw up> hint, else z)")
    p.add_argument("--package-dir", action="append", default=[],
                   help="where package:// meshes live (repeatable)")
    p.add_argument("--html", type=Path, help="write a self-contained HTML file instead of "
                   "serving")
    p.set_defaults(func=_cmd_view)

    p = sub.add_parser("reproduce", help="reproduce a paper's experiment in simulation (PNG)",
                       description="fig11: Shih et al. Fig. 11 (positioning error vs "
                       "measurements per joint and noise); table4: their Table 4 protocol; "
                       "hirsh: Hirsh et al. Figs. 3-4 (A = X B Y error vs iteration); crlb: "
                       "the joint refinement against the Cramer-Rao bound; robust: with 5 % "
                       "gross outliers, per robust loss.")
    p.add_argument("study", choices=("fig11", "table4", "hirsh", "crlb", "robust"))
    p.add_argument("--out", type=Path, default=Path("reproduce_out"),
                   help="output directory (default reproduce_out)")
    p.add_argument("--trials", type=_COUNT, default=None, help="random trials per point")
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument("--jobs", type=_COUNT, default=1, help="run the trials in N worker "
                   "processes (default 1: in this process)")
    p.add_argument("--json", action="store_true", help="print the study's JSON, not tables")
    p.set_defaults(func=_cmd_reproduce)

    p = sub.add_parser("crosscheck", help="check the CPC model against Pinocchio FK")
    p.add_argument("urdf", type=Path)
    p.add_argument("--frames", help="end frames, comma-separated (default: URDF hint)")
    p.add_argument("-n", type=_COUNT, default=200, help="random configurations (default 200)")
    p.add_argument("--seed", type=_SEED, default=0)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=_cmd_crosscheck)
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
                print(f"{record.levelname} {record.name}: {record.getMessage()}",
                      file=sys.stderr, flush=True)
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
