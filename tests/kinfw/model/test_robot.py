"""kinfw.model: loading, names, FK of continuous joints, topology, refused joints."""

import numpy as np
import pinocchio as pin
import pytest

from kinfw.geometry import matrix_from_rotation_vector
from kinfw.model import RobotModelError, UnknownFrameError, load_robot
from tests.robots import ARM_6R, PRISMATIC_TREE

MIXED = """<?xml version="1.0"?>
<robot name="mixed">
  <link name="world"/>
  <joint name="spin" type="continuous">
    <parent link="world"/><child link="a"/><origin xyz="0 0 0.5"/><axis xyz="0 0 -1"/>
  </joint>
  <link name="a"/>
  <joint name="free" type="floating"><parent link="a"/><child link="drone"/></joint>
  <link name="drone"/>
  <joint name="j1" type="revolute">
    <parent link="a"/><child link="b"/><origin xyz="0.2 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="b"/>
  <joint name="finger" type="revolute">
    <parent link="b"/><child link="tip"/><mimic joint="j1" multiplier="2"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="tip"/>
  <joint name="plane" type="planar"><parent link="world"/><child link="cart"/></joint>
  <link name="cart"/>
</robot>
"""


def test_continuous_joint_fk_by_hand():
    robot = load_robot(MIXED)
    assert robot.joint_names == ("spin", "j1", "finger")
    q = np.array([[0.7, 0.3, 0.0]])
    T = robot.frame_poses(q, "b")[0]
    # world_T_b = Trans(0,0,0.5) Rot(-z, 0.7) Trans(0.2,0,0) Rot(y, 0.3)
    R_spin = matrix_from_rotation_vector([0.0, 0.0, -0.7])
    expected_p = np.array([0.0, 0.0, 0.5]) + R_spin @ np.array([0.2, 0.0, 0.0])
    expected_R = R_spin @ matrix_from_rotation_vector([0.0, 0.3, 0.0])
    np.testing.assert_allclose(T[:3, 3], expected_p, atol=1e-15)
    np.testing.assert_allclose(T[:3, :3], expected_R, atol=1e-15)


def _pinocchio_fk(urdf, names, q, frame):
    """``root_T_frame`` straight from Pinocchio (its own model, not kinfw's): revolute and
    prismatic joints take q, continuous ones (cos q, sin q)."""
    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    config = pin.neutral(model)
    for name, value in zip(names, q, strict=True):
        joint = model.joints[model.getJointId(name)]
        config[joint.idx_q : joint.idx_q + joint.nq] = (
            [np.cos(value), np.sin(value)] if joint.nq == 2 else [value]
        )
    pin.framesForwardKinematics(model, data, config)
    return data.oMf[model.getFrameId(frame)].homogeneous


def test_frame_poses_batch_in_batch_out():
    """(k,) gives (4, 4), (n, k) gives (n, 4, 4) also for n = 1; the poses are
    Pinocchio's own FK."""
    robot = load_robot(ARM_6R)
    names = robot.joint_names
    qs = np.random.default_rng(3).uniform(-2.5, 2.5, size=(4, len(names)))
    truth = np.stack([_pinocchio_fk(ARM_6R, names, q, "flange") for q in qs])
    single = robot.frame_poses(qs[0], "flange")
    assert single.shape == (4, 4)
    np.testing.assert_allclose(single, truth[0], rtol=0, atol=1e-12)
    one = robot.frame_poses(qs[:1], "flange")
    assert one.shape == (1, 4, 4)
    np.testing.assert_allclose(one, truth[:1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(robot.frame_poses(qs, "flange"), truth, rtol=0, atol=1e-12)
    assert robot.frame_poses(np.empty((0, len(names))), "flange").shape == (0, 4, 4)
    with pytest.raises(ValueError, match=r"qs: expected shape \(6,\) or \(n, 6\).*got \(\)"):
        robot.frame_poses(0.0, "flange")
    with pytest.raises(ValueError, match=r"qs: expected shape \(6,\) or \(n, 6\)"):
        robot.frame_poses(qs[None], "flange")


def test_unlisted_joints_are_held_at_zero():
    robot = load_robot(MIXED)
    T_all = robot.frame_poses([0.0, 0.3, 0.0], "b")
    T_some = robot.frame_poses([0.3], "b", joint_names=("j1",))
    np.testing.assert_allclose(T_all, T_some, atol=1e-15)


def test_unknown_frame_raises_with_the_links_listed():
    robot = load_robot(ARM_6R)
    with pytest.raises(UnknownFrameError, match=r"no frame 'flang'; links are \['world'"):
        robot.frame_id("flang")
    with pytest.raises(KeyError):  # also a KeyError, for dict-like use
        robot.frame_poses([0.0] * 6, "nope")


def test_floating_planar_and_mimic_joints_on_a_path_are_refused_by_name():
    robot = load_robot(MIXED)
    with pytest.raises(RobotModelError, match="joint 'free' on the path to 'drone' is floating"):
        robot.topology(["drone"])
    with pytest.raises(RobotModelError, match="joint 'plane' on the path to 'cart' is planar"):
        robot.topology(["cart"])
    with pytest.raises(RobotModelError, match="joint 'finger' on the path to 'tip' mimics 'j1'"):
        robot.topology(["tip"])
    # ...but they do not matter off the measured paths
    topo = robot.topology(["b"])
    assert topo.joint_names == ("spin", "j1")


def test_topology_of_a_tree_with_three_branches():
    robot = load_robot(PRISMATIC_TREE)
    topo = robot.topology(["tool_a", "cam", "tool_b"])
    assert topo.joint_names == ("px", "py", "pan", "a1", "a2", "slide", "wrist")
    assert topo.revolute == (False, False, True, True, True, False, True)
    assert topo.parent == (-1, 0, 1, 2, 3, 2, 5)
    assert topo.frame_parent == (4, 2, 6)
    assert topo.branch_points == (2,)
    assert topo.chain("tool_b") == (0, 1, 2, 5, 6)
    assert topo.chain("cam") == (0, 1, 2)
    assert topo.children(2) == (3, 5)


def test_bad_urdf_inputs_name_the_source(tmp_path):
    with pytest.raises(RobotModelError, match="cannot read URDF"):
        load_robot(tmp_path / "missing.urdf")
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint name='j'", encoding="utf-8")
    with pytest.raises(RobotModelError, match=r"bad\.urdf: not well-formed XML"):
        load_robot(bad)
    two_roots = "<robot name='x'><link name='a'/><link name='b'/></robot>"
    with pytest.raises(RobotModelError, match="expected one root link"):
        load_robot(two_roots)


def test_wrong_number_of_joint_values_is_an_error():
    robot = load_robot(ARM_6R)
    with pytest.raises(ValueError, match=r"expected 6 columns"):
        robot.frame_poses(np.zeros(5), "flange")
    with pytest.raises(UnknownFrameError, match="no joint 'j9'"):
        robot.frame_poses([0.0], "flange", joint_names=("j9",))


def test_xml_that_is_not_a_urdf_is_refused():
    with pytest.raises(RobotModelError, match=r"root element is <html>, expected <robot>"):
        load_robot("<html><body/></html>")


def test_import_kinfw_loads_neither_casadi_nor_meshcat():
    import subprocess
    import sys

    code = "import sys, kinfw; print(int('casadi' in sys.modules), int('meshcat' in sys.modules))"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == ["0", "0"]
