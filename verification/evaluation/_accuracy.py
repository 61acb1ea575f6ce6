"""Errors of a robot model against measurements: what ``kinfw verify`` reports.

For every group of observations (one frame, kind and marker) the model predicts the
measurement and the error is *measured minus predicted*:

- ``pose``: position error vector in the measurement frame and the rotation angle of
  ``predicted_R^T measured_R``;
- ``target``: the same for ``camera_T_target``, with the position error in the camera
  frame;
- ``point``: the position error vector only.

Unknown rigid frames that are not in the URDF (the target's pose, a marker's pose or
offset, the pose of the root link in a ``measured_in`` frame) are fitted in closed form
from the same data by the observation kinds' start estimators (the ones the calibration
starts from): the measurement frames from all the data, the others per group. Every such
fit is listed in :attr:`AccuracyReport.fitted`: errors are then residuals after that
fit, slightly optimistic for few samples. Rotation errors are
``arcsin`` of the orientation residual's norm (exact below 90 degrees).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.measurements import Measurements
from kinfw.model import BlockKey, Robot
from kinfw.reports import CalibrationSidecar

__all__ = ["AccuracyReport", "GroupErrors", "evaluate_model", "known_frames"]


@dataclass(frozen=True, slots=True)
class GroupErrors:
    """Errors of one observation group.

    Attributes
    ----------
    frame, kind : str
        Frame (camera for ``target``) and observation kind.
    marker : str or None
    sample : ndarray of int, shape (m,)
        Sample indices of the rows.
    position_error_m : ndarray, shape (m, 3)
        Measured minus predicted position, metres, in the measurement frame (camera
        frame for ``target``).
    rotation_error_rad : ndarray, shape (m,)
        Rotation angle between measured and predicted orientation, rad; NaN for points.
    pixel_error_px : ndarray, shape (m, 2), or None
        Measured minus predicted pixels of image points (``pixels``), None for the
        other kinds (their position and rotation errors are NaN).
    """

    frame: str
    kind: str
    marker: str | None
    sample: NDArray[np.int64]
    position_error_m: NDArray[np.float64]
    rotation_error_rad: NDArray[np.float64]
    pixel_error_px: NDArray[np.float64] | None = None

    @property
    def n(self) -> int:
        return len(self.sample)

    @property
    def position_norm_mm(self) -> NDArray[np.float64]:
        """Per-sample position error norm, mm."""
        return 1e3 * np.linalg.norm(self.position_error_m, axis=1)

    @property
    def rotation_deg(self) -> NDArray[np.float64]:
        """Per-sample rotation error, degrees (NaN for points)."""
        return np.degrees(self.rotation_error_rad)

    def summary(self) -> dict[str, float | list[float]]:
        """Mean, RMS and max of the position norm (mm) and rotation (deg), and the
        paper's Table 4 statistics: mean and std of ``|error|`` per axis x, y, z (mm);
        for image points also the RMS and max of the pixel error norm (px)."""
        p = self.position_norm_mm
        r = self.rotation_deg
        abs_axis = 1e3 * np.abs(self.position_error_m)
        has_rot = self.kind != "point"
        pixels = {}
        if self.pixel_error_px is not None:
            e = np.linalg.norm(self.pixel_error_px, axis=1)
            pixels = {
                "pixel_rms_px": float(np.sqrt(np.mean(e**2))),
                "pixel_max_px": float(e.max()),
            }
        return {
            "n": self.n,
            "position_mean_mm": float(p.mean()),
            "position_rms_mm": float(np.sqrt(np.mean(p**2))),
            "position_max_mm": float(p.max()),
            "rotation_mean_deg": float(r.mean()) if has_rot else float("nan"),
            "rotation_rms_deg": float(np.sqrt(np.mean(r**2))) if has_rot else float("nan"),
            "rotation_max_deg": float(r.max()) if has_rot else float("nan"),
            "abs_mean_xyz_mm": abs_axis.mean(axis=0).tolist(),
            "abs_std_xyz_mm": abs_axis.std(axis=0).tolist(),
            **pixels,
        }


@dataclass(frozen=True, slots=True)
class AccuracyReport:
    """Errors of a model against a dataset, per observation group.

    Attributes
    ----------
    groups : tuple of GroupErrors
    fitted : tuple of str
        Human-readable list of the unknown frames fitted from the data.
    """

    groups: tuple[GroupErrors, ...]
    fitted: tuple[str, ...]

    def to_dict(self, *, per_sample: bool = False) -> dict:
        """JSON-ready summary (SI inside, mm and degrees in the field names); with
        ``per_sample`` each group also lists every sample's position error (mm, norm and
        x, y, z) and rotation error (deg), or for image points (``pixels``) every
        point's pixel error (px, norm and u, v). Undefined numbers are NaN: write the
        dict with :func:`kinfw.files.json_text` (null)."""
        groups = []
        for g in self.groups:
            entry = {"frame": g.frame, "kind": g.kind, "marker": g.marker, **g.summary()}
            if per_sample and g.pixel_error_px is not None:
                # one entry per image point: its pixel error (no position or rotation)
                entry["samples"] = [
                    {
                        "sample": int(k),
                        "pixel_px": float(np.hypot(*e)),
                        "pixel_uv_px": e.tolist(),
                    }
                    for k, e in zip(g.sample, g.pixel_error_px, strict=True)
                ]
            elif per_sample:
                entry["samples"] = [
                    {
                        "sample": int(k),
                        "position_mm": float(p),
                        "position_xyz_mm": (1e3 * e).tolist(),
                        "rotation_deg": None if np.isnan(r) else float(r),
                    }
                    for k, p, e, r in zip(
                        g.sample,
                        g.position_norm_mm,
                        g.position_error_m,
                        g.rotation_deg,
                        strict=True,
                    )
                ]
            groups.append(entry)
        return {"fitted": list(self.fitted), "groups": groups}


def known_frames(sidecar: CalibrationSidecar | None) -> dict[tuple[str, str], NDArray]:
    """The rigid frames and offsets a calibration sidecar (``*.kinfw.json``, read with
    :func:`kinfw.reports.read_sidecar`) provides:
    ``{("frame", name): meas_T_root, ("target", name): root_T_target,
    ("marker", name): frame_T_marker, ("offset", "frame:marker"): frame_p_point}``
    (:meth:`~kinfw.reports.CalibrationSidecar.known_frames`)."""
    return {} if sidecar is None else sidecar.known_frames()


def evaluate_model(
    robot: Robot, measurements: Measurements, *, sidecar: CalibrationSidecar | None = None
) -> AccuracyReport:
    """Errors of ``robot``'s URDF geometry against ``measurements``.

    The prediction is the estimation problem's at its start
    (:func:`kinfw.identification.problem.build_problem` with ``parameters="none"``: the CPC
    model converted from the URDF, equal to Pinocchio FK to 1e-12, see
    :mod:`kinfw.verification.evaluation`), so every observation kind of the registry is
    evaluated the way the calibration sees it. With the calibration's ``sidecar`` (the
    ``*.kinfw.json`` written beside a calibrated URDF), the frames it provides (the
    root's pose in the measurement frame, target poses, markers, point offsets) are used
    as calibrated instead of being fitted to these data, so the errors are honest
    predictions; the others get the kinds' closed-form start values.

    Raises
    ------
    DatasetError
        If the data does not fit the robot (see
        :func:`kinfw.measurements.check_against_robot`) or leaves an unknown frame
        unplaceable.
    """
    from kinfw.identification.problem import Unknown, build_problem
    from kinfw.measurements import check_against_robot

    measurements = check_against_robot(measurements, robot)
    known = tuple(
        Unknown(kind, name, value) for (kind, name), value in known_frames(sidecar).items()
    )
    known_keys = {BlockKey(u.kind, u.name) for u in known}
    problem = build_problem(robot, measurements, parameters="none", known=known)
    # external measurement frames: fitted once from all the data; every other unknown
    # (target, marker, offset) per group, by the kind's own closed-form start estimator
    fitted = [text for key, text in problem.fitted if key.kind == "frame"]
    start = problem.start_context(measurements)
    x0 = np.zeros(problem.n_parameters)
    groups: list[GroupErrors] = []
    for g in problem.groups:
        requests = [req for req in g.kind.unknowns(g.group, start) if req.key not in known_keys]
        # intrinsics are the file's (or --camera's), fixed: not fitted to these data
        fitted += [req.description for req in requests if req.key.kind != "intrinsics"]
        own = problem.with_starts(g, [req.block(req.key, req.estimates) for req in requests])
        r = own.evaluate(x0, False)[0].reshape(len(g.sample), g.rows)
        r = r / g.kind.row_weights(g.group)[:, None]  # the errors, not their fit weights
        m = len(g.sample)
        position = np.full((m, 3), np.nan)
        rotation = np.full(m, np.nan)
        pixel = None
        c0 = 0
        for c in g.components:
            rows = r[:, c0 : c0 + c.rows]
            if c.name == "position":
                position = rows
            elif c.name == "rotation":
                rotation = c.magnitude(rows)
            elif c.unit == "px":
                pixel = rows
            c0 += c.rows
        groups.append(
            GroupErrors(g.frame, g.kind.name, g.marker, g.sample, position, rotation, pixel)
        )
    return AccuracyReport(tuple(groups), tuple(fitted))
