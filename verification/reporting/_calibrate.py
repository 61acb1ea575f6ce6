"""The calibration workflow of ``kinfw calibrate`` and :func:`kinfw.calibrate`: the model
choice (when no parameter set is given), the pipeline, the report; then, on request, the
calibrated URDF and its sidecar written together.

:func:`calibrate_and_report` computes everything and writes nothing; the returned
:class:`CalibrationResult` writes the URDF and the sidecar with
:meth:`CalibrationResult.write`, after checking that neither is an input.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from kinfw import progress
from kinfw.files import check_outputs, sidecar_path, write_text_atomic
from kinfw.identification import Calibration
from kinfw.identification.checks import (
    ChangeBound,
    ImplausibleCalibrationError,
    InsufficientDataError,
    Plausibility,
    fit_plausibility,
    implausible_noise,
    stated_noise,
    target_scale,
)
from kinfw.identification.problem import NoiseModel
from kinfw.measurements import (
    Measurements,
    check_against_robot,
    check_measurements,
    drop_duplicate_samples,
)
from kinfw.model import STANDARD_GRAVITY, ModelSpec, PriorScales, Robot, check_robot
from kinfw.records import CalibrationReport, ModelSummary
from kinfw.urdf import OriginChange, origin_changes
from kinfw.verification.evaluation import ModelChoice
from kinfw.verification.reporting._guard import (
    guard_summary,
    implausible_message,
    nominal_misfit,
)
from kinfw.verification.reporting._report import calibration_report, file_sha256, sidecar

#: Pixel residuals worth a second look: an estimated pixel noise above this (px), or more
#: than :data:`SUSPECT_FRACTION` of the image points rejected as gross errors. Corner and
#: dot detectors reach a few tenths of a pixel with calibrated intrinsics; at 2 px the
#: nominal Kinect intrinsics of industrial_calibration's real circle grid (1.53 px) went
#: unchecked, though refining them predicts held-out images 3.40 -> 2.36 px and moves the
#: camera mount by 24 mm (``benchmarks/bench_circles_real.py``). Checking costs a second
#: fit; the significance test below keeps exact intrinsics silent whatever the noise.
SUSPECT_PIXEL_SIGMA_PX = 1.0
SUSPECT_FRACTION = 0.05
#: Refining the intrinsics must lower the pixel noise by this factor to be named a cause.
MATERIAL_RATIO = 1.1


@dataclass(frozen=True, slots=True)
class IntrinsicsEvidence:
    """Whether refined intrinsics explain large pixel residuals: the same calibration
    with every camera's intrinsics refined, compared (:func:`intrinsics_evidence`).

    Attributes
    ----------
    sigma_px : float
        Pixel noise of the calibration with the intrinsics as given, px (the estimated
        sigma, or the stated one times the root of the reduced chi-square).
    refined_sigma_px : float
        The same with the intrinsics refined, px.
    parameters : int
        Intrinsic parameters the refit freed.
    rows : int
        Pixel residual rows (two per image point).
    suspect : str
        What made the residuals suspect (the noise, the rejected points).
    moved : OriginChange or None
        The joint origin the refit moved most against the calibration's URDF (a camera's
        mount, typically): how much the geometry depends on the intrinsics, beyond the
        fit's own uncertainty, which takes them as exact. None when nothing moved.
    """

    sigma_px: float
    refined_sigma_px: float
    parameters: int
    rows: int
    suspect: str
    moved: OriginChange | None = None

    @property
    def chi2_drop(self) -> float:
        """The drop of the pixel chi-square (in the refined fit's noise) that freeing the
        intrinsics buys, ``rows (sigma^2 / refined^2 - 1)``."""
        return self.rows * ((self.sigma_px / self.refined_sigma_px) ** 2 - 1.0)

    @property
    def significant(self) -> bool:
        """The drop is beyond chance (a chi-square with :attr:`parameters` degrees of
        freedom plus 5 of its standard deviations) and material (the pixel noise falls by
        :data:`MATERIAL_RATIO`)."""
        k = self.parameters
        chance = k + 5.0 * math.sqrt(2.0 * k)
        return self.chi2_drop > chance and self.sigma_px > MATERIAL_RATIO * self.refined_sigma_px

    def message(self) -> str:
        """One line with the evidence, for a significant result."""
        moved = (
            ""
            if self.moved is None
            else f" and moves {self.moved.joint} by {self.moved.shift_m * 1e3:.3g} mm / "
            f"{np.degrees(self.moved.turn_rad):.3g} deg"
        )
        return (
            f"the image points' residuals are large ({self.suspect}) and refining the "
            f"camera intrinsics ({self.parameters} parameters) lowers the pixel noise from "
            f"{self.sigma_px:.3g} to {self.refined_sigma_px:.3g} px{moved}: the intrinsics "
            "are probably wrong; calibrate with --refine-intrinsics (or check the --camera "
            "files)"
        )


def intrinsics_evidence(
    nominal: Robot,
    data: Measurements,
    result: Calibration,
    *,
    parameters: str | tuple[str, ...],
    prior: PriorScales | None,
    noise: NoiseModel | None,
    loss: str,
) -> IntrinsicsEvidence | None:
    """When the pixel residuals of ``result`` are suspect (an estimated pixel noise above
    :data:`SUSPECT_PIXEL_SIGMA_PX`, or more than :data:`SUSPECT_FRACTION` of the image
    points rejected) and its intrinsics were fixed, refit with every
    camera's intrinsics refined and compare; None otherwise (no image points, intrinsics
    refined, residuals not suspect, or the refit refused).

    Large pixel residuals alone do not blame the intrinsics: a noisy detector or wrong
    robot poses make them too, and refined intrinsics then explain little.
    """
    from kinfw.identification import identify

    ref = result.refined
    n_points = sum(len(g.sample) for g in data.groups("pixels"))
    if ref is None or n_points == 0 or "pixel" not in dict(ref.noise.sigmas):
        return None
    if _intrinsics_freed(ref):
        return None
    sigma = ref.noise.of("pixel") * math.sqrt(ref.sigma_hat2)
    # rejected only: the robust loss down-weights ~7 % of clean image points (a 2-D
    # residual beyond its threshold), so down-weighted ones are no evidence
    off = sum(r.kind == "pixels" for r in ref.rejected)
    if off > SUSPECT_FRACTION * n_points:
        suspect = f"{off} of {n_points} image points rejected"
    elif ref.noise.estimated and sigma > SUSPECT_PIXEL_SIGMA_PX:
        suspect = f"estimated pixel noise {sigma:.3g} px"
    else:
        return None
    progress.stage("intrinsics check: the calibration with the intrinsics refined")
    with warnings.catch_warnings():  # the data's warnings came with the calibration
        warnings.simplefilter("ignore", UserWarning)
        try:
            refit = identify(
                nominal,
                data,
                parameters=parameters,
                prior=prior,
                noise=noise,
                loss=loss,
                refine_intrinsics=True,
            )
        except ValueError:
            return None
    alt = refit.refined
    moved = origin_changes(
        Robot(result.urdf_xml, "<calibrated>"), Robot(refit.urdf_xml, "<intrinsics refined>")
    )
    return IntrinsicsEvidence(
        sigma,
        alt.noise.of("pixel") * math.sqrt(alt.sigma_hat2),
        _intrinsics_freed(alt),
        2 * n_points,
        suspect,
        moved[0] if moved else None,
    )


def _intrinsics_freed(refined) -> int:
    """The intrinsic parameters a refinement estimated."""
    return sum(
        n.owner.startswith("intrinsics") and bool(f)
        for n, f in zip(refined.parameter_names, refined.free, strict=True)
    )


@dataclass(frozen=True, slots=True, eq=False)
class CalibrationResult:
    """A calibration with its report, not yet written (:func:`calibrate_and_report`).

    Attributes
    ----------
    robot : Robot
        The calibrated robot (its ``source`` is ``"<calibrated>"``).
    urdf_xml : str
        The calibrated URDF: the nominal one with only joint origins and axes changed.
    report : CalibrationReport
        What ``kinfw calibrate --report`` writes; its ``sidecar`` is None until
        :meth:`write` (which returns the report with it).
    calibration : Calibration
        The pipeline's result (stages, closed form, hand-eye, refinement).
    model : ModelSummary
        The parameter set and prior fitted, and why (``"given"`` or the model choice's
        reason); recorded in the sidecar.
    choice : ModelChoice or None
        The model choice, when the parameter set was chosen (``parameters="auto"``).
    intrinsics : IntrinsicsEvidence or None
        Whether refined intrinsics explain suspect pixel residuals (a significant one is
        also warned about and noted in the report); None when nothing was suspect.
    nominal : Robot
        The robot calibrated.
    inputs : mapping of str to str
        The files read (nominal URDF, data, held-out data) that :meth:`write` refuses to
        overwrite; in-memory sources (``"<...>"``) are skipped.
    plausibility : Plausibility or None
        The plausibility guard's verdict on the calibrated URDF (its record is the
        report's ``guard``).
    refusal : str or None
        The guard's error when a change is beyond its bound and large changes were not
        allowed: :meth:`write` raises it before writing anything. None otherwise.
    gravity : ndarray, shape (3,), or None
        The data's gravity (root frame, m/s^2) when not the standard one: recorded in the
        sidecar for what deflects a compliance later (``kinfw reach``).
    """

    robot: Robot
    urdf_xml: str
    report: CalibrationReport
    calibration: Calibration
    model: ModelSummary
    choice: ModelChoice | None
    intrinsics: IntrinsicsEvidence | None
    nominal: Robot
    inputs: Mapping[str, str]
    plausibility: Plausibility | None = None
    refusal: str | None = None
    gravity: NDArray[np.float64] | None = None

    def write(self, path: str | Path) -> CalibrationReport:
        """Write the calibrated URDF to ``path`` and its sidecar beside it
        (``<stem>.kinfw.json``, :func:`kinfw.files.sidecar_path`) and, with a model spec
        (compliance...), the per-joint YAML of what no URDF holds (``<stem>.joints.yaml``,
        :func:`kinfw.records.joint_model_text`), each atomically
        (:func:`kinfw.files.write_text_atomic`), after checking both paths.

        Returns
        -------
        CalibrationReport
            :attr:`report` with ``sidecar`` set to the sidecar's path.

        Raises
        ------
        kinfw.files.OutputPathError
            Before anything is written: a path is one of :attr:`inputs`, or cannot be
            written (missing directory, a directory, not writable).
        kinfw.identification.checks.ImplausibleCalibrationError
            Before anything is written: the plausibility guard tripped (:attr:`refusal`)
            and large changes were not allowed.
        """
        from kinfw.records import joint_model_path, joint_model_text, write_sidecar
        from kinfw.urdf import write_urdf

        if self.refusal is not None:
            raise ImplausibleCalibrationError(self.refusal)
        path = Path(path)
        outputs = {"URDF": path, "sidecar": sidecar_path(path)}
        if self.robot.spec:
            outputs["per-joint YAML"] = joint_model_path(path)
        check_outputs(outputs, inputs=self.inputs)
        nominal_path = None if self.nominal.source.startswith("<") else self.nominal.source
        side = sidecar(
            self.report,
            self.calibration,
            nominal_path=nominal_path,
            calibrated_path=path,
            model=self.model,
            guard=self.report.guard,
        )
        write_urdf(path, self.urdf_xml)
        side = replace(side, calibrated_urdf_sha256=file_sha256(path), gravity=self.gravity)
        write_sidecar(sidecar_path(path), side)
        if side.robot_blocks:
            write_text_atomic(joint_model_path(path), joint_model_text(side.robot_blocks, path))
        return replace(self.report, sidecar=str(sidecar_path(path)))


def _model_choice(
    nominal: Robot,
    data: Measurements,
    parameters: str | tuple[str, ...],
    prior: PriorScales | None,
    *,
    method: str,
    noise: NoiseModel | None,
    loss: str,
) -> tuple[str | tuple[str, ...], PriorScales | None, ModelChoice | None]:
    """``(parameters, prior, choice)``: with ``parameters="auto"`` and the refinement,
    the set and prior of :func:`kinfw.verification.evaluation.choose_parameters`;
    ``"auto"`` without the refinement is ``"full"``; given ones are kept (choice None)."""
    if parameters != "auto":
        return parameters, prior, None
    if method != "refine":
        return "full", prior, None
    from kinfw.verification.evaluation import choose_parameters

    progress.stage("model choice: the parameter set and prior")
    choice = choose_parameters(nominal, data, noise=noise, loss=loss, prior=prior)
    progress.stage(f"model choice: {choice.label}")
    return choice.parameters, choice.prior, choice


def shared_configurations(data: Measurements, held_out: Measurements) -> int:
    """How many samples of ``held_out`` have exactly (to 1e-12) the joint values of a
    sample of ``data``, on the joints both record; 0 when they share no joint."""
    names = [n for n in held_out.joint_names if n in data.joint_names]
    if not names or data.n_samples == 0:
        return 0
    train = {tuple(q) for q in np.round(data.q_of(names), 12).tolist()}
    return sum(tuple(q) in train for q in np.round(held_out.q_of(names), 12).tolist())


#: Held-out errors this many times the in-sample ones (same group, first metric) say the
#: held-out file is probably not of this robot and setup (:func:`_warn_far_held_out`):
#: held-out data of the same setup come at most a few times the in-sample error (the
#: parameters' share, sqrt(1 + p / n), and an overfit small set).
FAR_HELD_OUT = 10.0


def _warn_far_held_out(report: CalibrationReport, source: str) -> None:
    """Warn when the calibration predicts a held-out group :data:`FAR_HELD_OUT` times
    worse than the same group in-sample: another robot's or setup's file (markers, a
    plane, a board elsewhere) scores as if it were this one's."""
    inside = {row.group: row for row in report.errors_in_sample}
    for row in report.errors_held_out or ():
        same = inside.get(row.group)
        if same is None or not row.after or not same.after:
            continue
        held, fit = row.after[0], same.after[0]
        if fit.value > 0 and held.value > FAR_HELD_OUT * fit.value:
            warnings.warn(
                f"{source}: {row.group}: the held-out error after calibration is "
                f"{held.value / fit.value:.3g} times the calibration data's ({held.value:.3g} "
                f"vs {fit.value:.3g} {held.unit}): is it of this robot and setup (the same "
                "markers, plane, board and measurement frame)?",
                UserWarning,
                stacklevel=3,
            )


