"""The refinement of :func:`identification.axb.solve_axyb` (``refine=True``).

Exact linear least squares for both translations given the rotations
(:func:`translations_least_squares`: also the closed-form start's translations), and
Gauss-Newton on both rotations jointly with geodesic residuals
``log(R_A[i]^T R_X R_B[i] R_Y)`` in radians (:func:`refine_rotations`). Both are free of
the length unit; :mod:`identification.axb` says what they gain.

References
----------
M. Shah, "Solving the robot-world/hand-eye calibration problem using the Kronecker
product", J. Mechanisms Robotics 5(3), 2013.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from kinfw.transforms import (
    matrix_from_rotation_vector,
    project_to_rotation,
    rotation_vector_from_matrix,
    skew,
)

__all__ = ["GN_MAX_STEPS", "refine_rotations", "translations_least_squares"]


GN_MAX_STEPS = 50


def translations_least_squares(As: NDArray, Bs: NDArray, R_X: NDArray) -> tuple[NDArray, NDArray]:
    """Exact linear least squares of eqs. (4)-(6) for both translations, rotations fixed.

    ``t_X + R_X R_B[i] t_Y = t_A[i] - R_X t_B[i]`` stacked over poses (3n x 6); every
    entry is a length, so the solution does not depend on the unit.
    """
    n = len(As)
    P = R_X @ Bs[:, :3, :3]
    M = np.concatenate([np.broadcast_to(np.eye(3), (n, 3, 3)), P], axis=2).reshape(3 * n, 6)
    rhs = (As[:, :3, 3] - Bs[:, :3, 3] @ R_X.T).reshape(3 * n)
    sol = np.linalg.lstsq(M, rhs, rcond=None)[0]
    return sol[:3], sol[3:]


def _inverse_right_jacobian(phi: NDArray[np.float64]) -> NDArray[np.float64]:
    """``d log(exp(phi) exp(xi)) / d xi`` at ``xi = 0``, (n, 3) -> (n, 3, 3)."""
    theta = np.linalg.norm(phi, axis=-1)
    small = theta < 1e-6
    safe = np.where(small, 1.0, theta)
    coef = np.where(
        small,
        1.0 / 12.0 + theta**2 / 720.0,
        1.0 / safe**2 - (1.0 + np.cos(safe)) / (2.0 * safe * np.sin(safe)),
    )
    K = skew(phi)
    return np.eye(3) + 0.5 * K + coef[:, None, None] * (K @ K)


def refine_rotations(
    R_As: NDArray, R_Bs: NDArray, R_X: NDArray, R_Y: NDArray, *, tol: float
) -> tuple[NDArray, NDArray, bool]:
    """Gauss-Newton on ``sum_i |log(R_A[i]^T R_X R_B[i] R_Y)|^2`` over both rotations.

    Updates ``R_X exp(dx)``, ``R_Y exp(dy)``; with ``E_i`` the residual rotation and
    ``C_i = R_B[i] R_Y``, ``E_i -> E_i exp(C_i^T dx + dy)`` to first order, so the
    Jacobian of ``r_i = log E_i`` is ``Jr^-1(r_i) [C_i^T, I]``. Steps are halved while
    they raise the cost; converged when a step is below ``tol`` rad or no step lowers the
    cost any more (the optimum to rounding).
    """
    Rt_As = np.swapaxes(R_As, 1, 2)

    def residuals(R_X: NDArray, R_Y: NDArray) -> NDArray:
        return rotation_vector_from_matrix(Rt_As @ R_X @ R_Bs @ R_Y)

    r = residuals(R_X, R_Y)
    cost = float(np.sum(r**2))
    for _ in range(GN_MAX_STEPS):
        Jinv = _inverse_right_jacobian(r)
        J = np.concatenate([Jinv @ np.swapaxes(R_Bs @ R_Y, 1, 2), Jinv], axis=2)  # (n, 3, 6)
        delta = -np.linalg.solve(np.einsum("nki,nkj->ij", J, J), np.einsum("nki,nk->i", J, r))
        for _ in range(30):
            R_X_new = project_to_rotation(R_X @ matrix_from_rotation_vector(delta[:3]))
            R_Y_new = project_to_rotation(R_Y @ matrix_from_rotation_vector(delta[3:]))
            r_new = residuals(R_X_new, R_Y_new)
            cost_new = float(np.sum(r_new**2))
            if cost_new <= cost:
                break
            delta = 0.5 * delta
        else:  # no step lowers the cost: at the optimum to rounding
            return R_X, R_Y, True
        R_X, R_Y, r, cost = R_X_new, R_Y_new, r_new, cost_new
        if np.linalg.norm(delta) <= tol:
            return R_X, R_Y, True
    return R_X, R_Y, False
