"""The "true" robot and the measurement protocols of the simulated experiments.

- a "true" robot: the nominal URDF with random geometric errors
  (:func:`perturb_robot`, as in Shih et al. (1992), section 6);
- measurement protocols: one joint at a time, as section 4.1 requires
  (:func:`one_joint_at_a_time`), and random configurations for held-out tests
  (:func:`random_configurations`).

The observations made in those configurations are simulated by
:mod:`kinfw.simulation`. Every random draw comes from a ``numpy.random.Generator``
passed in by the caller.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import transform_from_rotation_translation
from kinfw.model import JointInfo, Robot
from kinfw.observations import random_small_rotations
from kinfw.urdf import edit_urdf

_UNBOUNDED = np.pi
"""Half range (rad, or m for a prismatic joint) used in place of an infinite limit."""


# -- random helpers --------------------------------------------------------------------


def check_sigma(value: float, name: str) -> float:
    """``value`` as a float, checked to be a finite standard deviation >= 0 (``name`` in the
    message)."""
    value = float(value)
    if not (np.isfinite(value) and value >= 0.0):
        raise ValueError(f"{name}: expected a finite standard deviation >= 0, got {value}")
    return value


# -- the true robot --------------------------------------------------------------------


def _default_perturbed_joints(robot: Robot) -> tuple[str, ...]:
    """Movable joints, fixed joints off the root link and fixed joints at branch ends.

    A fixed joint is at a branch end when no movable joint lies below it (the rigid
    chain from the last movable joint to a leaf link: plate, camera, flange, tool).
    """
    children: dict[str, list[JointInfo]] = {}
    for j in robot.joints:
        children.setdefault(j.parent, []).append(j)

    def moves_below(link: str) -> bool:
        return any(j.is_movable or moves_below(j.child) for j in children.get(link, ()))

    return tuple(
        j.name
        for j in robot.joints
        if j.is_movable
        or (j.type == "fixed" and (j.parent == robot.root_link or not moves_below(j.child)))
    )


def perturb_robot(
    robot: Robot,
    rng: np.random.Generator,
    *,
    origin_mm: float = 2.0,
    origin_deg: float = 0.5,
    axis_deg: float = 0.5,
    joints: Sequence[str] | None = None,
) -> str:
    """URDF text of a "true" robot: the nominal one with random geometric errors.

    For each perturbed joint, the ``<origin>`` ``parent_T_child`` becomes
    ``[R dR, p + dp]``: ``dp`` has independent N(0, ``origin_mm``) components (in the
    parent link), ``dR`` is a rotation about a uniformly random axis by an angle
    N(0, ``origin_deg``) (applied on the child side, so the joint axis turns with the
    origin). The ``<axis>`` ``a`` of a movable joint is then tilted by an angle
    N(0, ``axis_deg``) about a uniformly random direction perpendicular to it, and stays
    a unit vector. Everything else in the file is kept (written by
    :func:`kinfw.urdf.edit_urdf`).

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    rng : numpy.random.Generator
        Source of every random draw.
    origin_mm : float, optional
        Standard deviation of each origin translation component, millimetres.
    origin_deg : float, optional
        Standard deviation of the origin rotation angle, degrees.
    axis_deg : float, optional
        Standard deviation of the axis tilt angle, degrees.
    joints : sequence of str, optional
        Joints to perturb. Default: every movable joint, every fixed joint whose parent
        is the root link (the root-to-base joint, e.g. the world-to-base transform) and
        every fixed joint leading to leaf links with no movable joint below it (the rigid
        ends of the branches: plates, cameras mounted on them, flanges, tools). Fixed
        joints between two movable ones are kept nominal.

    Returns
    -------
    str
        The true robot's URDF text; load it with :func:`kinfw.model.load_robot`.

    Notes
    -----
    The paper's simulation (Fig. 10) uses the DH model of its Table 3 as the truth;
    perturbing the nominal model gives a truth that differs from the model an
    identification starts from, as a real robot does.
    """
    origin_m = check_sigma(origin_mm, "origin_mm") * 1e-3
    origin_rad = np.deg2rad(check_sigma(origin_deg, "origin_deg"))
    axis_rad = np.deg2rad(check_sigma(axis_deg, "axis_deg"))
    if isinstance(joints, str):
        raise TypeError("perturb_robot: joints must be a sequence of joint names, not a string")
    names = _default_perturbed_joints(robot) if joints is None else tuple(joints)
    joint_origins: dict[str, NDArray[np.float64]] = {}
    joint_axes: dict[str, NDArray[np.float64]] = {}
    for name in names:
        j = robot.joint(name)  # raises UnknownFrameError naming the joint
        parent_T_child = j.parent_T_child
        dp = rng.normal(0.0, origin_m, size=3)
        dR = random_small_rotations(rng, 1, origin_rad)[0]
        joint_origins[name] = transform_from_rotation_translation(
            parent_T_child[:3, :3] @ dR, parent_T_child[:3, 3] + dp
        )
        if j.is_movable:
            joint_axes[name] = _tilted_axis(j.axis, rng, axis_rad)
    return edit_urdf(robot.urdf_xml, joint_origins=joint_origins, joint_axes=joint_axes)


def _tilted_axis(
    axis: NDArray[np.float64], rng: np.random.Generator, sigma_rad: float
) -> NDArray[np.float64]:
    """Unit ``axis`` turned by N(0, sigma_rad) about a random direction perpendicular to it."""
    u = rng.normal(size=3)
    u -= (u @ axis) * axis
    u /= np.linalg.norm(u)
    angle = rng.normal(0.0, sigma_rad)
    # Rotation about u ⟂ axis: axis -> cos(angle) axis + sin(angle) u x axis.
    tilted = np.cos(angle) * axis + np.sin(angle) * np.cross(u, axis)
    return tilted / np.linalg.norm(tilted)


# -- measurement protocols -------------------------------------------------------------


def finite_limits(
    lower: ArrayLike, upper: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Joint limits (k,) checked, an infinite limit replaced by -pi or +pi (rad, or m)
    (:func:`random_configurations` draws in these ranges); ValueError naming the fault."""
    lower = np.array(lower, dtype=float, ndmin=1)
    upper = np.array(upper, dtype=float, ndmin=1)
    if lower.ndim != 1 or lower.shape != upper.shape:
        raise ValueError(
            f"lower, upper: expected two arrays of shape (k,), got {lower.shape} and {upper.shape}"
        )
    if np.isnan(lower).any() or np.isnan(upper).any():
        raise ValueError("lower, upper: limits must not be NaN")
    lower = np.where(np.isneginf(lower), -_UNBOUNDED, lower)
    upper = np.where(np.isposinf(upper), _UNBOUNDED, upper)
    if not (np.isfinite(lower).all() and np.isfinite(upper).all()):
        raise ValueError("lower, upper: lower limits must not be +inf nor upper limits -inf")
    bad = np.flatnonzero(lower > upper)
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"lower, upper: joint {i} has lower {lower[i]:.6g} > upper {upper[i]:.6g}")
    return lower, upper


