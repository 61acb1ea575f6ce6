"""The plausibility guard: what a calibration changed in the URDF's own terms (each joint
origin's move and turn, each mount, a stance link's pose in the root) against the prior
that was chosen and a physical bound (:func:`plausibility`).

A calibration that moves a joint origin by decimetres under a millimetre prior is not
a calibration of this robot with these data: a wrong board size, another robot's URDF,
a unit or a direction the data do not determine. The guard names it before anything is
written (:class:`ImplausibleCalibrationError`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from kinfw.geometry import angle_between, rotation_angle
from kinfw.measurements import Measurements
from kinfw.model import PriorScales, Robot
from kinfw.observations import kind_of
from kinfw.urdf import origin_changes


class ImplausibleCalibrationError(ValueError):
    """A calibration whose changes are beyond the plausibility bound, refused before
    anything is written. Its first line names the largest change and the bound; the
    lines after it list the changes and the likely causes (the command line prints them
    indented below it)."""


@dataclass(frozen=True, slots=True)
class ChangeBound:
    """How large a change the guard accepts (:func:`plausibility`).

    By default the bound on a move is the larger of ``prior_factor`` times the prior's
    length sigma and ``floor_m``, and never above ``size_fraction`` of the robot's size
    (:func:`robot_size`; no cap for a robot of no size, a pose chain); on a turn, the
    larger of ``prior_factor`` times the prior's angle sigma and ``floor_rad``. ``max_m``
    / ``max_rad``, when given, replace the rule.

    Attributes
    ----------
    prior_factor : float
        Multiple of the prior's sigmas a change may reach.
    floor_m : float
        The smallest bound on a move (m), with or without a prior.
    floor_rad : float
        The smallest bound on a turn (rad).
    size_fraction : float
        A move beyond this fraction of the robot's size is always beyond the bound.
    max_m, max_rad : float or None
        A bound stated outright (m; rad), e.g. ``--max-change-mm`` / ``--max-change-deg``.
    """

    prior_factor: float = 5.0
    floor_m: float = 0.020
    floor_rad: float = math.radians(2.0)
    size_fraction: float = 0.05
    max_m: float | None = None
    max_rad: float | None = None

    @classmethod
    def for_known_error(cls, sigma_m: float, sigma_rad: float) -> ChangeBound:
        """The bound for a URDF known to be off by ``sigma_m`` / ``sigma_rad`` per axis
        (a simulation's true robot, :func:`kinfw.simulation.perturb_robot`): a move's or
        a turn's norm is then about ``sqrt(3)`` times that, and the bound is
        ``prior_factor`` times it, as for a prior (m; rad)."""
        k = cls().prior_factor * math.sqrt(3.0)
        return cls(max_m=k * sigma_m, max_rad=k * sigma_rad)

    def limits(
        self, prior: PriorScales | tuple[float, float] | None, size_m: float
    ) -> tuple[float, float, str]:
        """``(bound_m, bound_rad, why)`` for a fit with ``prior`` (by group, or
        ``(sigma_m, sigma_rad)``, or None) of a robot of ``size_m``; ``why`` says in words
        how they were set. A prior by group bounds by its loosest length and angle sigma
        of the joints' geometry (:attr:`PriorScales.sigma_m`, ``sigma_rad``)."""
        prior = PriorScales.of(prior)
        sigma_m, sigma_rad = (0.0, 0.0) if prior is None else (prior.sigma_m, prior.sigma_rad)
        of_prior = "" if prior is None else f"{self.prior_factor:g} x the prior or "
        if self.max_m is not None:
            bound_m, why_m = self.max_m, "given"
        else:
            # a robot of no size (every joint origin at one point: a pose chain) has no cap
            cap = self.size_fraction * size_m if size_m > 0 else math.inf
            bound_m = min(max(self.prior_factor * sigma_m, self.floor_m), cap)
            why_m = (
                f"{self.size_fraction:.0%} of the robot's size {size_m:.3g} m"
                if bound_m == cap
                else f"{of_prior}{1e3 * self.floor_m:g} mm"
            )
        if self.max_rad is not None:
            bound_rad, why_rad = self.max_rad, "given"
        else:
            bound_rad = max(self.prior_factor * sigma_rad, self.floor_rad)
            why_rad = f"{of_prior}{math.degrees(self.floor_rad):g} deg"
        return bound_m, bound_rad, f"moves: {why_m}; turns: {why_rad}"


@dataclass(frozen=True, slots=True)
class LargeChange:
    """One change of the calibrated URDF against the nominal, measured against the bound.

    Attributes
    ----------
    name : str
        The joint (its ``<origin>`` and ``<axis>``), or ``"LINK in ROOT"`` for a stance
        link's pose in the root link at q = 0.
    what : str
        ``"joint origin"``, ``"mount"`` (a fixed joint's origin) or ``"pose"`` (a stance
        link in the root).
    shift_m : float
        The move (m).
    turn_rad : float
        The turn (rad): the origin's rotation, or the axis's, whichever is larger.
    ratio : float
        ``max(shift_m / bound_m, turn_rad / bound_rad)``: beyond the bound above 1.
    """

    name: str
    what: str
    shift_m: float
    turn_rad: float
    ratio: float

    def text(self) -> str:
        """E.g. ``"elbow_joint moved 191 mm / turned 0.84 deg (9.5 x the bound)"``."""
        return (
            f"{self.what} {self.name} moved {1e3 * self.shift_m:.3g} mm / turned "
            f"{math.degrees(self.turn_rad):.3g} deg ({self.ratio:.3g} x the bound)"
        )


@dataclass(frozen=True, slots=True)
class Plausibility:
    """The guard's verdict on a calibration (:func:`plausibility`).

    Attributes
    ----------
    bound_m, bound_rad : float
        The bound on a move (m) and a turn (rad).
    why : str
        How the bound was set (the prior, the floor, the robot's size, given).
    size_m : float
        The robot's size (m, :func:`robot_size`).
    changes : tuple of LargeChange
        Every change measured, largest ratio first (empty when nothing changed).
    """

    bound_m: float
    bound_rad: float
    why: str
    size_m: float
    changes: tuple[LargeChange, ...]

    @property
    def beyond(self) -> tuple[LargeChange, ...]:
        """The changes beyond the bound (ratio above 1), largest first."""
        return tuple(c for c in self.changes if c.ratio > 1.0)

    @property
    def plausible(self) -> bool:
        """No change is beyond the bound."""
        return not self.beyond

    @property
    def largest_ratio(self) -> float:
        """The largest change's ratio to the bound (0 when nothing changed)."""
        return self.changes[0].ratio if self.changes else 0.0

    def bound_text(self) -> str:
        """E.g. ``"20 mm / 2 deg"``."""
        return f"{1e3 * self.bound_m:.3g} mm / {math.degrees(self.bound_rad):.3g} deg"


def _zero_poses(robot: Robot) -> dict[str, np.ndarray]:
    """``{link: root_T_link}`` at q = 0 (the neutral configuration) for every link."""
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    return {
        link: data.oMf[robot.frame_id(link)].homogeneous.copy()
        for link in robot.link_names
        if robot.has_frame(link)
    }


def robot_size(robot: Robot) -> float:
    """The robot's size: the largest distance between two joint origins at q = 0 (m; the
    child links' frames of every URDF joint, fixed ones included, and the root's)."""
    poses = _zero_poses(robot)
    links = [robot.root_link, *(j.child for j in robot.joints)]
    points = np.array([poses[k][:3, 3] for k in links if k in poses])
    if len(points) < 2:
        return 0.0
    return float(np.max(np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)))


