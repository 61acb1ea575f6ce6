"""Joint nonlinear least squares over every unknown at once (CasADi + Levenberg-Marquardt).

One problem holds the identifiable CPC parameters of the whole tree (the chart of
:meth:`kinfw.cpc.CPCModel.perturbed`), each target's pose, the pose of the root in every
external measurement frame, every marker's pose and every unknown point offset, and uses
every ``pose``, ``target`` and ``point`` observation together. It is the nonlinear
identification the paper sets aside (Shih et al. eq. 23), started from the closed form
and the hand-eye solution (or from the nominal URDF).

Residuals are whitened by the measurement noise: ``(measured - predicted) / sigma_p`` for
positions and ``0.5 vee(R_meas^T R_pred - R_pred^T R_meas) / sigma_r`` for orientations
(the sine of the error angle about its axis: smooth at zero error, unlike a log). With
``sigma`` not given they are estimated from the residuals (variance components: each
kind's sum of squares over its share of the degrees of freedom, iterated).

CasADi builds each observation group's residual and its exact Jacobian from the CPC model
(:func:`kinfw.cpc_casadi.cpc_fk_function`) and maps them over the samples. The graphs take
every number (reference model, start frames, offsets) as an input, so they depend only on
the problem's structure and are cached by it: cross-validation folds, parameter sets and
Monte Carlo trials build them once. They are evaluated straight into numpy buffers, the
fit's Jacobian only for the estimated columns. The solver is
Levenberg-Marquardt on those functions (numpy), with an optional Huber or Cauchy loss by
iteratively reweighted least squares. Directions of the parameter space the data does not
determine are left at the start (minimum-norm steps) and reported.

Gauge. The CPC chart is minimal for poses of end frames in the measurement frame. Two
more redundancies are fixed here: when every observation is in one external frame
(``measured_in``), the model is expressed in that frame (the root's pose in it comes from
the export's registration, not from a separate unknown); and an end frame observed only
through markers or points of unknown offset keeps its nominal tool transform (the markers
carry the freedom).
"""

from __future__ import annotations

import functools
import logging
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from kinfw.cpc import CPCModel, cpc_from_robot
from kinfw.cpc_casadi import cpc_fk_function, cpc_reference_vector
from kinfw.measurements import DatasetError, Measurements, check_against_robot
from kinfw.robot import Robot, Topology
from kinfw.transforms import (
    average_transform,
    inverse_transform,
    transform_from_rotation_translation,
)

__all__ = [
    "Identifiability",
    "LeastSquaresProblem",
    "NoiseModel",
    "RefineResult",
    "Unknown",
    "build_problem",
    "clear_function_cache",
    "information_matrix",
    "parameter_unit",
    "refine",
]

log = logging.getLogger(__name__)

LOSSES = ("linear", "huber", "cauchy")

#: Fields whose values are angles (rad): chart tilts and rotations, CPC beta, URDF rpy.
_ANGLE_FIELDS = frozenset({"b_tilt_1", "b_tilt_2", "rot_x", "rot_y", "rot_z", "beta", "roll",
                           "pitch", "yaw"})
#: Fields whose values are lengths (m): CPC l, frame and point translations.
_LENGTH_FIELDS = frozenset({"l_x", "l_y", "l_z", "x", "y", "z"})
#: Fields without a unit: components of the CPC unit axis b, the motion sense.
_UNITLESS_FIELDS = frozenset({"b_x", "b_y", "b_z", "sign"})


def parameter_unit(owner: str, field: str, topology: Topology) -> str:
    """SI unit of a parameter or kinematic quantity named ``(owner, field)``.

    Covers the names of :attr:`RefineResult.parameter_names` (the CPC chart of
    :attr:`kinfw.cpc.CPCModel.parameter_names`, ``("base", ...)``, ``(joint,
    "zero_offset")``, ``("target:name", ...)``, ``("frame:name", ...)``,
    ``("marker:name", ...)``, ``("offset:frame:point", ...)``) and the rows of
    :meth:`kinfw.cpc.CPCModel.describe`.

    Parameters
    ----------
    owner, field : str
        The parameter's name, e.g. ``("pan", "zero_offset")`` or ``("left_plate", "x")``.
    topology : Topology
        Joint names and types (``model.topology``): a revolute joint's ``zero_offset``
        is an angle, a prismatic joint's a length.

    Returns
    -------
    str
        ``"rad"``, ``"m"`` or ``"unitless"``.

    Raises
    ------
    ValueError
        For a field this function does not know, or the ``zero_offset`` of a name that
        is not a joint of ``topology``.
    """
    if field in _ANGLE_FIELDS:
        return "rad"
    if field in _LENGTH_FIELDS:
        return "m"
    if field in _UNITLESS_FIELDS:
        return "unitless"
    if field == "zero_offset":
        if owner not in topology.joint_names:
            raise ValueError(f"parameter ({owner!r}, 'zero_offset'): {owner!r} is not a joint "
                             f"of the model; expected one of {list(topology.joint_names)}")
        return "rad" if topology.revolute[topology.joint_names.index(owner)] else "m"
    raise ValueError(f"parameter ({owner!r}, {field!r}): unknown field; expected an angle "
                     f"{sorted(_ANGLE_FIELDS)}, a length {sorted(_LENGTH_FIELDS)}, unitless "
                     f"{sorted(_UNITLESS_FIELDS)} or 'zero_offset'")


@dataclass(frozen=True, slots=True)
class NoiseModel:
    """Measurement noise used to whiten the residuals.

    Attributes
    ----------
    position_m : float
        Standard deviation of each position component, metres.
    rotation_rad : float
        Standard deviation of each orientation component (small-angle), radians.
    estimated : bool
        True when estimated from the residuals rather than given.

    Notes
    -----
    The robust estimate (``loss`` huber or cauchy) assumes the noise of Shih et al.
    (1992, Fig. 10), as :func:`verification.simulate.perturb_poses` draws it: each
    position component ``N(0, position_m)``; an orientation error is a rotation by an
    angle ``N(0, sqrt(3) rotation_rad)`` about a uniformly random axis, whose three
    components have deviation ``rotation_rad`` each without being Gaussian. It is
    consistent for that model (and within 1 % for Gaussian orientation components); see
    ``_estimate_noise``. Least squares' estimate assumes only the variances.
    """

    position_m: float
    rotation_rad: float
    estimated: bool = False


@dataclass(frozen=True, slots=True)
class Unknown:
    """A rigid frame or point estimated besides the kinematics.

    Attributes
    ----------
    kind : str
        ``"target"`` (root_T_target), ``"frame"`` (meas_T_root of an external
        measurement frame), ``"marker"`` (frame_T_marker) or ``"offset"``
        (frame_p_point, 3 numbers).
    name : str
        Target, measurement frame, marker or ``frame:marker`` name.
    value : ndarray
        The estimate: (4, 4) pose or (3,) point, metres.
    """

    kind: str
    name: str
    value: NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class Identifiability:
    """What the data determines, from the SVD of the whitened, column-scaled Jacobian.

    Attributes
    ----------
    rank, n_parameters : int
        Identifiable directions, and free parameters (both 0 with ``parameters="none"``
        and nothing else to estimate).
    condition : float
        Largest over smallest singular value among the identifiable directions; inf when
        no direction is identifiable, nan (undefined) when there is no free parameter.
    observability_o1 : float
        Borm & Menq's O1: geometric mean of the singular values over sqrt(rows); 0 when
        a direction is not identifiable, nan (undefined) when there is no free parameter.
    unidentifiable : tuple of (tuple of (owner, field), str)
        Per null direction, the parameters involved and why they are not determined.
    correlations : tuple of (str, str, float)
        Parameter pairs with |rho| > 0.9.
    """

    rank: int
    n_parameters: int
    condition: float
    observability_o1: float
    unidentifiable: tuple[tuple[tuple[tuple[str, str], ...], str], ...]
    correlations: tuple[tuple[str, str, float], ...]


