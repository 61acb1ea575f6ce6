"""The prior's scales chosen from the data: leave-one-sample-out of the linearised fit.

At a fit ``x`` of a problem under some prior, the whitened residuals are, to first order,
``b + B d`` (``B`` the Jacobian of the moving columns, the robust loss's weights held at
the fit, ``d`` a step from ``x``). Under a Gaussian prior of precision ``Lambda``
(diagonal, ``1 / sigma_g^2`` on the columns of group ``g``) and mean ``x + m``, the
estimate of that linear model is

.. math::

    d(\\Lambda) = A^{-1} (\\Lambda m - B^T b), \\qquad A = B^T B + \\Lambda,

its residuals ``e = b + B d``, and the residuals of sample ``i`` predicted by the
estimate without it (the leave-one-out identity of generalised ridge regression)

.. math::

    e_{-i} = (I - B_i A^{-1} B_i^T)^{-1} e_i
           = e_i + B_i (A - B_i^T B_i)^{-1} B_i^T e_i,

exact for the linear model and, at a converged fit, for a calibration as good as its
linearisation (:mod:`kinfw.verification.evaluation` scores the nonlinear fits the same way).
The sum ``sum_i |e_{-i}|^2`` over samples is a smooth function of the group sigmas, with
no refit and no random partition: :func:`choose_prior` minimises it over each group's
log sigma in turn (a scan, then golden-section search in the best bracket; a group may
also go without a prior), a few sweeps. A sample's rows (an image's corners, a pose's
six numbers) are held out together. Directions the data do not see at all (a contact
set's rigid motion) do not enter the score: their columns are zero in ``B``.

Every evaluation is one ``(P, P)`` factorisation and, per sample, a solve of its rows'
size (or of ``P`` when a sample has more rows than the problem has parameters: an image),
vectorised over the samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.identification.problem._problem import LeastSquaresProblem
from kinfw.identification.problem._solver import negligible_columns, row_weights
from kinfw.model import PriorScales

#: Where the search over a group's sigma starts and ends, relative to the sigma at which
#: the prior weighs as much as the data on one of its columns alone (``1 / |B_k|``,
#: :func:`_column_scales`): a hundredth of it fixes the group at the nominal, ten
#: thousand times it lets the data alone decide (a redundant group's posterior is much
#: wider than one column's). Without a prior is tried too.
SEARCH_SPAN = (1e-2, 1e4)

#: A leave-one-out system this close to singular (its smallest eigenvalue, or Cholesky
#: pivot over the largest diagonal entry) has no prediction: the sample alone
#: determines a direction.
SINGULAR = 1e-10

#: The search's bounds of a length (m) and an angle (rad) sigma: a machined robot's
#: deviations from its URDF, from a tenth of a millimetre (0.2 mrad) to centimetres
#: (0.3 rad: a mount guessed in the URDF); tighter is what the ``"frames"`` and
#: ``"offsets"`` candidates of the model choice are, and a sigma fitted to a noisy score
#: below it held the joints at the nominal on data that could barely see them
#: (``benchmarks/study_model_choice.py``, regime A). Other units (intrinsics, model spec
#: blocks) are searched over :data:`SEARCH_SPAN`.
PHYSICAL_SPAN = {"m": (1e-4, 3e-2), "rad": (2e-4, 0.3)}

#: Points of the first scan of a group's log sigma, and golden-section steps after it.
SCAN_POINTS = 9
GOLDEN_STEPS = 10

#: Coordinate sweeps over the groups, at most (fewer once a sweep changes no score by
#: more than :data:`SWEEP_TOL` of it).
SWEEPS = 3
SWEEP_TOL = 1e-4

#: The groups that share one length and one angle sigma in the first stage of the
#: choice (:func:`choose_prior`).
UNIFORM_GROUPS = ("offsets", "axes", "positions", "base")


#: Golden ratio's conjugate, for the golden-section search.
_INVPHI = (math.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True, slots=True)
class LinearisedFit:
    """A fit linearised for the choice of its prior's scales (the module docstring).

    Attributes
    ----------
    B : ndarray, shape (N, P)
        Whitened, weighted Jacobian of the data's rows, moving columns only.
    b : ndarray, shape (N,)
        Whitened, weighted residuals at the fit.
    sample : ndarray, shape (N,)
        The sample of each row (a held-out unit).
    mean : ndarray, shape (P,)
        The prior's mean minus the fit, per column.
    group : ndarray of int, shape (P,)
        Index into :attr:`keys` of each column's group, -1 for none.
    keys : tuple of (str, str)
        The ``(group, unit)`` searched.
    """

    B: NDArray[np.float64]
    b: NDArray[np.float64]
    sample: NDArray[np.int64]
    mean: NDArray[np.float64]
    group: NDArray[np.int64]
    keys: tuple[tuple[str, str], ...]

    def precisions(self, sigmas: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per column the prior's precision ``1 / sigma^2`` of its group (0: none, and
        for a group at sigma inf)."""
        lam = np.zeros(len(self.group))
        has = self.group >= 0
        lam[has] = 1.0 / sigmas[self.group[has]] ** 2
        return lam


