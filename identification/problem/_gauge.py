"""Gauge and fixing rules: which robot parameters the problem estimates.

The CPC chart is minimal for poses of end frames in the measurement frame. Around it:

- an end frame observed only indirectly (through markers or points of unknown offset,
  per :meth:`ObservationKind.direct_frames`) keeps its nominal tool transform: the
  markers carry the freedom;
- a revolute joint's child link keeps its origin on the joint axis (its tool ``x, y``);
- the base (a rigid transform of the whole model) and the joint zero offsets are
  redundant with the full chart: they are free only in the smaller parameter sets, the
  base only when some observation is expressed in the model frame, a zero offset only
  where it is not redundant with a tool or the base;
- ``parameters`` selects what else is free (see :func:`kinfw.identification.refine`);
  an extra robot block (a joint's gear scale) says itself what it frees under each set
  (:meth:`kinfw.model.RobotBlock.free_for`);
- with observations measured in a frame of the robot (relative poses between two
  branches), what they leave undetermined (the joints above the branches' common
  ancestor, the base, a rigid motion of the branches) is fixed from the problem's
  structure (:func:`relative_gauge`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.model import (
    CPC_KEY,
    BaseBlock,
    BlockKey,
    CPCBlock,
    CPCModel,
    Robot,
    RobotBlock,
    ZeroOffsetBlock,
)
from kinfw.observations import kind_of


def _ancestors(topo: Any, j: int) -> list[int]:
    out, p = [], topo.parent[j]
    while p >= 0:
        out.append(p)
        p = topo.parent[p]
    return out


def _cpc_free(
    model0: CPCModel,
    robot: Robot,
    groups: list[Any],
    observed: tuple[str, ...],
    parameters: str | tuple[str, ...],
) -> NDArray[np.bool_]:
    names = list(model0.parameter_names)
    free = np.ones(len(names), bool)
    direct = {f for g in groups for f in kind_of(g).direct_frames(g)}
    # a frame of the robot that observations are measured in enters them directly
    direct |= {kind_of(g).measured_in(g) for g in groups} & set(observed)
    for f in observed:
        if f not in direct:  # its markers carry the freedom: keep the nominal tool
            free[[k for k, (o, _) in enumerate(names) if o == f]] = False
    for f in observed:  # a revolute joint's child link has its origin on the joint axis
        path = robot.path_joints(f)
        last = path[-1] if path else None
        if last is not None and last.is_revolute and last.child == f:
            free[[k for k, (o, c) in enumerate(names) if o == f and c in ("x", "y")]] = False
    tools = np.array([o in model0.topology.frames for o, _ in names])
    if parameters == "full":
        return free
    if parameters in ("offsets", "frames", "none"):
        return free & (tools if parameters != "none" else np.zeros(len(names), bool))
    wanted = set()  # a mask: joint names (all their parameters) or "joint:field" entries
    for token in [] if isinstance(parameters, str) else parameters:
        owner, _, field_ = token.partition(":")
        matches = [
            k for k, (o, f) in enumerate(names) if o == owner and (not field_ or f == field_)
        ]
        if owner not in model0.topology.joint_names or not matches:
            raise ValueError(
                f"parameters: expected 'full', 'offsets', 'frames', 'none', joint names "
                f"or 'joint:field' of {list(model0.topology.joint_names)} (fields "
                f"b_tilt_1, b_tilt_2, l_x, l_y); got {token!r}"
            )
        wanted.update(matches)
    if isinstance(parameters, str) or not wanted:
        raise ValueError(
            f"parameters: expected 'full', 'offsets', 'frames', 'none' or a "
            f"mask of joints; got {parameters!r}"
        )
    return free & (tools | np.isin(np.arange(len(names)), sorted(wanted)))


def _without_exact(
    parameters: str | tuple[str, ...], topo: Any, exact: NDArray[np.bool_]
) -> str | tuple[str, ...]:
    """``"full"`` without the joints whose kinematics is exact (``exact``, along
    ``topo.joint_names``: :attr:`kinfw.model.Robot.exact_joints`): the mask of the others,
    or ``"frames"`` when every joint is exact; other sets as given."""
    if parameters != "full" or not exact.any():
        return parameters
    rest = tuple(name for name, e in zip(topo.joint_names, exact, strict=True) if not e)
    return rest or "frames"


def robot_blocks(
    model0: CPCModel,
    robot: Robot,
    groups: list[Any],
    model_frame: str | None,
    parameters: str | tuple[str, ...],
    *,
    with_prior: bool = False,
    extra: tuple[RobotBlock, ...] = (),
) -> tuple[RobotBlock, ...]:
    """The robot's blocks with their free masks: CPC chart, base, the ``extra`` ones,
    joint zero offsets.

    Parameters
    ----------
    model0 : CPCModel
        Start model (end frames: the observed frames), in the model frame.
    robot : Robot
        The nominal URDF (joint types, paths).
    groups : list
        Every observation group.
    model_frame : str or None
        The external frame the model is expressed in, None for the URDF root.
    parameters : str or tuple of str
        The parameter set (see :func:`kinfw.identification.refine`). The joints
        ``robot.exact_joints`` names keep their nominal CPC parameters and zero offsets
        under every set: ``"full"`` is then the mask of the other joints.
    with_prior : bool
        Whether a Gaussian prior restrains the robot's parameters. With ``"full"`` the
        joint zero offsets are then free too: redundant with the CPC chart without a
        prior (a zero offset turns every axis below the joint), but under a prior the
        one-parameter offset -- the encoder zero, often a real robot's largest error --
        costs one prior term where the chart would pay one per axis below.
    extra : tuple of RobotBlock
        Further robot blocks (e.g. a joint's gear scale), free as their
        :meth:`~kinfw.model.RobotBlock.free_for` says under ``parameters``.

    Raises
    ------
    ValueError
        For an extra block that is not a :class:`~kinfw.model.RobotBlock` or whose key
        is taken.
    """
    observed = model0.topology.frames
    topo = model0.topology
    exact = np.isin(topo.joint_names, robot.exact_joints)
    chart_set = _without_exact(parameters, topo, exact)
    cpc = CPCBlock(
        CPC_KEY, free=_cpc_free(model0, robot, groups, observed, chart_set), model=model0
    )
    in_model_frame = any(
        kind_of(g).has_measured_in and kind_of(g).measured_in(g) == model_frame for g in groups
    )
    base_free = chart_set not in ("full", "none") and in_model_frame
    base = BaseBlock(BlockKey("base"), free=np.full(6, base_free), start=np.eye(4))
    # a zero offset is redundant with a tool when the joint carries only end frames, and
    # with the base when only prismatic joints lie above it (a constant translation)
    useful = np.array(
        [
            (topo.revolute[j] and bool(topo.children(j)))
            or (not topo.revolute[j] and any(topo.revolute[a] for a in _ancestors(topo, j)))
            for j in range(model0.n_joints)
        ],
        dtype=bool,
    )
    zero = ZeroOffsetBlock(
        BlockKey("zero_offset"),
        free=useful & ~exact & (parameters == "offsets" or (parameters == "full" and with_prior)),
        joint_names=tuple(topo.joint_names),
        revolute=tuple(bool(r) for r in topo.revolute),
    )
    more: tuple[RobotBlock, ...] = ()
    for b in extra:
        if not isinstance(b, RobotBlock):
            raise ValueError(f"extra_blocks: expected RobotBlock instances, got {type(b).__name__}")
        if b.key in {o.key for o in (cpc, base, zero, *more)}:
            raise ValueError(f"extra_blocks: the key {b.key} is taken")
        more += (b.with_free(b.free_for(parameters)),)
    # the readings' maps act before the zero offsets (q' = (1 + s) q + z for a scale), so
    # that model_at's model, with the offsets folded in, takes the joint values after
    # them; a deflection acts after, on the physical joint values
    readings = tuple(b for b in more if b.stage != "deflection")
    deflections = tuple(b for b in more if b.stage == "deflection")
    return (cpc, base, *readings, zero, *deflections)


#: Relative norm (columns scaled to unit norm) below which a parameter's Jacobian column
#: adds nothing to the ones kept before it in :func:`relative_gauge`.
STRUCTURAL_RANK_TOL = 1e-7


def relative_gauge(
    blocks: tuple[Any, ...],
    groups: list[Any],
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
    rng: np.random.Generator | None = None,
) -> tuple[tuple[Any, ...], tuple[str, ...]]:
    """Fix the parameters that relative measurements leave undetermined.

    Observations measured in a frame of the robot (a head camera seeing the hand) depend
    on the two branches below their common ancestor only: the joints from the root to
    that ancestor, the base, and a rigid motion of everything below the ancestor do not
    change them. When no other observation pins those parameters, the rules of
    :func:`robot_blocks` leave them free and the problem singular. This finds them from
    the structure alone: the Jacobian of every group at random configurations (within
    the joint limits, at most +-pi; not the data's, so that a poorly exciting dataset is
    still reported by the diagnostics, not hidden here) and keeps the free columns one by
    one while they add rank, in the order: the unknown blocks (markers, targets,
    external frames), the end frames' tools, the joints from the deepest (most ancestors)
    to the root, the
    zero offsets, the base. The others are fixed at their start.

    Parameters
    ----------
    blocks : tuple of Block
        The robot's blocks and the unknowns, as built.
    groups : list of ResidualGroup
        Their residual functions (the free masks are not part of them).
    lower, upper : ndarray, shape (J,)
        Joint limits of the model's joints (rad or m; +-inf where unbounded).
    rng : numpy.random.Generator, optional
        For the configurations (default: a fixed seed, so the choice is reproducible).

    Returns
    -------
    blocks : tuple of Block
        With the undetermined entries fixed.
    fixed : tuple of str
        The names (``owner:field``) of the parameters fixed here.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    J = _structure_jacobian(blocks, groups, lower, upper, rng)
    starts = np.cumsum([0, *(b.size for b in blocks)])
    cpc = next(b for b in blocks if b.key == CPC_KEY)
    topo = cpc.model.topology
    rank = _column_ranks(blocks, starts, topo)
    free = np.concatenate([b.free for b in blocks])
    shared_names = {topo.joint_names[j] for j in _shared_joints(groups, topo)}
    for b, start in zip(blocks, starts[:-1], strict=True):
        if isinstance(b, RobotBlock) and not isinstance(b, BaseBlock):
            for k, (owner, _) in enumerate(b.names):
                if owner in shared_names:
                    free[start + k] = False
    order = sorted(np.flatnonzero(free), key=lambda col: rank[col])
    keep = _columns_adding_rank(J, order)
    dropped = np.concatenate([b.free for b in blocks]) & ~keep
    if not dropped.any():
        return blocks, ()
    names = [f"{n.owner}:{n.field}" for b in blocks for n in b.names]
    out = tuple(
        b.with_free(b.free & keep[s:e])
        for b, s, e in zip(blocks, starts[:-1], starts[1:], strict=True)
    )
    return out, tuple(names[k] for k in np.flatnonzero(dropped))


def _structure_jacobian(
    blocks: tuple[Any, ...],
    groups: list[Any],
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """The Jacobian, shape (rows, P), of every group at the start, at random
    configurations within the joint limits (at most +-pi) and cycling through the
    group's data (see :func:`relative_gauge`)."""
    lo = np.where(np.isfinite(lower), lower, -np.pi)
    hi = np.where(np.isfinite(upper), upper, np.pi)
    lo, hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)
    P = sum(b.size for b in blocks)
    n_free = int(sum(b.free.sum() for b in blocks))
    x = np.zeros(P)
    parts = []
    for g in groups:
        # enough configurations for every free parameter even from one group alone (a
        # contact gives one row per configuration, a pose six)
        n = max(12, -(-n_free // g.rows) + 6)
        qs = lo[:, None] + (hi - lo)[:, None] * rng.uniform(size=(len(lo), n))
        # the robot blocks' per-sample inputs after the joints: the group's own, cycled
        qs = np.vstack([qs, g.qs[len(lo) :, np.arange(n) % g.qs.shape[1]]])
        data = g.data[:, np.arange(n) % g.data.shape[1]]
        f = g.functions.j.map("structure", "serial", n, [2, 3], [])
        J = np.asarray(f(qs, data, x, g.const))  # (rows, n * P)
        parts.append(J.reshape(g.rows, n, P).transpose(1, 0, 2).reshape(-1, P))
    return np.concatenate(parts)


def _column_ranks(
    blocks: tuple[Any, ...], starts: NDArray[np.int_], topo: Any
) -> list[tuple[int, int]]:
    """Per column of the parameter vector its place in the order of
    :func:`relative_gauge`: unknown blocks, tools, joints deepest first, zero offsets and
    further robot blocks, base."""
    frames = set(topo.frames)
    depth = {j: len(_ancestors(topo, k)) for k, j in enumerate(topo.joint_names)}
    rank: list[tuple[int, int]] = []
    for b, start in zip(blocks, starts[:-1], strict=True):
        for k, (owner, _) in enumerate(b.names):
            col = int(start) + k
            if not isinstance(b, RobotBlock):
                rank.append((0, col))  # unknown blocks first
            elif b.key == CPC_KEY:
                joint = owner not in frames
                rank.append((2, -depth.get(owner, 0) * 100000 + col) if joint else (1, col))
            elif isinstance(b, BaseBlock):
                rank.append((4, col))
            else:  # zero offsets and any further robot block: after the joints' axes
                rank.append((3, -col))
    return rank


def _shared_joints(groups: list[Any], topo: Any) -> set[int]:
    """The joints above the common ancestor of every group's two frames (observed and
    measured in): they move both alike, so none of their parameters enters a relative
    pose (none when a group is measured in the root or an external frame)."""
    frames = set(topo.frames)
    shared = set(range(len(topo.joint_names)))
    for g in groups:
        kind, group = g.kind, g.group
        inside = kind.relative_to(group)
        if inside not in frames:  # measured in the root or an external frame: pins all
            return set()
        for f in kind.frames(group):
            a, b = topo.frames.index(f), topo.frames.index(inside)
            pa, pb = topo.frame_parent[a], topo.frame_parent[b]
            above_a = set() if pa < 0 else {pa, *_ancestors(topo, pa)}
            above_b = set() if pb < 0 else {pb, *_ancestors(topo, pb)}
            shared &= above_a & above_b
    return shared


def _columns_adding_rank(J: NDArray[np.float64], order: list[int]) -> NDArray[np.bool_]:
    """Mask of the columns of ``J`` kept, in ``order``, while they add rank: each one's
    part (unit-normed) orthogonal to those kept before exceeds
    :data:`STRUCTURAL_RANK_TOL`."""
    norms = np.linalg.norm(J, axis=0)
    basis = np.zeros((J.shape[0], 0))
    keep = np.zeros(J.shape[1], bool)
    for col in order:
        if norms[col] == 0.0:
            continue
        v = J[:, col] / norms[col]
        for _ in range(2):  # classical Gram-Schmidt, twice
            v = v - basis @ (basis.T @ v)
        size = np.linalg.norm(v)
        if size > STRUCTURAL_RANK_TOL:
            basis = np.column_stack([basis, v / size])
            keep[col] = True
    return keep