def _warn_overlap(data: Measurements, held_out: Measurements) -> None:
    """Warn when held-out samples repeat calibration samples' joint values: if they are
    the same measurements, their errors are in-sample, not held-out."""
    shared = shared_configurations(data, held_out)
    if shared == 0:
        return
    what = (
        "every held-out sample has"
        if shared == held_out.n_samples
        else f"{shared} of {held_out.n_samples} held-out samples have"
    )
    warnings.warn(
        f"{held_out.source}: {what} the joint values of a calibration sample of "
        f"{data.source}: if they are the same measurements, their errors are in-sample, "
        "not held-out (hold out samples the calibration never saw)",
        UserWarning,
        stacklevel=3,
    )


def _fitted(
    nominal: Robot,
    data: Measurements,
    parameters: str | tuple[str, ...],
    prior: PriorScales | None,
    choice: ModelChoice | None,
    *,
    method: str,
    noise: NoiseModel | None,
    loss: str,
    refine_intrinsics: bool | tuple[str, ...],
) -> tuple[Calibration, ModelChoice | None]:
    """The calibration with the chosen (or given) ``parameters`` and ``prior``, and the
    model choice it came from: the choice's own fit when it has one; a refusal of given
    parameters names what the data determine; a refusal of ``"full"`` that ``"auto"``
    chose unscored (plentiful data) falls back to the scored choice."""
    from kinfw.identification import identify

    if choice is not None and choice.fit is not None and not refine_intrinsics:
        return choice.fit, choice  # the chosen candidate, fitted on all the data
    options = dict(method=method, noise=noise, loss=loss, refine_intrinsics=refine_intrinsics)
    try:
        return identify(nominal, data, parameters=parameters, prior=prior, **options), choice
    except InsufficientDataError as exc:
        if method != "refine" or (choice is not None and choice.k > 0):
            raise
        if choice is None:  # given parameters: refused, with what the data determine
            raise InsufficientDataError(
                f"{exc}{_determined_candidates(nominal, data, noise=noise, loss=loss)}"
            ) from exc
        choice = _scored_choice(nominal, data, exc, noise=noise, loss=loss, prior=prior)
    if choice.fit is not None and not refine_intrinsics:
        return choice.fit, choice
    fit = identify(nominal, data, parameters=choice.parameters, prior=choice.prior, **options)
    return fit, choice


