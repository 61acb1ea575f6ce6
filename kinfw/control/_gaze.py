"""Fixation for a branched head: the joint values that put a 3D point on each camera's
optical axis (or on a chosen pixel), with any URDF model, nominal or calibrated.

Shih et al. (1992) close with "our next goal is to develop an inverse kinematic
solution" for the calibrated head; this is it, for any robot whose cameras are URDF
frames (optical convention: z along the optical axis, x right, y down).

The problem. Camera ``k`` should see the point ``root_p`` along the ray ``ray_k`` (unit,
camera frame; the optical axis ``(0, 0, 1)`` by default, or the back-projection of a
pixel, :meth:`kinfw.camera.CameraIntrinsics.rays`). With ``camera_p = camera_T_root
root_p`` expressed in a frame whose z is ``ray_k`` (``s = ray_R^T camera_p``), the two
residuals per camera are the tangents ``(s_x / s_z, s_y / s_z)`` of the angle between the
ray and the point. With ``s = ray_R^T camera_p`` (``ray_R`` a rotation whose z is the
ray), they are the stereographic coordinates ``2 s_xy / (|s| + s_z)``, of length
``2 tan(angle / 2)``: zero exactly when the point is on the ray in front of the camera,
smooth and growing with the angle all the way to a point behind the camera (where a
tangent ``s_xy / s_z`` would flip sign), so an unreachable point still has a closest
fixation. Their Jacobian is exact, from Pinocchio's frame Jacobian (LOCAL):
``d camera_p / dq = -J_v + [camera_p]_x J_w``.

The joints. By default, each camera's own joints (the vergences) and as many of the
joints shared by all cameras, nearest the cameras first (tilt, then pan), as make two
per camera: pan, tilt and both vergences on the IIS head; the X-Y table stays where
``q_start`` puts it unless ``free_joints`` frees it. Joints not freed keep their
``q_start`` value.

The solution. A closed-form start, then bounded Gauss-Newton on the exact kinematics
(:func:`solve_bounded`):

- start: each free revolute joint, root first, in turn turns its cameras' rays towards
  the point in closed form. Rotating a direction ``d`` about the unit axis ``a`` by
  ``t`` gives ``d(t) = (a.d) a + cos t d_perp + sin t (a x d_perp)``, so the sum of
  ``d_k(t) . w_k`` over the joint's cameras (``w_k`` the unit direction from camera
  ``k`` to the point) is largest at ``t = atan2(sum (a x d_perp) . w, sum d_perp . w)``
  (Paden-Kahan subproblem 1; Murray, Li & Sastry 1994, §3.3). This is exact when the
  camera's optical centre lies on the axis; the offsets of a real head make it a start.
- Gauss-Newton: to 1e-12 rad when the point can be fixated. When it cannot (out of
  range, or a geometry that cannot remove a vertical disparity: the nominal IIS head
  carries its right camera 150 mm higher up the vergence axis than the left, and one
  tilt joint cannot match both elevations), the closest achievable fixation in the
  least-squares sense of those coordinates, with each camera's remaining angle in
  :attr:`Fixation.error_rad`. Directions the joints barely move the residual in (on the
  IIS head, trading pan against both vergences to shave a vertical disparity) are left
  alone (``rcond``), so the head does not swing across its range for a negligible gain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from kinfw.control._solver import (
    check_configuration,
    check_held_joints,
    middle_configuration,
    solve_bounded,
    solve_weak_directions,
)
from kinfw.geometry import angle_between
from kinfw.model import Robot, RobotModelError

#: A point is fixated when every camera's remaining angle is below this (rad).
FIXATED_RAD = 1e-6
#: Singular values below this fraction of the largest are left out of a step.
RCOND = 1e-2
#: A solve that leaves between 1e-12 rad and this may be an exact fixation that needs the
#: left-out directions: it is continued along them (``solve_weak_directions``).
POLISH_BELOW_RAD = 1e-3


@dataclass(frozen=True, slots=True)
class Fixation:
    """The joint values that fixate a point, and how well (:func:`fixate`).

    Attributes
    ----------
    joint_names : tuple of str
        The robot's movable joints: the order of :attr:`q`.
    q : ndarray, shape (k,)
        Joint values (rad, m) of the whole robot: the free joints solved, the others at
        their ``q_start`` values.
    free_joints : tuple of str
        The joints that were solved for.
    cameras : tuple of str
        The camera frames, the order of :attr:`error_rad`.
    root_p_point : ndarray, shape (3,)
        The point, in the robot's root frame (m).
    camera_rays : ndarray, shape (n_cameras, 3)
        Each camera's aimed ray, unit, in its own frame.
    error_rad : ndarray, shape (n_cameras,)
        Angle between each camera's ray and the point, by this model (rad): zero for a
        fixated point; otherwise the closest achievable fixation's remaining error.
    fixated : bool
        Every error below :data:`FIXATED_RAD`.
    at_limits : tuple of str
        Free joints held at a limit.
    iterations : int
        Gauss-Newton iterations.
    rank : int
        Independent directions in which the free joints move the cameras' rays at the
        answer (singular values of the residual's Jacobian above :data:`RCOND` times the
        largest). Below two per camera, the joints cannot turn every ray in every
        direction independently (too few free joints, a roll about an optical axis, two
        cameras on one tilt: rank 3 of 4), so only points whose rays agree with that
        coupling can be fixated exactly: a head with both cameras at one height fixates
        everywhere, the IIS head (its vertical disparity) only near 4 m.
    command : ndarray, shape (k,)
        The joint command (the readings) that gives :attr:`q` through the robot's model
        spec (a calibration's gear scales, couplings, compliance under gravity:
        :meth:`kinfw.model.ModelSpec.readings`); :attr:`q` itself for a URDF alone.
    """

    joint_names: tuple[str, ...]
    q: NDArray[np.float64]
    free_joints: tuple[str, ...]
    cameras: tuple[str, ...]
    root_p_point: NDArray[np.float64]
    camera_rays: NDArray[np.float64]
    error_rad: NDArray[np.float64]
    fixated: bool
    at_limits: tuple[str, ...]
    iterations: int
    rank: int
    command: NDArray[np.float64] = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.command is None:
            object.__setattr__(self, "command", self.q)


def default_free_joints(robot: Robot, cameras: tuple[str, ...]) -> tuple[str, ...]:
    """Each camera's own movable joints, then as many of the joints shared by all
    cameras, nearest the cameras first, as make two per camera (module docstring); all
    joints on the cameras' paths when they are fewer. URDF order."""
    paths = [robot.movable_path(c) for c in cameras]
    on_paths = [n for n in robot.joint_names if any(n in p for p in paths)]
    shared = [n for n in paths[0] if all(n in p for p in paths)]
    private = [n for n in on_paths if n not in shared]
    needed = 2 * len(cameras) - len(private)
    chosen = set(private) | set(shared[len(shared) - needed :] if needed > 0 else ())
    return tuple(n for n in on_paths if n in chosen)