@dataclass(frozen=True, slots=True)
class GroupResiduals:
    """Residuals of one observation group after the fit (measured minus predicted).

    Attributes
    ----------
    kind, frame : str
    marker : str or None
    sample : ndarray of int, shape (m,)
    position_m : ndarray, shape (m, 3)
    rotation_rad : ndarray, shape (m, 3) or None
        Small-angle orientation error (sine of the angle about its axis), None for points.
    weight : ndarray, shape (m,)
        Robust-loss weight of each observation (1 = full weight).
    downweighted : ndarray of bool, shape (m,)
        Observations beyond the robust loss's threshold (all False for least squares).
    """

    kind: str
    frame: str
    marker: str | None
    sample: NDArray[np.int64]
    position_m: NDArray[np.float64]
    rotation_rad: NDArray[np.float64] | None
    weight: NDArray[np.float64]
    downweighted: NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class RefineResult:
    """The joint least-squares estimate and its quality.

    Attributes
    ----------
    model : CPCModel
        Refined kinematics (end frames: every observed frame), in the model frame
        ``w``: the URDF root, or the one external measurement frame when every
        observation is in it (:attr:`model_frame`).
    model_frame : str or None
        None for the URDF root, else the external measurement frame's name.
    unknowns : tuple of Unknown
        Target poses, external frames, markers, point offsets.
    parameter_names : tuple of (owner, field)
        Every parameter of the problem, in the order of ``estimate`` and ``covariance``;
        units from :func:`parameter_unit`.
    free : ndarray of bool, shape (P,)
        The parameters estimated; the others are fixed at the start (``estimate`` 0,
        ``std`` 0), e.g. the base and the joint zero offsets with ``parameters="full"``.
    estimate : ndarray, shape (P,)
        Chart coordinates from the start (rad, m).
    covariance : ndarray, shape (P, P)
        ``sigma_hat^2 (J^T J)^+`` in SI units, on the identifiable subspace.
    noise : NoiseModel
        The whitening used (given or estimated).
    sigma_hat2 : float
        Reduced chi-square of the whitened residuals (1 when the noise model fits).
    residuals : tuple of GroupResiduals
    downweighted : tuple of (kind, frame, sample, weight)
        Observations beyond the robust loss's threshold (empty for least squares), with
        the weight they got.
    identifiability : Identifiability
    iterations : int
    converged : bool
    cost : float
        Half the sum of squared whitened residuals (after robust weights).
    seconds : float
    """

    model: CPCModel
    model_frame: str | None
    unknowns: tuple[Unknown, ...]
    parameter_names: tuple[tuple[str, str], ...]
    free: NDArray[np.bool_]
    estimate: NDArray[np.float64]
    covariance: NDArray[np.float64]
    noise: NoiseModel
    sigma_hat2: float
    residuals: tuple[GroupResiduals, ...]
    downweighted: tuple[tuple[str, str, int, float], ...]
    identifiability: Identifiability
    iterations: int
    converged: bool
    cost: float
    seconds: float = field(default=0.0)

    @property
    def std(self) -> NDArray[np.float64]:
        """Standard deviation of each parameter (rad, m)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))


# -- CasADi pieces ---------------------------------------------------------------------
def _ca():
    import casadi

    return casadi


def _cayley_pose(ca, T0, d):
    """``T0 @ [cayley(d[:3]/2), d[3:]]`` as a CasADi 4x4 (chart of a rigid frame); ``T0``
    a (4, 4) array or a symbolic ``(R, p)`` pair."""
    a = 0.5 * d[0:3]
    K = ca.vertcat(ca.horzcat(0, -a[2], a[1]), ca.horzcat(a[2], 0, -a[0]),
                   ca.horzcat(-a[1], a[0], 0))
    dR = ca.DM.eye(3) + (2.0 / (1.0 + ca.dot(a, a))) * (K + K @ K)
    R0, p0 = (ca.DM(T0[:3, :3]), ca.DM(T0[:3, 3])) if isinstance(T0, np.ndarray) else T0
    R = R0 @ dR
    p = p0 + d[3:6]
    return ca.vertcat(ca.horzcat(R, p), ca.horzcat(0, 0, 0, 1))


def _cayley_pose_np(T0: NDArray, d: NDArray) -> NDArray:
    from kinfw.cpc import _cayley

    return transform_from_rotation_translation(T0[:3, :3] @ _cayley(0.5 * d[:3]),
                                               T0[:3, 3] + d[3:6])


def _inverse_ca(ca, T):
    R = T[0:3, 0:3]
    return ca.vertcat(ca.horzcat(R.T, -R.T @ T[0:3, 3]), ca.horzcat(0, 0, 0, 1))


def _pose_residual(ca, T_pred, T_meas_vec, sigma_p, sigma_r):
    """Whitened (position, orientation) residual of a predicted vs measured pose.

    ``T_meas_vec`` is the measured pose as 12 numbers (R column-major, then p).
    """
    Rm = ca.reshape(T_meas_vec[0:9], 3, 3)
    pm = T_meas_vec[9:12]
    Rp = T_pred[0:3, 0:3]
    E = Rp.T @ Rm - Rm.T @ Rp  # 2 sin(theta) [u]x in the predicted frame
    vee = 0.5 * ca.vertcat(E[2, 1], E[0, 2], E[1, 0])
    return ca.vertcat((pm - T_pred[0:3, 3]) / sigma_p, vee / sigma_r)


def _pose_vectors(T: NDArray) -> NDArray:
    """(m, 4, 4) poses as a (12, m) matrix: rotation column-major, then position."""
    return np.concatenate([np.swapaxes(T[:, :3, :3], 1, 2).reshape(len(T), 9),
                           T[:, :3, 3]], axis=1).T


# -- problem assembly --------------------------------------------------------------------
@dataclass
class _Group:
    """One observation group: its samples, data and compiled residual functions.

    ``functions`` are per-observation CasADi functions of ``(q, m, theta, sigma_p,
    sigma_r, const)`` shared (cached) by every problem of the same structure; ``const``
    holds this problem's numbers (reference CPC model, start frames, offsets).
    """

    kind: str
    frame: str
    marker: str | None
    sample: NDArray[np.int64]
    data: NDArray[np.float64]  # (12, m) or (3, m)
    qs: NDArray[np.float64]  # (J, m)
    functions: _GroupFunctions
    const: NDArray[np.float64]
    rows: int = 6
    _maps: dict = field(default_factory=dict, repr=False)

    def _mapped(self, which: str, free: NDArray[np.bool_] | None = None):
        """``which`` ("r", "rj" or "j"; "rj" restricted to the ``free`` columns when given)
        mapped over the samples, the per-problem inputs ``theta, sigma_p, sigma_r, const``
        shared by every sample."""
        key = (which, None if free is None else free.tobytes())
        if key not in self._maps:
            f = getattr(self.functions, which) if free is None else \
                self.functions.rj_free(free)
            self._maps[key] = f.map(f"{which}_map", "serial", len(self.sample),
                                    [2, 3, 4, 5], [])
        return self._maps[key]

    @property
    def residual(self):
        """Whitened residuals ``(q (J, m), data, x, sigma_p, sigma_r) -> (rows, m)``
        (CasADi; numeric or symbolic arguments)."""
        f = self._mapped("r")
        return lambda qs, data, x, sp, sr: f(qs, data, x, sp, sr, self.const)

    @property
    def jacobian(self):
        """Their Jacobian ``(q, data, x, sigma_p, sigma_r) -> (rows, m * P)`` (CasADi)."""
        f = self._mapped("j")
        return lambda qs, data, x, sp, sr: f(qs, data, x, sp, sr, self.const)

    def evaluate(self, x: NDArray, sigma: NoiseModel, with_jacobian: bool,
                 free: NDArray[np.bool_] | None = None) -> tuple[NDArray, NDArray | None]:
        """Residuals ``(m * rows,)`` (observation-major) and Jacobian ``(m * rows, P)``,
        or only its ``free`` columns ``(m * rows, n_free)``, written by CasADi straight
        into numpy arrays (no DM conversion)."""
        m = len(self.sample)
        n_cols = len(x) if free is None else int(free.sum())
        fn = self._mapped("rj", free) if with_jacobian else self._mapped("r")
        buf, call = fn.buffer()
        args = (self._q_rows, self._data_rows, np.ascontiguousarray(x, dtype=float),
                np.array([sigma.position_m], float), np.array([sigma.rotation_rad], float),
                self.const)
        for i, a in enumerate(args):
            buf.set_arg(i, memoryview(a))
        r = np.empty(m * self.rows)
        buf.set_res(0, memoryview(r))
        J = np.empty((m * self.rows, n_cols)) if with_jacobian else None
        if J is not None:
            buf.set_res(1, memoryview(J))
        call()
        return r, J

    def __post_init__(self):
        # column-major (J, m) and (k, m) inputs, as C-contiguous (m, J) and (m, k) buffers
        self._q_rows = np.ascontiguousarray(self.qs.T, dtype=float)
        self._data_rows = np.ascontiguousarray(self.data.T, dtype=float)
        self.const = np.ascontiguousarray(self.const, dtype=float)


@dataclass(frozen=True)
class _GroupFunctions:
    """Per-observation CasADi functions of one group, all of ``(q, m, theta, sigma_p,
    sigma_r, const)``: residual ``r``; residual and transposed dense Jacobian ``rj`` (one
    call, shared subexpressions); Jacobian ``j``; and :meth:`rj_free`, the Jacobian's
    columns of the estimated parameters only (cheaper for the small parameter sets)."""

    r: object
    rj: object
    j: object
    args: list = field(repr=False)
    residual_expr: object = field(repr=False)
    _by_free: dict = field(default_factory=dict, repr=False)

    def rj_free(self, free: NDArray[np.bool_]):
        """``rj`` with the Jacobian's ``free`` columns only: ``(rows,), (n_free, rows)``."""
        key = free.tobytes()
        with _FUNCTION_CACHE_LOCK:
            f = self._by_free.get(key)
        if f is None:
            ca = _ca()
            theta = self.args[2]
            cols = ca.vertcat(*[theta[int(i)] for i in np.flatnonzero(free)])
            J = ca.jacobian(self.residual_expr, cols)
            f = ca.Function("rjf", self.args, [self.residual_expr, ca.densify(J.T)])
            with _FUNCTION_CACHE_LOCK:
                if len(self._by_free) >= 8:  # bounded: a few parameter sets per structure
                    self._by_free.pop(next(iter(self._by_free)))
                self._by_free[key] = f
        return f