def _scored_choice(
    nominal: Robot,
    data: Measurements,
    refusal: InsufficientDataError,
    *,
    noise: NoiseModel | None,
    loss: str,
    prior: PriorScales | None,
) -> ModelChoice:
    """The model choice scored by cross-validation on data whose rows would choose
    ``"full"`` unscored but which refuse it (``refusal``), said in a warning and in its
    reason."""
    from kinfw.verification.evaluation import choose_parameters

    progress.stage("model choice: full refused; scoring the candidates")
    choice = choose_parameters(
        nominal, data, noise=noise, loss=loss, prior=prior, cross_validate=True
    )
    why = str(refusal).replace(f"{data.source}: ", "").split(": the exported")[0]
    warnings.warn(
        f"{data.source}: --params auto: {why}; chose {choice.label} by leave-one-out "
        "cross-validation instead",
        UserWarning,
        stacklevel=3,
    )
    progress.stage(f"model choice: {choice.label}")
    return dataclasses.replace(choice, reason=f"full refused ({why}); {choice.reason}")


def _determined_candidates(
    nominal: Robot, data: Measurements, *, noise: NoiseModel | None, loss: str
) -> str:
    """For a refusal of given parameters: the model choice's candidates these data
    determine, best held-out first (``"; determined by these data, ..."``), or ``""``
    when none is or the choice cannot run."""
    from kinfw.verification.evaluation import choose_parameters

    progress.stage("too little data: which parameter sets these data determine")
    try:
        choice = choose_parameters(nominal, data, noise=noise, loss=loss, cross_validate=True)
    except ValueError:
        return ""
    scored = sorted((c for c in choice.candidates if c.failed is None), key=lambda c: c.whitened)
    if not scored:
        return ""
    best = ", ".join(f"{_options(c.parameters, c.prior)} ({c.whitened:.3g})" for c in scored[:4])
    more = f" and {len(scored) - 4} more" if len(scored) > 4 else ""
    return (
        f"; the models these data determine, by leave-one-out held-out error (whitened), "
        f"best first: {best}{more} (--params auto chooses the best)"
    )


