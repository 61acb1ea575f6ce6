"""The numeric side of the observation kinds: prediction, simulation and drawing.

The CasADi residual of a kind (:meth:`~kinfw.observations.ObservationKind.residual`)
sees the model through a :class:`~kinfw.observations.SymbolicContext`; its numpy
prediction (:meth:`~kinfw.observations.ObservationKind.predict`), its simulation
and its drawing see the same model through a :class:`NumericContext`: the poses of the
URDF frames at every sample and the values of the unknown blocks (a target's pose, a
marker, a point offset), batched over a group's samples.

- :class:`NumericContext`: ``w_T(frame, sample)``, ``value(key)``, ``meas_T(measured_in,
  frame, sample)``, as the symbolic context but numeric; a value it does not hold raises
  :class:`MissingValue` (the view knows the targets but not the markers).
- :class:`Drawing`: what the view draws of a group, in the model frame ``w``: measured
  positions (and orientations, for a triad), predicted positions (for residual lines).
- The noise models of simulated data: :func:`random_small_rotations` (a rotation by an
  N(0, sigma) angle about a uniformly random axis, Shih et al. 1992, Fig. 10),
  :func:`perturb_transforms` and :func:`gaussian_rows`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import (
    inverse_transform,
    matrix_from_rotation_vector,
    transform_from_rotation_translation,
)
from kinfw.model import BlockKey


class MissingValue(KeyError):
    """A :class:`NumericContext` has no value for a block (e.g. a marker's unknown pose).

    Attributes
    ----------
    key : BlockKey
    """

    def __init__(self, key: BlockKey) -> None:
        super().__init__(key)
        self.key = key

    def __str__(self) -> str:
        return f"no value for {self.key}"


class NumericContext:
    """Numpy view of a model: frames' poses at every sample and the blocks' values.

    The numeric twin of :class:`~kinfw.observations.SymbolicContext`: a kind's
    :meth:`~kinfw.observations.ObservationKind.predict` reads it exactly as its
    residual reads the symbolic one, batched over a group's samples.

    Parameters
    ----------
    w_T_frames : callable
        ``w_T_frames(frame) -> ndarray (n, 4, 4)``: pose of a URDF frame in the model
        frame ``w`` at every sample, metres (called once per frame, cached).
    values : mapping of BlockKey to ndarray
        Values of the unknown blocks: (4, 4) for a rigid frame (``target``, ``marker``,
        ``frame`` = ``meas_T_w`` of a measurement frame), (3,) for a point.
    model_frame : str or None
        The external frame the model is expressed in (None: the URDF root).
    robot_frames : callable, optional
        ``robot_frames(name) -> bool``: whether a ``measured_in`` is a frame of the
        robot (moving with it, e.g. a head camera; observations in it are predicted as
        ``inv(w_T_c) @ w_T_frame``); default: none is.
    """

    def __init__(
        self,
        w_T_frames: Callable[[str], NDArray[np.float64]],
        values: Mapping[BlockKey, ArrayLike] | None = None,
        model_frame: str | None = None,
        robot_frames: Callable[[str], bool] | None = None,
    ) -> None:
        self._w_T_frames = w_T_frames
        self._cache: dict[str, NDArray[np.float64]] = {}
        self._values = {k: np.asarray(v, dtype=float) for k, v in (values or {}).items()}
        self.model_frame = model_frame
        self._robot_frames = robot_frames

    @classmethod
    def from_robot(
        cls,
        robot: Any,
        qs: ArrayLike,
        joint_names: Sequence[str] | None,
        values: Mapping[BlockKey, ArrayLike] | None = None,
    ) -> NumericContext:
        """The context of a :class:`~kinfw.model.Robot` at configurations ``qs`` (n, k)
        (columns in ``joint_names`` order; None: the robot's), in its root link."""
        qs2 = np.atleast_2d(np.asarray(qs, dtype=float))
        names = None if joint_names is None else tuple(joint_names)
        return cls(
            lambda frame: robot.frame_poses(qs2, frame, names),
            values,
            robot_frames=robot.has_frame,
        )

    def w_T(self, frame: str, sample: NDArray[np.int64]) -> NDArray[np.float64]:
        """Pose of ``frame`` in the model frame at the samples, shape (m, 4, 4)."""
        if frame not in self._cache:
            self._cache[frame] = np.asarray(self._w_T_frames(frame), dtype=float)
        return self._cache[frame][sample]

    def has(self, key: BlockKey) -> bool:
        """Whether the context holds a value for ``key``."""
        return key in self._values

    def value(self, key: BlockKey) -> NDArray[np.float64]:
        """Value of an unknown block; raises :class:`MissingValue` if it is not given."""
        try:
            return self._values[key]
        except KeyError:
            raise MissingValue(key) from None

    def is_robot_frame(self, name: str | None) -> bool:
        """Whether the measurement frame ``name`` is a frame of the robot."""
        return (
            name is not None
            and name != self.model_frame
            and self._robot_frames is not None
            and bool(self._robot_frames(name))
        )

    def meas_T_w(self, measured_in: str | None) -> NDArray[np.float64]:
        """Pose (4, 4) of the model frame in the external measurement frame
        ``measured_in`` (a robot frame moves: see :meth:`w_T_meas_at`)."""
        if measured_in is None or measured_in == self.model_frame:
            return np.eye(4)
        if self.is_robot_frame(measured_in):
            raise ValueError(
                f"meas_T_w: {measured_in!r} is a frame of the robot; its pose depends on "
                "the sample (w_T_meas_at)"
            )
        return self.value(BlockKey("frame", measured_in))

    def meas_T(
        self, measured_in: str | None, frame: str, sample: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """Pose (m, 4, 4) of ``frame`` in the measurement frame ``measured_in``:
        ``meas_T_w @ w_T_frame``, or ``inv(w_T_c) @ w_T_frame`` for a robot frame ``c``."""
        T = self.w_T(frame, sample)
        if measured_in is None or measured_in == self.model_frame:
            return T
        if self.is_robot_frame(measured_in):
            return inverse_transform(self.w_T(measured_in, sample)) @ T
        return self.value(BlockKey("frame", measured_in)) @ T

    def w_T_meas(self, measured_in: str | None) -> NDArray[np.float64]:
        """Pose (4, 4) of the external measurement frame ``measured_in`` in the model
        frame."""
        return inverse_transform(self.meas_T_w(measured_in))

    def w_T_meas_at(
        self, measured_in: str | None, sample: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """Pose (m, 4, 4) of the measurement frame in the model frame at the samples
        (constant for an external frame, the FK of a robot frame)."""
        if self.is_robot_frame(measured_in):
            return self.w_T(measured_in, sample)
        return np.broadcast_to(self.w_T_meas(measured_in), (len(sample), 4, 4))


@dataclass(frozen=True, slots=True, eq=False)
class Drawing:
    """What the view draws of a group's observations: one entry per row, frame ``w``.

    The view draws a triad at each measured pose (a ball where there is no
    orientation) under ``measured/<node>``, and a residual line from each predicted
    position towards the measured one under ``residuals/<node>``.

    Attributes
    ----------
    node : str
        Scene path below ``measured/`` and ``residuals/``, e.g. ``"poses/flange@m1"``
        (:func:`node_name`).
    w_p_measured : ndarray, shape (m, 3)
        Where each observation puts the observed thing, model frame, metres.
    w_R_measured : ndarray, shape (m, 3, 3), or None
        Its measured orientation (drawn as a triad); None for a position only (a ball).
    w_p_predicted : ndarray, shape (m, 3), or None
        Where the model puts it; None when the prediction needs a value the view does
        not have (``missing``).
    focus : bool
        Whether the camera frames these positions (a target seen far away is drawn but
        not framed).
    missing : BlockKey or None
        Why there is no prediction.
    """

    node: str
    w_p_measured: NDArray[np.float64]
    w_R_measured: NDArray[np.float64] | None = None
    w_p_predicted: NDArray[np.float64] | None = None
    focus: bool = True
    missing: BlockKey | None = None


def node_name(*path: str, marker: str | None = None) -> str:
    """A scene path: ``node_name("poses", "flange", marker="m1") == "poses/flange@m1"``,
    ``node_name("targets", "camera", "board") == "targets/camera/board"``; a ``/`` inside
    a name becomes ``_``."""
    *names, last = (str(p).replace("/", "_") for p in path)
    if marker is not None:
        last = f"{last}@{marker}".replace("/", "_")
    return "/".join([*names, last])


def predicted_or_missing(
    predict: Callable[[], NDArray[np.float64]],
) -> tuple[NDArray[np.float64] | None, BlockKey | None]:
    """``(predict(), None)``, or ``(None, key)`` when it needs a missing value."""
    try:
        return predict(), None
    except MissingValue as exc:
        return None, exc.key


# -- noise models of simulated measurements ------------------------------------------------


def random_unit_vectors(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    """``n`` unit vectors uniformly distributed on the sphere, shape (n, 3)."""
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_small_rotations(
    rng: np.random.Generator, n: int, sigma_rad: float
) -> NDArray[np.float64]:
    """``n`` rotations about uniformly random axes by angles N(0, sigma_rad), (n, 3, 3)."""
    axes = random_unit_vectors(rng, n)
    angles = rng.normal(0.0, sigma_rad, size=n)
    return matrix_from_rotation_vector(axes * angles[:, None])


def perturb_transforms(
    a_T_bs: NDArray[np.float64], rng: np.random.Generator, sigma_m: float, sigma_rad: float
) -> NDArray[np.float64]:
    """``[a_R_b dR, a_p_b + dp]`` for poses (n, 4, 4): ``dp ~ N(0, sigma_m^2 I)`` in frame
    a, ``dR`` a rotation by N(0, sigma_rad) about a uniformly random axis (in frame b).

    The draws, in order: ``dp`` (n, 3), the axes (n, 3), the angles (n,) (the stream of
    :func:`kinfw.simulation.perturb_poses`).
    """
    dp = rng.normal(0.0, sigma_m, size=(len(a_T_bs), 3))
    dR = random_small_rotations(rng, len(a_T_bs), sigma_rad)
    return transform_from_rotation_translation(a_T_bs[:, :3, :3] @ dR, a_T_bs[:, :3, 3] + dp)


def gaussian_rows(
    rows: NDArray[np.float64], rng: np.random.Generator, sigma_widths: Sequence[tuple[float, int]]
) -> NDArray[np.float64]:
    """``rows`` (m, w) plus independent N(0, sigma) noise on blocks of columns.

    ``sigma_widths`` is ``((sigma, width), ...)`` in column order, widths summing to w
    (a kind's noise components); the noise is drawn block by block, each (m, width).
    """
    out, k = np.array(rows, dtype=float), 0
    for sigma, width in sigma_widths:
        out[:, k : k + width] += rng.normal(0.0, sigma, size=(len(out), width))
        k += width
    return out


def transforms_from_pose_rows(rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """(m, 12) rows (rotation column-major, then position) -> (m, 4, 4) poses (the
    inverse of :func:`kinfw.observations._base.pose_rows`)."""
    rows = np.asarray(rows, dtype=float)
    return transform_from_rotation_translation(
        np.swapaxes(rows[:, :9].reshape(len(rows), 3, 3), 1, 2), rows[:, 9:12]
    )
