"""What a robot carries and what pulls on it: per-sample payloads and gravity.

A joint's deflection under load (:class:`kinfw.model.JointComplianceBlock`) is driven by the
generalised gravity torque of the URDF's link inertias plus the sample's payload. This
module holds the payloads of a dataset, vectorised over samples (:class:`Payloads`), and
evaluates that torque and its derivative with Pinocchio (:func:`gravity_torques`).

The measurement file's keys (``kinfw.measurements``): per sample ``"payload": {"frame":
LINK, "mass_kg": m, "com": [x, y, z], "inertia": [ixx, ixy, ixz, iyy, iyz, izz]}`` (com in
the file's length unit, in the frame; inertia in kg m^2 about the com, frame axes,
optional) and at the top level ``"gravity": [gx, gy, gz]`` (m/s^2, root frame).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

#: Gravity in the root frame when a dataset does not say (m/s^2): 9.81 along the root's -z.
STANDARD_GRAVITY = (0.0, 0.0, -9.81)


def _readonly(a: ArrayLike, dtype: type, shape: tuple[int, ...], what: str) -> NDArray:
    out = np.array(a, dtype=dtype)
    if out.shape != shape:
        raise ValueError(f"Payloads.{what}: expected shape {shape}, got {out.shape}")
    out.flags.writeable = False
    return out


@dataclass(frozen=True, slots=True)
class Payloads:
    """The payload of every sample of a dataset (none, one, or several kinds of load).

    Attributes
    ----------
    frames : tuple of str
        The frames (URDF links or frames) payloads are attached to, first-seen order.
    frame_index : ndarray of int, shape (n,)
        Per sample its payload's frame in ``frames``; -1 for a sample without a payload.
    mass_kg : ndarray, shape (n,)
        Payload mass (kg); 0 without a payload.
    com_m : ndarray, shape (n, 3)
        Payload centre of mass in its frame (m).
    inertia_kg_m2 : ndarray, shape (n, 3, 3)
        Rotational inertia about the centre of mass, in the frame's axes (kg m^2); zero
        for a point mass.
    """

    frames: tuple[str, ...]
    frame_index: NDArray[np.intp]
    mass_kg: NDArray[np.float64]
    com_m: NDArray[np.float64] = field(default=None)  # type: ignore[assignment]
    inertia_kg_m2: NDArray[np.float64] = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        n = len(np.atleast_1d(self.frame_index))
        com = np.zeros((n, 3)) if self.com_m is None else self.com_m
        inertia = np.zeros((n, 3, 3)) if self.inertia_kg_m2 is None else self.inertia_kg_m2
        object.__setattr__(self, "frames", tuple(self.frames))
        object.__setattr__(
            self, "frame_index", _readonly(self.frame_index, np.intp, (n,), "frame_index")
        )
        object.__setattr__(self, "mass_kg", _readonly(self.mass_kg, float, (n,), "mass_kg"))
        object.__setattr__(self, "com_m", _readonly(com, float, (n, 3), "com_m"))
        object.__setattr__(
            self, "inertia_kg_m2", _readonly(inertia, float, (n, 3, 3), "inertia_kg_m2")
        )
        if np.any(self.frame_index < -1) or np.any(self.frame_index >= len(self.frames)):
            raise ValueError("Payloads.frame_index: expected -1 or an index into frames")
        if np.any(self.mass_kg < 0) or not np.all(np.isfinite(self.mass_kg)):
            raise ValueError("Payloads.mass_kg: expected finite masses >= 0")
        if np.any(self.mass_kg[self.frame_index < 0] != 0):
            raise ValueError("Payloads.mass_kg: a sample without a frame has no mass")

    @classmethod
    def none(cls, n: int) -> Payloads:
        """``n`` samples without a payload."""
        return cls((), np.full(n, -1), np.zeros(n))

    @classmethod
    def constant(
        cls,
        n: int,
        frame: str,
        mass_kg: float,
        com_m: ArrayLike = (0.0, 0.0, 0.0),
        inertia_kg_m2: ArrayLike | None = None,
    ) -> Payloads:
        """The same payload on every one of ``n`` samples."""
        inertia = np.zeros((3, 3)) if inertia_kg_m2 is None else np.asarray(inertia_kg_m2)
        return cls(
            (frame,),
            np.zeros(n, np.intp),
            np.full(n, float(mass_kg)),
            np.tile(np.asarray(com_m, dtype=float), (n, 1)),
            np.tile(inertia, (n, 1, 1)),
        )

    def __len__(self) -> int:
        return len(self.frame_index)

    @property
    def any(self) -> bool:
        """Whether some sample carries a mass."""
        return bool(np.any(self.mass_kg > 0))

    def subset(self, samples: ArrayLike) -> Payloads:
        """The payloads of ``samples`` (indices or a boolean mask), in that order."""
        idx = np.arange(len(self))[np.asarray(samples)]
        return Payloads(
            self.frames,
            self.frame_index[idx],
            self.mass_kg[idx],
            self.com_m[idx],
            self.inertia_kg_m2[idx],
        )

    def concatenate(self, other: Payloads) -> Payloads:
        """These samples' payloads followed by ``other``'s."""
        frames = tuple(dict.fromkeys((*self.frames, *other.frames)))
        remap = np.array([frames.index(f) for f in other.frames] + [-1], dtype=np.intp)
        return Payloads(
            frames,
            np.concatenate([self.frame_index, remap[other.frame_index]]),
            np.concatenate([self.mass_kg, other.mass_kg]),
            np.concatenate([self.com_m, other.com_m]),
            np.concatenate([self.inertia_kg_m2, other.inertia_kg_m2]),
        )

    def kinds(self) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """The distinct payloads (frame, mass, com, inertia): ``(first, of_sample)`` with
        ``first`` (k,) a sample holding each and ``of_sample`` (n,) each sample's."""
        table = np.column_stack(
            [self.frame_index, self.mass_kg, self.com_m, self.inertia_kg_m2.reshape(-1, 9)]
        )
        _, first, of_sample = np.unique(table, axis=0, return_index=True, return_inverse=True)
        return first, np.asarray(of_sample).reshape(-1)

    def equals(self, other: Payloads) -> bool:
        """Whether both hold the same payload on every sample."""
        return (
            len(self) == len(other)
            and [self.frames[i] if i >= 0 else None for i in self.frame_index]
            == [other.frames[i] if i >= 0 else None for i in other.frame_index]
            and np.array_equal(self.mass_kg, other.mass_kg)
            and np.array_equal(self.com_m, other.com_m)
            and np.array_equal(self.inertia_kg_m2, other.inertia_kg_m2)
        )