def _options(parameters: str, prior: PriorScales | None) -> str:
    """The command-line options that fit ``parameters`` with ``prior``."""
    if prior is None:
        return f"--params {parameters}"
    return f"--params {parameters} {prior.options}"


def calibrate_and_report(
    nominal: Robot,
    data: Measurements,
    *,
    parameters: str | tuple[str, ...] = "auto",
    method: str = "refine",
    noise: NoiseModel | None = None,
    loss: str = "huber",
    prior: PriorScales | tuple[float, float] | None = None,
    held_out: Measurements | None = None,
    refine_intrinsics: bool | tuple[str, ...] = (),
    data_path: str | Path | None = None,
    keep_duplicates: bool = False,
    change_bound: ChangeBound | None = None,
    allow_large_changes: bool = False,
    model: ModelSpec | Sequence[str] | None = None,
) -> CalibrationResult:
    """Calibrate ``nominal`` from ``data`` as ``kinfw calibrate`` does (the same
    defaults), and report: :func:`kinfw.calibrate`.

    Parameters
    ----------
    nominal : Robot
        The nominal robot (:func:`kinfw.load_robot`).
    data : Measurements
        The calibration data (:func:`kinfw.read_measurements`); errors on it are
        in-sample.
    parameters : str or tuple of str
        ``"auto"`` (default, ``--params auto``): ``"full"`` when the data have at least
        :data:`kinfw.verification.evaluation.ROWS_PER_PARAMETER` residual rows per
        parameter, else the set and prior with the lowest leave-one-out held-out
        error (:func:`kinfw.verification.evaluation.choose_parameters`; the choice goes to the
        report's notes and the sidecar). Or a set: ``"full"``, ``"offsets"``,
        ``"frames"``, ``"none"``, or a mask (see :func:`kinfw.identification.refine`).
    method : {"refine", "closed-form"}
        ``"closed-form"`` stops after the closed form and hand-eye (``"auto"`` is then
        ``"full"``).
    noise : NoiseModel, optional
        Measurement noise; default estimated from the residuals.
    loss : {"huber", "linear", "cauchy"}
        Robust loss of the refinement.
    prior : PriorScales or (float, float), optional
        A Gaussian prior on the deviations from the nominal, one sigma per parameter
        group (:class:`kinfw.model.PriorScales`; a pair ``(sigma_m, sigma_rad)``: one
        length and one angle sigma); with ``parameters="auto"`` no prior is then chosen.
    held_out : Measurements, optional
        Data not used for calibration; its errors go to the report and the sidecar.
        Samples with a calibration sample's exact joint values are warned about
        (:func:`shared_configurations`).
    refine_intrinsics : bool or tuple of str
        Also estimate the intrinsics of these cameras (True: every camera).
    data_path : path, optional
        The file ``data`` was read from, recorded with its SHA-256.
    keep_duplicates : bool
        Keep the samples that repeat an earlier one (``--keep-duplicates``). By default
        they are dropped before anything else, with one ``UserWarning`` naming them
        (:func:`kinfw.measurements.drop_duplicate_samples`): a sample recorded twice
        would count twice and shrink every sigma by 1/sqrt(2).
    change_bound : ChangeBound, optional
        The plausibility guard's rule (default
        :class:`kinfw.identification.checks.ChangeBound`: the larger of 5 x the prior
        and 20 mm / 2 deg, a move never above 5 % of the robot's size).
    allow_large_changes : bool
        Write a calibration beyond the guard's bound knowingly (``--allow-large-changes``):
        warned about, and the report and sidecar say so.
    model : ModelSpec or sequence of str, optional
        Robot blocks the URDF cannot hold, estimated with it (``--model``: ``"compliance"``,
        ``"gear-scale:JOINT"``, ``"coupling:JOINT=K*OTHER"``; :class:`kinfw.model.ModelSpec`);
        default ``nominal``'s own (:attr:`kinfw.model.Robot.spec`, empty for a URDF). The
        calibrated robot carries their estimates (:attr:`CalibrationResult.robot`'s
        ``spec``), the sidecar records them, and the errors are predicted with them.

    Returns
    -------
    CalibrationResult
        The calibrated robot and URDF, the report; :meth:`CalibrationResult.write`
        writes the URDF and sidecar, or raises the guard's error
        (:attr:`CalibrationResult.refusal`) when a joint origin, a mount or a stance
        link's pose in the root changed beyond the bound.

    Raises
    ------
    TypeError
        ``nominal``, ``data`` or ``held_out`` is not a Robot / Measurements (a path:
        load it first), naming the argument.
    """
    nominal, data, held_out = _checked_inputs(nominal, data, held_out, model, keep_duplicates)
    parameters, prior, choice = _model_choice(
        nominal, data, parameters, PriorScales.of(prior), method=method, noise=noise, loss=loss
    )
    if choice is not None and choice.spec:  # the model choice added a compliance
        nominal = nominal.with_spec(choice.spec)
    result, choice = _fitted(
        nominal,
        data,
        parameters,
        prior,
        choice,
        method=method,
        noise=noise,
        loss=loss,
        refine_intrinsics=refine_intrinsics,
    )
    if choice is not None:
        parameters, prior = choice.parameters, choice.prior
    evidence = None
    if method == "refine" and not refine_intrinsics:
        evidence = intrinsics_evidence(
            nominal, data, result, parameters=parameters, prior=prior, noise=noise, loss=loss
        )
    calibrated = Robot(result.urdf_xml, "<calibrated>", spec=result.spec)
    progress.stage("report: errors after each stage")
    report = calibration_report(
        nominal,
        calibrated,
        data,
        result,
        method=method,
        loss=loss,
        data_path=data_path,
        held_out=held_out,
    )
    if held_out is not None:
        _warn_far_held_out(report, held_out.source)
    if choice is not None:  # the choice goes to the report's notes (and the sidecar)
        report = dataclasses.replace(
            report, notes=(*report.notes, f"parameters: {choice.label} ({choice.reason})")
        )
    # full alone is warned about in the fit, unless it is a scored candidate of the model
    # choice (whose warnings the choice silences; an unscored choice's fit warns)
    candidate = choice is not None and result is choice.fit and bool(choice.candidates)
    restricted = parameters != "full" or prior is not None or candidate
    report, verdict, refusal = _guarded(
        nominal,
        calibrated,
        data,
        report,
        prior,
        bound=change_bound,
        allowed=allow_large_changes,
    )
    _warn_fit(
        nominal,
        calibrated,
        data,
        result,
        restricted=restricted,
        given=(parameters, prior) if choice is None and method == "refine" else None,
        noise=noise,
    )
    if evidence is not None and evidence.significant:
        warnings.warn(f"{data.source}: {evidence.message()}", UserWarning, stacklevel=2)
        report = dataclasses.replace(report, notes=(*report.notes, evidence.message()))
    model = ModelSummary(
        (parameters,) if isinstance(parameters, str) else tuple(parameters),
        PriorScales.of(prior),
        "given" if choice is None else choice.reason,
        tuple(b.block_name for b in calibrated.spec.blocks),
    )
    sources = {"nominal URDF": nominal.source, "data": data.source}
    if held_out is not None:
        sources["held-out data"] = held_out.source
    return CalibrationResult(
        calibrated,
        result.urdf_xml,
        report,
        result,
        model,
        choice,
        evidence,
        nominal,
        sources,
        verdict,
        refusal,
        None if np.array_equal(data.gravity, STANDARD_GRAVITY) else data.gravity,
    )


