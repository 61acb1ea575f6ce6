"""Adding a ``kinfw`` command: the extension recipe of docs/architecture.md, done here.

A command is a function that adds its sub-parser, whose defaults name the command
(``func``) and the check of its outputs (``check_outputs``); in the library it is one
module and one entry of :data:`kinfw.cli.COMMANDS`. Here the command lives in this file
and is passed to :func:`kinfw.cli.main` beside the built-in ones; the shared machinery
(outputs checked before any work, one-line errors, exit codes) must hold for it. The truth
is Pinocchio's forward kinematics of the built-in head.
"""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from kinfw.cli import COMMANDS, main
from kinfw.files import check_outputs, write_text_atomic
from tests.paths import HEAD_URDF

CALLS: list[str] = []


def add_distance_parser(sub) -> None:
    """``kinfw distance MODEL A B --out FILE``: the distance between two frames at q = 0."""
    p = sub.add_parser("distance", help="distance between two frames at the zero configuration")
    p.add_argument("model")
    p.add_argument("a")
    p.add_argument("b")
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_distance, check_outputs=check_distance_outputs)


def check_distance_outputs(args) -> None:
    check_outputs({"--out": args.out}, inputs={"model": args.model})


def cmd_distance(args) -> int:
    from kinfw.model import load_robot

    CALLS.append(args.model)
    robot = load_robot(args.model)
    q = np.zeros(len(robot.joint_names))
    d = robot.frame_poses(q, args.a)[:3, 3] - robot.frame_poses(q, args.b)[:3, 3]
    write_text_atomic(args.out, json.dumps({"distance_m": float(np.linalg.norm(d))}))
    return 0


def _pinocchio_distance(a: str, b: str) -> float:
    model = pin.buildModelFromUrdf(str(HEAD_URDF))
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    pa = data.oMf[model.getFrameId(a)].translation
    pb = data.oMf[model.getFrameId(b)].translation
    return float(np.linalg.norm(pa - pb))


def test_a_command_added_beside_the_built_ins_runs_and_writes(tmp_path, capsys):
    out = tmp_path / "d.json"
    commands = (*COMMANDS, add_distance_parser)
    assert main(["--help"], commands=commands) == 0
    assert "distance" in capsys.readouterr().out
    code = main(
        ["distance", str(HEAD_URDF), "left_camera", "right_camera", "--out", str(out)],
        commands=commands,
    )
    assert code == 0
    expected = _pinocchio_distance("left_camera", "right_camera")
    assert abs(json.loads(out.read_text())["distance_m"] - expected) < 1e-12


def test_its_outputs_are_checked_before_any_work(tmp_path, capsys):
    """Writing over its own input is refused with one line and exit code 2, and the
    command itself never runs."""
    model = tmp_path / "head.urdf"
    model.write_text(HEAD_URDF.read_text())
    CALLS.clear()
    code = main(
        ["distance", str(model), "left_camera", "right_camera", "--out", str(model)],
        commands=(*COMMANDS, add_distance_parser),
    )
    err = capsys.readouterr().err
    assert code == 2 and not CALLS
    assert err.startswith("kinfw distance: error:") and err.count("\n") == 1
    assert model.read_text() == HEAD_URDF.read_text()


def test_its_user_errors_are_one_line(tmp_path, capsys):
    code = main(
        # -q: no progress lines (loading the URDF), the error alone
        [
            "-q",
            "distance",
            str(HEAD_URDF),
            "left_camera",
            "nowhere",
            "--out",
            str(tmp_path / "d.json"),
        ],
        commands=(*COMMANDS, add_distance_parser),
    )
    err = capsys.readouterr().err
    assert code == 2 and "nowhere" in err and err.count("\n") == 1


# -- from outside the library: register_command (a plugin's way, kinfw.plugins) ----------
@pytest.fixture
def registered(monkeypatch):
    """The commands of register_command, empty for one test and restored after it."""
    monkeypatch.setattr("kinfw.cli._main._REGISTERED", [])


def add_calibrate_again_parser(sub) -> None:
    """A second ``calibrate``: its name is taken."""
    sub.add_parser("calibrate", help="not kinfw's calibrate").set_defaults(func=cmd_distance)


def test_a_registered_command_is_listed_and_runs_without_a_commands_argument(
    registered, tmp_path, capsys
):
    from kinfw.cli import register_command

    assert register_command(add_distance_parser) is add_distance_parser
    assert main(["--help"]) == 0
    listed = capsys.readouterr().out
    assert "distance between two frames" in listed
    assert listed.index("export") < listed.index("distance")  # after the built-in commands
    out = tmp_path / "d.json"
    assert main(["distance", str(HEAD_URDF), "left_camera", "right_camera", "--out", str(out)]) == 0
    expected = _pinocchio_distance("left_camera", "right_camera")
    assert abs(json.loads(out.read_text())["distance_m"] - expected) < 1e-12
    with pytest.raises(ValueError, match=r"add_distance_parser is already a command"):
        register_command(add_distance_parser)


def test_a_registered_command_whose_name_is_taken_is_warned_and_left_out(registered, capsys):
    from kinfw.cli import register_command

    register_command(add_calibrate_again_parser)
    assert main(["--help"]) == 0
    captured = capsys.readouterr()
    assert "not kinfw's calibrate" not in captured.out and "calibrate" in captured.out
    assert captured.err == (
        "kinfw: warning: command of tests.kinfw.cli.test_cli_command_plugin."
        "add_calibrate_again_parser not added: ValueError: the command name 'calibrate' is "
        "taken\n"
    )
