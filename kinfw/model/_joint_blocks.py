"""The shipped robot blocks of a model spec: what a URDF cannot hold about the joints.

- :class:`JointComplianceBlock` (``compliance``, ``compliance:J1,J2``): each joint deflects
  by ``c_j tau_j`` under the torque ``tau`` gravity exerts on it through the URDF's link
  inertias and the sample's payload (rad/Nm, m/N);
- :class:`GearScaleBlock` (``gear-scale:JOINT``): the joint turns ``(1 + s) q`` for a
  reading ``q``;
- :class:`JointCouplingBlock` (``coupling:JOINT=K*OTHER``): the URDF's joint value is the
  reading plus ``k`` times another joint's reading (FANUC's J3 reads the forearm's angle to
  the horizontal: ``coupling:joint_3=-1*joint_2``); ``K`` fixed, ``?`` or ``?K``
  estimated (from 0 or from ``K``).

The readings' maps (gear scale, coupling) act before the joint zero offsets, the deflection
after them, on the physical joint values (:attr:`kinfw.model.RobotBlock.stage`).
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from kinfw.model._blocks import BlockKey, ParameterName, SpecBlock
from kinfw.model._loads import BlockSamples, massless_links
from kinfw.model._urdf_read import RobotModelError

logger = logging.getLogger("kinfw.model")

#: Below this spread of gravity's torque over the data (Nm, N; largest minus smallest) a
#: joint's compliance is not estimated: gravity does not load it (a vertical axis, a
#: horizontal table) or loads it alike in every sample (a vertical slide without a
#: varying payload), and a constant deflection is a zero offset.
UNLOADED_TORQUE = 1e-6

#: Terms of the Neumann series the CasADi hook of :class:`JointComplianceBlock` sums for
#: ``(I - C G_K)^-1``.
NEUMANN_TERMS = 3


def _model_joint(spec: str, joint: str, samples: BlockSamples) -> int:
    """The column of ``joint`` among the model's joints, or a clear error."""
    if joint not in samples.joint_names:
        raise RobotModelError(
            f"model {spec}: joint {joint!r} is not a movable joint on the measured paths "
            f"(those are: {', '.join(samples.joint_names)})"
        )
    return samples.joint_names.index(joint)


def _selector(joint_names: tuple[str, ...], joint: str) -> Any:
    """The CasADi column (J,) that is 1 at ``joint`` and 0 elsewhere."""
    import casadi as ca

    e = np.zeros(len(joint_names))
    e[joint_names.index(joint)] = 1.0
    return ca.DM(e)


def _unit(revolute: bool, per: str) -> str:
    return ("rad" if revolute else "m") + per


