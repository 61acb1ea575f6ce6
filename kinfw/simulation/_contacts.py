"""Configurations that put a probe on a plane, a ball or a point: the contacts of
``kinfw simulate --contacts``.

A probe at ``offset`` in URDF frame ``frame``, ``p(q) = root_T_frame(q) @ offset`` in the
root, touches

- the plane ``{x : n . x = d}`` when ``n . p(q) - d = 0`` (one residual);
- the ball of centre ``c`` and radius ``r`` when ``|p(q) - c| - r = 0`` (one residual);
- the point ``c`` when ``p(q) - c = 0`` (three residuals).

Random configurations are projected onto that manifold by Gauss-Newton steps of least
norm (:func:`contact_configurations`), the residuals' Jacobian from Pinocchio's frame
Jacobian (``LOCAL_WORLD_ALIGNED``: the probe moves at ``v - (R offset) x w``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import skew
from kinfw.model import Robot
from kinfw.simulation._perturb import finite_limits, random_configurations

#: A projection has converged when the probe is this close to the plane, metres.
CONTACT_TOLERANCE_M = 1e-12
#: Gauss-Newton steps tried from each random configuration.
MAX_STEPS = 30


def plane_through(point: ArrayLike, normal: ArrayLike) -> NDArray[np.float64]:
    """The plane ``(n, d)`` (4,) through ``point`` (3,) with unit normal along ``normal``
    (3,), both in the root frame (metres)."""
    n = np.asarray(normal, dtype=float)
    norm = float(np.linalg.norm(n))
    if not (np.isfinite(norm) and norm > 0.0):
        raise ValueError(f"plane normal: expected a non-zero vector, got {normal!r}")
    n = n / norm
    return np.append(n, n @ np.asarray(point, dtype=float))


def level_plane(
    robot: Robot,
    joint_names: Sequence[str],
    lower: ArrayLike,
    upper: ArrayLike,
    *,
    frame: str,
    offset: ArrayLike,
) -> NDArray[np.float64]:
    """The plane ``(n, d)`` (4,) normal to the root's z axis through the probe (``offset``
    (3,) in ``frame``, metres) at the middle of the joint ranges (an infinite limit:
    -pi .. pi, as :func:`random_configurations`)."""
    lo, hi = finite_limits(lower, upper)
    root_T_frame = robot.frame_poses(0.5 * (lo + hi), frame, tuple(joint_names))
    return plane_through(
        root_T_frame[:3, :3] @ np.asarray(offset, float) + root_T_frame[:3, 3], [0, 0, 1]
    )


def _probe_and_jacobian(
    robot: Robot,
    q: NDArray[np.float64],
    names: tuple[str, ...],
    frame: str,
    offset: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The probe's position ``root_p_probe`` (3,) at ``q`` (k,) and its Jacobian (3, k)
    with respect to ``q`` (joints ``names``)."""
    import pinocchio as pin

    model, data = robot.model, robot.model.createData()
    fid = robot.frame_id(frame)
    pin_q = robot.pin_configurations(q[None], names)[0]
    J = pin.computeFrameJacobian(model, data, pin_q, fid, pin.LOCAL_WORLD_ALIGNED)
    root_T_frame = data.oMf[fid].homogeneous
    lever = root_T_frame[:3, :3] @ offset
    J_probe = J[:3] - skew(lever) @ J[3:]
    columns = [robot.velocity_index(name) for name in names]
    return root_T_frame[:3, :3] @ offset + root_T_frame[:3, 3], J_probe[:, columns]


def _surface(
    plane: ArrayLike | None, sphere: ArrayLike | None, point: ArrayLike | None
) -> tuple[Callable[[NDArray], tuple[NDArray, NDArray]], str]:
    """The contact's residual ``p -> (r (k,), dr/dp (k, 3))`` of exactly one of
    ``plane`` ``(n, d)``, ``sphere`` ``(c, r)`` or ``point`` ``c`` (metres, root), and its
    description for messages."""
    given = [(name, v) for name, v in (("plane", plane), ("sphere", sphere), ("point", point))]
    given = [(name, np.asarray(v, dtype=float)) for name, v in given if v is not None]
    if len(given) != 1:
        raise ValueError("contact_configurations: give exactly one of plane, sphere, point")
    ((name, v),) = given
    size = {"plane": 4, "sphere": 4, "point": 3}[name]
    if v.shape != (size,) or not np.isfinite(v).all():
        raise ValueError(f"{name}: expected {size} finite numbers, got {v!r}")
    shown = np.round(v, 4).tolist()
    if name == "plane":
        return (lambda p: (np.array([v[:3] @ p - v[3]]), v[None, :3])), f"the plane {shown}"
    if name == "point":
        return (lambda p: (p - v, np.eye(3))), f"the point {shown}"

    def ball(p: NDArray) -> tuple[NDArray, NDArray]:
        gap = p - v[:3]
        norm = float(np.linalg.norm(gap))
        return np.array([norm - v[3]]), (gap / norm if norm > 0.0 else np.zeros(3))[None]

    return ball, f"the ball (centre, radius) {shown}"


