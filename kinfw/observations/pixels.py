"""``"pixels"``: image points of a fixed target seen by a camera frame on the robot.

One observation in the file is one image of one target by one camera: the pixels ``uv``
(k, 2) of the target's points ``points`` (k, 3, in the target's frame), optionally their
ids, an image label and a pixel sigma. Inside the dataset it is k rows, one per point,
whose residual is the reprojection error (2 rows, pixels)::

    uv_measured - project(K, inv(w_T_camera) @ w_T_target @ target_p)

with ``project`` OpenCV's pinhole and distortion model
(:func:`kinfw.camera_model.project_normalized`, the same formula in CasADi and numpy).
The camera's frame is its optical frame (z forward, x right, y down). Unknowns: the
target's pose (``BlockKey("target", name)``, shared with the ``target`` kind: a pose
target and a pixel target of one name are one unknown), started per image from
``cv2.solvePnP``; and the camera's intrinsics (``BlockKey("intrinsics", camera)``, 9
numbers in OpenCV's order), known (fixed) unless the fit frees them.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from kinfw.blocks import Block, BlockKey, RigidFrameBlock
from kinfw.camera_model import PARAMETER_NAMES, CameraIntrinsics, project_normalized
from kinfw.observations.base import (
    NoiseComponent,
    ObservationKind,
    StartContext,
    SymbolicContext,
    UnknownRequest,
    data_array,
    frozen_array,
    inverse_casadi,
    sample_array,
)
from kinfw.observations.numeric import Drawing, NumericContext, node_name
from kinfw.transforms import inverse_transform, transform_from_rotation_translation

__all__ = [
    "PIXEL",
    "UNDETERMINED_PX",
    "IntrinsicsBlock",
    "PixelKind",
    "PixelObservations",
    "pnp_camera_T_targets",
    "target_observations_from_pixels",
]

PIXEL = NoiseComponent("pixel", 2, "px")
"""The reprojection error of one point: (u, v) rows in pixels."""

_DEFAULT_TARGET = "target"
_MIN_POINTS = 4
#: A freed intrinsic parameter whose 1-sigma uncertainty moves a point of the image's
#: border by more than this many pixels is reported as not determined by the images.
UNDETERMINED_PX = 1.0
_PLANAR_TOL = 1e-9  # smallest/largest singular value of the centred points: planar


@dataclass(frozen=True, slots=True)
class IntrinsicsBlock(Block):
    """A camera's 9 intrinsic parameters ``start + d`` in OpenCV's order
    (:data:`kinfw.camera_model.PARAMETER_NAMES`: fx, fy, cx, cy in px, then k1, k2, p1,
    p2, k3 unitless); fixed (known) unless freed.

    Attributes
    ----------
    start : ndarray, shape (9,)
    """

    start: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros(9))
    width: int = 0
    height: int = 0

    @property
    def fields(self) -> tuple[str, ...]:
        return PARAMETER_NAMES

    @property
    def units(self) -> tuple[str, ...]:
        return ("px",) * 4 + ("unitless",) * 5

    @staticmethod
    def from_estimates(
        key: BlockKey, estimates: NDArray[np.float64], width: int = 0, height: int = 0
    ) -> IntrinsicsBlock:
        """The intrinsics (k, 9) of the camera's groups (all equal: the file's), fixed;
        ``width``, ``height`` the image size (px) for :meth:`undetermined`."""
        start = np.asarray(estimates, dtype=float).reshape(-1, 9).mean(axis=0)
        return IntrinsicsBlock(key, free=np.zeros(9, bool), start=start, width=width, height=height)

    def undetermined(self, d, covariance):
        """Freed intrinsics whose 1-sigma uncertainty moves a point at the image's
        border (corners and edge midpoints) by more than :data:`UNDETERMINED_PX`:
        the images do not determine them (e.g. k3 when the board stays near the
        image centre)."""
        import cv2

        if not self.width or not self.height:
            return ()
        params = self.start + d
        std = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
        w, h = self.width - 1.0, self.height - 1.0
        border = np.array(
            [[0, 0], [w, 0], [0, h], [w, h], [w / 2, 0], [w / 2, h], [0, h / 2], [w, h / 2]]
        )
        K = np.array([[params[0], 0, params[2]], [0, params[1], params[3]], [0, 0, 1.0]])
        xy = cv2.undistortPoints(border.reshape(-1, 1, 2), K, params[4:9]).reshape(-1, 2)
        out = []
        for j in np.flatnonzero(self.free & (std > 0)):
            step = np.zeros(9)
            step[j] = 1e-6 * max(1.0, abs(params[j]))
            up = np.stack(project_normalized(xy[:, 0], xy[:, 1], params + step), axis=1)
            down = np.stack(project_normalized(xy[:, 0], xy[:, 1], params - step), axis=1)
            moved_px = float(np.linalg.norm((up - down) / (2 * step[j]), axis=1).max() * std[j])
            if moved_px > UNDETERMINED_PX:
                out.append(
                    (
                        (self.names[j],),
                        f"the images do not determine it: its 1-sigma uncertainty "
                        f"{std[j]:.3g} {self.units[j]} moves the image border by "
                        f"{moved_px:.3g} px (use views with the target near the image "
                        "corners, or keep it fixed)",
                    )
                )
        return tuple(out)

    def constants(self) -> NDArray[np.float64]:
        return np.asarray(self.start, dtype=float)

    def numpy_value(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.start + d

    def casadi_value(self, d: Any, c: Any = None) -> Any:
        import casadi as ca

        start = ca.DM(self.start) if c is None else c[0:9]
        return start + d[0:9]

    def coordinates(self, p: Any) -> NDArray[np.float64]:
        return np.asarray(p, dtype=float) - self.start

    def describe(self) -> str:
        return f"intrinsics of camera {self.key.name!r}"


@dataclass(frozen=True, slots=True, eq=False)
class PixelObservations:
    """All ``pixels`` observations of one fixed target by one camera: one row per point.

    Attributes
    ----------
    camera : str
        URDF frame of the camera's optical frame on the robot (the file's ``"frame"``).
    intrinsics : CameraIntrinsics
        The camera's intrinsics (the file's ``"cameras"`` entry, or ``--camera``).
    sample : ndarray of int64, shape (m,)
        Sample of each point's image.
    uv : ndarray, shape (m, 2)
        Measured pixels (OpenCV's convention).
    target_p : ndarray, shape (m, 3)
        The points in the target's frame, metres.
    point_id : ndarray of int64, shape (m,)
        The board's id of each point (-1: none given).
    shot : ndarray of int64, shape (m,)
        Which image of the group's in its sample the point is in (0 for the first):
        the rows of one ``(sample, shot)`` are one file observation.
    image : ndarray of object, shape (m,)
        The image's label (file name), ``""`` when none.
    sigma_px : ndarray, shape (m,)
        The image's stated pixel sigma (NaN: none). Stored and reported; the fit
        whitens by the noise component ``"pixel"`` (one sigma for all images).
    target : str
        Name of the fixed target (its pose in the world is unknown).
    """

    kind: ClassVar[str] = "pixels"
    camera: str
    intrinsics: CameraIntrinsics
    sample: NDArray[np.int64]
    uv: NDArray[np.float64]
    target_p: NDArray[np.float64]
    point_id: NDArray[np.int64]
    shot: NDArray[np.int64]
    image: NDArray[np.object_]
    sigma_px: NDArray[np.float64]
    target: str = _DEFAULT_TARGET

    def __post_init__(self) -> None:
        name = f"PixelObservations(camera={self.camera!r})"
        if not isinstance(self.intrinsics, CameraIntrinsics):
            raise ValueError(f"{name}.intrinsics: expected CameraIntrinsics")
        sample = sample_array(self.sample, f"{name}.sample")
        m = len(sample)
        object.__setattr__(self, "sample", sample)
        object.__setattr__(self, "uv", data_array(self.uv, (m, 2), f"{name}.uv"))
        object.__setattr__(self, "target_p", data_array(self.target_p, (m, 3), f"{name}.target_p"))
        for field in ("point_id", "shot"):
            arr = np.asarray(getattr(self, field))
            if arr.shape != (m,):
                raise ValueError(f"{name}.{field}: expected shape ({m},), got {arr.shape}")
            object.__setattr__(self, field, frozen_array(arr, np.int64))
        image = np.asarray(self.image, dtype=object)
        if image.shape != (m,):
            raise ValueError(f"{name}.image: expected shape ({m},), got {image.shape}")
        object.__setattr__(self, "image", frozen_array(image, object))
        sigma = np.asarray(self.sigma_px, dtype=float)
        if sigma.shape != (m,):
            raise ValueError(f"{name}.sigma_px: expected shape ({m},), got {sigma.shape}")
        object.__setattr__(self, "sigma_px", frozen_array(sigma, np.float64))

    def __repr__(self) -> str:
        return (
            f"PixelObservations(camera={self.camera!r}, target={self.target!r}, "
            f"images={len(self.images()[0])}, points={len(self.sample)})"
        )

    def images(self) -> tuple[NDArray[np.int64], list[NDArray[np.intp]]]:
        """The images: each one's sample (k,) and its rows (in row order, first-seen)."""
        keys = np.stack([self.sample, self.shot], axis=1)
        _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first, kind="stable")
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        which = rank[np.ravel(inverse)]
        rows = [np.flatnonzero(which == k) for k in range(len(order))]
        return self.sample[first[order]], rows

    def image_labels(self) -> list[str]:
        """Per image (the order of :meth:`images`), its label or ``"sample i"``."""
        samples, rows = self.images()
        return [
            str(self.image[r[0]]) or f"sample {int(s)}"
            for s, r in zip(samples.tolist(), rows, strict=True)
        ]


