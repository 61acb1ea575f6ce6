"""The planning workflow of ``kinfw plan`` and :func:`kinfw.plan`: the held-out test
configurations, the candidate pool (recorded joint states or random ones, filtered by the
constraints), then the I-optimal plan (:func:`plan_configurations`); and the plan's
error-against-N figure.

Every random draw comes from one generator seeded by ``seed``, in a fixed order (the test
configurations, the random pool, the random designs of the comparison).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw import progress
from kinfw.files import atomic_path
from kinfw.identification.planning._objective import Setup
from kinfw.identification.planning._plan import Plan, plan_configurations
from kinfw.identification.planning._pool import Pool, candidate_pool
from kinfw.model import Robot, check_robot
from kinfw.simulation import random_configurations

#: Sizes at which a plan's predicted error is compared with random designs (with the
#: plan's own N), those the pool can fill.
CURVE_NS = (5, 10, 15, 20, 30, 40, 60, 100)


class PoolTooSmallError(ValueError):
    """Fewer candidates satisfy the constraints than configurations are wanted.

    Attributes
    ----------
    n : int
        Configurations wanted.
    pool : Pool
        The candidates that satisfy the constraints, and how many each dropped.
    """

    def __init__(self, n: int, pool: Pool) -> None:
        self.n, self.pool = n, pool
        super().__init__(f"n = {n}: {self.reason}")

    @property
    def reason(self) -> str:
        return (
            f"only {len(self.pool.qs)} candidates satisfy the constraints "
            f"(dropped: {self.pool.dropped or 'none'})"
        )


@dataclass(frozen=True, slots=True, eq=False)
class EvaluationSet:
    """Where a plan's held-out error is predicted (:func:`evaluation_set`).

    Attributes
    ----------
    joint_names : tuple of str
        The joints on the paths to the observed frames (the columns of ``qs``).
    qs : ndarray, shape (T, J)
        Test configurations, rad/m.
    w_T_target : ndarray, shape (4, 4), or None
        The target's pose in the root frame (stage 2), metres.
    """

    joint_names: tuple[str, ...]
    qs: NDArray[np.float64]
    w_T_target: NDArray[np.float64] | None


def evaluation_set(
    robot: Robot, setup: Setup, n: int, rng: np.random.Generator, *, fraction: float = 0.8
) -> EvaluationSet:
    """``n`` random test configurations in the centred ``fraction`` of each joint range
    (stage 2: those where the target is seen), with the target's pose
    (:meth:`Setup.target_pose` at the middle of the ranges)."""
    names = robot.topology(setup.observed).joint_names
    lower, upper = robot.joint_limits(names)
    w_T = setup.target_pose(robot, names, 0.5 * (lower + upper)) if setup.cameras else None
    test = random_configurations(lower, upper, n, rng, fraction=fraction)
    if setup.cameras:  # the held-out error where the board is seen
        test = candidate_pool(robot, setup, names, w_T, qs=test).qs
    return EvaluationSet(names, test, w_T)


def plan_measurement(
    robot: Robot,
    setup: Setup,
    n: int = 30,
    *,
    pool_qs: ArrayLike | None = None,
    within_limits: float | None = None,
    candidates: int = 1000,
    n_test: int = 200,
    collisions: bool = False,
    package_dirs: Sequence[str | Path] = (),
    target_m: float | None = None,
    seed: int = 0,
) -> Plan:
    """Choose ``n`` configurations to measure, as ``kinfw plan`` does (the same
    defaults): :func:`kinfw.plan`.

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    setup : Setup
        What is measured, how noisy, which parameters are estimated.
    n : int
        Configurations wanted.
    pool_qs : array_like, shape (N, J), optional
        Candidate joint states (recorded ones; :func:`read_pool`), columns in the order
        of ``robot.topology(setup.observed).joint_names``; default ``candidates`` random
        configurations.
    within_limits : float, optional
        The centred fraction of each joint range of the random candidates and test
        configurations (default 0.8); not with ``pool_qs``.
    candidates, n_test : int
        Random candidates and test configurations.
    collisions : bool
        Drop self-colliding random candidates
        (:func:`kinfw.identification.planning.collision_free`; refused when the check
        cannot be made).
    package_dirs : sequence of path
        Where the collision meshes' ``package://`` paths live.
    target_m : float, optional
        Plan the smallest N whose predicted position RMS is below this (m) instead.
    seed : int
        Seeds the one generator of every draw.

    Returns
    -------
    Plan
        With the predicted errors against N (:data:`CURVE_NS`).

    Raises
    ------
    PoolTooSmallError
        Fewer than ``n`` candidates satisfy the constraints (without ``target_m``).
    """
    robot = check_robot(robot, "robot")
    if pool_qs is not None and within_limits is not None:
        raise ValueError("give pool_qs or within_limits, not both")
    rng = np.random.default_rng(seed)
    fraction = within_limits or 0.8
    progress.stage(f"plan: {n_test} test configurations")
    tests = evaluation_set(robot, setup, n_test, rng, fraction=fraction)
    names, w_T = tests.joint_names, tests.w_T_target
    progress.stage("plan: the candidate pool")
    if pool_qs is not None:
        pool = candidate_pool(robot, setup, names, w_T, qs=pool_qs)
    else:
        pool = candidate_pool(
            robot,
            setup,
            names,
            w_T,
            within_limits=fraction,
            n=candidates,
            rng=rng,
            collisions=collisions,
            package_dirs=package_dirs,
        )
    if len(pool.qs) < n and target_m is None:
        raise PoolTooSmallError(n, pool)
    return plan_configurations(
        robot,
        setup,
        pool.qs,
        n,
        joint_names=names,
        test_qs=tests.qs,
        w_T_target=w_T,
        rng=rng,
        curve_ns=sorted({k for k in (*CURVE_NS, n) if k <= len(pool.qs)}),
        target_m=target_m,
        dropped=pool.dropped,
    )


def read_pool(path: str | Path, joint_names: Sequence[str]) -> NDArray[np.float64]:
    """Candidate joint states (n, J) in ``joint_names`` order from a JSON file: a
    ``kinfw-measurements`` file (its samples) or ``{"joint_names": [...],
    "configurations": [[...], ...]}`` (a plan file is one)."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc.msg} at line {exc.lineno})") from None
    if isinstance(doc, dict) and doc.get("format") == "kinfw-measurements":
        from kinfw.measurements import read_measurements

        data = read_measurements(path)
        names, qs = data.joint_names, data.qs
    else:
        names = doc.get("joint_names") if isinstance(doc, dict) else None
        if not isinstance(names, list) or not all(isinstance(v, str) for v in names):
            raise ValueError(f'{path}: "joint_names": expected a list of joint names')
        try:
            qs = np.array(doc.get("configurations"), dtype=float)
        except (TypeError, ValueError):
            qs = np.empty((0,))
        if qs.ndim != 2 or qs.shape[1] != len(names) or not np.isfinite(qs).all():
            raise ValueError(
                f'{path}: "configurations": expected rows of {len(names)} finite joint values'
            )
    missing = [j for j in joint_names if j not in names]
    if missing:
        raise ValueError(f'{path}: "joint_names": missing the joints {missing}')
    return qs[:, [list(names).index(j) for j in joint_names]]


def plot_plan(path: str | Path, plan: Plan) -> None:
    """The plan's predicted held-out position RMS against N, planned and random (mean),
    as a figure (PNG/PDF/SVG by the suffix of ``path``, written atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [c[0] for c in plan.curve]
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(n, [c[1] * 1e3 for c in plan.curve], "o-", label="planned")
    ax.plot(n, [c[2] * 1e3 for c in plan.curve], "s--", label="random (mean)")
    ax.set_xlabel("configurations N")
    ax.set_ylabel("predicted held-out position RMS (mm)")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp)
    finally:
        plt.close(fig)
