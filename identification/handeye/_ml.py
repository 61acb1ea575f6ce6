"""Maximum-likelihood hand-eye on SE(3): one robust refinement for both solvers
(Tsai & Lenz's ``A X = X B`` and Hirsh et al.'s ``A = X B Y``).

Both problems are one absolute-pose model,
``camera_T_target[i] ≈ camera_T_hand @ hand_T_base[i] @ base_T_target`` with the
camera's measured pose ``camera_T_target[i]`` and the robot's known pose
``hand_T_base[i]`` (in the code Hirsh's letters ``A[i] ≈ X @ B[i] @ Y``); the model,
its noise model (rotation and translation noise in the camera frame, scales estimated by
variance components) and the Levenberg-Marquardt fit are in
:mod:`kinfw.identification.handeye`.
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
in the order ``(dphi_X, dt_X, dphi_Y, dt_Y)`` (radians, input length unit).
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
    consistent_quats_xyzw,
    product_matrices,
)

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
    """Maximum-likelihood fit of
    ``camera_T_target[i] ≈ camera_T_hand @ hand_T_base[i] @ base_T_target`` (module
    docstring).

    Attributes
    ----------
    camera_T_hand, base_T_target : ndarray, shape (4, 4)
        The estimates (Hirsh's ``X``, ``Y``), input length unit.
    covariance : ndarray, shape (12, 12)
        Of ``(dphi_X, dt_X, dphi_Y, dt_Y)``: rotations right-perturbed (``R exp(dphi)``,
        radians, in the child frames hand and target), translations in the parent frames
        camera and base (input unit).
    sigma_rotation_rad, sigma_translation : float
        Estimated noise scales of the camera pose, per axis (radians, input unit).
    rotation_residuals, translation_residuals : ndarray, shape (n, 3)
        ``log(R_A R_hat^T)`` and ``t_A - t_hat`` of every pose (rejected ones included),
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

    camera_T_hand: NDArray[np.float64]
    base_T_target: NDArray[np.float64]
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


def _consensus_start(data: PoseData) -> tuple[NDArray, NDArray]:
    """Best closed form over minimal subsets of 3 poses, scored by the median residuals
    of all poses (the product of the rotation and translation medians: unit-free).

    A residual's rotation angle is ``2 acos |q_X^T K_i q_Y|`` (quaternions, see
    :func:`kinfw.identification.handeye._quaternion.closed_form_batch`) and its translation
    ``|R_X^T (t_A - t_X) - R_B t_Y - t_B|``: no rotation matrix per subset and pose.
    """
    q_A, q_B = consistent_quats_xyzw(data.R_A, data.R_B)
    K = product_matrices(q_A, q_B)
    subsets = _subsets(data.n)
    X, Y, q_X, q_Y = closed_form_batch(
        K[subsets], data.R_A[subsets], data.t_A[subsets], data.R_B[subsets], data.t_B[subsets]
    )
    n, s = data.n, len(X)
    # matmul, not einsum: these are BLAS products (einsum's loops are ~10x slower here)
    qXK = (q_X @ K.transpose(1, 0, 2).reshape(4, 4 * n)).reshape(s, n, 4)
    ang = 2.0 * np.arccos(np.minimum(np.abs(np.sum(qXK * q_Y[:, None], axis=2)), 1.0))
    in_X = (data.t_A[None] - X[:, None, :3, 3]) @ X[:, :3, :3]
    R_B_t_Y = (data.R_B.reshape(3 * n, 3) @ Y[:, :3, 3].T).reshape(n, 3, s).transpose(2, 0, 1)
    dist = np.linalg.norm(in_X - R_B_t_Y - data.t_B[None], axis=2)
    score = np.log(np.median(ang, axis=1) + 1e-300) + np.log(np.median(dist, axis=1) + 1e-300)
    k = int(np.argmin(score))
    return X[k], Y[k]


# ------------------------------------------------------------------------------- fit


def _robust_fit(data: PoseData, X: NDArray, Y: NDArray, min_inliers: int) -> tuple[LMFit, int]:
    """Huber IRLS, then rejection above :func:`rejection_threshold` and plain refits;
    total steps."""
    r_r, r_t, _, _ = data.residuals(X, Y)
    s_r, s_t = robust_sigmas(r_r, r_t, data.length)
    everything = np.ones(data.n, dtype=bool)
    fit = fit_lm(data, X, Y, everything, s_r, s_t, huber=True)
    total = fit.steps
    inliers = everything
    for _ in range(4):
        new_inliers = _inlier_mask(fit, data, min_inliers)
        if np.array_equal(new_inliers, inliers) and total > fit.steps:
            break
        inliers = new_inliers
        fit = fit_lm(data, fit.camera_T_hand, fit.base_T_target, inliers, fit.s_r, fit.s_t)
        total += fit.steps
    return fit, total


def fit_absolute(
    camera_T_targets: NDArray,
    hand_T_bases: NDArray,
    starts: Sequence[Start],
    *,
    robust: bool = True,
    min_inliers: int | None = None,
    fallback_starts: Callable[[], Sequence[tuple[NDArray, NDArray]]] | None = None,
    accept: Callable[[PoseFit], bool] | None = None,
) -> PoseFit:
    """Maximum-likelihood ``camera_T_hand`` and ``base_T_target`` of
    ``camera_T_target[i] ≈ camera_T_hand @ hand_T_base[i] @ base_T_target`` (module
    docstring).

    Parameters
    ----------
    camera_T_targets : ndarray, shape (n, 4, 4)
        Measured camera poses (the target's pose in the camera), rigid, any length unit.
    hand_T_bases : ndarray, shape (n, 4, 4)
        Known robot poses (the base's pose in the hand), same unit.
    starts : sequence of callables
        Each returns a candidate ``(camera_T_hand, base_T_target)`` (e.g. Tsai & Lenz,
        Hirsh's iteration). The fit starts from the closed form of all poses; only when
        that fit is not clean -- poses rejected (with fewer than ``CONSENSUS_MAX_POSES``
        poses), not converged, or ``accept`` says no -- are these candidates, and then
        those of ``fallback_starts``, fitted too, and the best fit is kept: at the first
        fit's noise scales, more poses within the rejection threshold, then the lower
        cost over them. A ``ValueError`` from a start means no candidate.
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
    data = PoseData(camera_T_targets, hand_T_bases)
    if min_inliers is None:
        min_inliers = max(3, data.n - max(1, data.n // 20))
    X, Y = closed_form_start(camera_T_targets, hand_T_bases)
    memo: dict = {}
    fit, inliers, steps = _fit_from(data, X, Y, robust, min_inliers, memo)
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
    for X0, Y0 in alternatives:
        alt, alt_inliers, more = _fit_from(
            data, np.asarray(X0, float), np.asarray(Y0, float), robust, min_inliers, memo
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
    r_r, r_t, _, _ = data.residuals(fit.camera_T_hand, fit.base_T_target)
    chi2 = np.sum(r_r**2, axis=1) / s_r**2 + np.sum(r_t**2, axis=1) / s_t**2
    kept = chi2 <= rejection_threshold(data.n)
    return int(np.count_nonzero(kept)), float(chi2[kept].sum())


def _fit_from(
    data: PoseData,
    X: NDArray,
    Y: NDArray,
    robust: bool,
    min_inliers: int,
    memo: dict,
) -> tuple[LMFit, NDArray[np.bool_], int]:
    """The fit from one start: plain, then (``robust``, a pose off) Huber, rejection and
    the consensus start; the fit, its inliers and its steps."""
    r_r, r_t, _, _ = data.residuals(X, Y)
    s_r, s_t = robust_sigmas(r_r, r_t, data.length)
    everything = np.ones(data.n, dtype=bool)
    fit = fit_lm(data, X, Y, everything, s_r, s_t)
    steps = fit.steps
    same = 1e-11 * max(1.0, data.length)
    for plain, result in memo.get("plain", []):
        # an earlier start's plain fit ended here too: the rest is the same
        if (
            np.abs(plain.camera_T_hand - fit.camera_T_hand).max() < same
            and np.abs(plain.base_T_target - fit.base_T_target).max() < same
        ):
            return result[0], result[1], steps
    first_plain = fit
    inliers = everything
    threshold = rejection_threshold(data.n)
    if robust and data.n > 3 and np.any(fit.chi2 > threshold):
        fit, more = _robust_fit(data, fit.camera_T_hand, fit.base_T_target, min_inliers)
        steps += more
        inliers = _inlier_mask(fit, data, min_inliers)
        if not inliers.all() and (
            5 <= data.n < CONSENSUS_MAX_POSES
            or np.count_nonzero(fit.chi2 > threshold) > data.n - min_inliers
        ):
            # a pose stays off and may have pulled the start: try a consensus start
            # (it depends on the data only: computed once per fit_absolute)
            if "consensus" not in memo:
                X1, Y1 = _consensus_start(data)
                alt, more = _robust_fit(data, X1, Y1, min_inliers)
                memo["consensus"] = (alt, _inlier_mask(alt, data, min_inliers))
                steps += more
            alt, alt_inliers = memo["consensus"]
            n_fit, n_alt = np.count_nonzero(inliers), np.count_nonzero(alt_inliers)
            if n_alt > n_fit or (
                n_alt == n_fit
                and _concentrated(data, alt.camera_T_hand, alt.base_T_target, alt_inliers)
                < _concentrated(data, fit.camera_T_hand, fit.base_T_target, inliers) - 1e-9
            ):
                fit, inliers = alt, alt_inliers
    memo.setdefault("plain", []).append((first_plain, (fit, inliers)))
    return fit, inliers, steps


def _pose_fit(
    data: PoseData, fit: LMFit, inliers: NDArray, steps: int, fallback: int = 0
) -> PoseFit:
    r_r, r_t, _, _ = data.residuals(fit.camera_T_hand, fit.base_T_target)
    try:
        covariance = np.linalg.inv(fit.H)
    except np.linalg.LinAlgError:
        covariance = np.linalg.pinv(fit.H)
    return PoseFit(
        camera_T_hand=fit.camera_T_hand,
        base_T_target=fit.base_T_target,
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


def _concentrated(data: PoseData, X: NDArray, Y: NDArray, inliers: NDArray) -> float:
    r_r, r_t, _, _ = data.residuals(X, Y)
    return float(
        np.log(np.sum(r_r[inliers] ** 2) + 1e-300) + np.log(np.sum(r_t[inliers] ** 2) + 1e-300)
    )


def assess(
    camera_T_targets: NDArray, hand_T_bases: NDArray, camera_T_hand: NDArray, base_T_target: NDArray
) -> PoseFit:
    """A :class:`PoseFit` at given ``camera_T_hand`` and ``base_T_target`` (not moved):
    noise scales from the residuals (variance components) and the covariance the
    maximum-likelihood fit would have there. Poses as for :func:`fit_absolute`."""
    data = PoseData(camera_T_targets, hand_T_bases)
    r_r, r_t, _, _ = data.residuals(camera_T_hand, base_T_target)
    s_r, s_t, covariance = variance_components(data, camera_T_hand, base_T_target)
    return PoseFit(
        camera_T_hand=camera_T_hand,
        base_T_target=base_T_target,
        covariance=covariance,
        sigma_rotation_rad=float(s_r),
        sigma_translation=float(s_t),
        rotation_residuals=r_r,
        translation_residuals=r_t,
        inliers=np.ones(data.n, dtype=bool),
        iterations=0,
        converged=True,
    )
