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
- ``parameters`` selects what else is free (see :func:`identification.refine.refine`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.blocks import BlockKey, CPCBlock, RigidFrameBlock, ZeroOffsetBlock
from kinfw.cpc import CPCModel
from kinfw.observations import kind_of
from kinfw.robot import Robot

__all__ = ["robot_blocks"]


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


def robot_blocks(
    model0: CPCModel,
    robot: Robot,
    groups: list[Any],
    model_frame: str | None,
    parameters: str | tuple[str, ...],
) -> tuple[CPCBlock, RigidFrameBlock, ZeroOffsetBlock]:
    """The robot's blocks with their free masks: CPC chart, base, joint zero offsets.

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
        The parameter set (see :func:`identification.refine.refine`).
    """
    observed = model0.topology.frames
    cpc = CPCBlock(
        BlockKey("cpc"), free=_cpc_free(model0, robot, groups, observed, parameters), model=model0
    )
    in_model_frame = any(
        kind_of(g).has_measured_in and kind_of(g).measured_in(g) == model_frame for g in groups
    )
    base_free = parameters not in ("full", "none") and in_model_frame
    base = RigidFrameBlock(BlockKey("base"), free=np.full(6, base_free), start=np.eye(4))
    topo = model0.topology
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
        free=useful & (parameters == "offsets"),
        joint_names=tuple(topo.joint_names),
        revolute=tuple(bool(r) for r in topo.revolute),
    )
    return cpc, base, zero
