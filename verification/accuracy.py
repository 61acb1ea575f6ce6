"""Errors of a robot model against measurements: what ``kinfw verify`` reports.

For every group of observations (one frame, kind and marker) the model predicts the
measurement and the error is *measured minus predicted*:

- ``pose``: position error vector in the measurement frame and the rotation angle of
  ``predicted_R^T measured_R``;
- ``target``: the same for ``camera_T_target``, with the position error in the camera
  frame;
- ``point``: the position error vector only.

Unknown rigid frames that are not in the URDF (the target's pose, a marker's pose or
offset, the pose of the root link in a ``measured_in`` frame) are fitted here in closed
form from the same data, and every such fit is listed in :attr:`AccuracyReport.fitted`:
errors are then residuals after that fit, slightly optimistic for few samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.cpc import cpc_from_robot
from kinfw.measurements import DatasetError, Measurements, check_against_robot
from kinfw.robot import Robot
from kinfw.transforms import average_transform, inverse_transform, rotation_angle

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
    """

    frame: str
    kind: str
    marker: str | None
    sample: NDArray[np.int64]
    position_error_m: NDArray[np.float64]
    rotation_error_rad: NDArray[np.float64]

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
        paper's Table 4 statistics: mean and std of ``|error|`` per axis x, y, z (mm)."""
        p = self.position_norm_mm
        r = self.rotation_deg
        abs_axis = 1e3 * np.abs(self.position_error_m)
        has_rot = self.kind != "point"
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
        x, y, z) and rotation error (deg)."""
        groups = []
        for g in self.groups:
            entry = {"frame": g.frame, "kind": g.kind, "marker": g.marker, **g.summary()}
            if per_sample:
                entry["samples"] = [
                    {"sample": int(k), "position_mm": float(p),
                     "position_xyz_mm": (1e3 * e).tolist(),
                     "rotation_deg": None if np.isnan(r) else float(r)}
                    for k, p, e, r in zip(g.sample, g.position_norm_mm, g.position_error_m,
                                          g.rotation_deg, strict=True)]
            groups.append(entry)
        return {"fitted": list(self.fitted), "groups": groups}


def _pose_errors(meas_T: NDArray, pred_T: NDArray) -> tuple[NDArray, NDArray]:
    dp = meas_T[:, :3, 3] - pred_T[:, :3, 3]
    dr = rotation_angle(np.swapaxes(pred_T[:, :3, :3], 1, 2) @ meas_T[:, :3, :3])
    return dp, dr


def known_frames(sidecar: dict | None) -> dict[tuple[str, str], NDArray]:
    """The rigid frames and offsets a calibration sidecar (``*.kinfw.json``) provides:
    ``{("frame", name): meas_T_root, ("target", name): root_T_target,
    ("marker", name): frame_T_marker, ("offset", "frame:marker"): frame_p_point}``."""
    if not sidecar:
        return {}
    known: dict[tuple[str, str], NDArray] = {}
    for t in sidecar.get("targets", []):
        known[("target", t["target"])] = np.array(t["root_T_target"])
    for u in sidecar.get("unknowns", []):
        known[(u["kind"], u["name"])] = np.array(u["value"])
    if sidecar.get("measurement_frame"):
        known[("frame", sidecar["measurement_frame"])] = np.array(sidecar["w_T_root"])
    return known


def evaluate_model(robot: Robot, measurements: Measurements, *,
                   sidecar: dict | None = None) -> AccuracyReport:
    """Errors of ``robot``'s URDF geometry against ``measurements``.

    The prediction uses the CPC model converted from the URDF (equal to Pinocchio FK to
    1e-12, see :mod:`verification.crosscheck`), vectorised over samples. With the
    calibration's ``sidecar`` (the ``*.kinfw.json`` written beside a calibrated URDF), the
    frames it provides (the root's pose in the measurement frame, target poses, markers,
    point offsets) are used as calibrated instead of being fitted to these data, so the
    errors are honest predictions.

    Raises
    ------
    DatasetError
        If the data does not fit the robot (see
        :func:`kinfw.measurements.check_against_robot`), or needs two unknown frames at
        once (a marker measured in a ``measured_in`` frame), which is a hand-eye problem
        for ``kinfw calibrate``, not a closed-form fit.
    """
    measurements = check_against_robot(measurements, robot)
    known = known_frames(sidecar)
    frames = measurements.observed_frames
    model = cpc_from_robot(robot, frames)
    root_T = model.frame_poses(measurements.q_of(model.topology.joint_names))
    if root_T.ndim == 3:  # a single sample
        root_T = root_T[None]
    index = {f: k for k, f in enumerate(model.topology.frames)}
    groups: list[GroupErrors] = []
    fitted: list[str] = []

    # measured_in frames: fit meas_T_root from every marker-free pose observed in them.
    meas_T_root: dict[str, NDArray] = {}
    for name in sorted({g.measured_in for g in (*measurements.poses, *measurements.points)
                        if g.measured_in is not None}):
        if ("frame", name) in known:
            meas_T_root[name] = known[("frame", name)]
            continue
        estimates = [g.meas_T_frame @ inverse_transform(root_T[g.sample, index[g.frame]])
                     for g in measurements.poses if g.measured_in == name and g.marker is None]
        if not estimates:
            raise DatasetError(
                f"{measurements.source}: verify needs marker-free pose observations in "
                f"{name!r} to place that frame; run 'kinfw calibrate' to estimate it")
        meas_T_root[name] = average_transform(np.concatenate(estimates))
        fitted.append(f"pose of the root link in {name!r} (from {sum(map(len, estimates))} "
                      "poses)")

    def to_meas(g, T_root):
        return T_root if g.measured_in is None else meas_T_root[g.measured_in] @ T_root

    for g in measurements.poses:
        pred = to_meas(g, root_T[g.sample, index[g.frame]])
        if g.marker is not None:
            if g.measured_in is not None:
                raise DatasetError(
                    f"{measurements.source}: marker {g.marker!r} measured in "
                    f"{g.measured_in!r} has two unknown frames; use 'kinfw calibrate'")
            frame_T_marker = known.get(("marker", g.marker))
            if frame_T_marker is None:
                frame_T_marker = average_transform(inverse_transform(pred) @ g.meas_T_frame)
                fitted.append(f"pose of marker {g.marker!r} on {g.frame!r}")
            pred = pred @ frame_T_marker
        dp, dr = _pose_errors(g.meas_T_frame, pred)
        groups.append(GroupErrors(g.frame, "pose", g.marker, g.sample, dp, dr))

    for g in measurements.targets:
        root_T_camera = root_T[g.sample, index[g.camera]]
        root_T_target = known.get(("target", g.target))
        if root_T_target is None:
            root_T_target = average_transform(root_T_camera @ g.camera_T_target)
            fitted.append(f"pose of target {g.target!r} (seen by {g.camera!r})")
        pred = inverse_transform(root_T_camera) @ root_T_target
        dp, dr = _pose_errors(g.camera_T_target, pred)
        groups.append(GroupErrors(g.camera, "target", None, g.sample, dp, dr))

    for g in measurements.points:
        pred_T = to_meas(g, root_T[g.sample, index[g.frame]])
        R, p = pred_T[:, :3, :3], pred_T[:, :3, 3]
        key = ("offset", f"{g.frame}:{g.marker or 'point'}")
        if g.offset is not None:
            offset = g.offset
        elif key in known:
            offset = known[key]
        else:
            # least squares offset: mean of R_i^T (m_i - p_i)
            offset = np.einsum("nji,nj->ni", R, g.meas_p_point - p).mean(axis=0)
            fitted.append(f"offset of point {g.marker or 'on ' + g.frame!r} on {g.frame!r}")
        dp = g.meas_p_point - (p + R @ offset)
        groups.append(GroupErrors(g.frame, "point", g.marker, g.sample, dp,
                                  np.full(len(g.sample), np.nan)))
    return AccuracyReport(tuple(groups), tuple(fitted))
