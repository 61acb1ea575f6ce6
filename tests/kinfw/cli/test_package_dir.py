"""``--package-dir`` on every command that loads meshes, and a collision check that
refuses rather than skips.

A copy of example-robot-data's UR5 URDF outside its package tree names its meshes
``package://example-robot-data/...``: they resolve only under the directory that holds
``example-robot-data`` (the ``share`` directory), given with ``--package-dir``.
"""

from __future__ import annotations

import shutil

import pytest

from kinfw.model import load_robot, resolve_meshes
from tests.cli_run import run_cli
from tests.erd import robots_dir, urdf_path

UR5 = "ur_description/urdf/ur5_robot.urdf"


@pytest.fixture(scope="module")
def ur5(tmp_path_factory):
    """The UR5 URDF copied out of its package tree, and the package directory."""
    copy = tmp_path_factory.mktemp("ur5") / "ur5.urdf"
    shutil.copy(urdf_path(UR5), copy)
    return copy, robots_dir().parents[1]


def test_meshes_resolve_only_under_the_package_directory(ur5):
    """Truth: the files the URDF names exist under share/ (7 collision meshes, 7 visual)."""
    copy, share = ur5
    robot = load_robot(copy)
    for element in ("visual", "collision"):
        _, missing = resolve_meshes(robot, (), element)
        assert len(missing) == 7 and all(m.filename.startswith("package://") for m in missing)
        xml, missing = resolve_meshes(robot, (share,), element)
        assert missing == () and str(share) in xml


def test_plan_collisions_refuses_missing_meshes_and_runs_with_package_dir(ur5, capsys):
    copy, share = ur5
    argv = ["-q", "plan", "--urdf", copy, "--frames", "tool0", "--n", "8", "--candidates", "60"]
    argv += ["--test", "30", "--collisions"]
    code, out, err = run_cli(argv, capsys)
    assert code == 2 and out == ""
    assert "7 collision mesh(es) not found" in err and "give --package-dir DIR" in err
    code, out, err = run_cli([*argv, "--package-dir", share], capsys)
    assert code == 0, err


def test_plan_collisions_refuses_a_urdf_without_collision_geometry(capsys):
    code, _, err = run_cli(["-q", "plan", "--n", "4", "--candidates", "40", "--collisions"], capsys)
    assert code == 2 and "no <collision> geometry" in err


@pytest.mark.slow
@pytest.mark.parametrize("command", ["reach", "gaze"])
def test_scenes_draw_the_meshes_found_under_package_dir(ur5, tmp_path, command, capsys):
    """Without --package-dir the 7 missing visuals are one warning and the arm is drawn
    as a skeleton; with it the meshes are drawn and nothing is warned."""
    copy, share = ur5
    if command == "reach":
        argv = ["reach", copy, "--frame", "tool0", "--point", "0.3", "0.2", "0.4"]
    else:
        argv = ["gaze", copy, "--cameras", "tool0", "--point", "0.6", "0.2", "0.4"]
    argv += ["--html", tmp_path / "scene.html"]
    _, _, err = run_cli(argv, capsys)
    warned = [line for line in err.splitlines() if "not found under" in line]
    assert len(warned) == 1 and "7 visual mesh(es) not found under package://" in warned[0]
    assert "drawn as a skeleton; give --package-dir DIR" in warned[0]
    small = (tmp_path / "scene.html").stat().st_size
    _, _, err = run_cli([*argv, "--package-dir", share], capsys)
    assert "not found under" not in err
    assert (tmp_path / "scene.html").stat().st_size > small  # the meshes are in it