def _checked_inputs(
    nominal: Robot,
    data: Measurements,
    held_out: Measurements | None,
    model: ModelSpec | Sequence[str] | None,
    keep_duplicates: bool,
) -> tuple[Robot, Measurements, Measurements | None]:
    """:func:`calibrate_and_report`'s inputs checked before any fit: the robot (with
    ``model``'s blocks), the data without repeated samples (unless kept), the held-out
    data against the robot and the data."""
    nominal = check_robot(nominal, "nominal")
    data = check_measurements(data, "data")
    if model is not None:
        nominal = nominal.with_spec(
            model if isinstance(model, ModelSpec) else ModelSpec.parse(model)
        )
    if not keep_duplicates:
        data = drop_duplicate_samples(data, stacklevel=4)
    held_out = None if held_out is None else check_measurements(held_out, "held_out")
    if held_out is not None:
        check_against_robot(held_out, nominal)  # its frames and joints, before any fit
        _warn_overlap(data, held_out)
    return nominal, data, held_out


def _warn_fit(
    nominal: Robot,
    calibrated: Robot,
    data: Measurements,
    result: Calibration,
    *,
    restricted: bool,
    given: tuple | None,
    noise: NoiseModel | None,
) -> None:
    """The warnings of :func:`calibrate_and_report` about a finished fit: a restricted
    model's implausible or misstated noise, residuals that follow the gravity torque
    under given parameters (``given``: their set and prior), a target of the wrong size."""
    refined = result.refined
    implausible = implausible_noise(refined, data) if restricted and refined else None
    if implausible:
        warnings.warn(f"{data.source}: {implausible}", UserWarning, stacklevel=3)
    for line in stated_noise(refined, data) if restricted and refined else ():
        warnings.warn(f"{data.source}: {line}", UserWarning, stacklevel=3)
    if given is not None and not nominal.spec:
        from kinfw.verification.evaluation import missing_compliance

        hint = missing_compliance(nominal, data, result, given, noise)
        if hint:
            warnings.warn(f"{data.source}: {hint}", UserWarning, stacklevel=3)
    for scale in target_scale(nominal, calibrated, data):
        if scale.off:
            warnings.warn(f"{data.source}: {scale.message()}", UserWarning, stacklevel=3)


