"""``"pose"``: the pose of a URDF frame (or of a marker on it) in a measurement frame."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import (
    check_transform,
    inverse_transform,
    transform_from_xyz_quat_xyzw,
    xyz_quat_xyzw_from_transform,
)
from kinfw.model import BlockKey, RigidFrameBlock
from kinfw.observations._base import (
    POSITION,
    ROTATION,
    UnknownRequest,
    data_array,
    pose_residual,
    pose_rows,
    sample_array,
)
from kinfw.observations._contexts import StartContext, SymbolicContext
from kinfw.observations._numeric import Drawing, NumericContext, node_name, predicted_or_missing
from kinfw.observations._reader import ObservationReader
from kinfw.observations._rigid import RigidTransformKind

QUAT_NORM_TOL = 1e-3
"""Largest accepted ``| |quat_xyzw| - 1 |`` in a file (quaternions written with 4 or 5
decimals are off by up to a few 1e-5); accepted quaternions are renormalised."""
QUAT_ROUNDED_TOL = 1e-6
"""Beyond this ``| |quat_xyzw| - 1 |`` (and within :data:`QUAT_NORM_TOL`) the reader warns,
once per file, that it renormalised rounded quaternions."""


@dataclass(frozen=True, slots=True, eq=False)
class PoseObservations:
    """All ``pose`` observations that share ``(frame, marker, measured_in)``.

    Attributes
    ----------
    frame : str
        URDF frame (link or joint) the pose belongs to.
    sample : ndarray of int64, shape (m,)
        Index into :attr:`Measurements.qs` of each observation's sample.
    meas_T_frame : ndarray, shape (m, 4, 4)
        Pose of ``frame`` (or of its marker) in the measurement frame, metres.
    marker : str or None
        Name of a rigid marker on ``frame`` whose pose in ``frame`` is unknown; None when
        ``frame`` itself is measured.
    measured_in : str or None
        Measurement frame; None is the URDF root link.
    """

    kind: ClassVar[str] = "pose"
    frame: str
    sample: NDArray[np.int64]
    meas_T_frame: NDArray[np.float64]
    marker: str | None = None
    measured_in: str | None = None

    def __post_init__(self) -> None:
        name = f"PoseObservations(frame={self.frame!r})"
        sample = sample_array(self.sample, f"{name}.sample")
        T = data_array(self.meas_T_frame, (len(sample), 4, 4), f"{name}.meas_T_frame")
        check_transform(T, name=f"{name}.meas_T_frame")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(self, "meas_T_frame", T)

    def __repr__(self) -> str:
        return (
            f"PoseObservations(frame={self.frame!r}, marker={self.marker!r}, "
            f"measured_in={self.measured_in!r}, m={len(self.sample)})"
        )

    @property
    def _key(self) -> tuple[Any, ...]:
        return PoseKind().key(self)


def read_quaternion(reader: ObservationReader, obs: dict[str, Any], at: str) -> list[float]:
    """``quat_xyzw`` of an observation: 4 numbers of unit norm (within QUAT_NORM_TOL),
    renormalised later; norms off by more than QUAT_ROUNDED_TOL are noted in the reader
    (``reader.rounded``) for one warning per file."""
    quat = reader.numbers(
        reader.get(obs, "quat_xyzw", at, "4 numbers [x, y, z, w] (scalar last)"),
        4,
        f"{at}.quat_xyzw",
        "[x, y, z, w], scalar last",
    )
    norm = float(np.linalg.norm(quat))
    if not abs(norm - 1.0) <= QUAT_NORM_TOL:
        raise reader.error(
            f"{at}.quat_xyzw",
            f"quaternion norm is {norm:.9g}; expected a unit quaternion "
            f"[x, y, z, w] (norm within {QUAT_NORM_TOL:g} of 1)",
        )
    reader.quaternions += 1
    if abs(norm - 1.0) > QUAT_ROUNDED_TOL:
        reader.rounded.append(abs(norm - 1.0))
    return quat


def read_quaternions(reader: ObservationReader, values: list[Any]) -> NDArray[np.float64] | None:
    """Many ``quat_xyzw`` at once (m, 4), as :func:`read_quaternion` checks and notes
    each; None when any fails a check (nothing noted: :func:`read_quaternion` then names
    it)."""
    quats = reader.numbers_many(values, 4)
    if quats is None:
        return None
    off = np.abs(np.linalg.norm(quats, axis=1) - 1.0)
    if not (off <= QUAT_NORM_TOL).all():
        return None
    reader.quaternions += len(quats)
    reader.rounded.extend(off[off > QUAT_ROUNDED_TOL].tolist())
    return quats


def transforms_from_rows(rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rows (m, 7) of xyz (m) and quat_xyzw -> (m, 4, 4), quaternions renormalised."""
    quats = rows[:, 3:7]
    return transform_from_xyz_quat_xyzw(rows[:, :3], quats / np.linalg.norm(quats, axis=1)[:, None])


