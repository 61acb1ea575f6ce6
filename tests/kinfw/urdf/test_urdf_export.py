"""Calibrated URDF export: the written URDF reproduces the calibrated model exactly.

Truth is independent of the exporter: the CPC model's own forward kinematics, Pinocchio
FK of the re-loaded URDF, yourdfpy's reading of the written origins and lxml's reading of
everything else.
"""

import io
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from lxml import etree

from kinfw.geometry import inverse_transform, rotation_angle
from kinfw.model import (
    ZeroGeometry,
    cpc_from_robot,
    geometry_from_cpc,
    geometry_from_robot,
    load_robot,
)
from kinfw.urdf import ExportError, ExportResult, edit_urdf, export_urdf, write_urdf

PI_2 = 1.5707963267948966

# An IIS-head-like tree: world (the stereo rig) -fixed-> base, an X-Y table, pan, tilt and
# two vergence joints, each carrying a fixed plate and a fixed camera.
HEAD_URDF = """<?xml version="1.0"?>
<!-- IIS-head-like test robot (numbers plausible, not the paper's). -->
<robot name="test_head">
  <link name="world"/>
  <joint name="world_to_base" type="fixed">
    <parent link="world"/>
    <child link="base"/>
    <origin xyz="-0.65 0.62 1.46" rpy="1.5707963267948966 -0.17453292519943295 1.5707963267948966"/>
  </joint>
  <link name="base">
    <inertial>
      <origin xyz="0.11 0.25 0.5" rpy="0 0 0"/>
      <mass value="30.0"/>
      <inertia ixx="6.9" ixy="0" ixz="0" iyy="4.9" iyz="0" izz="2.0"/>
    </inertial>
    <visual><origin xyz="0.115 0.25 0.5"/><geometry><box size="0.03 0.9 1.4"/></geometry></visual>
  </link>
  <joint name="x_table" type="prismatic">
    <parent link="base"/>
    <child link="x_carriage"/>
    <origin xyz="0 0 0" rpy="0 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="0" upper="1" effort="400" velocity="0.1"/>
  </joint>
  <link name="x_carriage">
    <visual><origin xyz="0.045 0.25 0"/><geometry><box size="0.03 0.84 0.2"/></geometry></visual>
  </link>
  <joint name="y_table" type="prismatic">
    <parent link="x_carriage"/>
    <child link="y_carriage"/>
    <origin xyz="0 0 0" rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="0" upper="0.5" effort="200" velocity="0.1"/>
  </joint>
  <link name="y_carriage">
    <visual>
      <origin xyz="-0.06 0 0" rpy="0 1.5707963267948966 0"/>
      <geometry><cylinder radius="0.07" length="0.1"/></geometry>
    </visual>
  </link>
  <joint name="pan" type="revolute">
    <parent link="y_carriage"/>
    <child link="pan_link"/>
    <origin xyz="0 0 0" rpy="-1.5707963267948966 0 1.5707963267948966"/>
    <axis xyz="0 0 1"/>
    <limit lower="0" upper="3.14" effort="20" velocity="1"/>
  </joint>
  <link name="pan_link">
    <inertial>
      <origin xyz="0 -0.01 0.3" rpy="0 0 0"/>
      <mass value="2.5"/>
      <inertia ixx="0.035" ixy="0" ixz="0" iyy="0.035" iyz="0" izz="0.004"/>
    </inertial>
    <visual>
      <origin xyz="0 0 0.26"/><geometry><cylinder radius="0.045" length="0.3"/></geometry>
    </visual>
    <collision>
      <origin xyz="0 0 0.26"/><geometry><cylinder radius="0.05" length="0.3"/></geometry>
    </collision>
  </link>
  <joint name="tilt" type="revolute">
    <parent link="pan_link"/>
    <child link="tilt_link"/>
    <origin xyz="0 0 0.45" rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="0" upper="1.05" effort="10" velocity="1"/>
  </joint>
  <link name="tilt_link">
    <visual>
      <origin xyz="0.015 0.035 0.09"/><geometry><box size="0.08 0.025 0.18"/></geometry>
    </visual>
  </link>
  <joint name="vergence_left" type="revolute">
    <parent link="tilt_link"/>
    <child link="vergence_left_link"/>
    <origin xyz="0.05 0 0.15" rpy="1.4835298641951802 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="0" upper="1.57" effort="2" velocity="2"/>
  </joint>
  <joint name="vergence_right" type="revolute">
    <parent link="tilt_link"/>
    <child link="vergence_right_link"/>
    <origin xyz="0.05 0 0.15" rpy="1.4835298641951802 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="0" upper="1.57" effort="2" velocity="2"/>
  </joint>
  <link name="vergence_left_link">
    <visual>
      <origin xyz="0 0 0.005"/><geometry><cylinder radius="0.035" length="0.01"/></geometry>
    </visual>
  </link>
  <link name="vergence_right_link">
    <visual><origin xyz="0.034 0 0.245"/><geometry><box size="0.068 0.02 0.01"/></geometry></visual>
  </link>
  <joint name="left_plate_joint" type="fixed">
    <parent link="vergence_left_link"/>
    <child link="left_plate"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/>
  </joint>
  <link name="left_plate">
    <visual><geometry><box size="0.004 0.08 0.08"/></geometry></visual>
  </link>
  <joint name="left_camera_joint" type="fixed">
    <parent link="left_plate"/>
    <child link="left_camera"/>
    <origin xyz="0.02 0 0" rpy="-1.5707963267948966 0 -1.5707963267948966"/>
  </joint>
  <link name="left_camera"/>
  <joint name="right_plate_joint" type="fixed">
    <parent link="vergence_right_link"/>
    <child link="right_plate"/>
    <origin xyz="0.07 0 0.25" rpy="0.6108652381980153 0 0"/>
  </joint>
  <link name="right_plate">
    <visual><geometry><box size="0.004 0.08 0.08"/></geometry></visual>
  </link>
  <joint name="right_camera_joint" type="fixed">
    <parent link="right_plate"/>
    <child link="right_camera"/>
    <origin xyz="0.02 0 0" rpy="-1.5707963267948966 0 -1.5707963267948966"/>
  </joint>
  <link name="right_camera"/>
</robot>
"""

