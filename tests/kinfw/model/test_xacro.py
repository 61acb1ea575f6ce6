"""xacro URDFs: expanded by the xacro package, with arguments, from a file, a string or
stdin, into the robot a hand-written URDF describes (Pinocchio's kinematics compared)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest

from kinfw.model import XACRO_NAMESPACE as NS
from kinfw.model import RobotModelError, load_robot
from tests.cli_run import run_cli
from tests.erd import urdf_path
from tests.paths import DATA

ARM = DATA / "xacro" / "arm.urdf.xacro"
EXPANDED = """<robot name="arm">
  <link name="base_link"/><link name="l1"/><link name="l2"/>
  <joint name="l1_joint" type="revolute"><parent link="base_link"/><child link="l1"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="l2_joint" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 {upper}" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
</robot>"""
Q = np.random.default_rng(0).uniform(-2, 2, (20, 2))
NAMES = ("l1_joint", "l2_joint")


def _l2(robot):
    return robot.frame_poses(Q, "l2", NAMES)


@pytest.mark.parametrize(("args", "upper"), [(None, "0.5"), ({"upper": "0.7"}, "0.7")])
def test_a_xacro_file_is_the_robot_its_expansion_describes(args, upper):
    robot = load_robot(ARM, xacro_args=args)
    assert robot.source == str(ARM) and robot.joint_names == NAMES
    np.testing.assert_allclose(
        _l2(robot), _l2(load_robot(EXPANDED.format(upper=upper))), atol=1e-15
    )
    # by hand at zero: l2 at the two heights above the base
    zero = robot.frame_poses(np.zeros((1, 2)), "l2", NAMES)[0, :3, 3]
    np.testing.assert_allclose(zero, [0, 0, 0.1 + float(upper)], atol=1e-15)


def test_xacro_errors_name_the_file_and_plain_urdfs_refuse_arguments(tmp_path):
    bad = tmp_path / "bad.urdf.xacro"
    bad.write_text(ARM.read_text().replace('filename="link.xacro"', 'filename="nope.xacro"'))
    with pytest.raises(RobotModelError, match=rf"^{bad}: xacro: .*nope\.xacro"):
        load_robot(bad)
    with pytest.raises(RobotModelError, match="xacro arguments given \\(upper\\) for a plain URDF"):
        load_robot(EXPANDED.format(upper=0.5), xacro_args={"upper": "1"})


@pytest.mark.slow
def test_the_command_line_takes_xacro_arguments_and_a_urdf_on_stdin(capsys):
    """reach puts l2 (on the y axes) at a point it can reach only with upper = 0.7 m: the
    distance from l1's joint to l2 is the argument."""
    argv = ["-q", "reach", ARM, "--frame", "l2", "--point", "0.7", "0", "0.1", "--json"]
    code, _, err = run_cli([*argv, "--xacro-arg", "upper:=0.7"], capsys)
    assert code == 0, err
    code, _, err = run_cli(argv, capsys)  # 0.5 m: out of reach
    assert code == 3, err
    code, _, err = run_cli([*argv, "--xacro-arg", "upper=0.7"], capsys)
    assert code == 2 and "expected NAME:=VALUE" in err
    text = EXPANDED.format(upper=0.7)
    done = subprocess.run(
        [sys.executable, "-m", "kinfw.cli", "-q", "reach", "-", *argv[3:]],
        input=text,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr


def _panda_fk_by_pinocchio(path, names, q, frame):
    """``root_T_frame`` from Pinocchio's own parse of the file (revolute joints only)."""
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    config = pin.neutral(model)
    for name, value in zip(names, q, strict=True):
        config[model.joints[model.getJointId(name)].idx_q] = value
    pin.framesForwardKinematics(model, data, config)
    return data.oMf[model.getFrameId(frame)].homogeneous


DECLARES = EXPANDED.replace('<robot name="arm">', f'<robot name="arm" xmlns:xacro="{NS}">')


def test_a_urdf_that_only_declares_the_xacro_namespace_needs_no_xacro(monkeypatch):
    """xacro's output keeps ``xmlns:xacro`` (example-robot-data's panda.urdf): without the
    xacro package it is read as the URDF it is (it was refused as a xacro file)."""
    monkeypatch.setitem(sys.modules, "xacro", None)  # import xacro: ImportError
    panda = urdf_path("panda_description/urdf/panda.urdf")
    assert NS in panda.read_text()
    robot = load_robot(panda)
    q = np.random.default_rng(1).uniform(-1.5, 1.5, len(robot.joint_names))
    np.testing.assert_allclose(
        robot.frame_poses(q, "panda_link8"),
        _panda_fk_by_pinocchio(panda, robot.joint_names, q, "panda_link8"),
        atol=1e-12,
    )
    arm = load_robot(DECLARES.format(upper=0.5))
    np.testing.assert_allclose(_l2(arm), _l2(load_robot(EXPANDED.format(upper=0.5))), atol=0)
    commented = DECLARES.format(upper=0.5).replace("</robot>", "<!-- ${no} $(arg x) --></robot>")
    assert load_robot(commented).joint_names == NAMES


@pytest.mark.parametrize(
    "edit",
    [
        ('<link name="l2"/>', '<link name="l2"/><xacro:property name="a" value="1"/>'),
        ('xyz="0 0 0.1"', 'xyz="0 0 ${0.1}"'),
        ('xyz="0 0 0.1"', 'xyz="0 0 $(arg z)"'),
    ],
)
def test_a_xacro_element_or_substitution_still_needs_xacro(monkeypatch, edit):
    monkeypatch.setitem(sys.modules, "xacro", None)
    text = DECLARES.format(upper=0.5).replace(*edit)
    with pytest.raises(RobotModelError, match=r"^<urdf string>: a xacro file; .*kinfw\[ros\]"):
        load_robot(text)


def test_empty_stdin_for_a_urdf_says_so():
    """``kinfw reach -`` with nothing piped in said '.: cannot read URDF (Is a directory)'."""
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "kinfw.cli",
            "-q",
            "reach",
            "-",
            "--frame",
            "l2",
            "--point",
            "0.7",
            "0",
            "0.1",
        ],
        input="\n",
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2
    assert done.stderr == (
        "kinfw reach: error: -: stdin is empty; expected a URDF's XML text there (a "
        "robot_description), or give the URDF's file name instead of -\n"
    )
    with pytest.raises(RobotModelError, match=r"^an empty URDF argument: expected a file name"):
        load_robot(" ")
