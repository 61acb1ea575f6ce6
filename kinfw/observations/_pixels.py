"""``"pixels"``: image points of a target seen by a camera frame on the robot.

One observation in the file is one image of one target by one camera: the pixels ``uv``
(k, 2) of the target's points ``points`` (k, 3, in the target's frame), optionally their
ids, an image label and a pixel sigma. Inside the dataset it is k rows, one per point,
whose residual is the reprojection error (2 rows, pixels)::

    uv_measured - project(K, camera_T_target(q) @ target_p)

with ``project`` OpenCV's pinhole and distortion model
(:func:`kinfw.camera.project_normalized`, the same formula in CasADi and numpy) and
``camera_T_target(q)`` the ``target`` kind's (:mod:`kinfw.observations`): the camera on
any URDF frame (a link fixed to the root is a static camera), the target fixed in the
world or, with ``target_frame``, on a URDF frame (a board on the flange).
The camera's frame is its optical frame (z forward, x right, y down). Unknowns: the
target's pose (``BlockKey("target", name)``, in the world or in ``target_frame``; shared
with the ``target`` kind: a pose target and a pixel target of one name are one unknown),
started per image from
``cv2.solvePnP``; and the camera's intrinsics (``BlockKey("intrinsics", camera)``, 9
numbers in OpenCV's order, :class:`kinfw.observations.IntrinsicsBlock`),
known (fixed) unless the fit frees them. The PnP start is :mod:`kinfw.observations`.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from kinfw.camera import CameraIntrinsics, project_normalized
from kinfw.model import BlockKey, RigidFrameBlock
from kinfw.observations._base import (
    Metric,
    NoiseComponent,
    ObservationKind,
    UnknownRequest,
    data_array,
    evenly_spaced,
    frozen_array,
    sample_array,
)
from kinfw.observations._contexts import StartContext, SymbolicContext
from kinfw.observations._intrinsics_block import IntrinsicsBlock
from kinfw.observations._numeric import Drawing, NumericContext, node_name
from kinfw.observations._pnp import PNP_MIN_POINTS, pnp_camera_T_targets
from kinfw.observations._target import (
    DEFAULT_TARGET,
    camera_T_target_symbolic,
    camera_T_targets_numeric,
    described_target,
    target_estimates,
    target_frames,
    target_keys,
)

PIXEL = NoiseComponent("pixel", 2, "px", metric=Metric("pixel", "px", axes="uv"))
"""The reprojection error of one point: (u, v) rows in pixels (its size: the norm, px)."""


@dataclass(frozen=True, slots=True, eq=False)
class PixelObservations:
    """All ``pixels`` observations of one target by one camera: one row per point.

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
        The image's stated pixel sigma (NaN: none): a relative weight in the fit (each
        image's residual rows times ``median(sigma_px) / sigma_px``, :func:`pixel_weights`)
        before the noise component ``"pixel"`` whitens them all by one sigma.
    target : str
        Name of the target (its pose in the world, or in ``target_frame``, is unknown).
    target_frame : str or None
        The URDF frame the target is fixed to (a board on the flange seen by a static
        camera); None: fixed in the world.
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
    target: str = DEFAULT_TARGET
    target_frame: str | None = None

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
            f"target_frame={self.target_frame!r}, images={len(self.images()[0])}, "
            f"points={len(self.sample)})"
        )

    def images(self) -> tuple[NDArray[np.int64], list[NDArray[np.intp]]]:
        """The images: each one's sample (k,) and its rows (in row order, first-seen)."""
        keys = np.stack([self.sample, self.shot], axis=1)
        _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first, kind="stable")
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        which = rank[np.ravel(inverse)]
        # each image's rows in row order: a stable sort by image, split at the counts
        by_image = np.argsort(which, kind="stable")
        rows = np.split(by_image, np.cumsum(np.bincount(which, minlength=len(order)))[:-1])
        return self.sample[first[order]], rows

    def image_labels(self) -> list[str]:
        """Per image (the order of :meth:`images`), its label or ``"sample i"``."""
        samples, rows = self.images()
        return [
            str(self.image[r[0]]) or f"sample {int(s)}"
            for s, r in zip(samples.tolist(), rows, strict=True)
        ]


def pixel_weights(group: PixelObservations) -> NDArray[np.float64]:
    """Each row's relative weight from its image's stated pixel sigma, (m,).

    ``median / sigma_px``, the median over the images that state one (each image counted
    once); 1 for the rows of images that state none. All 1 when no image states a sigma
    or all state the same: the stated sigmas only weigh the images against each other,
    the noise component ``"pixel"`` (estimated, or given) scales them all.
    """
    sigma = group.sigma_px
    given = np.isfinite(sigma)
    weights = np.ones(len(sigma))
    if given.any():
        _, rows = group.images()
        per_image = np.array([sigma[r[0]] for r in rows])
        reference = float(np.median(per_image[np.isfinite(per_image)]))
        weights[given] = reference / sigma[given]
    return weights


#: Images whose PnP poses start the target's pose (:func:`start_images`): a few hundred
#: average its noise out; PnP on every image of a large set would cost more than the fit.
START_IMAGES = 500


