"""Test robots shared by the tests (not fixtures: plain data; fixtures are in conftest.py).

- (the built-in IIS-head URDF's path is ``tests.paths.HEAD_URDF``).

- ``ARM_6R``: a serial 6R arm with tilted axes, a ``0 0 -1`` axis, an axis exactly
  anti-parallel to the previous one, a continuous joint and a pitch = pi/2 origin.
- ``PRISMATIC_TREE``: two prismatic joints (one tilted) under a pan joint that carries
  three branches (R-R, a fixed camera, P-R).
- ``IDEAL_HEAD``: a binocular head (slide, pan, tilt, two vergences) whose optical centres
  sit on the tilt axis and on parallel vergence axes, so any point in front of both
  cameras and off the baseline can be fixated exactly.
- ``PAN_CAMERA``: one camera on a pan joint (range -1 .. 1 rad), its optical centre on
  the pan axis 0.3 m above the root, looking horizontally along the pan link's x.
- ``PLANAR_2R``: a planar arm, links 0.5 m and 0.3 m, joint axes along z, ``j1`` within
  -0.5 .. 0.5 rad, ``j2`` within -3 .. 3 rad; its tool frame is the tip.
- :func:`pendulum_urdf`: one revolute joint ``j`` about y at the root, its link ``arm`` a
  point mass ``PENDULUM_KG`` at x = ``PENDULUM_L_M`` (or without ``<inertial>``), the
  frame ``tool`` at x = 2 L: gravity's torque about +y is ``m g L cos q``.
"""

ARM_6R = """<?xml version="1.0"?>
<robot name="arm6">
  <link name="world"/>
  <joint name="j1" type="revolute">
    <parent link="world"/><child link="l1"/>
    <origin xyz="0.1 -0.2 0.3" rpy="0.2 -0.1 0.4"/><axis xyz="0 0 -1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="l1"/>
  <joint name="j2" type="revolute">
    <parent link="l1"/><child link="l2"/>
    <origin xyz="0.05 0 0.2" rpy="1.5707963267948966 0 0"/>
    <axis xyz="0.3 0.1 0.9486832980505138"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="l2"/>
  <joint name="j3" type="revolute">
    <parent link="l2"/><child link="l3"/>
    <origin xyz="0.4 0 0" rpy="0 0 0"/><axis xyz="-0.3 -0.1 -0.9486832980505138"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="l3"/>
  <joint name="j4" type="continuous">
    <parent link="l3"/><child link="l4"/>
    <origin xyz="0.3 0.02 0" rpy="0 1.5707963267948966 0"/><axis xyz="0 1 0"/>
  </joint>
  <link name="l4"/>
  <joint name="j5" type="revolute">
    <parent link="l4"/><child link="l5"/>
    <origin xyz="0 0 0.1" rpy="0 3.141592653589793 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="l5"/>
  <joint name="j6" type="revolute">
    <parent link="l5"/><child link="l6"/>
    <origin xyz="0 0.08 0" rpy="-1.2 0 0.3"/><axis xyz="-1 0 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="l6"/>
  <joint name="flange_joint" type="fixed">
    <parent link="l6"/><child link="flange"/><origin xyz="0 0 0.05" rpy="0 0 0.7"/>
  </joint>
  <link name="flange"/>
</robot>
"""

PRISMATIC_TREE = """<?xml version="1.0"?>
<robot name="ptree">
  <link name="world"/>
  <joint name="base_joint" type="fixed">
    <parent link="world"/><child link="base"/><origin xyz="0.5 0.2 1.2" rpy="3.0 0.1 -0.5"/>
  </joint>
  <link name="base"/>
  <joint name="px" type="prismatic">
    <parent link="base"/><child link="cx"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.8" effort="1" velocity="1"/>
  </joint>
  <link name="cx"/>
  <joint name="py" type="prismatic">
    <parent link="cx"/><child link="cy"/><origin xyz="0.1 0 0.05" rpy="0 0 0.02"/>
    <axis xyz="0.05 1 0"/><limit lower="0" upper="0.4" effort="1" velocity="1"/>
  </joint>
  <link name="cy"/>
  <joint name="pan" type="revolute">
    <parent link="cy"/><child link="pan_link"/><origin xyz="0.02 0.03 0.3" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/>
  </joint>
  <link name="pan_link"/>
  <joint name="a1" type="revolute">
    <parent link="pan_link"/><child link="a1_link"/>
    <origin xyz="0.1 0 0.1" rpy="1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="a1_link"/>
  <joint name="a2" type="revolute">
    <parent link="a1_link"/><child link="a2_link"/><origin xyz="0.2 0 0" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="a2_link"/>
  <joint name="tool_a_joint" type="fixed">
    <parent link="a2_link"/><child link="tool_a"/>
    <origin xyz="0.1 0 0" rpy="0 1.5707963267948966 0"/>
  </joint>
  <link name="tool_a"/>
  <joint name="cam_joint" type="fixed">
    <parent link="pan_link"/><child link="cam"/>
    <origin xyz="0 0.05 0.2" rpy="-1.5707963267948966 0 0"/>
  </joint>
  <link name="cam"/>
  <joint name="slide" type="prismatic">
    <parent link="pan_link"/><child link="slide_link"/><origin xyz="-0.1 0 0.1" rpy="0 0.3 0"/>
    <axis xyz="0 0 -1"/><limit lower="0" upper="0.2" effort="1" velocity="1"/>
  </joint>
  <link name="slide_link"/>
  <joint name="wrist" type="revolute">
    <parent link="slide_link"/><child link="wrist_link"/><origin xyz="0 0 0.05" rpy="0 0 0"/>
    <axis xyz="0 0 -1"/><limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="wrist_link"/>
  <joint name="tool_b_joint" type="fixed">
    <parent link="wrist_link"/><child link="tool_b"/><origin xyz="0.03 0 0.04" rpy="0.1 0.2 0.3"/>
  </joint>
  <link name="tool_b"/>
</robot>
"""

