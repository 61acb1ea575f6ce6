"""Calibration reports: before/after errors and the identified parameters, as JSON-ready
dictionaries (SI inside; field names say mm or deg where a value is not SI)."""

from __future__ import annotations

import datetime as _dt
import hashlib
from pathlib import Path

import numpy as np

from identification.closed_form import ClosedFormResult
from kinfw.measurements import Measurements
from kinfw.robot import Robot
from kinfw.urdf_export import ExportResult
from verification.accuracy import evaluate_model

__all__ = ["before_after_rows", "calibration_report", "errors_by_group", "file_sha256"]


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (provenance of the input data)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def errors_by_group(robot: Robot, data: Measurements) -> dict[str, dict]:
    """Errors of ``robot`` on ``data`` keyed "frame (kind)" (see evaluate_model)."""
    report = evaluate_model(robot, data)
    return {f"{g['frame']} ({g['kind']})": g for g in report.to_dict()["groups"]}


def before_after_rows(before: dict[str, dict], after: dict[str, dict]) -> list[dict]:
    """Per observation group: RMS position (mm) and rotation (deg) before and after."""
    return [
        {"group": key,
         "n": before[key]["n"],
         "before_position_rms_mm": before[key]["position_rms_mm"],
         "after_position_rms_mm": after[key]["position_rms_mm"],
         "before_rotation_rms_deg": before[key]["rotation_rms_deg"],
         "after_rotation_rms_deg": after[key]["rotation_rms_deg"]}
        for key in before
    ]


def calibration_report(nominal: Robot, calibrated: Robot, data: Measurements,
                       result: ClosedFormResult, export: ExportResult, *,
                       method: str, data_path: str | Path | None = None,
                       held_out: Measurements | None = None) -> dict:
    """Everything a user needs to trust (or not) a calibration, as a dictionary.

    Parameters
    ----------
    nominal, calibrated : Robot
        The URDF before and after (the exported file, re-loaded).
    data : Measurements
        The calibration data; the errors on it are in-sample.
    result : ClosedFormResult
        The identification, for its parameters and diagnostics.
    export : ExportResult
        The export, for the measurement frame pose and moved link frames.
    method : str
    data_path : path, optional
        Recorded with its SHA-256.
    held_out : Measurements, optional
        Samples not used for calibration; their errors are the honest accuracy.
    """
    model = result.model
    before, after = errors_by_group(nominal, data), errors_by_group(calibrated, data)
    report = {
        "format": "kinfw-calibration-report", "version": 1,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "method": method,
        "nominal_urdf": nominal.source,
        "data": {"source": data.source, "n_samples": data.n_samples,
                 "sha256": file_sha256(data_path) if data_path else None},
        "errors_in_sample": before_after_rows(before, after),
        "errors_before": before,
        "errors_after": after,
        "closed_form": {
            "joint_names": list(model.topology.joint_names),
            "q0": result.q0.tolist(),
            "samples_per_joint": result.group_sizes.tolist(),
            "axis_residual_rad": [None if np.isnan(v) else float(v)
                                  for v in result.axis_residual_rad],
            "motion_per_unit_joint_value": result.motion_scale.tolist(),
            "position_rms_mm": 1e3 * result.position_rms_m,
        },
        "parameters": {
            "note": "canonical CPC parameters (Shih et al. eqs. 3-4, Table 1 gauge): per joint "
                    "the axis b of its frame in its parent's moved frame, beta, l (m) and the "
                    "motion sense; per end frame its pose in the moved frame of its last "
                    "joint (m, URDF rpy in rad)",
            "values": [{"owner": o, "name": n, "value": v} for o, n, v in model.describe()],
            "n_identifiable": model.n_parameters,
        },
        "export": {
            "w_T_root": export.w_T_root.tolist(),
            "moved_link_frames": [
                {"link": link, "shift_mm": 1e3 * float(np.linalg.norm(T[:3, 3]))}
                for link, T in export.link_shifts],
        },
    }
    if held_out is not None:
        report["errors_held_out"] = before_after_rows(errors_by_group(nominal, held_out),
                                                      errors_by_group(calibrated, held_out))
    return report