def _read_points(reader, obs, at, key, width, what):
    raw = reader.list_of(reader.get(obs, key, at, f"a list of {what}"), f"{at}.{key}", what)
    return [reader.numbers(p, width, f"{at}.{key}[{i}]") for i, p in enumerate(raw)]


def _is_planar(target_p: NDArray[np.float64]) -> bool:
    s = np.linalg.svd(target_p - target_p.mean(axis=0), compute_uv=False)
    return bool(s[0] > 0 and s[-1] <= _PLANAR_TOL * s[0])


def pnp_camera_T_targets(group: PixelObservations) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Per image, the target's pose in the camera from its pixels (OpenCV's PnP).

    ``cv2.solvePnP`` with ``SOLVEPNP_IPPE`` for planar points, ``SOLVEPNP_SQPNP`` else,
    then ``cv2.solvePnPRefineLM`` (the reprojection error's minimum, with the group's
    intrinsics).

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

    from kinfw.observations.reader import DatasetError

    K, dist = group.intrinsics.matrix, group.intrinsics.distortion
    all_samples, all_rows = group.images()
    labels = group.image_labels()
    keep = [k for k, r in enumerate(all_rows) if len(r) >= _MIN_POINTS]
    if not keep:
        raise DatasetError(
            f"pixels: camera {group.camera!r}: none of its {len(all_rows)} images has "
            f"{_MIN_POINTS} points (PnP needs {_MIN_POINTS})"
        )
    samples = all_samples[keep]
    rows = [all_rows[k] for k in keep]
    labels = [labels[k] for k in keep]
    out = np.empty((len(rows), 4, 4))
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-15)
    for k, r in enumerate(rows):
        obj = np.ascontiguousarray(group.target_p[r], dtype=np.float64)
        img = np.ascontiguousarray(group.uv[r], dtype=np.float64)
        flag = cv2.SOLVEPNP_IPPE if _is_planar(obj) else cv2.SOLVEPNP_SQPNP
        where = f"image {labels[k]} (sample {int(samples[k])}, {len(r)} points)"
        try:
            ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=flag)
            if not ok:
                ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
            if ok:
                rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec, criteria=criteria)
        except cv2.error as exc:
            raise DatasetError(
                f"pixels: camera {group.camera!r}: PnP failed on {where}: "
                + " ".join(str(exc.err or exc).split())
            ) from None
        if not ok:
            raise DatasetError(f"pixels: camera {group.camera!r}: PnP failed on {where}")
        if not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
            raise DatasetError(
                f"pixels: camera {group.camera!r}: PnP found no pose for {where} "
                "(are the points on one line?)"
            )
        R, _ = cv2.Rodrigues(rvec)
        out[k] = transform_from_rotation_translation(R, np.ravel(tvec))
    return samples, out