#: rpy of an optical frame (z forward, x right, y down) on a link whose x is forward, z up
_OPTICAL_RPY = "-1.5707963267948966 0 -1.5707963267948966"

IDEAL_HEAD = f"""<?xml version="1.0"?>
<robot name="ideal_head">
  <kinfw cameras="left_camera right_camera"/>
  <link name="world"/>
  <joint name="slide" type="prismatic">
    <parent link="world"/><child link="carriage"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <link name="carriage"/>
  <joint name="pan" type="revolute">
    <parent link="carriage"/><child link="pan_link"/><origin xyz="0 0 0.4" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/>
  </joint>
  <link name="pan_link"/>
  <joint name="tilt" type="revolute">
    <parent link="pan_link"/><child link="tilt_link"/><origin xyz="0 0 0.1" rpy="0 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="tilt_link"/>
  <joint name="vergence_left" type="revolute">
    <parent link="tilt_link"/><child link="left_link"/><origin xyz="0 0.1 0" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-0.7" upper="0.7" effort="1" velocity="1"/>
  </joint>
  <link name="left_link"/>
  <joint name="left_camera_joint" type="fixed">
    <parent link="left_link"/><child link="left_camera"/>
    <origin xyz="0 0 0" rpy="{_OPTICAL_RPY}"/>
  </joint>
  <link name="left_camera"/>
  <joint name="vergence_right" type="revolute">
    <parent link="tilt_link"/><child link="right_link"/><origin xyz="0 -0.1 0" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-0.7" upper="0.7" effort="1" velocity="1"/>
  </joint>
  <link name="right_link"/>
  <joint name="right_camera_joint" type="fixed">
    <parent link="right_link"/><child link="right_camera"/>
    <origin xyz="0 0 0" rpy="{_OPTICAL_RPY}"/>
  </joint>
  <link name="right_camera"/>
</robot>
"""

PAN_CAMERA = f"""<?xml version="1.0"?>
<robot name="pan_camera">
  <link name="world"/>
  <joint name="pan" type="revolute">
    <parent link="world"/><child link="pan_link"/><origin xyz="0 0 0.3" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="pan_link"/>
  <joint name="camera_joint" type="fixed">
    <parent link="pan_link"/><child link="camera"/><origin xyz="0 0 0" rpy="{_OPTICAL_RPY}"/>
  </joint>
  <link name="camera"/>
</robot>
"""

PLANAR_2R = """<?xml version="1.0"?>
<robot name="planar_2r">
  <link name="world"/>
  <joint name="j1" type="revolute">
    <parent link="world"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <link name="l1"/>
  <joint name="j2" type="revolute">
    <parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="l2"/>
  <joint name="tool_joint" type="fixed">
    <parent link="l2"/><child link="tool"/><origin xyz="0.3 0 0" rpy="0 0 0"/>
  </joint>
  <link name="tool"/>
</robot>
"""


PENDULUM_KG, PENDULUM_L_M = 2.0, 0.5


def pendulum_urdf(inertial: bool = True) -> str:
    """The pendulum of the module docstring (``inertial=False``: its link has no mass)."""
    body = (
        f'<inertial><origin xyz="{PENDULUM_L_M} 0 0"/><mass value="{PENDULUM_KG}"/>'
        '<inertia ixx="1e-9" iyy="1e-9" izz="1e-9" ixy="0" ixz="0" iyz="0"/></inertial>'
        if inertial
        else ""
    )
    return f"""<robot name="pendulum">
  <link name="base"/>
  <link name="arm">{body}</link>
  <link name="tool"/>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="arm"/><child link="tool"/>
    <origin xyz="{2 * PENDULUM_L_M} 0 0"/></joint>
</robot>"""
