"""A camera's intrinsics as an estimation block (``BlockKey("intrinsics", camera)``).

The 9 numbers of OpenCV's pinhole and distortion model, fixed (known) unless the fit
frees them, and the check that flags a freed one the images do not determine. The
``pixels`` kind (:mod:`kinfw.observations`) requests it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.camera import PARAMETER_NAMES, project_normalized
from kinfw.model import Block, BlockKey

#: A freed intrinsic parameter whose 1-sigma uncertainty moves a point of the image's
#: border by more than this many pixels is reported as not determined by the images.
UNDETERMINED_PX = 1.0


@dataclass(frozen=True, slots=True)
class IntrinsicsBlock(Block):
    """A camera's 9 intrinsic parameters ``start + d`` in OpenCV's order
    (:data:`kinfw.camera.PARAMETER_NAMES`: fx, fy, cx, cy in px, then k1, k2, p1,
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
