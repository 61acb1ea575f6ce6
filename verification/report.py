"""Calibration reports: before/after errors and the identified parameters, as JSON-ready
dictionaries (SI inside; field names say mm or deg where a value is not SI)."""

from __future__ import annotations

import datetime as _dt
import hashlib
from pathlib import Path

import numpy as np
import pinocchio as pin

from identification.cameras import CamerasResult
from identification.closed_form import ClosedFormResult
from identification.pipeline import Calibration
from identification.refine import RefineResult, parameter_unit
from kinfw.files import atomic_path
from kinfw.measurements import Measurements
from kinfw.robot import Robot
from verification.accuracy import evaluate_model

__all__ = [
    "before_after_rows",
    "calibration_report",
    "downweighted_rows",
    "errors_by_group",
    "file_sha256",
    "plot_stage_errors",
    "sidecar",
]


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


def _closed_form_section(result: ClosedFormResult) -> dict:
    model = result.model
    return {
        "method": "CPC closed form, Shih et al. (1992) section 4",
        "joint_names": list(model.topology.joint_names),
        "frames": list(model.topology.frames),
        "q0": result.q0.tolist(),
        "samples_per_joint": result.group_sizes.tolist(),
        "axis_residual_rad": [None if np.isnan(v) else float(v)
                              for v in result.axis_residual_rad],
        "motion_per_unit_joint_value": result.motion_scale.tolist(),
        "position_rms_mm": 1e3 * result.position_rms_m,
        "parameters": {
            "note": "canonical CPC parameters (Shih et al. eqs. 3-4, Table 1 gauge): per joint "
                    "the axis b of its frame in its parent's moved frame, beta, l (m) and the "
                    "motion sense; per end frame its pose in the moved frame of its last "
                    "joint (m, URDF rpy in rad)",
            "values": [{"owner": o, "name": n, "value": v,
                        "unit": parameter_unit(o, n, model.topology)}
                       for o, n, v in model.describe()],
            "n_identifiable": model.n_parameters,
        },
    }


def _xyz_rpy(T: np.ndarray) -> dict:
    return {"xyz_m": T[:3, 3].tolist(), "rpy_rad": pin.rpy.matrixToRpy(T[:3, :3]).tolist(),
            "matrix": T.tolist()}


def _hand_eye_section(result: CamerasResult) -> dict:
    return {
        "method": "iterative A = X B Y, Hirsh, DeSouza & Kak (2001), per camera",
        "cameras": [
            {"camera": c.camera, "target": c.target, "joint": c.joint, "hand": c.hand,
             "hand_T_camera": _xyz_rpy(c.hand_T_camera), "n_views": c.n_views,
             "iterations": c.solver.iterations, "restarts": c.solver.restarts,
             "converged": c.solver.converged,
             "rms_rotation_deg": float(np.degrees(c.solver.rms_rotation_rad)),
             "rms_translation_mm": 1e3 * c.solver.rms_translation}
            for c in result.cameras],
        "targets": [
            {"target": t, "root_T_target": _xyz_rpy(T), "camera_disagreement_mm": 1e3 * dp,
             "camera_disagreement_deg": float(np.degrees(dr))}
            for (t, T), (_, dp, dr) in zip(result.root_T_targets, result.target_spread,
                                           strict=True)],
    }