# A 6R arm with what real description packages carry: meshes (package:// paths that do not
# exist), a transmission, gazebo tags, comments, a custom tag, <calibration>, and a
# gripper with a mimic finger hanging off link6 (off the measured path to the flange).
ARM_URDF = """<?xml version="1.0" encoding="utf-8"?>
<!-- =================================================================== -->
<!-- | 6R test arm: tilted axes, a 0 0 -1 axis, a pitch = pi/2 origin.  | -->
<!-- =================================================================== -->
<robot name="arm6">
  <material name="grey"><color rgba="0.5 0.5 0.5 1"/></material>
  <link name="base_link">
    <inertial>
      <origin xyz="0 0 0.05" rpy="0 0 0"/>
      <mass value="4.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
    </inertial>
    <visual>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="package://arm6_description/meshes/visual/base_link.dae"/></geometry>
      <material name="grey"/>
    </visual>
    <collision>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry>
        <mesh filename="package://arm6_description/meshes/collision/base_link.stl"
              scale="0.001 0.001 0.001"/>
      </geometry>
    </collision>
  </link>
  <!-- shoulder -->
  <joint name="joint1" type="revolute">
    <parent link="base_link"/>
    <child link="link1"/>
    <origin xyz="0 0 0.15" rpy="0 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-3.1" upper="3.1" effort="150" velocity="3.15"/>
    <calibration rising="0.0"/>
    <dynamics damping="0.2" friction="0.0"/>
    <safety_controller soft_lower_limit="-3.0" soft_upper_limit="3.0"
                       k_position="15" k_velocity="10"/>
  </joint>
  <link name="link1">
    <inertial>
      <origin xyz="0.02 0 0.05" rpy="0 0 0"/>
      <mass value="3.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
    </inertial>
    <visual>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="package://arm6_description/meshes/visual/link1.dae"/></geometry>
    </visual>
    <collision>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="package://arm6_description/meshes/collision/link1.stl"/></geometry>
    </collision>
  </link>
  <joint name="joint2" type="revolute">
    <parent link="link1"/>
    <child link="link2"/>
    <origin xyz="0.05 0.0 0.1" rpy="0.3 1.5707963267948966 -0.2"/>
    <axis xyz="0 0 -1"/>
    <limit lower="-2.0" upper="2.0" effort="150" velocity="3.15"/>
  </joint>
  <link name="link2">
    <visual>
      <origin xyz="0.2 0 0" rpy="0 1.5707963267948966 0"/>
      <geometry><mesh filename="package://arm6_description/meshes/visual/link2.dae"/></geometry>
    </visual>
  </link>
  <joint name="joint3" type="revolute">
    <parent link="link2"/>
    <child link="link3"/>
    <origin xyz="0.4 0.0 0.02" rpy="0 0 0.1"/>
    <axis xyz="0.1 0.2 0.9746794344808963"/>
    <limit lower="-2.5" upper="2.5" effort="100" velocity="3.15"/>
  </joint>
  <link name="link3">
    <visual>
      <origin xyz="0.15 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="package://arm6_description/meshes/visual/link3.dae"/></geometry>
    </visual>
  </link>
  <joint name="joint4" type="continuous">
    <parent link="link3"/>
    <child link="link4"/>
    <origin xyz="0.35 0.01 0" rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/>
  </joint>
  <link name="link4">
    <visual>
      <origin xyz="0 0 0.05"/>
      <geometry><mesh filename="package://arm6_description/meshes/visual/link4.dae"/></geometry>
    </visual>
  </link>
  <joint name="joint5" type="revolute">
    <parent link="link4"/>
    <child link="link5"/>
    <origin xyz="0 0 0.12" rpy="1.5707963267948966 0 0"/>
    <axis xyz="0 -0.6 0.8"/>
    <limit lower="-2.0" upper="2.0" effort="28" velocity="3.2"/>
  </joint>
  <link name="link5">
    <visual>
      <geometry><mesh filename="package://arm6_description/meshes/visual/link5.dae"/></geometry>
    </visual>
  </link>
  <joint name="joint6" type="revolute">
    <parent link="link5"/>
    <child link="link6"/>
    <origin xyz="0 0.1 0" rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-6.2" upper="6.2" effort="28" velocity="3.2"/>
  </joint>
  <link name="link6">
    <inertial>
      <origin xyz="0 0 0.02" rpy="0.1 0.2 0.3"/>
      <mass value="0.3"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/>
    </inertial>
    <visual>
      <origin xyz="0 0 0.01" rpy="0 0 0"/>
      <geometry><mesh filename="package://arm6_description/meshes/visual/link6.dae"/></geometry>
    </visual>
  </link>
  <joint name="flange_joint" type="fixed">
    <parent link="link6"/>
    <child link="flange"/>
    <origin xyz="0 0 0.06" rpy="0 1.5707963267948966 0"/>
  </joint>
  <link name="flange"/>
  <!-- gripper: not measured -->
  <joint name="gripper_mount" type="fixed">
    <parent link="link6"/>
    <child link="gripper_base"/>
    <origin xyz="0 0 0.08" rpy="0 0 0.785"/>
  </joint>
  <link name="gripper_base">
    <visual>
      <geometry><mesh filename="package://arm6_description/meshes/visual/gripper.dae"/></geometry>
    </visual>
  </link>
  <joint name="finger_left_joint" type="prismatic">
    <parent link="gripper_base"/>
    <child link="finger_left"/>
    <origin xyz="0 0.01 0.05" rpy="0 0 0"/>
    <axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="20" velocity="0.1"/>
  </joint>
  <link name="finger_left">
    <visual><geometry><mesh filename="package://arm6_description/meshes/visual/finger.dae"/></geometry></visual>
  </link>
  <joint name="finger_right_joint" type="prismatic">
    <parent link="gripper_base"/>
    <child link="finger_right"/>
    <origin xyz="0 -0.01 0.05" rpy="0 0 3.141592653589793"/>
    <axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="20" velocity="0.1"/>
    <mimic joint="finger_left_joint" multiplier="1" offset="0"/>
  </joint>
  <link name="finger_right">
    <visual><geometry><mesh filename="package://arm6_description/meshes/visual/finger.dae"/></geometry></visual>
  </link>
  <transmission name="joint1_transmission">
    <type>transmission_interface/SimpleTransmission</type>
    <joint name="joint1">
      <hardwareInterface>hardware_interface/PositionJointInterface</hardwareInterface>
    </joint>
    <actuator name="joint1_motor"><mechanicalReduction>100</mechanicalReduction></actuator>
  </transmission>
  <gazebo reference="link2">
    <material>Gazebo/Orange</material><selfCollide>true</selfCollide>
  </gazebo>
  <gazebo>
    <plugin name="gazebo_ros_control" filename="libgazebo_ros_control.so">
      <robotNamespace>/arm6</robotNamespace>
    </plugin>
  </gazebo>
  <vendor_data   serial='A-17'  note="kept as written">free text &amp; more</vendor_data>
</robot>
<!-- trailing comment -->
"""

