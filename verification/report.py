"""Calibration reports and sidecars built from the pipeline's result, as the typed
:class:`kinfw.calibration_report.CalibrationReport` and
:class:`kinfw.calibration_file.CalibrationSidecar` (dictionaries only when written)."""

from __future__ import annotations

import datetime as _dt
import hashlib
from dataclasses import replace
from pathlib import Path

import numpy as np

from identification.cameras import CamerasResult
from identification.closed_form import ClosedFormResult
from identification.pipeline import Calibration
from identification.refine import RefineResult, parameter_unit
from kinfw.calibration_file import (
    BeforeAfter,
    CalibratedUnknown,
    CalibrationSidecar,
    DataProvenance,
    ModelSummary,
    NoiseSummary,
)
from kinfw.calibration_report import (
    CalibrationReport,
    CameraMount,
    ClosedFormSection,
    Correlation,
    DownweightedRow,
    ExportSection,
    GroupErrorSummary,
    HandEyeSection,
    IdentifiabilitySummary,
    KinematicValue,
    NotIdentifiable,
    ParameterRow,
    RefineSection,
    RejectedRow,
    StageErrors,
    TargetEstimate,
    before_after,
)
from kinfw.files import atomic_path
from kinfw.measurements import DatasetError, Measurements
from kinfw.observations import kind_named
from kinfw.robot import Robot
from verification.accuracy import evaluate_model
from verification.reprojection import reprojection_section

__all__ = [
    "before_after_rows",
    "calibrate_to_files",
    "calibration_report",
    "downweighted_rows",
    "errors_by_group",
    "file_sha256",
    "plot_stage_errors",
    "rejected_rows",
    "sidecar",
    "sidecar_path",
]


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (provenance of the input data)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def errors_by_group(robot: Robot, data: Measurements) -> tuple[GroupErrorSummary, ...]:
    """Errors of ``robot`` on ``data`` per observation group (see evaluate_model);
    each labelled ``"frame (kind)"`` (``"frame [marker] (kind)"``) by its ``group``."""
    report = evaluate_model(robot, data)
    return tuple(GroupErrorSummary(g.frame, g.kind, g.marker, **g.summary()) for g in report.groups)


def _errors_or_unavailable(
    robot: Robot, data: Measurements, like: tuple[GroupErrorSummary, ...], notes: list[str]
) -> tuple[GroupErrorSummary, ...]:
    """:func:`errors_by_group`, or, when ``robot`` cannot be evaluated on ``data`` (a
    frame its geometry cannot place: :class:`DatasetError`), the groups of ``like`` with
    every number NaN ("not available") and the reason added to ``notes``."""
    try:
        return errors_by_group(robot, data)
    except DatasetError as e:
        notes.append(f"errors of {robot.source or 'the nominal'} not available: {e}")
        nan = float("nan")
        return tuple(
            replace(
                g,
                **{k: nan for k in GroupErrorSummary._NUMBERS},
                abs_mean_xyz_mm=(nan, nan, nan),
                abs_std_xyz_mm=(nan, nan, nan),
            )
            for g in like
        )


def before_after_rows(
    before: tuple[GroupErrorSummary, ...], after: tuple[GroupErrorSummary, ...]
) -> tuple[BeforeAfter, ...]:
    """Per observation group: RMS position (mm) and rotation (deg) before and after."""
    return before_after(before, after)


def _kinematic_values(model) -> tuple[KinematicValue, ...]:
    return tuple(
        KinematicValue(o, n, v, parameter_unit(o, n, model.topology))
        for o, n, v in model.describe()
    )


def _closed_form_section(result: ClosedFormResult) -> ClosedFormSection:
    model = result.model
    return ClosedFormSection(
        joint_names=tuple(model.topology.joint_names),
        frames=tuple(model.topology.frames),
        q0=tuple(result.q0.tolist()),
        samples_per_joint=tuple(result.group_sizes.tolist()),
        axis_residual_rad=tuple(float(v) for v in result.axis_residual_rad),
        motion_per_unit_joint_value=tuple(result.motion_scale.tolist()),
        position_rms_mm=1e3 * result.position_rms_m,
        values=_kinematic_values(model),
        n_identifiable=model.n_parameters,
    )