@dataclass(frozen=True, slots=True)
class _Line:
    """A movable joint at q = 0 in the root: a point of its line (its child frame's
    origin, m), its unit direction, and whether it is revolute (a prismatic joint has a
    direction only)."""

    point: np.ndarray
    direction: np.ndarray
    revolute: bool


def _lines(robot: Robot, poses: dict[str, np.ndarray]) -> dict[str, _Line]:
    out = {}
    for j in robot.joints:
        if j.is_movable and j.child in poses:
            T = poses[j.child]
            out[j.name] = _Line(T[:3, 3], T[:3, :3] @ j.axis, j.is_revolute)
    return out


#: Nominal directions closer than this (rad) are parallel: the distance between such
#: lines is a point's (a calibration tilts them by a little, and the common normal of
#: nearly parallel lines runs far away).
_PARALLEL = 1e-3


def _distance(line: _Line, point: np.ndarray, direction: np.ndarray | None = None) -> float:
    """The distance from ``line`` to a point, or (with ``direction``) to the line through
    it: the length of their common normal (m)."""
    step = point - line.point
    if direction is not None:
        normal = np.cross(line.direction, direction)
        return float(abs(step @ normal) / np.linalg.norm(normal))
    return float(np.linalg.norm(step - (step @ line.direction) * line.direction))


