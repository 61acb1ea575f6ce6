"""``"target"``: the pose of a fixed target seen by a camera frame on the robot."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import check_transform, inverse_transform, xyz_quat_xyzw_from_transform
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
from kinfw.observations._contexts import StartContext, SymbolicContext, inverse_casadi
from kinfw.observations._numeric import Drawing, NumericContext, node_name, predicted_or_missing
from kinfw.observations._pose import read_quaternion, transforms_from_rows
from kinfw.observations._rigid import RigidTransformKind

__all__ = ["DEFAULT_TARGET", "TargetKind", "TargetObservations"]

DEFAULT_TARGET = "target"


@dataclass(frozen=True, slots=True, eq=False)
class TargetObservations:
    """All ``target`` observations of one fixed target by one camera frame.

    Attributes
    ----------
    camera : str
        URDF camera frame on the robot (the file's ``"frame"``).
    sample : ndarray of int64, shape (m,)
        Index into :attr:`Measurements.qs` of each observation's sample.
    camera_T_target : ndarray, shape (m, 4, 4)
        Pose of the target in the camera frame (camera extrinsic calibration), metres.
    target : str
        Name of the fixed target (file key ``"target"``, default ``"target"``); its pose
        in the world is unknown.
    """

    kind: ClassVar[str] = "target"
    camera: str
    sample: NDArray[np.int64]
    camera_T_target: NDArray[np.float64]
    target: str = DEFAULT_TARGET

    def __post_init__(self) -> None:
        name = f"TargetObservations(camera={self.camera!r})"
        sample = sample_array(self.sample, f"{name}.sample")
        T = data_array(self.camera_T_target, (len(sample), 4, 4), f"{name}.camera_T_target")
        check_transform(T, name=f"{name}.camera_T_target")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(self, "camera_T_target", T)

    def __repr__(self) -> str:
        return (
            f"TargetObservations(camera={self.camera!r}, target={self.target!r}, "
            f"m={len(self.sample)})"
        )

    @property
    def _key(self) -> tuple[Any, ...]:
        return TargetKind().key(self)


class TargetKind(RigidTransformKind):
    """``"target"``: ``xyz`` and ``quat_xyzw`` of the fixed target ``target`` in the
    camera frame ``frame``. Unknown: the target's pose in the root. Residual: position
    (3, m, in the camera frame) and orientation (3, rad)."""

    name = "target"
    group_type = TargetObservations
    row_fields = ("camera_T_target",)
    components = (POSITION, ROTATION)
    measurements_field = "targets"

    def parse(self, reader, obs, at, frame):
        xyz = reader.numbers(reader.get(obs, "xyz", at, "3 numbers [x, y, z]"), 3, f"{at}.xyz")
        reader.not_allowed(
            obs,
            "marker",
            at,
            self.name,
            "the target's pose in the world is the unknown; a camera frame has no marker",
        )
        reader.not_allowed(
            obs, "measured_in", at, self.name, "the pose is measured in the camera frame"
        )
        reader.not_allowed(obs, "offset", at, self.name, "offset belongs to 'point' observations")
        quat = read_quaternion(reader, obs, at)
        target = reader.optional_string(obs, "target", at) or DEFAULT_TARGET
        return (("camera", frame), ("target", target)), [*reader.lengths(xyz), *quat]

    def marker(self, key):
        return None

    def group_from_rows(self, key, sample, rows):
        return TargetObservations(
            sample=sample, camera_T_target=transforms_from_rows(rows), **dict(key)
        )

    def to_dicts(self, group, top_measured_in):
        more = {} if group.target == DEFAULT_TARGET else {"target": group.target}
        xyzs, quats = xyz_quat_xyzw_from_transform(group.camera_T_target)
        return [
            {"frame": group.camera, "kind": "target", "xyz": xyz, "quat_xyzw": quat, **more}
            for xyz, quat in zip(xyzs.tolist(), quats.tolist(), strict=True)
        ]

    def frames(self, group):
        return (group.camera,)

    def direct_frames(self, group):
        return (group.camera,)

    def unknowns(self, group, start: StartContext):
        return (
            UnknownRequest(
                BlockKey("target", group.target),
                start.w_T(group.camera, group.sample) @ group.camera_T_target,
                RigidFrameBlock.from_estimates,
                f"pose of target {group.target!r} (seen by {group.camera!r})",
            ),
        )

    def data(self, group):
        return pose_rows(group.camera_T_target)

    def residual(self, group, model: SymbolicContext, m):
        T = inverse_casadi(model.ca, model.w_T(group.camera)) @ model.value(
            BlockKey("target", group.target)
        )
        return pose_residual(model.ca, T, m)

    # -- numpy prediction, simulation, drawing
    def predicted_transforms(self, group, model: NumericContext):
        """Predicted ``camera_T_target`` (m, 4, 4), as :meth:`residual` forms it."""
        return inverse_transform(model.w_T(group.camera, group.sample)) @ model.value(
            BlockKey("target", group.target)
        )

    def drawing(self, group, model: NumericContext):
        """The target where the camera saw it (not framed: it may be far away), the
        residual line from the target's known pose."""
        w_T_seen = model.w_T(group.camera, group.sample) @ group.camera_T_target
        predicted, missing = predicted_or_missing(
            lambda: np.broadcast_to(
                model.value(BlockKey("target", group.target))[:3, 3], (len(group.sample), 3)
            )
        )
        return Drawing(
            node_name("targets", group.camera, group.target),
            w_T_seen[:, :3, 3],
            w_T_seen[:, :3, :3],
            predicted,
            focus=False,
            missing=missing,
        )

    def camera_frames(self, group):
        return (group.camera,)