def start_images(group: PixelObservations) -> PixelObservations:
    """``group`` restricted to at most :data:`START_IMAGES` of its images with
    :data:`PNP_MIN_POINTS` points or more, evenly spread over them in order
    (:func:`evenly_spaced`), samples unchanged; the group itself when it has no more."""
    _, rows = group.images()
    usable = [r for r in rows if len(r) >= PNP_MIN_POINTS]
    if len(usable) <= START_IMAGES:
        return group
    keep = np.concatenate([usable[k] for k in evenly_spaced(len(usable), START_IMAGES)])
    keep.sort()
    return PixelKind().take(group, keep, group.sample[keep])


def _read_points(reader, obs, at, key, width, what):
    raw = reader.list_of(reader.get(obs, key, at, f"a list of {what}"), f"{at}.{key}", what)
    return [reader.numbers(p, width, f"{at}.{key}[{i}]") for i, p in enumerate(raw)]


def _project(params: NDArray[np.float64], camera_ps: NDArray[np.float64]) -> NDArray[np.float64]:
    z = camera_ps[..., 2]
    u, v = project_normalized(camera_ps[..., 0] / z, camera_ps[..., 1] / z, params)
    return np.stack([u, v], axis=-1)


class PixelKind(ObservationKind):
    """``"pixels"`` (module docstring). One file observation (an image) is many rows."""

    name = "pixels"
    entity_field = "target"
    group_type = PixelObservations
    row_fields = ("uv", "target_p", "point_id", "shot", "image", "sigma_px")
    components = (PIXEL,)
    file_keys = ("uv", "points", "ids", "image", "sigma_px", "target", "target_frame")

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
        if len(uv) < PNP_MIN_POINTS:
            raise reader.error(
                f"{at}.uv",
                f"expected at least {PNP_MIN_POINTS} points (PnP needs 4), got {len(uv)}",
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
        target = reader.optional_string(obs, "target", at) or DEFAULT_TARGET
        target_frame = reader.optional_string(obs, "target_frame", at)
        rows = [
            (*p_uv, *pts(p), i, image, sigma) for p_uv, p, i in zip(uv, points, ids, strict=True)
        ]
        key = (
            ("camera", frame),
            ("intrinsics", cameras[frame]),
            ("target", target),
            ("target_frame", target_frame),
        )
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
            obs.update(target_keys(group.target, group.target_frame))
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
        return (self.name, group.camera, group.intrinsics, group.target, group.target_frame)

    # -- structure
    def frames(self, group):
        return target_frames(group.camera, group.target_frame)

    def direct_frames(self, group):
        return (group.camera,)

    def relative_to(self, group):
        """The camera, for a target on the robot (``target_frame``); None: absolute."""
        return None if group.target_frame is None else group.camera

    def camera_frames(self, group):
        return (group.camera,)

    # -- estimation
    def unknowns(self, group, start: StartContext):
        """The target's start from the PnP poses of at most :data:`START_IMAGES` of the
        images (:func:`start_images`), and the intrinsics' from the file."""
        samples, camera_T_targets = pnp_camera_T_targets(start_images(group))
        return (
            UnknownRequest(
                BlockKey("target", group.target),
                target_estimates(
                    start, group.camera, group.target_frame, samples, camera_T_targets
                ),
                RigidFrameBlock.from_estimates,
                described_target(group.target, group.camera, group.target_frame),
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

    def row_weights(self, group):
        """:func:`pixel_weights`: the relative weight of each image's rows."""
        return pixel_weights(group)

    def data(self, group):
        """Per point ``[u, v, x, y, z, w]``: pixels, target point (m), and the row's
        relative weight (:func:`pixel_weights`), data so the cached graph is structural."""
        return np.concatenate([group.uv, group.target_p, pixel_weights(group)[:, None]], axis=1)

    def residual(self, group, model: SymbolicContext, m):
        """``w * (uv_measured - uv_predicted)``, pixels times the row's weight ``m[5]``."""
        ca = model.ca
        c_T_t = camera_T_target_symbolic(model, group.camera, group.target, group.target_frame)
        p = c_T_t[0:3, 0:3] @ m[2:5] + c_T_t[0:3, 3]
        params = model.value(BlockKey("intrinsics", group.camera))
        u, v = project_normalized(p[0] / p[2], p[1] / p[2], params)
        return m[5] * ca.vertcat(m[0] - u, m[1] - v)

    # -- numpy prediction, simulation, drawing
    def _params(self, group, model: NumericContext) -> NDArray[np.float64]:
        key = BlockKey("intrinsics", group.camera)
        return model.value(key) if model.has(key) else group.intrinsics.parameters

    def camera_points(self, group, model: NumericContext) -> NDArray[np.float64]:
        """The target's points in the camera frame (m, 3), metres, as predicted."""
        c_T_t = camera_T_targets_numeric(
            model, group.camera, group.target, group.target_frame, group.sample
        )
        return np.einsum("mij,mj->mi", c_T_t[:, :3, :3], group.target_p) + c_T_t[:, :3, 3]

    def predict(self, group, model: NumericContext):
        """Predicted rows in :meth:`data`'s layout: the pixels ``uv`` (unweighted,
        ``[:, :2]``), the target points and the rows' weights."""
        uv = _project(self._params(group, model), self.camera_points(group, model))
        return np.concatenate([uv, group.target_p, pixel_weights(group)[:, None]], axis=1)

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