def downweighted_rows(result: RefineResult) -> list[dict]:
    """The observations the robust loss down-weighted, the worst (lowest weight) first.

    Parameters
    ----------
    result : RefineResult

    Returns
    -------
    list of dict
        One per down-weighted observation: ``sample`` (index into the data file's
        ``samples``, from 0), ``kind``, ``frame`` (the camera for ``target``
        observations), ``marker`` (None without one), ``position_residual_mm`` (norm of
        measured minus predicted position), ``rotation_residual_deg`` (angle between
        measured and predicted orientation; None for points) and ``weight`` (the robust
        loss's weight, 1 = full). Sorted by weight, then sample.
    """
    rows = []
    for g in result.residuals:
        rows_g = np.flatnonzero(g.downweighted)
        position_mm = 1e3 * np.linalg.norm(g.position_m[rows_g], axis=1)
        rotation_deg = (None if g.rotation_rad is None else np.degrees(np.arcsin(np.clip(
            np.linalg.norm(g.rotation_rad[rows_g], axis=1), 0.0, 1.0))))
        rows += [{"sample": int(g.sample[k]), "kind": g.kind, "frame": g.frame,
                  "marker": g.marker, "position_residual_mm": float(position_mm[c]),
                  "rotation_residual_deg": None if rotation_deg is None
                  else float(rotation_deg[c]),
                  "weight": float(g.weight[k])}
                 for c, k in enumerate(rows_g)]
    rows.sort(key=lambda row: (row["weight"], row["sample"]))
    return rows


def _refine_section(result: RefineResult, loss: str) -> dict:
    ident = result.identifiability
    topology = result.model.topology
    return {
        "method": "joint nonlinear least squares (CasADi residuals and Jacobians, "
                  "Levenberg-Marquardt), residuals whitened by the noise below",
        "loss": loss,
        "noise": {"position_sigma_mm": 1e3 * result.noise.position_m,
                  "rotation_sigma_deg_per_component": float(np.degrees(
                      result.noise.rotation_rad)),
                  "estimated": result.noise.estimated,
                  "sigma_per_component": dict(result.noise.sigmas),
                  "note": "weights: 1/sigma^2 per position component (mm) and per "
                          "small-angle orientation component (an angle sigma of s about a "
                          "random axis is s/sqrt(3) per component)"},
        "reduced_chi_square": result.sigma_hat2,
        "iterations": result.iterations, "converged": result.converged,
        "seconds": result.seconds,
        "model_frame": result.model_frame,
        "parameters_note": "delta_from_start and std in the parameter's unit (rad, m or "
                           "unitless); fixed: not estimated (held at the start, "
                           "delta_from_start 0, std null)",
        "parameters": [
            {"owner": o, "field": f, "unit": unit,
             "fixed": not free, "delta_from_start": float(d),
             "std": float(sd) if free else None}
            for (o, f), unit, free, d, sd in zip(result.parameter_names,
                                                 result.parameter_units, result.free,
                                                 result.estimate, result.std, strict=True)],
        "kinematics": [{"owner": o, "name": n, "value": v,
                        "unit": parameter_unit(o, n, topology)}
                       for o, n, v in result.model.describe()],
        "unknowns": [{"kind": u.kind, "name": u.name, "value": u.value.tolist()}
                     for u in result.unknowns],
        "identifiability": {
            "rank": ident.rank, "n_parameters": ident.n_parameters,
            # strict JSON: an undefined (no parameters) or infinite value is null
            "condition": _finite_or_none(ident.condition),
            "observability_O1": _finite_or_none(ident.observability_o1),
            "not_identifiable": [{"parameters": [":".join(p) for p in params], "why": why}
                                 for params, why in ident.unidentifiable],
            "correlations_above_0.9": [{"a": a, "b": b, "rho": r}
                                       for a, b, r in ident.correlations]},
        "downweighted_note": "observations beyond the robust loss's threshold, the worst "
                             "(lowest weight) first; sample is the index into the data "
                             "file's samples (from 0)",
        "downweighted": downweighted_rows(result),
    }


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def calibration_report(nominal: Robot, calibrated: Robot, data: Measurements,
                       calibration: Calibration, *, method: str, loss: str = "huber",
                       data_path: str | Path | None = None,
                       held_out: Measurements | None = None) -> dict:
    """Everything a user needs to trust (or not) a calibration, as a dictionary.

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
    """
    before = errors_by_group(nominal, data)
    after = errors_by_group(calibrated, data)
    stage_rms = {"nominal": {k: v["position_rms_mm"] for k, v in before.items()}}
    for name, xml in calibration.stages:
        errors = errors_by_group(Robot(xml, name), data)
        stage_rms[name] = {k: v["position_rms_mm"] for k, v in errors.items()}
    report = {
        "format": "kinfw-calibration-report", "version": 1,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "method": method,
        "nominal_urdf": nominal.source,
        "data": {"source": data.source, "n_samples": data.n_samples,
                 "sha256": file_sha256(data_path) if data_path else None},
        "notes": list(calibration.notes),
        "errors_in_sample": before_after_rows(before, after),
        "position_rms_mm_by_stage": stage_rms,
        "errors_before": before,
        "errors_after": after,
    }
    if calibration.closed_form is not None:
        report["kinematics"] = _closed_form_section(calibration.closed_form)
    if calibration.cameras is not None:
        report["hand_eye"] = _hand_eye_section(calibration.cameras)
    if calibration.refined is not None:
        report["refine"] = _refine_section(calibration.refined, loss)
    if calibration.export is not None:
        report["export"] = {
            "w_T_root": calibration.export.w_T_root.tolist(),
            "moved_link_frames": [
                {"link": link, "shift_mm": 1e3 * float(np.linalg.norm(T[:3, 3]))}
                for link, T in calibration.export.link_shifts],
        }
    if held_out is not None:
        report["errors_held_out"] = before_after_rows(errors_by_group(nominal, held_out),
                                                      errors_by_group(calibrated, held_out))
    return report


