"""The plausibility guard: what a calibration changed in the URDF's own terms (each joint
origin's move and turn, each mount, the root's pose in a stance link) against the prior
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

from kinfw.geometry import inverse_transform, rotation_angle
from kinfw.model import Robot
from kinfw.urdf import origin_changes


class ImplausibleCalibrationError(ValueError):
    """A calibration whose changes are beyond the plausibility bound, refused before
    anything is written. Its first line names the largest change and the bound; the
    lines after it list the changes and the likely causes (``multiline``: the command
    line prints them as they are)."""

    multiline = True


@dataclass(frozen=True, slots=True)
class ChangeBound:
    """How large a change the guard accepts (:func:`plausibility`).

    By default the bound on a move is the larger of ``prior_factor`` times the prior's
    length sigma and ``floor_m``, and never above ``size_fraction`` of the robot's size
    (:func:`robot_size`); on a turn, the larger of ``prior_factor`` times the prior's angle
    sigma and ``floor_rad``. ``max_m`` / ``max_rad``, when given, replace the rule.

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

    def limits(self, prior: tuple[float, float] | None, size_m: float) -> tuple[float, float, str]:
        """``(bound_m, bound_rad, why)`` for a fit with ``prior`` (``(sigma_m, sigma_rad)``
        or None) of a robot of ``size_m``; ``why`` says in words how they were set."""
        sigma_m, sigma_rad = (0.0, 0.0) if prior is None else prior
        of_prior = "" if prior is None else f"{self.prior_factor:g} x the prior or "
        if self.max_m is not None:
            bound_m, why_m = self.max_m, "given"
        else:
            cap = self.size_fraction * size_m
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
        The joint (its ``<origin>`` and ``<axis>``), or ``"ROOT in LINK"`` for the root
        link's pose in a stance link at q = 0.
    what : str
        ``"joint origin"``, ``"mount"`` (a fixed joint's origin) or ``"pose"`` (the root
        in a stance link).
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


def plausibility(
    nominal: Robot,
    calibrated: Robot,
    prior: tuple[float, float] | None,
    *,
    bound: ChangeBound | None = None,
    stance: Sequence[str] = (),
) -> Plausibility:
    """What ``calibrated`` changed against ``nominal``, in the URDF's own terms, against
    the bound for ``prior``.

    Parameters
    ----------
    nominal, calibrated : Robot
        The URDF before and after; joints are matched by name (those only one has are
        skipped).
    prior : (float, float) or None
        ``(sigma_m, sigma_rad)`` of the prior the fit was made with (on the CPC
        parameters' deviations, which the bound turns into a bound on the URDF's
        origins), None without one.
    bound : ChangeBound, optional
        The rule (default :class:`ChangeBound`).
    stance : sequence of str
        Links the data are measured in (a floating humanoid's foot): the root link's pose
        in each, at q = 0, is one more change.

    Returns
    -------
    Plausibility
        Each joint origin's move and turn (the larger of the origin's and the axis's
        turn; :func:`kinfw.urdf.origin_changes`) and each stance pose, with its ratio to
        the bound.
    """
    bound = ChangeBound() if bound is None else bound
    size = robot_size(nominal)
    bound_m, bound_rad, why = bound.limits(prior, size)

    def change(name: str, what: str, shift: float, turn: float) -> LargeChange:
        return LargeChange(name, what, shift, turn, max(shift / bound_m, turn / bound_rad))

    fixed = {j.name for j in nominal.joints if not j.is_movable}
    changes = [
        change(
            c.joint,
            "mount" if c.joint in fixed else "joint origin",
            c.shift_m,
            max(c.turn_rad, c.axis_turn_rad),
        )
        for c in origin_changes(nominal, calibrated)
    ]
    before, after = _zero_poses(nominal), _zero_poses(calibrated)
    root = nominal.root_link
    for link in dict.fromkeys(stance):
        if link == root or link not in before or link not in after:
            continue
        link_T_root_0 = inverse_transform(before[link])
        link_T_root_1 = inverse_transform(after[link])
        shift = float(np.linalg.norm(link_T_root_1[:3, 3] - link_T_root_0[:3, 3]))
        turn = float(rotation_angle(link_T_root_0[:3, :3].T @ link_T_root_1[:3, :3]))
        changes.append(change(f"{root} in {link}", "pose", shift, turn))
    changes.sort(key=lambda c: -c.ratio)
    return Plausibility(bound_m, bound_rad, why, size, tuple(changes))