def _hand_eye_section(result: CamerasResult) -> HandEyeSection:
    return HandEyeSection(
        cameras=tuple(
            CameraMount(
                c.camera,
                c.target,
                c.joint,
                c.hand,
                c.hand_T_camera,
                c.n_views,
                c.solver.iterations,
                c.solver.restarts,
                c.solver.converged,
                float(np.degrees(c.solver.rms_rotation_rad)),
                1e3 * c.solver.rms_translation,
            )
            for c in result.cameras
        ),
        targets=tuple(
            TargetEstimate(t, T, 1e3 * dp, float(np.degrees(dr)))
            for (t, T), (_, dp, dr) in zip(result.root_T_targets, result.target_spread, strict=True)
        ),
    )


def downweighted_rows(result: RefineResult) -> tuple[DownweightedRow, ...]:
    """The observations the robust loss down-weighted, the worst (lowest weight) first.

    Parameters
    ----------
    result : RefineResult

    Returns
    -------
    tuple of DownweightedRow
        One per down-weighted observation: ``sample`` (index into the data file's
        ``samples``, from 0), ``kind``, ``frame`` (the camera for ``target``
        observations), ``marker`` (None without one), ``position_residual_mm`` (norm of
        measured minus predicted position; for a kind without positions, of its rows in
        metres, e.g. a plane contact's distance), ``rotation_residual_deg`` (angle between
        measured and predicted orientation; None for points), ``weight`` (the robust
        loss's weight, 1 = full) and ``pixel_residual_px`` (an image point's
        reprojection error, px; None for other kinds). Sorted by weight, then sample.
    """
    rows = []
    for g in result.residuals:
        rows_g = np.flatnonzero(g.downweighted)
        # a kind without positions (a plane contact's distance): its rows in metres
        units = {c.name: c.unit for c in kind_named(g.kind).components}
        lengths = [v for n, v in g.components if units[n] == "m"]
        position_mm = 1e3 * np.linalg.norm(np.hstack(lengths)[rows_g], axis=1) if lengths else None
        pixels = [v for n, v in g.components if units[n] == "px"]
        pixel_px = np.linalg.norm(np.hstack(pixels)[rows_g], axis=1) if pixels else None
        rotation_deg = (
            None
            if g.rotation_rad is None
            else np.degrees(
                np.arcsin(np.clip(np.linalg.norm(g.rotation_rad[rows_g], axis=1), 0.0, 1.0))
            )
        )
        rows += [
            DownweightedRow(
                int(g.sample[k]),
                g.kind,
                g.frame,
                g.marker,
                None if position_mm is None else float(position_mm[c]),
                None if rotation_deg is None else float(rotation_deg[c]),
                float(g.weight[k]),
                None if pixel_px is None else float(pixel_px[c]),
                None if g.labels is None else g.labels[k],
            )
            for c, k in enumerate(rows_g)
        ]
    rows.sort(key=lambda row: (row.weight, row.sample))
    return tuple(rows)