def _parallel(u: np.ndarray, v: np.ndarray) -> bool:
    """Whether two directions are parallel (either sense): their common normal is then not
    unique, and the distance between the lines is a point's from the other line."""
    return bool(np.linalg.norm(np.cross(u, v)) < _PARALLEL)


def _above(robot: Robot, joint, lines: dict[str, _Line]) -> tuple[str | None, str | None]:
    """The nearest movable joint above ``joint`` and the nearest revolute one (None when
    there is none)."""
    movable = [j for j in reversed(robot.path_joints(joint.parent)) if j.name in lines]
    revolute = [j for j in movable if j.is_revolute]
    return (movable[0].name if movable else None, revolute[0].name if revolute else None)


def _seen(robot: Robot, measured: Sequence[str]) -> set[str]:
    """The joints the data see: on the path from the root to a measured frame, a fixed
    one only when a movable joint or the measured frame itself lies right below it (of
    fixed joints in a row, the data see only what they compose to: the last one's frame
    on the line above)."""
    seen: set[str] = set()
    for frame in measured:
        if not robot.has_frame(frame):
            continue
        path = robot.path_joints(frame)
        for k, joint in enumerate(path):
            below = path[k + 1 :]
            if joint.is_movable or not below or below[0].is_movable:
                seen.add(joint.name)
    return seen


def _base_mount(robot: Robot, joint) -> bool:
    """A fixed joint with no movable joint above it and some below (the root's base):
    where it sits is judged through the first movable joints below, in the root, as the
    export places it so that the measured frames move least (with a prismatic joint
    below, its position is anywhere along it)."""
    if joint.is_movable or any(j.is_movable for j in robot.path_joints(joint.parent)):
        return False
    below = {joint.child}  # the links below it, grown to a fixed point (any joint order)
    changed = True
    while changed:
        changed = False
        for j in robot.joints:
            if j.parent in below and j.child not in below:
                below.add(j.child)
                changed = True
    return any(j.is_movable and j.parent in below for j in robot.joints)


def _joint_change(
    robot: Robot,
    joint,
    nominal: tuple[dict[str, np.ndarray], dict[str, _Line]],
    calibrated: tuple[dict[str, np.ndarray], dict[str, _Line]],
    root_measured: bool,
) -> tuple[float, float] | None:
    """``(shift_m, turn_rad)`` of one joint against the joints above it, in what no rigid
    motion and no turn or slide about the joint above changes; None when nothing above
    it is measured. A movable joint: the change of the angle between its axis and the
    nearest movable axis above, and of the common normal's length to the nearest
    revolute line above (a prismatic joint has a direction only). A fixed joint's child
    frame (a mount): the change of the angles between its axes and the nearest movable
    axis above, and of its origin's distance from the nearest revolute line above. With
    nothing above, the root's frame (when ``root_measured``)."""
    (poses0, lines0), (poses1, lines1) = nominal, calibrated
    movable, revolute = _above(robot, joint, lines0)
    if movable is None and not root_measured:
        return None
    T0, T1 = poses0[joint.child], poses1[joint.child]
    if joint.is_movable:
        n, c = lines0[joint.name], lines1[joint.name]
        if movable is None:
            turn = float(angle_between(n.direction, c.direction))
        else:
            turn = abs(
                float(angle_between(lines0[movable].direction, n.direction))
                - float(angle_between(lines1[movable].direction, c.direction))
            )
        if not joint.is_revolute:
            return 0.0, turn
        if revolute is None:
            return (_distance(c, n.point) if root_measured else 0.0), turn
        ref0, ref1 = lines0[revolute], lines1[revolute]
        if _parallel(ref0.direction, n.direction):
            return abs(_distance(ref1, c.point) - _distance(ref0, n.point)), turn
        a0 = _distance(ref0, n.point, n.direction)
        a1 = _distance(ref1, c.point, c.direction)
        return abs(a1 - a0), turn
    if movable is None:
        return (
            float(np.linalg.norm(T1[:3, 3] - T0[:3, 3])),
            float(rotation_angle(T0[:3, :3].T @ T1[:3, :3])),
        )
    u0, u1 = lines0[movable].direction, lines1[movable].direction
    turn = float(np.max(np.abs(angle_between(T0[:3, :3].T, u0) - angle_between(T1[:3, :3].T, u1))))
    if revolute is None:
        shift = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3])) if root_measured else 0.0
    else:
        shift = abs(_distance(lines1[revolute], T1[:3, 3]) - _distance(lines0[revolute], T0[:3, 3]))
    return shift, turn


