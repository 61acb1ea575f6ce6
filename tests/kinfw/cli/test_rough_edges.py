"""Rough edges a new user meets (issue 25): each case is checked by its exit code and
what is printed, against what a shell user expects.

- Ctrl-C: one line, exit 130 (128 + SIGINT), no output file, no temporary left;
- a reader that leaves (``| head``): no message, exit 141 (128 + SIGPIPE);
- held-out data repeating the calibration data: a warning;
- quaternions stored scalar first: the refusal says so first;
- a path where data is expected: a TypeError naming the argument;
- an output in a missing directory: the error names the user's path.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from kinfw import builtin_head_urdf
from kinfw.files import write_text_atomic
from kinfw.identification import calibrate, refine
from kinfw.measurements import read_measurements
from kinfw.model import load_robot
from tests.cli_run import run_cli

HEAD = builtin_head_urdf()
KINFW = [sys.executable, "-m", "kinfw.cli"]


def _simulated(out, samples: int):
    """Simulated plate and camera poses of the IIS head (0.5 mm, 0.5 deg noise): stage 1
    and ``samples`` stage-2 configurations (none: the plates only)."""
    argv = [*KINFW, "-q", "simulate", "--out", out / "d.json", "--truth-out", out / "t.urdf"]
    if samples:
        argv += ["--stage", "both", "--stage2-samples", str(samples)]
    assert subprocess.run(argv, capture_output=True).returncode == 0
    return out / "d.json"


@pytest.fixture(scope="module")
def poses(tmp_path_factory) -> Path:
    """A small set: calibrated in about a second."""
    return _simulated(tmp_path_factory.mktemp("rough"), 40)


@pytest.fixture(scope="module")
def plates(tmp_path_factory) -> Path:
    """Stage 1 only: the two plates' poses, one joint at a time."""
    return _simulated(tmp_path_factory.mktemp("rough_plates"), 0)


@pytest.fixture(scope="module")
def long_poses(tmp_path_factory) -> Path:
    """A set whose calibration takes seconds: long enough to interrupt."""
    return _simulated(tmp_path_factory.mktemp("rough_long"), 1000)


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.slow
def test_ctrl_c_prints_one_line_exits_130_and_writes_nothing(long_poses, tmp_path):
    out = tmp_path / "c.urdf"
    proc = subprocess.Popen(
        [
            *KINFW,
            "calibrate",
            long_poses,
            "--urdf",
            HEAD,
            "--out",
            out,
            "--report",
            tmp_path / "r.json",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # as a terminal's Ctrl-C finds it: a runner started in the background (a shell's
        # `&` without job control) passes SIGINT on ignored, and Python then keeps it so
        preexec_fn=_default_sigint,
    )
    # the progress lines (piped: plain lines) say when the work has begun
    seen = [proc.stderr.readline() for _ in range(3)]
    assert all(line.strip() for line in seen), seen
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "kinfw calibrate: interrupted"
    assert "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no output, no temporary


@pytest.mark.slow
def test_a_closed_pipe_exits_quietly_with_141():
    """``kinfw reach --json | head`` when the reader has left before the output: the
    write fails with EPIPE."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    argv = [*KINFW, "-q", "reach", HEAD, "--frame", "left_plate", "--point", "0.3", "0.1", "0.4"]
    proc = subprocess.run([*argv, "--json"], stdout=write_end, stderr=subprocess.PIPE)
    os.close(write_end)
    assert proc.returncode == 141 and proc.stderr == b"", proc.stderr


@pytest.mark.slow
def test_held_out_data_equal_to_the_training_data_is_warned_about(poses, tmp_path, capsys):
    code, _out, err = run_cli(
        [
            "-q",
            "calibrate",
            poses,
            "--urdf",
            HEAD,
            "--out",
            tmp_path / "c.urdf",
            "--params",
            "full",
            "--holdout",
            poses,
        ],
        capsys,
    )
    assert code == 0, err
    assert "every held-out sample has the joint values of a calibration sample" in err


def _scalar_first(path: Path, to: Path) -> Path:
    """The file with every quaternion written (w, x, y, z) in the quat_xyzw fields."""

    def walk(o):
        if isinstance(o, dict):
            return {
                k: [v[3], *v[:3]] if k == "quat_xyzw" and len(v) == 4 else walk(v)
                for k, v in o.items()
            }
        return [walk(v) for v in o] if isinstance(o, list) else o

    to.write_text(json.dumps(walk(json.loads(path.read_text()))))
    return to


@pytest.mark.slow
@pytest.mark.parametrize("data", ["poses", "plates"])
def test_quaternions_stored_scalar_first_are_named_first(data, request, tmp_path, capsys):
    """Read as written, the data cannot fit the head (tens of mm; with the plates only,
    the geometry absorbs most of it and the fit passes its checks, but its rotation
    residuals follow the motion); reordered they fit to the simulated noise, without a
    warning: the refusal's first sentence says which order."""
    poses = request.getfixturevalue(data)
    wrong = _scalar_first(poses, tmp_path / "wxyz.json")
    reordered = read_measurements(wrong).with_quaternions_reordered()
    expected = read_measurements(poses)
    for a, b in zip(reordered.all_groups(), expected.all_groups(), strict=True):
        T_a = getattr(a, "meas_T_frame", getattr(a, "camera_T_target", None))
        T_b = getattr(b, "meas_T_frame", getattr(b, "camera_T_target", None))
        np.testing.assert_allclose(T_a, T_b, atol=1e-12)
    code, _out, err = run_cli(
        ["-q", "calibrate", wrong, "--urdf", HEAD, "--out", tmp_path / "c.urdf"], capsys
    )
    assert code == 2
    message = err.split("error: ", 1)[1]
    assert message.startswith(
        f"{wrong}: the orientations look like quaternions stored scalar first (w, x, y, z)"
    ), message[:300]
    assert not (tmp_path / "c.urdf").exists()


def test_a_path_where_data_is_expected_is_a_type_error_naming_the_argument():
    robot = load_robot(HEAD)
    with pytest.raises(TypeError, match=r"^data: expected Measurements, got str 'f\.json'"):
        calibrate(robot, "f.json")
    with pytest.raises(TypeError, match=r"^measurements: expected Measurements"):
        refine(robot, "f.json")
    with pytest.raises(TypeError, match=r"^nominal: expected a Robot, got PosixPath"):
        calibrate(HEAD, "f.json")


def test_an_output_in_a_missing_directory_names_the_users_path(tmp_path):
    target = tmp_path / "missing" / "scene.html"
    with pytest.raises(FileNotFoundError) as failed:
        write_text_atomic(target, "<html/>")
    assert failed.value.filename == str(target)
    assert ".tmp" not in str(failed.value)
