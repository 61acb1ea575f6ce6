"""The paper's iteration for ``A = X B Y`` (Hirsh, DeSouza & Kak 2001, sections 3-4).

The rotation alternation on quaternions (:func:`rotation_iteration`, with the random
restart after a 180-degree stall) and the translation alternation
(:func:`translation_iteration`), as :func:`kinfw.identification.handeye.solve_axyb` runs them; the
quaternions are kinfw's, scalar last ``(x, y, z, w)``.

Signs. Section 4's argument needs the per-pose errors of eq. (10) to be conjugates of
*one* quaternion, sign included. A rotation matrix fixes its quaternion only up to sign,
so the quaternions of ``A`` and ``B`` are given consistent signs once, from the data
(:func:`kinfw.identification.handeye._quaternion.consistent_quats_xyzw`). Aligning each average's
inputs to the current estimate instead makes errors beyond ~90 degrees grow to 180:
measured on 200 noise-free problems with uniformly random rotations and the identity
start, that variant needed restarts in 61 % of the runs for n = 5 and 10 (36 % for n =
3) and ended at wrong answers with small residuals in 35 of 200 runs for n = 3 (3 and 4
for n = 5 and 10). With consistent signs: no restart and no wrong answer for n = 5 and
10; for n = 3 one restart, and 2 runs (both nearly degenerate) not converged within 3000
iterations.

What the iteration is. Averaging is linear, so the average of the per-pose ``X``
estimates is ``N q_Y^-1`` and that of the ``Y`` estimates ``N^T q_X^-1`` (after the
conjugation is folded into ``N``) for one 4x4 matrix ``N = mean_i L(q_A[i]) R(q_B[i]^-1)
diag(-1, -1, -1, 1)``: the alternation is the power iteration for the top singular pair
of ``N``. Its fixed point, that singular pair, maximises ``sum_i q_X . q_X[i]`` = the
sum of ``cos(theta_i / 2)`` (``theta_i`` the rotation residual of pose ``i``, signs from
the data): block-coordinate ascent without spurious local optima. The paper's error "s-component" is
the component of the estimate along it; the 180-degree stall is a start orthogonal to
it; the convergence factor per iteration is ``(sigma_2 / sigma_1)^2`` of ``N`` (0.9929
measured on Tabb's real data: 88 poses, median relative rotation 12.7 deg, so 1000
iterations do not reach the default tolerance). The code computes the averages this way (O(1) per
iteration after an O(n) set-up); ``tests/identification/handeye/test_axb.py`` checks them
against the explicit
per-pose averages. The translation alternation is block Gauss-Seidel on the linear least
squares of eqs. (4)-(6) and converges to its exact solution, at the rate ``sigma^2``
(0.9928 on Tabb),
``sigma`` the largest singular value of ``mean_i R_B[i]`` (1 exactly when all rotations
of ``B`` share one axis, when neither X nor Y is determined).

References
----------
R. L. Hirsh, G. N. DeSouza, A. C. Kak, "An iterative approach to the hand-eye and
base-world calibration problem", ICRA 2001, sections 3-4, eqs. (1)-(10), Appendix A.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.identification.handeye._quaternion import (
    left_product_matrix_xyzw,
    right_product_matrix_xyzw,
)

# The solver's logger: its messages are filtered as kinfw.identification.handeye's.
log = logging.getLogger("kinfw.identification.handeye")


#: A rotation residual (rad) above this is not a calibration: during the iteration (as
#: ``2 acos(mean_i cos(theta_i / 2))``) it marks a stall when it stops falling; at the end
#: (as the RMS) it is an error.
STALL_RAD = 0.5


#: Stall: over this many iterations the residual fell by less than STALL_PROGRESS.
STALL_WINDOW = 5


STALL_PROGRESS = 1e-3


#: Norm of an averaged quaternion below which the average is undefined (the paper's
#: bisector with d = 0, section 2.2 property 4).
COLLAPSE = 1e-9


MAX_RESTARTS = 10


_CONJUGATE = np.array([-1.0, -1.0, -1.0, 1.0])


class AXYBError(ValueError):
    """The poses cannot determine X and Y, or the input is not a batch of rigid transforms."""


# ------------------------------------------------------------------- quaternions


def iteration_matrix(q_As: NDArray, q_Bs: NDArray) -> NDArray[np.float64]:
    """``N`` with ``mean_i q_A[i] q_Y^-1 q_B[i]^-1 = N q_Y`` and
    ``mean_i q_B[i]^-1 q_X^-1 q_A[i] = N^T q_X`` (module docstring)."""
    M = np.mean(
        left_product_matrix_xyzw(q_As) @ right_product_matrix_xyzw(q_Bs * _CONJUGATE), axis=0
    )
    return M * _CONJUGATE  # right-multiplied by diag(-1, -1, -1, 1): q_Y -> q_Y^-1


def normalise(total: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """The paper's bisector (section 2.2 property 4) for n quaternions: the average
    ``total`` divided by its norm ``d``; returns both. ``d`` near 0: undefined."""
    d = float(np.linalg.norm(total))
    return total / max(d, COLLAPSE), d


def _quat_angle(p: NDArray[np.float64], q: NDArray[np.float64]) -> float:
    """Rotation angle between unit quaternions, accurate near 0 (chord, not acos)."""
    chord = min(np.linalg.norm(p - q), np.linalg.norm(p + q))
    return 4.0 * float(np.arcsin(min(chord / 2.0, 1.0)))


# ---------------------------------------------------------------------- the paper


@dataclass(frozen=True, slots=True)
class RotationRun:
    """The rotation alternation's result: quaternions (x, y, z, w) of X and Y."""

    q_X: NDArray[np.float64]
    q_Y: NDArray[np.float64]
    iterations: int
    converged: bool
    restarts: int
    history_X: NDArray[np.float64]  # (iterations, 4) quaternions
    history_Y: NDArray[np.float64]


