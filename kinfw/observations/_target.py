"""``"target"``: the pose of a target seen by a camera frame on the robot.

The target (a board) is fixed in the world (the default: its pose in the model frame is
the unknown ``BlockKey("target", name)``) or rigidly on a URDF frame ``target_frame``
(eye-to-hand: a board on the flange seen by a static camera; its pose in that frame is
the unknown). Either way the camera sees::

    camera_T_target(q) = inv(w_T_camera(q)) @ w_T_target_frame(q) @ target_frame_T_target

with ``w_T_target_frame`` the identity for a target fixed in the world. The camera may be
on any frame (a link fixed to the root: a static camera). The helpers
:func:`camera_T_target_symbolic`, :func:`camera_T_targets_numeric` and
:func:`target_estimates` are that equation for the ``target`` and ``pixels`` kinds.
"""

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
        Name of the target (file key ``"target"``, default ``"target"``); its pose (in
        the world, or in ``target_frame``) is unknown.
    target_frame : str or None
        The URDF frame the target is fixed to (file key ``"target_frame"``: a board on
        the flange seen by a static camera); None: fixed in the world.
    """

    kind: ClassVar[str] = "target"
    camera: str
    sample: NDArray[np.int64]
    camera_T_target: NDArray[np.float64]
    target: str = DEFAULT_TARGET
    target_frame: str | None = None

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
            f"target_frame={self.target_frame!r}, m={len(self.sample)})"
        )

    @property
    def _key(self) -> tuple[Any, ...]:
        return TargetKind().key(self)


def target_frames(camera: str, target_frame: str | None) -> tuple[str, ...]:
    """The URDF frames a camera's view of a target depends on."""
    return (camera,) if target_frame is None else (camera, target_frame)


def camera_T_target_symbolic(
    model: SymbolicContext, camera: str, target: str, target_frame: str | None
) -> Any:
    """SX 4x4 ``camera_T_target`` (module docstring)."""
    w_T_target = model.value(BlockKey("target", target))
    if target_frame is not None:
        w_T_target = model.w_T(target_frame) @ w_T_target
    return inverse_casadi(model.ca, model.w_T(camera)) @ w_T_target


def w_T_targets_numeric(
    model: NumericContext, target: str, target_frame: str | None, sample: NDArray[np.int64]
) -> NDArray[np.float64]:
    """The target's pose in the model frame at the samples, (m, 4, 4), metres."""
    w_T_target = model.value(BlockKey("target", target))
    if target_frame is not None:
        return model.w_T(target_frame, sample) @ w_T_target
    return np.broadcast_to(w_T_target, (len(sample), 4, 4))


def camera_T_targets_numeric(
    model: NumericContext,
    camera: str,
    target: str,
    target_frame: str | None,
    sample: NDArray[np.int64],
) -> NDArray[np.float64]:
    """``camera_T_target`` (m, 4, 4) at the samples (module docstring), metres."""
    return inverse_transform(model.w_T(camera, sample)) @ w_T_targets_numeric(
        model, target, target_frame, sample
    )


def target_estimates(
    start: StartContext,
    camera: str,
    target_frame: str | None,
    sample: NDArray[np.int64],
    camera_T_targets: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Per view the target's pose (k, 4, 4) in the world or its ``target_frame``, from
    the measured (or PnP) ``camera_T_targets`` (k, 4, 4) and the start kinematics."""
    T = start.w_T(camera, sample) @ camera_T_targets
    if target_frame is not None:
        T = inverse_transform(start.w_T(target_frame, sample)) @ T
    return T


def target_keys(target: str, target_frame: str | None) -> dict[str, str]:
    """The file keys of a view's target beyond the defaults (``target``,
    ``target_frame``)."""
    more = {} if target == DEFAULT_TARGET else {"target": target}
    if target_frame is not None:
        more["target_frame"] = target_frame
    return more


def described_target(target: str, camera: str, target_frame: str | None) -> str:
    """``"pose of target 'board' on 'tool0' (seen by 'camera')"``."""
    on = "" if target_frame is None else f" on {target_frame!r}"
    return f"pose of target {target!r}{on} (seen by {camera!r})"


class TargetKind(RigidTransformKind):
    """``"target"``: ``xyz`` and ``quat_xyzw`` of the target ``target`` in the camera
    frame ``frame``. Unknown: the target's pose in the root, or in ``target_frame``
    (module docstring). Residual: position (3, m, in the camera frame) and orientation
    (3, rad)."""

    name = "target"
    entity_field = "target"
    group_type = TargetObservations
    row_fields = ("camera_T_target",)
    components = (POSITION, ROTATION)
    measurements_field = "targets"
    file_keys = ("xyz", "quat_xyzw", "target", "target_frame")

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
        target_frame = reader.optional_string(obs, "target_frame", at)
        key = (("camera", frame), ("target", target), ("target_frame", target_frame))
        return key, [*reader.lengths(xyz), *quat]

    def marker(self, key):
        return None

    def group_from_rows(self, key, sample, rows):
        return TargetObservations(
            sample=sample, camera_T_target=transforms_from_rows(rows), **dict(key)
        )

    def to_dicts(self, group, top_measured_in):
        more = target_keys(group.target, group.target_frame)
        xyzs, quats = xyz_quat_xyzw_from_transform(group.camera_T_target)
        return [
            {"frame": group.camera, "kind": "target", "xyz": xyz, "quat_xyzw": quat, **more}
            for xyz, quat in zip(xyzs.tolist(), quats.tolist(), strict=True)
        ]

    def frames(self, group):
        return target_frames(group.camera, group.target_frame)

    def direct_frames(self, group):
        return (group.camera,)

    def relative_to(self, group):
        """The camera, for a target on the robot (``target_frame``); None: absolute."""
        return None if group.target_frame is None else group.camera

    def unknowns(self, group, start: StartContext):
        return (
            UnknownRequest(
                BlockKey("target", group.target),
                target_estimates(
                    start, group.camera, group.target_frame, group.sample, group.camera_T_target
                ),
                RigidFrameBlock.from_estimates,
                described_target(group.target, group.camera, group.target_frame),
            ),
        )

    def data(self, group):
        return pose_rows(group.camera_T_target)

    def residual(self, group, model: SymbolicContext, m):
        T = camera_T_target_symbolic(model, group.camera, group.target, group.target_frame)
        return pose_residual(model.ca, T, m)

    # -- numpy prediction, simulation, drawing
    def predicted_transforms(self, group, model: NumericContext):
        """Predicted ``camera_T_target`` (m, 4, 4), as :meth:`residual` forms it."""
        return camera_T_targets_numeric(
            model, group.camera, group.target, group.target_frame, group.sample
        )

    def drawing(self, group, model: NumericContext):
        """The target where the camera saw it (not framed: it may be far away), the
        residual line from the target's known pose."""
        w_T_seen = model.w_T(group.camera, group.sample) @ group.camera_T_target
        predicted, missing = predicted_or_missing(
            lambda: w_T_targets_numeric(model, group.target, group.target_frame, group.sample)[
                :, :3, 3
            ]
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
