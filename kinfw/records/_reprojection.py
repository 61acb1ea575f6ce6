"""The reprojection section of a calibration report (:mod:`kinfw.records`):
the pixel errors of ``pixels`` observations per camera and per image, typed frozen
dataclasses with ``to_dict`` / ``from_dict`` (the ``reprojection`` key of
``report.json``, format ``kinfw-calibration-report`` v1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from kinfw.records._doc_reader import DocReader


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
            r.rows(CameraReprojection, doc, "cameras", at),
            r.rows(ImageReprojection, doc, "images", at),
            r.rows(ImageReprojection, doc, "worst_images", at),
        )
