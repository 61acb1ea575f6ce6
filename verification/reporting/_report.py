"""Calibration reports and sidecars built from the pipeline's result, as the typed
:class:`kinfw.records.CalibrationReport` and
:class:`kinfw.records.CalibrationSidecar` (dictionaries only when written; the
workflow that writes them is :func:`kinfw.verification.reporting.calibrate_and_report`).
The stages' sections are built by :mod:`kinfw.verification.reporting`, the errors-by-stage
figure drawn by :mod:`kinfw.verification.reporting`."""

from __future__ import annotations

import datetime as _dt
import hashlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from kinfw.identification import Calibration, RefineResult, refine
from kinfw.identification.problem import Unknown
from kinfw.measurements import Measurements
from kinfw.model import Robot
from kinfw.observations import DatasetError, kind_of
from kinfw.records import (
    BeforeAfter,
    CalibrationReport,
    CalibrationSidecar,
    DataProvenance,
    ExportSection,
    GroupErrorSummary,
    GuardSummary,
    ModelSummary,
    RobotBlockRecord,
    StageErrors,
    before_after,
)
from kinfw.verification.evaluation import (
    evaluate_model,
    rejected_keys,
    reprojection_section,
    without_observations,
)
from kinfw.verification.reporting._sections import (
    calibrated_unknowns,
    closed_form_section,
    hand_eye_section,
    noise_summary,
    refine_section,
)


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (provenance of the input data)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def errors_by_group(
    robot: Robot, data: Measurements, known: Iterable[Any] = ()
) -> tuple[GroupErrorSummary, ...]:
    """Errors of ``robot`` on ``data`` per observation group (see evaluate_model: the
    ``known`` unknowns, e.g. a calibration's target poses, as given, the others fitted
    to ``data``); each labelled ``"frame (kind)"`` (``"frame [marker] (kind)"``) by its
    ``group``, with what it observes (``"(plane table)"``) when groups of one frame, kind
    and marker observe different things."""
    report = evaluate_model(robot, data, known=known)
    return tuple(
        GroupErrorSummary.of(g.frame, g.kind, g.marker, g.summary(), entity)
        for g, entity in zip(report.groups, report.entities(), strict=True)
    )


def _errors_or_unavailable(
    robot: Robot,
    data: Measurements,
    like: tuple[GroupErrorSummary, ...],
    notes: list[str],
    known: Iterable[Any] = (),
) -> tuple[GroupErrorSummary, ...]:
    """:func:`errors_by_group`, or, when ``robot`` cannot be evaluated on ``data`` (a
    frame its geometry cannot place: :class:`DatasetError`), the groups of ``like`` with
    every number NaN ("not available") and the reason added to ``notes``."""
    try:
        return errors_by_group(robot, data, known)
    except DatasetError as e:
        notes.append(f"errors of {robot.source or 'the nominal'} not available: {e}")
        return tuple(g.unavailable() for g in like)


def before_after_rows(
    before: tuple[GroupErrorSummary, ...], after: tuple[GroupErrorSummary, ...]
) -> tuple[BeforeAfter, ...]:
    """Per observation group: each metric's headline (RMS, or a group metric's value)
    before and after."""
    return before_after(before, after)


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


def _nominal_trained(nominal: Robot, data: Measurements) -> tuple[Unknown, ...]:
    """The unknowns fitted to ``data`` with the nominal robot (``parameters="none"``,
    least squares) when a kind scores other data with trained unknowns (the planes and
    their probes: :meth:`~kinfw.observations.ObservationKind.trained_unknowns`): the
    nominal's errors are then distances from its own trained planes, as the calibrated
    model's from its. Empty when no kind asks for them or the fit refuses the data."""
    if not any(kind_of(g).trained_unknowns(g) for g in data.all_groups()):
        return ()
    try:
        return refine(nominal, data, parameters="none", loss="linear").unknowns
    except DatasetError:
        return ()


