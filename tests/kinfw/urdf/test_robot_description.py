"""``kinfw export robot-description``: the calibrated URDF read back from the parameter file
(PyYAML) and from the launch file (parsed by ``ast``, then run with stand-ins for ROS 2's
``launch`` and ``launch_ros``) is the URDF text, and its Pinocchio forward kinematics is
the calibrated URDF's."""

from __future__ import annotations

import ast
import runpy
import sys
import types

import numpy as np
import yaml

from kinfw.cli._main import main
from kinfw.model import load_robot
from kinfw.urdf import ROBOT_DESCRIPTION_FILES
from tests.robots import ARM_6R

NAMES = ("j1", "j2", "j3", "j4", "j5", "j6")


def _launch_parameters(path, monkeypatch):
    """The ``parameters`` of the launch file's one Node, by running its
    ``generate_launch_description`` with stand-ins for ``launch`` and ``launch_ros``."""
    nodes = []
    launch = types.ModuleType("launch")
    launch.LaunchDescription = list
    launch_ros = types.ModuleType("launch_ros")
    actions = types.ModuleType("launch_ros.actions")
    actions.Node = lambda **kwargs: nodes.append(kwargs) or kwargs
    launch_ros.actions = actions
    for name, module in (("launch", launch), ("launch_ros", launch_ros)):
        monkeypatch.setitem(sys.modules, name, module)
    monkeypatch.setitem(sys.modules, "launch_ros.actions", actions)
    description = runpy.run_path(str(path))["generate_launch_description"]()
    assert len(description) == 1 and len(nodes) == 1
    node = nodes[0]
    assert (node["package"], node["executable"]) == ("robot_state_publisher",) * 2
    return node["parameters"]


def test_robot_description_read_back_gives_the_same_fk(tmp_path, capsys, monkeypatch):
    urdf = tmp_path / "cal.urdf"
    urdf.write_text(ARM_6R)
    out = tmp_path / "ros"
    assert main(["export", "robot-description", str(urdf), "--out", str(out)]) == 0
    assert capsys.readouterr().out.count("kinfw export: wrote") == 3

    params = yaml.safe_load((out / ROBOT_DESCRIPTION_FILES["params"]).read_text())
    from_params = params["robot_state_publisher"]["ros__parameters"]["robot_description"]
    launch = out / ROBOT_DESCRIPTION_FILES["launch"]
    ast.parse(launch.read_text())  # valid Python
    from_launch = _launch_parameters(launch, monkeypatch)[0]["robot_description"]
    assert from_params == from_launch == ARM_6R

    qs = np.random.default_rng(0).uniform(-np.pi, np.pi, (20, 6))
    truth = load_robot(urdf).frame_poses(qs, "flange", NAMES)
    for text in (from_params, from_launch):
        np.testing.assert_array_equal(load_robot(text).frame_poses(qs, "flange", NAMES), truth)


def test_robot_description_refuses_a_file_as_directory_and_overwriting_its_input(tmp_path, capsys):
    urdf = tmp_path / "cal.urdf"
    urdf.write_text(ARM_6R)
    code = main(["export", "robot-description", str(urdf), "--out", str(urdf)])
    assert code == 2
    assert f"--out {urdf}: exists and is not a directory" in capsys.readouterr().err
    inside = tmp_path / ROBOT_DESCRIPTION_FILES["urdf"]
    inside.write_text(ARM_6R)
    assert main(["export", "robot-description", str(inside), "--out", str(tmp_path)]) == 2
    assert "refusing to overwrite an input" in capsys.readouterr().err
