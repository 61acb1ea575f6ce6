"""The CasADi residual functions of a least-squares problem, and their cache.

:func:`build_functions` builds, per observation group, the residual of
:meth:`kinfw.observations.ObservationKind.residual` and its exact Jacobian as functions of
``(q, m, theta, const)``: configuration (the readings, then the robot blocks'
per-sample inputs: :meth:`kinfw.model.RobotBlock.sample_inputs`), measured row,
parameter vector and the blocks' constants. :func:`group_functions` caches them by the
problem's structure, so cross-validation folds, parameter sets and Monte Carlo trials
on one robot and observation layout build the graph once.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.identification.problem._compiled import compiled
from kinfw.model import CPC_KEY, Block, CPCModel, RobotBlock, cpc_fk_function
from kinfw.observations import SymbolicContext, kind_of


@dataclass(frozen=True, eq=False)
class GroupFunctions:
    """Per-observation CasADi functions of one group, all of ``(q, m, theta, const)``:
    residual ``r``; residual and transposed dense Jacobian ``rj`` (one call, shared
    subexpressions); Jacobian ``j``; and :meth:`rj_free`, the Jacobian's columns of the
    estimated parameters only (cheaper for the small parameter sets). Unwhitened (SI).
    :meth:`numeric_map` gives them mapped over a group's samples, compiled.
    """

    r: Any
    rj: Any
    j: Any
    args: list = field(repr=False)
    residual_expr: Any = field(repr=False)
    _by_free: dict = field(default_factory=dict, repr=False)
    _numeric_maps: OrderedDict = field(default_factory=OrderedDict, repr=False)
    _compiled: dict = field(default_factory=dict, repr=False)

    def rj_free(self, free: NDArray[np.bool_]):
        """``rj`` with the Jacobian's ``free`` columns only: ``(rows,), (n_free, rows)``."""
        import casadi as ca

        key = free.tobytes()
        with _FUNCTION_CACHE_LOCK:
            f = self._by_free.get(key)
        if f is None:
            theta = self.args[2]
            cols = ca.vertcat(*[theta[int(i)] for i in np.flatnonzero(free)])
            J = ca.jacobian(self.residual_expr, cols)
            f = ca.Function("rjf", self.args, [self.residual_expr, ca.densify(J.T)])
            with _FUNCTION_CACHE_LOCK:
                if len(self._by_free) >= 8:  # bounded: a few parameter sets per structure
                    self._by_free.pop(next(iter(self._by_free)))
                self._by_free[key] = f
        return f

    def numeric_map(
        self, with_jacobian: bool, free: NDArray[np.bool_] | None, m: int, samples: int
    ):
        """``r`` (or ``rj``, or ``rj_free(free)``) mapped over ``m`` samples (at most
        :data:`MAP_CHUNK`: building a CasADi map grows faster than its size; the
        evaluations ask for :data:`MAP_CHUNK` and powers of two below it), compiled
        when that pays for a group of ``samples`` samples, or already done
        (:func:`~kinfw.identification.problem._compiled.compiled`: the same results, bit
        for bit; numeric arguments only), with the parameters and constants shared:
        ``(q (J, m), data (width, m), theta, const)``. Kept for the problems of one
        structure (cross-validation folds, rejection refits, noise rounds)."""
        key = (with_jacobian, None if free is None else free.tobytes(), m)
        with _FUNCTION_CACHE_LOCK:
            f = self._numeric_maps.get(key)
            if f is not None:
                self._numeric_maps.move_to_end(key)
                return f
        with _FUNCTION_CACHE_LOCK:
            f = self._compiled.get(key[:2])
        if f is None:
            if not with_jacobian:
                f = compiled(self.r, samples)
            else:
                f = compiled(self.rj if free is None else self.rj_free(free), samples)
            with _FUNCTION_CACHE_LOCK:
                self._compiled[key[:2]] = f
        f = f.map("numeric_map", "serial", m, [2, 3], [])
        with _FUNCTION_CACHE_LOCK:
            self._numeric_maps[key] = f
            # bounded: the chunk sizes (MAP_CHUNK and powers of two below it) of a few
            # parameter sets
            while len(self._numeric_maps) > 64:
                self._numeric_maps.popitem(last=False)
        return f


#: Samples per call of a mapped function (:meth:`GroupFunctions.numeric_map`): building a
#: map of 2,048 samples takes ~10 ms, of 10,000 ~0.1 s, of 100,000 ~2 s.
MAP_CHUNK = 2048

#: Compiled residual functions by problem structure (see :func:`group_functions`): a small
#: LRU so that cross-validation folds, parameter sets and Monte Carlo trials on the same
#: robot and observation layout build the CasADi graph once.
_FUNCTION_CACHE: OrderedDict[tuple, tuple[GroupFunctions, ...]] = OrderedDict()