def linearised_fit(
    problem: LeastSquaresProblem, x: NDArray, noise, loss: str, k: NDArray
) -> LinearisedFit:
    """``problem`` linearised at its fit ``x`` (noise ``noise``, robust ``loss`` with
    thresholds ``k``): the data's rows, the free columns the data see."""
    r, J = problem.evaluate_free(x, noise)
    n_obs = sum(len(g.sample) * g.rows for g in problem.groups)
    w = np.sqrt(row_weights(r, problem.obs_sizes, loss, k)[:n_obs])
    B, b = w[:, None] * J[:n_obs], w * r[:n_obs]
    moving = ~negligible_columns(B)
    free = np.flatnonzero(problem.free)[moving]
    labels = [problem.prior_groups[i] for i in free]
    keys = tuple(dict.fromkeys((g, u) for g, u in labels if g is not None))
    group = np.array([keys.index((g, u)) if g is not None else -1 for g, u in labels], dtype=int)
    return LinearisedFit(
        B[:, moving],
        b,
        np.concatenate([np.repeat(g.sample, g.rows) for g in problem.groups]),
        (problem.prior_mean - np.asarray(x))[free],
        group.reshape(-1),
        keys,
    )


class LinearLeaveOneOut:
    """The leave-one-sample-out score of a :class:`LinearisedFit` at any group sigmas
    (the module docstring), with what does not depend on them computed once."""

    def __init__(self, lin: LinearisedFit) -> None:
        self.lin = lin
        self.H = lin.B.T @ lin.B
        self.g = lin.B.T @ lin.b
        samples, inverse = np.unique(lin.sample, return_inverse=True)
        counts = np.bincount(inverse)
        width = int(counts.max()) if len(counts) else 0
        order = np.argsort(inverse, kind="stable")
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        slot = np.arange(len(order)) - np.repeat(starts, counts)
        index = np.full((len(samples), width), -1)
        index[inverse[order], slot] = order
        self.index, self.mask = index, index >= 0
        self.Bp = np.where(self.mask[..., None], lin.B[np.maximum(index, 0)], 0.0)
        self.in_rows = width <= lin.B.shape[1]  # the cheaper of the two forms
        if not self.in_rows:  # per sample B_i^T B_i and B_i^T b_i
            bp = np.where(self.mask, lin.b[np.maximum(index, 0)], 0.0)
            self.G = np.einsum("nap,naq->npq", self.Bp, self.Bp)
            self.c = np.einsum("nap,na->np", self.Bp, bp)
            self.bb = np.sum(bp**2, axis=1)

    def score(self, sigmas: NDArray[np.float64]) -> float:
        """``sum_i |e_{-i}|^2`` (the module docstring) at the group ``sigmas``; inf where
        a sample alone determines a direction (no prediction without it)."""
        return float(np.sum(self.per_sample(sigmas)))

    def per_sample(self, sigmas: NDArray[np.float64]) -> NDArray[np.float64]:
        """Each sample's ``|e_{-i}|^2`` at the group ``sigmas``, shape (n,); inf
        everywhere when a sample alone determines a direction."""
        lam = self.lin.precisions(sigmas)
        A = self.H + np.diag(lam)
        try:
            d = np.linalg.solve(A, lam * self.lin.mean - self.g)
            held = self._in_rows(A, d) if self.in_rows else self._in_parameters(A, d)
        except np.linalg.LinAlgError:
            held = np.full(len(self.index), np.inf)
        return held if np.all(np.isfinite(held)) else np.full(len(self.index), np.inf)

    def _in_rows(self, A: NDArray, d: NDArray) -> NDArray:
        e = self.lin.b + self.lin.B @ d
        ep = np.where(self.mask, e[np.maximum(self.index, 0)], 0.0)
        C = np.linalg.solve(A, self.lin.B.T).T  # B A^-1, (N, P)
        Cp = np.where(self.mask[..., None], C[np.maximum(self.index, 0)], 0.0)
        M = np.eye(self.Bp.shape[1]) - np.einsum("nap,nbp->nab", Cp, self.Bp)
        # I - H_ii is singular (a leverage of 1) when sample i alone determines a direction
        if np.linalg.eigvalsh(M)[:, 0].min() <= SINGULAR:
            raise np.linalg.LinAlgError("a sample alone determines a direction")
        held = np.linalg.solve(M, ep[..., None])[..., 0]
        return np.sum(held**2, axis=1)

    def _in_parameters(self, A: NDArray, d: NDArray) -> NDArray:
        Gd = self.G @ d
        rhs = self.c + Gd  # B_i^T e_i
        ee = self.bb + 2.0 * self.c @ d + Gd @ d  # |e_i|^2
        removed = A[None] - self.G
        # singular when sample i alone determines a direction: a Cholesky pivot ~ 0
        pivots = np.diagonal(np.linalg.cholesky(removed), axis1=1, axis2=2) ** 2
        if (pivots / np.diagonal(removed, axis1=1, axis2=2).max()).min() <= SINGULAR:
            raise np.linalg.LinAlgError("a sample alone determines a direction")
        delta = np.linalg.solve(removed, rhs[..., None])[..., 0]
        return (
            ee
            + 2.0 * np.einsum("np,np->n", delta, rhs)
            + np.einsum("np,npq,nq->n", delta, self.G, delta)
        )


