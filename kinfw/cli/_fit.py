"""The commands of the ``kinfw`` command line that fit a model: ``calibrate``, ``demo``
and ``crossval``, with their tables and printers (the other commands are in
:mod:`kinfw.cli._commands`, their parsers in :mod:`kinfw.cli._fit_parser`, :func:`kinfw.cli.main`
in :mod:`kinfw.cli`).

Each ``cmd_<name>(args)`` runs ``kinfw <name>`` on the parsed arguments and returns the
exit code; user errors are raised (ValueError, OSError) and reported by
:func:`kinfw.cli.main`. Like :mod:`kinfw.cli`, this module imports only the standard
library at start-up: numpy, Pinocchio and CasADi are imported inside the commands.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Sequence
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Any

from kinfw.cli._args import load_model, model_arg, mounted_model, read_data
from kinfw.cli._tables import format_table, metric_format, number
from kinfw.files import json_text

if TYPE_CHECKING:
    from kinfw.measurements import Measurements
    from kinfw.records import (
        BeforeAfter,
        DownweightedRow,
        ErrorValue,
        RefineSection,
        RejectedRow,
        StageErrors,
    )
    from kinfw.verification.evaluation import CrossValidation

#: Rejected observations listed one per line; the others are counted.
MAX_LINES = 10
#: Sets of parameters not identifiable listed one per line (a noise-free stereo rig gave
#: six look-alike sets); the others are counted, and the report has them all.
UNSEEN_LINES = 3


# -- kinfw calibrate ---------------------------------------------------------------------
def _labels(values: Sequence[ErrorValue]) -> list[str]:
    """Column labels of error values: ``"RMS mm"`` where the unit alone tells the metric
    apart from the others, else with the metric's name (``"height RMS mm"``)."""
    units = [v.unit for v in values]
    return [
        v.label() if units.count(v.unit) > 1 or not v.stat else v.label().split(" ", 1)[1]
        for v in values
    ]


def _before_after_table(rows: Sequence[BeforeAfter]) -> str:
    """Per group its errors before and after, a pair of columns per metric of any group
    (``-`` where a group's kind has none)."""
    values = list({v.key: v for r in rows for v in r.before}.values())
    cells = []
    for r in rows:
        row = [r.group, r.n]
        for v in values:
            pair = r.of(v.name)
            fmt = metric_format(v.name, v.unit)
            row += [number(x, fmt) for x in (pair if pair else (None, None))]
        cells.append(row)
    header = ["frame", "n"]
    for label in _labels(values):
        header += [f"before {label}", f"after {label}"]
    return format_table(cells, header)


def _stage_table(stages: Sequence[StageErrors]) -> str:
    """Per group the headline of its first metric after each stage (position RMS mm,
    pixel RMS px, ...); the metric named per row when the groups differ."""
    rms = {s.stage: {g: v for g, v in s.rms} for s in stages}
    first = stages[0].rms
    kinds = list({v.key: v for _, v in first}.values())
    mixed = len(kinds) > 1
    head = "RMS: " + ", ".join(f"{v.name} {v.unit}" for v in kinds) if mixed else kinds[0].label()
    return format_table(
        [
            [
                f"{g} [{v.name} {v.unit}]" if mixed else g,
                *(f"{rms[s.stage][g].value:.3f}" for s in stages),
            ]
            for g, v in first
        ],
        [head, *rms],
    )


def params_arg(text: str) -> str | tuple[str, ...]:
    """``full``, ``offsets``, ``frames``, ``none``, or a comma-separated mask."""
    if text in ("full", "offsets", "frames", "none"):
        return text
    return tuple(t for t in text.replace(" ", "").split(",") if t)


def _prior_arg(args: argparse.Namespace):
    """The prior of ``--prior-mm``/``--prior-deg`` and ``--prior GROUP=VALUE`` (which
    overrides their groups), or None."""
    if (args.prior_mm is None) != (args.prior_deg is None):
        raise ValueError("give both --prior-mm and --prior-deg")
    from kinfw.model import PriorScales

    prior = PriorScales()
    if args.prior_mm is not None:
        prior = PriorScales.uniform(args.prior_mm * 1e-3, math.radians(args.prior_deg))
    groups = args.prior or []
    if groups:
        prior = prior.with_sigmas({(s.group, s.unit): s.sigma for s in groups}, "given")
    return prior if prior.scales else None