#: Compiled residual functions by problem structure (see :func:`_structure_key`); a
#: small LRU so that cross-validation folds, parameter sets and Monte Carlo trials on the
#: same robot and observation layout build the CasADi graph once.
_FUNCTION_CACHE: OrderedDict[tuple, tuple[_GroupFunctions, ...]] = OrderedDict()
_FUNCTION_CACHE_SIZE = 16
_FUNCTION_CACHE_LOCK = threading.Lock()


def clear_function_cache() -> None:
    """Forget every cached CasADi residual function (they are rebuilt on demand)."""
    with _FUNCTION_CACHE_LOCK:
        _FUNCTION_CACHE.clear()


def _start_extras(measurements: Measurements, model: CPCModel, q_all: NDArray,
                  model_frame: str | None, targets: dict[str, NDArray]
                  ) -> tuple[list[tuple[str, str, NDArray]], list[tuple[str, NDArray]]]:
    """Start values of the extra rigid frames and point offsets, in closed form."""
    index = {f: k for k, f in enumerate(model.topology.frames)}
    w_T = model.frame_poses(q_all)
    if w_T.ndim == 3:
        w_T = w_T[None]
    frames: list[tuple[str, str, NDArray]] = []
    external = sorted({g.measured_in for g in (*measurements.poses, *measurements.points)
                       if g.measured_in is not None and g.measured_in != model_frame})
    meas_T_w: dict[str, NDArray] = {}
    for name in external:
        est = [g.meas_T_frame @ inverse_transform(w_T[g.sample, index[g.frame]])
               for g in measurements.poses if g.measured_in == name and g.marker is None]
        if not est:
            raise DatasetError(
                f"{measurements.source}: frame {name!r} is observed only through markers or "
                "points; give some marker-free pose observations in it, or measure everything "
                "in it (then the model is expressed in it)")
        meas_T_w[name] = average_transform(np.concatenate(est))
        frames.append(("frame", name, meas_T_w[name]))

    def to_meas(g, T):
        name = g.measured_in if g.measured_in != model_frame else None
        return T if name is None else meas_T_w[name] @ T

    for name in dict.fromkeys(g.target for g in measurements.targets):
        if name in targets:
            frames.append(("target", name, targets[name]))
            continue
        est = [w_T[g.sample, index[g.camera]] @ g.camera_T_target
               for g in measurements.targets if g.target == name]
        frames.append(("target", name, average_transform(np.concatenate(est))))
    for g in measurements.poses:
        if g.marker is not None and all(f[1] != g.marker for f in frames if f[0] == "marker"):
            pred = to_meas(g, w_T[g.sample, index[g.frame]])
            frames.append(("marker", g.marker, average_transform(inverse_transform(pred)
                                                                 @ g.meas_T_frame)))
    offsets: list[tuple[str, NDArray]] = []
    for g in measurements.points:
        if g.offset is not None:
            continue
        key = f"{g.frame}:{g.marker or 'point'}"
        if any(k == key for k, _ in offsets):
            continue
        T = to_meas(g, w_T[g.sample, index[g.frame]])
        offsets.append((key, np.einsum("nji,nj->ni", T[:, :3, :3],
                                       g.meas_p_point - T[:, :3, 3]).mean(axis=0)))
    return frames, offsets