def _guarded(
    nominal: Robot,
    calibrated: Robot,
    data: Measurements,
    report: CalibrationReport,
    prior: PriorScales | None,
    *,
    bound: ChangeBound | None,
    allowed: bool,
) -> tuple[CalibrationReport, Plausibility, str | None]:
    """The plausibility guard on a calibration: ``(report, verdict, refusal)``, the
    report with the guard's record (and, when large changes were allowed, a note and a
    warning that say so), the verdict, and the error :meth:`CalibrationResult.write`
    raises (None when plausible or allowed)."""
    verdict = fit_plausibility(nominal, calibrated, data, prior, bound=bound)
    report = dataclasses.replace(report, guard=guard_summary(verdict, prior, allowed=allowed))
    if verdict.plausible:
        return report, verdict, None
    message = implausible_message(
        data.source,
        nominal,
        verdict,
        misfit=nominal_misfit(report.errors_in_sample, verdict),
        refine=report.refine,
    )
    if not allowed:
        return report, verdict, message
    top = verdict.beyond[0]
    note = (
        f"large changes allowed (--allow-large-changes): {top.text()}, beyond the bound "
        f"{verdict.bound_text()}"
    )
    warnings.warn(f"{data.source}: {note}", UserWarning, stacklevel=3)
    return dataclasses.replace(report, notes=(*report.notes, note)), verdict, None