def rotation_iteration(
    N: NDArray, q_Y: NDArray, *, tol: float, max_iterations: int, rng: np.random.Generator
) -> RotationRun:
    """Section 3, first paragraph, and section 4: alternate averages of eqs. (1)-(3).

    Eq. (9): given the guess ``Y``, pose ``i`` gives ``q_X[i] = q_A[i] q_Y^-1 q_B[i]^-1``;
    their average (``N q_Y``) normalised is the new ``X``. Then ``q_Y[i] = q_B[i]^-1
    q_X^-1 q_A[i]`` averaged (``N^T q_X``). With sign-consistent quaternions the errors of
    the ``q_X[i]`` are conjugates of one quaternion (eq. 10), so each normalised average
    divides the error's scalar part by ``d <= 1``: the error angle shrinks monotonically
    from any start short of 180 degrees. Stops when neither rotation moves by more than
    ``tol`` rad in an iteration.

    Stall (section 4, last paragraph): at 180 degrees the error's scalar part is 0 and
    does not grow. Observable as the residual ``2 acos(d)`` (``d`` = norm of the average
    of the ``Y`` estimates = ``mean_i cos(theta_i / 2)``) staying above ``STALL_RAD``
    without falling by ``STALL_PROGRESS`` over ``STALL_WINDOW`` iterations or reaching a
    fixed point there, or as an average whose norm collapses. Then: a random ``Y``.
    """
    q_X_prev: NDArray | None = None
    hist_X: list[NDArray] = []
    hist_Y: list[NDArray] = []
    residual_run: list[float] = []
    restarts = 0
    best: tuple[float, NDArray, NDArray] | None = None  # lowest residual so far
    k = 0
    while k < max_iterations:
        k += 1
        q_X, d_X = normalise(N @ q_Y)  # eq. (9) for every pose, averaged
        q_Y_new, d_Y = normalise(N.T @ q_X)  # the same for Y given the new X
        step = (
            np.inf
            if q_X_prev is None
            else max(_quat_angle(q_X, q_X_prev), _quat_angle(q_Y_new, q_Y))
        )
        q_Y, q_X_prev = q_Y_new, q_X
        hist_X.append(q_X)
        hist_Y.append(q_Y)
        residual = 2.0 * float(np.arccos(np.clip(d_Y, -1.0, 1.0)))
        residual_run.append(residual)
        if best is None or residual < best[0]:
            best = (residual, q_X, q_Y)
        if step <= tol and residual <= STALL_RAD:
            return RotationRun(q_X, q_Y, k, True, restarts, np.array(hist_X), np.array(hist_Y))
        collapsed = min(d_X, d_Y) < COLLAPSE
        flat = (
            len(residual_run) > STALL_WINDOW
            and residual > STALL_RAD
            and residual > (1.0 - STALL_PROGRESS) * residual_run[-1 - STALL_WINDOW]
        )
        if (collapsed or flat or step <= tol) and restarts < MAX_RESTARTS:
            log.info(
                "rotation iteration stalled after %d iterations (residual %.3g deg%s): "
                "restart from a random guess",
                k,
                np.degrees(residual),
                ", average collapsed" if collapsed else "",
            )
            restarts += 1
            q_Y = rng.normal(size=4)
            q_Y /= np.linalg.norm(q_Y)
            q_X_prev, residual_run = None, []
    if best is None:  # unreachable: max_iterations >= 1 is checked by the caller
        raise AXYBError("no iteration was run")
    return RotationRun(best[1], best[2], k, False, restarts, np.array(hist_X), np.array(hist_Y))


