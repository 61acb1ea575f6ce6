"""A camera's intrinsics: pinhole with radial/tangential distortion, OpenCV's convention.

A point ``camera_p`` (metres, in the camera's optical frame: x right, y down, z forward
along the optical axis) projects to the pixel ``(u, v)`` by OpenCV's model
(``cv2.projectPoints``, Brown-Conrady "plumb_bob" in ROS)::

    x, y = X / Z, Y / Z,                        r^2 = x^2 + y^2
    radial = 1 + k1 r^2 + k2 r^4 + k3 r^6
    x'' = x radial + 2 p1 x y + p2 (r^2 + 2 x^2)
    y'' = y radial + p1 (r^2 + 2 y^2) + 2 p2 x y
    u = fx x'' + cx,    v = fy y'' + cy.

Pixel coordinates follow OpenCV: the centre of the top-left pixel is ``(0, 0)``, ``u``
grows to the right, ``v`` downwards. The nine parameters are ordered ``(fx, fy, cx, cy,
k1, k2, p1, p2, k3)`` (:data:`PARAMETER_NAMES`), pixels and unitless.

One formula (:func:`project_normalized`) serves numpy arrays and CasADi expressions, so
the refinement's residual and the simulation cannot disagree.

Files (:func:`read_camera`):

- ROS ``camera_info`` YAML (``camera_calibration``'s output: ``image_width``,
  ``image_height``, ``camera_name``, ``camera_matrix``, ``distortion_model:
  plumb_bob``, ``distortion_coefficients``);
- OpenCV ``FileStorage`` YAML/XML (``camera_matrix`` / ``distortion_coefficients`` as
  ``!!opencv-matrix``, ``image_width`` / ``image_height``), as written by OpenCV's
  calibration sample;
- plain JSON: ``{"width": 640, "height": 480, "fx": ..., "fy": ..., "cx": ..., "cy": ...,
  "k1": 0, "k2": 0, "p1": 0, "p2": 0, "k3": 0, "name": "left"}`` (distortion terms
  optional, zero by default), the form :meth:`CameraIntrinsics.to_dict` writes.

YAML is read with OpenCV's ``FileStorage`` (imported when a YAML file is read).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: The intrinsic parameters in OpenCV's order: focal lengths and principal point (px),
#: then the distortion coefficients (unitless) as in ``cv2.projectPoints``.
PARAMETER_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
_DISTORTION = ("k1", "k2", "p1", "p2", "k3")


class CameraError(ValueError):
    """A camera file or intrinsics that cannot be used; the message names the file and key."""


def project_normalized(x: Any, y: Any, params: Any) -> tuple[Any, Any]:
    """Pixel coordinates of normalized image coordinates ``x = X/Z``, ``y = Y/Z``.

    Parameters
    ----------
    x, y : ndarray or casadi.SX
        Normalized coordinates (any matching shapes, or CasADi scalars).
    params : sequence of 9
        ``(fx, fy, cx, cy, k1, k2, p1, p2, k3)`` (:data:`PARAMETER_NAMES`): numbers or
        CasADi scalars.

    Returns
    -------
    u, v : like ``x``
        Pixels (OpenCV's convention; module docstring). Plain arithmetic: the same code
        builds the CasADi residual and the numpy prediction.
    """
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = (params[i] for i in range(9))
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xy = x * y
    xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy
    return fx * xd + cx, fy * yd + cy


@dataclass(frozen=True, slots=True)
class CameraIntrinsics:
    """A camera's image size, pinhole and distortion (OpenCV's convention).

    Attributes
    ----------
    width, height : int
        Image size, pixels.
    fx, fy : float
        Focal lengths, pixels.
    cx, cy : float
        Principal point, pixels (top-left pixel centre at (0, 0)).
    k1, k2, p1, p2, k3 : float
        Radial (k) and tangential (p) distortion, unitless.
    name : str
        The camera's name in its file (ROS ``camera_name``), for messages.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    name: str = "camera"

    def __post_init__(self) -> None:
        for field in ("width", "height"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value <= 0:
                raise CameraError(
                    f"camera {self.name!r}: {field} must be a positive integer (pixels), "
                    f"got {value!r}"
                )
        for field in PARAMETER_NAMES:
            value = getattr(self, field)
            if isinstance(value, bool) or not math.isfinite(float(value)):
                raise CameraError(f"camera {self.name!r}: {field} must be a finite number")
        for field in ("fx", "fy"):
            if float(getattr(self, field)) <= 0.0:
                raise CameraError(
                    f"camera {self.name!r}: {field} must be positive (pixels), "
                    f"got {getattr(self, field)!r}"
                )

    @property
    def parameters(self) -> NDArray[np.float64]:
        """``(fx, fy, cx, cy, k1, k2, p1, p2, k3)``, shape (9,) (:data:`PARAMETER_NAMES`)."""
        return np.array([float(getattr(self, f)) for f in PARAMETER_NAMES])

    @property
    def matrix(self) -> NDArray[np.float64]:
        """OpenCV's camera matrix ``K``, shape (3, 3), pixels."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def distortion(self) -> NDArray[np.float64]:
        """OpenCV's distortion vector ``(k1, k2, p1, p2, k3)``, shape (5,)."""
        return np.array([float(getattr(self, f)) for f in _DISTORTION])

    def with_parameters(self, parameters: ArrayLike) -> CameraIntrinsics:
        """The same camera with other ``(fx, fy, cx, cy, k1, k2, p1, p2, k3)``."""
        values = np.asarray(parameters, dtype=float)
        if values.shape != (9,):
            raise CameraError(
                f"camera {self.name!r}: expected 9 parameters {PARAMETER_NAMES}, "
                f"got shape {values.shape}"
            )
        return CameraIntrinsics(
            self.width,
            self.height,
            **dict(zip(PARAMETER_NAMES, values.tolist(), strict=True)),
            name=self.name,
        )

    def project(self, camera_ps: ArrayLike) -> NDArray[np.float64]:
        """Pixels of points in the camera's optical frame.

        Parameters
        ----------
        camera_ps : array_like, shape (..., 3)
            Points in the camera frame, metres (z along the optical axis).

        Returns
        -------
        ndarray, shape (..., 2)
            ``(u, v)`` pixels; points at or behind the camera (z <= 0) give NaN (see
            :meth:`in_view`).
        """
        p = np.asarray(camera_ps, dtype=float)
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            safe = np.where(z > 0.0, z, np.nan)
            u, v = project_normalized(p[..., 0] / safe, p[..., 1] / safe, self.parameters)
        return np.stack([u, v], axis=-1)

    def rays(self, uv: ArrayLike) -> NDArray[np.float64]:
        """Unit rays in the camera's optical frame of pixels: the inverse of
        :meth:`project` (``project(rays(uv)) == uv``).

        The distortion is inverted by OpenCV's ``cv2.undistortPointsIter`` iterated to
        1e-15 (its default of 5 iterations leaves up to ~0.1 px at a wide lens's border).

        Parameters
        ----------
        uv : array_like, shape (..., 2)
            Pixels (OpenCV convention, module docstring).

        Returns
        -------
        ndarray, shape (..., 3)
            Unit vectors, z > 0.
        """
        import cv2

        uv = np.asarray(uv, dtype=float)
        if uv.shape[-1:] != (2,) or not np.all(np.isfinite(uv)):
            raise CameraError(
                f"camera {self.name!r}: pixels must be finite (..., 2), got shape {uv.shape}"
            )
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
        xy = cv2.undistortPointsIter(
            uv.reshape(-1, 1, 2), self.matrix, self.distortion, None, None, criteria
        ).reshape(*uv.shape[:-1], 2)
        rays = np.concatenate([xy, np.ones((*uv.shape[:-1], 1))], axis=-1)
        return rays / np.linalg.norm(rays, axis=-1, keepdims=True)

    def in_view(
        self, camera_ps: ArrayLike, *, margin_px: float = 0.0, max_angle_deg: float = 60.0
    ) -> NDArray[np.bool_]:
        """Whether points are seen: in front of the camera, within ``max_angle_deg`` of the
        optical axis (where the distortion polynomial is trusted), and projecting inside
        the image at least ``margin_px`` from its border.

        Parameters
        ----------
        camera_ps : array_like, shape (..., 3)
            Points in the camera frame, metres.

        Returns
        -------
        ndarray of bool, shape (...)
        """
        p = np.asarray(camera_ps, dtype=float)
        uv = self.project(p)
        norm = np.linalg.norm(p, axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ahead = p[..., 2] > norm * math.cos(math.radians(max_angle_deg))
        lo, hi_u, hi_v = (
            margin_px - 0.5,
            self.width - 0.5 - margin_px,
            self.height - 0.5 - margin_px,
        )
        with np.errstate(invalid="ignore"):
            inside = (
                (uv[..., 0] >= lo)
                & (uv[..., 0] <= hi_u)
                & (uv[..., 1] >= lo)
                & (uv[..., 1] <= hi_v)
            )
        return ahead & inside

    def to_dict(self) -> dict[str, Any]:
        """The plain JSON form (module docstring), exact floats."""
        return {
            "name": self.name,
            "width": int(self.width),
            "height": int(self.height),
            **{f: float(getattr(self, f)) for f in PARAMETER_NAMES},
        }


def intrinsics_from_dict(doc: Mapping[str, Any], source: str = "<memory>") -> CameraIntrinsics:
    """A :class:`CameraIntrinsics` from the plain JSON form (module docstring).

    Raises
    ------
    CameraError
        Naming ``source`` and the key: a missing or non-numeric entry, an unknown key.
    """
    if not isinstance(doc, Mapping):
        raise CameraError(f"{source}: expected a JSON object with the camera's intrinsics")
    known = {"name", "width", "height", *PARAMETER_NAMES}
    unknown = sorted(set(doc) - known)
    if unknown:
        raise CameraError(
            f"{source}: unknown key(s) {unknown}; expected width, height, fx, fy, cx, cy and "
            f"optionally k1, k2, p1, p2, k3, name"
        )
    values: dict[str, Any] = {}
    for key in ("width", "height", "fx", "fy", "cx", "cy"):
        if key not in doc:
            raise CameraError(f"{source}: missing {key!r} (the camera's {_MEANING[key]})")
    for key in ("width", "height"):
        value = doc[key]
        if isinstance(value, bool) or not isinstance(value, int | float) or value != int(value):
            raise CameraError(
                f"{source}: {key!r} must be an integer number of pixels, got {value!r}"
            )
        values[key] = int(value)
    for key in PARAMETER_NAMES:
        value = doc.get(key, 0.0)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CameraError(f"{source}: {key!r} must be a number, got {value!r}")
        values[key] = float(value)
    name = doc.get("name", Path(source).stem if source != "<memory>" else "camera")
    try:
        return CameraIntrinsics(**values, name=str(name))
    except CameraError as exc:
        raise CameraError(f"{source}: {exc}") from None


_MEANING = {
    "width": "image width in pixels",
    "height": "image height in pixels",
    "fx": "focal length along u, pixels",
    "fy": "focal length along v, pixels",
    "cx": "principal point u, pixels",
    "cy": "principal point v, pixels",
}


def read_camera(path: str | Path) -> CameraIntrinsics:
    """Read a camera's intrinsics from a ROS ``camera_info`` YAML, an OpenCV
    ``FileStorage`` YAML/XML or the plain JSON form (module docstring).

    Raises
    ------
    CameraError
        Naming the file and what is missing or wrong (e.g. a distortion model other than
        plumb_bob, or a fisheye/rational model with more than 5 coefficients).
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise CameraError(f"{path}: cannot read the camera file ({exc.strerror})") from None
    if path.suffix.lower() == ".json" or text.lstrip().startswith("{"):
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise CameraError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
        return intrinsics_from_dict(doc, str(path))
    return _read_filestorage(path, text)


def _read_filestorage(path: Path, text: str) -> CameraIntrinsics:
    """ROS camera_info or OpenCV FileStorage YAML/XML, through ``cv2.FileStorage``."""
    import cv2

    stripped = text.lstrip()
    if not stripped.startswith(("%YAML", "<?xml", "<opencv_storage")):
        text = "%YAML:1.0\n" + text  # ROS writes plain YAML; FileStorage wants the header
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError):  # a parse error surfaces as either
        fs = None
    if fs is None or not fs.isOpened():
        raise CameraError(
            f"{path}: not a camera file OpenCV can read (expected a ROS camera_info YAML, an "
            f"OpenCV FileStorage YAML/XML or the plain JSON form)"
        )
    K = _matrix(fs, path, "camera_matrix", 9)
    D = _matrix(fs, path, "distortion_coefficients", None)
    model = fs.getNode("distortion_model")
    if not model.empty() and model.string() not in ("plumb_bob", "radtan", ""):
        raise CameraError(
            f"{path}: distortion_model {model.string()!r} is not supported; expected "
            f"'plumb_bob' (OpenCV's k1, k2, p1, p2, k3)"
        )
    if len(D) > 5 and np.any(D[5:] != 0.0):
        raise CameraError(
            f"{path}: distortion_coefficients has {len(D)} entries with nonzero terms beyond "
            f"k3 (OpenCV's rational model); only k1, k2, p1, p2, k3 are supported"
        )
    D = np.concatenate([D, np.zeros(5)])[:5]
    size = {}
    for key in ("image_width", "image_height"):
        node = fs.getNode(key)
        if node.empty():
            raise CameraError(f"{path}: missing {key!r} (pixels)")
        size[key] = node.real()
    name_node = fs.getNode("camera_name")
    name = name_node.string() if not name_node.empty() and name_node.string() else path.stem
    if K[1] != 0.0 or K[3] != 0.0 or K[6:].tolist() != [0.0, 0.0, 1.0]:
        raise CameraError(
            f"{path}: camera_matrix must be [fx, 0, cx, 0, fy, cy, 0, 0, 1] (no skew), got "
            f"{K.tolist()}"
        )
    doc = {
        "width": size["image_width"],
        "height": size["image_height"],
        "fx": float(K[0]),
        "fy": float(K[4]),
        "cx": float(K[2]),
        "cy": float(K[5]),
        **dict(zip(_DISTORTION, D.tolist(), strict=True)),
        "name": name,
    }
    return intrinsics_from_dict(doc, str(path))


def _matrix(fs: Any, path: Path, key: str, size: int | None) -> NDArray[np.float64]:
    """The numbers of a ROS ``{rows, cols, data}`` or OpenCV ``!!opencv-matrix`` node."""
    node = fs.getNode(key)
    if node.empty():
        raise CameraError(f"{path}: missing {key!r}")
    data = node.getNode("data") if node.isMap() else node
    if node.isMap() and node.getNode("dt").empty() and data.isSeq():  # ROS: rows, cols, data
        values = np.array([data.at(i).real() for i in range(data.size())], dtype=float)
    elif node.isMap() and not node.getNode("dt").empty():  # OpenCV's !!opencv-matrix
        values = np.asarray(node.mat(), dtype=float).ravel()
    elif node.isSeq():
        values = np.array([node.at(i).real() for i in range(node.size())], dtype=float)
    else:
        raise CameraError(f"{path}: {key!r} is not a matrix (rows, cols, data)")
    if size is not None and values.size != size:
        raise CameraError(f"{path}: {key!r} must have {size} numbers, got {values.size}")
    if not np.isfinite(values).all():
        raise CameraError(f"{path}: {key!r} has non-finite numbers")
    return values
