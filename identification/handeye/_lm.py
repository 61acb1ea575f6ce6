"""Maximum-likelihood model of the hand-eye on SE(3): residuals, Jacobian and the
Levenberg-Marquardt fit with variance components.

The model
---------
Both hand-eye problems are one absolute-pose model in the package's frames (eye-in-hand,
:mod:`kinfw.identification.handeye`): the camera's measured pose of the target is the
product of two unknown rigid transforms and the robot's known pose::

    camera_T_target[i] ≈ camera_T_hand @ hand_T_base[i] @ base_T_target.

In the code, the letters of Hirsh et al.'s ``A[i] ≈ X @ B[i] @ Y`` (the aliases of
:class:`kinfw.identification.handeye.AXYBResult`): ``A = camera_T_target``,
``B = hand_T_base``, ``X = camera_T_hand``, ``Y = base_T_target``.
:func:`kinfw.identification.handeye.solve_axyb` fits it as it stands;
:func:`kinfw.identification.handeye.solve_axxb` fits it too and reports
``hand_T_camera = inv(camera_T_hand)`` (Tsai & Lenz's ``X``).

Noise model: the camera's pose is off by a rotation ``exp(e_r)`` and a translation
``e_t``, both expressed in the camera's frame::

    R_A = exp(e_r) R_X R_B R_Y,      t_A = t_X + R_X (R_B t_Y + t_B) + e_t,

with ``e_r ~ N(0, sigma_r^2 I3)`` (radians) and ``e_t ~ N(0, sigma_t^2 I3)`` (length),
independent over poses. The residuals ``r_r = log(R_A R_hat^T)`` and
``r_t = t_A - t_hat`` are then exactly the noise, and the maximum-likelihood estimate
minimises ``sum_i |r_r|^2 / sigma_r^2 + |r_t|^2 / sigma_t^2``. ``sigma_r`` and
``sigma_t`` are not given: they are estimated from the residuals (variance components,
each group's residual sum over its redundancy ``n_g - tr(H^-1 H_g)``), alternating with
the fit. The weights therefore scale with the length unit and the estimate does not
depend on it.

Minimisation: Levenberg-Marquardt on the manifold, ``R_X <- R_X exp(dphi_X)``,
``t_X <- t_X + dt_X`` (and the same for ``Y``), analytic Jacobians, vectorised over
poses. The rotation parametrisation has no singularity (a half turn is an ordinary
point). With ``huber=True`` the poses are weighted by Huber's IRLS weights of their
whitened residual norms.

Covariance: ``(J^T W J)^-1`` at the optimum with the estimated ``sigma_r``, ``sigma_t``,
in the order ``(dphi_X, dt_X, dphi_Y, dt_Y)`` (radians, input length unit).

The robust stage, the starts and the result type are in :mod:`kinfw.identification.handeye`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw import progress
from kinfw.geometry import rotation_vector_from_matrix, skew

#: Huber's threshold on the whitened residual norm (sqrt of the 95 % quantile of chi^2_6).
HUBER_K = 3.5485
#: Median of chi^2 with 3 degrees of freedom (robust initial noise scales).
_CHI2_3_MEDIAN = 2.365974
#: Levenberg-Marquardt: most steps per fit.
LM_MAX_STEPS = 40
#: Levenberg-Marquardt: converged when a step is below this (radians, or relative to the
#: scene's length) and the noise scales changed by less than ``LM_SCALE_TOL`` (relative).
LM_STEP_TOL = 1e-9
LM_SCALE_TOL = 1e-7
#: Noise scales below this (radians, or relative to the scene's length) are rounding:
#: on noise-free data they shrink with every step and never settle to ``LM_SCALE_TOL``,
#: so a fit whose steps are below ``LM_STEP_TOL`` there has converged.
LM_ROUNDING = 1e-12
#: Bounds of sigma_t / (sigma_r * L), L the RMS camera-target distance: keeps the
#: weights finite on noise-free data (rotation-only or translation-only noise).
_RATIO_BOUNDS = (1e-6, 1e6)


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
    R_A: NDArray, t_A: NDArray, R_B: NDArray, t_B: NDArray, X: NDArray, Y: NDArray
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """``r_r`` (n, 3), ``r_t`` (n, 3), ``R_hat`` (n, 3, 3) and ``v = R_B t_Y + t_B``."""
    R_X, t_X, R_Y, t_Y = X[:3, :3], X[:3, 3], Y[:3, :3], Y[:3, 3]
    R_hat = R_X @ R_B @ R_Y
    v = R_B @ t_Y + t_B
    r_r = _log_small(R_A @ np.swapaxes(R_hat, 1, 2))
    r_t = t_A - v @ R_X.T - t_X
    return r_r, r_t, R_hat, v


def _jacobian(r_r: NDArray, R_hat: NDArray, v: NDArray, R_B: NDArray, X: NDArray) -> NDArray:
    """Jacobian (n, 6, 12) of ``(r_r, r_t)`` in ``(dphi_X, dt_X, dphi_Y, dt_Y)``."""
    n = len(r_r)
    R_X = X[:3, :3]
    Jinv = _inverse_right_jacobian(r_r)
    J = np.zeros((n, 6, 12))
    J[:, :3, 0:3] = -Jinv @ R_X
    J[:, :3, 6:9] = -Jinv @ R_hat
    J[:, 3:, 0:3] = R_X @ skew(v)
    J[:, 3:, 3:6] = -np.eye(3)
    J[:, 3:, 9:12] = -(R_X @ R_B)
    return J


def _log_small(R: NDArray) -> NDArray:
    """Rotation vectors of rotations (n, 3, 3), fast when all are below ~170 deg (the
    residuals); otherwise :func:`kinfw.geometry.rotation_vector_from_matrix`."""
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


class PoseData:
    """The poses of ``camera_T_target[i] ≈ camera_T_hand @ hand_T_base[i] @ base_T_target``
    split into rotations and translations, and the scene's length scale.

    ``camera_T_targets`` (n, 4, 4) are the measured camera poses, ``hand_T_bases``
    (n, 4, 4) the known robot poses, rigid, one length unit. Attributes, in Hirsh's
    letters (module docstring): ``R_A``, ``R_B`` (n, 3, 3) and ``t_A``, ``t_B`` (n, 3),
    views of them; ``n`` poses; ``length``, the RMS of ``|t_A|`` (the camera-target
    distance; of ``|t_B|`` when all are zero; 1 when both are), the scale of the step
    tolerance and of the bounds on the scales' ratio.
    """

    def __init__(self, camera_T_targets: NDArray, hand_T_bases: NDArray) -> None:
        self.R_A, self.t_A = camera_T_targets[:, :3, :3], camera_T_targets[:, :3, 3]
        self.R_B, self.t_B = hand_T_bases[:, :3, :3], hand_T_bases[:, :3, 3]
        self.n = len(camera_T_targets)
        length = float(np.sqrt(np.mean(np.sum(self.t_A**2, axis=1))))
        if length == 0.0:
            length = float(np.sqrt(np.mean(np.sum(self.t_B**2, axis=1))))
        self.length = length if length > 0.0 else 1.0

    def residuals(
        self, camera_T_hand: NDArray, base_T_target: NDArray
    ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """Residuals of every pose at ``X = camera_T_hand``, ``Y = base_T_target`` (each
        (4, 4)): ``r_r = log(R_A R_hat^T)`` (n, 3, radians) and ``r_t = t_A - t_hat``
        (n, 3, input unit), both in the camera frame; ``R_hat = R_X R_B R_Y`` (n, 3, 3)
        and ``v = R_B t_Y + t_B`` (n, 3)."""
        return _residuals(self.R_A, self.t_A, self.R_B, self.t_B, camera_T_hand, base_T_target)


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


def robust_sigmas(r_r: NDArray, r_t: NDArray, length: float) -> tuple[float, float]:
    """Noise scales per axis ``(sigma_r, sigma_t)`` (radians, input unit) from the median
    residual norms, as for a 3-D isotropic Gaussian: the start of the variance components.

    ``r_r``, ``r_t`` are the (n, 3) residuals of :meth:`PoseData.residuals`; ``length``
    is :attr:`PoseData.length`, which bounds ``sigma_t / (sigma_r length)`` to
    ``[1e-6, 1e6]`` (finite weights on noise-free data).
    """
    m_r, m_t = _medians(np.sum(r_r**2, axis=1), np.sum(r_t**2, axis=1))
    s_r = math.sqrt(m_r / _CHI2_3_MEDIAN)
    s_t = math.sqrt(m_t / _CHI2_3_MEDIAN)
    return _bounded_sigmas(s_r, s_t, length)


def _normal_matrices(
    data: PoseData, X: NDArray, Y: NDArray, weights: NDArray, w_r: float, w_t: float
) -> tuple[NDArray, NDArray]:
    """The rotation and translation parts of ``J^T W J`` at ``X, Y``."""
    r_r, _, R_hat, v = data.residuals(X, Y)
    J = _jacobian(r_r, R_hat, v, data.R_B, X) * np.sqrt(weights)[:, None, None]
    H_r = w_r * np.einsum("nki,nkj->ij", J[:, :3], J[:, :3])
    H_t = w_t * np.einsum("nki,nkj->ij", J[:, 3:], J[:, 3:])
    return H_r, H_t


@dataclass(frozen=True, slots=True)
class LMFit:
    """One Levenberg-Marquardt fit (:func:`fit_lm`).

    Attributes
    ----------
    camera_T_hand, base_T_target : ndarray, shape (4, 4)
        The estimates (Hirsh's ``X``, ``Y``), input length unit.
    s_r, s_t : float
        Estimated noise scales per axis (radians, input unit).
    H : ndarray, shape (12, 12)
        ``J^T W J`` at the end over the fitted poses, without Huber's weights, in the
        order ``(dphi_X, dt_X, dphi_Y, dt_Y)``: its inverse is the covariance.
    chi2 : ndarray, shape (n,)
        Squared whitened residual ``|r_r|^2 / s_r^2 + |r_t|^2 / s_t^2`` of every pose
        (fitted or not).
    steps : int
        Levenberg-Marquardt steps taken.
    converged : bool
        Whether the fit stopped on its tolerance.
    """

    camera_T_hand: NDArray
    base_T_target: NDArray
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

    def __init__(self, data: PoseData) -> None:
        self.d = data
        self.J = np.zeros((data.n, 6, 12))
        self.J[:, 3:, 3:6] = -np.eye(3)
        self.K = np.zeros((data.n, 3, 3))  # skew-symmetric scratch

    def residuals(self, X: NDArray, Y: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        d = self.d
        R_X = X[:3, :3]
        RXB = R_X @ d.R_B
        R_hat = RXB @ Y[:3, :3]
        v = d.R_B @ Y[:3, 3] + d.t_B
        r = np.empty((d.n, 6))
        E = d.R_A @ np.swapaxes(R_hat, 1, 2)
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
        r[:, 3:] = d.t_A - v @ R_X.T - X[:3, 3]
        return r, RXB, R_hat, v

    def jacobian(self, r: NDArray, RXB: NDArray, R_hat: NDArray, v: NDArray, X: NDArray):
        J = self.J
        R_X = X[:3, :3]
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
        J[:, :3, 0:3] = -Jinv @ R_X
        J[:, :3, 6:9] = -Jinv @ R_hat
        K[:, _SK_ROW, _SK_COL] = v[:, _SK_SRC] * _SK_SIGN
        J[:, 3:, 0:3] = R_X @ K
        J[:, 3:, 9:12] = -RXB
        return J


def fit_lm(
    data: PoseData,
    camera_T_hand: NDArray,
    base_T_target: NDArray,
    mask: NDArray,
    s_r: float,
    s_t: float,
    *,
    huber: bool = False,
    max_steps: int = LM_MAX_STEPS,
) -> LMFit:
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
    scene's length) with the scales settled to ``LM_SCALE_TOL`` (relative). Each step's
    weighted cost is told to :mod:`kinfw.progress`.

    Parameters
    ----------
    data : PoseData
        The poses ``camera_T_target[i]`` and ``hand_T_base[i]``.
    camera_T_hand, base_T_target : ndarray, shape (4, 4)
        The start, input length unit.
    mask : ndarray of bool, shape (n,)
        The poses fitted (the others get a ``chi2`` but no weight).
    s_r, s_t : float
        Starting noise scales per axis (radians, input unit), e.g. :func:`robust_sigmas`.
    huber : bool, keyword-only
        Huber's IRLS weights (threshold ``HUBER_K``) on the whitened residual norms.
    max_steps : int, keyword-only
        Most Levenberg-Marquardt steps.

    Returns
    -------
    LMFit
    """
    X, Y = camera_T_hand, base_T_target
    lean = _Lean(data)
    update_scales = float(np.count_nonzero(mask)) >= 4
    maskf = mask.astype(float)
    r, RXB, R_hat, v = lean.residuals(X, Y)
    lam = 1e-6
    steps = 0
    converged = False
    last_du: float | None = None
    # the cost is whitened by noise scales re-estimated after every step, so it is not
    # monotone: it tends to the redundancy (6 n - 12 without down-weighted poses)
    title = "hand-eye Levenberg-Marquardt, noise re-estimated each step"
    with progress.task(title, unit="step") as bar:
        while steps < max_steps:
            steps += 1
            c, cost = _irls_weights(r, maskf, s_r, s_t, huber=huber)
            Jr, Jt = _whitened(lean.jacobian(r, RXB, R_hat, v, X), c, s_r, s_t)
            sc = np.sqrt(c)[:, None]
            H_r = Jr.T @ Jr
            H_t = Jt.T @ Jt
            g = Jr.T @ (r[:, :3] * (sc / s_r)).ravel() + Jt.T @ (r[:, 3:] * (sc / s_t)).ravel()
            H = H_r + H_t
            lam, step = _damped_step(lean, X, Y, H, g, c, cost, lam, s_r, s_t)
            if lam > 1e12:  # no step lowers the cost: at the optimum to rounding
                converged = True
                break
            lam = max(lam / 10.0, 1e-12)
            X, Y, r, RXB, R_hat, v = step.X, step.Y, step.r, step.RXB, step.R_hat, step.v
            bar.advance(1, f"cost {step.cost:#.6g}")
            change = 0.0
            if update_scales:
                s_r, s_t, change, last_du = _updated_scales(
                    H, H_r, H_t, c, r, s_r, s_t, data.length, last_du
                )
            exact = s_r < LM_ROUNDING and s_t < LM_ROUNDING * data.length
            if (step.size < LM_STEP_TOL and (change < LM_SCALE_TOL or exact)) or step.cost == 0.0:
                converged = True
                break
    Jr, Jt = _whitened(lean.jacobian(r, RXB, R_hat, v, X), maskf, s_r, s_t)
    H = Jr.T @ Jr + Jt.T @ Jt
    chi2 = (r * r).reshape(data.n, 2, 3).sum(axis=2) @ (1.0 / s_r**2, 1.0 / s_t**2)
    return LMFit(X, Y, s_r, s_t, H, chi2, steps, converged)


def _irls_weights(
    r: NDArray, maskf: NDArray, s_r: float, s_t: float, *, huber: bool
) -> tuple[NDArray, float]:
    """The weights ``c`` (n,) of the poses (``maskf``, times Huber's IRLS weights of the
    whitened residual norms with ``huber``) and the weighted cost ``sum c_i chi2_i`` at
    the residuals ``r`` (n, 6)."""
    r2 = r * r
    e2 = r2.reshape(len(r), 2, 3).sum(axis=2)  # (n, 2): |r_r|^2, |r_t|^2
    chi = e2 @ (1.0 / s_r**2, 1.0 / s_t**2)
    c = maskf
    if huber:
        c = maskf * np.minimum(1.0, HUBER_K / np.maximum(np.sqrt(chi), 1e-300))
    return c, float(c @ chi)


def _whitened(J: NDArray, c: NDArray, s_r: float, s_t: float) -> tuple[NDArray, NDArray]:
    """The rotation and translation rows of the Jacobian ``J`` (n, 6, 12), each scaled by
    ``sqrt(c_i) / s``, stacked over the poses: (3 n, 12) each."""
    sc = np.sqrt(c)[:, None]
    Jr = (J[:, :3] * (sc / s_r)[:, :, None]).reshape(-1, 12)
    Jt = (J[:, 3:] * (sc / s_t)[:, :, None]).reshape(-1, 12)
    return Jr, Jt


@dataclass(frozen=True, slots=True)
class _Step:
    """A Levenberg-Marquardt step's new estimates ``X``, ``Y`` (4, 4), the model there
    (:meth:`_Lean.residuals`: ``r``, ``RXB``, ``R_hat``, ``v``), its weighted cost and its
    size (the largest rotation step in radians or translation step over the length)."""

    X: NDArray
    Y: NDArray
    r: NDArray
    RXB: NDArray
    R_hat: NDArray
    v: NDArray
    cost: float
    size: float


def _damped_step(
    lean: _Lean,
    X: NDArray,
    Y: NDArray,
    H: NDArray,
    g: NDArray,
    c: NDArray,
    cost: float,
    lam: float,
    s_r: float,
    s_t: float,
) -> tuple[float, _Step]:
    """The step of ``(H + lam diag(H)) delta = -g``, the damping ``lam`` raised tenfold
    until the weighted cost (weights ``c``) does not exceed ``cost`` or the step is below
    1e-7; returns the damping (above 1e12: no step lowers the cost) and the last step."""
    D = np.maximum(H.diagonal(), 1e-300)
    w = (1.0 / s_r**2, 1.0 / s_r**2, 1.0 / s_r**2, 1.0 / s_t**2, 1.0 / s_t**2, 1.0 / s_t**2)
    while True:
        try:
            delta = -np.linalg.solve(H + lam * np.diag(D), g)
        except np.linalg.LinAlgError:
            delta = -np.linalg.lstsq(H + lam * np.diag(D), g, rcond=None)[0]
        X_new = _exp_update(X, delta[0:6])
        Y_new = _exp_update(Y, delta[6:12])
        n_r, n_RXB, n_R, n_v = lean.residuals(X_new, Y_new)
        new_cost = float(c @ ((n_r * n_r) @ w))
        dl = np.abs(delta).tolist()
        size = max(max(dl[0:3] + dl[6:9]), max(dl[3:6] + dl[9:12]) / lean.d.length)
        if new_cost <= cost or size < 1e-7:
            break
        lam *= 10.0
        if lam > 1e12:
            break
    return lam, _Step(X_new, Y_new, n_r, n_RXB, n_R, n_v, new_cost, size)


def _updated_scales(
    H: NDArray,
    H_r: NDArray,
    H_t: NDArray,
    c: NDArray,
    r: NDArray,
    s_r: float,
    s_t: float,
    length: float,
    last_du: float | None,
) -> tuple[float, float, float, float | None]:
    """Variance components after a step: each group's weighted residual sum (weights
    ``c``, residuals ``r`` (n, 6)) over its redundancy ``3 sum c - tr(H^-1 H_g)``, bounded
    (:func:`_bounded_sigmas`), the ratio extrapolated by Aitken when two successive
    changes of ``log(s_t / s_r)`` contract. Returns the new ``s_r``, ``s_t``, the largest
    relative change (log) and the change to remember for the next step (``last_du``)."""
    try:
        Hinv = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        Hinv = np.linalg.pinv(H)
    csum = 3.0 * float(c.sum())
    red_r = csum - float(np.sum(Hinv * H_r.T))
    red_t = csum - float(np.sum(Hinv * H_t.T))
    ss_r, ss_t = (c @ (r * r).reshape(len(r), 2, 3).sum(axis=2)).tolist()
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
    return new_r, new_t, change, last_du


def variance_components(
    data: PoseData, camera_T_hand: NDArray, base_T_target: NDArray
) -> tuple[float, float, NDArray[np.float64]]:
    """Noise scales and covariance at given transforms (not moved).

    Parameters
    ----------
    data : PoseData
        The poses ``camera_T_target[i]`` and ``hand_T_base[i]``.
    camera_T_hand, base_T_target : ndarray, shape (4, 4)
        The transforms ``X``, ``Y`` of the model (module docstring), input length unit.

    Returns
    -------
    sigma_rotation_rad, sigma_translation : float
        The noise scales per axis (radians, input unit): robust ones from the median
        residuals, then three rounds of variance components (each group's residual sum
        over its redundancy).
    covariance : ndarray, shape (12, 12)
        ``(J^T W J)^+`` there with those scales, in the order
        ``(dphi_X, dt_X, dphi_Y, dt_Y)``: what the maximum-likelihood fit would report
        there.
    """
    X, Y = camera_T_hand, base_T_target
    r_r, r_t, _, _ = data.residuals(X, Y)
    s_r, s_t = robust_sigmas(r_r, r_t, data.length)
    ones = np.ones(data.n)
    for _ in range(3):
        H_r, H_t = _normal_matrices(data, X, Y, ones, 1.0 / s_r**2, 1.0 / s_t**2)
        Hinv = np.linalg.pinv(H_r + H_t)
        red_r = 3.0 * data.n - float(np.trace(Hinv @ H_r))
        red_t = 3.0 * data.n - float(np.trace(Hinv @ H_t))
        s_r = np.sqrt(np.sum(r_r**2) / red_r) if red_r > 1e-9 else s_r
        s_t = np.sqrt(np.sum(r_t**2) / red_t) if red_t > 1e-9 else s_t
        s_r, s_t = _bounded_sigmas(s_r, s_t, data.length)
    H_r, H_t = _normal_matrices(data, X, Y, ones, 1.0 / s_r**2, 1.0 / s_t**2)
    return s_r, s_t, np.linalg.pinv(H_r + H_t)
