"""Reaching: the joint values that put a robot frame at a pose or a point, with any URDF
model, so a user can check "does my calibrated arm now hit the target".

Damped least squares on Pinocchio's exact frame Jacobian
(:func:`solve_bounded`; Wampler 1986, Nakamura & Hanafusa 1986),
within the joint limits. The residual for a pose target ``root_T_target`` is
``(p - p_target, w log3(R_target^T R))`` (m; the rotation part in radians times the
weight ``w``, metres per radian), for a point target ``p - p_target``; its Jacobian is
``(R J_v, w Jlog3 J_w)`` with ``(J_v, J_w)`` the LOCAL frame Jacobian. A redundant arm
takes the smallest step from ``q_start`` (the damped pseudo-inverse's minimum norm).

Inverse kinematics has several solutions and local minima: when the start does not
reach the target, up to ``restarts`` random configurations within the limits (seeded)
are tried in turn; the answer is the first that reaches it, else the closest; each
revolute joint is then moved by whole turns as near to its start as its limits allow. With the
default 50, 300 of 300 random reachable UR10 poses and 299 of 300 of the 6R test arm's
are reached (20: 300 and 296); an unreachable target costs all 51 starts.

A robot with a model spec (:attr:`kinfw.model.Robot.spec`: a calibration's joint
compliance, gear scales, couplings) is solved in its URDF's joint values, the physical
ones; :attr:`Reach.command` is then the readings that give them
(:meth:`kinfw.model.ModelSpec.readings`): with a compliance, the command that lands the
frame on the target *with* the deflection under gravity and the ``payload``
(compensation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from kinfw.control._solver import (
    BoundedSolution,
    Residual,
    check_configuration,
    check_held_joints,
    middle_configuration,
    nearest_turn,
    solve_bounded,
)
from kinfw.geometry import check_transform
from kinfw.model import STANDARD_GRAVITY, Payloads, Robot, RobotModelError

#: Reached: position within this (m) and rotation within :data:`REACHED_RAD`.
REACHED_M = 1e-6
REACHED_RAD = 1e-6
#: Longest joint step per iteration (rad, m): the linearisation's trust region.
MAX_STEP = 0.3


@dataclass(frozen=True, slots=True)
class Reach:
    """The joint values :func:`reach` found, and how close they come.

    Attributes
    ----------
    joint_names : tuple of str
        The robot's movable joints: the order of :attr:`q`.
    q : ndarray, shape (k,)
        Joint values (rad, m) of the URDF (the physical ones), within the limits; joints
        not freed at ``q_start``.
    frame : str
        The frame that reaches.
    free_joints : tuple of str
        The joints solved for.
    root_T_target : ndarray, shape (4, 4)
        The target in the root frame (m); for a point target, its rotation is unused.
    position_error_m : float
        Distance from the frame's origin to the target's (m), by this model.
    rotation_error_rad : float or None
        Angle between the frame's and the target's rotation (rad); None for a point.
    reached : bool
        Within :data:`REACHED_M` and :data:`REACHED_RAD`.
    at_limits : tuple of str
        Free joints at a limit.
    starts : int
        Starts tried (1 = ``q_start`` sufficed).
    command : ndarray, shape (k,)
        The joint command (the readings) that gives :attr:`q` through the robot's model
        spec under the payload: :attr:`q` itself for a URDF alone.
    """

    joint_names: tuple[str, ...]
    q: NDArray[np.float64]
    frame: str
    free_joints: tuple[str, ...]
    root_T_target: NDArray[np.float64]
    position_error_m: float
    rotation_error_rad: float | None
    reached: bool
    at_limits: tuple[str, ...]
    starts: int
    command: NDArray[np.float64] = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.command is None:
            object.__setattr__(self, "command", self.q)


def reach(
    robot: Robot,
    frame: str,
    target: ArrayLike,
    *,
    q_start: ArrayLike | None = None,
    free_joints: tuple[str, ...] | None = None,
    rotation_weight_m: float = 0.1,
    restarts: int = 50,
    seed: int = 0,
    max_iterations: int = 100,
    payload: Payloads | None = None,
    gravity: ArrayLike = STANDARD_GRAVITY,
) -> Reach:
    """Joint values that put ``frame`` at ``target`` (module docstring).

    Parameters
    ----------
    robot : Robot
        The model (nominal or calibrated).
    frame : str
        A link or joint of the robot.
    target : array_like, shape (4, 4) or (3,)
        ``root_T_target`` (a pose to reach) or ``root_p_target`` (a point for the
        frame's origin), in the root frame, metres.
    q_start : array_like, shape (k,), optional
        All movable joints (:attr:`Robot.joint_names` order): the first start, and the
        values of joints not freed; default the middle of each range (zero if unbounded).
    free_joints : tuple of str, optional
        The joints to solve for; default every movable joint on the path to ``frame``.
    rotation_weight_m : float
        Metres per radian of rotation error in the least squares (matters only when the
        target cannot be reached exactly).
    restarts : int
        Random starts after ``q_start`` at most.
    seed : int
        Seed of the random starts.
    max_iterations : int
        Iterations per start.
    payload : Payloads, optional
        What the robot carries (one sample: ``Payloads.constant(1, FRAME, MASS_KG,
        COM_M)``); with a compliance in the robot's spec, :attr:`Reach.command`
        compensates its deflection. Default none.
    gravity : array_like, shape (3,)
        In the root frame, m/s^2.

    Raises
    ------
    RobotModelError
        An unknown frame or joint, a fixed joint freed, no joint moving the frame, or a
        bad target or ``q_start`` (naming it).
    """
    frame_id = robot.frame_id(frame)
    free = robot.movable_path(frame) if free_joints is None else tuple(free_joints)
    if not set(free) & set(robot.movable_path(frame)):
        raise RobotModelError(f"frame {frame!r}: none of the joints {list(free)} moves it")
    v_columns = np.array([robot.velocity_index(n) for n in free], dtype=int)
    columns = np.array([robot.joint_names.index(n) for n in free], dtype=int)
    root_T_target, is_pose = _target(target)
    lower, upper = robot.joint_limits(free)
    q = middle_configuration(robot) if q_start is None else check_configuration(robot, q_start)
    check_held_joints(robot, q, free)
    residual = _frame_residual(
        robot, frame_id, q, columns, v_columns, root_T_target, is_pose, rotation_weight_m
    )
    starts, solution, (position_error, rotation_error) = _best_start(
        residual,
        q[columns].copy(),
        lower,
        upper,
        restarts,
        seed,
        max_iterations,
        is_pose,
        rotation_weight_m,
    )
    revolute = np.array([robot.joint(n).is_revolute for n in free])
    x = nearest_turn(solution.x, starts[0], lower, upper, revolute)
    q[columns] = x
    at_limit = (x <= lower) | (x >= upper)
    command = q
    if robot.spec:
        command = robot.spec.readings(robot, robot.joint_names, q[None], payload, gravity)[0]
    return Reach(
        joint_names=robot.joint_names,
        q=q,
        frame=frame,
        free_joints=free,
        root_T_target=root_T_target,
        position_error_m=position_error,
        rotation_error_rad=rotation_error,
        reached=position_error <= REACHED_M
        and (rotation_error is None or rotation_error <= REACHED_RAD),
        at_limits=tuple(n for n, b in zip(free, at_limit, strict=True) if b),
        starts=len(starts),
        command=command,
    )


def _frame_residual(
    robot: Robot,
    frame_id: int,
    q: NDArray[np.float64],
    columns: NDArray[np.int_],
    v_columns: NDArray[np.int_],
    root_T_target: NDArray[np.float64],
    is_pose: bool,
    rotation_weight_m: float,
) -> Residual:
    """The residual of ``frame`` against the target as a function of the free joints.

    ``residual(x, jacobian)`` writes ``x`` into ``q[columns]`` (``q`` is updated in
    place) and returns the position error (m) and, for a pose, the rotation error
    (``log3``, rad) times ``rotation_weight_m``, with the Jacobian in the free joints'
    velocity columns ``v_columns`` if ``jacobian``.
    """
    data = robot.model.createData()
    target_M = pin.SE3(root_T_target[:3, :3], root_T_target[:3, 3])

    def residual(x, jacobian):
        q[columns] = x
        configuration = robot.pin_configurations(q)[0]
        if jacobian:
            pin.computeJointJacobians(robot.model, data, configuration)
        else:
            pin.forwardKinematics(robot.model, data, configuration)
        root_M_frame = pin.updateFramePlacement(robot.model, data, frame_id)
        position = root_M_frame.translation - target_M.translation
        if is_pose:
            rotation = pin.log3(target_M.rotation.T @ root_M_frame.rotation)
            r = np.concatenate([position, rotation_weight_m * rotation])
        else:
            r = position
        if not jacobian:
            return r, None
        local = pin.getFrameJacobian(robot.model, data, frame_id, pin.LOCAL)
        local = local.reshape(6, -1)[:, v_columns]  # (6,) for a one-joint model
        jac = root_M_frame.rotation @ local[:3]
        if is_pose:
            jac_rotation = pin.Jlog3(target_M.rotation.T @ root_M_frame.rotation) @ local[3:]
            jac = np.vstack([jac, rotation_weight_m * jac_rotation])
        return r, jac

    return residual


def _best_start(
    residual: Residual,
    x_first: NDArray[np.float64],
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
    restarts: int,
    seed: int,
    max_iterations: int,
    is_pose: bool,
    rotation_weight_m: float,
) -> tuple[list[NDArray[np.float64]], BoundedSolution, tuple[float, float | None]]:
    """Solve from ``x_first``, then from random starts, until one reaches the target.

    Random starts are uniform in the joint ranges (an unbounded side at +-pi), at most
    ``restarts`` of them. Returns the starts tried, the solution of least cost and its
    (position m, rotation rad or None) errors.
    """
    rng = np.random.default_rng(seed)
    starts = [x_first]
    wide_lower = np.where(np.isfinite(lower), lower, -math.pi)
    wide_upper = np.where(np.isfinite(upper), upper, math.pi)
    best = None
    for start in range(restarts + 1):
        if start > 0:
            starts.append(rng.uniform(wide_lower, wide_upper))
        solution = solve_bounded(
            residual, starts[start], lower, upper, max_iterations=max_iterations, max_step=MAX_STEP
        )
        errors = _errors(solution.residual, is_pose, rotation_weight_m)
        reached = errors[0] <= REACHED_M and (errors[1] is None or errors[1] <= REACHED_RAD)
        cost = float(solution.residual @ solution.residual)
        if best is None or cost < best[0]:
            best = (cost, solution, errors)
        if reached:
            break
    _, solution, errors = best
    return starts, solution, errors


def _target(target: ArrayLike) -> tuple[NDArray[np.float64], bool]:
    array = np.asarray(target, dtype=float)
    if array.shape == (3,):
        if not np.all(np.isfinite(array)):
            raise RobotModelError(f"target point: expected 3 finite numbers, got {array}")
        root_T_target = np.eye(4)
        root_T_target[:3, 3] = array
        return root_T_target, False
    if array.shape != (4, 4):
        raise RobotModelError(
            f"target: expected a point (3,) or a pose (4, 4), got shape {array.shape}"
        )
    try:
        return check_transform(array, "target"), True
    except ValueError as error:
        raise RobotModelError(str(error)) from None


def _errors(
    r: NDArray[np.float64], is_pose: bool, rotation_weight_m: float
) -> tuple[float, float | None]:
    position = float(np.linalg.norm(r[:3]))
    if not is_pose:
        return position, None
    return position, float(np.linalg.norm(r[3:])) / rotation_weight_m
