"""Start poses of the ``pixels`` kind: per image, the target's pose in the camera from
OpenCV's PnP (:func:`pnp_camera_T_targets`), and the images as ``target`` observations
(:func:`target_observations_from_pixels`) for the hand-eye stage.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import transform_from_rotation_translation

if TYPE_CHECKING:
    from kinfw.observations._pixels import PixelObservations

#: Fewest points of one image PnP needs.
PNP_MIN_POINTS = 4
_PLANAR_TOL = 1e-9  # smallest/largest singular value of the centred points: planar

#: Poses found, by a hash of each image's points, pixels and intrinsics: every problem
#: built from the same images (rejection refits, the report's evaluations, folds) asks
#: for the same PnP again; bounded (~0.3 kB an entry).
_PNP_CACHE: OrderedDict[bytes, NDArray[np.float64]] = OrderedDict()
_PNP_CACHE_SIZE = 200_000
_PNP_CACHE_LOCK = threading.Lock()


def _is_planar(target_p: NDArray[np.float64]) -> bool:
    s = np.linalg.svd(target_p - target_p.mean(axis=0), compute_uv=False)
    return bool(s[0] > 0 and s[-1] <= _PLANAR_TOL * s[0])


def _pnp_candidates(cv2: Any, obj, img, K, dist, criteria) -> list[tuple[Any, Any]]:
    """The PnP poses of one image worth refining, each refined by ``solvePnPRefineLM``:
    both of IPPE's (planar points) and SQPnP's; only finite poses with every point in
    front of the camera."""
    starts = []
    if _is_planar(obj):
        _, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
        starts += list(zip(rvecs, tvecs, strict=True))
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_SQPNP)
    if ok:
        starts.append((rvec, tvec))
    out = []
    for rvec, tvec in starts:
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec, criteria=criteria)
        if not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
            continue
        R, _ = cv2.Rodrigues(rvec)
        if ((obj @ R.T)[:, 2] + tvec[2, 0] > 0).all():
            out.append((rvec, tvec))
    return out


def _reprojection_rms(cv2: Any, obj, img, K, dist, rvec, tvec) -> float:
    uv, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    return float(np.sqrt(np.mean((uv.reshape(-1, 2) - img) ** 2)))


def pnp_camera_T_targets(group: PixelObservations) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Per image, the target's pose in the camera from its pixels (OpenCV's PnP).

    Both of ``SOLVEPNP_IPPE``'s poses (planar points) and ``SOLVEPNP_SQPNP``'s, each
    refined by ``cv2.solvePnPRefineLM`` (the reprojection error's minimum, with the
    group's intrinsics); the one with the lowest reprojection error among those that put
    every point in front of the camera (IPPE's first pose alone can be far off on an
    image of a few corners near a line). Each image's pose is kept (by a hash of its
    points, pixels and the intrinsics) and not searched again when another problem holds
    the same image.

    Images with fewer than 4 points (left by a rejection of gross errors, or a held-out
    split) are skipped: PnP needs 4.

    Returns
    -------
    samples : ndarray of int64, shape (k,)
        The sample of each image with at least 4 points (the order of
        :meth:`PixelObservations.images`).
    camera_T_targets : ndarray, shape (k, 4, 4)
        Pose of the target in the camera's optical frame, metres.

    Raises
    ------
    DatasetError
        Naming the camera (and the image and sample): no image has 4 points, or PnP
        fails on an image.
    """
    import cv2

    from kinfw.observations._reader import DatasetError

    K, dist = group.intrinsics.matrix, group.intrinsics.distortion
    all_samples, all_rows = group.images()
    labels = group.image_labels()
    keep = [k for k, r in enumerate(all_rows) if len(r) >= PNP_MIN_POINTS]
    if not keep:
        raise DatasetError(
            f"pixels: camera {group.camera!r}: none of its {len(all_rows)} images has "
            f"{PNP_MIN_POINTS} points (PnP needs {PNP_MIN_POINTS})"
        )
    samples = all_samples[keep]
    rows = [all_rows[k] for k in keep]
    labels = [labels[k] for k in keep]
    out = np.empty((len(rows), 4, 4))
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-15)
    intrinsics = (
        np.ascontiguousarray(K, dtype=np.float64).tobytes()
        + np.ascontiguousarray(dist, dtype=np.float64).tobytes()
    )
    for k, r in enumerate(rows):
        obj = np.ascontiguousarray(group.target_p[r], dtype=np.float64)
        img = np.ascontiguousarray(group.uv[r], dtype=np.float64)
        key = hashlib.blake2b(obj.tobytes() + img.tobytes() + intrinsics, digest_size=16).digest()
        with _PNP_CACHE_LOCK:
            known = _PNP_CACHE.get(key)
        if known is not None:
            out[k] = known
            continue
        where = f"image {labels[k]} (sample {int(samples[k])}, {len(r)} points)"
        try:
            found = _pnp_candidates(cv2, obj, img, K, dist, criteria)
        except cv2.error as exc:
            raise DatasetError(
                f"pixels: camera {group.camera!r}: PnP failed on {where}: "
                + " ".join(str(exc.err or exc).split())
            ) from None
        if not found:
            raise DatasetError(
                f"pixels: camera {group.camera!r}: PnP found no pose for {where} "
                "(are the points on one line?)"
            )
        rvec, tvec = min(found, key=lambda c: _reprojection_rms(cv2, obj, img, K, dist, *c))
        R, _ = cv2.Rodrigues(rvec)
        out[k] = transform_from_rotation_translation(R, np.ravel(tvec))
        with _PNP_CACHE_LOCK:
            _PNP_CACHE[key] = out[k].copy()
            while len(_PNP_CACHE) > _PNP_CACHE_SIZE:
                _PNP_CACHE.popitem(last=False)
    return samples, out


def target_observations_from_pixels(group: PixelObservations) -> Any:
    """The group's images as ``target`` observations: per image the PnP pose
    (:func:`pnp_camera_T_targets`), for the hand-eye stage (A = X B Y) and for
    comparing the pixel path with the pose path on the same detections."""
    from kinfw.observations._target import TargetObservations

    samples, camera_T_targets = pnp_camera_T_targets(group)
    return TargetObservations(
        camera=group.camera,
        sample=samples,
        camera_T_target=camera_T_targets,
        target=group.target,
        target_frame=group.target_frame,
    )