def camera_points(root_T_cameras: ArrayLike, root_p_point: ArrayLike) -> NDArray[np.float64]:
    """A point in each camera's frame, ``camera_T_root @ root_p``.

    Parameters
    ----------
    root_T_cameras : array_like, shape (..., 4, 4)
        Camera poses in the root frame (m).
    root_p_point : array_like, shape (..., 3)
        The point in the root frame (m), broadcast against the cameras.

    Returns
    -------
    ndarray, shape (..., 3)
        ``camera_p`` (m).
    """
    root_T = np.asarray(root_T_cameras, dtype=float)
    toward = np.asarray(root_p_point, dtype=float) - root_T[..., :3, 3]
    return np.einsum("...ji,...j->...i", root_T[..., :3, :3], toward)


def ray_errors_rad(
    root_T_cameras: ArrayLike, camera_rays: ArrayLike, root_p_point: ArrayLike
) -> NDArray[np.float64]:
    """Angle between each camera's ray and the direction from the camera to the point.

    Parameters
    ----------
    root_T_cameras : array_like, shape (..., 4, 4)
        Camera poses in the root frame (m).
    camera_rays : array_like, shape (..., 3)
        Rays in each camera's frame (any length).
    root_p_point : array_like, shape (..., 3)
        The point in the root frame (m).

    Returns
    -------
    ndarray, shape (...)
        Angles in [0, pi] (rad).
    """
    return angle_between(camera_rays, camera_points(root_T_cameras, root_p_point))


