"""Simulated plane contacts for the tests (plain helpers, no fixtures).

:func:`contact_configurations` draws joint values whose probe lies on a plane exactly:
random values inside the limits, then one joint solved by bisection (60 halvings, to
rounding) between two grid values where the probe's signed distance changes sign.
:func:`two_arm_contacts` uses it for a humanoid's two arms touching one table.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import inverse_transform
from kinfw.measurements import Measurements
from kinfw.model import Robot
from kinfw.observations import PlaneContacts
from kinfw.verification.evaluation import random_joint_values

__all__ = ["contact_configurations", "probe_distances", "two_arm_contacts"]


def probe_distances(
    robot: Robot,
    qs: NDArray[np.float64],
    joint_names: tuple[str, ...],
    frame: str,
    offset: NDArray[np.float64],
    plane: NDArray[np.float64],
    measured_in: str | None = None,
) -> NDArray[np.float64]:
    """Signed distance (m,) of the probe at ``offset`` in ``frame`` from the plane
    ``(n, d)`` fixed in ``measured_in`` (None: the root), by Pinocchio FK, metres."""
    T = robot.frame_poses(qs, frame, joint_names)
    if measured_in is not None:
        T = inverse_transform(robot.frame_poses(qs, measured_in, joint_names)) @ T
    return (T[:, :3, :3] @ offset + T[:, :3, 3]) @ plane[:3] - plane[3]


def contact_configurations(
    robot: Robot,
    joint_names: tuple[str, ...],
    frame: str,
    offset: NDArray[np.float64],
    plane: NDArray[np.float64],
    solve: str,
    n: int,
    rng: np.random.Generator,
    *,
    measured_in: str | None = None,
    fixed: dict[str, float] | None = None,
) -> NDArray[np.float64]:
    """``n`` joint configurations (n, k) with the probe on ``plane``: random values in the
    limits (``fixed`` joints held at their value), then joint ``solve`` by bisection
    between the two grid values (241 across its limits) where the distance first changes
    sign; configurations without a sign change are drawn again."""
    col = joint_names.index(solve)
    lower, upper = robot.joint_limits((solve,))
    grid = np.linspace(max(lower[0], -np.pi), min(upper[0], np.pi), 241)

    def dist(q: NDArray[np.float64]) -> NDArray[np.float64]:
        return probe_distances(robot, q, joint_names, frame, offset, plane, measured_in)

    out: list[NDArray[np.float64]] = []
    while sum(map(len, out)) < n:
        q = random_joint_values(robot, joint_names, 200, rng)
        for name, value in (fixed or {}).items():
            q[:, joint_names.index(name)] = value
        f = np.empty((len(q), len(grid)))
        for k, a in enumerate(grid):
            q[:, col] = a
            f[:, k] = dist(q)
        cross = np.argmax(np.sign(f[:, :-1]) != np.sign(f[:, 1:]), axis=1)
        rows = np.arange(len(q))
        ok = np.sign(f[rows, cross]) != np.sign(f[rows, cross + 1])
        q, lo, hi, f_lo = q[ok], grid[cross[ok]], grid[cross[ok] + 1], f[ok, cross[ok]]
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            q[:, col] = mid
            f_mid = dist(q)
            left = np.sign(f_mid) == np.sign(f_lo)
            lo, f_lo = np.where(left, mid, lo), np.where(left, f_mid, f_lo)
            hi = np.where(left, hi, mid)
        q[:, col] = 0.5 * (lo + hi)
        out.append(q)
    return np.concatenate(out)[:n]


#: TALOS (example-robot-data ``talos_reduced.urdf``): the torso and both arms.
TALOS_JOINTS = (
    "torso_1_joint",
    "torso_2_joint",
    *(f"arm_{side}_{k}_joint" for side in ("left", "right") for k in range(1, 8)),
)


def two_arm_contacts(
    robot: Robot,
    plane: NDArray[np.float64],
    offsets: dict[str, NDArray[np.float64]],
    n: int,
    rng: np.random.Generator,
    *,
    measured_in: str | None = None,
    joint_names: tuple[str, ...] = TALOS_JOINTS,
    fixed: dict[str, float] | None = None,
) -> Measurements:
    """``n`` contacts per arm of TALOS's torso and arms: the probe at ``offsets[frame]``
    on each arm's frame (``"arm_left_7_link"``, ``"arm_right_7_link"``) touches one plane
    ``"table"`` fixed in ``measured_in``, the elbow (joint 4) solved; the probes' offsets
    unknown (markers ``"left_tip"`` and ``"right_tip"``: a marker belongs to one frame).
    ``joint_names`` are the columns (more joints than the torso's and arms': a leg),
    ``fixed`` joints held at their value."""
    qs, groups = [], []
    for frame, offset in offsets.items():
        side = "left" if "left" in frame else "right"
        q = contact_configurations(
            robot,
            joint_names,
            frame,
            offset,
            plane,
            f"arm_{side}_4_joint",
            n,
            rng,
            measured_in=measured_in,
            fixed=fixed,
        )
        start = sum(map(len, qs))
        groups.append(
            PlaneContacts(
                frame,
                np.arange(start, start + n),
                np.zeros(n),
                plane="table",
                marker=f"{side}_tip",
                measured_in=measured_in,
            )
        )
        qs.append(q)
    return Measurements(joint_names, np.concatenate(qs), others=tuple(groups))