def _check_fraction(fraction: float) -> float:
    fraction = float(fraction)
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction: expected 0 < fraction <= 1, got {fraction}")
    return fraction


def one_joint_at_a_time(
    lower: ArrayLike,
    upper: ArrayLike,
    *,
    per_joint: int = 9,
    fraction: float = 0.8,
    q0: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The measurement protocol of Shih et al. (1992), section 4.1 (their Fig. 8).

    Sample 0 is the initial configuration ``q0``; then each joint ``i`` in turn takes
    ``per_joint`` values ``q_ik`` (k = 1..M) while every other joint stays at ``q0``:
    ``M * N + 1`` configurations for ``N`` joints and ``M = per_joint``.

    Parameters
    ----------
    lower, upper : array_like, shape (N,)
        Joint limits (rad or m) in ``joint_names`` order; an infinite limit (continuous
        joint) is replaced by -pi or +pi.
    per_joint : int, optional
        Values per joint, ``M`` (the paper uses nine).
    fraction : float, optional
        Part of each range used, centred on the middle of the range (0 < fraction <= 1).
    q0 : array_like, shape (N,), optional
        Initial configuration; default the middle of each range.

    Returns
    -------
    qs : ndarray, shape (M * N + 1, N)
        Joint values (rad or m).
    moved : ndarray of int64, shape (M * N + 1,)
        Index of the joint moved in each sample; -1 for sample 0 (``q0``).

    Notes
    -----
    The values of joint ``i`` are ``M + 1`` evenly spaced points spanning the centred
    ``fraction`` of its range, less the one nearest ``q0_i`` — so none equals ``q0_i``
    (such a sample would add nothing) and, unless ``q0_i`` is nearest an end point, they
    span the whole ``fraction``.
    """
    lower, upper = finite_limits(lower, upper)
    per_joint = int(per_joint)
    if per_joint < 1:
        raise ValueError(f"per_joint: expected at least 1 value per joint, got {per_joint}")
    fraction = _check_fraction(fraction)
    mid, half = 0.5 * (lower + upper), 0.5 * (upper - lower) * fraction
    n_joints = len(lower)
    if q0 is None:
        q0 = mid
    q0 = np.array(q0, dtype=float, ndmin=1)
    if q0.shape != (n_joints,) or not np.isfinite(q0).all():
        raise ValueError(f"q0: expected {n_joints} finite values, got shape {q0.shape}")
    flat = np.flatnonzero(half <= 0.0)
    if flat.size:
        raise ValueError(
            f"lower, upper: joint {int(flat[0])} has an empty range "
            f"[{lower[flat[0]]:.6g}, {upper[flat[0]]:.6g}]; it cannot be moved"
        )
    t = np.linspace(-1.0, 1.0, per_joint + 1)
    candidates = mid[:, None] + half[:, None] * t  # (N, M + 1)
    drop = np.argmin(np.abs(candidates - q0[:, None]), axis=1)
    keep = np.ones_like(candidates, dtype=bool)
    keep[np.arange(n_joints), drop] = False
    values = candidates[keep].reshape(n_joints, per_joint)  # (N, M)

    qs = np.tile(q0, (n_joints * per_joint + 1, 1))
    moved = np.full(n_joints * per_joint + 1, -1, dtype=np.int64)
    rows = 1 + np.arange(n_joints * per_joint)
    moved[1:] = np.repeat(np.arange(n_joints), per_joint)
    qs[rows, moved[1:]] = values.ravel()
    return qs, moved


def random_configurations(
    lower: ArrayLike, upper: ArrayLike, n: int, rng: np.random.Generator, *, fraction: float = 1.0
) -> NDArray[np.float64]:
    """Configurations drawn uniformly in the centred ``fraction`` of each joint's range.

    Parameters
    ----------
    lower, upper : array_like, shape (k,)
        Joint limits (rad or m); an infinite limit is replaced by -pi or +pi.
    n : int
        Number of configurations.
    rng : numpy.random.Generator
    fraction : float, optional
        Part of each range used, centred on its middle (0 < fraction <= 1).

    Returns
    -------
    ndarray, shape (n, k)
        Joint values (rad or m).
    """
    lower, upper = finite_limits(lower, upper)
    fraction = _check_fraction(fraction)
    if int(n) < 0:
        raise ValueError(f"n: expected a number of configurations >= 0, got {n}")
    mid, half = 0.5 * (lower + upper), 0.5 * (upper - lower) * fraction
    return mid + half * rng.uniform(-1.0, 1.0, size=(int(n), len(lower)))