def contact_configurations(
    robot: Robot,
    joint_names: Sequence[str],
    lower: ArrayLike,
    upper: ArrayLike,
    n: int,
    rng: np.random.Generator,
    *,
    frame: str,
    offset: ArrayLike,
    plane: ArrayLike | None = None,
    sphere: ArrayLike | None = None,
    point: ArrayLike | None = None,
    fraction: float = 0.8,
    max_rounds: int = 50,
) -> NDArray[np.float64]:
    """``n`` configurations that put the probe on the plane, the ball or the point,
    within the joint ranges.

    Configurations are drawn by :func:`random_configurations` (``fraction`` of each
    joint range) and each is projected onto the contact manifold by Gauss-Newton steps
    of least norm, ``q <- q - G^+ r(p(q))`` with ``G`` the Jacobian of the contact's
    residuals ``r`` (Pinocchio Jacobian); a projection is kept when it converges
    (:data:`CONTACT_TOLERANCE_M`) within the ``fraction`` of every joint range.

    Parameters
    ----------
    robot : Robot
        The true robot.
    joint_names : sequence of str
        Columns of the configurations.
    lower, upper : array_like, shape (k,)
        Joint limits in ``joint_names`` order (rad, m).
    n : int
        Configurations wanted.
    rng : numpy.random.Generator
    frame : str
        URDF frame carrying the probe.
    offset : array_like, shape (3,)
        The probe's position in ``frame``, metres.
    plane : array_like, shape (4,), optional
        ``(n, d)``: unit normal and offset of the plane ``{x : n . x = d}`` in the root
        frame (metres).
    sphere : array_like, shape (4,), optional
        ``(c, r)``: the ball's centre in the root frame and its radius (metres).
    point : array_like, shape (3,), optional
        The point in the root frame (metres). Exactly one of ``plane``, ``sphere``,
        ``point`` is given.
    fraction : float
    max_rounds : int
        Rounds of ``2 n`` draws before giving up.

    Returns
    -------
    qs : ndarray, shape (n, k)
        In draw order; the probe is within :data:`CONTACT_TOLERANCE_M` of the surface
        (of the point).

    Raises
    ------
    ValueError
        When fewer than ``n`` of ``2 n max_rounds`` draws reach the surface within the
        ranges (out of the probe's reach), or not exactly one surface is given.
    """
    names = tuple(joint_names)
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    offset = np.asarray(offset, dtype=float)
    residual, shown = _surface(plane, sphere, point)
    lo, hi = finite_limits(lower, upper)
    mid, half = 0.5 * (lo + hi), 0.5 * fraction * (hi - lo) + 1e-12
    found: list[NDArray[np.float64]] = []
    for _ in range(max_rounds):
        for q in random_configurations(lower, upper, 2 * n, rng, fraction=fraction):
            for _ in range(MAX_STEPS):
                p, J = _probe_and_jacobian(robot, q, names, frame, offset)
                r, dr_dp = residual(p)
                G = dr_dp @ J
                if np.abs(r).max() < CONTACT_TOLERANCE_M or not np.abs(G).max() > 0.0:
                    break
                q = q - np.linalg.lstsq(G, r, rcond=None)[0]
            if np.abs(r).max() < CONTACT_TOLERANCE_M and np.all(np.abs(q - mid) <= half):
                found.append(q)
                if len(found) == n:
                    return np.array(found)
    raise ValueError(
        f"contacts of {frame!r}: only {len(found)} of {2 * n * max_rounds} random "
        f"configurations reach {shown} within {fraction:g} of the joint ranges; {n} "
        "wanted (is it in reach?)"
    )
