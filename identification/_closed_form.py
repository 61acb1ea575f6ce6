"""Closed-form CPC identification from one-joint-at-a-time pose data.

Shih et al. (1992), section 4, generalised from the IIS-head to any tree of revolute and
prismatic joints read from a URDF (only the topology is used, never the nominal
geometry).

The protocol (section 4.1, Fig. 8): from a common configuration ``q0`` one joint at a
time moves through several values while the end frames' poses are measured. When only
joint ``j`` moves by ``dq`` from ``q0``, every end frame below it moves rigidly by the
screw motion of joint ``j`` *as it is at* ``q0``::

    w_T_e(q0 + dq e_j) = exp(S_j(q0) dq) w_T_e(q0).                         (*)

The paper exploits (*) in chains of local frames, from the end effectors toward the
base. Here every quantity is expressed once, in the measurement frame ``w`` at ``q0``;
the equations are the paper's, and each step says which:

Step 1 (rotations, eqs. 29-35, 36-41, 46-52)
    For each revolute joint, the relative rotations ``C = R_e(b) R_e(a)^T`` between any
    two samples ``a, b`` of its group (the samples where only it moved, and those at
    ``q0``) rotate about its axis ``w`` in ``w``: ``(C - I) w = 0`` (eq. 33 in world
    coordinates). Stacking every pair and *every end frame below the joint* (both chains
    for a shared joint, eq. 52) gives the axis as the eigenvector of the smallest
    eigenvalue of the stacked ``(C - I)^T (C - I)`` (eq. 35). Pairs rather than only
    ``(q0, q_k)`` use every sample symmetrically, so no single measurement of ``q0``
    dominates and the result does not depend on sample order. The eigenvector has no
    sign: the axis sense is the one about which the frames turn right-handed as ``q``
    increases (DESIGN.md's pitfall). Because the frames of all branches are expressed in
    the one frame ``w``, the paper's branch alignment ``beta_3`` (step 1-c, eq. 45) is
    not needed: it exists only to map the right chain's local frames into the left
    chain's before stacking, which ``w`` does for free. The end frames' orientations at
    ``q0`` are the chordal mean over all their samples with the identified rotations
    undone.
Step 2 (translations, eqs. 58-64)
    With the rotations known, (*) is linear in the remaining unknowns: each end frame's
    position at ``q0`` (the paper's ``l_5``), a point on each revolute axis (2 numbers,
    the paper's ``l_x, l_y``; the position along the axis is the redundant ``l_z``) and
    each prismatic joint's direction (the paper's ``w_r_0z``, ``w_r_1z``). One linear
    least squares over every sample and end frame, subject to unit prismatic directions
    (eq. 64), solved exactly by Gauss-Newton on the unit spheres from the normalised
    unconstrained solution.
Step 3 (base side, eqs. 65-67)
    The screw axes at ``q0`` are carried back to ``q = 0`` (undoing each joint's ``q0``
    from the root outward) and converted to the canonical CPC parameters by
    :func:`kinfw.model.cpc_from_geometry`, which does the paper's Step 3 in general: the
    base-side rotations ``R(b)`` of every frame and the base offset.

Degenerate data is detected and explained, never solved: samples that are not
one-joint-at-a-time around a common ``q0``, a joint that never moved or moved through
too few values, a joint that no observed frame depends on, and joint values whose unit
does not match the measured motion (e.g. degrees read as radians).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw import progress
from kinfw.geometry import (
    inverse_transform,
    matrix_from_rotation_vector,
    project_to_rotation,
    rotation_vector_from_matrix,
    transform_from_rotation_translation,
)
from kinfw.identification.checks import UnitError, check_joint_scale
from kinfw.measurements import Measurements, check_against_robot
from kinfw.model import (
    CPCModel,
    Robot,
    Topology,
    ZeroGeometry,
    cpc_from_geometry,
    perpendicular_basis,
)
from kinfw.observations import DatasetError

log = logging.getLogger(__name__)

#: Joint values closer than this are the same value (rad or m).
SAME_VALUE = 1e-9


class ProtocolError(DatasetError):
    """The data is not one-joint-at-a-time, or cannot identify a joint."""


class JointScaleError(ProtocolError, UnitError):
    """A joint's measured motion per unit of its value is not 1 (another unit, a gear
    ratio): a unit error, refused by every method of the pipeline."""


@dataclass(frozen=True, slots=True)
class ClosedFormResult:
    """The closed-form estimate and the evidence behind it.

    Attributes
    ----------
    model : CPCModel
        Canonical CPC model of the identified geometry (end frames: the pose-observed
        frames).
    geometry : ZeroGeometry
        Screw axes and end-frame poses at ``q = 0`` in the measurement frame.
    q0 : ndarray, shape (J,)
        The common configuration of the protocol, ``model.topology.joint_names`` order.
    group_sizes : ndarray of int, shape (J,)
        Samples in which each joint alone moved.
    axis_residual_rad : ndarray, shape (J,)
        RMS of ``|(C - I) w|`` over the stacked pairs (Step 1; NaN for prismatic joints).
    motion_scale : ndarray, shape (J,)
        Measured rotation (rad) or translation (m) per unit of joint value; 1 for
        consistent units.
    position_rms_m : float
        RMS position residual of the Step 2 least squares, metres.
    """

    model: CPCModel
    geometry: ZeroGeometry
    q0: NDArray[np.float64]
    group_sizes: NDArray[np.int64]
    axis_residual_rad: NDArray[np.float64]
    motion_scale: NDArray[np.float64]
    position_rms_m: float


def _mode(values: NDArray[np.float64]) -> float:
    """Most frequent value (ties: the smallest), values within SAME_VALUE merged."""
    v = np.sort(values)
    starts = np.concatenate(([0], np.flatnonzero(np.diff(v) > SAME_VALUE) + 1))
    counts = np.diff(np.concatenate((starts, [len(v)])))
    return float(v[starts[np.argmax(counts)]])


def one_joint_groups(
    qs: NDArray[np.float64], joint_names: tuple[str, ...], source: str
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The common configuration ``q0`` and which joint moved in each sample.

    Parameters
    ----------
    qs : ndarray, shape (n, J)
    joint_names : tuple of str
        Names of the columns, for messages.
    source : str
        Dataset name, for messages.

    Returns
    -------
    q0 : ndarray, shape (J,)
        Per joint, its most frequent value.
    moved : ndarray of int, shape (n,)
        Index of the joint that differs from ``q0`` in each sample, -1 for none.

    Raises
    ------
    ProtocolError
        Naming the first sample that differs from ``q0`` in more than one joint.
    """
    q0 = np.array([_mode(qs[:, j]) for j in range(qs.shape[1])])
    differs = np.abs(qs - q0) > SAME_VALUE
    count = differs.sum(axis=1)
    if np.any(count > 1):
        k = int(np.argmax(count > 1))
        names = [joint_names[j] for j in np.flatnonzero(differs[k])]
        raise ProtocolError(
            f"{source}: sample {k} differs from the common configuration q0 in joints "
            f"{names}; the closed form needs one-joint-at-a-time data (Shih et al. "
            "section 4.1): every sample equal to q0 except in at most one joint"
        )
    moved = np.where(count == 1, np.argmax(differs, axis=1), -1)
    return q0, moved