@dataclass(frozen=True, slots=True)
class LeastSquaresProblem:
    """The assembled problem: unknowns, their start values, and the residual groups.

    ``x`` below is the vector of chart coordinates from the start (rad, m), in the
    order of :attr:`names`; only the :attr:`free` entries are estimated.
    """

    model0: CPCModel
    model_frame: str | None
    names: tuple[tuple[str, str], ...]
    free: NDArray[np.bool_]
    frames: tuple[tuple[str, str, NDArray[np.float64]], ...]
    offsets: tuple[tuple[str, NDArray[np.float64]], ...]
    extra_slice: dict[tuple[str, str], slice]
    offset_slice: dict[str, slice]
    groups: tuple[_Group, ...]
    base_slice: slice
    zero_slice: slice
    prior_mean: NDArray[np.float64]
    prior_sigma: NDArray[np.float64]

    @property
    def prior_rows(self) -> NDArray[np.int64]:
        """Parameters with a prior (free, finite sigma): one residual row each."""
        return np.flatnonzero(self.free & np.isfinite(self.prior_sigma))

    @property
    def n_parameters(self) -> int:
        return len(self.names)

    @property
    def obs_sizes(self) -> list[tuple[int, int]]:
        """(observations, rows per observation) of each group, then one row per prior."""
        sizes = [(len(g.sample), g.rows) for g in self.groups]
        return sizes + ([(len(self.prior_rows), 1)] if len(self.prior_rows) else [])

    def evaluate(self, x: NDArray, sigma: NoiseModel, with_jacobian: bool = True, *,
                 only_free: bool = False) -> tuple[NDArray, NDArray | None]:
        """Whitened residuals (N,) and their Jacobian (N, P) at ``x``.

        With ``only_free`` the columns of the fixed parameters are left at zero (not
        computed: what the fit needs, cheaper for the small parameter sets).
        """
        P = self.n_parameters
        no_columns = only_free and not self.free.any()
        rs, Js = [], []
        for grp in self.groups:
            r, J = grp.evaluate(x, sigma, with_jacobian and not no_columns,
                                self.free if only_free else None)
            rs.append(r)
            if with_jacobian and only_free:
                full = np.zeros((len(r), P))
                if J is not None:
                    full[:, self.free] = J
                J = full
            if with_jacobian:
                Js.append(J)
        k = self.prior_rows
        if len(k):  # Gaussian prior: (x - mean) / sigma
            rs.append((x[k] - self.prior_mean[k]) / self.prior_sigma[k])
            if with_jacobian:
                Jp = np.zeros((len(k), P))
                Jp[np.arange(len(k)), k] = 1.0 / self.prior_sigma[k]
                Js.append(Jp)
        return np.concatenate(rs), (np.concatenate(Js) if with_jacobian else None)

    def casadi_residual(self, sigma: NoiseModel):
        """``(x, r)``: a CasADi MX symbol for the free entries of ``x`` and the whitened
        residual vector as an MX expression of it (data embedded), for CasADi solvers."""
        ca = _ca()
        x_free = ca.MX.sym("x", int(self.free.sum()))
        x = self.full_x(x_free)
        r = ca.vertcat(*[ca.vec(g.residual(ca.DM(g.qs), ca.DM(g.data), x, sigma.position_m,
                                           sigma.rotation_rad)) for g in self.groups])
        return x_free, r

    def full_x(self, x_free):
        """The whole chart vector (CasADi MX) from its free entries, fixed ones at zero."""
        ca = _ca()
        parts, k = [], 0
        for i in range(self.n_parameters):
            if self.free[i]:
                parts.append(x_free[k])
                k += 1
            else:
                parts.append(ca.MX(0.0))
        return ca.vertcat(*parts)

    def model_at(self, x: NDArray) -> CPCModel:
        """The kinematics at ``x`` (base transform and joint zero offsets folded in)."""
        from kinfw.cpc import ZeroGeometry, cpc_from_geometry, geometry_from_cpc

        model = self.model0.perturbed(x[: self.model0.n_parameters])
        base = _cayley_pose_np(np.eye(4), x[self.base_slice])
        zero = x[self.zero_slice]
        if not np.any(base != np.eye(4)) and not np.any(zero):
            return model
        # FK(q + zero) = FK with every joint pre-moved by its offset: the geometry at q = 0
        # of the offset model is the original geometry at q = zero.
        moved = model.joint_frames(zero)[0]
        geo = geometry_from_cpc(model)
        axes = moved[:, :3, 2] * model.sign[:, None]
        shifted = ZeroGeometry(geo.topology, axes @ base[:3, :3].T,
                               moved[:, :3, 3] @ base[:3, :3].T + base[:3, 3],
                               base @ model.frame_poses(zero))
        return cpc_from_geometry(shifted, sign=model.sign)

    def unknowns_at(self, x: NDArray) -> tuple[Unknown, ...]:
        """Target poses, external frames, markers and offsets at ``x``."""
        return tuple(
            [Unknown(kind, name, _cayley_pose_np(value, x[self.extra_slice[(kind, name)]]))
             for kind, name, value in self.frames]
            + [Unknown("offset", key, value + x[self.offset_slice[key]])
               for key, value in self.offsets])


def _build_functions(model0: CPCModel, layout: list[tuple], frames, offsets, P: int,
                     slices: tuple[slice, slice, dict, dict], n_const: int
                     ) -> tuple[_GroupFunctions, ...]:
    """The CasADi residual functions of every observation group (see :class:`_Group`).

    ``layout`` describes each group (kind, frame, marker or target, measurement frame,
    and for points whether the offset is known); every number enters through the
    ``const`` input, laid out as in :func:`build_problem`: the reference CPC model
    (:func:`kinfw.cpc_casadi.cpc_reference_vector`), each extra frame's start pose (12),
    each unknown offset's start (3), each known point offset (3).
    """
    ca = _ca()
    base_slice, zero_slice, extra_slice, offset_slice = slices
    fk = cpc_fk_function(model0, symbolic_reference=True)
    theta = ca.SX.sym("theta", P)
    q = ca.SX.sym("q", model0.n_joints)
    const = ca.SX.sym("const", n_const)
    sp = ca.SX.sym("sigma_p")
    sr = ca.SX.sym("sigma_r")
    k = len(cpc_reference_vector(model0))
    T_frames = fk(q + theta[zero_slice], theta[: model0.n_parameters], const[:k])
    T_frames = T_frames if isinstance(T_frames, (list, tuple)) else [T_frames]
    base = _cayley_pose(ca, np.eye(4), theta[base_slice])
    frame_T = {f: base @ T_frames[i] for i, f in enumerate(model0.topology.frames)}
    extra_T = {}
    for kind, name, _ in frames:
        extra_T[(kind, name)] = _cayley_pose(ca, (ca.reshape(const[k : k + 9], 3, 3),
                                                  const[k + 9 : k + 12]),
                                             theta[extra_slice[(kind, name)]])
        k += 12
    offset_p = {}
    for key, _ in offsets:
        offset_p[key] = const[k : k + 3] + theta[offset_slice[key]]
        k += 3

    def meas_frame(name):
        return ca.DM.eye(4) if name is None else extra_T[("frame", name)]

    out = []
    for lay in layout:
        if lay[0] == "pose":
            _, frame, marker, meas = lay
            T = meas_frame(meas) @ frame_T[frame]
            if marker is not None:
                T = T @ extra_T[("marker", marker)]
            m = ca.SX.sym("m", 12)
            r = _pose_residual(ca, T, m, sp, sr)
        elif lay[0] == "target":
            _, camera, target = lay
            T = _inverse_ca(ca, frame_T[camera]) @ extra_T[("target", target)]
            m = ca.SX.sym("m", 12)
            r = _pose_residual(ca, T, m, sp, sr)
        else:
            _, frame, marker, meas, known = lay
            T = meas_frame(meas) @ frame_T[frame]
            if known:
                o = const[k : k + 3]
                k += 3
            else:
                o = offset_p[f"{frame}:{marker or 'point'}"]
            m = ca.SX.sym("m", 3)
            r = (m - (T[0:3, 0:3] @ o + T[0:3, 3])) / sp
        args = [q, m, theta, sp, sr, const]
        J = ca.jacobian(r, theta)
        out.append(_GroupFunctions(ca.Function("r", args, [r]),
                                   ca.Function("rj", args, [r, ca.densify(J.T)]),
                                   ca.Function("j", args, [J]), args, r))
    return tuple(out)


