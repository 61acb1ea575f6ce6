"""Cross-check of the CPC model (numpy and CasADi) against Pinocchio's FK of a URDF."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import rotation_angle
from kinfw.model import CPCModel, Robot, cpc_fk_function, cpc_from_robot


@dataclass(frozen=True, slots=True)
class CrossCheck:
    """Largest discrepancies between CPC FK and Pinocchio FK over random configurations.

    Attributes
    ----------
    frames : tuple of str
    n_configurations : int
    numpy_position_m, numpy_rotation_rad : float
        Max over frames and configurations, numpy CPC chain vs Pinocchio.
    casadi_position_m, casadi_rotation_rad : float
        The same for the CasADi graph (evaluated at ``delta = 0``).
    """

    frames: tuple[str, ...]
    n_configurations: int
    numpy_position_m: float
    numpy_rotation_rad: float
    casadi_position_m: float
    casadi_rotation_rad: float

    def passed(self, tol: float = 1e-12) -> bool:
        """True when every discrepancy is below ``tol`` (m and rad)."""
        return (
            max(
                self.numpy_position_m,
                self.numpy_rotation_rad,
                self.casadi_position_m,
                self.casadi_rotation_rad,
            )
            < tol
        )


def random_joint_values(
    robot: Robot, joint_names: tuple[str, ...], n: int, rng: np.random.Generator
) -> NDArray[np.float64]:
    """Uniform joint values inside the URDF limits, (n, k); [-pi, pi] where unbounded."""
    lower, upper = robot.joint_limits(joint_names)
    lower = np.where(np.isfinite(lower), lower, -np.pi)
    upper = np.where(np.isfinite(upper), upper, np.pi)
    return rng.uniform(lower, upper, size=(n, len(joint_names)))


def pose_discrepancy(a_T_x: NDArray[np.float64], a_T_y: NDArray[np.float64]) -> tuple[float, float]:
    """Largest position (m) and rotation (rad) difference between two pose batches."""
    dp = np.linalg.norm(a_T_x[..., :3, 3] - a_T_y[..., :3, 3], axis=-1)
    dr = rotation_angle(np.swapaxes(a_T_x[..., :3, :3], -1, -2) @ a_T_y[..., :3, :3])
    return float(dp.max(initial=0.0)), float(dr.max(initial=0.0))


def crosscheck_cpc(
    robot: Robot,
    frames: tuple[str, ...] | list[str],
    *,
    n: int = 200,
    rng: np.random.Generator | None = None,
    model: CPCModel | None = None,
) -> CrossCheck:
    """Compare CPC FK (numpy and CasADi) with Pinocchio FK of ``robot``.

    Parameters
    ----------
    robot : Robot
        The URDF whose Pinocchio FK is the reference.
    frames : sequence of str
        End frames to compare.
    n : int
        Number of random configurations inside the joint limits.
    rng : numpy.random.Generator, optional
    model : CPCModel, optional
        The CPC model to check; default the one converted from ``robot``'s URDF.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    model = cpc_from_robot(robot, frames) if model is None else model
    names = model.topology.joint_names
    qs = random_joint_values(robot, names, n, rng)
    fk = cpc_fk_function(model, frames).map(n)
    outs = fk(qs.T, np.zeros((model.n_parameters, n)))
    outs = outs if isinstance(outs, (list, tuple)) else [outs]
    worst = np.zeros(4)
    for frame, out in zip(frames, outs, strict=True):
        reference = robot.frame_poses(qs, frame, names)
        casadi_T = np.array(out).reshape(4, n, 4).transpose(1, 0, 2)
        worst = np.maximum(
            worst,
            [
                *pose_discrepancy(model.frame_poses(qs, frame), reference),
                *pose_discrepancy(casadi_T, reference),
            ],
        )
    return CrossCheck(tuple(frames), n, *map(float, worst))