def rejected_rows(result: RefineResult) -> tuple[RejectedRow, ...]:
    """The observations rejected as gross errors, the worst (largest excess over the
    rejection threshold) first.

    Parameters
    ----------
    result : RefineResult

    Returns
    -------
    tuple of RejectedRow
        One per :attr:`RefineResult.rejected` entry: ``sample`` (index into the data
        file's samples, from 0), ``kind``, ``frame``, ``marker``, the residual norms in
        mm (for a kind without positions, of its rows in metres) and deg (None without
        orientation) against the final fit,
        and ``excess`` (its whitened norm over the threshold). Sorted by excess, largest
        first, then sample.
    """
    rows = []
    for o in result.rejected:
        # a kind without positions (a plane contact's distance): its lengths, as for
        # the down-weighted rows
        lengths = [v for _, unit, v in o.residuals if unit == "m"]
        p = o.residual("position")
        p = float(np.linalg.norm(lengths)) if p is None and lengths else p
        rot = o.residual("rotation")
        pixels = [v for _, unit, v in o.residuals if unit == "px"]
        rows.append(
            RejectedRow(
                o.sample,
                o.kind,
                o.frame,
                o.marker,
                None if p is None else 1e3 * p,
                None if rot is None else float(np.degrees(rot)),
                o.excess,
                float(np.linalg.norm(pixels)) if pixels else None,
                o.where,
            )
        )
    rows.sort(key=lambda row: (-row.excess, row.sample))
    return tuple(rows)


def _noise_summary(result: RefineResult) -> NoiseSummary:
    """The noise of the components the data has (a default sigma of a component without
    rows, the 1 mm position of pixel-only data, whitened nothing and is not reported)."""
    present = {name for g in result.residuals for name, _ in g.components}
    return NoiseSummary(
        tuple((k, v) for k, v in result.noise.sigmas if k in present), result.noise.estimated
    )


def _unknowns(result: RefineResult) -> tuple[CalibratedUnknown, ...]:
    return tuple(CalibratedUnknown(u.kind, u.name, u.value) for u in result.unknowns)


def _refine_section(result: RefineResult, loss: str) -> RefineSection:
    ident = result.identifiability
    return RefineSection(
        loss=loss,
        noise=_noise_summary(result),
        reduced_chi_square=result.sigma_hat2,
        iterations=result.iterations,
        converged=result.converged,
        seconds=result.seconds,
        model_frame=result.model_frame,
        # units from the parameter blocks (RefineResult.parameter_units)
        parameters=tuple(
            ParameterRow(o, f, unit, not free, float(d), float(sd) if free else None)
            for (o, f), unit, free, d, sd in zip(
                result.parameter_names,
                result.parameter_units,
                result.free,
                result.estimate,
                result.std,
                strict=True,
            )
        ),
        kinematics=_kinematic_values(result.model),
        unknowns=_unknowns(result),
        identifiability=IdentifiabilitySummary(
            rank=ident.rank,
            n_parameters=ident.n_parameters,
            # strict JSON: an undefined (no parameters) or infinite value is None (null)
            condition=_finite_or_none(ident.condition),
            observability_o1=_finite_or_none(ident.observability_o1),
            not_identifiable=tuple(
                NotIdentifiable(tuple(":".join(p) for p in params), why)
                for params, why in ident.unidentifiable
            ),
            correlations=tuple(Correlation(a, b, r) for a, b, r in ident.correlations),
        ),
        downweighted=downweighted_rows(result),
        rejected=rejected_rows(result),
        rejection_note=result.rejection_note,
    )


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _with_refined_intrinsics(data: Measurements, calibration: Calibration) -> Measurements:
    """``data`` with the intrinsics the refinement estimated (unknowns of kind
    ``"intrinsics"``, named by camera) in place of the start ones; ``data`` itself when
    none were estimated."""
    refined = calibration.refined
    if refined is None:
        return data
    cameras = {
        u.name: data.cameras[u.name].with_parameters(u.value)
        for u in refined.unknowns
        if u.kind == "intrinsics" and u.name in data.cameras
    }
    return data.with_cameras(cameras) if cameras else data