def _loaded_model(robot, payloads: Payloads, sample: int, gravity: NDArray) -> pin.Model:
    """A copy of the robot's Pinocchio model with sample ``sample``'s payload added to the
    body of its frame's joint and ``gravity`` (root frame, m/s^2) set."""
    model = pin.Model(robot.model)
    model.gravity = pin.Motion(np.asarray(gravity, dtype=float), np.zeros(3))
    f = int(payloads.frame_index[sample])
    if f >= 0 and payloads.mass_kg[sample] > 0:
        frame = model.frames[robot.frame_id(payloads.frames[f])]
        body = pin.Inertia(
            float(payloads.mass_kg[sample]),
            payloads.com_m[sample].copy(),
            payloads.inertia_kg_m2[sample].copy(),
        )
        model.inertias[frame.parentJoint] = model.inertias[frame.parentJoint] + (
            frame.placement.act(body)
        )
    return model


def gravity_torques(
    robot,
    joint_names: tuple[str, ...],
    qs: ArrayLike,
    payloads: Payloads | None = None,
    gravity: ArrayLike = STANDARD_GRAVITY,
    *,
    derivative: bool = True,
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """The torques gravity exerts on the joints, and their derivative, per sample.

    ``tau = -g(q)`` with ``g`` Pinocchio's generalised gravity
    (``computeGeneralizedGravity``: the torque a controller must apply to hold the
    robot), of the URDF's link inertias plus each sample's payload, so a joint of
    compliance ``c`` deflects by ``c * tau`` (the direction gravity pulls).

    Parameters
    ----------
    robot : Robot
    joint_names : tuple of str
        The joints (columns of ``qs`` and of the results).
    qs : array_like, shape (n, J)
        URDF joint values (rad, m); other joints at zero.
    payloads : Payloads, optional
        Per-sample payloads (default none).
    gravity : array_like, shape (3,)
        Gravity in the root frame (m/s^2).
    derivative : bool
        Whether to return ``dtau/dq`` too (``computeGeneralizedGravityDerivatives``).

    Returns
    -------
    tau : ndarray, shape (n, J)
        Nm for revolute joints, N for prismatic ones.
    dtau_dq : ndarray, shape (n, J, J), or None
        ``dtau[i, a, b] = d tau_a / d q_b`` at sample ``i`` (Nm/rad, N/m...).
    """
    qs = np.atleast_2d(np.asarray(qs, dtype=float))
    n = len(qs)
    payloads = Payloads.none(n) if payloads is None else payloads
    if len(payloads) != n:
        raise ValueError(f"payloads: expected {n} samples, got {len(payloads)}")
    configurations = robot.pin_configurations(qs, joint_names)
    cols = np.array([robot.velocity_index(j) for j in joint_names], dtype=np.intp)
    tau = np.empty((n, len(joint_names)))
    dtau = np.empty((n, len(joint_names), len(joint_names))) if derivative else None
    first, of_sample = payloads.kinds()
    for k, s in enumerate(first):
        model = _loaded_model(robot, payloads, int(s), np.asarray(gravity, dtype=float))
        data = model.createData()
        for i in np.flatnonzero(of_sample == k):  # Pinocchio has no batch call
            q = configurations[i]
            tau[i] = -pin.computeGeneralizedGravity(model, data, q)[cols]
            if dtau is not None:
                dg = pin.computeGeneralizedGravityDerivatives(model, data, q)
                dtau[i] = -dg[np.ix_(cols, cols)]
    return tau, dtau


def massless_links(robot, joint_names: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
    """The joints of ``joint_names`` whose moving body has no mass, each with its links
    (the joint's child link and the links fixed to it): their URDF ``<link>`` s lack
    ``<inertial>``, so the gravity torque on every joint above them is unknown."""
    model = robot.model
    out = {}
    for name in joint_names:
        jid = model.getJointId(name)
        if model.inertias[jid].mass > 0:
            continue
        out[name] = tuple(
            f.name for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == jid
        )
    return out


@dataclass(frozen=True, slots=True)
class BlockSamples:
    """The samples as a robot block's numeric hooks see them
    (:meth:`kinfw.model.RobotBlock.sample_inputs`, :meth:`~kinfw.model.RobotBlock.for_data`).

    Attributes
    ----------
    robot : Robot
        The URDF the problem is built on: its link inertias drive the gravity torque.
    joint_names : tuple of str
        The model's joints (columns of ``qs``).
    qs : ndarray, shape (n, J)
        The joint readings (rad, m).
    payloads : Payloads
        One per sample.
    gravity : ndarray, shape (3,)
        Root frame, m/s^2.
    """

    robot: Any
    joint_names: tuple[str, ...]
    qs: NDArray[np.float64]
    payloads: Payloads = None  # type: ignore[assignment]
    gravity: NDArray[np.float64] = field(default_factory=lambda: np.array(STANDARD_GRAVITY))

    def __post_init__(self) -> None:
        qs = np.atleast_2d(np.asarray(self.qs, dtype=float))
        if qs.shape[1] != len(self.joint_names):
            raise ValueError(
                f"BlockSamples.qs: expected {len(self.joint_names)} columns, got {qs.shape}"
            )
        object.__setattr__(self, "qs", qs)
        if self.payloads is None:
            object.__setattr__(self, "payloads", Payloads.none(len(qs)))
        elif len(self.payloads) != len(qs):
            raise ValueError(
                f"BlockSamples.payloads: expected {len(qs)} samples, got {len(self.payloads)}"
            )
        object.__setattr__(self, "gravity", np.asarray(self.gravity, dtype=float).reshape(3))

    def at(self, qs: ArrayLike) -> BlockSamples:
        """The same samples (payloads, gravity) at other joint values."""
        return replace(self, qs=np.asarray(qs, dtype=float))

    def subset(self, samples: ArrayLike) -> BlockSamples:
        """The samples ``samples`` (indices or mask)."""
        return replace(self, qs=self.qs[samples], payloads=self.payloads.subset(samples))

    def gravity_torques(
        self, joints: tuple[str, ...], derivative: bool = True
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
        """:func:`gravity_torques` of ``joints`` (rows) at these samples, the derivative
        with respect to every model joint: ``tau`` (n, K), ``dtau_dq`` (n, K, J)."""
        tau, dtau = gravity_torques(
            self.robot,
            self.joint_names,
            self.qs,
            self.payloads,
            self.gravity,
            derivative=derivative,
        )
        rows = [self.joint_names.index(j) for j in joints]
        return tau[:, rows], None if dtau is None else dtau[:, rows, :]
