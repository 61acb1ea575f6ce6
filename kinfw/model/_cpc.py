"""The CPC kinematic model over a tree of revolute and prismatic joints.

Zhuang & Roth's *complete and parametrically continuous* model as used by Shih et al.
(1992, section 2). Every joint ``j`` has a frame ``F_j`` whose z axis is the joint axis.
The link transform into joint ``j`` from the moved frame ``F_p'`` of its parent joint
``p`` (or from the measurement frame ``w`` for a joint at the root) is, eq. (3),

.. math::  {}^{p'}T_{j} = R(b_j)\\,Rot(\\hat z, \\beta_j)\\,Trans(l_j),

with :math:`R(b)` the rotation of eq. (4) that takes z onto the unit vector ``b``, and
the joint motion is, eq. (6), ``F_j' = F_j M_j(q_j)`` with
``M_j = Rot(z, s_j q_j)`` (revolute) or ``Trans(0, 0, s_j q_j)`` (prismatic).
Each end frame ``e`` (a plate, a camera, a tool flange) hangs off the moved frame of its
last joint by a constant 6-DoF tool transform ``F_p'_T_e``.

Indexing. kinfw indexes a link transform by the joint it leads *to*, so that a tree
(where a joint may have several children but only one parent) has one ``(b, beta, l)``
per joint: kinfw's ``(b_j, beta_j, l_j)`` are the paper's ``(b_{j-1}, beta_{j-1},
l_{j-1})``, and the paper's world-to-base ``(b_0, beta_0, l_0)`` belongs to the first
joint of the chain.

Gauge (Table 1). The canonical model fixes every redundant parameter: ``beta_j = 0``
for every joint, ``l_j = (l_x, l_y, 0)`` into a revolute joint (the frame origin is
where the axis meets the plane through the parent's origin normal to the axis), and
``l_j = 0`` into a prismatic joint (its origin is not observable). All rotation about
joint axes and all offsets along them are absorbed downstream, in the end frames'
tool transforms. That leaves 4 parameters per revolute joint, 2 per prismatic joint
and 6 per end frame (32 for the IIS-head's two plates), the identifiable count.

Axis sense. ``b`` has no sign in the paper's eigenvector step. kinfw stores the motion
sense separately: ``s_j = +1`` when the frame's z is the URDF axis (positive q turns
right-handed about it), ``-1`` when it is flipped so that ``b_z >= 0`` (DESIGN.md:
an anti-parallel or ``0 0 -1`` axis keeps its joint reading's sign).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import (
    inverse_transform,
    rigid_from_chart,
    rot_z,
    rotation_chart,
    transform_from_rotation_translation,
)
from kinfw.model._robot import Robot, Topology


def rotation_from_axis(b: ArrayLike) -> NDArray[np.float64]:
    """:math:`R(b)` of Shih et al. eq. (4): the minimal rotation taking z onto ``b``.

    Parameters
    ----------
    b : array_like, shape (..., 3)
        Unit vectors with ``b_z > -1``.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Rotation whose third column is ``b``.
    """
    b = np.asarray(b, dtype=float)
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    if np.any(bz <= -1.0 + 1e-12):
        raise ValueError("rotation_from_axis: b_z = -1 is singular; flip the axis sense")
    c = 1.0 / (1.0 + bz)
    return np.stack(
        [
            np.stack([1 - bx * bx * c, -bx * by * c, bx], -1),
            np.stack([-bx * by * c, 1 - by * by * c, by], -1),
            np.stack([-bx, -by, bz], -1),
        ],
        axis=-2,
    )


def cayley_coordinates(dR: ArrayLike) -> NDArray[np.float64]:
    """Cayley chart coordinates ``d`` (3,) of a rotation ``dR`` (3, 3): ``dR = cayley(d / 2)``.

    The inverse of the chart :meth:`CPCModel.perturbed` uses for tool orientations (the
    one rigid-frame chart of :mod:`kinfw.geometry`): ``d = 2 vee(dR - dR^T) / (1 + tr dR)``,
    twice the Gibbs vector ``tan(theta / 2) u``, equal to the rotation vector ``theta u``
    to first order; undefined at ``theta = pi``.
    """
    return rotation_chart(dR)


def perpendicular_basis(b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Two unit vectors (2, 3) orthogonal to unit ``b`` (3,) and to each other."""
    helper = np.eye(3)[np.argmin(np.abs(b))]
    e1 = np.cross(b, helper)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(b, e1)])


