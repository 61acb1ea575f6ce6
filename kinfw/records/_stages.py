"""The stage sections of a calibration report (:mod:`kinfw.records`): closed
form, hand-eye and export, as typed frozen dataclasses with ``to_dict`` / ``from_dict``
(the keys of ``report.json``, format ``kinfw-calibration-report`` v1). The joint
refinement's section is :mod:`kinfw.records`, the reprojection errors'
:mod:`kinfw.records`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from kinfw.records._doc_reader import DocReader


def _none_if_nan(v: float) -> float | None:
    return None if np.isnan(v) else float(v)


def _xyz_rpy(T: NDArray[np.float64]) -> dict[str, Any]:
    import pinocchio as pin

    return {
        "xyz_m": T[:3, 3].tolist(),
        "rpy_rad": pin.rpy.matrixToRpy(T[:3, :3]).tolist(),
        "matrix": T.tolist(),
    }


def _pose(doc: dict, key: str, r: DocReader, at: str) -> NDArray[np.float64]:
    """A pose written by :func:`_xyz_rpy`: its ``matrix`` is read (xyz and rpy follow)."""
    pose_at = r.path(at, key)
    pose = r.obj(r.value(doc, key, at), pose_at)
    return r.array(r.value(pose, "matrix", pose_at), f"{pose_at}.matrix", (4, 4))


# -- closed form and hand-eye -----------------------------------------------------------
@dataclass(frozen=True, slots=True)
class KinematicValue:
    """A kinematic quantity ``(owner, name)`` of a CPC model and its SI unit
    (:meth:`kinfw.model.CPCModel.describe`)."""

    owner: str
    name: str
    value: float
    unit: str

    def to_dict(self) -> dict[str, Any]:
        return {"owner": self.owner, "name": self.name, "value": self.value, "unit": self.unit}

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> KinematicValue:
        doc = r.obj(doc, at)
        return cls(
            r.string(doc, "owner", at),
            r.string(doc, "name", at),
            r.number(doc, "value", at),
            r.string(doc, "unit", at),
        )


@dataclass(frozen=True, slots=True)
class ClosedFormSection:
    """Stage 1, Shih et al.'s closed form (:class:`kinfw.identification.
    ClosedFormResult`): per joint its samples, axis-fit residual (rad, NaN when not
    fitted) and motion per unit joint value; the canonical CPC parameters."""

    joint_names: tuple[str, ...]
    frames: tuple[str, ...]
    q0: tuple[float, ...]
    samples_per_joint: tuple[int, ...]
    axis_residual_rad: tuple[float, ...]
    motion_per_unit_joint_value: tuple[float, ...]
    position_rms_mm: float
    values: tuple[KinematicValue, ...]
    n_identifiable: int

    METHOD: ClassVar[str] = "CPC closed form, Shih et al. (1992) section 4"
    NOTE: ClassVar[str] = (
        "canonical CPC parameters (Shih et al. eqs. 3-4, Table 1 gauge): per joint the "
        "axis b of its frame in its parent's moved frame, beta, l (m) and the motion "
        "sense; per end frame its pose in the moved frame of its last joint (m, URDF rpy "
        "in rad)"
    )

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.METHOD,
            "joint_names": list(self.joint_names),
            "frames": list(self.frames),
            "q0": list(self.q0),
            "samples_per_joint": list(self.samples_per_joint),
            "axis_residual_rad": [_none_if_nan(v) for v in self.axis_residual_rad],
            "motion_per_unit_joint_value": list(self.motion_per_unit_joint_value),
            "position_rms_mm": self.position_rms_mm,
            "parameters": {
                "note": self.NOTE,
                "values": [v.to_dict() for v in self.values],
                "n_identifiable": self.n_identifiable,
            },
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> ClosedFormSection:
        doc = r.obj(doc, at)
        params = r.obj(r.value(doc, "parameters", at), r.path(at, "parameters"))
        p_at = r.path(at, "parameters")

        def numbers(key: str, null: bool = False) -> tuple[float, ...]:
            return tuple(r.array(r.value(doc, key, at), r.path(at, key), allow_null=null).tolist())

        samples = r.items(doc, "samples_per_joint", at)
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in samples):
            raise r.fail(r.path(at, "samples_per_joint"), "a list of integers", samples)
        return cls(
            r.strings(doc, "joint_names", at),
            r.strings(doc, "frames", at),
            numbers("q0"),
            tuple(samples),
            numbers("axis_residual_rad", True),
            numbers("motion_per_unit_joint_value"),
            r.number(doc, "position_rms_mm", at),
            r.rows(KinematicValue, params, "values", p_at),
            r.integer(params, "n_identifiable", p_at),
        )


@dataclass(frozen=True, slots=True, eq=False)
class CameraMount:
    """One camera's hand-eye solution (Hirsh et al. A = X B Y): ``hand_T_camera``
    (4, 4, metres), the solver's iterations and its RMS residuals."""

    camera: str
    target: str
    joint: str
    hand: str
    hand_T_camera: NDArray[np.float64]
    n_views: int
    iterations: int
    restarts: int
    converged: bool
    rms_rotation_deg: float
    rms_translation_mm: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "camera": self.camera,
            "target": self.target,
            "joint": self.joint,
            "hand": self.hand,
            "hand_T_camera": _xyz_rpy(self.hand_T_camera),
            "n_views": self.n_views,
            "iterations": self.iterations,
            "restarts": self.restarts,
            "converged": self.converged,
            "rms_rotation_deg": self.rms_rotation_deg,
            "rms_translation_mm": self.rms_translation_mm,
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> CameraMount:
        doc = r.obj(doc, at)
        s = (r.string(doc, k, at) for k in ("camera", "target", "joint", "hand"))
        return cls(
            *s,
            _pose(doc, "hand_T_camera", r, at),
            r.integer(doc, "n_views", at),
            r.integer(doc, "iterations", at),
            r.integer(doc, "restarts", at),
            r.boolean(doc, "converged", at),
            r.number(doc, "rms_rotation_deg", at),
            r.number(doc, "rms_translation_mm", at),
        )


@dataclass(frozen=True, slots=True, eq=False)
class TargetEstimate:
    """A target's pose from the hand-eye step and how far the cameras disagree on it."""

    target: str
    root_T_target: NDArray[np.float64]
    camera_disagreement_mm: float
    camera_disagreement_deg: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "target": self.target,
            "root_T_target": _xyz_rpy(self.root_T_target),
            "camera_disagreement_mm": self.camera_disagreement_mm,
            "camera_disagreement_deg": self.camera_disagreement_deg,
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> TargetEstimate:
        doc = r.obj(doc, at)
        return cls(
            r.string(doc, "target", at),
            _pose(doc, "root_T_target", r, at),
            r.number(doc, "camera_disagreement_mm", at),
            r.number(doc, "camera_disagreement_deg", at),
        )


@dataclass(frozen=True, slots=True)
class HandEyeSection:
    """Stage 2: every camera's mount and every target's pose."""

    cameras: tuple[CameraMount, ...]
    targets: tuple[TargetEstimate, ...]

    METHOD: ClassVar[str] = "iterative A = X B Y, Hirsh, DeSouza & Kak (2001), per camera"

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.METHOD,
            "cameras": [c.to_dict() for c in self.cameras],
            "targets": [t.to_dict() for t in self.targets],
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> HandEyeSection:
        doc = r.obj(doc, at)
        return cls(
            r.rows(CameraMount, doc, "cameras", at), r.rows(TargetEstimate, doc, "targets", at)
        )


# -- export -----------------------------------------------------------------------------
@dataclass(frozen=True, slots=True, eq=False)
class ExportSection:
    """The last URDF export: the root's pose in the measurement frame ``w_T_root`` (4, 4,
    metres) and the link frames it moved, with the shift of each (mm)."""

    w_T_root: NDArray[np.float64]
    moved_link_frames: tuple[tuple[str, float], ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "w_T_root": self.w_T_root.tolist(),
            "moved_link_frames": [
                {"link": link, "shift_mm": mm} for link, mm in self.moved_link_frames
            ],
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> ExportSection:
        doc = r.obj(doc, at)
        moved = []
        for k, m in enumerate(r.items(doc, "moved_link_frames", at)):
            m_at = f"{at}.moved_link_frames[{k}]"
            m = r.obj(m, m_at)
            moved.append((r.string(m, "link", m_at), r.number(m, "shift_mm", m_at)))
        return cls(r.array(r.value(doc, "w_T_root", at), f"{at}.w_T_root", (4, 4)), tuple(moved))