@dataclass(frozen=True, slots=True)
class TranslationRun:
    """The translation alternation's result: translations of X and Y (input unit)."""

    t_X: NDArray[np.float64]
    t_Y: NDArray[np.float64]
    iterations: int
    converged: bool
    history_X: NDArray[np.float64]  # (iterations, 3)
    history_Y: NDArray[np.float64]


def translation_iteration(
    As: NDArray, Bs: NDArray, R_X: NDArray, t_Y: NDArray, *, tol: float, max_iterations: int
) -> TranslationRun:
    """Section 3, second paragraph: alternate averages of eqs. (4)-(6) for translations.

    The translation part of eq. (4), ``t_A = R_X (R_B t_Y + t_B) + t_X``, gives per pose
    ``t_X[i] = t_A[i] - R_X (R_B[i] t_Y + t_B[i])`` for the current ``t_Y``, averaged,
    then ``t_Y[i] = R_B[i]^T (R_X^T (t_A[i] - t_X) - t_B[i])``, averaged (the averages by
    linearity from means formed once). Only ``X``'s rotation enters. Stops when neither
    moves by more than ``tol`` times the RMS length of the input translations.
    """
    R_Bs, t_As, t_Bs = Bs[:, :3, :3], As[:, :3, 3], Bs[:, :3, 3]
    scale = float(np.sqrt(np.mean(np.sum(t_As**2, 1)) + np.mean(np.sum(t_Bs**2, 1))))
    mean_R_B = R_Bs.mean(axis=0)
    mean_t_A, mean_t_B = t_As.mean(axis=0), t_Bs.mean(axis=0)
    mean_Rt_B_Rt_X_t_A = np.einsum("nji,kj,nk->i", R_Bs, R_X, t_As) / len(As)
    mean_Rt_B_t_B = np.einsum("nji,nj->i", R_Bs, t_Bs) / len(As)
    t_X: NDArray | None = None
    hist_X: list[NDArray] = []
    hist_Y: list[NDArray] = []
    k = 0
    while k < max_iterations:
        k += 1
        t_X_new = mean_t_A - R_X @ (mean_R_B @ t_Y + mean_t_B)
        t_Y_new = mean_Rt_B_Rt_X_t_A - mean_R_B.T @ (R_X.T @ t_X_new) - mean_Rt_B_t_B
        step = (
            np.inf
            if t_X is None
            else max(np.linalg.norm(t_X_new - t_X), np.linalg.norm(t_Y_new - t_Y))
        )
        t_X, t_Y = t_X_new, t_Y_new
        hist_X.append(t_X)
        hist_Y.append(t_Y)
        if step <= tol * scale:
            return TranslationRun(t_X, t_Y, k, True, np.array(hist_X), np.array(hist_Y))
    return TranslationRun(t_X, t_Y, k, False, np.array(hist_X), np.array(hist_Y))