_FUNCTION_CACHE_SIZE = 16

_FUNCTION_CACHE_LOCK = threading.Lock()


def clear_function_cache() -> None:
    """Forget every cached CasADi residual function (they are rebuilt on demand)."""
    with _FUNCTION_CACHE_LOCK:
        _FUNCTION_CACHE.clear()


def build_functions(
    model0: CPCModel,
    blocks: tuple[Block, ...],
    groups: list[Any],
    model_frame: str | None,
    n_const: int,
) -> tuple[GroupFunctions, ...]:
    """The CasADi residual functions of every group, of ``(q, m, theta, const)``.

    ``const`` is the blocks' :meth:`~kinfw.model.Block.constants` one after the other
    (the CPC block's: the reference model of :func:`kinfw.model.cpc_reference_vector`).
    The end frames' poses are the robot blocks' hooks around the CPC forward kinematics
    (:class:`kinfw.model.RobotBlock`): the joint readings through every
    ``casadi_joint_values``, the CPC block's FK, then every ``casadi_frame_poses``.
    """
    import casadi as ca

    P = sum(b.size for b in blocks)
    theta = ca.SX.sym("theta", P)
    const = ca.SX.sym("const", n_const)
    joint_names = tuple(model0.topology.joint_names)
    widths = [b.sample_width(joint_names) if isinstance(b, RobotBlock) else 0 for b in blocks]
    q = ca.SX.sym("q", model0.n_joints + sum(widths))  # readings, then the blocks' inputs
    parts, k, c, w = [], 0, 0, model0.n_joints  # (block, its theta, constants, inputs)
    for b, width in zip(blocks, widths, strict=True):
        n = len(b.constants())
        parts.append((b, theta[k : k + b.size], const[c : c + n], q[w : w + width]))
        k, c, w = k + b.size, c + n, w + width
    robot = [p for p in parts if isinstance(p[0], RobotBlock)]
    q_model = q[: model0.n_joints]
    for b, d, cs, s in robot:
        q_model = b.casadi_joint_values(q_model, d, cs, joint_names, s)
    (_, d_cpc, c_cpc, _) = next(p for p in robot if p[0].key == CPC_KEY)
    T_frames = cpc_fk_function(model0, symbolic_reference=True)(q_model, d_cpc, c_cpc)
    T_frames = T_frames if isinstance(T_frames, (list, tuple)) else [T_frames]
    frames = dict(zip(model0.topology.frames, T_frames, strict=True))
    for b, d, cs, _ in robot:
        frames = b.casadi_frame_poses(frames, d, cs)
    values = {
        b.key: b.casadi_value(d, cs) for b, d, cs, _ in parts if not isinstance(b, RobotBlock)
    }
    context = SymbolicContext(ca, frames, values, model_frame)
    out = []
    for g in groups:
        kind = kind_of(g)
        m_sym = ca.SX.sym("m", np.shape(kind.data(g))[1])
        r = kind.residual(g, context, m_sym)
        args = [q, m_sym, theta, const]
        J = ca.jacobian(r, theta)
        out.append(
            GroupFunctions(
                ca.Function("r", args, [r]),
                ca.Function("rj", args, [r, ca.densify(J.T)]),
                ca.Function("j", args, [J]),
                args,
                r,
            )
        )
    return tuple(out)


def _width(block: Block, topology: Any) -> int:
    """A block's per-sample inputs (robot blocks only)."""
    if not isinstance(block, RobotBlock):
        return 0
    return block.sample_width(tuple(topology.joint_names))


def group_functions(
    model0: CPCModel,
    blocks: tuple[Block, ...],
    groups: list[Any],
    model_frame: str | None,
    n_const: int,
) -> tuple[GroupFunctions, ...]:
    """:func:`build_functions`, cached by the problem's structure: every number
    (reference model, block starts) is an input, so problems of one structure (topology,
    blocks' types, keys and sizes, groups' keys) share them."""
    topo = model0.topology
    key = (
        (topo.joint_names, topo.revolute, topo.parent, topo.frames, topo.frame_parent),
        tuple(float(v) for v in model0.sign),
        model_frame,
        tuple(
            (type(b).__module__, type(b).__qualname__, b.key, b.size, _width(b, topo))
            for b in blocks
        ),
        tuple(kind_of(g).key(g) for g in groups),
    )
    with _FUNCTION_CACHE_LOCK:
        functions = _FUNCTION_CACHE.get(key)
        if functions is not None:
            _FUNCTION_CACHE.move_to_end(key)
    if functions is None:
        functions = build_functions(model0, blocks, groups, model_frame, n_const)
        with _FUNCTION_CACHE_LOCK:
            _FUNCTION_CACHE[key] = functions
            while len(_FUNCTION_CACHE) > _FUNCTION_CACHE_SIZE:
                _FUNCTION_CACHE.popitem(last=False)
    return functions
