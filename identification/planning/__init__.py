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
    PLAN_FORMAT,
    Plan,
    plan_configurations,
    plan_per_joint,
    predicted_error,
    read_plan,
    short_path,
    write_plan,
)
from kinfw.identification.planning._pool import Pool, candidate_pool, collision_free

__all__ = [
    "PLAN_FORMAT",
    "CandidateInformation",
    "HeldOut",
    "Plan",
    "Pool",
    "Setup",
    "candidate_information",
    "candidate_pool",
    "collision_free",
    "exchange",
    "greedy",
    "held_out",
    "mean_square",
    "plan_configurations",
    "plan_per_joint",
    "predicted_error",
    "read_plan",
    "short_path",
    "write_plan",
]