def sidecar(report: dict, calibration: Calibration, *, nominal_path: str | Path | None,
            calibrated_path: str | Path) -> dict:
    """The provenance written beside a calibrated URDF: what produced it and what is
    needed to predict measurements that is not in the URDF (the root's pose in the
    measurement frame, target poses, markers, noise)."""
    refined = calibration.refined
    return {
        "format": "kinfw-calibration", "version": 1,
        "created": report["created"],
        "kinfw_version": _kinfw_version(),
        "method": report["method"],
        "calibrated_urdf": Path(calibrated_path).name,
        "nominal_urdf": {"path": str(nominal_path) if nominal_path else None,
                         "sha256": file_sha256(nominal_path) if nominal_path else None},
        "data": report["data"],
        "w_T_root": calibration.w_T_root.tolist(),
        "measurement_frame": None if refined is None else refined.model_frame,
        "noise": None if refined is None else report["refine"]["noise"],
        "unknowns": [] if refined is None else report["refine"]["unknowns"],
        "targets": [] if calibration.cameras is None else [
            {"target": t, "root_T_target": T.tolist()}
            for t, T in calibration.cameras.root_T_targets],
        "errors_held_out": report.get("errors_held_out"),
    }


def _kinfw_version() -> str:
    from importlib import metadata

    try:
        return metadata.version("kinfw")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def plot_stage_errors(stage_rms: dict[str, dict[str, float]], path: str | Path, *,
                      title: str = "") -> Path:
    """Grouped bars: position RMS (mm, log scale) per observation group after each stage.

    ``stage_rms`` maps a stage name ("nominal", "closed form", ...) to
    ``{"frame (kind)": rms_mm}``, as in the reports' ``*_by_stage`` entries.
    """
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
        bars = ax.bar(x + (k - (len(stages) - 1) / 2) * width, values, width, label=stage,
                      color=colours[k % len(colours)])
        ax.bar_label(bars, labels=[f"{v:.2g}" for v in values], fontsize=7, padding=1)
    ax.set_yscale("log")
    ax.set_xticks(x, groups)
    ax.set_ylabel("held-out position RMS (mm, log scale)")
    ax.grid(axis="y", which="both", alpha=0.3)
    ax.legend(title="after stage", ncols=len(stages), loc="upper center",
              bbox_to_anchor=(0.5, -0.11), frameon=False)
    if title:
        ax.set_title(title, fontsize=10)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format=path.suffix.lstrip(".") or "png")
    return path
