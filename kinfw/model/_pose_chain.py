"""A robot known only by its hand poses, as a six-joint chain (``kinfw pose-chain``).

Hand-eye data sets often log the hand's pose in the base (the robot controller's
``base_T_hand``, a TF lookup) and no joint values: industrial_calibration's
``cal_data.yaml``, ViSP's ``pose_fPe_*.yaml``, easy_handeye's samples. Written as the
joint values of a chain whose forward kinematics is that pose exactly,

.. math::

    {}^{base}T_{hand}(q) = \\mathrm{Trans}(q_x, q_y, q_z)\\,R_z(q_{yaw})\\,R_y(q_{pitch})\\,
    R_x(q_{roll}),

they go through ``kinfw detect`` and ``kinfw calibrate`` as any robot's: the camera is a
link on a fixed joint of the hand (eye-in-hand) or of the base (eye-to-hand), and
``--params frames`` fits the camera's mount and the board's pose from the pixels
(maximum likelihood in pixels, not from PnP poses). The chain is exact by construction:
its joints carry no kinematic error to calibrate, and the URDF says so
(``<kinfw exact="pose_x ..."/>``, :attr:`kinfw.model.Robot.exact_joints`): no parameter
set estimates them, and ``--params auto`` is ``frames``.

The angles are Pinocchio's roll-pitch-yaw (``pinocchio.rpy.matrixToRpy``: ``R = Rz(yaw)
Ry(pitch) Rx(roll)``); pitch in [-pi/2, pi/2], the others in (-pi, pi]. Near pitch = +-pi/2
yaw and roll are not unique but any pair returned reproduces the pose.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

#: The chain's joints, in the order of :func:`pose_chain_joint_values`' columns: three
#: prismatic (m) along the base's x, y, z, then revolute (rad) about z, y, x.
POSE_CHAIN_JOINTS = ("pose_x", "pose_y", "pose_z", "pose_yaw", "pose_pitch", "pose_roll")

_AXES = ("1 0 0", "0 1 0", "0 0 1", "0 0 1", "0 1 0", "1 0 0")
#: Joint limits: positions within 100 m, angles a little beyond their ranges.
_LIMITS = ((-100.0, 100.0),) * 3 + ((-3.2, 3.2), (-1.6, 1.6), (-3.2, 3.2))


def pose_chain_joint_values(base_T_hands: NDArray[np.float64]) -> NDArray[np.float64]:
    """The chain's joint values that put the hand at each pose.

    Parameters
    ----------
    base_T_hands : ndarray, shape (n, 4, 4)
        The hand's poses in the base (metres).

    Returns
    -------
    ndarray, shape (n, 6)
        ``(x, y, z, yaw, pitch, roll)`` per pose (m, rad), :data:`POSE_CHAIN_JOINTS`.
    """
    import pinocchio as pin

    T = np.asarray(base_T_hands, dtype=float)
    rpy = np.array([pin.rpy.matrixToRpy(R) for R in T[:, :3, :3]]).reshape(len(T), 3)
    return np.column_stack([T[:, :3, 3], rpy[:, ::-1]])


def pose_chain_urdf(
    *,
    camera: str,
    hand: str = "hand",
    base: str = "base",
    camera_on: str = "hand",
    name: str = "pose_chain",
) -> str:
    """The URDF of the chain, with the camera's link on a fixed joint.

    Parameters
    ----------
    camera : str
        The camera's optical frame (z forward, x right, y down): a link on a fixed joint
        ``{camera}_joint`` at identity, the mount ``kinfw calibrate`` estimates.
    hand, base : str
        Names of the chain's last and first links.
    camera_on : {"hand", "base"}
        Eye-in-hand (the camera on the hand, the board fixed) or eye-to-hand (the camera
        fixed to the base, the board on the hand: ``kinfw detect --target-frame HAND``).
    name : str
        The robot's name.

    Returns
    -------
    str
        The URDF text, with the hint ``<kinfw exact="pose_x ... pose_roll"
        cameras="{camera}" placeholder="{camera}_joint"/>``.

    Raises
    ------
    ValueError
        For ``camera_on`` not ``"hand"`` or ``"base"``, or names that collide.
    """
    if camera_on not in ("hand", "base"):
        raise ValueError(f"camera_on: expected 'hand' or 'base', got {camera_on!r}")
    links = [base, *(f"{j}_link" for j in POSE_CHAIN_JOINTS[:-1]), hand, camera]
    if len(set(links)) != len(links):
        raise ValueError(f"pose chain: the links {links} must have distinct names")
    parts, parent = [f'  <link name="{base}"/>'], base
    for joint, axis, (lower, upper), child in zip(
        POSE_CHAIN_JOINTS, _AXES, _LIMITS, links[1:-1], strict=True
    ):
        kind = "prismatic" if joint in POSE_CHAIN_JOINTS[:3] else "revolute"
        parts.append(
            f'  <joint name="{joint}" type="{kind}">\n'
            f'    <parent link="{parent}"/><child link="{child}"/>\n'
            f'    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="{axis}"/>\n'
            f'    <limit lower="{lower}" upper="{upper}" effort="1" velocity="1"/>\n'
            f"  </joint>\n"
            f'  <link name="{child}"/>'
        )
        parent = child
    mount = hand if camera_on == "hand" else base
    parts.append(
        f'  <joint name="{camera}_joint" type="fixed">\n'
        f'    <parent link="{mount}"/><child link="{camera}"/>\n'
        f'    <origin xyz="0 0 0" rpy="0 0 0"/>\n'
        f"  </joint>\n"
        f'  <link name="{camera}"/>'
    )
    # kinfw's hints: the chain's joints are exact (never calibrated), the camera observes,
    # its mount is a placeholder (identity: estimated, not a nominal)
    parts.append(
        f'  <kinfw exact="{" ".join(POSE_CHAIN_JOINTS)}" cameras="{camera}" '
        f'placeholder="{camera}_joint"/>'
    )
    body = "\n".join(parts)
    return f'<?xml version="1.0"?>\n<robot name="{name}">\n{body}\n</robot>\n'
