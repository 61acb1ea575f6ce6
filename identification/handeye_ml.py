"""Maximum-likelihood hand-eye on SE(3): one refinement for ``A X = X B`` and ``A = X B Y``.

The model
---------
Both hand-eye problems are one absolute-pose model: the camera's measured pose
``M[i]`` (``camera_T_target``) is the product of two unknown rigid transforms and the
robot's known pose ``N[i]``::

    M[i] ≈ P @ N[i] @ Q.

``A = X B Y`` (:func:`identification.axb.solve_axyb`) is it with ``M = A``, ``N = B``,
``P = X``, ``Q = Y``; ``A X = X B`` written for absolute poses (``A[i] X B[i] =
base_T_target``, :func:`identification.handeye.solve_axxb`) is it with ``M = B``,
``N = A^-1``, ``P = X^-1`` and ``Q = base_T_target``.

Noise model: the camera's pose is off by a rotation ``exp(e_r)`` and a translation
``e_t``, both expressed in the camera's frame::

    R_M = exp(e_r) R_P R_N R_Q,      t_M = t_P + R_P (R_N t_Q + t_N) + e_t,

with ``e_r ~ N(0, sigma_r^2 I3)`` (radians) and ``e_t ~ N(0, sigma_t^2 I3)`` (length),
independent over poses. The residuals ``r_r = log(R_M R_hat^T)`` and
``r_t = t_M - t_hat`` are then exactly the noise, and the maximum-likelihood estimate
minimises ``sum_i |r_r|^2 / sigma_r^2 + |r_t|^2 / sigma_t^2``. ``sigma_r`` and
``sigma_t`` are not given: they are estimated from the residuals (variance components,
each group's residual sum over its redundancy ``n_g - tr(H^-1 H_g)``), alternating with
the fit. The weights therefore scale with the length unit and the estimate does not
depend on it.

Minimisation: Levenberg-Marquardt on the manifold, ``R_P <- R_P exp(dphi_P)``,
``t_P <- t_P + dt_P`` (and the same for ``Q``), analytic Jacobians, vectorised over
poses. The rotation parametrisation has no singularity (a half turn is an ordinary
point).

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

from identification.handeye_quaternion import (
    closed_form_batch,
    closed_form_start,
    consistent_quats,
    product_matrices,
)
from kinfw.transforms import (
    rotation_vector_from_matrix,
    skew,
)

__all__ = ["CHI2_6_999", "PoseFit", "assess", "fit_absolute", "rejection_threshold"]

#: 99.9 % quantile of chi^2 with 6 degrees of freedom: the rejection threshold of a pose's
#: squared whitened residual.
CHI2_6_999 = 22.457744484825323
#: Huber's threshold on the whitened residual norm (sqrt of the 95 % quantile of chi^2_6).
HUBER_K = 3.5485
#: Median of chi^2 with 3 degrees of freedom (robust initial noise scales).
_CHI2_3_MEDIAN = 2.365974
#: Most minimal subsets scored by the consensus start.
CONSENSUS_MAX_SUBSETS = 400
#: From this many poses on, one outlier cannot pull the start far: the consensus start
#: runs only when more poses are off than may be rejected.
CONSENSUS_MAX_POSES = 30
#: Family-wise false-rejection rate of :func:`rejection_threshold` on clean data.
REJECTION_ALPHA = 0.01
#: Levenberg-Marquardt: most steps per fit.
LM_MAX_STEPS = 40
#: Levenberg-Marquardt: converged when a step is below this (radians, or relative to the
#: scene's length) and the noise scales changed by less than ``LM_SCALE_TOL`` (relative).
LM_STEP_TOL = 1e-9
LM_SCALE_TOL = 1e-7
#: Bounds of sigma_t / (sigma_r * L), L the RMS camera-target distance: keeps the
#: weights finite on noise-free data (rotation-only or translation-only noise).
_RATIO_BOUNDS = (1e-6, 1e6)


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


# ----------------------------------------------------------------------------- model


def _inverse_right_jacobian(phi: NDArray[np.float64]) -> NDArray[np.float64]:
    """``d log(exp(phi) exp(xi)) / d xi`` at ``xi = 0``, (n, 3) -> (n, 3, 3)."""
    theta = np.linalg.norm(phi, axis=-1)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    coef = np.where(
        small,
        1.0 / 12.0 + theta**2 / 720.0,
        1.0 / safe**2 - (1.0 + np.cos(safe)) / (2.0 * safe * np.sin(safe)),
    )
    K = skew(phi)
    return np.eye(3) + 0.5 * K + coef[:, None, None] * (K @ K)


def _residuals(
    R_M: NDArray, t_M: NDArray, R_N: NDArray, t_N: NDArray, P: NDArray, Q: NDArray
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """``r_r`` (n, 3), ``r_t`` (n, 3), ``R_hat`` (n, 3, 3) and ``v = R_N t_Q + t_N``."""
    R_P, t_P, R_Q, t_Q = P[:3, :3], P[:3, 3], Q[:3, :3], Q[:3, 3]
    R_hat = R_P @ R_N @ R_Q
    v = R_N @ t_Q + t_N
    r_r = _log_small(R_M @ np.swapaxes(R_hat, 1, 2))
    r_t = t_M - v @ R_P.T - t_P
    return r_r, r_t, R_hat, v


def _jacobian(r_r: NDArray, R_hat: NDArray, v: NDArray, R_N: NDArray, P: NDArray) -> NDArray:
    """Jacobian (n, 6, 12) of ``(r_r, r_t)`` in ``(dphi_P, dt_P, dphi_Q, dt_Q)``."""
    n = len(r_r)
    R_P = P[:3, :3]
    Jinv = _inverse_right_jacobian(r_r)
    J = np.zeros((n, 6, 12))
    J[:, :3, 0:3] = -Jinv @ R_P
    J[:, :3, 6:9] = -Jinv @ R_hat
    J[:, 3:, 0:3] = R_P @ skew(v)
    J[:, 3:, 3:6] = -np.eye(3)
    J[:, 3:, 9:12] = -(R_P @ R_N)
    return J


def _update(T: NDArray, dphi: NDArray, dt: NDArray) -> NDArray:
    """``(R exp(dphi), t + dt)`` for one transform (Rodrigues, scalar arithmetic)."""
    theta = float(np.sqrt(dphi @ dphi))
    K = np.array([[0.0, -dphi[2], dphi[1]], [dphi[2], 0.0, -dphi[0]], [-dphi[1], dphi[0], 0.0]])
    if theta < 1e-8:
        a, b = 1.0 - theta**2 / 6.0, 0.5 - theta**2 / 24.0
    else:
        a, b = np.sin(theta) / theta, (1.0 - np.cos(theta)) / theta**2
    out = np.eye(4)
    out[:3, :3] = T[:3, :3] @ (np.eye(3) + a * K + b * (K @ K))
    out[:3, 3] = T[:3, 3] + dt
    return out


def _log_small(R: NDArray) -> NDArray:
    """Rotation vectors of rotations (n, 3, 3), fast when all are below ~170 deg (the
    residuals); otherwise :func:`kinfw.transforms.rotation_vector_from_matrix`."""
    v = 0.5 * np.stack(
        [R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], 1
    )
    s = np.sqrt(np.einsum("ni,ni->n", v, v))
    c = 0.5 * (R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2] - 1.0)
    if np.any(c < -0.98):
        return rotation_vector_from_matrix(R)
    theta = np.arctan2(s, c)
    factor = np.where(s < 1e-8, 1.0 + theta**2 / 6.0, theta / np.where(s < 1e-8, 1.0, s))
    return v * factor[:, None]


class _Data:
    """The poses split into rotations and translations, and the scene's length scale."""

    def __init__(self, M: NDArray, N: NDArray) -> None:
        self.R_M, self.t_M = M[:, :3, :3], M[:, :3, 3]
        self.R_N, self.t_N = N[:, :3, :3], N[:, :3, 3]
        self.n = len(M)
        length = float(np.sqrt(np.mean(np.sum(self.t_M**2, axis=1))))
        if length == 0.0:
            length = float(np.sqrt(np.mean(np.sum(self.t_N**2, axis=1))))
        self.length = length if length > 0.0 else 1.0

    def residuals(self, P: NDArray, Q: NDArray):
        return _residuals(self.R_M, self.t_M, self.R_N, self.t_N, P, Q)