def fixate(
    robot: Robot,
    root_p_point: ArrayLike,
    *,
    cameras: tuple[str, ...] | None = None,
    camera_rays: ArrayLike | None = None,
    q_start: ArrayLike | None = None,
    free_joints: tuple[str, ...] | None = None,
) -> Fixation:
    """Joint values that put ``root_p_point`` on every camera's ray (module docstring):
    ``GazeSolver(robot, cameras, free_joints=free_joints).fixate(...)``; build a
    :class:`GazeSolver` once to fixate many points."""
    solver = GazeSolver(robot, cameras, free_joints=free_joints)
    return solver.fixate(root_p_point, camera_rays=camera_rays, q_start=q_start)


class GazeSolver:
    """Fixation of points by one robot model's cameras (module docstring).

    Parameters
    ----------
    robot : Robot
        The model to fixate with (nominal or calibrated).
    cameras : tuple of str, optional
        Camera frames (z = optical axis); default the URDF's ``<kinfw cameras>`` hint.
    free_joints : tuple of str, optional
        The joints to solve for; default :func:`default_free_joints`.

    Raises
    ------
    RobotModelError
        No cameras, an unknown camera or joint, a fixed joint freed, or a camera no
        free joint moves (naming it).
    """

    def __init__(
        self,
        robot: Robot,
        cameras: tuple[str, ...] | None = None,
        *,
        free_joints: tuple[str, ...] | None = None,
    ) -> None:
        cameras = robot.default_cameras if cameras is None else tuple(cameras)
        if not cameras:
            raise RobotModelError(
                f"{robot.source}: no cameras given and the URDF has no <kinfw cameras> hint"
            )
        self.frame_ids = [robot.frame_id(c) for c in cameras]  # raises naming the links
        free = default_free_joints(robot, cameras) if free_joints is None else tuple(free_joints)
        self.v_columns = np.array([robot.velocity_index(n) for n in free])  # raises if fixed
        paths = [set(robot.movable_path(c)) for c in cameras]
        for c, path in zip(cameras, paths, strict=True):
            if not path & set(free):
                raise RobotModelError(
                    f"camera {c!r}: none of the free joints {list(free)} moves it"
                )
        self.robot, self.cameras, self.free_joints = robot, cameras, free
        self.model, self.data = robot.model, robot.model.createData()
        self.free_columns = np.array([robot.joint_names.index(n) for n in free], dtype=int)
        self.lower, self.upper = robot.joint_limits(free)
        self.moves = np.array([[n in p for p in paths] for n in free])  # (k, n_cameras)
        self.revolute = np.array([robot.joint(n).is_revolute for n in free])
        self.joint_ids = [self.model.getJointId(n) for n in free]
        self.q_slots = np.array([self.model.joints[i].idx_q for i in self.joint_ids], dtype=int)
        self.continuous = np.array([self.model.joints[i].nq == 2 for i in self.joint_ids])
        self.q_middle = middle_configuration(robot)

    def fixate(
        self,
        root_p_point: ArrayLike,
        *,
        camera_rays: ArrayLike | None = None,
        q_start: ArrayLike | None = None,
        max_iterations: int = 50,
    ) -> Fixation:
        """Joint values that put ``root_p_point`` on every camera's ray.

        Parameters
        ----------
        root_p_point : array_like, shape (3,)
            The point in the robot's root frame (the measurement frame), metres.
        camera_rays : array_like, shape (n_cameras, 3), optional
            The ray each camera should see the point along, in its frame (any length,
            z > 0); default the optical axes. A pixel's ray:
            :meth:`kinfw.camera.CameraIntrinsics.rays`.
        q_start : array_like, shape (k,), optional
            All movable joints (:attr:`Robot.joint_names` order, rad / m): the start,
            and the values of the joints not freed; default the middle of each joint's
            range (zero where unbounded).
        max_iterations : int
            Gauss-Newton iterations at most.

        Returns
        -------
        Fixation
            Always a configuration within the joint limits: the fixation, or the closest
            achievable one with its remaining error (``fixated`` False).

        Raises
        ------
        RobotModelError
            A bad point, ray or ``q_start`` (naming it), or a point at a camera's
            optical centre or exactly behind it at the start.
        """
        point = np.asarray(root_p_point, dtype=float)
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            raise RobotModelError(f"point: expected 3 finite numbers (m), got {point.tolist()}")
        rays = self._rays(camera_rays)
        if q_start is None:
            q = self.q_middle.copy()  # within the limits
        else:
            q = check_configuration(self.robot, q_start)
            check_held_joints(self.robot, q, self.free_joints)
        residual = _GazeResidual(self, rays, point, self.robot.pin_configurations(q)[0])
        x = residual.aim(np.clip(q[self.free_columns], self.lower, self.upper))
        try:
            solution = solve_bounded(
                residual, x, self.lower, self.upper, rcond=RCOND, max_iterations=max_iterations
            )
        except ValueError:
            raise RobotModelError(
                f"point {point.tolist()}: at a camera's optical centre or exactly behind it "
                "at the start configuration; give another q_start"
            ) from None
        errors = _angles(solution.residual)
        iterations = solution.iterations
        if 1e-12 < errors.max() < POLISH_BELOW_RAD:
            # near the IIS head's 4 m curve the truncated solve stops at 1e-7 - 1e-5 rad:
            # follow the left-out directions, kept only when that fixates
            polish = solve_weak_directions(residual, solution, self.lower, self.upper, rcond=RCOND)
            polished = _angles(polish.residual)
            if polished.max() < FIXATED_RAD:
                solution, errors = polish, polished
            iterations = polish.iterations
        q[self.free_columns] = solution.x
        at_limit = (solution.x <= self.lower) | (solution.x >= self.upper)
        return Fixation(
            joint_names=self.robot.joint_names,
            q=q,
            free_joints=self.free_joints,
            cameras=self.cameras,
            root_p_point=point,
            camera_rays=rays,
            error_rad=errors,
            fixated=bool(np.all(errors < FIXATED_RAD)),
            at_limits=tuple(n for n, b in zip(self.free_joints, at_limit, strict=True) if b),
            iterations=iterations,
            rank=_rank(solution.jacobian),
            command=self.robot.spec.readings(self.robot, self.robot.joint_names, q[None])[0]
            if self.robot.spec
            else q,
        )

    def _rays(self, camera_rays: ArrayLike | None) -> NDArray[np.float64]:
        if camera_rays is None:
            return np.tile([0.0, 0.0, 1.0], (len(self.cameras), 1))
        rays = np.asarray(camera_rays, dtype=float)
        if rays.shape != (len(self.cameras), 3) or not np.all(np.isfinite(rays)):
            raise RobotModelError(
                f"camera_rays: expected shape ({len(self.cameras)}, 3) for cameras "
                f"{list(self.cameras)}, got {rays.shape}"
            )
        for c, ray in zip(self.cameras, rays, strict=True):
            if ray[2] <= 0.0:
                raise RobotModelError(
                    f"camera {c!r}: ray {ray.tolist()} does not point forward (z > 0)"
                )
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)


