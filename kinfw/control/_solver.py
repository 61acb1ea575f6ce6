"""Bounded Gauss-Newton / Levenberg-Marquardt on joint values: the engine of
:mod:`kinfw.control._gaze` and :mod:`kinfw.control._reach`.

Both solve ``min_x 1/2 |r(x)|^2`` over the values ``x`` (rad, m) of a few joints within
their limits, where ``r`` comes from Pinocchio's kinematics with its exact Jacobian.

Each step is the damped, truncated least-squares step (Nocedal & Wright 2006, §10.3)::

    J = U S V^T,    dx = -V_k diag(s_k / (s_k^2 + lambda)) U_k^T r,

over the singular values ``s_k > rcond * s_max`` only: a direction the joints barely move
the residual in (a redundant or singular direction) is left alone instead of swung
through the whole joint range for a negligible gain. ``lambda`` starts at zero (pure
Gauss-Newton: quadratic convergence on a reachable target) and grows tenfold after a
step that does not lower the cost (Levenberg-Marquardt). A joint at a limit whose
gradient pushes it outward is held there (active set), and every step is clipped to the
limits, so the answer always respects them.

The directions left out can be the ones an exact solution needs: a nearly flat valley
that curves (the IIS head fixates exactly only near 4 m, by trading pan against both
vergences: a condition number of ~7,000). A full Gauss-Newton step along such a valley
overshoots its curve, and damping creeps along it in hundreds of steps.
:func:`solve_weak_directions` follows the valley instead: a Gauss-Newton step in the
left-out directions only, then the well-determined ones solved again from there (a few
:func:`solve_bounded` steps back down to the valley floor), the weak step halved until
the cost falls (at most 5 halvings); 3-4 such steps reach 1e-11 rad where the plain
solver stops at 1e-5.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.model import Robot, RobotModelError

#: ``residual(x, jacobian)`` -> ``(r, J)``: ``r`` (m,), ``J`` (m, k) when ``jacobian`` is
#: true (else None), or ``(None, None)`` where the residual is not defined (e.g. a point
#: behind the camera): such a step is rejected like one that raises the cost.
Residual = Callable[
    [NDArray[np.float64], bool],
    tuple[NDArray[np.float64] | None, NDArray[np.float64] | None],
]


@dataclass(frozen=True, slots=True)
class BoundedSolution:
    """The minimiser found by :func:`solve_bounded`.

    Attributes
    ----------
    x : ndarray, shape (k,)
        Joint values (rad, m), within the bounds.
    residual : ndarray, shape (m,)
        ``r(x)``.
    iterations : int
        Accepted steps plus one (the start).
    converged : bool
        The last step was below ``step_tolerance``, or it lowered the cost by less than
        1e-10 of itself (a minimum with a residual left: no further digit of the
        angles changes; the joint values move by ~1e-6 rad more along a flat valley); False
        when ``max_iterations`` ran out first.
    at_bound : ndarray of bool, shape (k,)
        Joints held at a limit at the answer.
    jacobian : ndarray, shape (m, k)
        The residual's Jacobian at ``x``.
    """

    x: NDArray[np.float64]
    residual: NDArray[np.float64]
    iterations: int
    converged: bool
    at_bound: NDArray[np.bool_]
    jacobian: NDArray[np.float64]


def solve_bounded(
    residual: Residual,
    x_start: ArrayLike,
    lower: ArrayLike,
    upper: ArrayLike,
    *,
    rcond: float = 1e-6,
    max_iterations: int = 50,
    step_tolerance: float = 1e-12,
    max_step: float = np.inf,
) -> BoundedSolution:
    """Minimise ``1/2 |residual(x)|^2`` for ``lower <= x <= upper`` (module docstring).

    Parameters
    ----------
    residual : Residual
        The residual and its Jacobian (see :data:`Residual`); must be defined at the
        start.
    x_start : array_like, shape (k,)
        Start values; clipped to the bounds.
    lower, upper : array_like, shape (k,)
        Bounds (``-inf`` / ``inf`` where unbounded).
    rcond : float
        Singular values below ``rcond`` times the largest are left out of the step.
    max_iterations : int
        ``iterations`` at most.
    step_tolerance : float
        Converged when a step's largest component is below this (rad, m).
    max_step : float
        A step whose largest component is longer is shortened to it (rad, m): a trust
        region for residuals far from linear over the joint range (reaching).

    Raises
    ------
    ValueError
        When the residual is not defined at the (clipped) start.
    """
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    x = np.clip(np.asarray(x_start, dtype=float), lower, upper)
    r, jac = residual(x, True)
    if r is None or jac is None or not np.all(np.isfinite(r)):
        raise ValueError("the residual is not defined at the start values")
    cost = float(r @ r)
    damping = 0.0
    converged = False
    iterations = 1
    at_bound = np.zeros(len(x), dtype=bool)
    while iterations <= max_iterations:
        gradient = jac.T @ r
        at_bound = ((x <= lower) & (gradient > 0.0)) | ((x >= upper) & (gradient < 0.0))
        step = np.zeros(len(x))
        if not at_bound.all():
            free_jac = jac if not at_bound.any() else jac[:, ~at_bound]
            u, s, vt = np.linalg.svd(free_jac, full_matrices=False)
            keep = s > rcond * s[0] if s[0] > 0.0 else np.zeros(len(s), dtype=bool)
            gain = s[keep] / (s[keep] ** 2 + damping)
            step[~at_bound] = -vt[keep].T @ (gain * (u[:, keep].T @ r))
        longest = np.max(np.abs(step), initial=0.0)
        if longest < step_tolerance:
            converged = True
            break
        if longest > max_step:
            step *= max_step / longest
        x_new = np.clip(x + step, lower, upper)
        # with its Jacobian: most trial steps are accepted, and then it is needed
        r_new, jac_new = residual(x_new, True)
        cost_new = float(r_new @ r_new) if r_new is not None else np.inf
        if not cost_new < cost:  # also NaN
            scale = float(s[0] ** 2) if not at_bound.all() else 1.0
            damping = max(10.0 * damping, 1e-3 * scale)
            if damping > 1e12 * scale:  # no descent left: a (constrained) minimum
                converged = True
                break
            continue
        damping = 0.0 if damping < 1e-9 else 0.1 * damping
        small_change = cost - cost_new <= 1e-10 * cost
        x, r, jac, cost = x_new, r_new, jac_new, cost_new
        iterations += 1
        if small_change:
            converged = True
            break
    return BoundedSolution(x, r, iterations, converged, at_bound, jac)


def solve_weak_directions(
    residual: Residual,
    solution: BoundedSolution,
    lower: ArrayLike,
    upper: ArrayLike,
    *,
    rcond: float,
    max_steps: int = 8,
    inner_iterations: int = 5,
    max_step: float = 2.0,
) -> BoundedSolution:
    """Continue a truncated :func:`solve_bounded` along the directions it left out
    (module docstring).

    Parameters
    ----------
    residual : Residual
        As for :func:`solve_bounded`.
    solution : BoundedSolution
        Its answer with the same ``rcond``.
    lower, upper : array_like, shape (k,)
        Bounds.
    rcond : float
        The ``rcond`` of ``solution``: singular values at or below ``rcond`` times the
        largest are the weak directions.
    max_steps : int
        Weak steps at most.
    inner_iterations : int
        :func:`solve_bounded` iterations after each weak step.
    max_step : float
        Stop when the weak Gauss-Newton step is longer than this (rad, m): the minimum
        is then not a near miss of an exact solution but a compromise that only a swing
        across the joint range would shave (on the IIS head, most points off its 4 m
        curve). With 2 rad, 10 % of random points at 3.8-4.2 m are fixated exactly at
        no cost to the others (``benchmarks/bench_gaze.py``; 0.5 rad: 2 %).

    Returns
    -------
    BoundedSolution
        With a cost no higher than ``solution``'s; ``iterations`` counts every
        Jacobian evaluation, ``converged`` whether a weak step stopped helping (or none
        was left) before ``max_steps``.
    """
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    best, iterations = solution, solution.iterations
    for _ in range(max_steps):
        r = best.residual
        _, jac = residual(best.x, True)
        iterations += 1
        u, s, vt = np.linalg.svd(jac, full_matrices=False)
        weak = (s <= rcond * s[0]) & (s > 0.0)
        if not weak.any():
            break
        step = -vt[weak].T @ ((u[:, weak].T @ r) / s[weak])
        if np.max(np.abs(step)) > max_step:
            break
        fraction = 1.0
        while fraction > 0.05:
            trial = solve_bounded(
                residual,
                np.clip(best.x + fraction * step, lower, upper),
                lower,
                upper,
                rcond=rcond,
                max_iterations=inner_iterations,
            )
            iterations += trial.iterations
            if trial.residual @ trial.residual < r @ r:
                break
            fraction *= 0.5
        else:
            return replace(best, iterations=iterations, converged=True)
        best = trial
    else:
        return replace(best, iterations=iterations, converged=False)
    return replace(best, iterations=iterations, converged=True)


def middle_configuration(robot: Robot) -> NDArray[np.float64]:
    """All movable joints at the middle of their ranges (zero where a limit is
    infinite), :attr:`Robot.joint_names` order (rad, m): the default start."""
    lower, upper = robot.joint_limits()
    both = np.isfinite(lower) & np.isfinite(upper)
    return np.where(both, 0.5 * (np.where(both, lower, 0.0) + np.where(both, upper, 0.0)), 0.0)


def check_configuration(robot: Robot, q: ArrayLike, name: str = "q_start") -> NDArray[np.float64]:
    """``q`` as a fresh float array of all movable joints' values; raises
    :class:`RobotModelError` naming ``name`` and the joints on a wrong shape or a
    non-finite value."""
    names = robot.joint_names
    out = np.array(q, dtype=float)
    if out.shape != (len(names),) or not np.all(np.isfinite(out)):
        raise RobotModelError(
            f"{name}: expected {len(names)} finite values ({list(names)}), got {out.tolist()}"
        )
    return out


def check_held_joints(robot: Robot, q: NDArray[np.float64], free: tuple[str, ...]) -> None:
    """Raise :class:`RobotModelError` when a joint that is held (not in ``free``) is
    outside its URDF limits in ``q`` (all movable joints): the answer would not be within
    the limits, and such a value is usually a unit slip (mm given as m, deg as rad). Free
    joints are only started there, and clipped."""
    lower, upper = robot.joint_limits()
    for k, joint in enumerate(robot.joint_names):
        if joint in free or lower[k] - 1e-9 <= q[k] <= upper[k] + 1e-9:
            continue
        revolute = robot.joint(joint).is_revolute
        unit, scale = ("deg", np.degrees(1.0)) if revolute else ("mm", 1e3)
        raise RobotModelError(
            f"joint {joint!r} is held (not solved for) at {q[k] * scale:.6g} {unit}, outside "
            f"its limits [{lower[k] * scale:.6g}, {upper[k] * scale:.6g}] {unit} (a unit "
            f"slip? joint values are in {'rad' if revolute else 'm'})"
        )


def nearest_turn(
    x: NDArray[np.float64],
    reference: NDArray[np.float64],
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
    revolute: NDArray[np.bool_],
) -> NDArray[np.float64]:
    """Each revolute value moved by whole turns (2 pi) as close to ``reference`` as its
    limits allow: the same pose, the smallest motion (a UR10's pan of 352 deg is -8 deg
    from a start at 0). Prismatic values are returned unchanged."""
    turns = np.round((reference - x) / (2.0 * np.pi))
    moved = x + 2.0 * np.pi * turns
    # step back towards x until within the limits (at most the turns taken)
    for _ in range(int(np.max(np.abs(turns), initial=0.0))):
        outside = (moved < lower) | (moved > upper)
        if not outside.any():
            break
        moved = np.where(outside, moved - 2.0 * np.pi * np.sign(turns), moved)
    keep = revolute & (moved >= lower) & (moved <= upper)
    return np.where(keep, moved, x)