# A prismatic base carrying three branches (R-R, R-P, continuous), no root-to-base joint.
TREE_URDF = """<robot name="three_branches">
  <link name="world"/>
  <joint name="slide" type="prismatic">
    <parent link="world"/><child link="carriage"/>
    <origin xyz="0.2 -0.1 0.5" rpy="0.1 -0.2 0.3"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="carriage">
    <visual><origin xyz="0 0 0.02"/><geometry><box size="0.3 0.2 0.04"/></geometry></visual>
  </link>
  <joint name="a1" type="revolute">
    <parent link="carriage"/><child link="a_link"/>
    <origin xyz="0.1 0.05 0.04"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="a_link">
    <visual><origin xyz="0.05 0 0.02"/><geometry><box size="0.1 0.02 0.02"/></geometry></visual>
  </link>
  <joint name="a2" type="revolute">
    <parent link="a_link"/><child link="a2_link"/>
    <origin xyz="0.1 0 0.02" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="a2_link"/>
  <joint name="a_tool_joint" type="fixed">
    <parent link="a2_link"/><child link="a_tool"/><origin xyz="0.08 0 0"/>
  </joint>
  <link name="a_tool"/>
  <joint name="b1" type="revolute">
    <parent link="carriage"/><child link="b_link"/>
    <origin xyz="-0.1 0.05 0.04"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="b_link"/>
  <joint name="b2" type="prismatic">
    <parent link="b_link"/><child link="b2_link"/>
    <origin xyz="0 0 0.1"/><axis xyz="0.6 0 0.8"/>
    <limit lower="-0.2" upper="0.2" effort="1" velocity="1"/>
  </joint>
  <link name="b2_link"/>
  <joint name="b_tool_joint" type="fixed">
    <parent link="b2_link"/><child link="b_tool"/>
    <origin xyz="0 0 0.05" rpy="0 -1.5707963267948966 0"/>
  </joint>
  <link name="b_tool"/>
  <joint name="c1" type="continuous">
    <parent link="carriage"/><child link="c_link"/>
    <origin xyz="0 -0.1 0.04" rpy="0.2 0 0"/><axis xyz="1 0 0"/>
  </joint>
  <link name="c_link"/>
  <joint name="c_tool_joint" type="fixed">
    <parent link="c_link"/><child link="c_tool"/><origin xyz="0.05 0.02 0.03"/>
  </joint>
  <link name="c_tool"/>
</robot>
"""

CASES = {
    "head": (HEAD_URDF, ("left_plate", "right_plate")),
    "arm": (ARM_URDF, ("flange",)),
    "tree": (TREE_URDF, ("a_tool", "b_tool", "c_tool")),
}
FK_TOL = 1e-9  # m and rad


def _case(name):
    urdf, frames = CASES[name]
    return load_robot(urdf), frames


