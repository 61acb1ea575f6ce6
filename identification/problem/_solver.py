"""Levenberg-Marquardt with robust losses by iteratively reweighted least squares.

The solver sees only a function ``evaluate(x, with_jacobian) -> (r, J)`` of whitened
residuals and the problem's ``obs_sizes``: ``(observations, rows per observation)`` per
group (a robust loss weighs an observation by the norm of its rows).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from kinfw import progress
from kinfw.identification.problem._noise import norm2_cdf, quantile
from kinfw.observations import NoiseComponent

LOSSES = ("linear", "huber", "cauchy")

#: Where the robust losses depart from least squares by default, as a standard-normal
#: quantile ``z`` of each observation's clean whitened norm (:func:`thresholds`): 2.33
#: flags 1 % of clean observations.
LOSS_SCALE = 2.33

ObsSizes = Sequence[tuple[int, int]]

#: Relative norm (to the largest column) below which a column of the whitened Jacobian
#: is numerically zero: rounding, not information (a joint's axis tilt when the only
#: observed point lies on that axis has a column ~1e-12 of the others).
NEGLIGIBLE_COLUMN = 1e-10


def scaled_columns(J: NDArray) -> tuple[NDArray, NDArray]:
    """``J`` (N, P) with unit-norm columns, and the column norms ``c`` (P,).

    Columns below :data:`NEGLIGIBLE_COLUMN` of the largest norm are set to zero (with
    ``c = 1``) rather than scaled up: scaling rounding noise to unit norm would make a
    direction the data do not see look as determined as any other, and a solver step
    along it ``1 / c`` times too long (an axis walked to its chart's singularity).

    Returns
    -------
    Js : ndarray, shape (N, P)
    c : ndarray, shape (P,)
    """
    c = column_norms(J)
    tiny = negligible_columns(J, c)
    c = np.where(tiny, 1.0, c)
    return np.where(tiny, 0.0, J / c), c


#: Rows per block of the passes over a tall Jacobian (:func:`column_norms`,
#: :func:`leverages`, :func:`tall_r`, the normal equations): a block of a few hundred
#: columns stays in the cache, and no temporary of the Jacobian's size is made.
_BLOCK = 4096


def _blocks(n: int) -> range:
    """The first rows of the blocks of :data:`_BLOCK` rows of an (n, ...) array."""
    return range(0, n, _BLOCK)


def column_norms(A: NDArray) -> NDArray:
    """The Euclidean norm of each column of ``A`` (N, P), shape (P,): by blocks of rows,
    without a temporary of ``A``'s size."""
    n, p = A.shape
    s2 = np.zeros(p)
    for a in _blocks(n):
        block = A[a : a + _BLOCK]
        s2 += np.einsum("ij,ij->j", block, block)
    return np.sqrt(s2)


def normal_equations(
    J: NDArray, r: NDArray, row_scale: NDArray, columns: NDArray[np.bool_] | None = None
) -> tuple[NDArray, NDArray]:
    """``A^T A`` and ``A^T b`` of ``A = diag(row_scale) J[:, columns]`` and ``b = row_scale
    r``, by blocks of rows (no copy of ``J``).

    Parameters
    ----------
    J : ndarray, shape (N, P)
    r : ndarray, shape (N,)
    row_scale : ndarray, shape (N,)
    columns : ndarray of bool, shape (P,), optional
        The columns of ``J`` to use (default all).

    Returns
    -------
    G : ndarray, shape (p, p)
    g : ndarray, shape (p,)
    """
    p = J.shape[1] if columns is None else int(columns.sum())
    G, g = np.zeros((p, p)), np.zeros(p)
    for a in _blocks(len(J)):
        block = J[a : a + _BLOCK] if columns is None else J[a : a + _BLOCK, columns]
        w = row_scale[a : a + _BLOCK]
        A = block * w[:, None]
        G += A.T @ A
        g += A.T @ (r[a : a + _BLOCK] * w)
    return G, g


def _scaled_normal_equations(G: NDArray, g: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """``Js^T Js``, ``Js^T b`` and ``c`` of :func:`scaled_columns` ``(Js, c)`` of ``A``
    from ``G = A^T A`` and ``g = A^T b`` (:func:`normal_equations`): the column norms are
    the square roots of its diagonal, numerically zero columns give zero rows and
    columns."""
    c = np.sqrt(np.maximum(np.diag(G), 0.0))
    tiny = _negligible(c)
    c = np.where(tiny, 1.0, c)
    H = G / np.outer(c, c)
    H[tiny, :] = 0.0
    H[:, tiny] = 0.0
    return H, np.where(tiny, 0.0, g / c), c


def negligible_columns(J: NDArray, norms: NDArray | None = None) -> NDArray[np.bool_]:
    """Columns of ``J`` (N, P) whose norm is at most :data:`NEGLIGIBLE_COLUMN` of the
    largest (exact zeros included): parameters the data do not see, shape (P,)."""
    return _negligible(column_norms(J) if norms is None else norms)


def _negligible(c: NDArray) -> NDArray[np.bool_]:
    """Of the column norms ``c``, those at most :data:`NEGLIGIBLE_COLUMN` of the largest."""
    return c <= NEGLIGIBLE_COLUMN * (c.max() if c.size else 0.0)


def tall_r(A: NDArray, column_scale: NDArray) -> NDArray:
    """``R`` of a thin QR of ``A diag(column_scale)`` (A: (N, p)), by blocks of rows.

    Each block's ``R``, then the QR of the stacked ``R`` s (a tall-skinny QR): ``R^T R =
    A_s^T A_s`` and the singular values and right singular vectors of ``R`` are those of
    ``A_s`` to rounding (backward stable, rank-deficient ``A`` included), at the cost of
    ``R`` alone: no ``Q`` and no temporary of ``A``'s size.

    Returns
    -------
    R : ndarray, shape (min(N, p), p)
        Upper triangular (trapezoidal when N < p).
    """
    n = A.shape[0]
    if n <= 2 * _BLOCK:
        return np.linalg.qr(A[:n] * column_scale, mode="r")
    stacked = [np.linalg.qr(A[a : a + _BLOCK] * column_scale, mode="r") for a in _blocks(n)]
    return np.linalg.qr(np.vstack(stacked), mode="r")


def leverages(A: NDArray, row_scale: NDArray | None = None) -> NDArray:
    """Each row's leverage: the diagonal of the hat matrix ``A (A^T A)^+ A^T``, shape (N,).

    The squared row norms of ``Q`` of a thin QR of ``A`` (N, p), or of
    ``diag(row_scale) A`` when ``row_scale`` (N,) is given (without forming it). For a
    tall ``A`` whose unit-norm columns are well conditioned (reciprocal condition of ``R``
    above 1e-8), ``R`` comes from a QR by blocks of rows (:func:`tall_r`) and ``Q = A
    R^-1``, a block of rows at a time: the same numbers to rounding, without forming
    ``Q`` by Householder reflections (5-10 times slower for N >> p). Otherwise (rank
    deficient or ill conditioned) ``Q`` is numpy's thin QR of ``A``.
    """
    n, p = A.shape
    if row_scale is not None:
        A = _RowScaled(A, row_scale)
    if n > 2 * _BLOCK and p > 0:
        c = column_norms(A)
        if c.min() > 0.0:
            R = tall_r(A, 1.0 / c)
            d = np.abs(np.diag(R))
            if d.min() > 1e-8 * d.max():
                T = np.linalg.inv(R) / c[:, None]  # (A / c) R^-1 = A T
                h = np.empty(n)
                for a in _blocks(n):
                    Q = A[a : a + _BLOCK] @ T
                    h[a : a + _BLOCK] = np.einsum("ij,ij->i", Q, Q)
                return h
    A = A[:n]
    Q, _ = np.linalg.qr(A)
    return np.sum(Q**2, axis=1)


#: :func:`leverage_sums` works from the normal matrix when the reciprocal condition of
#: its column-scaled Cholesky factor (that of the Jacobian) is above this: the sums are
#: then exact to ~1e-8 of the parameter count; otherwise :func:`leverages` decides.
_GRAM_RCOND = 1e-4


def leverage_sums(G: NDArray, by_component: dict[str, NDArray]) -> dict[str, float] | None:
    """Per noise component, the sum of the leverages of its rows, from the normal matrix.

    For the rows ``A_c`` of a component of ``A`` (N, p) with ``G = A^T A`` and
    ``G_c = A_c^T A_c``: ``sum_i h_i = trace(A_c G^-1 A_c^T) = trace(G^-1 G_c)``, linear
    in the rows (the matrices come from
    :meth:`~kinfw.identification.problem.LeastSquaresProblem.normal_equations`). None when
    ``A`` has a zero column or its column-scaled Cholesky factor's reciprocal condition
    is not above :data:`_GRAM_RCOND`: then :func:`leverages` of the rows themselves.

    Parameters
    ----------
    G : ndarray, shape (p, p)
    by_component : dict of str to ndarray, shape (p, p)

    Returns
    -------
    dict of str to float, or None
    """
    c = np.sqrt(np.maximum(np.diag(G), 0.0))
    if not len(c) or c.min() <= 0.0:
        return None
    try:
        L = np.linalg.cholesky(G / np.outer(c, c))
    except np.linalg.LinAlgError:
        return None
    d = np.abs(np.diag(L))
    if d.min() <= _GRAM_RCOND * d.max():
        return None
    # trace(Gs^-1 Gs_c) with Gs = G / (c c^T): the scaling cancels in the trace
    L_inv = np.linalg.inv(L) / c  # L^-1 D^-1, so that G^-1 = L_inv^T L_inv
    return {
        name: float(np.einsum("ij,ij->", L_inv @ Gc, L_inv)) for name, Gc in by_component.items()
    }


class _RowScaled:
    """``diag(row_scale) A`` read by slices of rows (``[a:b]``) without forming it."""

    def __init__(self, A: NDArray, row_scale: NDArray) -> None:
        self.A, self.row_scale, self.shape = A, row_scale, A.shape

    def __getitem__(self, rows: slice) -> NDArray:
        return self.A[rows] * self.row_scale[rows, None]


def observation_norms(r: NDArray, obs_sizes: ObsSizes) -> NDArray:
    """The norm of each observation's rows of ``r``."""
    out, k = [], 0
    for m, rows in obs_sizes:
        out.append(np.linalg.norm(r[k : k + m * rows].reshape(m, rows), axis=1))
        k += m * rows
    return np.concatenate(out)


def _repeat_rows(per_obs: NDArray, obs_sizes: ObsSizes) -> NDArray:
    out, k = [], 0
    for m, rows in obs_sizes:
        out.append(np.repeat(per_obs[k : k + m], rows))
        k += m
    return np.concatenate(out)


def thresholds(observations: Sequence[tuple[int, Sequence[NoiseComponent]]], z: float) -> NDArray:
    """Per observation, the ``Phi(z)`` quantile of the norm of its clean whitened residual.

    ``observations`` lists, per group, its number of observations and its noise
    components (:attr:`LeastSquaresProblem.obs_components`). Under the components' noise
    models (:func:`kinfw.identification.problem.norm2_cdf`): a point's squared norm is
    ``chi2(3)``, a pose's ``chi2(3) + 3 chi2(1)``, a prior row's ``chi2(1)``; exact
    quantiles, so ``z = 2.33`` flags 1 % of clean observations of every kind.
    """
    per_obs = [
        np.full(m, _threshold(tuple(components), float(z))) for m, components in observations
    ]
    return np.concatenate(per_obs) if per_obs else np.zeros(0)


@functools.lru_cache(maxsize=64)
def _threshold(components: tuple[NoiseComponent, ...], z: float) -> float:
    """The threshold of :func:`thresholds` for one set of components (computed once: the
    quadrature of a pose's distribution is not free)."""
    p = 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))
    return math.sqrt(quantile(norm2_cdf(components), p))


