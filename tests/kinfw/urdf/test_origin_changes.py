"""What a calibration changed, joint by joint (:func:`kinfw.urdf.origin_changes`).

Truth: hand-made edits of the head's URDF (a known shift, turn and axis tilt) with
:func:`kinfw.urdf.edit_urdf`; the function must report exactly those, largest first.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from kinfw.model import load_robot
from kinfw.urdf import edit_urdf, origin_changes
from tests.paths import HEAD_URDF


def test_the_changed_joints_come_back_with_their_shift_turn_and_axis_tilt():
    nominal = load_robot(HEAD_URDF)
    camera = nominal.joint("left_camera_joint").parent_T_child.copy()
    turn = pin.exp3(np.array([0.0, math.radians(2.0), 0.0]))
    camera[:3, :3] = camera[:3, :3] @ turn
    camera[:3, 3] += [0.003, 0.0, -0.004]  # 5 mm
    tilt = pin.exp3(np.array([math.radians(1.0), 0.0, 0.0]))
    pan_axis = tilt @ nominal.joint("pan").axis
    edited = load_robot(
        edit_urdf(
            nominal.urdf_xml,
            joint_origins={"left_camera_joint": camera},
            joint_axes={"pan": pan_axis},
        )
    )
    changes = origin_changes(nominal, edited)
    assert [c.joint for c in changes] == ["left_camera_joint", "pan"]
    cam, pan = changes
    np.testing.assert_allclose(
        [cam.shift_m, math.degrees(cam.turn_rad), cam.axis_turn_rad], [0.005, 2.0, 0.0], atol=1e-9
    )
    np.testing.assert_allclose(cam.parent_T_child, camera, atol=1e-12)
    np.testing.assert_allclose(
        [pan.shift_m, pan.turn_rad, math.degrees(pan.axis_turn_rad)], [0.0, 0.0, 1.0], atol=1e-9
    )
    assert origin_changes(nominal, nominal) == ()