def target_observations_from_pixels(group: PixelObservations) -> Any:
    """The group's images as ``target`` observations: per image the PnP pose
    (:func:`pnp_camera_T_targets`), for the hand-eye stage (A = X B Y) and for
    comparing the pixel path with the pose path on the same detections."""
    from kinfw.observations.target import TargetObservations

    samples, camera_T_targets = pnp_camera_T_targets(group)
    return TargetObservations(
        camera=group.camera, sample=samples, camera_T_target=camera_T_targets, target=group.target
    )


def _project(params: NDArray[np.float64], camera_ps: NDArray[np.float64]) -> NDArray[np.float64]:
    z = camera_ps[..., 2]
    u, v = project_normalized(camera_ps[..., 0] / z, camera_ps[..., 1] / z, params)
    return np.stack([u, v], axis=-1)


class PixelKind(ObservationKind):
    """``"pixels"`` (module docstring). One file observation (an image) is many rows."""

    name = "pixels"
    group_type = PixelObservations
    row_fields = ("uv", "target_p", "point_id", "shot", "image", "sigma_px")
    components = (PIXEL,)

    # -- file edge
    def parse(self, reader, obs, at, frame):
        """One image -> (key, its points as a list of row tuples); see
        :meth:`group_from_parsed`."""
        for key, why in (
            ("marker", "a camera frame has no marker"),
            ("measured_in", "pixels are measured in the camera frame"),
            ("xyz", "a 'pixels' observation gives uv and points, not a pose"),
        ):
            reader.not_allowed(obs, key, at, self.name, why)
        cameras: Mapping[str, CameraIntrinsics] = getattr(reader, "cameras", {}) or {}
        if frame not in cameras:
            raise reader.error(
                f"{at}.frame",
                f"camera {frame!r} has no intrinsics; give them in the file's top-level "
                f'"cameras" section (or --camera {frame}=FILE)',
            )
        uv = _read_points(reader, obs, at, "uv", 2, "[u, v] pixels")
        pts = reader.lengths
        points = _read_points(reader, obs, at, "points", 3, "[x, y, z] target points")
        if len(uv) != len(points):
            raise reader.error(
                f"{at}.points",
                f"expected {len(uv)} points (one per uv entry), got {len(points)}",
            )
        if len(uv) < _MIN_POINTS:
            raise reader.error(
                f"{at}.uv", f"expected at least {_MIN_POINTS} points (PnP needs 4), got {len(uv)}"
            )
        ids = [-1] * len(uv)
        if obs.get("ids") is not None:
            raw = obs["ids"]
            if not isinstance(raw, list) or len(raw) != len(uv):
                got = f"{len(raw)}" if isinstance(raw, list) else "not a list"
                raise reader.error(f"{at}.ids", f"expected {len(uv)} integer ids, got {got}")
            for i, x in enumerate(raw):
                if isinstance(x, bool) or not isinstance(x, int) or x < 0:
                    raise reader.error(
                        f"{at}.ids[{i}]", f"expected a non-negative integer, got {x!r}"
                    )
            if len(set(raw)) != len(raw):
                raise reader.error(f"{at}.ids", "ids must be distinct")
            ids = list(raw)
        image = reader.optional_string(obs, "image", at) or ""
        sigma = float("nan")
        if obs.get("sigma_px") is not None:
            sigma = reader.number(obs, "sigma_px", at, "a positive pixel sigma")
            if not sigma > 0:
                raise reader.error(f"{at}.sigma_px", f"expected a positive number, got {sigma!r}")
        target = reader.optional_string(obs, "target", at) or _DEFAULT_TARGET
        rows = [
            (*p_uv, *pts(p), i, image, sigma) for p_uv, p, i in zip(uv, points, ids, strict=True)
        ]
        key = (("camera", frame), ("intrinsics", cameras[frame]), ("target", target))
        return key, rows

    def group_from_parsed(self, key, sample, parsed):
        """The group from the images of one key: ``parsed`` one list of point rows
        ``(u, v, x, y, z, id, image, sigma)`` per image, ``sample`` (k,) per image."""
        n = np.array([len(p) for p in parsed], dtype=np.int64)
        rows = [r for p in parsed for r in p]
        seen: dict[int, int] = {}  # the k-th image of the group in its sample
        per_image: list[int] = []
        for s in np.asarray(sample).tolist():
            per_image.append(seen.get(s, 0))
            seen[s] = per_image[-1] + 1
        shot = np.repeat(np.asarray(per_image, dtype=np.int64), n)
        return PixelObservations(
            sample=np.repeat(np.asarray(sample, dtype=np.int64), n),
            uv=np.array([r[0:2] for r in rows], dtype=float).reshape(-1, 2),
            target_p=np.array([r[2:5] for r in rows], dtype=float).reshape(-1, 3),
            point_id=np.array([r[5] for r in rows], dtype=np.int64),
            shot=shot,
            image=np.array([r[6] for r in rows], dtype=object),
            sigma_px=np.array([r[7] for r in rows], dtype=float),
            **dict(key),
        )

    def sample_dicts(self, group, top_measured_in):
        """One dict per image: ``(sample, dict)`` pairs."""
        out = []
        samples, rows = group.images()
        for s, r in zip(samples.tolist(), rows, strict=True):
            obs: dict[str, Any] = {"frame": group.camera, "kind": self.name}
            if group.target != _DEFAULT_TARGET:
                obs["target"] = group.target
            if group.image[r[0]]:
                obs["image"] = str(group.image[r[0]])
            obs["uv"] = group.uv[r].tolist()
            obs["points"] = group.target_p[r].tolist()
            if (group.point_id[r] >= 0).all():
                obs["ids"] = group.point_id[r].tolist()
            if np.isfinite(group.sigma_px[r[0]]):
                obs["sigma_px"] = float(group.sigma_px[r[0]])
            out.append((s, obs))
        return out

    def to_dicts(self, group, top_measured_in):
        return [obs for _, obs in self.sample_dicts(group, top_measured_in)]

    def cameras(self, group) -> dict[str, CameraIntrinsics]:
        return {group.camera: group.intrinsics}

    def with_cameras(self, group, cameras: Mapping[str, CameraIntrinsics]):
        if group.camera in cameras:
            return dataclasses.replace(group, intrinsics=cameras[group.camera])
        return group

    def marker(self, key):
        return None

    def key(self, group):
        return (self.name, group.camera, group.intrinsics, group.target)

    # -- structure
    def frames(self, group):
        return (group.camera,)

    def direct_frames(self, group):
        return (group.camera,)

    def camera_frames(self, group):
        return (group.camera,)

    # -- estimation
    def unknowns(self, group, start: StartContext):
        samples, camera_T_targets = pnp_camera_T_targets(group)
        return (
            UnknownRequest(
                BlockKey("target", group.target),
                start.w_T(group.camera, samples) @ camera_T_targets,
                RigidFrameBlock.from_estimates,
                f"pose of target {group.target!r} (seen by {group.camera!r})",
            ),
            UnknownRequest(
                BlockKey("intrinsics", group.camera),
                group.intrinsics.parameters[None],
                functools.partial(
                    IntrinsicsBlock.from_estimates,
                    width=group.intrinsics.width,
                    height=group.intrinsics.height,
                ),
                f"intrinsics of camera {group.camera!r}",
            ),
        )

    def data(self, group):
        return np.concatenate([group.uv, group.target_p], axis=1)

    def residual(self, group, model: SymbolicContext, m):
        ca = model.ca
        c_T_t = inverse_casadi(ca, model.w_T(group.camera)) @ model.value(
            BlockKey("target", group.target)
        )
        p = c_T_t[0:3, 0:3] @ m[2:5] + c_T_t[0:3, 3]
        params = model.value(BlockKey("intrinsics", group.camera))
        u, v = project_normalized(p[0] / p[2], p[1] / p[2], params)
        return ca.vertcat(m[0] - u, m[1] - v)

    # -- numpy prediction, simulation, drawing
    def _params(self, group, model: NumericContext) -> NDArray[np.float64]:
        key = BlockKey("intrinsics", group.camera)
        return model.value(key) if model.has(key) else group.intrinsics.parameters

    def camera_points(self, group, model: NumericContext) -> NDArray[np.float64]:
        """The target's points in the camera frame (m, 3), metres, as predicted."""
        c_T_t = inverse_transform(model.w_T(group.camera, group.sample)) @ model.value(
            BlockKey("target", group.target)
        )
        return np.einsum("mij,mj->mi", c_T_t[:, :3, :3], group.target_p) + c_T_t[:, :3, 3]

    def predict(self, group, model: NumericContext):
        uv = _project(self._params(group, model), self.camera_points(group, model))
        return np.concatenate([uv, group.target_p], axis=1)

    def with_data(self, group, rows):
        return dataclasses.replace(group, uv=np.asarray(rows, dtype=float)[:, :2])

    def simulate(self, group, model: NumericContext, rng, sigmas):
        """Pixels predicted plus independent N(0, sigmas["pixel"]) per coordinate."""
        uv = self.predict(group, model)[:, :2]
        return self.with_data(group, uv + rng.normal(0.0, float(sigmas["pixel"]), uv.shape))

    def drawing(self, group, model: NumericContext):
        """The target's points where the model puts them, and each measured pixel's ray
        at the predicted point's depth (the residual line between them)."""
        import cv2

        w_T_c = model.w_T(group.camera, group.sample)
        c_p = self.camera_points(group, model)
        params = self._params(group, model)
        K = np.array([[params[0], 0, params[2]], [0, params[1], params[3]], [0, 0, 1.0]])
        xy = cv2.undistortPoints(group.uv.reshape(-1, 1, 2), K, params[4:9]).reshape(-1, 2)
        c_p_seen = np.concatenate([xy, np.ones((len(xy), 1))], axis=1) * c_p[:, 2:3]

        def to_w(p: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.einsum("mij,mj->mi", w_T_c[:, :3, :3], p) + w_T_c[:, :3, 3]

        return Drawing(
            node_name("pixels", group.camera, group.target),
            to_w(c_p_seen),
            None,
            to_w(c_p),
            focus=False,
        )