def build_problem(robot: Robot, measurements: Measurements, *, start: Robot | None = None,
                  targets: dict[str, NDArray] | None = None,
                  parameters: str | tuple[str, ...] = "full",
                  prior: tuple[float, float] | None = None,
                  known: tuple[Unknown, ...] = ()) -> LeastSquaresProblem:
    """Assemble the least-squares problem (see :func:`refine` for the arguments).

    ``known`` gives start values for extra unknowns (e.g. a previous calibration's target
    pose and markers) instead of estimating them from these data.
    """
    measurements = check_against_robot(measurements, robot)
    start = robot if start is None else start
    observed = measurements.observed_frames
    in_frames = {g.measured_in for g in (*measurements.poses, *measurements.points)}
    model_frame = None
    if not measurements.targets and len(in_frames) == 1 and None not in in_frames:
        model_frame = next(iter(in_frames))  # everything in one external frame
    model0 = cpc_from_robot(start, observed)
    q_all = measurements.q_of(model0.topology.joint_names)
    given = {(u.kind, u.name): u.value for u in known}
    if model_frame is not None:
        model0 = _express_in(model0, measurements, q_all, model_frame,
                             given.get(("frame", model_frame)))
    frames, offsets = _start_extras(measurements, model0, q_all, model_frame, targets or {})
    frames = [(k, n, given.get((k, n), v)) for k, n, v in frames]
    offsets = [(key, given.get(("offset", key), v)) for key, v in offsets]

    # -- parameter vector: CPC chart, then 6 per extra frame, then 3 per offset ----------
    names = list(model0.parameter_names)
    free = np.ones(len(names), bool)
    only_indirect = [f for f in observed
                     if not any(g.frame == f and g.marker is None for g in measurements.poses)
                     and not any(g.camera == f for g in measurements.targets)
                     and not any(g.frame == f and g.offset is not None
                                 for g in measurements.points)]
    for f in only_indirect:  # its markers carry the freedom: keep the nominal tool
        free[[k for k, (o, _) in enumerate(names) if o == f]] = False
    for f in observed:  # a revolute joint's child link has its origin on the joint axis
        last = robot.path_joints(f)[-1] if robot.path_joints(f) else None
        if last is not None and last.is_revolute and last.child == f:
            free[[k for k, (o, c) in enumerate(names) if o == f and c in ("x", "y")]] = False
    n_cpc = len(names)
    tools = np.array([o in model0.topology.frames for o, _ in names])
    if parameters == "full":
        pass
    elif parameters in ("offsets", "frames", "none"):
        free &= tools if parameters != "none" else np.zeros(n_cpc, bool)
    else:  # a mask: joint names (all their parameters) or "joint:field" entries
        wanted = set()
        for token in ([] if isinstance(parameters, str) else parameters):
            owner, _, field_ = token.partition(":")
            matches = [k for k, (o, f) in enumerate(names) if o == owner
                       and (not field_ or f == field_)]
            if owner not in model0.topology.joint_names or not matches:
                raise ValueError(
                    f"parameters: expected 'full', 'offsets', 'frames', 'none', joint names "
                    f"or 'joint:field' of {list(model0.topology.joint_names)} (fields "
                    f"b_tilt_1, b_tilt_2, l_x, l_y); got {token!r}")
            wanted.update(matches)
        if isinstance(parameters, str) or not wanted:
            raise ValueError(f"parameters: expected 'full', 'offsets', 'frames', 'none' or a "
                             f"mask of joints; got {parameters!r}")
        free &= tools | np.isin(np.arange(n_cpc), sorted(wanted))
    # the base (a rigid transform of the whole model) and joint zero offsets: redundant
    # with the full chart, used by the smaller parameter sets
    base_slice = slice(len(names), len(names) + 6)
    names += [("base", c) for c in ("rot_x", "rot_y", "rot_z", "x", "y", "z")]
    zero_slice = slice(len(names), len(names) + model0.n_joints)
    names += [(j, "zero_offset") for j in model0.topology.joint_names]
    in_model_frame = any((g.measured_in or None) == model_frame
                         for g in (*measurements.poses, *measurements.points))
    base_free = parameters != "full" and parameters != "none" and in_model_frame
    topo = model0.topology
    # a zero offset is redundant with a tool when the joint carries only end frames, and
    # with the base when only prismatic joints lie above it (a constant translation)
    useful_offset = np.array([
        (topo.revolute[j] and bool(topo.children(j)))
        or (not topo.revolute[j] and any(topo.revolute[a] for a in _ancestors(topo, j)))
        for j in range(model0.n_joints)])
    extra_free = np.concatenate([np.full(6, base_free),
                                 useful_offset & (parameters == "offsets")])
    free = np.concatenate([free, extra_free])
    extra_slice: dict[tuple[str, str], slice] = {}
    for kind, name, _ in frames:
        extra_slice[(kind, name)] = slice(len(names), len(names) + 6)
        names += [(f"{kind}:{name}", c) for c in ("rot_x", "rot_y", "rot_z", "x", "y", "z")]
    offset_slice: dict[str, slice] = {}
    for key, _ in offsets:
        offset_slice[key] = slice(len(names), len(names) + 3)
        names += [(f"offset:{key}", c) for c in ("x", "y", "z")]
    free = np.concatenate([free, np.ones(len(names) - len(free), bool)])
    P = len(names)

    def meas_name(g):
        return g.measured_in if g.measured_in != model_frame else None

    # what the CasADi graph depends on; the numbers (reference model, start frames,
    # known point offsets) are inputs, so problems of one structure share the functions
    layout = ([("pose", g.frame, g.marker, meas_name(g)) for g in measurements.poses]
              + [("target", g.camera, g.target) for g in measurements.targets]
              + [("point", g.frame, g.marker, meas_name(g), g.offset is not None)
                 for g in measurements.points])
    topo = model0.topology
    key = ((topo.joint_names, topo.revolute, topo.parent, topo.frames, topo.frame_parent),
           tuple(float(v) for v in model0.sign), tuple(names),
           tuple((k, v.start) for k, v in extra_slice.items()),
           tuple((k, v.start) for k, v in offset_slice.items()), tuple(layout))
    const = np.concatenate(
        [cpc_reference_vector(model0)]
        + [_pose_vectors(value[None]).ravel() for _, _, value in frames]
        + [np.asarray(value, float) for _, value in offsets]
        + [np.asarray(g.offset, float) for g in measurements.points if g.offset is not None])
    with _FUNCTION_CACHE_LOCK:
        functions = _FUNCTION_CACHE.get(key)
        if functions is not None:
            _FUNCTION_CACHE.move_to_end(key)
    if functions is None:
        functions = _build_functions(model0, layout, frames, offsets, P,
                                     (base_slice, zero_slice, extra_slice, offset_slice),
                                     len(const))
        with _FUNCTION_CACHE_LOCK:
            _FUNCTION_CACHE[key] = functions
            while len(_FUNCTION_CACHE) > _FUNCTION_CACHE_SIZE:
                _FUNCTION_CACHE.popitem(last=False)
    data = ([_pose_vectors(g.meas_T_frame) for g in measurements.poses]
            + [_pose_vectors(g.camera_T_target) for g in measurements.targets]
            + [g.meas_p_point.T for g in measurements.points])
    observations = [*measurements.poses, *measurements.targets, *measurements.points]
    groups = [_Group(lay[0], lay[1], lay[2] if lay[0] != "target" else None, g.sample, d,
                     q_all[g.sample].T, fn, const, 3 if lay[0] == "point" else 6)
              for lay, g, d, fn in zip(layout, observations, data, functions, strict=True)]

    prior_sigma = np.full(P, np.inf)
    prior_mean = np.zeros(P)
    if prior is not None:
        sigma_m, sigma_rad = prior[0], prior[1]
        angular = np.array([parameter_unit(o, f, model0.topology) == "rad"
                            for o, f in names[: zero_slice.stop]])
        prior_sigma[: zero_slice.stop] = np.where(angular, sigma_rad, sigma_m)
        if model_frame is None:  # deviations from the nominal, in the start's chart
            from kinfw.cpc import cpc_from_geometry, geometry_from_robot

            nominal = cpc_from_geometry(geometry_from_robot(robot, observed), sign=model0.sign)
            prior_mean[:n_cpc] = model0.chart_coordinates(nominal)
    return LeastSquaresProblem(model0, model_frame, tuple(names), free, tuple(frames),
                               tuple(offsets), extra_slice, offset_slice, tuple(groups),
                               base_slice, zero_slice, prior_mean, prior_sigma)


def information_matrix(problem: LeastSquaresProblem, noise: NoiseModel) -> NDArray[np.float64]:
    """Fisher information ``J^T J`` of the whitened residuals at the problem's start.

    Built around the *true* model and frames, its inverse is the Cramer-Rao bound on the
    covariance of any unbiased estimate of the chart coordinates (free entries only).
    """
    _, J = problem.evaluate(np.zeros(problem.n_parameters), noise, True)
    Jf = J[:, problem.free]
    return Jf.T @ Jf