def _random_qs(topology, n, rng):
    """Configurations (n, J) well beyond the joint limits (FK does not care)."""
    span = np.where(topology.revolute, np.pi, 0.5)
    return rng.uniform(-span, span, size=(n, len(span)))


def _pose_errors(a_T_bs, a_T_cs):
    """Largest position (m) and orientation (rad) difference over a batch of poses."""
    dp = np.linalg.norm(a_T_bs[..., :3, 3] - a_T_cs[..., :3, 3], axis=-1).max()
    dr = rotation_angle(np.swapaxes(a_T_bs[..., :3, :3], -1, -2) @ a_T_cs[..., :3, :3]).max()
    return dp, dr


def _fk_errors(result, model, n=200, seed=0, m_T_w=None):
    """Max FK discrepancy of the exported URDF against a CPC model over random q.

    The export was given the model's geometry in frame ``m`` (``m_T_w``, default ``w``).
    """
    exported = load_robot(result.urdf_xml)
    names = model.topology.joint_names
    qs = _random_qs(model.topology, n, np.random.default_rng(seed))
    root_T_w = inverse_transform(result.w_T_root) @ (np.eye(4) if m_T_w is None else m_T_w)
    errors = [
        _pose_errors(exported.frame_poses(qs, f, names), root_T_w @ model.frame_poses(qs, f))
        for f in model.topology.frames
    ]
    return max(e[0] for e in errors), max(e[1] for e in errors)


def _perturbed(robot, frames, seed, scale=0.01):
    model = cpc_from_robot(robot, frames)
    return model.perturbed(np.random.default_rng(seed).normal(size=model.n_parameters) * scale)


def _moved(m_T_w, geometry):
    """The same geometry expressed in another frame ``m``."""
    R, t = m_T_w[:3, :3], m_T_w[:3, 3]
    return ZeroGeometry(
        topology=geometry.topology,
        axes=geometry.axes @ R.T,
        points=geometry.points @ R.T + t,
        w_T_frames=m_T_w @ geometry.w_T_frames,
    )


def _transform(rpy, xyz=(0.1, -0.2, 0.3)):
    a_T_b = np.eye(4)
    a_T_b[:3, :3] = pin.rpy.rpyToMatrix(np.asarray(rpy, dtype=float))
    a_T_b[:3, 3] = xyz
    return a_T_b


def _links_at_zero(robot):
    """``root_T_link`` at q = 0 of every link, by Pinocchio."""
    zero = np.zeros(len(robot.joint_names))
    return {link: robot.frame_poses(zero, link) for link in robot.link_names}


def _non_origin_content(xml):
    """Everything lxml sees but <origin> and <axis>: (tag, attributes, text, tail) in order."""
    return [
        (str(e.tag), tuple(e.attrib.items()), e.text, e.tail)
        for e in etree.fromstring(xml.encode()).iter()
        if e.tag not in ("origin", "axis")
    ]


# -- identity and idempotence -------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(CASES))
def test_nominal_geometry_exports_the_nominal_urdf_unchanged(name):
    robot, frames = _case(name)
    result = export_urdf(robot, geometry_from_robot(robot, frames))
    assert result.urdf_xml == robot.urdf_xml
    assert result.link_shifts == ()
    np.testing.assert_array_equal(result.w_T_root, np.eye(4))
    reloaded = load_robot(result.urdf_xml)
    for nominal, again in zip(robot.joints, reloaded.joints, strict=True):
        np.testing.assert_array_equal(again.parent_T_child, nominal.parent_T_child)
    names = robot.topology(frames).joint_names
    qs = _random_qs(robot.topology(frames), 50, np.random.default_rng(1))
    for frame in frames:
        np.testing.assert_allclose(
            reloaded.frame_poses(qs, frame, names),
            robot.frame_poses(qs, frame, names),
            rtol=0,
            atol=1e-12,
        )


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("root_is_w", [True, False])
def test_reexport_of_the_exported_urdf_is_identical(name, root_is_w):
    robot, frames = _case(name)
    first = export_urdf(
        robot,
        geometry_from_cpc(_perturbed(robot, frames, seed=2)),
        root_is_measurement_frame=root_is_w,
    )
    exported = load_robot(first.urdf_xml)
    again = export_urdf(
        exported, geometry_from_robot(exported, frames), root_is_measurement_frame=root_is_w
    )
    assert again.urdf_xml == first.urdf_xml
    assert again.link_shifts == ()


def test_calibrated_export_keeps_every_other_tag_comment_and_declaration():
    robot, frames = _case("arm")
    result = export_urdf(robot, geometry_from_cpc(_perturbed(robot, frames, seed=3)))
    assert result.urdf_xml != robot.urdf_xml
    assert result.urdf_xml.startswith('<?xml version="1.0" encoding="utf-8"?>\n<!-- ====')
    assert result.urdf_xml.endswith("</robot>\n<!-- trailing comment -->\n")
    assert _non_origin_content(result.urdf_xml) == _non_origin_content(robot.urdf_xml)
    tree = etree.fromstring(result.urdf_xml.encode())
    assert [c.text for c in tree.iter(etree.Comment)] == [" shoulder ", " gripper: not measured "]
    assert len(tree.findall("transmission")) == 1 and len(tree.findall("gazebo")) == 2
    assert tree.find("joint[@name='finger_right_joint']/mimic").get("joint") == "finger_left_joint"
    assert tree.find("joint[@name='joint1']/calibration") is not None
    nominal_tree = etree.fromstring(robot.urdf_xml.encode())
    assert [m.attrib for m in tree.iter("mesh")] == [m.attrib for m in nominal_tree.iter("mesh")]
    assert '<vendor_data serial="A-17" note="kept as written">free text &amp; more' in (
        result.urdf_xml
    )  # lxml normalises quotes and spaces inside a tag, nothing else


