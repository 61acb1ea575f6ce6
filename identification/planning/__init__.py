"""Experiment design: which configurations to measure, and how many, chosen by the
predicted held-out error of the calibration they would give (:func:`plan`).
"""

from __future__ import annotations

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
from kinfw.identification.planning._plan import (
    Plan,
    plan_configurations,
    plan_per_joint,
    predicted_error,
    read_plan,
    short_path,
    write_plan,
)
from kinfw.identification.planning._pool import (
    Pool,
    candidate_pool,
    collision_free,
)
from kinfw.identification.planning._workflow import (
    EvaluationSet,
    PoolTooSmallError,
    evaluation_set,
    plan_measurement,
    plot_plan,
    read_pool,
)

__all__ = [
    "CandidateInformation",
    "EvaluationSet",
    "HeldOut",
    "Plan",
    "Pool",
    "PoolTooSmallError",
    "Setup",
    "candidate_information",
    "candidate_pool",
    "collision_free",
    "evaluation_set",
    "exchange",
    "greedy",
    "held_out",
    "mean_square",
    "plan_configurations",
    "plan_measurement",
    "plan_per_joint",
    "plot_plan",
    "predicted_error",
    "read_plan",
    "read_pool",
    "short_path",
    "write_plan",
]
