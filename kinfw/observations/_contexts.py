"""The views of the model that an observation kind's methods receive.

:class:`StartContext` is the numeric start model for the kinds' start-value estimators
(:meth:`kinfw.observations.ObservationKind.unknowns`); :class:`SymbolicContext` the
CasADi model for their residuals (:meth:`~kinfw.observations.ObservationKind.residual`),
with :func:`inverse_casadi`. The numpy view for prediction and drawing is
:class:`kinfw.observations.NumericContext`.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import inverse_transform
from kinfw.model import BlockKey


class StartContext:
    """Numeric view of the start model for start-value estimators.

    Parameters
    ----------
    w_T_frames : ndarray, shape (n, F, 4, 4)
        Every frame's pose in the model frame ``w`` at every sample.
    frames : sequence of str
        Frame names (axis 1).
    meas_T_w : dict of str to ndarray (4, 4)
        Start pose of the model frame in each external measurement frame (a
        ``measured_in`` that is one of ``frames`` is a robot frame: no entry).
    model_frame : str or None
        The external frame the model is expressed in (None: the URDF root).
    """

    def __init__(
        self,
        w_T_frames: NDArray[np.float64],
        frames: Sequence[str],
        meas_T_w: dict[str, NDArray[np.float64]],
        model_frame: str | None,
    ) -> None:
        self._w_T = w_T_frames
        self._index = {f: k for k, f in enumerate(frames)}
        self._meas_T_w = meas_T_w
        self.model_frame = model_frame

    def with_frames(self, meas_T_w: dict[str, NDArray[np.float64]]) -> StartContext:
        """The same poses with other external frames' start poses (nothing recomputed)."""
        out = copy.copy(self)
        out._meas_T_w = meas_T_w
        return out

    def w_T(self, frame: str, sample: NDArray[np.int64]) -> NDArray[np.float64]:
        """Pose of ``frame`` in the model frame at the samples, shape (m, 4, 4)."""
        return self._w_T[sample, self._index[frame]]

    def is_robot_frame(self, name: str | None) -> bool:
        """Whether ``name`` is a frame of the model (a measurement frame that moves with
        the robot, e.g. a head camera), not the model frame nor an external frame."""
        return name is not None and name in self._index

    def meas_T(
        self, measured_in: str | None, frame: str, sample: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """Pose (m, 4, 4) of ``frame`` in the measurement frame ``measured_in`` (None:
        the root): ``meas_T_w @ w_T_frame`` for an external frame, ``inv(w_T_c) @
        w_T_frame`` for a frame ``c`` of the robot (both from the model's FK)."""
        T = self.w_T(frame, sample)
        if measured_in is None or measured_in == self.model_frame:
            return T
        if self.is_robot_frame(measured_in):
            return inverse_transform(self.w_T(measured_in, sample)) @ T
        return self._meas_T_w[measured_in] @ T


class SymbolicContext:
    """CasADi view of the model for residuals: frames at the symbolic ``q``, block values.

    Attributes
    ----------
    ca : module
        ``casadi``.
    """

    def __init__(
        self, ca: Any, frames: dict[str, Any], values: dict[BlockKey, Any], model_frame: str | None
    ) -> None:
        self.ca = ca
        self._frames = frames
        self._values = values
        self.model_frame = model_frame

    def w_T(self, frame: str) -> Any:
        """SX 4x4 pose of a URDF frame in the model frame."""
        return self._frames[frame]

    def value(self, key: BlockKey) -> Any:
        """SX value of an unknown block (4x4 for a rigid frame, 3x1 for a point)."""
        return self._values[key]

    def is_robot_frame(self, name: str | None) -> bool:
        """Whether ``name`` is a frame of the model (a measurement frame that moves with
        the robot), not the model frame nor an external frame."""
        return name is not None and name in self._frames

    def meas_T(self, measured_in: str | None, frame: str) -> Any:
        """SX 4x4 pose of ``frame`` in the measurement frame ``measured_in``:
        ``meas_T_w @ w_T_frame`` for an external frame (its block), ``inv(w_T_c) @
        w_T_frame`` for a frame ``c`` of the robot (the calibration acts on both
        branches)."""
        T = self.w_T(frame)
        if measured_in is None or measured_in == self.model_frame:
            return T
        if self.is_robot_frame(measured_in):
            return inverse_casadi(self.ca, self.w_T(measured_in)) @ T
        return self.value(BlockKey("frame", measured_in)) @ T


def inverse_casadi(ca: Any, T: Any) -> Any:
    """Inverse of a CasADi 4x4 rigid transform."""
    R = T[0:3, 0:3]
    return ca.vertcat(ca.horzcat(R.T, -R.T @ T[0:3, 3]), ca.horzcat(0, 0, 0, 1))