# -- calibrated forward kinematics --------------------------------------------------------


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("seed", [0, 1])
def test_calibrated_export_reproduces_the_calibrated_fk(name, seed):
    robot, frames = _case(name)
    model = _perturbed(robot, frames, seed)
    result = export_urdf(robot, geometry_from_cpc(model))
    dp, dr = _fk_errors(result, model, n=200, seed=seed)
    assert dp < FK_TOL and dr < FK_TOL, (dp, dr)
    np.testing.assert_array_equal(result.w_T_root, np.eye(4))


@pytest.mark.parametrize("name", sorted(CASES))
def test_external_measurement_frame_is_reported_not_written(name):
    robot, frames = _case(name)
    model = _perturbed(robot, frames, seed=4)
    mocap_T_root = _transform((0.4, -1.1, 2.0), xyz=(3.0, -1.5, 0.8))
    result = export_urdf(
        robot, _moved(mocap_T_root, geometry_from_cpc(model)), root_is_measurement_frame=False
    )
    dp, dr = _fk_errors(result, model, n=100, seed=5, m_T_w=mocap_T_root)
    assert dp < FK_TOL and dr < FK_TOL, (dp, dr)
    exported = load_robot(result.urdf_xml)
    for nominal, written in zip(robot.joints, exported.joints, strict=True):
        if nominal.parent == robot.root_link and nominal.type == "fixed":
            np.testing.assert_array_equal(written.parent_T_child, nominal.parent_T_child)


def test_external_measurement_frame_of_the_nominal_robot_is_found_exactly():
    for name in sorted(CASES):
        robot, frames = _case(name)
        mocap_T_root = _transform((0.4, -1.1, 2.0), xyz=(3.0, -1.5, 0.8))
        result = export_urdf(
            robot,
            _moved(mocap_T_root, geometry_from_robot(robot, frames)),
            root_is_measurement_frame=False,
        )
        np.testing.assert_allclose(result.w_T_root, mocap_T_root, rtol=0, atol=1e-12)
        assert result.urdf_xml == robot.urdf_xml


def test_a_rigidly_moved_head_only_changes_the_root_to_base_joint():
    robot, frames = _case("head")
    w_T_moved = _transform((0.02, -0.01, 0.03), xyz=(0.01, -0.02, 0.015))
    result = export_urdf(robot, _moved(w_T_moved, geometry_from_robot(robot, frames)))
    assert result.link_shifts == ()
    exported = load_robot(result.urdf_xml)
    for nominal, written in zip(robot.joints, exported.joints, strict=True):
        expected = nominal.parent_T_child
        if nominal.name == "world_to_base":
            expected = w_T_moved @ expected
        np.testing.assert_allclose(written.parent_T_child, expected, rtol=0, atol=1e-12)


def test_root_to_base_joint_takes_the_registered_base_placement():
    robot, frames = _case("head")
    result = export_urdf(robot, geometry_from_cpc(_perturbed(robot, frames, seed=6)))
    assert "base" not in dict(result.link_shifts)  # the base moved as a body, visuals with it
    moved = load_robot(result.urdf_xml).joint("world_to_base").parent_T_child
    dp, dr = _pose_errors(moved, robot.joint("world_to_base").parent_T_child)
    assert 0.0 < dp < 0.2 and 0.0 < dr < 0.2


def test_end_frames_named_by_joints_are_their_child_links():
    robot = load_robot(TREE_URDF)
    model = _perturbed(robot, ("a_tool_joint", "b_tool_joint", "c_tool"), seed=11)
    dp, dr = _fk_errors(export_urdf(robot, geometry_from_cpc(model)), model, n=100)
    assert dp < FK_TOL and dr < FK_TOL, (dp, dr)


@settings(max_examples=25, deadline=None)
@given(st.sampled_from(sorted(CASES)), st.data())
def test_any_small_perturbation_is_reproduced(name, data):
    robot, frames = _case(name)
    model = cpc_from_robot(robot, frames)
    delta = data.draw(
        arrays(
            np.float64, model.n_parameters, elements=st.floats(-0.03, 0.03, allow_subnormal=False)
        )
    )
    calibrated = model.perturbed(delta)
    dp, dr = _fk_errors(export_urdf(robot, geometry_from_cpc(calibrated)), calibrated, n=100)
    assert dp < FK_TOL and dr < FK_TOL, (dp, dr)


