"""The exact linear least squares of :func:`kinfw.identification.handeye.solve_axyb` for both
translations given the rotations (:func:`translations_least_squares`): the closed-form
start's translations, and the paper-iteration path's. Free of the length unit (every
entry is a length). The maximum-likelihood refinement that follows is
:mod:`kinfw.identification.handeye`.

References
----------
M. Shah, "Solving the robot-world/hand-eye calibration problem using the Kronecker
product", J. Mechanisms Robotics 5(3), 2013.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


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