@dataclass(frozen=True, slots=True)
class ZeroGeometry:
    """Screw-axis description of a tree at ``q = 0``, in the measurement frame ``w``.

    The product-of-exponentials form: ``w_T_e(q) = prod_j exp(S_j q_j) w_T_e(0)`` over
    the joints on ``e``'s chain. It is the exchange format between a URDF, the CPC model
    and the URDF exporter.

    Attributes
    ----------
    topology : Topology
    axes : ndarray, shape (J, 3)
        Unit direction of each joint in ``w``: positive q turns right-handed about it
        (revolute) or moves along it (prismatic).
    points : ndarray, shape (J, 3)
        A point on each revolute axis in ``w``, metres (any point for prismatic joints).
    w_T_frames : ndarray, shape (E, 4, 4)
        Pose of each end frame in ``w`` at ``q = 0``.
    """

    topology: Topology
    axes: NDArray[np.float64]
    points: NDArray[np.float64]
    w_T_frames: NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class CPCModel:
    """CPC parameters of a tree (see the module docstring for the equations).

    Attributes
    ----------
    topology : Topology
        Joints (parents first) and end frames.
    b : ndarray, shape (J, 3)
        Unit z axis of ``F_j`` in the parent's moved frame ``F_p'`` (``w`` at the root).
    beta : ndarray, shape (J,)
        Rotation about that axis, rad (0 in the canonical gauge).
    l : ndarray, shape (J, 3)
        Translation in ``F_j`` after the rotations, metres (``l_z = 0`` into revolute
        joints and ``l = 0`` into prismatic ones in the canonical gauge).
    sign : ndarray, shape (J,)
        Motion sense ``s_j`` in {+1, -1} (module docstring).
    tool_T : ndarray, shape (E, 4, 4)
        Pose of each end frame in the moved frame of its last joint (``w`` if none).
    """

    topology: Topology
    b: NDArray[np.float64]
    beta: NDArray[np.float64]
    l: NDArray[np.float64]
    sign: NDArray[np.float64]
    tool_T: NDArray[np.float64]

    # -- sizes and names -----------------------------------------------------------------
    @property
    def n_joints(self) -> int:
        return len(self.topology.joint_names)

    @property
    def parameter_names(self) -> tuple[tuple[str, str], ...]:
        """Names ``(owner, field)`` of the identifiable parameters, in chart order.

        Per joint: ``("pan", "b_tilt_1"), ("pan", "b_tilt_2")`` (axis tilts, rad) and,
        for a revolute joint, ``("pan", "l_x"), ("pan", "l_y")`` (m). Per end frame:
        ``("left_plate", "rot_x"|"rot_y"|"rot_z")`` (rad) and ``"x"|"y"|"z"`` (m, in
        the moved frame of its last joint).
        """
        names: list[tuple[str, str]] = []
        for name, rev in zip(self.topology.joint_names, self.topology.revolute, strict=True):
            names += [(name, "b_tilt_1"), (name, "b_tilt_2")]
            if rev:
                names += [(name, "l_x"), (name, "l_y")]
        for frame in self.topology.frames:
            names += [(frame, f) for f in ("rot_x", "rot_y", "rot_z", "x", "y", "z")]
        return tuple(names)

    @property
    def n_parameters(self) -> int:
        """Number of identifiable parameters: 4 per revolute, 2 per prismatic, 6 per frame."""
        return len(self.parameter_names)

    # -- the chart of identifiable parameters --------------------------------------------
    def axis_bases(self) -> NDArray[np.float64]:
        """Per joint, two unit vectors orthogonal to ``b`` (J, 2, 3): the axis-tilt chart."""
        return np.array([perpendicular_basis(b) for b in self.b]).reshape(-1, 2, 3)

    def perturbed(self, delta: ArrayLike) -> CPCModel:
        """The model moved by ``delta`` in the chart of :attr:`parameter_names`.

        Axes: ``b = normalise(b0 + d1 e1 + d2 e2)`` with ``(e1, e2)`` from
        :meth:`axis_bases`; revolute offsets ``l_x, l_y`` add; tool rotations multiply on
        the right by the Cayley rotation of ``rot / 2`` and tool positions add. At
        ``delta = 0`` the chart's derivative is the identity in (rad, m), and it is smooth
        everywhere near the model, including ``b_z = 0`` where ``(b_x, b_y)`` is not.
        The same chart is built in CasADi by :func:`kinfw.model.cpc_fk_function`.
        """
        delta = np.asarray(delta, dtype=float)
        if delta.shape != (self.n_parameters,):
            raise ValueError(f"delta: expected shape ({self.n_parameters},), got {delta.shape}")
        b, l, tool_T = self.b.copy(), self.l.copy(), self.tool_T.copy()
        bases = self.axis_bases()
        k = 0
        for j, rev in enumerate(self.topology.revolute):
            v = b[j] + delta[k] * bases[j, 0] + delta[k + 1] * bases[j, 1]
            b[j] = v / np.linalg.norm(v)
            k += 2
            if rev:
                l[j, :2] += delta[k : k + 2]
                k += 2
        for e in range(len(self.topology.frames)):
            tool_T[e] = rigid_from_chart(tool_T[e], delta[k : k + 6])
            k += 6
        return replace(self, b=b, l=l, tool_T=tool_T)

    def chart_coordinates(self, other: CPCModel) -> NDArray[np.float64]:
        """The chart coordinates ``delta`` with ``self.perturbed(delta) == other``.

        ``other`` must be canonical with the same topology and motion senses (e.g.
        ``cpc_from_geometry(geometry, sign=self.sign)``); the inverse of :meth:`perturbed`:
        axes ``d_i = e_i . b / (b0 . b)``, offsets by difference, tool rotations
        ``2 vee(dR - dR^T) / (1 + tr dR)`` (the inverse Cayley map,
        :func:`cayley_coordinates`), positions by difference.
        """
        if other.topology != self.topology or np.any(other.sign != self.sign):
            raise ValueError("chart_coordinates: models differ in topology or motion senses")
        bases = self.axis_bases()
        out = []
        for j, rev in enumerate(self.topology.revolute):
            out += list(bases[j] @ other.b[j] / (self.b[j] @ other.b[j]))
            if rev:
                out += list(other.l[j, :2] - self.l[j, :2])
        for e in range(len(self.topology.frames)):
            out += list(cayley_coordinates(self.tool_T[e, :3, :3].T @ other.tool_T[e, :3, :3]))
            out += list(other.tool_T[e, :3, 3] - self.tool_T[e, :3, 3])
        return np.array(out)

    # -- forward kinematics ----------------------------------------------------------------
    def link_transforms(self) -> NDArray[np.float64]:
        """Constant ``F_p'_T_F_j = R(b_j) Rot(z, beta_j) Trans(l_j)``, shape (J, 4, 4)."""
        R = rotation_from_axis(self.b) @ rot_z(self.beta)
        return transform_from_rotation_translation(R, np.einsum("jab,jb->ja", R, self.l))

    def joint_frames(self, qs: ArrayLike) -> NDArray[np.float64]:
        """Moved joint frames ``w_T_F_j'`` for configurations ``qs`` (n, J) -> (n, J, 4, 4).

        ``qs`` columns follow ``topology.joint_names`` (URDF units: rad, m).
        """
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        if qs.shape[1] != self.n_joints:
            raise ValueError(
                f"qs: expected {self.n_joints} columns "
                f"{list(self.topology.joint_names)}, got shape {qs.shape}"
            )
        n = qs.shape[0]
        links = self.link_transforms()
        sq = qs * self.sign
        out = np.empty((n, self.n_joints, 4, 4))
        for j, (rev, p) in enumerate(
            zip(self.topology.revolute, self.topology.parent, strict=True)
        ):
            w_T_Fj = links[j] if p < 0 else out[:, p] @ links[j]
            motion = np.tile(np.eye(4), (n, 1, 1))
            if rev:
                motion[:, :3, :3] = rot_z(sq[:, j])
            else:
                motion[:, 2, 3] = sq[:, j]
            out[:, j] = w_T_Fj @ motion
        return out

    def frame_poses(self, qs: ArrayLike, frame: str | None = None) -> NDArray[np.float64]:
        """Pose of the end frames in ``w``, vectorised over configurations.

        Batch in, batch out: one configuration of shape (J,) gives one pose, a batch of
        shape (n, J) gives n poses, with the batch axis kept for n = 1.

        Parameters
        ----------
        qs : array_like, shape (J,) or (n, J)
            Joint values in ``topology.joint_names`` order (rad, m): one configuration,
            or a batch of n.
        frame : str, optional
            One end frame; default all of them, in ``topology.frames`` order.

        Returns
        -------
        ndarray
            ``w_T_frame``, metres. For a batch ``qs`` (n, J): shape (n, 4, 4) for one
            ``frame``, (n, E, 4, 4) for all E end frames. For one configuration (J,):
            the same without the leading axis, (4, 4) or (E, 4, 4).

        Raises
        ------
        ValueError
            ``qs`` neither (J,) nor (n, J).
        KeyError
            ``frame`` is not an end frame of the model.
        """
        qs = np.asarray(qs, dtype=float)
        if qs.ndim not in (1, 2):
            raise ValueError(
                f"qs: expected shape ({self.n_joints},) or (n, {self.n_joints}) "
                f"(columns {list(self.topology.joint_names)}), got {qs.shape}"
            )
        frames = self.joint_frames(qs)  # (n, J, 4, 4); n = 1 for one configuration
        idx = range(len(self.topology.frames)) if frame is None else [self._frame_index(frame)]
        out = np.stack(
            [
                np.broadcast_to(self.tool_T[e], (len(frames), 4, 4))
                if self.topology.frame_parent[e] < 0
                else frames[:, self.topology.frame_parent[e]] @ self.tool_T[e]
                for e in idx
            ],
            axis=1,
        )
        if frame is not None:
            out = out[:, 0]
        return out[0] if qs.ndim == 1 else out

    def _frame_index(self, frame: str) -> int:
        try:
            return self.topology.frames.index(frame)
        except ValueError:
            raise KeyError(
                f"no end frame {frame!r}; the model has {self.topology.frames}"
            ) from None

    # -- reporting ---------------------------------------------------------------------
    def describe(self) -> list[tuple[str, str, float, str]]:
        """Paper-style parameter table: ``(owner, name, value, unit)`` with lengths in
        ``"m"``, angles in ``"rad"`` and the axis and sense ``"unitless"``: ``b_x, b_y,
        b_z, beta, l_x, l_y, l_z, sign`` per joint and ``x, y, z, roll, pitch, yaw`` per
        end frame (``F_p'_T_e``, URDF rpy)."""
        rows: list[tuple[str, str, float, str]] = []
        for j, name in enumerate(self.topology.joint_names):
            for k, f in enumerate(("b_x", "b_y", "b_z")):
                rows.append((name, f, float(self.b[j, k]), "unitless"))
            rows.append((name, "beta", float(self.beta[j]), "rad"))
            for k, f in enumerate(("l_x", "l_y", "l_z")):
                rows.append((name, f, float(self.l[j, k]), "m"))
            rows.append((name, "sign", float(self.sign[j]), "unitless"))
        for e, frame in enumerate(self.topology.frames):
            rpy = pin.rpy.matrixToRpy(self.tool_T[e, :3, :3])
            for k, f in enumerate(("x", "y", "z")):
                rows.append((frame, f, float(self.tool_T[e, k, 3]), "m"))
            for k, f in enumerate(("roll", "pitch", "yaw")):
                rows.append((frame, f, float(rpy[k]), "rad"))
        return rows