class _GazeResidual:
    """The residual of :meth:`GazeSolver.fixate` over the free joints' values."""

    def __init__(
        self,
        solver: GazeSolver,
        rays: NDArray[np.float64],
        point: NDArray[np.float64],
        configuration0: NDArray[np.float64],
    ) -> None:
        self.s, self.rays, self.point = solver, rays, point
        self.configuration0 = configuration0
        # each camera's frame turned so that its z is the ray: s = ray_R^T camera_p
        self.ray_Rs = None if np.all(rays[:, :2] == 0.0) else [_frame_with_z(r) for r in rays]

    def configuration(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        s = self.s
        configuration = self.configuration0.copy()
        configuration[s.q_slots] = x
        cos_sin = s.q_slots[s.continuous]
        configuration[cos_sin] = np.cos(x[s.continuous])
        configuration[cos_sin + 1] = np.sin(x[s.continuous])
        return configuration

    def __call__(
        self, x: NDArray[np.float64], jacobian: bool
    ) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
        model, data = self.s.model, self.s.data
        if jacobian:
            pin.computeJointJacobians(model, data, self.configuration(x))
        else:
            pin.forwardKinematics(model, data, self.configuration(x))
        r = np.empty(2 * len(self.rays))
        jac = np.empty((len(r), model.nv)) if jacobian else None  # all joints' columns
        for k, fid in enumerate(self.s.frame_ids):
            root_M_camera = pin.updateFramePlacement(model, data, fid)
            camera_p = (self.point - root_M_camera.translation) @ root_M_camera.rotation
            s = camera_p if self.ray_Rs is None else camera_p @ self.ray_Rs[k]
            norm = math.sqrt(s @ s)
            denominator = norm + s[2]
            if not denominator > 1e-12 * (1.0 + norm):  # at the centre or exactly behind
                return None, None
            r_k = r[2 * k : 2 * k + 2]
            r_k[:] = 2.0 * s[:2] / denominator
            if jacobian:
                local = pin.getFrameJacobian(model, data, fid, pin.LOCAL).reshape(6, -1)
                d_s = pin.skew(camera_p) @ local[3:] - local[:3]
                if self.ray_Rs is not None:
                    d_s = self.ray_Rs[k].T @ d_s
                d_denominator = (s @ d_s) / norm + d_s[2]
                jac[2 * k : 2 * k + 2] = (
                    2.0 * d_s[:2] - r_k[:, None] * d_denominator
                ) / denominator
        return r, (jac[:, self.s.v_columns] if jacobian else None)

    def aim(self, x: NDArray[np.float64], sweeps: int = 1) -> NDArray[np.float64]:
        """The closed-form start (module docstring): each free revolute joint, root
        first, turns its cameras' rays towards the point; ``sweeps`` passes (one suffices as
        a start: Gauss-Newton converges from it in 3-5 steps on the IIS head)."""
        s, x = self.s, x.copy()
        for _ in range(sweeps):
            for j in np.flatnonzero(s.revolute):
                pin.computeJointJacobians(s.model, s.data, self.configuration(x))
                # reshape: Pinocchio returns a (6,) vector for a one-joint model
                jacobian = pin.getJointJacobian(s.model, s.data, s.joint_ids[j], pin.WORLD)
                axis = jacobian.reshape(6, -1)[3:, s.v_columns[j]]
                axis = axis / math.sqrt(axis @ axis)
                num = den = 0.0
                for k in np.flatnonzero(s.moves[j]):
                    root_M_camera = pin.updateFramePlacement(s.model, s.data, s.frame_ids[k])
                    d = root_M_camera.rotation @ self.rays[k]
                    w = self.point - root_M_camera.translation
                    w_norm = math.sqrt(w @ w)
                    if w_norm == 0.0:
                        continue
                    d_perp = d - (axis @ d) * axis
                    num += (pin.skew(axis) @ d_perp) @ w / w_norm
                    den += d_perp @ w / w_norm
                x[j] = min(max(x[j] + math.atan2(num, den), s.lower[j]), s.upper[j])
        return x


def _rank(jacobian: NDArray[np.float64]) -> int:
    """Singular values above :data:`RCOND` times the largest."""
    s = np.linalg.svd(jacobian, compute_uv=False)
    return int(np.sum(s > RCOND * s[0])) if s[0] > 0.0 else 0


def _angles(residual: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each camera's angle (rad) from its stereographic coordinates (length 2 tan(a/2))."""
    return 2.0 * np.arctan(0.5 * np.linalg.norm(residual.reshape(-1, 2), axis=1))


def _frame_with_z(ray: NDArray[np.float64]) -> NDArray[np.float64]:
    """A rotation whose third column is the unit ``ray``."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(ray[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = pin.skew(helper) @ ray
    x /= math.sqrt(x @ x)
    return np.column_stack([x, pin.skew(ray) @ x, ray])
