"""Errors of a robot model against measurements: what ``kinfw verify`` reports.

For every group of observations (one frame, kind and marker) the model predicts the
measurement and the error is *measured minus predicted*, read in the metrics of the
group's kind (:meth:`kinfw.observations.ObservationKind.errors`), e.g.:

- ``pose``: position error vector in the measurement frame (mm) and the rotation angle
  of ``predicted_R^T measured_R`` (deg);
- ``target``: the same for ``camera_T_target``, with the position error in the camera
  frame;
- ``point``: the position error vector only;
- ``pixels``: the reprojection error (px); ``plane``: each contact's height off the plane
  (mm) and the contacts' tilt (deg); a registered kind: its own.

Unknown rigid frames that are not in the URDF (the target's pose, a marker's pose or
offset, the pose of the root link in a ``measured_in`` frame) are fitted in closed form
from the same data by the observation kinds' start estimators (the ones the calibration
starts from): the measurement frames from all the data, the others per group. Every such
fit is listed in :attr:`AccuracyReport.fitted`: errors are then residuals after that
fit, slightly optimistic for few samples. Rotation errors are
``arcsin`` of the orientation residual's norm (exact below 90 degrees).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.measurements import Measurements
from kinfw.model import Block, BlockKey, Robot
from kinfw.observations import Metric, MetricErrors, NumericContext
from kinfw.records import CalibrationSidecar


@dataclass(frozen=True, slots=True)
class GroupErrors:
    """Errors of one observation group, in the metrics of its kind.

    Attributes
    ----------
    frame, kind : str
        Frame (camera for ``target``) and observation kind.
    marker : str or None
    sample : ndarray of int, shape (m,)
        Sample indices of the rows.
    errors : tuple of MetricErrors
        Per metric of the kind (:attr:`kinfw.observations.ObservationKind.metrics`: a
        pose's position and rotation, a point's position, an image point's pixel error,
        a plane contact's height and the contacts' tilt, a registered kind's own), SI.
    entity : str or None
        What the group observes besides its frame (its plane, ball, divot or target:
        :meth:`kinfw.observations.ObservationKind.entity`).
    """

    frame: str
    kind: str
    marker: str | None
    sample: NDArray[np.int64]
    errors: tuple[MetricErrors, ...]
    entity: str | None = None

    @property
    def n(self) -> int:
        return len(self.sample)

    @property
    def metrics(self) -> tuple[Metric, ...]:
        return tuple(e.metric for e in self.errors)

    def of(self, name: str) -> MetricErrors | None:
        """The errors in the metric ``name`` (``"position"``), None if the kind has none."""
        return next((e for e in self.errors if e.metric.name == name), None)

    def summary(self) -> dict[str, float | list[float]]:
        """``n``, then per metric its mean, RMS and max over the observations (or the
        group's number) in its display unit, keyed ``name_stat_unit``
        (``position_rms_mm``); then for a metric with axes the paper's Table 4
        statistics, the mean and std of ``|error|`` per axis (``abs_mean_xyz_mm``)."""
        return {
            "n": self.n,
            **{k: v for e in self.errors for k, v in e.summary()},
            **{k: v for e in self.errors for k, v in e.axis_stats()},
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

    @property
    def metrics(self) -> tuple[Metric, ...]:
        """Every metric of the groups, in order of first appearance."""
        return tuple(dict.fromkeys(m for g in self.groups for m in g.metrics))

    def values(self, name: str) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Per observation of the groups that have the per-observation metric ``name``
        its error size (SI) and sample index, each (n,), in group order."""
        found = [(e.values, g.sample) for g in self.groups if (e := g.of(name)) is not None]
        if not found:
            return np.zeros(0), np.zeros(0, np.int64)
        return np.concatenate([v for v, _ in found]), np.concatenate([k for _, k in found])

    def entities(self) -> tuple[str | None, ...]:
        """Per group what it observes (:attr:`GroupErrors.entity`) where another group
        of the same frame, kind and marker observes something else (one probe on a table
        and a wall), else None: what tells the groups' labels apart."""
        alike = Counter((g.frame, g.kind, g.marker) for g in self.groups)
        return tuple(
            g.entity if alike[g.frame, g.kind, g.marker] > 1 else None for g in self.groups
        )

    def to_dict(self, *, per_sample: bool = False) -> dict:
        """JSON-ready summary (SI inside, the display unit in the key names:
        :meth:`GroupErrors.summary`); with ``per_sample`` each group also lists every
        observation's error in each per-observation metric (``position_mm``,
        ``rotation_deg``, ``pixel_px``; with axes also the vector, ``position_xyz_mm``).
        Undefined numbers are NaN: write the dict with :func:`kinfw.files.json_text`
        (null)."""
        groups = []
        for g, entity in zip(self.groups, self.entities(), strict=True):
            entry = {"frame": g.frame, "kind": g.kind, "marker": g.marker}
            entry |= ({} if entity is None else {"entity": entity}) | g.summary()
            if per_sample:
                per = [e for e in g.errors if e.metric.per_observation]
                entry["samples"] = [
                    {"sample": int(k)} | {k2: v for e in per for k2, v in _sample(e, row)}
                    for row, k in enumerate(g.sample)
                ]
            groups.append(entry)
        return {"fitted": list(self.fitted), "groups": groups}


def _sample(e: MetricErrors, row: int) -> list[tuple[str, object]]:
    """One observation's error in a per-observation metric: its size (None if
    undefined) and, with axes, its vector, in the display unit."""
    value = float(e.shown()[row])
    out: list[tuple[str, object]] = [(e.metric.key(), None if np.isnan(value) else value)]
    if e.vectors is not None:
        axes = f"{e.metric.name}_{e.metric.axes}_{e.metric.unit}"
        out.append((axes, (e.metric.scale * e.vectors[row]).tolist()))
    return out


def group_errors(group: Any, rows: NDArray[np.float64], model: NumericContext) -> GroupErrors:
    """The errors of one residual group of a problem
    (:class:`kinfw.identification.problem.ResidualGroup`) from its rows (m, rows), SI
    and weighted as the problem weighs them (the kind's row weights are divided out
    here), in its kind's metrics (:meth:`kinfw.observations.ObservationKind.errors`)."""
    rows = rows / group.kind.row_weights(group.group)[:, None]  # the errors, not their weights
    return GroupErrors(
        group.frame,
        group.kind.name,
        group.marker,
        group.sample,
        tuple(group.kind.errors(group.group, rows, model)),
        group.kind.entity(group.group),
    )


def known_frames(sidecar: CalibrationSidecar | None) -> dict[tuple[str, str], NDArray]:
    """The rigid frames and offsets a calibration sidecar (``*.kinfw.json``, read with
    :func:`kinfw.records.read_sidecar`) provides:
    ``{("frame", name): meas_T_root, ("target", name): root_T_target,
    ("marker", name): frame_T_marker, ("offset", "frame:marker"): frame_p_point}``
    (:meth:`~kinfw.records.CalibrationSidecar.known_frames`)."""
    return {} if sidecar is None else sidecar.known_frames()


def evaluate_model(
    robot: Robot,
    measurements: Measurements,
    *,
    sidecar: CalibrationSidecar | None = None,
    known: Iterable[Any] = (),
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
    predictions; the others get the kinds' closed-form start values. ``known`` does the
    same from a calibration's own unknowns (:attr:`RefineResult.unknowns`: ``kind``,
    ``name``, ``value``; they take precedence over the sidecar's): held-out images are
    then scored by reprojection with the board pose from training.

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
    given = {(u.kind, u.name): np.asarray(u.value, dtype=float) for u in known}
    known = tuple(
        Unknown(kind, name, value)
        for (kind, name), value in {**known_frames(sidecar), **given}.items()
    )
    known_keys = {BlockKey(u.kind, u.name) for u in known}
    problem = build_problem(robot, measurements, parameters="none", known=known)
    # external measurement frames: fitted once from all the data; every other unknown
    # (target, marker, offset) per group, by the kind's own closed-form start estimator
    fitted = [text for key, text in problem.fitted if key.kind == "frame"]
    start = problem.start_context()
    x0 = np.zeros(problem.n_parameters)
    # the model the errors are predicted by, for a metric that needs geometry: the
    # robot at the samples, the known and the fitted unknowns' values
    qs, names = measurements.qs, measurements.joint_names
    values = {b.key: _value(b) for b in problem.unknown_blocks}
    values.update({BlockKey(u.kind, u.name): u.value for u in known})
    groups: list[GroupErrors] = []
    for g in problem.groups:
        requests = [req for req in g.kind.unknowns(g.group, start) if req.key not in known_keys]
        # intrinsics are the file's (or --camera's), fixed: not fitted to these data
        fitted += [req.description for req in requests if req.key.kind != "intrinsics"]
        blocks = [req.block(req.key, req.estimates) for req in requests]
        own = problem.with_starts(g, blocks)
        r = own.evaluate(x0, False)[0].reshape(len(g.sample), g.rows)
        mine = {**values, **{b.key: _value(b) for b in blocks}}
        groups.append(group_errors(g, r, NumericContext.from_robot(robot, qs, names, mine)))
    return AccuracyReport(tuple(groups), tuple(fitted))


def _value(block: Block) -> NDArray[np.float64]:
    """A block's value at its start (chart coordinates zero)."""
    return block.numpy_value(np.zeros(block.size))
