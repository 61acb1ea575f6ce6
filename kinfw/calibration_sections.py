"""The sections of a calibration report (:mod:`kinfw.calibration_report`): closed form,
hand-eye, joint refinement and export, as typed frozen dataclasses with ``to_dict`` /
``from_dict`` (the keys of ``report.json``, format ``kinfw-calibration-report`` v1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from kinfw.calibration_file import CalibratedUnknown, DocReader, NoiseSummary

__all__ = [
    "CameraMount",
    "CameraReprojection",
    "ClosedFormSection",
    "Correlation",
    "DownweightedRow",
    "ExportSection",
    "HandEyeSection",
    "IdentifiabilitySummary",
    "ImageReprojection",
    "KinematicValue",
    "NotIdentifiable",
    "ParameterRow",
    "RefineSection",
    "ReprojectionSection",
    "TargetEstimate",
]


def _none_if_nan(v: float) -> float | None:
    return None if np.isnan(v) else float(v)


def _rows(cls, doc: dict, key: str, r: DocReader, at: str) -> tuple:
    path = r.path(at, key)
    return tuple(cls.from_dict(d, r, f"{path}[{k}]") for k, d in enumerate(r.items(doc, key, at)))


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
    (:meth:`kinfw.cpc.CPCModel.describe`)."""

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
    """Stage 1, Shih et al.'s closed form (:class:`identification.closed_form.
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
            _rows(KinematicValue, params, "values", r, p_at),
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
            _rows(CameraMount, doc, "cameras", r, at), _rows(TargetEstimate, doc, "targets", r, at)
        )


# -- refinement -------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class ParameterRow:
    """One parameter of the joint least squares: its unit (from its block), whether it
    was fixed, its change from the start and its standard deviation (None if fixed)."""

    owner: str
    field: str
    unit: str
    fixed: bool
    delta_from_start: float
    std: float | None

    def to_dict(self) -> dict[str, Any]:
        return {
            "owner": self.owner,
            "field": self.field,
            "unit": self.unit,
            "fixed": self.fixed,
            "delta_from_start": self.delta_from_start,
            "std": self.std,
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> ParameterRow:
        doc = r.obj(doc, at)
        return cls(
            r.string(doc, "owner", at),
            r.string(doc, "field", at),
            r.string(doc, "unit", at),
            r.boolean(doc, "fixed", at),
            r.number(doc, "delta_from_start", at),
            r.number(doc, "std", at, optional=True),
        )


@dataclass(frozen=True, slots=True)
class NotIdentifiable:
    """Parameters (``"owner:field"``) the data does not determine, and why."""

    parameters: tuple[str, ...]
    why: str

    def to_dict(self) -> dict[str, Any]:
        return {"parameters": list(self.parameters), "why": self.why}

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> NotIdentifiable:
        doc = r.obj(doc, at)
        return cls(r.strings(doc, "parameters", at), r.string(doc, "why", at))


@dataclass(frozen=True, slots=True)
class Correlation:
    """Two parameters whose estimates correlate beyond 0.9."""

    a: str
    b: str
    rho: float

    def to_dict(self) -> dict[str, Any]:
        return {"a": self.a, "b": self.b, "rho": self.rho}

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> Correlation:
        doc = r.obj(doc, at)
        return cls(r.string(doc, "a", at), r.string(doc, "b", at), r.number(doc, "rho", at))


@dataclass(frozen=True, slots=True)
class IdentifiabilitySummary:
    """Rank, condition number and Borm & Menq's O1 (None when undefined or infinite),
    the parameters the data does not determine and the strong correlations."""

    rank: int
    n_parameters: int
    condition: float | None
    observability_o1: float | None
    not_identifiable: tuple[NotIdentifiable, ...]
    correlations: tuple[Correlation, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "rank": self.rank,
            "n_parameters": self.n_parameters,
            "condition": self.condition,
            "observability_O1": self.observability_o1,
            "not_identifiable": [n.to_dict() for n in self.not_identifiable],
            "correlations_above_0.9": [c.to_dict() for c in self.correlations],
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> IdentifiabilitySummary:
        doc = r.obj(doc, at)
        return cls(
            r.integer(doc, "rank", at),
            r.integer(doc, "n_parameters", at),
            r.number(doc, "condition", at, optional=True),
            r.number(doc, "observability_O1", at, optional=True),
            _rows(NotIdentifiable, doc, "not_identifiable", r, at),
            _rows(Correlation, doc, "correlations_above_0.9", r, at),
        )


def _observation_dict(row: Any) -> dict[str, Any]:
    """The fields a down-weighted and a rejected observation share, in file order."""
    return {
        "sample": row.sample,
        "kind": row.kind,
        "frame": row.frame,
        "marker": row.marker,
        "position_residual_mm": row.position_residual_mm,
        "rotation_residual_deg": row.rotation_residual_deg,
        **({} if row.pixel_residual_px is None else {"pixel_residual_px": row.pixel_residual_px}),
        **({} if row.where is None else {"where": row.where}),
    }


def _observation_fields(doc: Any, r: DocReader, at: str, *, position_optional: bool) -> tuple:
    """Those shared fields read back: (sample, kind, frame, marker, mm, deg)."""
    return (
        r.integer(doc, "sample", at),
        r.string(doc, "kind", at),
        r.string(doc, "frame", at),
        r.string(doc, "marker", at, optional=True),
        r.number(doc, "position_residual_mm", at, optional=position_optional),
        r.number(doc, "rotation_residual_deg", at, optional=True),
    )


def _pixel_field(doc: Any, r: DocReader, at: str) -> dict[str, Any]:
    """The optional ``pixel_residual_px`` (a ``pixels`` observation's reprojection error)
    and ``where`` (its image and corner)."""
    return {
        "pixel_residual_px": r.number(doc, "pixel_residual_px", at, optional=True),
        "where": r.string(doc, "where", at, optional=True),
    }


@dataclass(frozen=True, slots=True)
class DownweightedRow:
    """An observation the robust loss down-weighted: ``sample`` (index into the data
    file's samples, from 0), kind, frame (camera for targets), marker, residual norms
    (mm, None for a kind without lengths; deg, None without orientation; px for an
    image point, else None) and the weight it got (1 = full)."""

    sample: int
    kind: str
    frame: str
    marker: str | None
    position_residual_mm: float | None
    rotation_residual_deg: float | None
    weight: float
    pixel_residual_px: float | None = None
    where: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {**_observation_dict(self), "weight": self.weight}

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> DownweightedRow:
        doc = r.obj(doc, at)
        return cls(
            *_observation_fields(doc, r, at, position_optional=True),
            r.number(doc, "weight", at),
            **_pixel_field(doc, r, at),
        )


@dataclass(frozen=True, slots=True)
class RejectedRow:
    """An observation excluded from the fit as a gross error
    (:class:`identification.refine.RejectedObservation`): ``sample`` (index into the
    data file's samples, from 0), kind, frame (camera for targets), marker, residual
    norms against the calibration (mm; deg, None without orientation; px for an image
    point), and how far beyond the rejection threshold its whitened norm was
    (``excess``, > 1)."""

    sample: int
    kind: str
    frame: str
    marker: str | None
    position_residual_mm: float | None
    rotation_residual_deg: float | None
    excess: float
    pixel_residual_px: float | None = None
    where: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {**_observation_dict(self), "excess": self.excess}

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> RejectedRow:
        doc = r.obj(doc, at)
        return cls(
            *_observation_fields(doc, r, at, position_optional=True),
            r.number(doc, "excess", at),
            **_pixel_field(doc, r, at),
        )


@dataclass(frozen=True, slots=True)
class RefineSection:
    """The joint least squares (:class:`identification.refine.RefineResult`) as reported."""

    loss: str
    noise: NoiseSummary
    reduced_chi_square: float
    iterations: int
    converged: bool
    seconds: float
    model_frame: str | None
    parameters: tuple[ParameterRow, ...]
    kinematics: tuple[KinematicValue, ...]
    unknowns: tuple[CalibratedUnknown, ...]
    identifiability: IdentifiabilitySummary
    downweighted: tuple[DownweightedRow, ...]
    #: None: a report written before rejection existed (the keys are then not written)
    rejected: tuple[RejectedRow, ...] | None = ()
    rejection_note: str | None = None

    METHOD: ClassVar[str] = (
        "joint nonlinear least squares (CasADi residuals and Jacobians, "
        "Levenberg-Marquardt), residuals whitened by the noise below"
    )
    PARAMETERS_NOTE: ClassVar[str] = (
        "delta_from_start and std in the parameter's unit (rad, m or unitless); fixed: not "
        "estimated (held at the start, delta_from_start 0, std null)"
    )
    DOWNWEIGHTED_NOTE: ClassVar[str] = (
        "observations beyond the robust loss's threshold, the worst (lowest weight) first; "
        "sample is the index into the data file's samples (from 0)"
    )
    REJECTED_NOTE: ClassVar[str] = (
        "gross errors: observations beyond the 99.9 % quantile of the clean residual norm "
        "under the estimated noise, excluded and the problem refitted without them (not in "
        "the fit, the noise estimate nor the errors above); the worst (largest excess over "
        "the threshold) first; residuals against the calibrated model"
    )

    @property
    def n_fixed(self) -> int:
        return sum(p.fixed for p in self.parameters)

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.METHOD,
            "loss": self.loss,
            "noise": self.noise.to_dict(),
            "reduced_chi_square": self.reduced_chi_square,
            "iterations": self.iterations,
            "converged": self.converged,
            "seconds": self.seconds,
            "model_frame": self.model_frame,
            "parameters_note": self.PARAMETERS_NOTE,
            "parameters": [p.to_dict() for p in self.parameters],
            "kinematics": [k.to_dict() for k in self.kinematics],
            "unknowns": [u.to_dict() for u in self.unknowns],
            "identifiability": self.identifiability.to_dict(),
            "downweighted_note": self.DOWNWEIGHTED_NOTE,
            "downweighted": [d.to_dict() for d in self.downweighted],
            **(
                {}
                if self.rejected is None
                else {
                    "rejected_note": self.REJECTED_NOTE,
                    "rejected": [d.to_dict() for d in self.rejected],
                    "rejection_note": self.rejection_note,
                }
            ),
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> RefineSection:
        doc = r.obj(doc, at)
        return cls(
            r.string(doc, "loss", at),
            NoiseSummary.from_dict(r.value(doc, "noise", at), r, r.path(at, "noise")),
            r.number(doc, "reduced_chi_square", at),
            r.integer(doc, "iterations", at),
            r.boolean(doc, "converged", at),
            r.number(doc, "seconds", at),
            r.string(doc, "model_frame", at, optional=True),
            _rows(ParameterRow, doc, "parameters", r, at),
            _rows(KinematicValue, doc, "kinematics", r, at),
            _rows(CalibratedUnknown, doc, "unknowns", r, at),
            IdentifiabilitySummary.from_dict(
                r.value(doc, "identifiability", at), r, r.path(at, "identifiability")
            ),
            _rows(DownweightedRow, doc, "downweighted", r, at),
            None  # a report written before rejection existed
            if "rejected" not in doc
            else _rows(RejectedRow, doc, "rejected", r, at),
            r.string(doc, "rejection_note", at, optional=True),
        )


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


# -- reprojection (pixels) ---------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class ImageReprojection:
    """One image's reprojection error against the calibration: the camera and target,
    ``sample`` (index into the data file's samples, from 0), the image's label (its
    file name, or ``"sample i"``), its points, and the RMS and max of the points' error
    norms (px)."""

    camera: str
    target: str
    sample: int
    image: str
    n_points: int
    rms_px: float
    max_px: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "camera": self.camera,
            "target": self.target,
            "sample": self.sample,
            "image": self.image,
            "n_points": self.n_points,
            "rms_px": self.rms_px,
            "max_px": self.max_px,
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> ImageReprojection:
        doc = r.obj(doc, at)
        return cls(
            r.string(doc, "camera", at),
            r.string(doc, "target", at),
            r.integer(doc, "sample", at),
            r.string(doc, "image", at),
            r.integer(doc, "n_points", at),
            r.number(doc, "rms_px", at),
            r.number(doc, "max_px", at),
        )


@dataclass(frozen=True, slots=True)
class CameraReprojection:
    """A camera's reprojection error over all its images: RMS and max of the points'
    error norms (px), and the largest RMS of one image (px)."""

    camera: str
    n_images: int
    n_points: int
    rms_px: float
    max_px: float
    worst_image_rms_px: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "camera": self.camera,
            "n_images": self.n_images,
            "n_points": self.n_points,
            "rms_px": self.rms_px,
            "max_px": self.max_px,
            "worst_image_rms_px": self.worst_image_rms_px,
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> CameraReprojection:
        doc = r.obj(doc, at)
        return cls(
            r.string(doc, "camera", at),
            r.integer(doc, "n_images", at),
            r.integer(doc, "n_points", at),
            r.number(doc, "rms_px", at),
            r.number(doc, "max_px", at),
            r.number(doc, "worst_image_rms_px", at),
        )


@dataclass(frozen=True, slots=True)
class ReprojectionSection:
    """Reprojection errors of ``pixels`` observations against the calibration (the
    calibrated kinematics, target poses and intrinsics), in pixels: per camera, per
    image, and the worst images by RMS (worst first)."""

    cameras: tuple[CameraReprojection, ...]
    images: tuple[ImageReprojection, ...]
    worst: tuple[ImageReprojection, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "cameras": [c.to_dict() for c in self.cameras],
            "worst_images": [i.to_dict() for i in self.worst],
            "images": [i.to_dict() for i in self.images],
        }

    @classmethod
    def from_dict(cls, doc: Any, r: DocReader, at: str) -> ReprojectionSection:
        doc = r.obj(doc, at)
        return cls(
            _rows(CameraReprojection, doc, "cameras", r, at),
            _rows(ImageReprojection, doc, "images", r, at),
            _rows(ImageReprojection, doc, "worst_images", r, at),
        )
