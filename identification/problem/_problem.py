"""The least-squares problem's data: its unknowns, residual groups and parameter layout.

:class:`LeastSquaresProblem` holds the parameter blocks (the robot's
:class:`~kinfw.model.RobotBlock` s: CPC chart, base, zero offsets and any extra one; then
every unknown the observation kinds ask for), their start values and the
:class:`ResidualGroup` of each observation group, whose CasADi residual and exact
Jacobian are mapped over the samples. The built functions are unwhitened (SI):
:meth:`LeastSquaresProblem.evaluate` whitens each row in numpy by the sigma of its noise
component, so they do not depend on the noise.
:func:`~kinfw.identification.problem.build_problem` assembles it.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.identification.problem._functions import MAP_CHUNK, GroupFunctions
from kinfw.identification.problem._start import start_context
from kinfw.model import (
    CPC_KEY,
    Block,
    BlockKey,
    CPCModel,
    ModelSpec,
    ParameterName,
    PriorScales,
    RobotBlock,
    SpecBlock,
    prior_sigmas,
)
from kinfw.observations import NoiseComponent, ObservationKind, StartContext

PRIOR = NoiseComponent("prior", 1, "m")
"""The rows of a Gaussian prior (whitened by their own sigma, one row each)."""


@dataclass(frozen=True, slots=True)
class Unknown:
    """A rigid frame or point estimated besides the kinematics.

    Attributes
    ----------
    kind : str
        ``"target"`` (root_T_target), ``"frame"`` (meas_T_root of an external
        measurement frame), ``"marker"`` (frame_T_marker), ``"offset"`` (frame_p_point,
        3 numbers), or a new observation kind's own.
    name : str
        Target, measurement frame, marker or ``frame:marker`` name.
    value : ndarray
        The estimate: (4, 4) pose or (3,) point, metres.
    """

    kind: str
    name: str
    value: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ResidualGroup:
    """One observation group in the problem: its data and CasADi residual functions.

    Attributes
    ----------
    kind : ObservationKind
    group : object
        The observation group (e.g. :class:`~kinfw.measurements.PoseObservations`).
    qs : ndarray, shape (J + W, m)
        Joint values of its samples, model joint order, then the robot blocks' ``W``
        per-sample inputs (:meth:`kinfw.model.RobotBlock.sample_inputs`).
    data : ndarray, shape (width, m)
        Measured values, one column per observation.
    functions : GroupFunctions
        Shared (cached) by every problem of the same structure.
    const : ndarray
        This problem's numbers (reference CPC model, block starts), an input of the
        functions.
    """

    kind: ObservationKind
    group: Any
    qs: NDArray[np.float64]
    data: NDArray[np.float64]
    functions: GroupFunctions
    const: NDArray[np.float64]
    _maps: dict = field(default_factory=dict, repr=False)
    _q_rows: NDArray[np.float64] = field(init=False, repr=False)
    _data_rows: NDArray[np.float64] = field(init=False, repr=False)
    _last: dict = field(init=False, repr=False)
    _buffers: dict = field(init=False, repr=False)

    def __post_init__(self) -> None:
        # column-major (J, m) and (k, m) inputs, as C-contiguous (m, J) and (m, k) buffers
        object.__setattr__(self, "_q_rows", np.ascontiguousarray(self.qs.T, dtype=float))
        object.__setattr__(self, "_data_rows", np.ascontiguousarray(self.data.T, dtype=float))
        object.__setattr__(self, "const", np.ascontiguousarray(self.const, dtype=float))
        # the last evaluation (see evaluate) and the CasADi call buffers by (with_jacobian,
        # free, chunk size); not shared by dataclasses.replace copies
        object.__setattr__(self, "_last", {})
        object.__setattr__(self, "_buffers", {})

    @property
    def sample(self) -> NDArray[np.int64]:
        return self.group.sample

    @property
    def rows(self) -> int:
        """Residual rows per observation."""
        return self.kind.rows

    @property
    def components(self) -> tuple[NoiseComponent, ...]:
        return self.kind.components

    @property
    def frame(self) -> str:
        return self.kind.frames(self.group)[0]

    @property
    def marker(self) -> str | None:
        return getattr(self.group, "marker", None)

    def row_sigma(self, noise: Any) -> NDArray[np.float64]:
        """Per residual row of one observation, its noise sigma (SI)."""
        return np.concatenate([np.full(c.rows, noise.sigma(c)) for c in self.components])

    def _mapped(self, which: str):
        """CasADi's own ``r`` or ``j`` (numeric or symbolic arguments) mapped over the
        samples."""
        if which not in self._maps:
            f = getattr(self.functions, which)
            self._maps[which] = f.map(f"{which}_map", "serial", len(self.sample), [2, 3], [])
        return self._maps[which]

    @property
    def residual(self):
        """Unwhitened residuals ``(q (J, m), data (width, m), x) -> (rows, m)`` (CasADi;
        numeric or symbolic arguments)."""
        f = self._mapped("r")
        return lambda qs, data, x: f(qs, data, x, self.const)

    @property
    def jacobian(self):
        """Their Jacobian ``(q, data, x) -> (rows, m * P)`` (CasADi)."""
        f = self._mapped("j")
        return lambda qs, data, x: f(qs, data, x, self.const)

    def evaluate(
        self, x: NDArray, with_jacobian: bool, free: NDArray[np.bool_] | None = None
    ) -> tuple[NDArray, NDArray | None]:
        """Unwhitened residuals ``(m * rows,)`` (observation-major) and Jacobian
        ``(m * rows, P)``, or only its ``free`` columns ``(m * rows, n_free)``, written by
        the compiled CasADi functions (:meth:`GroupFunctions.numeric_map`) straight into
        numpy arrays.

        The last evaluation is kept: asking again at the same ``x`` (the end of one
        noise round and the start of the next, the quality at the estimate) returns the
        same arrays, which callers must not modify.
        """
        x = np.ascontiguousarray(x, dtype=float)
        free_key = None if free is None else free.tobytes()
        key = (x.tobytes(), free_key)
        last = self._last.get(key)
        if last is not None and (last[1] is not None or not with_jacobian):
            return last[0], (last[1] if with_jacobian else None)
        m, rows = len(self.sample), self.rows
        r = np.empty(m * rows)
        n_cols = len(x) if free is None else int(free.sum())
        J = np.empty((m * rows, n_cols)) if with_jacobian else None
        for a, b in chunks(m):
            J_chunk = None if J is None else J[a * rows : b * rows]
            self._call(a, b, x, free, r[a * rows : b * rows], J_chunk)
        self._last.clear()
        self._last[key] = (r, J)
        return r, J

    def _call(
        self,
        a: int,
        b: int,
        x: NDArray,
        free: NDArray[np.bool_] | None,
        r_out: NDArray,
        J_out: NDArray | None,
    ) -> None:
        """Samples ``a:b``'s residuals into ``r_out`` and, unless None, the Jacobian's
        ``free`` columns (None: all) into ``J_out`` (contiguous), by the compiled map of
        that chunk size (its CasADi call buffer kept)."""
        size_key = (J_out is not None, None if free is None else free.tobytes(), b - a)
        if size_key not in self._buffers:
            fn = self.functions.numeric_map(J_out is not None, free, b - a, len(self.sample))
            self._buffers[size_key] = fn.buffer()
        buf, call = self._buffers[size_key]
        args = (self._q_rows[a:b], self._data_rows[a:b], x, self.const)
        for i, arg in enumerate(args):
            buf.set_arg(i, memoryview(arg))
        buf.set_res(0, memoryview(r_out))
        if J_out is not None:
            buf.set_res(1, memoryview(J_out))
        call()

    def jacobian_blocks(
        self, x: NDArray, free: NDArray[np.bool_]
    ) -> Iterator[tuple[int, int, NDArray, NDArray]]:
        """The residuals and the ``free`` columns of the Jacobian at ``x``, a chunk of
        samples at a time (:func:`chunks`): ``(first, end, r, J)`` with ``r`` the chunk's
        unwhitened residuals ``((end - first) * rows,)`` and ``J`` its Jacobian rows
        ``((end - first) * rows, n_free)``, without forming the whole Jacobian (for the
        normal equations of many samples: no array of its size, no page faults).

        ``J`` is a buffer the next chunk overwrites (the caller may modify it); ``r`` is
        part of the whole residual vector, kept at the end as the last evaluation (see
        :meth:`evaluate`), which callers must not modify.
        """
        x = np.ascontiguousarray(x, dtype=float)
        m, rows = len(self.sample), self.rows
        r = np.empty(m * rows)
        J = np.empty((min(m, MAP_CHUNK) * rows, int(free.sum())))  # the first is the largest
        for a, b in chunks(m):
            r_chunk, J_chunk = r[a * rows : b * rows], J[: (b - a) * rows]
            self._call(a, b, x, free, r_chunk, J_chunk)
            yield a, b, r_chunk, J_chunk
        self._last.clear()
        self._last[(x.tobytes(), free.tobytes())] = (r, None)


def chunks(m: int) -> list[tuple[int, int]]:
    """The ``(first, end)`` samples of the calls of a mapped function over ``m`` samples:
    chunks of :data:`MAP_CHUNK`, then the rest in powers of two (largest first), so that
    any ``m`` (a refit without a few observations, a cross-validation fold) uses maps of
    a few sizes, built once (a map of 2,048 samples takes ~10 ms to build)."""
    out, a = [], 0
    size = MAP_CHUNK
    while a < m:
        while size > m - a:
            size //= 2
        out.append((a, a + size))
        a += size
    return out


@dataclass(frozen=True, slots=True)
class NormalEquations:
    """The normal equations of :meth:`LeastSquaresProblem.normal_equations`.

    Attributes
    ----------
    G : ndarray, shape (p, p)
        ``A^T A`` of the scaled whitened Jacobian's columns ``A``.
    g : ndarray, shape (p,)
        ``A^T b`` of the scaled whitened residuals ``b``.
    by_component : dict of str to ndarray, shape (p, p)
        ``A_c^T A_c`` over the rows of each noise component (by name) of the groups
        (empty unless asked for).
    b : ndarray, shape (N,)
        The scaled whitened residuals.
    """

    G: NDArray[np.float64]
    g: NDArray[np.float64]
    by_component: dict[str, NDArray[np.float64]]
    b: NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class LeastSquaresProblem:
    """The assembled problem: parameter blocks, their start values, the residual groups.

    ``x`` below is the vector of chart coordinates from the start (rad, m): the blocks'
    entries one after the other, in the order of :attr:`names`; only the :attr:`free`
    entries are estimated.

    Attributes
    ----------
    model0 : CPCModel
        The start model (end frames: every observed frame) in the model frame.
    model_frame : str or None
        None for the URDF root, else the one external measurement frame.
    blocks : tuple of Block
        The robot's (:attr:`robot_blocks`: the CPC chart, base, zero offsets and any
        extra one), then the unknowns (:attr:`unknown_blocks`); found by role and key
        (:meth:`block`), never by position.
    groups : tuple of ResidualGroup
    prior_mean, prior_sigma : ndarray, shape (P,)
        Gaussian prior on ``x`` (sigma inf: none).
    fitted : tuple of (BlockKey, str)
        The unknowns whose start was estimated from these data, with a description.
    start_qs : ndarray, shape (n, J)
        The samples' joint values (model joint order) after the robot blocks' hooks at
        their starts (the readings themselves without a model spec): what the start
        values were estimated at (:meth:`start_context`).
    prior_groups : tuple of (str or None, str)
        Every parameter's prior group and unit
        (:func:`~kinfw.identification.problem.prior_groups`): what :meth:`with_prior`
        sets the sigmas by.
    """

    model0: CPCModel
    model_frame: str | None
    blocks: tuple[Block, ...]
    groups: tuple[ResidualGroup, ...]
    prior_mean: NDArray[np.float64]
    prior_sigma: NDArray[np.float64]
    fitted: tuple[tuple[BlockKey, str], ...] = ()
    start_qs: NDArray[np.float64] | None = None
    prior_groups: tuple[tuple[str | None, str], ...] = ()

    def with_prior(self, prior: PriorScales | None) -> LeastSquaresProblem:
        """This problem under the prior ``prior`` (its sigmas by group; the same mean):
        the same functions and data, so a fit warm-starts from another prior's."""
        return replace(self, prior_sigma=prior_sigmas(self.prior_groups, prior))

    @property
    def slices(self) -> tuple[slice, ...]:
        """The slice of ``x`` of each block."""
        out, k = [], 0
        for b in self.blocks:
            out.append(slice(k, k + b.size))
            k += b.size
        return tuple(out)

    def block(self, key: BlockKey) -> tuple[Block, slice]:
        """A block and its slice of ``x`` by key (KeyError if absent)."""
        for b, s in zip(self.blocks, self.slices, strict=True):
            if b.key == key:
                return b, s
        raise KeyError(key)

    @property
    def robot_blocks(self) -> tuple[RobotBlock, ...]:
        """The robot's blocks (:class:`~kinfw.model.RobotBlock`), in the problem's order."""
        return tuple(b for b in self.blocks if isinstance(b, RobotBlock))

    @property
    def unknown_blocks(self) -> tuple[Block, ...]:
        """The blocks besides the robot's (targets, frames, markers, offsets...)."""
        return tuple(b for b in self.blocks if not isinstance(b, RobotBlock))

    @property
    def names(self) -> tuple[ParameterName, ...]:
        return tuple(n for b in self.blocks for n in b.names)

    @property
    def units(self) -> tuple[str, ...]:
        """SI unit of each parameter (``"rad"``, ``"m"``, ``"unitless"``...), from its
        block (:attr:`kinfw.model.Block.units`)."""
        return tuple(u for b in self.blocks for u in b.units)

    @property
    def free(self) -> NDArray[np.bool_]:
        return np.concatenate([b.free for b in self.blocks])

    @property
    def prior_rows(self) -> NDArray[np.int64]:
        """Parameters with a prior (free, finite sigma): one residual row each."""
        return np.flatnonzero(self.free & np.isfinite(self.prior_sigma))

    @property
    def n_parameters(self) -> int:
        return sum(b.size for b in self.blocks)

    @property
    def obs_sizes(self) -> list[tuple[int, int]]:
        """(observations, rows per observation) of each group, then one row per prior."""
        sizes = [(len(g.sample), g.rows) for g in self.groups]
        return sizes + ([(len(self.prior_rows), 1)] if len(self.prior_rows) else [])

    @property
    def obs_components(self) -> list[tuple[int, tuple[NoiseComponent, ...]]]:
        """(observations, noise components) of each group, then the prior's rows (one
        Gaussian row each): what :func:`kinfw.identification.problem.thresholds` needs."""
        out = [(len(g.sample), g.components) for g in self.groups]
        return out + ([(len(self.prior_rows), (PRIOR,))] if len(self.prior_rows) else [])

    def raw_residuals(
        self, x: NDArray, with_jacobian: bool = True
    ) -> list[tuple[NDArray, NDArray | None]]:
        """Per group the unwhitened residuals (m, rows) and Jacobian (m, rows, P) at x."""
        out = []
        for g in self.groups:
            r, J = g.evaluate(x, with_jacobian)
            m = len(g.sample)
            out.append((r.reshape(m, g.rows), None if J is None else J.reshape(m, g.rows, len(x))))
        return out

    def evaluate(
        self, x: NDArray, noise: Any, with_jacobian: bool = True, *, only_free: bool = False
    ) -> tuple[NDArray, NDArray | None]:
        """Whitened residuals (N,) and their Jacobian (N, P) at ``x``.

        Rows are observation by observation (each observation's rows together), group
        by group, then one row per prior entry; each row divided by its component's
        sigma in ``noise`` (:class:`kinfw.identification.problem.NoiseModel`). With
        ``only_free`` the columns of the fixed parameters are left at zero (not
        computed: what the fit needs, cheaper for the small parameter sets).
        """
        free = self.free
        if not only_free:
            return self._whitened(x, noise, with_jacobian, None)
        r, J_free = self._whitened(x, noise, with_jacobian, free)
        if J_free is None:
            return r, None
        J = np.zeros((len(r), self.n_parameters))
        J[:, free] = J_free
        return r, J

    def evaluate_free(
        self, x: NDArray, noise: Any, with_jacobian: bool = True
    ) -> tuple[NDArray, NDArray | None]:
        """Whitened residuals (N,) and the free columns of their Jacobian
        ``(N, n_free)`` at ``x``: :meth:`evaluate` with ``only_free`` without the fixed
        parameters' zero columns (what the solver works on)."""
        return self._whitened(x, noise, with_jacobian, self.free)

    def _whitened(
        self, x: NDArray, noise: Any, with_jacobian: bool, columns: NDArray[np.bool_] | None
    ) -> tuple[NDArray, NDArray | None]:
        """Whitened residuals and the Jacobian's ``columns`` (a mask; None: all)."""
        x = np.asarray(x, dtype=float)
        n_cols = self.n_parameters if columns is None else int(columns.sum())
        k = self.prior_rows
        n_rows = sum(len(g.sample) * g.rows for g in self.groups)
        r_out = np.empty(n_rows + len(k))
        J_out = np.empty((len(r_out), n_cols)) if with_jacobian else None
        if J_out is not None:
            J_out[n_rows:] = 0.0  # the prior's rows: one entry each, set below
        a = 0
        for g in self.groups:
            r, J = g.evaluate(x, with_jacobian and n_cols > 0, columns)
            inv = np.tile(1.0 / g.row_sigma(noise), len(g.sample))
            b = a + len(r)
            np.multiply(r, inv, out=r_out[a:b])
            if J is not None and J_out is not None:
                np.multiply(J, inv[:, None], out=J_out[a:b])
            a = b
        if len(k):  # Gaussian prior: (x - mean) / sigma
            r_out[a:] = (x[k] - self.prior_mean[k]) / self.prior_sigma[k]
            if J_out is not None:
                # the prior's parameters are free: their columns among ``columns``
                cols = k if columns is None else np.searchsorted(np.flatnonzero(columns), k)
                J_out[a + np.arange(len(k)), cols] = 1.0 / self.prior_sigma[k]
        return r_out, J_out

    def normal_equations(
        self, x: NDArray, noise: Any, row_scale: NDArray, *, by_component: bool = False
    ) -> NormalEquations:
        """The normal equations of the whitened residuals at ``x`` over the free
        parameters, each row scaled by ``row_scale`` (e.g. the square roots of the robust
        weights), without forming the whitened Jacobian.

        With ``A`` the free columns of the whitened Jacobian (:meth:`evaluate_free`) and
        ``r`` the whitened residuals, both scaled row by row:
        ``A^T A``, ``A^T r`` and, with ``by_component``, per noise component of the
        groups ``A_c^T A_c`` over its rows (the prior's rows belong to none; what
        :func:`~kinfw.identification.problem.leverage_sums` takes; else the
        ``by_component`` of the result is empty), accumulated chunk by chunk of each
        group's samples (:meth:`ResidualGroup.jacobian_blocks`: no array of the whole
        Jacobian's size; the residuals kept for the next call at the same ``x``).

        Parameters
        ----------
        x : ndarray, shape (P,)
        noise : NoiseModel
        row_scale : ndarray, shape (N,)
            One per row of :meth:`evaluate`'s residuals.
        """
        x = np.asarray(x, dtype=float)
        columns = self.free
        n_cols = int(columns.sum())
        G, g = np.zeros((n_cols, n_cols)), np.zeros(n_cols)
        grams: dict[str, NDArray] = {}
        r_out = np.empty(len(row_scale))
        a = 0
        for grp in self.groups:
            m, rows = len(grp.sample), grp.rows
            scale = np.tile(1.0 / grp.row_sigma(noise), min(m, MAP_CHUNK))
            for first, end, r, A in grp.jacobian_blocks(x, columns):
                rs = slice(first * rows, end * rows)
                s = scale[: rs.stop - rs.start] * row_scale[a + rs.start : a + rs.stop]
                A *= s[:, None]  # the chunk's buffer: whitened and scaled in place
                b = r * s
                g += A.T @ b
                r_out[a + rs.start : a + rs.stop] = b
                if not by_component:
                    G += A.T @ A
                    continue
                A3, c0 = A.reshape(len(b) // rows, rows, n_cols), 0
                for c in grp.components:
                    Ac = A3[:, c0 : c0 + c.rows].reshape(len(A3) * c.rows, n_cols)
                    Gc = grams.setdefault(c.name, np.zeros((n_cols, n_cols)))
                    Gc += Ac.T @ Ac
                    c0 += c.rows
            a += m * rows
        for Gc in grams.values():
            G += Gc
        k = self.prior_rows
        if len(k):  # one row each: (x - mean) / sigma, its one entry 1 / sigma
            s = row_scale[a:] / self.prior_sigma[k]
            cols = np.searchsorted(np.flatnonzero(columns), k)
            G[cols, cols] += s**2
            g[cols] += s * s * (x[k] - self.prior_mean[k])
            r_out[a:] = s * (x[k] - self.prior_mean[k])
        return NormalEquations(G, g, grams, r_out)

    def casadi_residual(self, noise: Any):
        """``(x, r)``: a CasADi MX symbol for the free entries of ``x`` and the whitened
        residual vector as an MX expression of it (data embedded), for CasADi solvers."""
        import casadi as ca

        x_free = ca.MX.sym("x", int(self.free.sum()))
        x = self.full_x(x_free)
        parts = []
        for g in self.groups:
            sig = np.tile(g.row_sigma(noise)[:, None], (1, len(g.sample)))
            parts.append(ca.vec(g.residual(ca.DM(g.qs), ca.DM(g.data), x) / ca.DM(sig)))
        return x_free, ca.vertcat(*parts)

    def full_x(self, x_free):
        """The whole chart vector (CasADi MX) from its free entries, fixed ones at zero."""
        import casadi as ca

        parts, k = [], 0
        for f in self.free:
            if f:
                parts.append(x_free[k])
                k += 1
            else:
                parts.append(ca.MX(0.0))
        return ca.vertcat(*parts)

    def model_at(self, x: NDArray) -> CPCModel:
        """The kinematics at ``x``: the CPC block's model with every other robot block
        folded in (:meth:`kinfw.model.RobotBlock.moved_model`: the base transform and the
        joint zero offsets; a block no CPC model holds, such as a gear scale, stands
        beside it)."""
        cpc, s_cpc = self.block(CPC_KEY)
        model = cpc.numpy_value(x[s_cpc])
        for b, s in zip(self.blocks, self.slices, strict=True):
            if isinstance(b, RobotBlock) and b.key != CPC_KEY:
                model = b.moved_model(model, x[s])
        return model

    def spec_at(self, x: NDArray) -> ModelSpec:
        """The model spec's blocks (:class:`kinfw.model.SpecBlock`) at ``x``, each started
        at its value there: what stands beside :meth:`model_at`'s model."""
        return ModelSpec(
            tuple(
                b.with_start(b.numpy_value(x[s]))
                for b, s in zip(self.blocks, self.slices, strict=True)
                if isinstance(b, SpecBlock)
            )
        )

    def base_motion_at(self, x: NDArray) -> NDArray[np.float64] | None:
        """The base's estimate at ``x``: the rigid motion ``w_T_base`` of the whole
        nominal robot in the model frame (:class:`kinfw.model.BaseBlock`), or None when
        the parameter set left the base fixed (``"full"``: the chart's first joints carry
        it)."""
        for b, s in zip(self.blocks, self.slices, strict=True):
            if b.key == BlockKey("base") and b.free.any():
                return b.numpy_value(x[s])
        return None

    def start_context(self) -> StartContext:
        """The start model's poses at the problem's samples (at :attr:`start_qs`, the
        joint values after the robot blocks' hooks) and the external frames' starts,
        for the kinds' estimators."""
        meas_T_w = {b.key.name: b.start for b in self.unknown_blocks if b.key.kind == "frame"}
        return start_context(self.model0, self.start_qs, meas_T_w, self.model_frame)

    def with_starts(self, group: ResidualGroup, blocks: Sequence[Block]) -> ResidualGroup:
        """``group`` evaluated with other start values for some of the problem's unknown
        blocks (same keys; e.g. each group's own closed-form fit): the functions take the
        starts as inputs, so nothing is rebuilt."""
        const = group.const.copy()
        offsets, c = {}, 0
        for b in self.blocks:
            n = len(b.constants())
            offsets[b.key] = slice(c, c + n)
            c += n
        for b in blocks:
            const[offsets[b.key]] = b.constants()
        return replace(group, const=const)

    def unknowns_at(self, x: NDArray) -> tuple[Unknown, ...]:
        """Every unknown block's value at ``x`` (targets, frames, markers, offsets...)."""
        return tuple(
            Unknown(b.key.kind, b.key.name, b.numpy_value(x[s]))
            for b, s in zip(self.blocks, self.slices, strict=True)
            if not isinstance(b, RobotBlock)
        )