def plausibility(
    nominal: Robot,
    calibrated: Robot,
    prior: PriorScales | tuple[float, float] | None,
    *,
    bound: ChangeBound | None = None,
    stance: Sequence[str] = (),
    root_measured: bool = True,
    measured: Sequence[str] | None = None,
    unknown: Sequence[str] = (),
    tol: float = 1e-9,
) -> Plausibility:
    """What ``calibrated`` changed against ``nominal``, in the URDF's own terms, against
    the bound for ``prior``.

    Parameters
    ----------
    nominal, calibrated : Robot
        The URDF before and after; joints are matched by name (those only one has are
        skipped).
    prior : PriorScales or (float, float) or None
        The prior the fit was made with, by group or ``(sigma_m, sigma_rad)`` (on the CPC
        parameters' deviations, which the bound turns into a bound on the URDF's
        joints), None without one.
    bound : ChangeBound, optional
        The rule (default :class:`ChangeBound`).
    stance : sequence of str
        Links the data are measured in (a floating humanoid's foot): each one's pose in
        the root at q = 0 is one more change, with the bound times the square root of
        the movable joints between them (independent changes of the joints on the way add
        up in quadrature).
    root_measured : bool
        The data are measured in the root or another link of the robot, so the first
        joints' placement in the root is measured. False for an external frame (a
        tracker's, whose pose in the root is estimated with the calibration): a joint with
        no movable joint above it is then not judged.
    measured : sequence of str, optional
        The frames the data observe (and are measured in): only joints on their paths
        from the root are judged (:func:`_seen`), as the calibration changes only those
        (the export re-expresses the others under a moved link, where they keep their
        place). Default: every joint.
    unknown : sequence of str
        Joints whose ``<origin>`` in ``nominal`` is a start, not a nominal (a mounted
        frame the data gave no pose for: :func:`fit_plausibility`), not judged, as the
        URDF's placeholders are.
    tol : float
        A joint counts as changed when its move (m) or turn (rad) exceeds it.

    Returns
    -------
    Plausibility
        Each joint's move and turn and each stance pose, with its ratio to the bound.

    Notes
    -----
    Each joint is judged by what it is on the joints above it, at q = 0, in quantities
    that no rigid motion of the robot and no turn or slide about the joint above changes
    (:func:`_joint_change`): the angle between its axis (or a mount's axes) and the
    nearest movable axis above, and its line's common normal with (or a mount origin's
    distance from) the nearest revolute line above, as DH's twist and length are. The
    first joints are judged in the root's frame when the data are measured in the robot.
    This is :func:`kinfw.urdf.origin_changes` without what the export chose and the robot
    does not: where a link frame sits on its own axis, link frames kept unrotated under a
    turned joint (every axis below a tilted torso reads as turned), the root placed by
    registration in a tracker's frame; compared origin to origin, TIAGo's arm read 7 deg
    on its real Vicon data and the IIS-head's pan 19.6 mm under a 2 mm simulated error.
    What it does not see: a joint's zero offset (a turn about its own axis) and a slide
    along the axis above, which only a third joint above could place. Joints the URDF
    marks as placeholders (:attr:`kinfw.model.Robot.placeholder_joints`) have no nominal
    and are not judged.
    """
    bound = ChangeBound() if bound is None else bound
    size = robot_size(nominal)
    bound_m, bound_rad, why = bound.limits(prior, size)

    def change(name: str, what: str, shift: float, turn: float, scale: float = 1.0):
        ratio = max(shift / bound_m, turn / bound_rad) / scale
        return LargeChange(name, what, shift, turn, ratio)

    before, after = _zero_poses(nominal), _zero_poses(calibrated)
    lines0, lines1 = _lines(nominal, before), _lines(calibrated, after)
    changes = []
    # each change is judged at the joint whose <origin> or <axis> the calibration wrote
    # (the export leaves joints off the measured paths as they were)
    written = {c.joint for c in origin_changes(nominal, calibrated, tol=tol)}
    if measured is not None:
        written &= _seen(nominal, measured)
    placeholders = {*nominal.placeholder_joints, *unknown}  # no nominal to compare with
    for joint in nominal.joints:
        if joint.name not in written or joint.child not in after or _base_mount(nominal, joint):
            continue
        if joint.name in placeholders:
            continue
        moved = _joint_change(nominal, joint, (before, lines0), (after, lines1), root_measured)
        if moved is not None and max(moved) > tol:
            what = "joint origin" if joint.is_movable else "mount"
            changes.append(change(joint.name, what, *moved))
    root = nominal.root_link
    for link in dict.fromkeys(stance):
        if link == root or link not in before or link not in after:
            continue
        if placeholders & {j.name for j in nominal.path_joints(link)}:
            continue
        # the link's pose in the root: where the foot is under the base (the root's pose
        # in the link would multiply any turn by the root's distance from it)
        T0, T1 = before[link], after[link]
        shift = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3]))
        turn = float(rotation_angle(T0[:3, :3].T @ T1[:3, :3]))
        n = max(1, len(nominal.movable_path(link)))
        changes.append(change(f"{link} in {root}", "pose", shift, turn, math.sqrt(n)))
    changes.sort(key=lambda c: -c.ratio)
    return Plausibility(bound_m, bound_rad, why, size, tuple(changes))