def _bounded_sigmas(s_r: float, s_t: float, length: float) -> tuple[float, float]:
    """Keep ``s_t / (s_r L)`` within ``_RATIO_BOUNDS`` and both positive."""
    tiny = 1e-15
    s_r, s_t = max(s_r, tiny), max(s_t, tiny * length)
    lo, hi = _RATIO_BOUNDS
    ratio = s_t / (s_r * length)
    if ratio < lo:
        s_t = lo * s_r * length
    elif ratio > hi:
        s_r = s_t / (hi * length)
    return s_r, s_t


def _medians(a: NDArray, b: NDArray) -> tuple[float, float]:
    """``np.median`` of two vectors of one length (n,), in one sort."""
    s = np.sort(np.stack([a, b]), axis=1)
    m = s.shape[1] // 2
    if s.shape[1] % 2:
        return float(s[0, m]), float(s[1, m])
    return float(0.5 * (s[0, m - 1] + s[0, m])), float(0.5 * (s[1, m - 1] + s[1, m]))


def _robust_sigmas(r_r: NDArray, r_t: NDArray, length: float) -> tuple[float, float]:
    """Noise scales from the median residual norms (3-D isotropic Gaussian)."""
    m_r, m_t = _medians(np.sum(r_r**2, axis=1), np.sum(r_t**2, axis=1))
    s_r = math.sqrt(m_r / _CHI2_3_MEDIAN)
    s_t = math.sqrt(m_t / _CHI2_3_MEDIAN)
    return _bounded_sigmas(s_r, s_t, length)