def _standard_error(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Standard error of ``sum(a) - sum(b)`` from the per-sample differences (paired)."""
    diff = a - b
    return float(np.std(diff, ddof=1) * math.sqrt(len(diff))) if len(diff) > 1 else math.inf


def _column_scales(lin: LinearisedFit) -> NDArray[np.float64]:
    """Per searched group the sigma at which the prior weighs as much as the data on one
    of its columns alone (``1 / |B_k|``, the median over the group's columns): the unit
    of its search, whatever the prior it was fitted under."""
    norms = np.linalg.norm(lin.B, axis=0)
    return np.array(
        [1.0 / np.median(norms[lin.group == i]) for i in range(len(lin.keys))], dtype=float
    )


def _search_coordinate(
    held: LinearLeaveOneOut, sigmas: NDArray[np.float64], members: NDArray, lo: float, hi: float
) -> tuple[NDArray[np.float64], float]:
    """``sigmas`` with the groups ``members`` set to one sigma, the best of a log scan
    over ``[lo, hi]``, none (inf) and golden-section search in the best bracket; and its
    score."""

    def at(log_sigma: float) -> float:
        trial = sigmas.copy()
        trial[members] = math.exp(log_sigma) if math.isfinite(log_sigma) else math.inf
        return held.score(trial)

    grid = np.linspace(math.log(lo), math.log(hi), SCAN_POINTS)
    scores = [at(v) for v in grid]
    flat = at(math.inf)
    j = int(np.argmin(scores))
    if flat < scores[j]:
        best_log, best = math.inf, flat
    else:
        a, c = grid[max(j - 1, 0)], grid[min(j + 1, len(grid) - 1)]
        best_log, best = _golden(at, a, c, grid[j], scores[j])
    out = sigmas.copy()
    out[members] = math.exp(best_log) if math.isfinite(best_log) else math.inf
    return out, best


def _descent(
    held: LinearLeaveOneOut,
    sigmas: NDArray[np.float64],
    coordinates: list[tuple[NDArray, float, float]],
) -> tuple[NDArray[np.float64], float]:
    """Coordinate descent of the score over ``coordinates`` (groups sharing one sigma,
    its bounds), from ``sigmas``: the sigmas and their score."""
    best = held.score(sigmas)
    for _ in range(SWEEPS):
        before = best
        for members, lo, hi in coordinates:
            trial, score = _search_coordinate(held, sigmas, members, lo, hi)
            if score < best:
                sigmas, best = trial, score
        if not before - best > SWEEP_TOL * abs(before):
            break
    return sigmas, best


def _golden(f, a: float, c: float, x0: float, f0: float) -> tuple[float, float]:
    """Minimum of ``f`` on ``[a, c]`` by :data:`GOLDEN_STEPS` golden-section steps,
    or ``(x0, f0)`` when no point tried is lower."""
    best_x, best_f = x0, f0
    x1, x2 = c - _INVPHI * (c - a), a + _INVPHI * (c - a)
    f1, f2 = f(x1), f(x2)
    for _ in range(GOLDEN_STEPS):
        if f1 <= f2:
            c, x2, f2 = x2, x1, f1
            x1 = c - _INVPHI * (c - a)
            f1 = f(x1)
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + _INVPHI * (c - a)
            f2 = f(x2)
    for x, fx in ((x1, f1), (x2, f2)):
        if fx < best_f:
            best_x, best_f = x, fx
    return best_x, best_f


def choose_prior(
    problem: LeastSquaresProblem,
    x: NDArray,
    noise,
    loss: str,
    k: NDArray,
    prior: PriorScales,
) -> tuple[PriorScales, float]:
    """The group sigmas that minimise the linearised leave-one-sample-out error of the
    fit ``x`` of ``problem`` under ``prior`` (the module docstring), and that error
    (``sum_i |e_{-i}|^2``, whitened).

    First one length and one angle sigma shared by :data:`UNIFORM_GROUPS` (over
    :data:`PHYSICAL_SPAN`), then every group with a free column the data see its own
    (no prior tried too), kept only when the score drops by more than the paired
    standard error of the difference; the groups the data do not touch keep
    ``prior``'s. Returns the scales with ``how="leave-one-out"`` (a group best without
    a prior left out).
    """
    lin = linearised_fit(problem, x, noise, loss, k)
    if not lin.keys:
        return prior, math.nan
    held = LinearLeaveOneOut(lin)
    unit = _column_scales(lin)
    lo, hi = unit * SEARCH_SPAN[0], unit * SEARCH_SPAN[1]
    for i, (_, u) in enumerate(lin.keys):
        if u in PHYSICAL_SPAN:
            lo[i], hi[i] = PHYSICAL_SPAN[u]
    sigmas = np.array([prior.sigma(g, u) for g, u in lin.keys], dtype=float)
    sigmas = np.where(np.isfinite(sigmas), np.clip(sigmas, lo, hi), np.inf)
    # one length and one angle sigma for the joints and the base first (the family of
    # --prior-mm/--prior-deg), then every group its own when that predicts better by
    # GROUP_GAIN: a sigma per group is more to choose from the same samples
    shared = []
    for unit_name in ("m", "rad"):
        members = np.array(
            [i for i, (g, u) in enumerate(lin.keys) if g in UNIFORM_GROUPS and u == unit_name],
            dtype=int,
        )
        if len(members):
            shared.append((members, float(lo[members].min()), float(hi[members].max())))
    uniform, score = _descent(held, sigmas, shared)
    own = [(np.array([i]), lo[i], hi[i]) for i in range(len(lin.keys))]
    by_group, group_score = _descent(held, uniform, own)
    gain = score - group_score
    if gain > _standard_error(held.per_sample(uniform), held.per_sample(by_group)):
        uniform = by_group
    chosen = dict(zip(lin.keys, uniform, strict=True))
    return prior.with_sigmas(chosen, "leave-one-out"), held.score(uniform)