def _stage_rms(
    before: tuple,
    data: Measurements,
    refined_data: Measurements,
    calibration: Calibration,
    trained: tuple[Unknown, ...],
) -> tuple[StageErrors, ...]:
    """The errors on ``data`` of the nominal (``before``) and of each stage's URDF, the
    refinement's with its trained unknowns on ``refined_data`` (refined intrinsics)."""
    return (
        StageErrors.of("nominal", before),
        *(
            StageErrors.of(
                name,
                errors_by_group(Robot(xml, name, spec=calibration.spec), refined_data, trained)
                if name == "refine"
                else errors_by_group(Robot(xml, name), data),
            )
            for name, xml in calibration.stages
        ),
    )


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
    # each model scored with the unknowns it was trained with (target poses, markers,
    # measurement frames, planes): held-out images by reprojection with the board pose
    # from training, contacts by distance from the trained plane; for the nominal, those
    # fitted to the calibration data with the nominal robot when a kind scores with them
    trained = () if calibration.refined is None else calibration.refined.unknowns
    trained_nominal = _nominal_trained(nominal, data)
    after = errors_by_group(calibrated, refined_data, trained)
    notes = list(calibration.notes)
    before = _errors_or_unavailable(nominal, data, after, notes, trained_nominal)
    held_out_rows = None
    if held_out is not None:
        held = _with_refined_intrinsics(held_out, calibration)
        after_held = errors_by_group(calibrated, held, trained)
        before_held = _errors_or_unavailable(nominal, held_out, after_held, notes, trained_nominal)
        held_out_rows = before_after(before_held, after_held)
    stage_rms = _stage_rms(before, data, refined_data, calibration, trained)
    stage_rms_kept = None  # without the rejected observations, when some were
    if calibration.refined is not None and calibration.refined.rejected:
        drop = {(k, f, m, s) for s, k, f, m in rejected_keys(calibration)}
        kept, refined_kept = (without_observations(d, drop) for d in (data, refined_data))
        after_kept = errors_by_group(calibrated, refined_kept, trained)
        before_kept = _errors_or_unavailable(nominal, kept, after_kept, [], trained_nominal)
        stage_rms_kept = _stage_rms(before_kept, kept, refined_kept, calibration, trained)
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
        rms_by_stage=stage_rms,
        rms_by_stage_without_rejected=stage_rms_kept,
        errors_before=before,
        errors_after=after,
        kinematics=None
        if calibration.closed_form is None
        else closed_form_section(calibration.closed_form),
        hand_eye=None if calibration.cameras is None else hand_eye_section(calibration.cameras),
        refine=None if calibration.refined is None else refine_section(calibration.refined, loss),
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
        reprojection_held_out=None
        if calibration.refined is None or held_out is None
        else reprojection_section(calibrated, held_out, calibration.refined.unknowns),
    )


def sidecar(
    report: CalibrationReport,
    calibration: Calibration,
    *,
    nominal_path: str | Path | None,
    calibrated_path: str | Path,
    model: ModelSummary | None = None,
    guard: GuardSummary | None = None,
) -> CalibrationSidecar:
    """The provenance written beside a calibrated URDF: what produced it and what is
    needed to predict measurements that is not in the URDF (the root's pose in the
    measurement frame, target poses, markers, noise), and the model the refinement
    fitted (``model``; dropped without a refinement) and the plausibility guard's
    outcome (``guard``)."""
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
        noise=None if refined is None else noise_summary(refined),
        unknowns=() if refined is None else calibrated_unknowns(refined),
        hand_eye_targets=()
        if calibration.cameras is None
        else tuple(calibration.cameras.root_T_targets),
        errors_held_out=report.errors_held_out,
        model=None if refined is None else model,
        guard=guard,
        robot_blocks=() if refined is None else robot_block_records(refined),
    )


def robot_block_records(refined: RefineResult) -> tuple[RobotBlockRecord, ...]:
    """The calibrated model spec's blocks of a refinement (:attr:`RefineResult.spec`),
    each with its entries' standard deviations (by name from the refinement's)."""
    std = dict(zip(refined.parameter_names, refined.std, strict=True))
    return tuple(
        RobotBlockRecord(
            b.spec,
            tuple(f"{n.owner}:{n.field}" for n in b.names),
            b.units,
            b.start,
            np.array([std.get(n, 0.0) for n in b.names]),
        )
        for b in refined.spec.blocks
    )


def _kinfw_version() -> str:
    from importlib import metadata

    try:
        return metadata.version("kinfw")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"