def _step_size(delta: NDArray, length: float) -> float:
    """Largest rotation (rad) or translation (relative to ``length``) of a step."""
    return max(
        float(np.abs(delta[[0, 1, 2, 6, 7, 8]]).max()),
        float(np.abs(delta[[3, 4, 5, 9, 10, 11]]).max()) / length,
    )


def _normal_matrices(
    data: _Data, P: NDArray, Q: NDArray, weights: NDArray, w_r: float, w_t: float
) -> tuple[NDArray, NDArray]:
    """The rotation and translation parts of ``J^T W J`` at ``P, Q``."""
    r_r, _, R_hat, v = data.residuals(P, Q)
    J = _jacobian(r_r, R_hat, v, data.R_N, P) * np.sqrt(weights)[:, None, None]
    H_r = w_r * np.einsum("nki,nkj->ij", J[:, :3], J[:, :3])
    H_t = w_t * np.einsum("nki,nkj->ij", J[:, 3:], J[:, 3:])
    return H_r, H_t


@dataclass(frozen=True, slots=True)
class _Fit:
    P: NDArray
    Q: NDArray
    s_r: float
    s_t: float
    H: NDArray  # J^T W J at the end, inliers only, no Huber weights
    chi2: NDArray  # squared whitened residual of every pose
    steps: int
    converged: bool


def _exp_update(T: NDArray, d: NDArray) -> NDArray:
    """``(R exp(d[:3]), t + d[3:])`` for one transform (Rodrigues in scalar arithmetic:
    ``K^2 = d d^T - theta^2 I``)."""
    x, y, z, dx, dy, dz = d.tolist()
    th2 = x * x + y * y + z * z
    if th2 < 1e-16:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = math.sqrt(th2)
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    E = np.array(
        [
            [1.0 - b * (y * y + z * z), -a * z + b * x * y, a * y + b * x * z],
            [a * z + b * x * y, 1.0 - b * (x * x + z * z), -a * x + b * y * z],
            [-a * y + b * x * z, a * x + b * y * z, 1.0 - b * (x * x + y * y)],
        ]
    )
    out = np.empty((4, 4))
    out[:3, :3] = T[:3, :3] @ E
    out[:3, 3] = T[:3, 3] + (dx, dy, dz)
    out[3] = (0.0, 0.0, 0.0, 1.0)
    return out