@dataclass(frozen=True, slots=True)
class JointComplianceBlock(SpecBlock):
    """Joint compliance under gravity and payload: ``q_phys = q + c * tau(q_phys)``.

    ``tau`` is the torque gravity exerts on the joints (:func:`kinfw.model.gravity_torques`:
    minus Pinocchio's generalised gravity, of the URDF's inertias plus the sample's
    payload), evaluated at the deflected configuration. The hook solves that equation to
    second order in the joints' moves ``q_phys - q_read``: with ``tau0`` and ``G =
    dtau/dq`` at the readings (:meth:`sample_inputs`),
    ``(I - C G_K) delta = C (tau0 + G (q - q_read))`` and ``q_phys = q + delta`` (``C``
    the compliances, ``G_K`` the columns of the compliant joints), by
    :data:`NEUMANN_TERMS` terms of its Neumann series. The error left is
    ``c d2tau dq^2 / 2``: about 1e-8 rad for an industrial arm with a degree of zero
    offsets (c = 5e-6 rad/Nm, tau'' ~ 200 Nm).

    Attributes
    ----------
    joints : tuple of str
        The compliant joints; empty in the spec ``compliance`` (every model joint, bound by
        :meth:`for_data`).
    revolute : tuple of bool
        Per joint: rad/Nm (revolute) or m/N (prismatic).
    """

    joints: tuple[str, ...] = ()
    revolute: tuple[bool, ...] = ()

    block_name: ClassVar[str] = "compliance"
    stage: ClassVar[str] = "deflection"

    @classmethod
    def from_spec(cls, argument: str) -> JointComplianceBlock:
        joints = tuple(j for j in argument.split(",") if j) if argument else ()
        return cls(BlockKey("compliance", ",".join(joints)), joints=joints)

    @property
    def fields(self) -> tuple[str, ...]:
        return ("compliance",) * len(self.joints)

    @property
    def names(self) -> tuple[ParameterName, ...]:
        return tuple(ParameterName(j, "compliance") for j in self.joints)

    @property
    def units(self) -> tuple[str, ...]:
        return tuple(_unit(r, "/Nm" if r else "/N") for r in self.revolute)

    def for_data(self, context: BlockSamples) -> JointComplianceBlock:
        """Bound to the model's joints (all of them for ``compliance``), refused when a
        link lacks inertias, and fixed at its start on joints whose gravity torque does
        not vary in these data (:data:`UNLOADED_TORQUE`: their compliance is not
        determined, a constant deflection being a zero offset)."""
        names = context.joint_names
        joints = self.joints or names
        for j in joints:
            _model_joint(self.spec, j, context)
        _refuse_massless(self.spec, context)
        revolute = tuple(context.robot.joint(j).type != "prismatic" for j in joints)
        start = self.start if self.joints else np.zeros(len(joints))
        tau, _ = context.gravity_torques(joints, derivative=False)
        loaded = np.ptp(tau, axis=0) > UNLOADED_TORQUE if len(tau) else np.zeros(len(joints), bool)
        if not loaded.all():
            logger.info(
                "%s: gravity's torque on %s does not vary in these data (a constant deflection "
                "is a zero offset): its compliance is not estimated",
                self.spec,
                ", ".join(j for j, on in zip(joints, loaded, strict=True) if not on),
            )
        free = np.resize(self.free, len(joints)) if self.joints else np.ones(len(joints), bool)
        return replace(
            self,
            key=BlockKey("compliance", ",".join(joints)),
            joints=tuple(joints),
            revolute=revolute,
            start=start,
            free=free & loaded,
        )

    def sample_width(self, joint_names: tuple[str, ...]) -> int:
        J, K = len(joint_names), len(self.joints)
        return J + K + K * J

    def sample_inputs(self, context: BlockSamples) -> NDArray[np.float64]:
        """Per sample ``[q_read (J), tau0 (K), G (K x J, row-major)]`` at the readings."""
        tau, dtau = context.gravity_torques(self.joints)
        n = len(context.qs)
        return np.hstack([context.qs, tau, dtau.reshape(n, -1)])

    def _columns(self, joint_names: tuple[str, ...]) -> list[int]:
        return [joint_names.index(j) for j in self.joints]

    def casadi_joint_values(
        self, q: Any, d: Any, c: Any, joint_names: tuple[str, ...], s: Any = None
    ) -> Any:
        import casadi as ca

        J, K = len(joint_names), len(self.joints)
        cols = self._columns(joint_names)
        q_read, tau0 = s[:J], s[J : J + K]
        G = ca.reshape(s[J + K :], J, K).T  # (K, J): numpy's row-major rows
        C = self.casadi_value(d, c)
        # (I - C G_K) delta = b by its Neumann series: C G_K ~ 1e-3 for an arm, so three
        # terms leave (C G_K)^3 delta ~ 1e-12 rad; matrix-vector products only (a
        # symbolic solve made an 8-joint arm's graph 20 times slower)
        b = C * (tau0 + G @ (q - q_read))
        G_K = G[:, cols]
        delta = b
        for _ in range(NEUMANN_TERMS - 1):
            delta = b + C * (G_K @ delta)
        E = np.zeros((J, K))
        E[cols, np.arange(K)] = 1.0
        return q + ca.DM(E) @ delta

    def joint_values(
        self, q: NDArray[np.float64], context: BlockSamples, d: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """The deflected joint values, exactly: Newton's method on
        ``delta = C tau(q + delta)`` with Pinocchio's torque and derivative at each
        iterate (the CasADi hook's second-order solution is its first step from the
        readings)."""
        C = self.start if d is None else self.numpy_value(d)
        cols = self._columns(context.joint_names)
        out = np.array(q, dtype=float)
        delta = np.zeros((len(out), len(cols)))
        for _ in range(10):
            tau, G = context.at(out).gravity_torques(self.joints)
            A = np.eye(len(cols)) - C[:, None] * G[:, :, cols]
            step = np.linalg.solve(A, (C * tau - delta)[..., None])[..., 0]
            delta += step
            out[:, cols] += step
            if np.abs(step).max(initial=0.0) < 1e-15:
                break
        return out

    def readings(
        self, q: NDArray[np.float64], context: BlockSamples, tol: float = 1e-13
    ) -> NDArray[np.float64]:
        """The command that deflects to ``q``: ``q - c tau(q)`` (exact: the torque at the
        deflected configuration is known)."""
        tau, _ = context.at(q).gravity_torques(self.joints, derivative=False)
        out = np.array(q, dtype=float)
        out[:, self._columns(context.joint_names)] -= self.start * tau
        return out


def _refuse_massless(spec: str, context: BlockSamples) -> None:
    """A RobotModelError naming the links without ``<inertial>`` on the model's paths."""
    missing = massless_links(context.robot, context.joint_names)
    if missing:
        links = sorted({link for ls in missing.values() for link in ls})
        raise RobotModelError(
            f"model {spec}: {context.robot.source}: the link(s) {', '.join(links)} have no "
            f"<inertial>: the gravity torque on the joints above them "
            f"({', '.join(missing)}) is unknown; give them masses in the URDF or drop {spec}"
        )


@dataclass(frozen=True, slots=True)
class GearScaleBlock(SpecBlock):
    """A joint's gear scale: it turns ``(1 + s) q`` for a reading ``q`` (``s`` unitless).

    Attributes
    ----------
    joint : str
    """

    joint: str = ""

    block_name: ClassVar[str] = "gear-scale"

    @classmethod
    def from_spec(cls, argument: str) -> GearScaleBlock:
        if not argument or "," in argument:
            raise ValueError(f"gear-scale:{argument}: expected gear-scale:JOINT (one joint)")
        return cls(BlockKey("gear-scale", argument), joint=argument)

    @property
    def fields(self) -> tuple[str, ...]:
        return ("gear_scale",)

    @property
    def names(self) -> tuple[ParameterName, ...]:
        return (ParameterName(self.joint, "gear_scale"),)

    @property
    def units(self) -> tuple[str, ...]:
        return ("unitless",)

    def for_data(self, context: BlockSamples) -> GearScaleBlock:
        _model_joint(self.spec, self.joint, context)
        return self

    def casadi_joint_values(
        self, q: Any, d: Any, c: Any, joint_names: tuple[str, ...], s: Any = None
    ) -> Any:
        e = _selector(joint_names, self.joint)
        return q + self.casadi_value(d, c)[0] * (q * e)

    def joint_values(
        self, q: NDArray[np.float64], context: BlockSamples, d: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        s = self.start[0] if d is None else self.numpy_value(d)[0]
        out = np.array(q, dtype=float)
        out[:, context.joint_names.index(self.joint)] *= 1.0 + s
        return out

    def readings(
        self, q: NDArray[np.float64], context: BlockSamples, tol: float = 1e-13
    ) -> NDArray[np.float64]:
        out = np.array(q, dtype=float)
        out[:, context.joint_names.index(self.joint)] /= 1.0 + self.start[0]
        return out


_COUPLING = re.compile(r"^([^=*\s]+)=(\?)?([-+]?[0-9.eE+-]*)\*([^=*\s]+)$")


@dataclass(frozen=True, slots=True)
class JointCouplingBlock(SpecBlock):
    """A linear coupling of the readings: ``q_joint = r_joint + k r_other``.

    Attributes
    ----------
    joint, other : str
        The coupled joint and the joint whose reading adds to it.
    """

    joint: str = ""
    other: str = ""

    block_name: ClassVar[str] = "coupling"

    @classmethod
    def from_spec(cls, argument: str) -> JointCouplingBlock:
        m = _COUPLING.match(argument)
        form = "coupling:JOINT=K*OTHER (K a number: fixed; ?K or ?: estimated from K or 0)"
        if m is None or (not m.group(2) and not m.group(3)):
            raise ValueError(f"coupling:{argument}: expected {form}")
        joint, estimated, k, other = m.groups()
        if joint == other:
            raise ValueError(f"coupling:{argument}: a joint cannot be coupled to itself")
        try:
            k0 = float(k) if k not in ("", "+", "-") else 0.0
        except ValueError:
            raise ValueError(
                f"coupling:{argument}: {k!r} is not a number; expected {form}"
            ) from None
        return cls(
            BlockKey("coupling", f"{joint}={other}"),
            free=[bool(estimated)],
            start=[k0],
            joint=joint,
            other=other,
        )

    @property
    def argument(self) -> str:
        k = f"{self.start[0]:.17g}"
        return f"{self.joint}={'?' if self.free[0] else ''}{k}*{self.other}"

    @property
    def fields(self) -> tuple[str, ...]:
        return ("coupling",)

    @property
    def names(self) -> tuple[ParameterName, ...]:
        return (ParameterName(self.joint, f"coupling:{self.other}"),)

    @property
    def units(self) -> tuple[str, ...]:
        return ("unitless",)

    def for_data(self, context: BlockSamples) -> JointCouplingBlock:
        prismatic = set()
        for j in (self.joint, self.other):
            _model_joint(self.spec, j, context)
            prismatic.add(context.robot.joint(j).type == "prismatic")
        if len(prismatic) > 1:
            raise RobotModelError(
                f"model {self.spec}: {self.joint!r} and {self.other!r} are one revolute "
                "and one prismatic joint; a coupling adds readings of one unit"
            )
        return self

    def casadi_joint_values(
        self, q: Any, d: Any, c: Any, joint_names: tuple[str, ...], s: Any = None
    ) -> Any:
        e = _selector(joint_names, self.joint)
        return q + self.casadi_value(d, c)[0] * q[joint_names.index(self.other)] * e

    def joint_values(
        self, q: NDArray[np.float64], context: BlockSamples, d: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        k = self.start[0] if d is None else self.numpy_value(d)[0]
        names = context.joint_names
        out = np.array(q, dtype=float)
        out[:, names.index(self.joint)] += k * q[:, names.index(self.other)]
        return out

    def readings(
        self, q: NDArray[np.float64], context: BlockSamples, tol: float = 1e-13
    ) -> NDArray[np.float64]:
        names = context.joint_names
        out = np.array(q, dtype=float)
        out[:, names.index(self.joint)] -= self.start[0] * q[:, names.index(self.other)]
        return out