def robust_loss(s: NDArray, loss: str, k: NDArray) -> tuple[NDArray, NDArray]:
    """Loss rho(s) and IRLS weight rho'(s)/s of whitened residual norms ``s``."""
    if loss == "huber":
        # weight min(1, k / s), written without dividing by a zero residual
        return np.where(s <= k, 0.5 * s**2, k * s - 0.5 * k**2), k / np.maximum(s, k)
    if loss == "cauchy":
        return 0.5 * k**2 * np.log1p((s / k) ** 2), 1.0 / (1.0 + (s / k) ** 2)
    return 0.5 * s**2, np.ones_like(s)


def row_weights(r: NDArray, obs_sizes: ObsSizes, loss: str, k: NDArray) -> NDArray:
    """The IRLS weight of each row (its observation's weight)."""
    return _repeat_rows(robust_loss(observation_norms(r, obs_sizes), loss, k)[1], obs_sizes)


def levenberg_marquardt(
    evaluate: Callable[[NDArray, bool], tuple[NDArray, NDArray | None]],
    x: NDArray,
    free: NDArray,
    obs_sizes: ObsSizes,
    loss: str,
    k: NDArray,
    max_iterations: int,
    normal: Callable[[NDArray, NDArray], tuple[NDArray, NDArray]] | None = None,
) -> tuple[NDArray, int, bool]:
    """Levenberg-Marquardt with IRLS weights, in column-scaled coordinates.

    Steps solve ``(Js^T Js + lam I) y = -Js^T r`` with unit-norm columns ``Js``: no
    component along directions the Jacobian does not see (they stay at the start),
    numerically zero columns included (:func:`scaled_columns`). Converged when an
    accepted step decreases the cost by at most 1e-12 of it, or when a step is not taken:
    ``y`` shorter than 1e-12, or a step that raised the cost while the linear model
    promised a decrease below 1e-12 of it (the cost differs by rounding only).

    Parameters
    ----------
    evaluate : callable
        ``evaluate(x, with_jacobian) -> (r (N,), J (N, P) or None)``, whitened.
    x : ndarray, shape (P,)
        Start.
    free : ndarray of bool, shape (P,)
        Entries to move.
    obs_sizes : sequence of (observations, rows)
    loss : {"linear", "huber", "cauchy"}
    k : ndarray
        Per observation, the robust threshold (:func:`thresholds`).
    max_iterations : int
    normal : callable, optional
        ``normal(x, row_scale) -> (A^T A, A^T b)`` of the Jacobian's rows and residuals
        scaled by ``row_scale`` (N,), over all its columns (e.g.
        :meth:`~kinfw.identification.problem.LeastSquaresProblem.normal_equations`): then
        ``evaluate`` is only asked for residuals and the Jacobian is never formed.
        Default: from ``evaluate``'s Jacobian (:func:`normal_equations`).

    Returns
    -------
    x : ndarray, shape (P,)
    iterations : int
    converged : bool

    Notes
    -----
    Each iteration's cost, the sum of the robust loss over the observations
    (:func:`robust_loss`), is told to :mod:`kinfw.progress` (iteration 0: the start).
    """
    with progress.task("Levenberg-Marquardt", unit="iteration") as bar:
        return _levenberg_marquardt(
            evaluate, x, free, obs_sizes, loss, k, max_iterations, normal, bar
        )