# -- where the link frames go -------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(CASES))
def test_moved_link_frames_are_projections_onto_the_calibrated_axes(name):
    robot, frames = _case(name)
    geometry = geometry_from_cpc(_perturbed(robot, frames, seed=7))
    result = export_urdf(robot, geometry)
    shifts = dict(result.link_shifts)
    exported = load_robot(result.urdf_xml)
    w_T_links = _links_at_zero(exported)
    for j, joint_name in enumerate(geometry.topology.joint_names):
        joint = robot.joint(joint_name)
        w_T_candidate = (
            w_T_links[joint.parent]
            @ inverse_transform(shifts.get(joint.parent, np.eye(4)))
            @ joint.parent_T_child
        )
        w_T_child = w_T_links[joint.child]
        axis = geometry.axes[j] / np.linalg.norm(geometry.axes[j])
        np.testing.assert_allclose(
            w_T_child[:3, :3] @ exported.joint(joint_name).axis, axis, atol=1e-12
        )
        np.testing.assert_allclose(w_T_child[:3, :3], w_T_candidate[:3, :3], atol=1e-12)
        if not joint.is_revolute:
            np.testing.assert_allclose(w_T_child[:3, 3], w_T_candidate[:3, 3], atol=1e-12)
            continue
        offset = w_T_candidate[:3, 3] - geometry.points[j]
        projection = geometry.points[j] + (offset @ axis) * axis
        distance = np.linalg.norm(w_T_candidate[:3, 3] - projection)
        moved = np.linalg.norm(w_T_child[:3, 3] - w_T_candidate[:3, 3])
        assert moved <= distance + 1e-12
        np.testing.assert_allclose(w_T_child[:3, 3], projection, atol=1e-12)
        if joint.child in shifts:
            np.testing.assert_allclose(
                shifts[joint.child], inverse_transform(w_T_candidate) @ w_T_child, atol=1e-12
            )


@pytest.mark.parametrize("name", sorted(CASES))
def test_shifted_links_keep_visuals_collisions_inertials_and_children_in_place(name):
    robot, frames = _case(name)
    result = export_urdf(robot, geometry_from_cpc(_perturbed(robot, frames, seed=8)))
    assert result.link_shifts
    exported = load_robot(result.urdf_xml)
    w_T_links = _links_at_zero(exported)
    nominal_urdf, exported_urdf = _yourdfpy(robot.urdf_xml), _yourdfpy(result.urdf_xml)
    for link, old_T_new in result.link_shifts:
        w_T_old = w_T_links[link] @ inverse_transform(old_T_new)  # the nominal link frame
        for old_T_x, new_T_x in zip(
            _geometry_origins(nominal_urdf, link),
            _geometry_origins(exported_urdf, link),
            strict=True,
        ):
            np.testing.assert_allclose(w_T_links[link] @ new_T_x, w_T_old @ old_T_x, atol=1e-12)
        for joint in robot.joints:
            if joint.parent == link and joint.child not in frames and not joint.is_movable:
                np.testing.assert_allclose(
                    w_T_links[joint.child], w_T_old @ joint.parent_T_child, atol=1e-12
                )


def _yourdfpy(xml):
    return yourdfpy.URDF.load(
        io.BytesIO(xml.encode()),
        load_meshes=False,
        build_scene_graph=False,
        load_collision_meshes=False,
        build_collision_scene_graph=False,
    )


def _geometry_origins(urdf, link):
    """Origins (4, 4) of a link's visuals, collisions and inertial, in file order."""
    elem = urdf.link_map[link]
    out = [v.origin for v in elem.visuals] + [c.origin for c in elem.collisions]
    out += [] if elem.inertial is None else [elem.inertial.origin]
    return [np.eye(4) if T is None else np.asarray(T, dtype=float) for T in out]


# -- an end frame that is a revolute joint's child link -----------------------------------

REVOLUTE_CHILD_FRAMES = ("a_link", "a_tool", "c_link", "b_tool")


def _delta(model, **entries):
    """A chart step that is zero except for ``{"frame__field": value}`` entries."""
    delta = np.zeros(model.n_parameters)
    for key, value in entries.items():
        delta[model.parameter_names.index(tuple(key.split("__")))] = value
    return delta


def test_end_frame_on_a_revolute_child_link_exports_when_it_stays_on_the_axis():
    robot = load_robot(TREE_URDF)
    model = cpc_from_robot(robot, REVOLUTE_CHILD_FRAMES)
    rng = np.random.default_rng(9)
    delta = rng.normal(size=model.n_parameters) * 0.01
    for frame in ("a_link", "c_link"):  # keep their tool origins on the joint axis
        delta[model.parameter_names.index((frame, "x"))] = 0.0
        delta[model.parameter_names.index((frame, "y"))] = 0.0
    calibrated = model.perturbed(delta)
    result = export_urdf(robot, geometry_from_cpc(calibrated))
    dp, dr = _fk_errors(result, calibrated, n=150)
    assert dp < FK_TOL and dr < FK_TOL, (dp, dr)
    assert {"a_link", "c_link"} <= set(dict(result.link_shifts))


def test_end_frame_off_its_revolute_axis_is_refused_with_the_fix():
    robot = load_robot(TREE_URDF)
    model = cpc_from_robot(robot, REVOLUTE_CHILD_FRAMES)
    calibrated = model.perturbed(_delta(model, c_link__y=1e-3))
    with pytest.raises(
        ExportError,
        match=r"'c_link' is the child link of revolute joint 'c1'"
        r".*0\.001 m off.*fixed",
    ):
        export_urdf(robot, geometry_from_cpc(calibrated))


@pytest.mark.parametrize(
    ("frames", "entries", "match"),
    [
        (("world", "a_tool"), {"world__x": 1e-3}, "'world' is the root link"),
        (("a2", "a2_link", "b_tool"), {"a2_link__rot_z": 1e-3}, "name link 'a2_link' twice"),
    ],
)
def test_end_frames_that_cannot_take_their_calibrated_pose_are_refused(frames, entries, match):
    robot = load_robot(TREE_URDF)
    model = cpc_from_robot(robot, frames)
    export_urdf(robot, geometry_from_cpc(model))  # consistent as long as nothing moves them
    with pytest.raises(ExportError, match=match):
        export_urdf(robot, geometry_from_cpc(model.perturbed(_delta(model, **entries))))