def mount_plausibility(
    robot: Robot,
    name: str,
    nominal_T: np.ndarray,
    calibrated_T: np.ndarray,
    *,
    bound: ChangeBound | None = None,
) -> Plausibility:
    """The guard's verdict on one mount written on its own (``kinfw handeye``): the
    calibrated ``mount_T_camera`` against the URDF's, with no prior.

    Parameters
    ----------
    robot : Robot
        The nominal robot (its size caps the bound).
    name : str
        The mount, in words (``"tool0_T_camera"``).
    nominal_T, calibrated_T : ndarray, shape (4, 4)
        The camera's pose on its mount in the URDF and as calibrated (m).
    bound : ChangeBound, optional
        The rule (default :class:`ChangeBound`).

    Returns
    -------
    Plausibility
        One change: the camera's move and turn on its mount.
    """
    bound = ChangeBound() if bound is None else bound
    size = robot_size(robot)
    bound_m, bound_rad, why = bound.limits(None, size)
    shift = float(np.linalg.norm(calibrated_T[:3, 3] - nominal_T[:3, 3]))
    turn = float(rotation_angle(nominal_T[:3, :3].T @ calibrated_T[:3, :3]))
    ratio = max(shift / bound_m, turn / bound_rad)
    return Plausibility(
        bound_m, bound_rad, why, size, (LargeChange(name, "mount", shift, turn, ratio),)
    )


def stance_links(robot: Robot, data: Measurements) -> tuple[str, ...]:
    """The links of ``robot`` that groups of ``data`` are measured in (a foot's sole for a
    humanoid's plane contacts), in order of first appearance."""
    links = (kind_of(g).measured_in(g) for g in data.all_groups())
    return tuple(dict.fromkeys(k for k in links if k and k in robot.link_names))


def root_measured(robot: Robot, data: Measurements) -> bool:
    """Whether ``data`` measure frames of the robot in its root (or another of its links):
    poses or points measured there. A target, a plane or a sphere is estimated in the root
    with the calibration, and a tracker's frame too: the robot's placement against them
    is not measured, only its shape."""
    for group in data.all_groups():
        kind = kind_of(group)
        frame = kind.measured_in(group)
        if kind.name in ("pose", "point") and (frame is None or frame in robot.link_names):
            return True
    return False


def fit_plausibility(
    nominal: Robot,
    calibrated: Robot,
    data: Measurements,
    prior: PriorScales | tuple[float, float] | None,
    *,
    bound: ChangeBound | None = None,
) -> Plausibility:
    """The guard's verdict on a calibration of ``nominal`` from ``data``
    (:func:`plausibility`): every joint and mount on the paths of the frames the data
    observe; the pose in the root of each link the data are measured in
    (:func:`stance_links`); the first joints judged in the root only when the data measure
    the robot there (:func:`root_measured`). A frame the data mount at the identity
    (``Measurements.mounts``: a pose unknown, which the hand-eye stage starts from the
    data) has no nominal, and its joint is not judged."""
    frames = {f for g in data.all_groups() for f in kind_of(g).frames(g)}
    starts = {
        j.name
        for j in nominal.joints
        if j.child in data.mounts and np.array_equal(data.mounts[j.child].parent_T_frame, np.eye(4))
    }
    return plausibility(
        nominal,
        calibrated,
        prior,
        bound=bound,
        stance=stance_links(nominal, data),
        root_measured=root_measured(nominal, data),
        measured=(*frames, *stance_links(nominal, data)),
        unknown=tuple(starts),
    )
