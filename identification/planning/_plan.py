"""Plan the measurement: which configurations to measure, and how many.

:func:`plan_configurations` chooses ``n`` configurations from a candidate pool that
minimise the **predicted held-out error** of the calibrated model: the expected RMS
error of the observed quantities (frame positions, camera_T_target) at independent test
configurations, ``sqrt(mean_t trace(G_t M^-1 G_t^T))`` with ``M`` the Fisher information
of the chosen configurations (:mod:`kinfw.identification.planning`): an I-optimal design.

Algorithm: greedy forward selection from a regularised start, then Fedorov exchange
passes until no swap improves. Greedy + exchange is the standard for exact I-optimal
designs: the objective is not submodular, so greedy alone can be improved, and exchange
removes most of that gap at the cost of a few vectorised passes; a convex relaxation
(weights on the pool, then rounding) is the alternative, but it needs a conic solver and
its rounding for small ``n`` is itself a heuristic.

The pool (:func:`kinfw.identification.planning.candidate_pool`) is the user's recorded joint
states or random configurations inside the joint limits, filtered by the constraints: the
target in view of a camera (the visibility rules of
:func:`kinfw.simulation.visible_points`), the measured frames facing the
tracker, and optionally no self-collision.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw import progress
from kinfw.identification.planning._objective import (
    CandidateInformation,
    HeldOut,
    Setup,
    candidate_information,
    exchange,
    greedy,
    held_out,
    mean_square,
)
from kinfw.model import Robot
from kinfw.observations import Metric
from kinfw.simulation import one_joint_at_a_time

log = logging.getLogger(__name__)

PLAN_FORMAT = "kinfw-plan"
PLAN_VERSION = 1


# -- the plan ------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Plan:
    """A planned measurement.

    Attributes
    ----------
    joint_names : tuple of str
    qs : ndarray, shape (n, J)
        The configurations in the order to measure them (:func:`short_path`), rad/m.
    predicted : tuple of (Metric, float)
        Per noise component of the observed quantities (:attr:`HeldOut.weights`: a
        position, a rotation), in its metric, the predicted held-out RMS error of the
        calibrated model at the test configurations, SI (m, rad); the first is the
        objective, the error the plan minimises.
    random_rms : float
        The objective's for ``n`` random pool configurations (mean of the mean squares
        over draws, then the root), SI.
    greedy_ms, exchanged_ms : float
        ``trace(A M^-1)`` (the objective, scaled) after greedy and after exchange.
    curve : list of (n, planned_rms, random_rms)
        Predicted errors against ``n``: the greedy prefix of that length (the plan itself,
        greedy + exchange, at the plan's own ``n``) and random pool configurations.
    seconds : float
        Time of the selection (greedy + exchange), s.
    """

    joint_names: tuple[str, ...]
    qs: NDArray[np.float64]
    predicted: tuple[tuple[Metric, float], ...]
    random_rms: float
    greedy_ms: float
    exchanged_ms: float
    curve: list = field(default_factory=list)
    seconds: float = 0.0
    dropped: dict = field(default_factory=dict)
    pool_size: int = 0

    @property
    def objective(self) -> Metric:
        """The metric of the error the plan minimises."""
        return self.predicted[0][0]

    def rms(self, name: str) -> float:
        """The predicted held-out RMS in the metric ``name`` (SI)."""
        return next(v for m, v in self.predicted if m.name == name)


@dataclass(frozen=True, eq=False)
class _Context:
    info: CandidateInformation
    heldout: HeldOut


def _context(robot, setup, pool_qs, test_qs, names, w_T_target) -> _Context:
    info = candidate_information(robot, setup, pool_qs, names, w_T_target)
    return _Context(info, held_out(robot, setup, test_qs, names, w_T_target, info))


def _random_ms(ctx: _Context, A, n: int, rng: np.random.Generator, draws: int) -> float:
    N = ctx.info.factors.shape[0]
    return float(
        np.mean([mean_square(ctx.info, A, rng.choice(N, n, replace=False)) for _ in range(draws)])
    )


def plan_configurations(
    robot: Robot,
    setup: Setup,
    pool_qs: ArrayLike,
    n: int,
    *,
    joint_names: Sequence[str],
    test_qs: ArrayLike,
    w_T_target: NDArray | None = None,
    rng: np.random.Generator | None = None,
    curve_ns: Sequence[int] = (),
    random_draws: int = 5,
    target_m: float | None = None,
    dropped: dict | None = None,
) -> Plan:
    """Choose ``n`` of ``pool_qs`` minimising the predicted held-out position error.

    Parameters
    ----------
    robot : Robot
        Nominal robot.
    setup : Setup
    pool_qs : array_like, shape (N, J)
        Candidates (already filtered: :func:`kinfw.identification.planning.candidate_pool`),
        ``joint_names`` order.
    n : int
        Configurations wanted (ignored with ``target_m``: the smallest ``n`` whose
        greedy design predicts a position RMS below it).
    joint_names : sequence of str
    test_qs : array_like, shape (T, J)
        Held-out configurations the error is averaged over.
    w_T_target : ndarray (4, 4), optional
        The target's pose (stage 2; default :meth:`Setup.target_pose`).
    rng : numpy.random.Generator, optional
        For the random designs of the comparison.
    curve_ns : sequence of int
        Sizes at which to report planned (greedy prefix) vs random RMS.
    target_m : float, optional
        Target position RMS, metres.

    Returns
    -------
    Plan
    """
    names = tuple(joint_names)
    pool_qs = np.atleast_2d(np.asarray(pool_qs, dtype=float))
    rng = np.random.default_rng(0) if rng is None else rng
    if setup.cameras and w_T_target is None:
        lower, upper = robot.joint_limits(names)
        w_T_target = setup.target_pose(robot, names, 0.5 * (lower + upper))
    progress.stage(f"plan: the information of {len(pool_qs)} candidates")
    ctx = _context(robot, setup, pool_qs, test_qs, names, w_T_target)
    A = ctx.heldout.objective[1]
    N = len(pool_qs)
    t0 = time.perf_counter()
    n_max = max([n, *curve_ns]) if target_m is None else N
    n_max = min(n_max, N)
    order, values = greedy(ctx.info, A, n_max) if target_m is None else _greedy_to(ctx, A, target_m)
    if target_m is not None:
        n = len(order)
    if n > N:
        raise ValueError(f"n = {n}: the pool has only {N} candidates")
    chosen, final, swaps = exchange(ctx.info, A, order[:n])
    seconds = time.perf_counter() - t0
    log.info("plan: %d of %d candidates in %.2f s (%d swaps)", n, N, seconds, swaps)
    progress.stage("plan: random designs, for comparison")
    random_ms = _random_ms(ctx, A, n, rng, random_draws)
    curve = []
    for k in curve_ns:
        if k <= len(values) and k <= N:
            # the greedy prefix (no exchange) except at the plan's own n, which is the plan
            planned = mean_square(ctx.info, A, chosen if k == n else order[:k])
            random_k = random_ms if k == n else _random_ms(ctx, A, k, rng, random_draws)
            curve.append((int(k), float(np.sqrt(planned)), float(np.sqrt(random_k))))
    lower, upper = robot.joint_limits(names)
    qs = pool_qs[chosen][short_path(pool_qs[chosen], lower, upper)]
    return Plan(
        joint_names=names,
        qs=qs,
        predicted=_predicted(ctx, chosen),
        random_rms=float(np.sqrt(random_ms)),
        greedy_ms=float(values[n - 1]),
        exchanged_ms=float(final),
        curve=curve,
        seconds=seconds,
        dropped=dict(dropped or {}),
        pool_size=N,
    )


def _predicted(ctx: _Context, chosen) -> tuple[tuple[Metric, float], ...]:
    """Per observed component its metric and predicted held-out RMS (SI) of ``chosen``."""
    return tuple(
        (c.display, float(np.sqrt(mean_square(ctx.info, A, chosen))))
        for c, A in ctx.heldout.weights
    )


def _greedy_to(ctx: _Context, A, target_m: float):
    """Greedy picks until the position RMS is below ``target_m`` (ValueError if never)."""
    N = ctx.info.factors.shape[0]
    k = 16
    while True:  # the greedy prefix is the same whatever its length: grow it by doubling
        k = min(2 * k, N)
        order, values = greedy(ctx.info, A, k)
        below = np.flatnonzero(np.sqrt(values) <= target_m)
        if len(below) or k == N:
            break
    if not len(below):
        raise ValueError(
            f"--target-mm {target_m * 1e3:g}: even all {N} candidates predict "
            f"{np.sqrt(values[-1]) * 1e3:.4g} mm"
        )
    k = int(below[0]) + 1
    return order[:k], values[:k]


def predicted_error(
    robot: Robot,
    setup: Setup,
    qs: ArrayLike,
    test_qs: ArrayLike,
    *,
    joint_names: Sequence[str],
    w_T_target: NDArray | None = None,
) -> tuple[tuple[Metric, float], ...]:
    """Predicted held-out RMS of a calibration from ``qs``: per observed noise component
    its metric and the RMS in SI (position m, rotation rad), as :attr:`Plan.predicted`."""
    names = tuple(joint_names)
    if setup.cameras and w_T_target is None:
        lower, upper = robot.joint_limits(names)
        w_T_target = setup.target_pose(robot, names, 0.5 * (lower + upper))
    ctx = _context(robot, setup, qs, test_qs, names, w_T_target)
    return _predicted(ctx, np.arange(len(np.atleast_2d(qs))))


def plan_per_joint(
    robot: Robot,
    setup: Setup,
    per_joint: int,
    *,
    joint_names: Sequence[str],
    test_qs: ArrayLike,
    grid: int = 41,
    fraction: float = 0.8,
    w_T_target: NDArray | None = None,
) -> dict:
    """Shih et al.'s one-joint-at-a-time protocol with the best ``per_joint`` values per
    joint (from a ``grid`` of values in the centred ``fraction`` of each range, others at
    the middle), against ``per_joint`` and 9 evenly spaced values.

    Returns
    -------
    dict
        ``qs`` (planned, with the initial configuration first), the predicted position
        RMS (m) of the planned, evenly spaced (same M) and paper (M = 9) protocols.
    """
    names = tuple(joint_names)
    lower, upper = robot.joint_limits(names)
    if setup.cameras and w_T_target is None:
        w_T_target = setup.target_pose(robot, names, 0.5 * (lower + upper))
    fine, moved = one_joint_at_a_time(lower, upper, per_joint=grid, fraction=fraction)
    even, _ = one_joint_at_a_time(lower, upper, per_joint=per_joint, fraction=fraction)
    paper, _ = one_joint_at_a_time(lower, upper, per_joint=9, fraction=fraction)
    pool = np.concatenate([fine, even, paper])
    ctx = _context(robot, setup, pool, test_qs, names, w_T_target)
    A = ctx.heldout.objective[1]
    groups = np.concatenate([moved, np.full(len(even) + len(paper), -2)])
    allowed = groups >= 0
    start = np.flatnonzero(groups == -1)  # the initial configuration, always measured
    J = len(names)
    order, _ = greedy(ctx.info, A, J * per_joint, allowed=allowed, groups=groups, quota=per_joint)
    chosen, _, _ = exchange(
        ctx.info, A, np.concatenate([start, order]), allowed=allowed, groups=groups
    )
    n_fine, n_even = len(fine), len(even)

    def rms(idx):
        return float(np.sqrt(mean_square(ctx.info, A, idx)))

    return {
        "qs": pool[chosen],
        "planned_position_rms_m": rms(chosen),
        "even_position_rms_m": rms(np.arange(n_fine, n_fine + n_even)),
        "paper_position_rms_m": rms(np.arange(n_fine + n_even, len(pool))),
        "per_joint": per_joint,
        "n_planned": len(chosen),
        "n_paper": len(paper),
    }


# -- a robot-friendly order ---------------------------------------------------------------
def short_path(qs: ArrayLike, lower: ArrayLike, upper: ArrayLike) -> NDArray[np.int64]:
    """An order of ``qs`` with a short joint-space path: nearest neighbour from the
    configuration closest to the middle of the ranges, then 2-opt; distances in units of
    each joint's range (infinite limits: 2 pi)."""
    qs = np.atleast_2d(np.asarray(qs, dtype=float))
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    span = np.where(np.isfinite(upper - lower), upper - lower, 2 * np.pi)
    mid = np.where(np.isfinite(lower + upper), 0.5 * (lower + upper), 0.0)
    x = qs / np.where(span > 0, span, 1.0)
    D = np.linalg.norm(x[:, None] - x[None], axis=-1)
    n = len(qs)
    if n < 3:
        return np.arange(n)
    start = int(np.argmin(np.linalg.norm(x - mid / np.where(span > 0, span, 1.0), axis=1)))
    order, left = [start], set(range(n)) - {start}
    while left:
        last = order[-1]
        nxt = min(left, key=lambda j: D[last, j])
        order.append(nxt)
        left.remove(nxt)
    order = np.array(order)
    improved = True
    while improved:  # 2-opt on an open path (the start stays first)
        improved = False
        for i in range(1, n - 1):
            a, b = order[i - 1], order[i]
            c = order[i + 1 :]
            d = np.append(order[i + 2 :], -1)
            old = D[a, b] + np.where(d >= 0, D[c, d], 0.0)
            new = D[a, c] + np.where(d >= 0, D[b, d], 0.0)
            k = int(np.argmin(new - old))
            if new[k] - old[k] < -1e-12:
                order[i : i + k + 2] = order[i : i + k + 2][::-1]
                improved = True
    return order


# -- the plan file -------------------------------------------------------------------------
def plan_to_dict(plan: Plan, setup: dict) -> dict:
    """The plan file's content (format ``kinfw-plan`` v1, see docs/planning.md)."""
    return {
        "format": PLAN_FORMAT,
        "version": PLAN_VERSION,
        "joint_names": list(plan.joint_names),
        "units": "rad for revolute joints, m for prismatic joints",
        "configurations": plan.qs.tolist(),
        "predicted": {
            **{m.headline: m.scale * v for m, v in plan.predicted},
            f"random_{plan.objective.headline}": plan.objective.scale * plan.random_rms,
        },
        "setup": setup,
    }


def write_plan(path: str | Path, plan: Plan, setup: dict) -> Path:
    """Write the plan file atomically."""
    from kinfw.files import write_text_atomic

    return write_text_atomic(path, json.dumps(plan_to_dict(plan, setup), indent=2) + "\n")


def read_plan(path: str | Path) -> tuple[tuple[str, ...], NDArray[np.float64]]:
    """``(joint_names, configurations (n, J))`` of a plan file; ValueError naming the
    file and key when it is not one."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(doc, dict) or doc.get("format") != PLAN_FORMAT:
        raise ValueError(f'{path}: "format": expected "{PLAN_FORMAT}"')
    if doc.get("version") != PLAN_VERSION:
        raise ValueError(f'{path}: "version": expected {PLAN_VERSION}, got {doc.get("version")!r}')
    names = doc.get("joint_names")
    if not isinstance(names, list) or not names or not all(isinstance(v, str) for v in names):
        raise ValueError(f'{path}: "joint_names": expected a list of joint names')
    try:
        qs = np.array(doc.get("configurations"), dtype=float)
    except (TypeError, ValueError):
        qs = np.empty((0,))
    if qs.ndim != 2 or qs.shape[1] != len(names) or not len(qs) or not np.isfinite(qs).all():
        raise ValueError(
            f'{path}: "configurations": expected a non-empty list of rows of '
            f"{len(names)} finite joint values"
        )
    return tuple(names), qs