_I, _J = np.array([2, 0, 1]), np.array([1, 2, 0])
_DIAG = np.arange(3)
#: Off-diagonal entries of skew(w): rows, columns, source component and sign.
_SK_ROW = np.array([0, 0, 1, 1, 2, 2])
_SK_COL = np.array([1, 2, 0, 2, 0, 1])
_SK_SRC = np.array([2, 1, 2, 0, 1, 0])
_SK_SIGN = np.array([-1.0, 1.0, 1.0, -1.0, -1.0, 1.0])


class _Lean:
    """Residuals (n, 6) and Jacobian (n, 6, 12) of the model with few numpy calls: the
    LM's inner loop (same quantities as :func:`_residuals` and :func:`_jacobian`)."""

    def __init__(self, data: _Data) -> None:
        self.d = data
        self.J = np.zeros((data.n, 6, 12))
        self.J[:, 3:, 3:6] = -np.eye(3)
        self.K = np.zeros((data.n, 3, 3))  # skew-symmetric scratch

    def residuals(self, P: NDArray, Q: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        d = self.d
        R_P = P[:3, :3]
        RPN = R_P @ d.R_N
        R_hat = RPN @ Q[:3, :3]
        v = d.R_N @ Q[:3, 3] + d.t_N
        r = np.empty((d.n, 6))
        E = d.R_M @ np.swapaxes(R_hat, 1, 2)
        c = 0.5 * (np.einsum("nii->n", E) - 1.0)
        if c.min() < -0.98:
            r[:, :3] = rotation_vector_from_matrix(E)
        else:  # as _log_small
            vec = 0.5 * (E[:, _I, _J] - E[:, _J, _I])
            s = np.sqrt(np.einsum("ni,ni->n", vec, vec))
            theta = np.arctan2(s, c)
            tiny = s < 1e-8
            r[:, :3] = (
                vec * np.where(tiny, 1.0 + theta**2 / 6.0, theta / np.where(tiny, 1.0, s))[:, None]
            )
        r[:, 3:] = d.t_M - v @ R_P.T - P[:3, 3]
        return r, RPN, R_hat, v

    def jacobian(self, r: NDArray, RPN: NDArray, R_hat: NDArray, v: NDArray, P: NDArray):
        J = self.J
        R_P = P[:3, :3]
        phi = r[:, :3]
        th2 = np.einsum("ni,ni->n", phi, phi)
        theta = np.sqrt(th2)
        small = theta < 1e-4
        safe = np.where(small, 1.0, theta)
        coef = np.where(
            small,
            1.0 / 12.0 + th2 / 720.0,
            1.0 / safe**2 - (1.0 + np.cos(safe)) / (2.0 * safe * np.sin(safe)),
        )
        # as _inverse_right_jacobian: I + K / 2 + coef K^2, K^2 = phi phi^T - theta^2 I
        K = self.K
        K[:, _SK_ROW, _SK_COL] = phi[:, _SK_SRC] * _SK_SIGN
        Jinv = 0.5 * K + coef[:, None, None] * (phi[:, :, None] * phi[:, None, :])
        Jinv[:, _DIAG, _DIAG] += (1.0 - coef * th2)[:, None]
        J[:, :3, 0:3] = -Jinv @ R_P
        J[:, :3, 6:9] = -Jinv @ R_hat
        K[:, _SK_ROW, _SK_COL] = v[:, _SK_SRC] * _SK_SIGN
        J[:, 3:, 0:3] = R_P @ K
        J[:, 3:, 9:12] = -RPN
        return J


def _fit(
    data: _Data,
    P: NDArray,
    Q: NDArray,
    mask: NDArray,
    s_r: float,
    s_t: float,
    *,
    huber: bool = False,
    max_steps: int = LM_MAX_STEPS,
) -> _Fit:
    """Levenberg-Marquardt on ``sum_i c_i (|r_r|^2 / s_r^2 + |r_t|^2 / s_t^2)`` over the
    poses in ``mask``, the noise scales re-estimated after every step (variance
    components: each group's weighted residual sum over its redundancy) and, with
    ``huber``, ``c_i`` Huber's weights of the whitened residual norms (IRLS).

    Re-estimating the scales each step is Gauss-Newton on ``sum_g red_g log RSS_g``: it
    converges with the parameters instead of in outer rounds; linearly, so the ratio of
    the scales is extrapolated (Aitken) from two successive changes. With little redundancy
    (fewer than 4 poses) the scales stay as given. Below ~1e-7 the cost's rounding hides
    the decrease: near the optimum the Gauss-Newton steps contract, so they are taken as
    they come. Converged: a step below ``LM_STEP_TOL`` (radians, or relative to the
    scene's length) with the scales settled to ``LM_SCALE_TOL`` (relative).
    """
    lean = _Lean(data)
    n = data.n
    n_in = float(np.count_nonzero(mask))
    update_scales = n_in >= 4
    maskf = mask.astype(float)
    r, RPN, R_hat, v = lean.residuals(P, Q)
    lam = 1e-6
    steps = 0
    converged = False
    size = change = 0.0
    last_du: float | None = None
    new_cost = 1.0
    length = data.length
    while steps < max_steps:
        steps += 1
        r2 = r * r
        e2 = r2.reshape(n, 2, 3).sum(axis=2)  # (n, 2): |r_r|^2, |r_t|^2
        chi = e2 @ (1.0 / s_r**2, 1.0 / s_t**2)
        c = maskf
        if huber:
            c = maskf * np.minimum(1.0, HUBER_K / np.maximum(np.sqrt(chi), 1e-300))
        cost = float(c @ chi)
        J = lean.jacobian(r, RPN, R_hat, v, P)
        sc = np.sqrt(c)[:, None]
        Jr = (J[:, :3] * (sc / s_r)[:, :, None]).reshape(-1, 12)
        Jt = (J[:, 3:] * (sc / s_t)[:, :, None]).reshape(-1, 12)
        H_r = Jr.T @ Jr
        H_t = Jt.T @ Jt
        g = Jr.T @ (r[:, :3] * (sc / s_r)).ravel() + Jt.T @ (r[:, 3:] * (sc / s_t)).ravel()
        H = H_r + H_t
        D = np.maximum(H.diagonal(), 1e-300)
        w = (1.0 / s_r**2, 1.0 / s_r**2, 1.0 / s_r**2, 1.0 / s_t**2, 1.0 / s_t**2, 1.0 / s_t**2)
        while True:
            try:
                delta = -np.linalg.solve(H + lam * np.diag(D), g)
            except np.linalg.LinAlgError:
                delta = -np.linalg.lstsq(H + lam * np.diag(D), g, rcond=None)[0]
            P_new = _exp_update(P, delta[0:6])
            Q_new = _exp_update(Q, delta[6:12])
            n_r, n_RPN, n_R, n_v = lean.residuals(P_new, Q_new)
            new_cost = float(c @ ((n_r * n_r) @ w))
            dl = np.abs(delta).tolist()
            size = max(max(dl[0:3] + dl[6:9]), max(dl[3:6] + dl[9:12]) / length)
            if new_cost <= cost or size < 1e-7:
                break
            lam *= 10.0
            if lam > 1e12:
                break
        if lam > 1e12:  # no step lowers the cost: at the optimum to rounding
            converged = True
            break
        lam = max(lam / 10.0, 1e-12)
        P, Q, r, RPN, R_hat, v = P_new, Q_new, n_r, n_RPN, n_R, n_v
        change = 0.0
        if update_scales:
            try:
                Hinv = np.linalg.inv(H)
            except np.linalg.LinAlgError:
                Hinv = np.linalg.pinv(H)
            csum = 3.0 * float(c.sum())
            red_r = csum - float(np.sum(Hinv * H_r.T))
            red_t = csum - float(np.sum(Hinv * H_t.T))
            ss_r, ss_t = (c @ (r * r).reshape(n, 2, 3).sum(axis=2)).tolist()
            new_r = math.sqrt(ss_r / red_r) if red_r > 1e-9 else s_r
            new_t = math.sqrt(ss_t / red_t) if red_t > 1e-9 else s_t
            new_r, new_t = _bounded_sigmas(new_r, new_t, length)
            change = max(abs(math.log(new_r / s_r)), abs(math.log(new_t / s_t)))
            # The scales' ratio converges linearly (factor rho ~ 0.1): Aitken's
            # extrapolation of log(s_t / s_r) from two successive changes.
            du = math.log(new_t / new_r) - math.log(s_t / s_r)
            if last_du is not None and last_du != 0.0 and 0.0 < du / last_du < 0.8:
                rho = du / last_du
                jump = du * rho / (1.0 - rho)
                new_t *= math.exp(jump)
                change = max(change, abs(jump))
                last_du = None
            else:
                last_du = du
            s_r, s_t = new_r, new_t
        if (size < LM_STEP_TOL and change < LM_SCALE_TOL) or new_cost == 0.0:
            converged = True
            break
    J = lean.jacobian(r, RPN, R_hat, v, P)
    sm = np.sqrt(maskf)[:, None]
    Jr = (J[:, :3] * (sm / s_r)[:, :, None]).reshape(-1, 12)
    Jt = (J[:, 3:] * (sm / s_t)[:, :, None]).reshape(-1, 12)
    H = Jr.T @ Jr + Jt.T @ Jt
    chi2 = (r * r).reshape(n, 2, 3).sum(axis=2) @ (1.0 / s_r**2, 1.0 / s_t**2)
    return _Fit(P, Q, s_r, s_t, H, chi2, steps, converged)


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


def _consensus_start(data: _Data, M: NDArray, N: NDArray) -> tuple[NDArray, NDArray]:
    """Best closed form over minimal subsets of 3 poses, scored by the median residuals
    of all poses (the product of the rotation and translation medians: unit-free).

    A residual's rotation angle is ``2 acos |q_P^T K_i q_Q|`` (quaternions, see
    :func:`identification.handeye_quaternion.closed_form_batch`) and its translation
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


def _robust_fit(data: _Data, P: NDArray, Q: NDArray, min_inliers: int) -> tuple[_Fit, int]:
    """Huber IRLS, then rejection above :func:`rejection_threshold` and plain refits;
    total steps."""
    r_r, r_t, _, _ = data.residuals(P, Q)
    s_r, s_t = _robust_sigmas(r_r, r_t, data.length)
    everything = np.ones(data.n, dtype=bool)
    fit = _fit(data, P, Q, everything, s_r, s_t, huber=True)
    total = fit.steps
    inliers = everything
    for _ in range(4):
        new_inliers = _inlier_mask(fit, data, min_inliers)
        if np.array_equal(new_inliers, inliers) and total > fit.steps:
            break
        inliers = new_inliers
        fit = _fit(data, fit.P, fit.Q, inliers, fit.s_r, fit.s_t)
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
    data = _Data(M, N)
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


def _better(data: _Data, a: _Fit, b: _Fit, s_r: float, s_t: float) -> bool:
    """Whether fit ``a`` beats ``b`` at the same noise scales ``s_r, s_t``: more poses
    within :func:`rejection_threshold`, or as many with a lower cost ``sum (|r_r|^2 /
    s_r^2 + |r_t|^2 / s_t^2)`` over them. (Each fit's own inliers are not comparable: a
    fit in a wrong basin estimates huge noise scales and keeps every pose.)"""
    n_a, cost_a = _kept_and_cost(data, a, s_r, s_t)
    n_b, cost_b = _kept_and_cost(data, b, s_r, s_t)
    if n_a != n_b:
        return n_a > n_b
    return cost_a < cost_b * (1.0 - 1e-9)


def _kept_and_cost(data: _Data, fit: _Fit, s_r: float, s_t: float) -> tuple[int, float]:
    r_r, r_t, _, _ = data.residuals(fit.P, fit.Q)
    chi2 = np.sum(r_r**2, axis=1) / s_r**2 + np.sum(r_t**2, axis=1) / s_t**2
    kept = chi2 <= rejection_threshold(data.n)
    return int(np.count_nonzero(kept)), float(chi2[kept].sum())


def _fit_from(
    data: _Data,
    M: NDArray,
    N: NDArray,
    P: NDArray,
    Q: NDArray,
    robust: bool,
    min_inliers: int,
    memo: dict,
) -> tuple[_Fit, NDArray[np.bool_], int]:
    """The fit from one start: plain, then (``robust``, a pose off) Huber, rejection and
    the consensus start; the fit, its inliers and its steps."""
    r_r, r_t, _, _ = data.residuals(P, Q)
    s_r, s_t = _robust_sigmas(r_r, r_t, data.length)
    everything = np.ones(data.n, dtype=bool)
    fit = _fit(data, P, Q, everything, s_r, s_t)
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


def _pose_fit(data: _Data, fit: _Fit, inliers: NDArray, steps: int, fallback: int = 0) -> PoseFit:
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


def _inlier_mask(fit: _Fit, data: _Data, min_inliers: int) -> NDArray[np.bool_]:
    """The poses the final refit of :func:`_robust_fit` used (its H is over them)."""
    inliers = fit.chi2 <= rejection_threshold(data.n)
    if np.count_nonzero(inliers) < min_inliers:
        inliers = np.zeros(data.n, dtype=bool)
        inliers[np.argsort(fit.chi2, kind="stable")[:min_inliers]] = True
    return inliers


def _concentrated(data: _Data, P: NDArray, Q: NDArray, inliers: NDArray) -> float:
    r_r, r_t, _, _ = data.residuals(P, Q)
    return float(
        np.log(np.sum(r_r[inliers] ** 2) + 1e-300) + np.log(np.sum(r_t[inliers] ** 2) + 1e-300)
    )


def assess(M: NDArray, N: NDArray, P: NDArray, Q: NDArray) -> PoseFit:
    """A :class:`PoseFit` at given ``P, Q`` (not moved): noise scales from the residuals
    (variance components) and the covariance the maximum-likelihood fit would have there."""
    data = _Data(M, N)
    r_r, r_t, _, _ = data.residuals(P, Q)
    s_r, s_t = _robust_sigmas(r_r, r_t, data.length)
    ones = np.ones(data.n)
    for _ in range(3):
        H_r, H_t = _normal_matrices(data, P, Q, ones, 1.0 / s_r**2, 1.0 / s_t**2)
        Hinv = np.linalg.pinv(H_r + H_t)
        red_r = 3.0 * data.n - float(np.trace(Hinv @ H_r))
        red_t = 3.0 * data.n - float(np.trace(Hinv @ H_t))
        s_r = np.sqrt(np.sum(r_r**2) / red_r) if red_r > 1e-9 else s_r
        s_t = np.sqrt(np.sum(r_t**2) / red_t) if red_t > 1e-9 else s_t
        s_r, s_t = _bounded_sigmas(s_r, s_t, data.length)
    H_r, H_t = _normal_matrices(data, P, Q, ones, 1.0 / s_r**2, 1.0 / s_t**2)
    return PoseFit(
        P=P,
        Q=Q,
        covariance=np.linalg.pinv(H_r + H_t),
        sigma_rotation_rad=float(s_r),
        sigma_translation=float(s_t),
        rotation_residuals=r_r,
        translation_residuals=r_t,
        inliers=np.ones(data.n, dtype=bool),
        iterations=0,
        converged=True,
    )
