"""What a calibration changed in the URDF, joint by joint: each joint's ``<origin>`` and
``<axis>`` in the calibrated file against the nominal's (:func:`origin_changes`), the
table ``kinfw calibrate`` prints (a camera's mount on a fixed joint, a joint's offset).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import angle_between, rotation_angle
from kinfw.model import Robot


@dataclass(frozen=True)
class OriginChange:
    """One joint of the calibrated URDF whose origin or axis differs from the nominal's.

    Attributes
    ----------
    joint : str
        The URDF joint.
    parent_T_child : ndarray, shape (4, 4)
        Its calibrated ``<origin>`` (the child link's pose in the parent link at q = 0,
        metres).
    shift_m : float
        Distance between the nominal and calibrated origins' positions (m).
    turn_rad : float
        Angle of the rotation from the nominal origin's orientation to the calibrated
        one's (rad).
    axis_turn_rad : float
        Angle between the nominal and calibrated axes, each in its own child frame (rad;
        0 for fixed joints).
    """

    joint: str
    parent_T_child: NDArray[np.float64]
    shift_m: float
    turn_rad: float
    axis_turn_rad: float


def origin_changes(
    nominal: Robot, calibrated: Robot, *, tol: float = 1e-9
) -> tuple[OriginChange, ...]:
    """The joints whose origin or axis the calibration changed, largest shift first.

    Parameters
    ----------
    nominal, calibrated : Robot
        The URDF before and after (:attr:`kinfw.CalibrationResult.nominal`, ``.robot``);
        joints are matched by name, those only one of them has are skipped (frames the
        calibration added are new joints, see the report's mounts).
    tol : float
        A joint counts as changed when its shift (m), turn or axis turn (rad) exceeds it.

    Returns
    -------
    tuple of OriginChange
        Sorted by ``shift_m`` then ``turn_rad``, largest first; empty when nothing changed.
    """
    changes = []
    for before in nominal.joints:
        try:
            after = calibrated.joint(before.name)
        except KeyError:
            continue
        T0, T1 = before.parent_T_child, after.parent_T_child
        shift = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3]))
        turn = float(rotation_angle(T0[:3, :3].T @ T1[:3, :3]))
        axis = float(angle_between(before.axis, after.axis)) if before.is_movable else 0.0
        if max(shift, turn, axis) > tol:
            changes.append(OriginChange(before.name, T1.copy(), shift, turn, axis))
    return tuple(sorted(changes, key=lambda c: (-c.shift_m, -c.turn_rad)))