def geometry_from_cpc(model: CPCModel) -> ZeroGeometry:
    """Screw axes and end-frame poses at ``q = 0`` of a CPC model (any gauge)."""
    zero = np.zeros(model.n_joints)
    frames = model.joint_frames(zero)[0]  # F_j' = F_j at q = 0
    return ZeroGeometry(
        topology=model.topology,
        axes=frames[:, :3, 2] * model.sign[:, None],
        points=frames[:, :3, 3].copy(),
        w_T_frames=model.frame_poses(zero),
    )


def cpc_from_geometry(geometry: ZeroGeometry, sign: ArrayLike | None = None) -> CPCModel:
    """The canonical CPC model (module docstring) of screw axes at ``q = 0``.

    Parameters
    ----------
    geometry : ZeroGeometry
    sign : array_like of +-1, shape (J,), optional
        Motion senses to use (e.g. the nominal model's, so that a calibrated model keeps
        them). By default ``b_z >= 0`` decides: ``s_j = -1`` exactly when the joint axis
        points away from its parent's z axis.

    Notes
    -----
    Top-down over the tree: ``F_j`` has z = ``s_j`` times the axis, orientation
    ``R_{F_p'} R(b_j)`` (``beta_j = 0``) and, for a revolute joint, origin at the point
    of the axis in the plane through ``F_p'``'s origin normal to the axis (so
    ``l_z = 0``); a prismatic joint's frame keeps its parent's origin (``l = 0``).
    """
    topo = geometry.topology
    J = len(topo.joint_names)
    b = np.zeros((J, 3))
    l = np.zeros((J, 3))
    signs = np.ones(J) if sign is None else np.asarray(sign, dtype=float).copy()
    w_T_F = np.empty((J, 4, 4))  # frames at q = 0, where F_j' = F_j
    for j in range(J):
        p = topo.parent[j]
        w_T_P = np.eye(4) if p < 0 else w_T_F[p]
        axis = geometry.axes[j] / np.linalg.norm(geometry.axes[j])
        if sign is None:
            signs[j] = -1.0 if axis @ w_T_P[:3, 2] < -1e-12 else 1.0
        z = signs[j] * axis
        b[j] = w_T_P[:3, :3].T @ z
        b[j] /= np.linalg.norm(b[j])
        R = w_T_P[:3, :3] @ rotation_from_axis(b[j])
        if topo.revolute[j]:
            origin = geometry.points[j] + ((w_T_P[:3, 3] - geometry.points[j]) @ z) * z
            l[j] = R.T @ (origin - w_T_P[:3, 3])
            l[j, 2] = 0.0
        w_T_F[j] = transform_from_rotation_translation(R, w_T_P[:3, 3] + R @ l[j])
    w_T_P = np.stack([np.eye(4) if p < 0 else w_T_F[p] for p in topo.frame_parent])
    tool_T = inverse_transform(w_T_P) @ geometry.w_T_frames
    return CPCModel(topology=topo, b=b, beta=np.zeros(J), l=l, sign=signs, tool_T=tool_T)


def geometry_from_robot(robot: Robot, frames: tuple[str, ...] | list[str]) -> ZeroGeometry:
    """Screw axes at ``q = 0`` of the URDF joints that carry ``frames``, by Pinocchio FK.

    Coordinates are in the URDF root link.
    """
    topo = robot.topology(frames)
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    axes = np.empty((len(topo.joint_names), 3))
    points = np.empty_like(axes)
    for j, name in enumerate(topo.joint_names):
        w_T_J = data.oMi[model.getJointId(name)]
        axes[j] = w_T_J.rotation @ robot.joint(name).axis
        points[j] = w_T_J.translation
    w_T_frames = np.stack([data.oMf[robot.frame_id(f)].homogeneous for f in topo.frames])
    return ZeroGeometry(topology=topo, axes=axes, points=points, w_T_frames=w_T_frames)


def cpc_from_robot(
    robot: Robot, frames: tuple[str, ...] | list[str], sign: ArrayLike | None = None
) -> CPCModel:
    """The canonical CPC model of a URDF's nominal geometry for the given end frames."""
    return cpc_from_geometry(geometry_from_robot(robot, frames), sign=sign)