def _levenberg_marquardt(evaluate, x, free, obs_sizes, loss, k, max_iterations, normal, bar):
    """:func:`levenberg_marquardt`, each cost told to ``bar``."""

    def cost_of(r):
        return float(robust_loss(observation_norms(r, obs_sizes), loss, k)[0].sum())

    def normal_matrix(x, r, J, w):
        if normal is None:
            return normal_equations(J, r, w, None if free.all() else free)
        G, g = normal(x, w)
        return (G, g) if free.all() else (G[np.ix_(free, free)], g[free])

    r, J = evaluate(x, normal is None)
    cost = cost_of(r)
    bar.advance(0, f"cost {cost:#.6g}")
    lam = 1e-6  # column-scaled: start close to Gauss-Newton
    converged = False
    it = 0
    for it in range(1, max_iterations + 1):
        w = np.sqrt(row_weights(r, obs_sizes, loss, k))
        H, g, c = _scaled_normal_equations(*normal_matrix(x, r, J, w))
        while True:
            y = -np.linalg.solve(H + lam * np.eye(len(H)), g)
            if np.linalg.norm(y) < 1e-12:
                # at the minimum to rounding: a step this short changes nothing, and its
                # cost only differs by rounding (retrying with a larger lam would spend
                # up to ~40 residual evaluations to learn that)
                bar.advance(1, f"cost {cost:#.6g}")
                return x, it, True
            x_new = x.copy()
            x_new[free] += y / c
            r_new, _ = evaluate(x_new, False)
            cost_new = cost_of(r_new)
            if cost_new <= cost:
                break
            if -(g @ y + 0.5 * y @ (H @ y)) <= 1e-12 * max(cost, 1e-300):
                # the model promises no more than the convergence threshold and the step
                # failed on rounding: shorter steps (a larger lam) promise even less
                bar.advance(1, f"cost {cost:#.6g}")
                return x, it, True
            lam *= 4.0
            if lam > 1e12:
                return x, it, converged
        decrease = cost - cost_new
        x, r, cost = x_new, r_new, cost_new
        bar.advance(1, f"cost {cost:#.6g}")
        lam = max(lam / 3.0, 1e-12)
        if decrease <= 1e-12 * max(cost, 1e-300) or np.linalg.norm(y) < 1e-12:
            converged = True
            break
        if normal is None:
            _, J = evaluate(x, True)
    return x, it, converged
