"""Maximum-likelihood hand-eye on SE(3): one robust refinement for ``A X = X B`` and
``A = X B Y``.

Both problems are one absolute-pose model, ``M[i] ≈ P @ N[i] @ Q`` with the camera's
measured pose ``M[i]`` and the robot's known pose ``N[i]``; the model, its noise model
(rotation and translation noise in the camera frame, scales estimated by variance
components) and the Levenberg-Marquardt fit are in :mod:`kinfw.identification.handeye`.
This module starts, robustifies and packs that fit (:func:`fit_absolute`) and evaluates
it at given transforms (:func:`assess`).

Start: the quaternion closed form of all poses
(:func:`kinfw.identification.handeye.closed_form_start`; Hirsh et al.'s fixed
point); other starts (Tsai & Lenz, Hirsh's iteration, the closed forms of
:mod:`kinfw.identification.handeye`) only when that fit is not clean.

Robustness: Huber IRLS on the whitened per-pose residual, then rejection of poses whose
squared whitened residual exceeds :func:`rejection_threshold` (the quantile of chi^2
with 6 degrees of freedom at ``1 - 0.01 / n``, and at least the 99.9 % quantile: a
false rejection in 1 % of clean data sets of any size; at most 5 % of the poses, at
least one: the worst), and a plain refit of the others (repeated while the set
changes). When a pose stays off and could have pulled the start (fewer than
``CONSENSUS_MAX_POSES`` poses, or more outliers than may be rejected), a consensus start
is tried as well: the closed form on every minimal subset of 3 poses (at most
``CONSENSUS_MAX_SUBSETS``), scored by the median residual of all poses.

Covariance: ``(J^T W J)^-1`` at the optimum with the estimated ``sigma_r``, ``sigma_t``,
in the order ``(dphi_P, dt_P, dphi_Q, dt_Q)`` (radians, input length unit).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from itertools import combinations

import numpy as np
from numpy.typing import NDArray

from kinfw.identification.handeye._lm import (
    LMFit,
    PoseData,
    fit_lm,
    robust_sigmas,
    variance_components,
)
from kinfw.identification.handeye._quaternion import (
    closed_form_batch,
    closed_form_start,
    consistent_quats,
    product_matrices,
)

__all__ = ["CHI2_6_999", "PoseFit", "assess", "fit_absolute", "rejection_threshold"]

#: 99.9 % quantile of chi^2 with 6 degrees of freedom: the rejection threshold of a pose's
#: squared whitened residual.
CHI2_6_999 = 22.457744484825323
#: Most minimal subsets scored by the consensus start.
CONSENSUS_MAX_SUBSETS = 400
#: From this many poses on, one outlier cannot pull the start far: the consensus start
#: runs only when more poses are off than may be rejected.
CONSENSUS_MAX_POSES = 30
#: Family-wise false-rejection rate of :func:`rejection_threshold` on clean data.
REJECTION_ALPHA = 0.01


@lru_cache(maxsize=64)
def rejection_threshold(n: int) -> float:
    """Squared whitened residual above which one of ``n`` poses is an outlier.

    The quantile of chi^2 with 6 degrees of freedom at ``1 - REJECTION_ALPHA / n``
    (Bonferroni: a clean data set of any size loses a pose with probability at most
    ``REJECTION_ALPHA``), and never below ``CHI2_6_999`` (the 99.9 % quantile, which it
    equals at ``n = 10``). Solved by bisection on chi^2_6's survival function
    ``exp(-x/2) (1 + x/2 + x^2/8)``.
    """
    p = REJECTION_ALPHA / max(n, 1)
    lo, hi = 0.0, 400.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if math.exp(-mid / 2.0) * (1.0 + mid / 2.0 + mid * mid / 8.0) > p:
            lo = mid
        else:
            hi = mid
    return max(CHI2_6_999, hi)


Start = Callable[[], tuple[NDArray[np.float64], NDArray[np.float64]]]


@dataclass(frozen=True, slots=True)
class PoseFit:
    """Maximum-likelihood fit of ``M[i] ≈ P @ N[i] @ Q`` (module docstring).

    Attributes
    ----------
    P, Q : ndarray, shape (4, 4)
        The estimates, input length unit.
    covariance : ndarray, shape (12, 12)
        Of ``(dphi_P, dt_P, dphi_Q, dt_Q)``: rotations right-perturbed (``R exp(dphi)``,
        radians, in the child frame), translations in the parent frame (input unit).
    sigma_rotation_rad, sigma_translation : float
        Estimated noise scales of the camera pose, per axis (radians, input unit).
    rotation_residuals, translation_residuals : ndarray, shape (n, 3)
        ``log(R_M R_hat^T)`` and ``t_M - t_hat`` of every pose (rejected ones included),
        in the camera frame.
    inliers : ndarray of bool, shape (n,)
        Poses used by the final fit.
    iterations : int
        Levenberg-Marquardt steps over all stages.
    converged : bool
        Whether the final fit stopped on its tolerance.
    fallback_starts_tried : int
        How many other starts were fitted (0: the first fit, from the closed form, was
        clean, or none were given).
    """

    P: NDArray[np.float64]
    Q: NDArray[np.float64]
    covariance: NDArray[np.float64]
    sigma_rotation_rad: float
    sigma_translation: float
    rotation_residuals: NDArray[np.float64]
    translation_residuals: NDArray[np.float64]
    inliers: NDArray[np.bool_]
    iterations: int
    converged: bool
    fallback_starts_tried: int = 0

    @property
    def rejected(self) -> tuple[int, ...]:
        """Indices of the poses left out as outliers."""
        return tuple(int(k) for k in np.flatnonzero(~self.inliers))


# ------------------------------------------------------------------------ consensus


@lru_cache(maxsize=16)
def _subsets(n: int) -> NDArray[np.intp]:
    """The minimal subsets the consensus start scores: all 3-subsets of ``n`` poses in
    lexicographic order, or ``CONSENSUS_MAX_SUBSETS`` of them evenly spaced in that order
    (picked while enumerating, not listed)."""
    total = math.comb(n, 3)
    if total <= CONSENSUS_MAX_SUBSETS:
        out = np.array(list(combinations(range(n), 3)), dtype=np.intp).reshape(-1, 3)
    else:
        pick = np.linspace(0, total - 1, CONSENSUS_MAX_SUBSETS).astype(int).tolist()
        wanted = iter(pick)
        nxt = next(wanted)
        rows = []
        for k, c in enumerate(combinations(range(n), 3)):
            while k == nxt:  # repeated ranks (none when total > the cap) kept as is
                rows.append(c)
                nxt = next(wanted, -1)
            if nxt < 0:
                break
        out = np.array(rows, dtype=np.intp)
    out.setflags(write=False)
    return out


def _consensus_start(data: PoseData, M: NDArray, N: NDArray) -> tuple[NDArray, NDArray]:
    """Best closed form over minimal subsets of 3 poses, scored by the median residuals
    of all poses (the product of the rotation and translation medians: unit-free).

    A residual's rotation angle is ``2 acos |q_P^T K_i q_Q|`` (quaternions, see
    :func:`kinfw.identification.handeye.closed_form_batch`) and its translation
    ``|R_P^T (t_M - t_P) - R_N t_Q - t_N|``: no rotation matrix per subset and pose.
    """
    q_M, q_N = consistent_quats(data.R_M, data.R_N)
    K = product_matrices(q_M, q_N)
    subsets = _subsets(data.n)
    P, Q, q_P, q_Q = closed_form_batch(
        K[subsets], data.R_M[subsets], data.t_M[subsets], data.R_N[subsets], data.t_N[subsets]
    )
    n, s = data.n, len(P)
    # matmul, not einsum: these are BLAS products (einsum's loops are ~10x slower here)
    qPK = (q_P @ K.transpose(1, 0, 2).reshape(4, 4 * n)).reshape(s, n, 4)
    ang = 2.0 * np.arccos(np.minimum(np.abs(np.sum(qPK * q_Q[:, None], axis=2)), 1.0))
    in_P = (data.t_M[None] - P[:, None, :3, 3]) @ P[:, :3, :3]
    R_N_t_Q = (data.R_N.reshape(3 * n, 3) @ Q[:, :3, 3].T).reshape(n, 3, s).transpose(2, 0, 1)
    dist = np.linalg.norm(in_P - R_N_t_Q - data.t_N[None], axis=2)
    score = np.log(np.median(ang, axis=1) + 1e-300) + np.log(np.median(dist, axis=1) + 1e-300)
    k = int(np.argmin(score))
    return P[k], Q[k]


# ------------------------------------------------------------------------------- fit


def _robust_fit(data: PoseData, P: NDArray, Q: NDArray, min_inliers: int) -> tuple[LMFit, int]:
    """Huber IRLS, then rejection above :func:`rejection_threshold` and plain refits;
    total steps."""
    r_r, r_t, _, _ = data.residuals(P, Q)
    s_r, s_t = robust_sigmas(r_r, r_t, data.length)
    everything = np.ones(data.n, dtype=bool)
    fit = fit_lm(data, P, Q, everything, s_r, s_t, huber=True)
    total = fit.steps
    inliers = everything
    for _ in range(4):
        new_inliers = _inlier_mask(fit, data, min_inliers)
        if np.array_equal(new_inliers, inliers) and total > fit.steps:
            break
        inliers = new_inliers
        fit = fit_lm(data, fit.P, fit.Q, inliers, fit.s_r, fit.s_t)
        total += fit.steps
    return fit, total


def fit_absolute(
    M: NDArray,
    N: NDArray,
    starts: Sequence[Start],
    *,
    robust: bool = True,
    min_inliers: int | None = None,
    fallback_starts: Callable[[], Sequence[tuple[NDArray, NDArray]]] | None = None,
    accept: Callable[[PoseFit], bool] | None = None,
) -> PoseFit:
    """Maximum-likelihood ``P, Q`` of ``M[i] ≈ P @ N[i] @ Q`` (module docstring).

    Parameters
    ----------
    M : ndarray, shape (n, 4, 4)
        Measured camera poses (``camera_T_target``), rigid, any length unit.
    N : ndarray, shape (n, 4, 4)
        Known robot poses, same unit.
    starts : sequence of callables
        Each returns a candidate ``(P, Q)`` (e.g. Tsai & Lenz, Hirsh's iteration). The
        fit starts from the closed form of all poses; only when that fit is not clean --
        poses rejected (with fewer than ``CONSENSUS_MAX_POSES`` poses), not converged,
        or ``accept`` says no -- are these candidates, and then those of
        ``fallback_starts``, fitted too, and the best fit is kept: at the first fit's
        noise scales, more poses within the rejection threshold, then the lower cost over
        them. A ``ValueError`` from a start means no candidate.
    robust : bool
        Huber IRLS, rejection and (when a pose stays off) the consensus start.
    min_inliers : int, optional
        Fewest poses kept; default: at most 5 % of the poses are rejected, at least one
        may be (the worst ones), and never fewer than 3 kept.
    fallback_starts : callable, optional
        Returns more candidates (e.g. other closed forms), tried after ``starts`` when
        the first fit is not clean; a ``ValueError`` from it means none.
    accept : callable, optional
        Whether a fit is clean beyond the above (e.g. its verdict is "determined").

    Returns
    -------
    PoseFit

    Notes
    -----
    The closed form is the fixed point of Hirsh's iteration and equals the truth on
    noise-free data at every rotation angle; the other starts cost time (Tsai & Lenz's
    pairs are O(n^2)) and change the answer only where the likelihood has more than
    one basin, which a clean fit rules out in practice.
    """
    data = PoseData(M, N)
    if min_inliers is None:
        min_inliers = max(3, data.n - max(1, data.n // 20))
    P, Q = closed_form_start(M, N)
    memo: dict = {}
    fit, inliers, steps = _fit_from(data, M, N, P, Q, robust, min_inliers, memo)
    result = _pose_fit(data, fit, inliers, steps)
    clean = result.converged and (inliers.all() or data.n >= CONSENSUS_MAX_POSES)
    if clean and (accept is None or accept(result)):
        return result
    # Not clean: the other starts may lead elsewhere; keep the best fit at the first
    # fit's noise scales (_better).
    s_r, s_t = fit.s_r, fit.s_t
    alternatives = []
    for start in starts:
        try:
            alternatives.append(start())
        except ValueError:
            continue
    if fallback_starts is not None:
        with contextlib.suppress(ValueError):
            alternatives.extend(fallback_starts())
    for P0, Q0 in alternatives:
        alt, alt_inliers, more = _fit_from(
            data, M, N, np.asarray(P0, float), np.asarray(Q0, float), robust, min_inliers, memo
        )
        steps += more
        if _better(data, alt, fit, s_r, s_t):
            fit, inliers = alt, alt_inliers
    return _pose_fit(data, fit, inliers, steps, fallback=len(alternatives))


def _better(data: PoseData, a: LMFit, b: LMFit, s_r: float, s_t: float) -> bool:
    """Whether fit ``a`` beats ``b`` at the same noise scales ``s_r, s_t``: more poses
    within :func:`rejection_threshold`, or as many with a lower cost ``sum (|r_r|^2 /
    s_r^2 + |r_t|^2 / s_t^2)`` over them. (Each fit's own inliers are not comparable: a
    fit in a wrong basin estimates huge noise scales and keeps every pose.)"""
    n_a, cost_a = _kept_and_cost(data, a, s_r, s_t)
    n_b, cost_b = _kept_and_cost(data, b, s_r, s_t)
    if n_a != n_b:
        return n_a > n_b
    return cost_a < cost_b * (1.0 - 1e-9)


def _kept_and_cost(data: PoseData, fit: LMFit, s_r: float, s_t: float) -> tuple[int, float]:
    r_r, r_t, _, _ = data.residuals(fit.P, fit.Q)
    chi2 = np.sum(r_r**2, axis=1) / s_r**2 + np.sum(r_t**2, axis=1) / s_t**2
    kept = chi2 <= rejection_threshold(data.n)
    return int(np.count_nonzero(kept)), float(chi2[kept].sum())


def _fit_from(
    data: PoseData,
    M: NDArray,
    N: NDArray,
    P: NDArray,
    Q: NDArray,
    robust: bool,
    min_inliers: int,
    memo: dict,
) -> tuple[LMFit, NDArray[np.bool_], int]:
    """The fit from one start: plain, then (``robust``, a pose off) Huber, rejection and
    the consensus start; the fit, its inliers and its steps."""
    r_r, r_t, _, _ = data.residuals(P, Q)
    s_r, s_t = robust_sigmas(r_r, r_t, data.length)
    everything = np.ones(data.n, dtype=bool)
    fit = fit_lm(data, P, Q, everything, s_r, s_t)
    steps = fit.steps
    for plain, result in memo.get("plain", []):
        # an earlier start's plain fit ended here too: the rest is the same
        if np.abs(plain.P - fit.P).max() < 1e-11 * max(1.0, data.length) and (
            np.abs(plain.Q - fit.Q).max() < 1e-11 * max(1.0, data.length)
        ):
            return result[0], result[1], steps
    first_plain = fit
    inliers = everything
    threshold = rejection_threshold(data.n)
    if robust and data.n > 3 and np.any(fit.chi2 > threshold):
        fit, more = _robust_fit(data, fit.P, fit.Q, min_inliers)
        steps += more
        inliers = _inlier_mask(fit, data, min_inliers)
        if not inliers.all() and (
            5 <= data.n < CONSENSUS_MAX_POSES
            or np.count_nonzero(fit.chi2 > threshold) > data.n - min_inliers
        ):
            # a pose stays off and may have pulled the start: try a consensus start
            # (it depends on the data only: computed once per fit_absolute)
            if "consensus" not in memo:
                P1, Q1 = _consensus_start(data, M, N)
                alt, more = _robust_fit(data, P1, Q1, min_inliers)
                memo["consensus"] = (alt, _inlier_mask(alt, data, min_inliers))
                steps += more
            alt, alt_inliers = memo["consensus"]
            n_fit, n_alt = np.count_nonzero(inliers), np.count_nonzero(alt_inliers)
            if n_alt > n_fit or (
                n_alt == n_fit
                and _concentrated(data, alt.P, alt.Q, alt_inliers)
                < _concentrated(data, fit.P, fit.Q, inliers) - 1e-9
            ):
                fit, inliers = alt, alt_inliers
    memo.setdefault("plain", []).append((first_plain, (fit, inliers)))
    return fit, inliers, steps


def _pose_fit(
    data: PoseData, fit: LMFit, inliers: NDArray, steps: int, fallback: int = 0
) -> PoseFit:
    r_r, r_t, _, _ = data.residuals(fit.P, fit.Q)
    try:
        covariance = np.linalg.inv(fit.H)
    except np.linalg.LinAlgError:
        covariance = np.linalg.pinv(fit.H)
    return PoseFit(
        P=fit.P,
        Q=fit.Q,
        covariance=covariance,
        sigma_rotation_rad=float(fit.s_r),
        sigma_translation=float(fit.s_t),
        rotation_residuals=r_r,
        translation_residuals=r_t,
        inliers=inliers,
        iterations=int(steps),
        converged=bool(fit.converged),
        fallback_starts_tried=fallback,
    )


def _inlier_mask(fit: LMFit, data: PoseData, min_inliers: int) -> NDArray[np.bool_]:
    """The poses the final refit of :func:`_robust_fit` used (its H is over them)."""
    inliers = fit.chi2 <= rejection_threshold(data.n)
    if np.count_nonzero(inliers) < min_inliers:
        inliers = np.zeros(data.n, dtype=bool)
        inliers[np.argsort(fit.chi2, kind="stable")[:min_inliers]] = True
    return inliers


def _concentrated(data: PoseData, P: NDArray, Q: NDArray, inliers: NDArray) -> float:
    r_r, r_t, _, _ = data.residuals(P, Q)
    return float(
        np.log(np.sum(r_r[inliers] ** 2) + 1e-300) + np.log(np.sum(r_t[inliers] ** 2) + 1e-300)
    )


def assess(M: NDArray, N: NDArray, P: NDArray, Q: NDArray) -> PoseFit:
    """A :class:`PoseFit` at given ``P, Q`` (not moved): noise scales from the residuals
    (variance components) and the covariance the maximum-likelihood fit would have there."""
    data = PoseData(M, N)
    r_r, r_t, _, _ = data.residuals(P, Q)
    s_r, s_t, covariance = variance_components(data, P, Q)
    return PoseFit(
        P=P,
        Q=Q,
        covariance=covariance,
        sigma_rotation_rad=float(s_r),
        sigma_translation=float(s_t),
        rotation_residuals=r_r,
        translation_residuals=r_t,
        inliers=np.ones(data.n, dtype=bool),
        iterations=0,
        converged=True,
    )