def _noise_arg(args: argparse.Namespace):
    from kinfw.identification.problem import NoiseModel

    sigma_px = getattr(args, "sigma_px", None)
    pixel = {} if sigma_px is None else {"pixel": sigma_px}
    if args.sigma_mm is None and args.sigma_deg is None:
        return NoiseModel(sigmas=pixel) if pixel else None
    if args.sigma_mm is None or args.sigma_deg is None:
        raise ValueError(
            "give both --sigma-mm and --sigma-deg, or neither (then the noise "
            "is estimated from the residuals)"
        )
    # an angle sigma about a random axis is sigma / sqrt(3) per orientation component
    return NoiseModel(
        args.sigma_mm * 1e-3, math.radians(args.sigma_deg) / math.sqrt(3.0), sigmas=pixel
    )


def calibration_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of :func:`kinfw.verification.reporting.calibrate_and_report`
    that the calibration's options give (:func:`kinfw.cli._fit_parser.
    add_calibration_options`): parameters, method, noise, loss, prior, intrinsics,
    duplicates, the plausibility guard's bound and whether large changes are allowed."""
    return {
        "parameters": "auto" if args.params == "auto" else params_arg(args.params),
        "method": args.method,
        "noise": _noise_arg(args),
        "loss": args.loss,
        "prior": _prior_arg(args),
        "refine_intrinsics": _intrinsics_arg(args.refine_intrinsics),
        "keep_duplicates": args.keep_duplicates,
        "change_bound": change_bound(args),
        "allow_large_changes": args.allow_large_changes,
        "model": model_arg(args),
    }


def change_bound(args: argparse.Namespace):
    """The plausibility guard's rule of ``--max-change-mm`` / ``--max-change-deg``
    (:func:`kinfw.cli._fit_parser.add_guard_options`): None (the default rule) when
    neither is given."""
    from kinfw.identification.checks import ChangeBound

    if args.max_change_mm is None and args.max_change_deg is None:
        return None
    return ChangeBound(
        max_m=None if args.max_change_mm is None else 1e-3 * args.max_change_mm,
        max_rad=None if args.max_change_deg is None else math.radians(args.max_change_deg),
    )


def cmd_calibrate(args: argparse.Namespace) -> int:
    from kinfw.records import write_report
    from kinfw.verification.reporting import calibrate_and_report

    nominal = load_model(args.urdf, args)
    data = read_data(args.data, args)
    held_out = read_data(args.holdout, args) if args.holdout else None
    nominal = mounted_model(nominal, data, *filter(None, [held_out]))
    result = calibrate_and_report(
        nominal,
        data,
        **calibration_options(args),
        held_out=held_out,
        data_path=args.data,
    )
    report, choice = result.write(args.out), result.choice
    if args.report:
        write_report(args.report, report)
    if args.json:
        print(json_text(report.to_dict()))
        return 0
    print(
        f"calibrated {args.urdf} with {args.method} from {args.data} "
        f"({data.n_samples} samples) -> {args.out} (+ {report.sidecar})"
    )
    if result.robot.spec:
        _print_spec(result, args.out)
    warned = () if result.intrinsics is None else (result.intrinsics.message(),)
    for note in report.notes:
        if note not in warned:  # said on stderr already
            print(f"note: {note}")
    if choice is not None and choice.candidates:
        print("model choice: leave-one-out held-out error of each candidate (closed form):")
        print(_choice_table(choice))
    print("RMS on the calibration data after each stage (in-sample):")
    print(_stage_table(report.rms_by_stage))
    if report.rms_by_stage_without_rejected is not None and report.refine is not None:
        n = len(report.refine.rejected or ())
        print(f"the same without the {n} rejected observations (what the fit was made on):")
        print(_stage_table(report.rms_by_stage_without_rejected))
    if report.refine is not None:
        _print_refine(report.refine, has_report=bool(args.report))
    if report.reprojection is not None:
        _print_reprojection(report.reprojection)
    _print_origin_changes(result.nominal, result.robot)
    if report.guard is not None:
        g = report.guard
        print(
            f"plausibility guard: bound {1e3 * g.bound_m:.3g} mm / {math.degrees(g.bound_rad):.3g} "
            f"deg ({g.why}); largest: {g.largest or 'nothing changed'}"
        )
    if report.errors_held_out is not None:
        print("held-out errors:")
        print(_before_after_table(report.errors_held_out))
    if report.reprojection_held_out is not None:
        _print_reprojection(report.reprojection_held_out, "the held-out data")
    if args.report:
        print(f"report: {args.report}")
    return 0


def _print_spec(result, out: Path) -> None:
    """What the URDF cannot hold, as calibrated: per block entry its value and sigma;
    where it was written (the sidecar and the per-joint YAML)."""
    from kinfw.records import joint_model_path
    from kinfw.verification.reporting import robot_block_records

    records = robot_block_records(result.calibration.refined)
    rows = [
        [name, unit, f"{value:.4g}", f"{std:.2g}" if std > 0 else "fixed", _stiffness(unit, value)]
        for r in records
        for name, unit, value, std in zip(r.names, r.units, r.values, r.std, strict=True)
    ]
    print(
        "the URDF holds the geometry; what no URDF holds "
        f"({', '.join(b.block_name for b in result.robot.spec.blocks)}) is in the sidecar and "
        f"{joint_model_path(out)}:"
    )
    print(format_table(rows, ["parameter", "unit", "estimate", "std", "stiffness"]))


def _stiffness(unit: str, compliance: float) -> str:
    """A compliance's stiffness (``1 / c``, Nm/rad or N/m), ``-`` for another entry."""
    per = {"rad/Nm": "Nm/rad", "m/N": "N/m"}.get(unit)
    return f"{1.0 / compliance:.4g} {per}" if per and compliance > 0 else "-"


def _print_reprojection(rep, on: str = "the calibration data (in-sample)") -> None:
    """Reprojection RMS per camera and the worst images (px) on ``on``."""
    print(f"reprojection error on {on}, px:")
    rows = [
        [c.camera, str(c.n_images), str(c.n_points), f"{c.rms_px:.3g}", f"{c.max_px:.3g}"]
        for c in rep.cameras
    ]
    print(format_table(rows, ["camera", "images", "points", "RMS px", "max px"]))
    worst = rep.worst[:5]
    folder = _common_folder([i.image for i in worst])
    print(
        f"  worst images (RMS px{f', in {folder}' if folder else ''}): "
        + ", ".join(
            f"{i.image[len(folder) :]} ({i.camera}, samples[{i.sample}]) {i.rms_px:.3g}"
            for i in worst
        )
    )


def _common_folder(labels: list[str]) -> str:
    """The folder (with its trailing separator) every label's path is in, or "" when
    they are not paths or not in one folder."""
    folders = {str(PurePath(label).parent) for label in labels}
    if len(folders) != 1 or (folder := folders.pop()) == ".":
        return ""
    return folder.rstrip(os.sep) + os.sep


def _print_origin_changes(nominal, calibrated, shown: int = 8) -> None:
    """The joints whose origin the calibrated URDF changed, largest shift first: the
    camera's mount, a joint's offset (:func:`kinfw.urdf.origin_changes`)."""
    import pinocchio as pin

    from kinfw.urdf import origin_changes

    changes = origin_changes(nominal, calibrated)
    if not changes:
        print("the calibrated URDF has the nominal's joint origins and axes")
        return
    rows = [
        [
            c.joint,
            f"{1e3 * c.shift_m:.3g}",
            f"{math.degrees(c.turn_rad):.3g}",
            f"{math.degrees(c.axis_turn_rad):.3g}",
            " ".join(f"{1e3 * v:.2f}" for v in c.parent_T_child[:3, 3]),
            " ".join(
                f"{math.degrees(v):.3f}" for v in pin.rpy.matrixToRpy(c.parent_T_child[:3, :3])
            ),
        ]
        for c in changes[:shown]
    ]
    print("joint origins the calibration changed (calibrated vs nominal, largest first):")
    header = ["joint", "moved mm", "turned deg", "axis deg", "origin xyz mm", "origin rpy deg"]
    print(format_table(rows, header))
    if len(changes) > shown:
        print(f"  ... and {len(changes) - shown} more (the calibrated URDF has them all)")


def _intrinsics_arg(frames: list[str] | None) -> bool | tuple[str, ...]:
    """``--refine-intrinsics``: absent (), given without frames True (every camera)."""
    if frames is None:
        return ()
    return tuple(frames) if frames else True


def _choice_table(choice) -> str:
    """The candidates of a model choice with their held-out scores (whitened, and the
    mean RMS in each metric of the data), the chosen marked."""
    metrics = list(dict.fromkeys(m for c in choice.candidates for m, _ in c.errors))
    labels = [f"{m.name} {m.unit}" for m in metrics]
    head = f"  {'candidate':<32} {'whitened':>9}" + "".join(f" {t:>8}" for t in labels)
    rows = [head]
    chosen = (choice.parameters, choice.prior, tuple(b.block_name for b in choice.spec.blocks))
    for c in choice.candidates:
        mark = " <- chosen" if (c.parameters, c.prior, c.model) == chosen else ""
        label = c.label
        if c.prior is not None and c.prior.how != "given":  # its groups are printed below
            label = f"{c.parameters}, prior by group" + "".join(f" + {m}" for m in c.model)
        if c.failed is not None:
            rows.append(f"  {label:<32} not scored: {_short_failure(c.failed)}")
            continue
        mine = dict(c.errors)
        cells = "".join(
            f" {number(mine.get(m), '.3g'):>{max(8, len(t))}}"
            for m, t in zip(metrics, labels, strict=True)
        )
        rows.append(f"  {label:<32} {c.whitened:>9.3g}{cells}{mark}")
    rows += [
        f"  (prior by group, chosen by {c.prior.how}: {c.prior.label.removeprefix('prior ')})"
        for c in choice.candidates
        if c.prior is not None and c.prior.how != "given" and not c.model
    ]
    return "\n".join(rows)


def _short_failure(failed: str) -> str:
    """A candidate's refusal in a table row: from "too little data" (the data file's
    name dropped) to the first detail in parentheses or after ", which"."""
    text = failed[failed.find("too little data") :] if "too little data" in failed else failed
    for stop in (" (the largest move", ", which it cannot", ": the exported"):
        text = text.split(stop)[0]
    return text if len(text) <= 120 else text[:117] + "..."


def _noise_text(noise) -> str:
    """The sigma of each noise component the data has, in its metric's unit:
    ``position 0.5 mm, rotation 0.289 deg, pixel 0.5 px`` (per row of the component)."""
    from kinfw.observations import kinds

    display = {c.name: c.display for k in kinds() for c in k.components}
    parts = []
    for name, sigma in noise.sigmas:
        m = display.get(name)
        parts.append(
            f"{name} {sigma:.3g}" if m is None else f"{name} {m.scale * sigma:.3g} {m.unit}"
        )
    return ", ".join(parts) or "-"


def _print_refine(ref: RefineSection, *, has_report: bool) -> None:
    """The refinement's summary: noise, fit, rank, fixed and unidentifiable parameters,
    the worst down-weighted observations."""
    ident = ref.identifiability
    if ident.condition is not None:
        condition = f"condition {ident.condition:.3g}"
    else:  # null in the report: no free parameters, or a rank-deficient problem
        condition = "condition undefined" if not ident.n_parameters else "condition inf"
    print(
        f"refine: noise sigma {_noise_text(ref.noise)}"
        + f" ({'estimated' if ref.noise.estimated else 'given'}); reduced chi-square "
        f"{ref.reduced_chi_square:.3g}; rank {ident.rank}/{ident.n_parameters}, " + condition
    )
    print(
        f"  parameters: {len(ref.parameters) - ref.n_fixed} estimated, {ref.n_fixed} fixed "
        "(not estimated; std null in the report)"
    )
    unseen = ident.not_identifiable
    for item in unseen[:UNSEEN_LINES]:
        print(f"  not identifiable: {', '.join(item.parameters)}: {item.why}")
    if len(unseen) > UNSEEN_LINES:
        print(
            f"  ... and {len(unseen) - UNSEEN_LINES} more sets not identifiable "
            f"({'see the report' if has_report else 'write them with --report'})"
        )
    rejected = ref.rejected or ()
    for row in rejected[:MAX_LINES]:
        why = (
            "beyond the 99.9 % quantile (expected on clean data)"
            if row.clean_tail
            else "rejected as a gross error"
        )
        print(
            f"  {why}: samples[{row.sample}] {_observed(row)}: "
            f"residual {_residual_sizes(row)}, {row.excess:.3g} x the threshold"
            f"{_threshold(row, 1.0 / row.excess)} (refitted without it)"
        )
    if len(rejected) > MAX_LINES:
        print(
            f"  ... and {len(rejected) - MAX_LINES} more rejected "
            f"({len(rejected)} in all; "
            + ("see the report)" if has_report else "write them with --report)")
        )
    # the rejection note (data inconsistent with the model) is a warning, printed once
    # on stderr by the command's warning printer
    down = ref.downweighted
    if down:
        print(f"  {len(down)} observations down-weighted by the {ref.loss} loss, worst first:")
    for row in down[:5]:
        print(
            f"    samples[{row.sample}] {_observed(row)}: residual {_residual_sizes(row)}, "
            f"weight {row.weight:.2g}{_threshold(row, row.weight, 'the loss bends at')}"
        )
    if len(down) > 5:
        print(
            f"    ... and {len(down) - 5} more "
            f"({'see the report' if has_report else 'write them with --report'})"
        )


# -- kinfw demo --------------------------------------------------------------------------
def cmd_demo(args: argparse.Namespace) -> int:
    from kinfw.verification.studies import N_STAGE2, NOISE_DEG, NOISE_MM, PIXEL_SIGMA, run_demo

    pixels = bool(getattr(args, "pixels", False))
    demo = run_demo(args.out, seed=args.seed, pixels=pixels)
    report = demo.report
    if args.json:
        print(json_text(report.to_dict()))
        return 0
    out = demo.out
    seen = ""
    if pixels:  # the images each camera has: a camera does not see the board everywhere
        seen = ", ".join(f"{c.camera} {c.n_images}" for c in report.reprojection.cameras)
    print("kinfw demo: the IIS-head experiment of Shih et al. (1992) in simulation")
    print(
        f"  true robot = built-in URDF with 5 mm / 1 deg errors (seed {args.seed}); stage 1: "
        f"{demo.n_stage1} one-joint-at-a-time configurations (9 per joint), plate poses from "
        "the stereo rig; stage 2: "
        + (
            "the cameras (640x480, fx = fy = 600 px) see the corners of a fixed 9x6 "
            f"chessboard in {N_STAGE2} random configurations (images: {seen}), pixel "
            f"noise {PIXEL_SIGMA:g} px; "
            if pixels
            else f"both cameras see a fixed target in {N_STAGE2} random configurations; "
        )
        + f"noise sigma {NOISE_MM:g} mm / {NOISE_DEG:g} deg; closed form, "
        "A = X B Y, then the joint least squares"
        + (" on reprojection error" if pixels else "")
        + "; 100 held-out configurations"
    )
    print("\nheld-out position RMS against the true robot (noise-free), mm, after each stage:")
    print(_stage_table(report.rms_vs_truth_held_out_by_stage))
    print("\nheld-out errors against noisy measurements (targets: camera_T_target):")
    print(_before_after_table(report.errors_held_out))
    noise = report.refine.noise
    if pixels:
        print()
        _print_reprojection(report.reprojection)
        held = demo.held_out_pixels
        n_images = sum(c.n_images for c in held.cameras)
        print(
            f"reprojection error on {n_images} held-out images ({N_STAGE2} fresh "
            "configurations), px:"
        )
        rows = [
            [c.camera, str(c.n_images), str(c.n_points), f"{c.rms_px:.3g}", f"{c.max_px:.3g}"]
            for c in held.cameras
        ]
        print(format_table(rows, ["camera", "images", "points", "RMS px", "max px"]))
        print(
            "  worst held-out images (RMS px): "
            + ", ".join(f"{i.image} ({i.camera}) {i.rms_px:.3g}" for i in held.worst[:5])
        )
        print(
            f"\nestimated noise: {noise.position_sigma_mm:.3f} mm per axis, "
            f"{noise.rotation_sigma_deg_per_component:.3f} deg per orientation component, "
            f"{noise.of('pixel'):.3f} px (true: {NOISE_MM:g} mm, "
            f"{NOISE_DEG / math.sqrt(3.0):.3f} deg, {PIXEL_SIGMA:g} px)"
        )
    else:
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
    from kinfw.verification.evaluation import crossvalidate, open_executor

    nominal = load_model(args.urdf, args)
    data = read_data(args.data, args)
    nominal = mounted_model(nominal, data)
    model = model_arg(args)
    nominal = nominal if model is None else nominal.with_spec(model)
    prior = _prior_arg(args)
    with open_executor(args.jobs, args.executor) as executor:
        cv = crossvalidate(
            nominal,
            data,
            k=args.k,
            seed=args.seed,
            select=args.select,
            noise=_noise_arg(args),
            loss=args.loss,
            prior=prior,
            executor=executor,
            exclude_flagged=args.exclude_flagged,
            keep_duplicates=args.keep_duplicates,
            change_bound=change_bound(args),
        )
    if args.json:
        print(json_text(cv.to_dict()))
        return 0
    _print_crossval(cv, args, data)
    return 0


def _print_crossval(cv: CrossValidation, args: argparse.Namespace, data: Measurements) -> None:
    """The table of ``kinfw crossval``: held-out RMS per fold and parameter set, the
    excluded observations, the warnings and the selected set."""
    from kinfw.observations import kind_of

    sets = cv.sets
    label = {
        "none": "nominal",
        "frames": "frames only",
        "offsets": "offsets+frames",
        "full": "full",
        "auto": "default",
    }
    metrics = cv.metrics
    images = any(kind_of(g).name == "pixels" for g in data.all_groups())
    print(
        f"{args.k}-fold cross-validation of {args.data} ({data.n_samples} samples, folds "
        f"by sample{', images whole' if images else ''}, seed {args.seed}): held-out RMS, "
        + " / ".join(f"{m.name} {m.unit}" for m in metrics)
    )

    def cell(value_of) -> str:
        return " / ".join(number(value_of(m), m.fmt) for m in metrics)

    rows = []
    for fold in range(args.k):
        row = [fold, next(s.n_test for s in cv.scores if s.fold == fold)]
        for p in sets:
            sc = next(s for s in cv.scores if s.fold == fold and s.parameters == p)
            row.append(cell(lambda m, sc=sc: sc.of(m.name)))
        rows.append(row)
    rows.append(["mean", "", *(cell(lambda m, p=p: cv.mean(p, m.name)) for p in sets)])
    print(format_table(rows, ["fold", "n test", *(label[p] for p in sets)]))
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
        sigmas = ", ".join(
            f"{c.name} {c.display.scale * sigma:.3g} {c.display.unit}" for c, sigma in cv.noise
        )
        errors = " / ".join(
            f"{number(cv.mean(cv.selected, m.name), m.fmt)} {m.unit}" for m in metrics
        )
        print(
            f"selected: {label[cv.selected]} ({cv.selected!r}), the lowest mean held-out "
            f"error whitened by the noise ({sigmas}): {errors}, whitened "
            f"{cv.whitened(cv.selected):.3g}"
        )


def _observed(row: DownweightedRow | RejectedRow) -> str:
    """``frame [marker m] (kind) [image LABEL corner ID]`` of a down-weighted or
    rejected observation."""
    return (
        row.frame
        + (f" marker {row.marker}" if row.marker else "")
        + f" ({row.kind})"
        + (f" {row.where}" if row.where else "")
    )


def _threshold(row: DownweightedRow | RejectedRow, factor: float, said: str = "") -> str:
    """The robust threshold in the display unit of an observation measured in one metric
    (an image point's px, a contact's mm): its residual times ``factor`` (``1 / excess``
    for a rejected one, the Huber weight ``k / |r|`` for a down-weighted one), as the
    whitened norm is the residual over the noise sigma. Empty for kinds of several metrics
    (a pose's mm and deg share one whitened norm)."""
    values = [v for v in row.residuals if v.value == v.value]
    if len(values) != 1:
        return ""
    lead = f" ({said} " if said else " of "
    return f"{lead}{values[0].value * factor:.3g} {values[0].unit}" + (")" if said else "")


def _residual_sizes(row: DownweightedRow | RejectedRow) -> str:
    """The residual's size in each metric of the observation's kind: mm, deg, px, ..."""
    return ", ".join(f"{v.value:.3g} {v.unit}" for v in row.residuals if v.value == v.value)