def refine(robot: Robot, measurements: Measurements, *, start: Robot | None = None,
           targets: dict[str, NDArray] | None = None, noise: NoiseModel | None = None,
           loss: str = "linear", loss_scale: float = 2.33, max_iterations: int = 100,
           noise_rounds: int = 5, parameters: str | tuple[str, ...] = "full",
           prior: tuple[float, float] | None = None,
           known: tuple[Unknown, ...] = ()) -> RefineResult:
    """Refine every unknown jointly by whitened nonlinear least squares.

    Parameters
    ----------
    robot : Robot
        The nominal URDF: topology, joint types, and the tool transforms kept for frames
        observed only through markers.
    measurements : Measurements
        ``pose``, ``target`` and ``point`` observations (any mix).
    start : Robot, optional
        Start geometry (e.g. the closed-form + hand-eye URDF); default ``robot``.
    targets : dict of str to ndarray (4, 4), optional
        Start poses ``root_T_target`` (e.g. from the hand-eye step); default estimated.
    noise : NoiseModel, optional
        Measurement noise; default estimated from the residuals (starting from 1 mm and
        0.5 deg).
    loss : {"linear", "huber", "cauchy"}
        Robust loss on each observation's whitened residual norm.
    loss_scale : float
        Where the robust loss departs from least squares, as a standard-normal quantile
        ``z``: an observation's whitened residual norm is compared with the same quantile
        of its clean distribution under the noise model of :class:`NoiseModel` (exact:
        ``chi2(3) + 3 chi2(1)`` for poses and targets, ``chi2(3)`` for points), so 2.33
        flags 1 % of clean observations.
    max_iterations : int
        Levenberg-Marquardt iterations per noise round.
    noise_rounds : int
        Re-estimations of the noise when it is not given.
    parameters : {"full", "offsets", "frames", "none"} or tuple of joint names
        What to estimate besides the targets, external frames, markers and offsets:
        ``"full"`` every identifiable CPC parameter; ``"offsets"`` joint zero offsets,
        the base frame and the end frames' tool transforms; ``"frames"`` the base and tool
        frames only (nominal joints); ``"none"`` nothing of the robot (the nominal
        baseline); a mask: ``"frames"`` plus the CPC parameters named by joint (all of
        its parameters) or ``"joint:field"`` (``b_tilt_1``, ``b_tilt_2``, ``l_x``,
        ``l_y``).
    prior : (sigma_m, sigma_rad), optional
        Gaussian prior on the robot parameters' deviations from the nominal URDF (from
        the start when the model lives in an external frame), for small datasets.
    known : tuple of Unknown
        Start values of extra unknowns (targets, frames, markers, offsets) instead of
        estimating them from these data.

    Returns
    -------
    RefineResult

    Raises
    ------
    DatasetError
        When the data does not fit the robot or leaves an external frame unplaceable.
    """
    if loss not in LOSSES:
        raise ValueError(f"loss: expected one of {LOSSES}, got {loss!r}")
    t0 = time.perf_counter()
    problem = build_problem(robot, measurements, start=start, targets=targets,
                            parameters=parameters, prior=prior, known=known)
    P, free, obs_sizes = problem.n_parameters, problem.free, problem.obs_sizes
    given = noise is not None
    sigma = noise if given else NoiseModel(1e-3, np.radians(0.5), estimated=True)
    k = _thresholds(obs_sizes, loss_scale)
    x = np.zeros(P)
    iterations, converged = 0, False
    for round_ in range(1 if given else noise_rounds):
        x, its, converged = _levenberg_marquardt(
            lambda v, jac, s=sigma: problem.evaluate(v, s, jac, only_free=True), x, free,
            obs_sizes, loss, k, max_iterations)
        iterations += its
        if given:
            break
        r, J = problem.evaluate(x, sigma, True, only_free=True)
        Q, _ = np.linalg.qr(J[:, free] * np.sqrt(_row_weights(r, obs_sizes, loss, k))[:, None])
        sigma = _estimate_noise(r, problem.groups, sigma, np.sum(Q**2, axis=1),
                                robust=loss != "linear", first=round_ == 0)
    r, J = problem.evaluate(x, sigma, True, only_free=True)
    w_rows = _row_weights(r, obs_sizes, loss, k)
    rw, Jw = r * np.sqrt(w_rows), J * np.sqrt(w_rows)[:, None]
    dof = max(len(r) - int(free.sum()), 1)
    sigma_hat2 = float(rw @ rw / dof)
    # a given noise model is trusted; an estimated one is rescaled by the fit
    covariance, ident = _covariance_and_identifiability(
        Jw, free, list(problem.names), 1.0 if given else sigma_hat2, measurements,
        problem.model0)
    flagged = _obs_norms(r, obs_sizes) > k if loss != "linear" else np.zeros(len(k), bool)
    residuals, downweighted = _group_residuals(list(problem.groups), r, w_rows, sigma,
                                               flagged)
    result = RefineResult(
        model=problem.model_at(x), model_frame=problem.model_frame,
        unknowns=problem.unknowns_at(x), parameter_names=problem.names,
        free=problem.free.copy(), estimate=x,
        covariance=covariance, noise=sigma, sigma_hat2=sigma_hat2, residuals=residuals,
        downweighted=downweighted, identifiability=ident, iterations=iterations,
        converged=converged, cost=0.5 * float(rw @ rw), seconds=time.perf_counter() - t0)
    log.info("refine: %d free parameters (%d before gauge fixing and the parameter set), "
             "%d residuals, %d iterations, sigma_hat^2 %.3g, %.3f s", ident.n_parameters, P,
             len(r), iterations, sigma_hat2, result.seconds)
    return result


# -- helpers ---------------------------------------------------------------------------
def _ancestors(topo, j: int) -> list[int]:
    out, p = [], topo.parent[j]
    while p >= 0:
        out.append(p)
        p = topo.parent[p]
    return out


def _express_in(model: CPCModel, measurements: Measurements, q_all: NDArray, name: str,
                meas_T_root: NDArray | None = None) -> CPCModel:
    """The model moved into the external frame ``name`` by ``name_T_root``: given, or a
    closed-form estimate (pose observations averaged, or points registered)."""
    from kinfw.cpc import ZeroGeometry, cpc_from_geometry, geometry_from_cpc
    from kinfw.registration import register_points

    index = {f: k for k, f in enumerate(model.topology.frames)}
    w_T = model.frame_poses(q_all)
    w_T = w_T[None] if w_T.ndim == 3 else w_T
    est = [g.meas_T_frame @ inverse_transform(w_T[g.sample, index[g.frame]])
           for g in measurements.poses if g.marker is None]
    if meas_T_root is not None:
        pass
    elif est:
        meas_T_root = average_transform(np.concatenate(est))
    else:
        known = [g for g in measurements.points if g.offset is not None]
        if not known:
            raise DatasetError(
                f"{measurements.source}: everything is measured in {name!r} through markers "
                "or points of unknown offset; give at least one point offset (or a "
                "marker-free pose) so that the frame can be placed")
        root_p = np.concatenate([(w_T[g.sample, index[g.frame]] @ np.append(g.offset, 1.0))
                                 [:, :3] for g in known])
        meas_p = np.concatenate([g.meas_p_point for g in known])
        meas_T_root = register_points(root_p, meas_p)
    geo = geometry_from_cpc(model)
    R, p = meas_T_root[:3, :3], meas_T_root[:3, 3]
    moved = ZeroGeometry(geo.topology, geo.axes @ R.T, geo.points @ R.T + p,
                         meas_T_root @ geo.w_T_frames)
    return cpc_from_geometry(moved, sign=model.sign)


def _obs_norms(r: NDArray, obs_sizes: list[tuple[int, int]]) -> NDArray:
    out, k = [], 0
    for m, rows in obs_sizes:
        out.append(np.linalg.norm(r[k : k + m * rows].reshape(m, rows), axis=1))
        k += m * rows
    return np.concatenate(out)


def _repeat_rows(per_obs: NDArray, obs_sizes: list[tuple[int, int]]) -> NDArray:
    out, k = [], 0
    for m, rows in obs_sizes:
        out.append(np.repeat(per_obs[k : k + m], rows))
        k += m
    return np.concatenate(out)


def _thresholds(obs_sizes: list[tuple[int, int]], z: float) -> NDArray:
    """Per observation, the ``Phi(z)`` quantile of the norm of its clean whitened residual.

    Under the noise model of :class:`NoiseModel` (positions isotropic Gaussian,
    orientations an angle about a uniformly random axis): a point's squared norm is
    ``chi2(3)``, a pose's ``chi2(3) + 3 chi2(1)`` (:func:`_pose_norm2_cdf`), a prior row's
    ``chi2(1)``; exact quantiles, so ``z = 2.33`` flags 1 % of clean observations of every
    kind. Other row counts fall back to ``chi2(rows)`` by Wilson-Hilferty.
    """
    per_obs = [np.full(m, _threshold(rows, float(z))) for m, rows in obs_sizes]
    return np.concatenate(per_obs) if per_obs else np.zeros(0)