def calibration_report(
    nominal: Robot,
    calibrated: Robot,
    data: Measurements,
    calibration: Calibration,
    *,
    method: str,
    loss: str = "huber",
    data_path: str | Path | None = None,
    held_out: Measurements | None = None,
) -> CalibrationReport:
    """Everything a user needs to trust (or not) a calibration.

    Parameters
    ----------
    nominal, calibrated : Robot
        The URDF before and after (the written file, re-loaded).
    data : Measurements
        The calibration data; the errors on it are in-sample.
    calibration : Calibration
        The pipeline's result (stages, their URDFs and diagnostics).
    method, loss : str
    data_path : path, optional
        Recorded with its SHA-256.
    held_out : Measurements, optional
        Samples not used for calibration; their errors are the honest accuracy.

    Returns
    -------
    CalibrationReport
        ``to_dict()`` is the JSON of ``kinfw calibrate --report``.
    """
    # the refined intrinsics (--refine-intrinsics) for the calibrated model's errors;
    # the start ones (the file's) for the nominal and the stages before the refinement
    refined_data = _with_refined_intrinsics(data, calibration)
    after = errors_by_group(calibrated, refined_data)
    notes = list(calibration.notes)
    before = _errors_or_unavailable(nominal, data, after, notes)
    held_out_rows = None
    if held_out is not None:
        after_held = errors_by_group(calibrated, _with_refined_intrinsics(held_out, calibration))
        before_held = _errors_or_unavailable(nominal, held_out, after_held, notes)
        held_out_rows = before_after(before_held, after_held)
    stage_rms = [StageErrors.of("nominal", before)]
    stage_rms += [
        StageErrors.of(
            name, errors_by_group(Robot(xml, name), refined_data if name == "refine" else data)
        )
        for name, xml in calibration.stages
    ]
    export = calibration.export
    return CalibrationReport(
        created=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        method=method,
        nominal_urdf=nominal.source,
        data=DataProvenance(
            data.source, data.n_samples, file_sha256(data_path) if data_path else None
        ),
        notes=tuple(notes),
        errors_in_sample=before_after(before, after),
        position_rms_by_stage=tuple(stage_rms),
        errors_before=before,
        errors_after=after,
        kinematics=None
        if calibration.closed_form is None
        else _closed_form_section(calibration.closed_form),
        hand_eye=None if calibration.cameras is None else _hand_eye_section(calibration.cameras),
        refine=None if calibration.refined is None else _refine_section(calibration.refined, loss),
        export=None
        if export is None
        else ExportSection(
            export.w_T_root,
            tuple((link, 1e3 * float(np.linalg.norm(T[:3, 3]))) for link, T in export.link_shifts),
        ),
        errors_held_out=None if held_out is None else held_out_rows,
        reprojection=None
        if calibration.refined is None
        else reprojection_section(calibrated, data, calibration.refined.unknowns),
    )


def sidecar(
    report: CalibrationReport,
    calibration: Calibration,
    *,
    nominal_path: str | Path | None,
    calibrated_path: str | Path,
    model: ModelSummary | None = None,
) -> CalibrationSidecar:
    """The provenance written beside a calibrated URDF: what produced it and what is
    needed to predict measurements that is not in the URDF (the root's pose in the
    measurement frame, target poses, markers, noise), and the model the refinement
    fitted (``model``; dropped without a refinement)."""
    refined = calibration.refined
    return CalibrationSidecar(
        created=report.created,
        kinfw_version=_kinfw_version(),
        method=report.method,
        calibrated_urdf=Path(calibrated_path).name,
        nominal_urdf=str(nominal_path) if nominal_path else None,
        nominal_urdf_sha256=file_sha256(nominal_path) if nominal_path else None,
        data=report.data,
        w_T_root=calibration.w_T_root,
        measurement_frame=None if refined is None else refined.model_frame,
        noise=None if refined is None else _noise_summary(refined),
        unknowns=() if refined is None else _unknowns(refined),
        hand_eye_targets=()
        if calibration.cameras is None
        else tuple(calibration.cameras.root_T_targets),
        errors_held_out=report.errors_held_out,
        model=None if refined is None else model,
    )