def test_geometry_of_another_tree_is_refused():
    robot, frames = _case("tree")
    geometry = geometry_from_robot(robot, frames)
    topology = geometry.topology
    other = replace(geometry, topology=replace(topology, parent=(-1,) * len(topology.parent)))
    with pytest.raises(ExportError, match="does not match"):
        export_urdf(robot, other)


# -- rpy and gimbal lock ------------------------------------------------------------------

ONE_JOINT = """<robot name="one">
  <link name="a"/>
  <joint name="j" type="revolute">
    <parent link="a"/><child link="b"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="b">
    <visual><geometry><sphere radius="0.1"/></geometry></visual>
  </link>
</robot>
"""


@pytest.mark.parametrize("pitch", [PI_2, -PI_2, PI_2 - 1e-13, -PI_2 + 1e-9, PI_2 - 1e-6, 3.0])
@pytest.mark.parametrize(("roll", "yaw"), [(0.3, -0.2), (2.9, 3.1), (-3.1, -2.0), (0.0, 0.0)])
def test_origin_round_trips_through_rpy_at_and_near_gimbal_lock(pitch, roll, yaw):
    a_T_b = _transform((roll, pitch, yaw))
    xml = edit_urdf(ONE_JOINT, joint_origins={"j": a_T_b})
    written = load_robot(xml).joint("j").parent_T_child  # yourdfpy's own rpy -> matrix
    np.testing.assert_allclose(written, a_T_b, rtol=0, atol=1e-12)
    origin = etree.fromstring(xml.encode()).find("joint/origin")
    rpy = np.array(origin.get("rpy").split(), dtype=float)
    np.testing.assert_allclose(pin.rpy.rpyToMatrix(rpy), a_T_b[:3, :3], rtol=0, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-np.pi, np.pi),
    st.floats(-np.pi, np.pi),
    st.sampled_from([PI_2, -PI_2]),
    st.floats(-1e-6, 1e-6),
    arrays(np.float64, 3, elements=st.floats(-1e-8, 1e-8)),
)
def test_rpy_near_gimbal_lock_reproduces_the_matrix(roll, yaw, pitch, tiny, rotvec):
    a_T_b = _transform((roll, pitch + tiny, yaw))
    a_T_b[:3, :3] = a_T_b[:3, :3] @ pin.exp3(rotvec)  # also off the rpy grid
    xml = edit_urdf(ONE_JOINT, joint_origins={"j": a_T_b})
    np.testing.assert_allclose(load_robot(xml).joint("j").parent_T_child, a_T_b, rtol=0, atol=1e-12)


def test_floats_are_written_with_repr_and_read_back_exactly():
    a_T_b = _transform((0.1, 0.2, 0.3), xyz=(1 / 3, -2 / 7, 1e-17))
    xml = edit_urdf(ONE_JOINT, joint_origins={"j": a_T_b}, joint_axes={"j": [0.6, 0.0, -0.8]})
    joint = etree.fromstring(xml.encode()).find("joint")
    assert joint.find("origin").get("xyz") == f"{1 / 3!r} {-2 / 7!r} 1e-17"
    assert [float(v) for v in joint.find("axis").get("xyz").split()] == [0.6, 0.0, -0.8]
    rpy = [float(v) for v in joint.find("origin").get("rpy").split()]
    np.testing.assert_array_equal(rpy, pin.rpy.matrixToRpy(a_T_b[:3, :3]))


# -- edit_urdf ----------------------------------------------------------------------------


def test_edit_creates_missing_origin_and_axis_and_keeps_the_rest():
    xml = edit_urdf(
        ONE_JOINT,
        joint_origins={"j": _transform((0, 0, 0), xyz=(0, 0, 0.5))},
        joint_axes={"j": [0.0, 1.0, 0.0]},
    )
    assert '<origin xyz="0.0 0.0 0.5"/>' in xml  # the rotation did not change: no rpy
    assert '<axis xyz="0.0 1.0 0.0"/>' in xml
    robot = load_robot(xml)
    np.testing.assert_array_equal(robot.joint("j").axis, [0.0, 1.0, 0.0])
    stripped = xml.replace('<origin xyz="0.0 0.0 0.5"/>\n    ', "").replace(
        '<axis xyz="0.0 1.0 0.0"/>\n    ', ""
    )
    assert stripped == ONE_JOINT


def test_unchanged_values_keep_the_original_text():
    robot, _ = _case("arm")
    origins = {j.name: j.parent_T_child + 1e-13 * (j.parent_T_child != 0) for j in robot.joints}
    axes = {j.name: j.axis for j in robot.joints if j.is_movable}
    shifts = {"link3": np.eye(4)}
    assert (
        edit_urdf(robot.urdf_xml, joint_origins=origins, joint_axes=axes, link_shifts=shifts)
        == robot.urdf_xml
    )