@functools.lru_cache(maxsize=64)
def _threshold(rows: int, z: float) -> float:
    """The threshold of :func:`_thresholds` for one row count (computed once)."""
    from math import erf, sqrt

    p = 0.5 * (1.0 + erf(z / sqrt(2.0)))
    if rows == 6:
        return sqrt(_quantile(_pose_norm2_cdf, p))
    if rows in (1, 3):
        return sqrt(_chi2_quantile(p, rows))
    c = 2.0 / (9.0 * rows)
    return sqrt(rows * (1.0 - c + z * sqrt(c)) ** 3)


_GAUSS_LEGENDRE_64 = np.polynomial.legendre.leggauss(64)


def _pose_norm2_cdf(s: float) -> float:
    """CDF of ``S = X + 3 Y``, ``X ~ chi2(3)``, ``Y ~ chi2(1)``: a pose's whitened squared
    residual norm (position + angle about a random axis). With ``Y = t^2``,
    ``P(S <= s) = int_0^sqrt(s/3) 2 phi(t) F_3(s - 3 t^2) dt`` (Gauss-Legendre, 64 nodes)."""
    from math import pi, sqrt

    if s <= 0.0:
        return 0.0
    nodes, weights = _GAUSS_LEGENDRE_64
    b = sqrt(s / 3.0)
    t = 0.5 * b * (nodes + 1.0)
    f = [_chi2_cdf(s - 3.0 * ti * ti, 3) for ti in t]
    return float(0.5 * b * np.sum(weights * 2.0 * np.exp(-0.5 * t * t) / sqrt(2.0 * pi) * f))


def _quantile(cdf, p: float) -> float:
    """Quantile of a distribution on [0, inf) from its CDF, by bisection."""
    lo, hi = 0.0, 1.0
    while cdf(hi) < p:
        hi *= 2.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < p else (lo, mid)
    return 0.5 * (lo + hi)


def _robust(s: NDArray, loss: str, k: NDArray) -> tuple[NDArray, NDArray]:
    """Loss rho(s) and IRLS weight rho'(s)/s of whitened residual norms ``s``."""
    if loss == "huber":
        return np.where(s <= k, 0.5 * s**2, k * s - 0.5 * k**2), np.where(s <= k, 1.0, k / s)
    if loss == "cauchy":
        return 0.5 * k**2 * np.log1p((s / k) ** 2), 1.0 / (1.0 + (s / k) ** 2)
    return 0.5 * s**2, np.ones_like(s)


def _row_weights(r: NDArray, obs_sizes, loss: str, k: NDArray) -> NDArray:
    return _repeat_rows(_robust(_obs_norms(r, obs_sizes), loss, k)[1], obs_sizes)


def _levenberg_marquardt(evaluate, x: NDArray, free: NDArray, obs_sizes, loss: str,
                         k: NDArray, max_iterations: int) -> tuple[NDArray, int, bool]:
    """Levenberg-Marquardt with IRLS weights, in column-scaled coordinates.

    Steps solve ``(Js^T Js + lam I) y = -Js^T r`` with unit-norm columns ``Js``: no
    component along directions the Jacobian does not see (they stay at the start).
    """
    def cost_of(r):
        return float(_robust(_obs_norms(r, obs_sizes), loss, k)[0].sum())

    r, J = evaluate(x, True)
    cost = cost_of(r)
    lam = 1e-6  # column-scaled: start close to Gauss-Newton
    converged = False
    it = 0
    for it in range(1, max_iterations + 1):
        w = np.sqrt(_row_weights(r, obs_sizes, loss, k))
        Jf = J[:, free] * w[:, None]
        c = np.linalg.norm(Jf, axis=0)
        c[c == 0.0] = 1.0
        Js = Jf / c
        g = Js.T @ (r * w)
        H = Js.T @ Js
        while True:
            y = -np.linalg.solve(H + lam * np.eye(len(H)), g)
            x_new = x.copy()
            x_new[free] += y / c
            r_new, _ = evaluate(x_new, False)
            cost_new = cost_of(r_new)
            if cost_new <= cost:
                break
            lam *= 4.0
            if lam > 1e12:
                return x, it, converged
        decrease = cost - cost_new
        x, r, cost = x_new, r_new, cost_new
        lam = max(lam / 3.0, 1e-12)
        if decrease <= 1e-12 * max(cost, 1e-300) or np.linalg.norm(y) < 1e-12:
            converged = True
            break
        _, J = evaluate(x, True)
    return x, it, converged


def _chi2_cdf(x: float, dof: int) -> float:
    """CDF of the chi-square distribution with an odd number of degrees of freedom.

    Closed form: ``F_1(x) = erf(sqrt(x / 2))`` and
    ``F_{k+2}(x) = F_k(x) - (x / 2)^(k / 2) exp(-x / 2) / Gamma(k / 2 + 1)``.
    """
    from math import erf, exp, gamma, sqrt

    if dof < 1 or dof % 2 == 0:
        raise ValueError(f"dof: expected an odd positive integer, got {dof}")
    F = erf(sqrt(x / 2.0))
    for k in range(1, dof, 2):
        F -= (x / 2.0) ** (k / 2.0) * exp(-x / 2.0) / gamma(k / 2.0 + 1.0)
    return F


def _chi2_quantile(p: float, dof: int) -> float:
    """Quantile of the chi-square distribution (odd ``dof``), by bisection on its CDF."""
    return _quantile(lambda x: _chi2_cdf(x, dof), p)


@dataclass(frozen=True, slots=True)
class _NoiseShape:
    """Distribution of one observation's whitened squared residual norm ``X`` (3 rows,
    each of unit variance) under a noise model: the constants of the robust estimate.

    Attributes
    ----------
    median : float
        Median of ``X``.
    cut : float
        Its 99.9 % quantile: the trimmed second moment keeps ``X < cut``.
    trimmed : float
        ``E[X | X < cut] / 3``: the trimmed second moment per row, relative to the
        untrimmed one (1).
    """

    median: float
    cut: float
    trimmed: float


def _isotropic_gaussian_shape() -> _NoiseShape:
    """``X ~ chi2(3)``: three independent N(0, 1) components (positions).

    ``E[chi2_k; chi2_k < c] = k F_{k+2}(c)``, so ``E[X | X < c] / 3 = F_5(c) / F_3(c)``.
    """
    cut = _chi2_quantile(0.999, 3)
    return _NoiseShape(_chi2_quantile(0.5, 3), cut, _chi2_cdf(cut, 5) / _chi2_cdf(cut, 3))


def _angle_about_random_axis_shape() -> _NoiseShape:
    """``X = 3 chi2(1)``: a rotation vector ``theta u`` with ``theta ~ N(0, s)`` and ``u``
    uniform on the unit sphere, whitened by its per-component deviation ``s / sqrt(3)``
    (orientations, Shih et al. 1992 Fig. 10): ``|theta u|^2 = theta^2 = (s^2 / 3) 3 z^2``.

    ``E[X | X < c] / 3 = E[Y | Y < c / 3]`` with ``Y ~ chi2(1)``, ``= F_3(c/3) / F_1(c/3)``.
    """
    cut = 3.0 * _chi2_quantile(0.999, 1)
    return _NoiseShape(3.0 * _chi2_quantile(0.5, 1), cut,
                       _chi2_cdf(cut / 3.0, 3) / _chi2_cdf(cut / 3.0, 1))


#: Robust-estimate constants for positions (isotropic Gaussian) and orientations (an
#: angle about a uniformly random axis); derived in closed form at import.
_POSITION_SHAPE = _isotropic_gaussian_shape()
_ROTATION_SHAPE = _angle_about_random_axis_shape()