def _revolute_exp(axis: NDArray, point: NDArray, angles: NDArray) -> NDArray:
    """Screw motions ``exp(S dq)`` about the line (axis, point), (n, 4, 4)."""
    R = matrix_from_rotation_vector(angles[:, None] * axis)
    return transform_from_rotation_translation(R, point - R @ point)


def _smallest_eigenvector(M: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    w, V = np.linalg.eigh(M)
    return V[:, 0], float(max(w[0], 0.0))


def _step1_axis(
    R: NDArray, a: NDArray, b: NDArray, dq: NDArray, name: str, source: str
) -> tuple[NDArray, float, float]:
    """Axis (sense from the data), RMS residual and rotation per unit q of one joint.

    ``R`` (m, 3, 3) are measured orientations; pairs ``(a[i], b[i])`` index rows of ``R``
    with joint value difference ``dq[i] = q_b - q_a``.
    """
    C = R[b] @ np.swapaxes(R[a], 1, 2)  # rotation from pose a to pose b, in w
    D = C - np.eye(3)
    axis, lam = _smallest_eigenvector(np.einsum("kji,kjl->il", D, D))  # eq. (35)
    rotvec = rotation_vector_from_matrix(C)
    theta = np.linalg.norm(rotvec, axis=1)
    # Sense and scale from the pairs whose rotation cannot wrap around pi.
    short = (theta < np.pi - 0.2) & (np.abs(dq) < np.pi - 0.2)
    if np.any(short):
        scale = float((rotvec[short] @ axis) @ dq[short] / (dq[short] @ dq[short]))
    else:  # no unambiguous pair: still tell degrees-read-as-radians apart
        clear = theta < np.pi - 0.2
        scale = (
            float(theta[clear] @ np.abs(dq[clear]) / (dq[clear] @ dq[clear]))
            if np.any(clear)
            else float("nan")
        )
    if scale < 0.0:
        axis, scale = -axis, -scale
    check_joint_scale(name, scale, revolute=True, source=source, error=JointScaleError)
    if not np.any(short):
        raise ProtocolError(
            f"{source}: joint {name!r}: every pair of its values is at least "
            "pi - 0.2 rad apart, so the sense of rotation is ambiguous; add "
            "values closer together"
        )
    return axis, float(np.sqrt(lam / len(C))), scale


def _pairs(rows: NDArray[np.int64]) -> tuple[NDArray, NDArray]:
    a, b = np.triu_indices(len(rows), k=1)
    return rows[a], rows[b]


def _unit_sphere_gauss_newton(
    A: NDArray, y: NDArray, x: NDArray, blocks: list[slice], iterations: int = 30
) -> NDArray:
    """Minimise ``|A x - y|^2`` subject to every ``x[block]`` being a unit 3-vector.

    The constrained least squares of eq. (64): Gauss-Newton in the tangent spaces of the
    unit spheres (the other unknowns are free), from the normalised start ``x``.
    """
    x = x.copy()
    constrained = np.zeros(len(x), bool)
    for blk in blocks:
        x[blk] /= np.linalg.norm(x[blk])
        constrained[blk] = True
    free = np.eye(len(x))[:, ~constrained]
    for _ in range(iterations):
        tangents = []
        for blk in blocks:
            t = np.zeros((len(x), 2))
            t[blk] = perpendicular_basis(x[blk]).T
            tangents.append(t)
        B = np.concatenate([free, *tangents], axis=1)
        step, *_ = np.linalg.lstsq(A @ B, y - A @ x, rcond=None)
        x = x + B @ step
        for blk in blocks:
            x[blk] /= np.linalg.norm(x[blk])
        if np.linalg.norm(step) < 1e-14 * (1.0 + np.linalg.norm(x)):
            break
    return x


@dataclass(frozen=True, slots=True)
class _FrameData:
    """The pose observations of one end frame: poses, joint values, moved joint."""

    w_T_e: NDArray[np.float64]  # (m, 4, 4)
    qs: NDArray[np.float64]  # (m, J)
    moved: NDArray[np.int64]  # (m,) joint index, -1 at q0


def collect_frame_data(
    robot: Robot, measurements: Measurements, frames: tuple[str, ...] | None
) -> tuple[Topology, NDArray, list[_FrameData], NDArray]:
    """Topology, q0, per-frame data and per-joint group sizes; checks the protocol."""
    source = measurements.source
    groups = [g for g in measurements.poses if g.marker is None and g.measured_in is None]
    if frames is not None:
        groups = [g for g in groups if g.frame in frames]
    if not groups:
        raise ProtocolError(
            f"{source}: the closed form needs 'pose' observations of end frames in the root "
            f"frame {robot.root_link!r} (no marker, no measured_in)"
        )
    topo = robot.topology(tuple(dict.fromkeys(g.frame for g in groups)))
    names = topo.joint_names
    q_all = measurements.q_of(names)
    observed = np.unique(np.concatenate([g.sample for g in groups]))
    q0, moved_observed = one_joint_groups(q_all[observed], names, source)
    moved = np.full(measurements.n_samples, -2)
    moved[observed] = moved_observed
    data = []
    for f in topo.frames:
        mine = [g for g in groups if g.frame == f]
        sample = np.concatenate([g.sample for g in mine])
        data.append(
            _FrameData(np.concatenate([g.meas_T_frame for g in mine]), q_all[sample], moved[sample])
        )
    sizes = np.array([int(np.sum(moved_observed == j)) for j in range(len(names))])
    for j, name in enumerate(names):
        in_group = (moved_observed == j) | (moved_observed == -1)
        values = np.unique(np.round(q_all[observed][in_group, j] / SAME_VALUE))
        if len(values) < 2:
            raise ProtocolError(
                f"{source}: joint {name!r} moves through {len(values)} distinct value(s) in "
                "the one-joint-at-a-time samples; it needs at least 2 (with every other "
                "joint at q0), observed by a frame below it, to be identified"
            )
    return topo, q0, data, sizes


def identify_axes(
    topo: Topology, data: list[_FrameData], source: str
) -> tuple[NDArray, NDArray, NDArray]:
    """Revolute axes at q0 in w (eqs. 33-35, 52), their residuals and motion scales:
    a :func:`kinfw.progress.steps` step per joint (its pairs of poses grow with the
    square of its samples)."""
    J = len(topo.joint_names)
    axes = np.zeros((J, 3))
    residual = np.full(J, np.nan)
    scale = np.ones(J)
    revolute = [int(j) for j in np.flatnonzero(topo.revolute)]
    for j in progress.steps(revolute, "closed form: joint axes", unit="joints"):
        R, a_all, b_all, dq_all, offset = [], [], [], [], 0
        for e, f in enumerate(topo.frames):
            if j not in topo.chain(f):
                continue
            d = data[e]
            a, b = _pairs(np.flatnonzero((d.moved == j) | (d.moved == -1)))
            dq = d.qs[b, j] - d.qs[a, j]
            keep = np.abs(dq) > SAME_VALUE
            R.append(d.w_T_e[:, :3, :3])
            a_all.append(a[keep] + offset)
            b_all.append(b[keep] + offset)
            dq_all.append(dq[keep])
            offset += len(d.moved)
        dq = np.concatenate(dq_all)
        if not len(dq):
            raise ProtocolError(
                f"{source}: joint {topo.joint_names[j]!r}: no frame below it "
                "was measured at two of its values"
            )
        axes[j], residual[j], scale[j] = _step1_axis(
            np.concatenate(R),
            np.concatenate(a_all),
            np.concatenate(b_all),
            dq,
            topo.joint_names[j],
            source,
        )
    return axes, residual, scale


def identify_translations(
    topo: Topology, data: list[_FrameData], q0: NDArray, axes: NDArray, source: str
) -> tuple[NDArray, NDArray, NDArray, NDArray, float]:
    """End-frame poses at q0, axis points, prismatic directions (eqs. 58-64).

    Returns ``w_T_e_q0`` (E, 4, 4), revolute axis points (J, 3), prismatic directions
    (J, 3; unit), prismatic motion scales (J,) before the unit constraint, and the RMS
    position residual (m).
    """
    J, E = len(topo.joint_names), len(topo.frames)
    col, n = {}, 3 * E
    for j in range(J):
        col[j], n = n, n + (2 if topo.revolute[j] else 3)
    bases = {j: perpendicular_basis(axes[j]) for j in np.flatnonzero(topo.revolute)}
    A_blocks, y_blocks, w_R_e_q0 = [], [], []
    for e, f in enumerate(topo.frames):
        d = data[e]
        m = len(d.moved)
        dq = np.where(
            d.moved >= 0,
            d.qs[np.arange(m), np.maximum(d.moved, 0)] - q0[np.maximum(d.moved, 0)],
            0.0,
        )
        A = np.zeros((m, 3, n))
        A[:, :, 3 * e : 3 * e + 3] = np.eye(3)
        undo = np.tile(np.eye(3), (m, 1, 1))
        for j in topo.chain(f):
            rows = d.moved == j
            if not np.any(rows):
                continue
            if topo.revolute[j]:  # p = R p0 + (I - R) c,  c = bases^T (c_1, c_2)
                Rj = matrix_from_rotation_vector(dq[rows, None] * axes[j])
                A[rows, :, 3 * e : 3 * e + 3] = Rj
                A[rows, :, col[j] : col[j] + 2] = (np.eye(3) - Rj) @ bases[j].T
                undo[rows] = np.swapaxes(Rj, 1, 2)
            else:  # p = p0 + dq v
                A[rows, :, col[j] : col[j] + 3] = dq[rows, None, None] * np.eye(3)
        A_blocks.append(A.reshape(-1, n))
        y_blocks.append(d.w_T_e[:, :3, 3].reshape(-1))
        w_R_e_q0.append(project_to_rotation((undo @ d.w_T_e[:, :3, :3]).mean(axis=0)))
    A, y = np.concatenate(A_blocks), np.concatenate(y_blocks)
    x, *_ = np.linalg.lstsq(A, y, rcond=None)
    prismatic = [j for j in range(J) if not topo.revolute[j]]
    scale = np.ones(J)
    for j in prismatic:
        scale[j] = float(np.linalg.norm(x[col[j] : col[j] + 3]))
        check_joint_scale(
            topo.joint_names[j], scale[j], revolute=False, source=source, error=JointScaleError
        )
    if prismatic:
        x = _unit_sphere_gauss_newton(A, y, x, [slice(col[j], col[j] + 3) for j in prismatic])
    points = np.zeros((J, 3))
    directions = np.zeros((J, 3))
    for j in range(J):
        if topo.revolute[j]:
            points[j] = bases[j].T @ x[col[j] : col[j] + 2]
        else:
            directions[j] = x[col[j] : col[j] + 3]
    w_T_e_q0 = transform_from_rotation_translation(np.stack(w_R_e_q0), x[: 3 * E].reshape(E, 3))
    rms = float(np.sqrt(np.mean((A @ x - y) ** 2) * 3.0))
    return w_T_e_q0, points, directions, scale, rms


def geometry_at_zero(
    topo: Topology, axes: NDArray, points: NDArray, w_T_e_q0: NDArray, q0: NDArray
) -> ZeroGeometry:
    """Carry screw axes and end-frame poses from configuration ``q0`` back to ``q = 0``.

    With ``G_j`` the motion of everything below joint ``j``'s parent link when the joints
    above ``j`` go from 0 to ``q0``, ``G_j = exp(S_p(q0) q0_p) G_p`` (the screw at
    ``q0`` already includes ``G_p``), and ``S_j(0) = Ad(G_j^-1) S_j(q0)``.
    """
    J = len(topo.joint_names)
    G = np.empty((J, 4, 4))
    moved_by = np.empty((J, 4, 4))  # exp(S_j(q0) q0_j) G_j: what q0 did below joint j
    for j in range(J):
        p = topo.parent[j]
        G[j] = np.eye(4) if p < 0 else moved_by[p]
        if topo.revolute[j]:
            step = _revolute_exp(axes[j], points[j], np.array([q0[j]]))[0]
        else:
            step = transform_from_rotation_translation(np.eye(3), q0[j] * axes[j])
        moved_by[j] = step @ G[j]
    G_inv = inverse_transform(G)
    axes0 = np.einsum("jab,jb->ja", G_inv[:, :3, :3], axes)
    points0 = np.einsum("jab,jb->ja", G_inv[:, :3, :3], points) + G_inv[:, :3, 3]
    last = np.stack([np.eye(4) if p < 0 else moved_by[p] for p in topo.frame_parent])
    return ZeroGeometry(topo, axes0, points0, inverse_transform(last) @ w_T_e_q0)


def identify_closed_form(
    robot: Robot, measurements: Measurements, *, frames: tuple[str, ...] | None = None
) -> ClosedFormResult:
    """Identify the CPC model of ``robot``'s tree from one-joint-at-a-time pose data.

    Parameters
    ----------
    robot : Robot
        Supplies the topology only (which joints carry which frames, joint types); the
        nominal geometry is not used.
    measurements : Measurements
        ``pose`` observations of end frames in the URDF root frame (no ``marker``, no
        ``measured_in``); other observations are ignored here.
    frames : tuple of str, optional
        End frames to use; default every frame with such pose observations.

    Returns
    -------
    ClosedFormResult

    Raises
    ------
    ProtocolError
        For data that cannot identify the model, naming the sample or joint.
    """
    measurements = check_against_robot(measurements, robot)
    topo, q0, data, sizes = collect_frame_data(robot, measurements, frames)
    axes, residual, scale = identify_axes(topo, data, measurements.source)
    w_T_e_q0, points, directions, p_scale, rms = identify_translations(
        topo, data, q0, axes, measurements.source
    )
    prismatic = ~np.array(topo.revolute)
    axes[prismatic] = directions[prismatic]
    scale[prismatic] = p_scale[prismatic]
    geometry = geometry_at_zero(topo, axes, points, w_T_e_q0, q0)
    log.info(
        "closed form: %d joints, %d frames, position RMS %.3g mm",
        len(topo.joint_names),
        len(topo.frames),
        1e3 * rms,
    )
    return ClosedFormResult(cpc_from_geometry(geometry), geometry, q0, sizes, residual, scale, rms)
