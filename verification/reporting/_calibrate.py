"""The calibration workflow of ``kinfw calibrate`` and :func:`kinfw.calibrate`: the model
choice (when no parameter set is given), the pipeline, the report; then, on request, the
calibrated URDF and its sidecar written together.

:func:`calibrate_and_report` computes everything and writes nothing; the returned
:class:`CalibrationResult` writes the URDF and the sidecar with
:meth:`CalibrationResult.write`, after checking that neither is an input.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

from kinfw import progress
from kinfw.files import check_outputs, sidecar_path
from kinfw.identification import Calibration
from kinfw.identification.problem import NoiseModel
from kinfw.measurements import Measurements, check_measurements
from kinfw.model import Robot, check_robot
from kinfw.reports import CalibrationReport, ModelSummary
from kinfw.verification.evaluation import ModelChoice
from kinfw.verification.reporting._report import calibration_report, sidecar

__all__ = ["CalibrationResult", "calibrate_and_report"]


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
    nominal : Robot
        The robot calibrated.
    inputs : mapping of str to str
        The files read (nominal URDF, data, held-out data) that :meth:`write` refuses to
        overwrite; in-memory sources (``"<...>"``) are skipped.
    """

    robot: Robot
    urdf_xml: str
    report: CalibrationReport
    calibration: Calibration
    model: ModelSummary
    choice: ModelChoice | None
    nominal: Robot
    inputs: Mapping[str, str]

    def write(self, path: str | Path) -> CalibrationReport:
        """Write the calibrated URDF to ``path`` and its sidecar beside it
        (``<stem>.kinfw.json``, :func:`kinfw.files.sidecar_path`), each atomically
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
        """
        from kinfw.reports import write_sidecar
        from kinfw.urdf import write_urdf

        path = Path(path)
        check_outputs({"URDF": path, "sidecar": sidecar_path(path)}, inputs=self.inputs)
        nominal_path = None if self.nominal.source.startswith("<") else self.nominal.source
        side = sidecar(
            self.report,
            self.calibration,
            nominal_path=nominal_path,
            calibrated_path=path,
            model=self.model,
        )
        write_urdf(path, self.urdf_xml)
        write_sidecar(sidecar_path(path), side)
        return replace(self.report, sidecar=str(sidecar_path(path)))


def _model_choice(
    nominal: Robot,
    data: Measurements,
    parameters: str | tuple[str, ...],
    prior: tuple[float, float] | None,
    *,
    method: str,
    noise: NoiseModel | None,
    loss: str,
) -> tuple[str | tuple[str, ...], tuple[float, float] | None, ModelChoice | None]:
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


def calibrate_and_report(
    nominal: Robot,
    data: Measurements,
    *,
    parameters: str | tuple[str, ...] = "auto",
    method: str = "refine",
    noise: NoiseModel | None = None,
    loss: str = "huber",
    prior: tuple[float, float] | None = None,
    held_out: Measurements | None = None,
    refine_intrinsics: bool | tuple[str, ...] = (),
    data_path: str | Path | None = None,
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
    prior : (float, float), optional
        ``(sigma_m, sigma_rad)`` of a Gaussian prior on the deviations from the nominal.
    held_out : Measurements, optional
        Data not used for calibration; its errors go to the report and the sidecar.
    refine_intrinsics : bool or tuple of str
        Also estimate the intrinsics of these cameras (True: every camera).
    data_path : path, optional
        The file ``data`` was read from, recorded with its SHA-256.

    Returns
    -------
    CalibrationResult
        The calibrated robot and URDF, the report; :meth:`CalibrationResult.write`
        writes the URDF and sidecar.

    Raises
    ------
    TypeError
        ``nominal``, ``data`` or ``held_out`` is not a Robot / Measurements (a path:
        load it first), naming the argument.
    """
    from kinfw.identification import calibrate

    nominal = check_robot(nominal, "nominal")
    data = check_measurements(data, "data")
    held_out = None if held_out is None else check_measurements(held_out, "held_out")
    parameters, prior, choice = _model_choice(
        nominal, data, parameters, prior, method=method, noise=noise, loss=loss
    )
    if choice is not None and choice.fit is not None and not refine_intrinsics:
        result = choice.fit  # the chosen candidate, fitted on all the data with these options
    else:
        result = calibrate(
            nominal,
            data,
            method=method,
            noise=noise,
            loss=loss,
            parameters=parameters,
            prior=prior,
            refine_intrinsics=refine_intrinsics,
        )
    calibrated = Robot(result.urdf_xml, "<calibrated>")
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
    if choice is not None:  # the choice goes to the report's notes (and the sidecar)
        report = dataclasses.replace(
            report, notes=(*report.notes, f"parameters: {choice.label} ({choice.reason})")
        )
    model = ModelSummary(
        (parameters,) if isinstance(parameters, str) else tuple(parameters),
        None if prior is None else float(prior[0]),
        None if prior is None else float(prior[1]),
        "given" if choice is None else choice.reason,
    )
    sources = {"nominal URDF": nominal.source, "data": data.source}
    if held_out is not None:
        sources["held-out data"] = held_out.source
    return CalibrationResult(
        calibrated, result.urdf_xml, report, result, model, choice, nominal, sources
    )