def _estimate_noise(r: NDArray, groups: list[_Group], sigma: NoiseModel,
                    leverage: NDArray, *, robust: bool = False, first: bool = True
                    ) -> NoiseModel:
    """Rescale each kind's sigma from the whitened residuals.

    Parameters
    ----------
    r : ndarray, shape (R,)
        Whitened residuals (by ``sigma``) of every observation, groups in order.
    groups : list of _Group
        The observation groups (6 rows per pose or target, 3 per point).
    sigma : NoiseModel
        The whitening of ``r``.
    leverage : ndarray, shape (R,)
        Diagonal of the hat matrix ``J (J^T J)^+ J^T`` (one per row): a kind's residual
        degrees of freedom are its rows minus its leverages, so a kind that the fit
        follows closely (orientations, here) is not underestimated.
    robust : bool
        False: least squares' variance components. True: the robust estimate below.
    first : bool
        Robust only: the first round (median) rather than a later one (trimmed moment).

    Returns
    -------
    NoiseModel
        ``estimated=True``; ``position_m`` per axis (m), ``rotation_rad`` per orientation
        component (rad).

    Notes
    -----
    Noise model (that of :func:`verification.simulate.perturb_poses`, Shih et al. 1992
    Fig. 10): each position component is ``N(0, sigma_p)``, independently; an
    orientation error is a rotation by an angle ``N(0, sigma)`` about a uniformly random
    axis, so each of its three small-angle components has standard deviation
    ``sigma_r = sigma / sqrt(3)`` (the reported ``rotation_rad``) but is not Gaussian.
    Per observation, the squared norm of the whitened residual is ``X_p ~ chi2(3)`` for
    positions and ``X_r = 3 chi2(1)`` (the angle squared) for orientations, both of mean
    3. Their robust quantiles differ: the median of ``X_r`` is 1.365 against 2.366, and
    2 % of the orientations (carrying 14 % of the second moment) lie beyond chi2(3)'s
    99.9 % quantile; constants of chi2(3) for both kinds made the orientation estimate
    about 10 % low.

    Least squares: variance components, ``sigma_new^2 = sigma^2 sum(X) / (3 n share)``,
    with ``share`` the kind's mean ``1 - leverage``; consistent for any shape.

    Robust, first round: ``sigma_new^2 = sigma^2 median(X) / (share median_model)``,
    which gross outliers do not inflate. Later rounds: the trimmed second moment,
    ``sigma_new^2 = sigma^2 mean(X | X < cut) / (3 share trimmed)`` with ``cut`` the
    model's 99.9 % quantile of ``X`` and ``trimmed = E[X | X < cut] / 3`` (see
    :class:`_NoiseShape`; closed forms through chi-square CDFs). Its fixed point is the
    true sigma under the model; gross outliers (beyond ``cut``) do not enter it. For
    orientations whose components are instead independent Gaussians (e.g. a pose fitted
    to noisy points), the orientation ``cut`` (5.7 sigma_r) drops almost nothing and the
    estimate is 0.6 % high (``1 / sqrt(0.9883)``) after the trimmed rounds.
    """
    pos, rot, hp, hr, k = [], [], [], [], 0
    for grp in groups:
        m = len(grp.sample)
        block = r[k : k + m * grp.rows].reshape(m, grp.rows)
        h = leverage[k : k + m * grp.rows].reshape(m, grp.rows)
        pos.append(block[:, :3])
        hp.append(h[:, :3])
        if grp.rows == 6:
            rot.append(block[:, 3:])
            hr.append(h[:, 3:])
        k += m * grp.rows

    def factor(blocks: list[NDArray], hats: list[NDArray], shape: _NoiseShape) -> float:
        if not blocks:
            return 1.0
        block, hat = np.concatenate(blocks), np.concatenate(hats)
        share = max(1.0 - hat.sum() / block.size, 1e-3)
        s2 = np.sum(block**2, axis=1)
        if robust and first:
            return float(np.sqrt(np.median(s2) / (shape.median * share)))
        if robust:
            inside = s2[s2 < shape.cut]
            return float(np.sqrt(np.mean(inside) / (3.0 * shape.trimmed * share))) \
                if len(inside) else 1.0
        return float(np.sqrt(np.sum(s2) / (block.size * share)))

    return NoiseModel(
        float(max(sigma.position_m * factor(pos, hp, _POSITION_SHAPE), 1e-12)),
        float(max(sigma.rotation_rad * factor(rot, hr, _ROTATION_SHAPE), 1e-15)),
        estimated=True)


def _covariance_and_identifiability(Jw: NDArray, free: NDArray, names: list,
                                    sigma_hat2: float, measurements: Measurements,
                                    model: CPCModel
                                    ) -> tuple[NDArray, Identifiability]:
    P = len(names)
    Jf = Jw[:, free]
    c = np.linalg.norm(Jf, axis=0)
    c[c == 0.0] = 1.0
    _, s, Vt = np.linalg.svd(Jf / c, full_matrices=False)
    rank = int(np.sum(s > s[0] * 1e-8)) if len(s) else 0
    V = Vt[:rank].T
    cov_free = (V / s[:rank] ** 2) @ V.T / np.outer(c, c) * sigma_hat2
    covariance = np.zeros((P, P))
    idx = np.flatnonzero(free)
    covariance[np.ix_(idx, idx)] = cov_free
    free_names = [names[k] for k in idx]
    q_range = np.ptp(measurements.q_of(model.topology.joint_names), axis=0) \
        if measurements.n_samples else np.zeros(model.n_joints)
    still = {n for n, rng in zip(model.topology.joint_names, q_range, strict=True)
             if rng < 1e-9}
    unidentifiable = []
    for v in Vt[rank:]:
        involved = tuple(free_names[k] for k in np.flatnonzero(np.abs(v) > 0.2 * np.abs(v).max()))
        owners = {o for o, _ in involved}
        if owners & still:
            why = (f"joint(s) {sorted(owners & still)} never move in the data, so their "
                   "axes are not observed")
        elif all(f.startswith("rot") for _, f in involved):
            why = "only positions of these frames are observed; their orientation is free"
        else:
            why = ("these parameters change every prediction in the same way; the data "
                   "cannot tell them apart (add motion of the joints involved)")
        unidentifiable.append((involved, why))
    d = np.sqrt(np.clip(np.diag(cov_free), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = cov_free / np.outer(d, d)
    pairs = [(abs(rho[a, b]), a, b) for a in range(len(d)) for b in range(a + 1, len(d))
             if d[a] > 0 and d[b] > 0 and abs(rho[a, b]) > 0.9]
    pairs.sort(reverse=True)
    correlations = tuple((":".join(free_names[a]), ":".join(free_names[b]), float(rho[a, b]))
                         for _, a, b in pairs[:20])
    # no free parameter: nothing to condition or observe, both undefined (nan)
    if not len(s):
        o1 = condition = float("nan")
    else:
        o1 = float(np.exp(np.mean(np.log(s))) / np.sqrt(Jf.shape[0])) if rank == len(s) \
            else 0.0
        condition = float(s[0] / s[rank - 1]) if rank else float("inf")
    return covariance, Identifiability(
        rank=rank, n_parameters=len(free_names), condition=condition,
        observability_o1=o1, unidentifiable=tuple(unidentifiable), correlations=correlations)


def _group_residuals(groups: list[_Group], r: NDArray, w_rows: NDArray, sigma: NoiseModel,
                     flagged: NDArray) -> tuple[tuple[GroupResiduals, ...], tuple]:
    """Per-group residuals in SI, and the observations beyond the robust threshold."""
    out, down, k, o = [], [], 0, 0
    for grp in groups:
        m = len(grp.sample)
        block = r[k : k + m * grp.rows].reshape(m, grp.rows)
        weight = w_rows[k : k + m * grp.rows : grp.rows]
        out.append(GroupResiduals(
            grp.kind, grp.frame, grp.marker, grp.sample, block[:, :3] * sigma.position_m,
            block[:, 3:] * sigma.rotation_rad if grp.rows == 6 else None, weight,
            flagged[o : o + m].copy()))
        down += [(grp.kind, grp.frame, int(sm), float(wt))
                 for sm, wt, bad in zip(grp.sample, weight, flagged[o : o + m], strict=True)
                 if bad]
        k += m * grp.rows
        o += m
    return tuple(out), tuple(down)