def _kinfw_version() -> str:
    from importlib import metadata

    try:
        return metadata.version("kinfw")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def plot_stage_errors(
    stages: tuple[StageErrors, ...], path: str | Path, *, title: str = ""
) -> Path:
    """Grouped bars: position RMS (mm, log scale) per observation group after each stage
    (the report's ``position_rms_by_stage`` or ``..._vs_truth_held_out_by_stage``)."""
    stage_rms = {s.stage: dict(s.position_rms_mm) for s in stages}
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    stages = list(stage_rms)
    groups = list(stage_rms[stages[0]])
    fig = Figure(figsize=(8.5, 4.2))
    FigureCanvasAgg(fig)
    # fixed margins: the constrained layout engine costs more than the rest of the plot
    fig.subplots_adjust(left=0.08, right=0.99, top=0.93, bottom=0.25)
    ax = fig.add_subplot()
    width = 0.8 / len(stages)
    colours = ["0.6", "tab:orange", "tab:green", "tab:blue", "tab:purple"]
    x = np.arange(len(groups))
    for k, stage in enumerate(stages):
        values = [stage_rms[stage][g] for g in groups]
        bars = ax.bar(
            x + (k - (len(stages) - 1) / 2) * width,
            values,
            width,
            label=stage,
            color=colours[k % len(colours)],
        )
        ax.bar_label(bars, labels=[f"{v:.2g}" for v in values], fontsize=7, padding=1)
    ax.set_yscale("log")
    ax.set_xticks(x, groups)
    ax.set_ylabel("held-out position RMS (mm, log scale)")
    ax.grid(axis="y", which="both", alpha=0.3)
    ax.legend(
        title="after stage",
        ncols=len(stages),
        loc="upper center",
        bbox_to_anchor=(0.5, -0.11),
        frameon=False,
    )
    if title:
        ax.set_title(title, fontsize=10)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format=path.suffix.lstrip(".") or "png")
    return path


def sidecar_path(urdf_path: str | Path) -> Path:
    """Where the calibration sidecar of the calibrated URDF ``urdf_path`` goes:
    ``<stem>.kinfw.json`` beside it."""
    return Path(urdf_path).with_suffix(".kinfw.json")


def calibrate_to_files(
    nominal: Robot,
    data: Measurements,
    out: str | Path,
    *,
    method: str,
    noise=None,
    loss: str = "huber",
    parameters: str | tuple[str, ...] = "full",
    prior=None,
    data_path: str | Path | None = None,
    held_out: Measurements | None = None,
    progress=None,
    reason: str = "given",
    refine_intrinsics: bool | tuple[str, ...] = (),
) -> tuple[CalibrationReport, Calibration]:
    """Calibrate (:func:`identification.pipeline.calibrate`), then write the calibrated
    URDF ``out`` and its sidecar (:func:`sidecar_path`), each atomically once everything
    is computed. The sidecar records ``parameters`` and ``prior`` with ``reason`` (why
    this model: ``"given"``, or the model choice's reason).

    Returns
    -------
    report : CalibrationReport
        With ``sidecar`` set to the sidecar's path.
    calibration : Calibration
    """

    from identification.pipeline import calibrate
    from kinfw.calibration_file import write_sidecar
    from kinfw.urdf_export import write_urdf

    result = calibrate(
        nominal,
        data,
        method=method,
        noise=noise,
        loss=loss,
        parameters=parameters,
        prior=prior,
        progress=progress,
        refine_intrinsics=refine_intrinsics,
    )
    report = calibration_report(
        nominal,
        Robot(result.urdf_xml, str(out)),
        data,
        result,
        method=method,
        loss=loss,
        data_path=data_path,
        held_out=held_out,
    )
    nominal_path = None if nominal.source.startswith("<") else nominal.source
    model = ModelSummary(
        (parameters,) if isinstance(parameters, str) else tuple(parameters),
        None if prior is None else float(prior[0]),
        None if prior is None else float(prior[1]),
        reason,
    )
    side = sidecar(report, result, nominal_path=nominal_path, calibrated_path=out, model=model)
    write_urdf(out, result.urdf_xml)
    write_sidecar(sidecar_path(out), side)
    return replace(report, sidecar=str(sidecar_path(out))), result
