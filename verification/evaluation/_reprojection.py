"""Reprojection errors of ``pixels`` observations against a calibration, in pixels.

Per image the RMS and max of its points' error norms ``|uv_measured - uv_predicted|``
(px), per camera the same over all its points, and the worst images named by their
label (the file name of the ``image`` key, or ``"sample i"``). The prediction is the
``pixels`` kind's numpy one (:meth:`kinfw.observations.PixelKind.predict`): the
robot's forward kinematics (Pinocchio), the target's pose and the camera's intrinsics as
calibrated (the file's intrinsics where the calibration did not estimate them).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from kinfw.measurements import Measurements
from kinfw.model import BlockKey, Robot
from kinfw.observations import NumericContext, kind_of
from kinfw.records import CameraReprojection, ImageReprojection, ReprojectionSection

#: How many of the worst images the section names.
WORST_IMAGES = 10


def reprojection_section(
    robot: Robot, data: Measurements, unknowns: Iterable[Any], *, worst: int = WORST_IMAGES
) -> ReprojectionSection | None:
    """The reprojection errors of ``data``'s ``pixels`` groups under ``robot``.

    Parameters
    ----------
    robot : Robot
        The calibrated robot (its root is the frame the unknowns are expressed in).
    data : Measurements
    unknowns : iterable of Unknown
        The calibration's unknowns (``kind``, ``name``, ``value``): target poses
        ``root_T_target`` (4, 4) and, when estimated, intrinsics (9,).
    worst : int
        How many of the worst images (by RMS) to name.

    Returns
    -------
    ReprojectionSection or None
        None when the data have no ``pixels`` observations, or a target's pose is not
        among ``unknowns``.
    """
    groups = data.groups("pixels")
    if not groups:
        return None
    values = {BlockKey(u.kind, u.name): np.asarray(u.value, dtype=float) for u in unknowns}
    if any(BlockKey("target", g.target) not in values for g in groups):
        return None
    model = NumericContext.from_robot(robot, data.qs, data.joint_names, values)
    images: list[ImageReprojection] = []
    per_camera: dict[str, list[Any]] = {}
    for g in groups:
        err = np.linalg.norm(g.uv - kind_of(g).predict(g, model)[:, :2], axis=1)
        samples, rows = g.images()
        for s, r, label in zip(samples.tolist(), rows, g.image_labels(), strict=True):
            e = err[r]
            images.append(
                ImageReprojection(
                    g.camera,
                    g.target,
                    int(s),
                    label,
                    len(r),
                    float(np.sqrt(np.mean(e**2))),
                    float(e.max()),
                )
            )
        per_camera.setdefault(g.camera, []).append(err)
    cameras = []
    for camera, errs in per_camera.items():
        e = np.concatenate(errs)
        mine = [i.rms_px for i in images if i.camera == camera]
        cameras.append(
            CameraReprojection(
                camera,
                len(mine),
                len(e),
                float(np.sqrt(np.mean(e**2))),
                float(e.max()),
                float(max(mine)),
            )
        )
    ranked = sorted(images, key=lambda i: (-i.rms_px, i.sample))
    return ReprojectionSection(tuple(cameras), tuple(images), tuple(ranked[:worst]))