class PoseKind(RigidTransformKind):
    """``"pose"``: ``xyz`` and ``quat_xyzw`` of ``frame`` (or of its ``marker``) in the
    measurement frame. Residual: position (3, m) and orientation (3, rad)."""

    name = "pose"
    group_type = PoseObservations
    row_fields = ("meas_T_frame",)
    components = (POSITION, ROTATION)
    measurements_field = "poses"
    has_measured_in = True
    file_keys = ("xyz", "quat_xyzw", "marker", "measured_in")

    def parse(self, reader, obs, at, frame):
        xyz = reader.numbers(reader.get(obs, "xyz", at, "3 numbers [x, y, z]"), 3, f"{at}.xyz")
        reader.not_allowed(obs, "target", at, self.name, "only 'target' observations name a target")
        quat = read_quaternion(reader, obs, at)
        reader.not_allowed(obs, "offset", at, self.name, "offset belongs to 'point' observations")
        marker = reader.optional_string(obs, "marker", at)
        measured_in = reader.optional_string(obs, "measured_in", at) or reader.default_measured_in
        key = (("frame", frame), ("marker", marker), ("measured_in", measured_in))
        return key, [*reader.lengths(xyz), *quat]

    def group_from_rows(self, key, sample, rows):
        return PoseObservations(sample=sample, meas_T_frame=transforms_from_rows(rows), **dict(key))

    def to_dicts(self, group, top_measured_in):
        more = {
            k: v
            for k, v in (
                ("marker", group.marker),
                (
                    "measured_in",
                    None if group.measured_in == top_measured_in else group.measured_in,
                ),
            )
            if v is not None
        }
        xyzs, quats = xyz_quat_xyzw_from_transform(group.meas_T_frame)
        return [
            {"frame": group.frame, "kind": "pose", "xyz": xyz, "quat_xyzw": quat, **more}
            for xyz, quat in zip(xyzs.tolist(), quats.tolist(), strict=True)
        ]

    def frames(self, group):
        return (group.frame,)

    def direct_frames(self, group):
        return (group.frame,) if group.marker is None else ()

    def root_pose_estimates(self, group, start: StartContext):
        if group.marker is not None:
            return None
        return group.meas_T_frame @ inverse_transform(start.w_T(group.frame, group.sample))

    def marker_tracks(self, group, start: StartContext):
        """A marker pose for placing an external frame seen only through markers
        (:func:`kinfw.identification.problem.frame_from_markers`): the frame's start poses
        in the model frame, the marker's measured positions and rotations and its block
        key; None for a marker-free pose (it places the frame alone)."""
        if group.marker is None:
            return None
        return (
            start.w_T(group.frame, group.sample),
            group.meas_T_frame[:, :3, 3],
            None,
            group.meas_T_frame[:, :3, :3],
            BlockKey("marker", group.marker),
        )

    def unknowns(self, group, start: StartContext):
        if group.marker is None:
            return ()
        pred = start.meas_T(group.measured_in, group.frame, group.sample)
        return (
            UnknownRequest(
                BlockKey("marker", group.marker),
                inverse_transform(pred) @ group.meas_T_frame,
                RigidFrameBlock.from_estimates,
                f"pose of marker {group.marker!r} on {group.frame!r}",
            ),
        )

    def data(self, group):
        return pose_rows(group.meas_T_frame)

    def residual(self, group, model: SymbolicContext, m):
        T = model.meas_T(group.measured_in, group.frame)
        if group.marker is not None:
            T = T @ model.value(BlockKey("marker", group.marker))
        return pose_residual(model.ca, T, m)

    # -- numpy prediction, simulation, drawing
    def w_T_predicted(self, group, model: NumericContext):
        """Predicted pose (m, 4, 4) of the frame (or its marker) in the model frame."""
        T = model.w_T(group.frame, group.sample)
        return T if group.marker is None else T @ model.value(BlockKey("marker", group.marker))

    def predicted_transforms(self, group, model: NumericContext):
        """Predicted ``meas_T_frame`` (m, 4, 4), as :meth:`residual` forms it."""
        T = model.meas_T(group.measured_in, group.frame, group.sample)
        return T if group.marker is None else T @ model.value(BlockKey("marker", group.marker))

    def drawing(self, group, model: NumericContext):
        w_T = model.w_T_meas_at(group.measured_in, group.sample) @ group.meas_T_frame
        predicted, missing = predicted_or_missing(
            lambda: self.w_T_predicted(group, model)[:, :3, 3]
        )
        return Drawing(
            node_name("poses", group.frame, marker=group.marker),
            w_T[:, :3, 3],
            w_T[:, :3, :3],
            predicted,
            missing=missing,
        )
