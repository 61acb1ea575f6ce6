"""Serial arms from Denavit-Hartenberg tables as URDF: the UR10 of Universal Robots'
published parameters, so that studies need no robot package
(:mod:`kinfw.verification.studies`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from kinfw.urdf import UR_JOINTS

#: Universal Robots' DH parameters of the UR10 (standard DH), per joint:
#: ``(d, a, alpha)`` in m, m, rad ("DH parameters for calculations of kinematics and
#: dynamics", Universal Robots support article).
UR10_DH = (
    (0.1273, 0.0, math.pi / 2),
    (0.0, -0.612, 0.0),
    (0.0, -0.5723, 0.0),
    (0.163941, 0.0, math.pi / 2),
    (0.1157, 0.0, -math.pi / 2),
    (0.0922, 0.0, 0.0),
)
UR10_JOINTS = UR_JOINTS


def dh_urdf(
    name: str,
    dh: Sequence[tuple[float, float, float]],
    joints: Sequence[str],
    *,
    limit_rad: float = 2 * math.pi,
) -> str:
    """URDF of a serial revolute arm from standard DH rows ``(d, a, alpha)``: joint ``i``
    turns about z of frame ``i - 1``, then ``Trans_z(d) Trans_x(a) Rot_x(alpha)`` leads to
    frame ``i`` (the next joint's origin); links ``world``, ``base_link`` (frame 0,
    through a fixed joint), ``link_1`` ... and ``tool0`` (frame n); limits
    ``+-limit_rad``."""
    lines = [
        '<?xml version="1.0"?>',
        f'<robot name="{name}">',
        '  <link name="world"/>',
        '  <joint name="world_joint" type="fixed"><parent link="world"/>'
        '<child link="base_link"/><origin xyz="0 0 0" rpy="0 0 0"/></joint>',
        '  <link name="base_link"/>',
    ]
    parent, origin = "base_link", (0.0, 0.0, 0.0)
    for i, (joint, (d, a, alpha)) in enumerate(zip(joints, dh, strict=True), 1):
        xyz, rpy = f"{origin[0]!r} 0 {origin[1]!r}", f"{origin[2]!r} 0 0"
        lines += [
            f'  <joint name="{joint}" type="revolute"><parent link="{parent}"/>'
            f'<child link="link_{i}"/><origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="0 0 1"/>'
            f'<limit lower="{-limit_rad!r}" upper="{limit_rad!r}" effort="1" velocity="1"/>'
            "</joint>",
            f'  <link name="link_{i}"/>',
        ]
        parent, origin = f"link_{i}", (float(a), float(d), float(alpha))
    lines += [
        f'  <joint name="tool0_joint" type="fixed"><parent link="{parent}"/>'
        f'<child link="tool0"/><origin xyz="{origin[0]!r} 0 {origin[1]!r}" '
        f'rpy="{origin[2]!r} 0 0"/></joint>',
        '  <link name="tool0"/>',
        "</robot>",
    ]
    return "\n".join(lines) + "\n"


def ur10_urdf() -> str:
    """The UR10 from :data:`UR10_DH` (:func:`dh_urdf`; joint limits +-2 pi as shipped)."""
    return dh_urdf("ur10", UR10_DH, UR10_JOINTS)