def test_link_shift_reexpresses_geometry_and_child_joints_unless_given():
    robot, _ = _case("arm")
    old_T_new = _transform((0.05, -0.02, 0.1), xyz=(0.01, 0.02, -0.03))
    given_origin = _transform((0.0, PI_2, 0.0), xyz=(0.0, 0.0, 0.07))
    xml = edit_urdf(
        robot.urdf_xml,
        link_shifts={"link6": old_T_new},
        joint_origins={"flange_joint": given_origin},
    )
    new_T_old = inverse_transform(old_T_new)
    before, after = _yourdfpy(robot.urdf_xml), _yourdfpy(xml)
    for old_T_x, new_T_x in zip(
        _geometry_origins(before, "link6"), _geometry_origins(after, "link6"), strict=True
    ):
        np.testing.assert_allclose(new_T_x, new_T_old @ old_T_x, atol=1e-12)
    edited = load_robot(xml)
    np.testing.assert_allclose(
        edited.joint("gripper_mount").parent_T_child,
        new_T_old @ robot.joint("gripper_mount").parent_T_child,
        atol=1e-12,
    )
    np.testing.assert_allclose(
        edited.joint("flange_joint").parent_T_child, given_origin, atol=1e-12
    )
    # Everything else, e.g. the transmission's own <joint name="joint1">, is untouched.
    np.testing.assert_array_equal(
        edited.joint("joint6").parent_T_child, robot.joint("joint6").parent_T_child
    )
    assert _non_origin_content(xml) == _non_origin_content(robot.urdf_xml)


def test_unknown_joint_and_link_names_are_all_named():
    with pytest.raises(ExportError, match=r"unknown joint name\(s\) \['nope', 'zzz'\]"):
        edit_urdf(
            ONE_JOINT,
            joint_origins={"nope": np.eye(4), "j": np.eye(4)},
            joint_axes={"zzz": [0.0, 0.0, 1.0]},
        )
    with pytest.raises(ExportError, match=r"unknown link name\(s\) \['c'\]"):
        edit_urdf(ONE_JOINT, link_shifts={"c": np.eye(4)})


def test_joints_inside_a_transmission_are_not_edited():
    robot, _ = _case("arm")
    xml = edit_urdf(
        robot.urdf_xml,
        joint_origins={"joint1": _transform((0.0, 0.0, 0.1))},
        joint_axes={"joint1": [0.0, 0.0, -1.0]},
    )
    tree = etree.fromstring(xml.encode())
    assert tree.find("transmission/joint").getchildren()[0].tag == "hardwareInterface"
    assert len(tree.find("transmission/joint")) == 1
    np.testing.assert_allclose(
        load_robot(xml).joint("joint1").parent_T_child, _transform((0.0, 0.0, 0.1)), atol=1e-12
    )


def test_attribute_order_is_kept_when_an_origin_changes():
    urdf = ONE_JOINT.replace(
        '<parent link="a"/>', '<origin rpy="0 0 0" xyz="0 0 0"/><parent link="a"/>'
    )
    xml = edit_urdf(urdf, joint_origins={"j": _transform((0.0, 0.5, 0.0), xyz=(0, 0, 0))})
    assert '<origin rpy="0.0 0.5 0.0" xyz="0 0 0"/><parent link="a"/>' in xml


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"joint_origins": {"j": np.ones((3, 4))}}, ValueError, r"joint_origins\['j'\].*shape"),
        ({"joint_origins": {"j": np.diag([1.0, 1.0, -1.0, 1.0])}}, ValueError, "not a rotation"),
        ({"joint_axes": {"j": [0.0, 0.0, 2.0]}}, ExportError, "unit 3-vector"),
        ({"joint_axes": {"j": [0.0, 1.0]}}, ExportError, "unit 3-vector"),
        (
            {"joint_origins": {"j": _transform((0, 0, 0)) @ np.diag([1.0, 1.0 + 1e-9, 1.0, 1.0])}},
            ExportError,
            "reproduce the rotation only to",
        ),
    ],
)
def test_bad_edits_are_refused(kwargs, error, match):
    with pytest.raises(error, match=match):
        edit_urdf(ONE_JOINT, **kwargs)


def test_bad_xml_is_refused():
    with pytest.raises(ExportError, match="not well-formed"):
        edit_urdf("<robot><link name='a'></robot>", link_shifts={"a": np.eye(4)})
    with pytest.raises(ExportError, match="expected <robot>"):
        edit_urdf("<sdf/>")
    bad = ONE_JOINT.replace('<parent link="a"/>', '<origin xyz="1 2"/><parent link="a"/>')
    with pytest.raises(ExportError, match=r"joint 'j': <origin xyz='1 2'> is not three numbers"):
        edit_urdf(bad, joint_origins={"j": np.eye(4)})


# -- writing ------------------------------------------------------------------------------


def test_write_urdf_writes_the_text_as_utf8_with_its_declaration(tmp_path):
    robot, frames = _case("arm")
    result = export_urdf(robot, geometry_from_cpc(_perturbed(robot, frames, seed=10)))
    assert isinstance(result, ExportResult)
    write_urdf(tmp_path / "arm.urdf", result)
    data = (tmp_path / "arm.urdf").read_bytes()
    assert data == result.urdf_xml.encode("utf-8")
    assert data.startswith(b'<?xml version="1.0" encoding="utf-8"?>')
    write_urdf(str(tmp_path / "one.urdf"), ONE_JOINT.replace("one", "\u00fcber"))
    assert load_robot(tmp_path / "one.urdf").urdf_xml == ONE_JOINT.replace("one", "\u00fcber")
