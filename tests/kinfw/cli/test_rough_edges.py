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

import hashlib
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
from kinfw.identification import identify, refine
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
    first, *details = err.split("error: ", 1)[1].splitlines()
    assert first == (
        f"{wrong}: the orientations look like quaternions stored scalar first (w, x, y, z), "
        "kinfw reads them scalar last (quat_xyzw): reorder them in the file"
    )  # the evidence after it, each on its own indented line (it was one 2,007-character line)
    assert details[0].startswith("  read in that order, the data fit (median residual 0.")
    assert details[1].startswith("  as written: ")
    assert all(line.startswith("  ") for line in details)
    assert not (tmp_path / "c.urdf").exists()


def test_a_path_where_data_is_expected_is_a_type_error_naming_the_argument():
    robot = load_robot(HEAD)
    with pytest.raises(TypeError, match=r"^data: expected Measurements, got str 'f\.json'"):
        identify(robot, "f.json")
    with pytest.raises(TypeError, match=r"^measurements: expected Measurements"):
        refine(robot, "f.json")
    with pytest.raises(TypeError, match=r"^nominal: expected a Robot, got PosixPath"):
        identify(HEAD, "f.json")


def test_an_output_in_a_missing_directory_names_the_users_path(tmp_path):
    target = tmp_path / "missing" / "scene.html"
    with pytest.raises(FileNotFoundError) as failed:
        write_text_atomic(target, "<html/>")
    assert failed.value.filename == str(target)
    assert ".tmp" not in str(failed.value)


@pytest.mark.parametrize(
    ("plot", "what"),
    [("p.xyz", "matplotlib cannot write a .xyz figure"), ("p", "no suffix names a format")],
)
def test_a_plot_matplotlib_cannot_write_is_refused_before_anything_is_written(
    plot, what, tmp_path, capsys
):
    """``plan --plot p.xyz`` wrote the plan, then failed in matplotlib's savefig."""
    from matplotlib.backend_bases import FigureCanvasBase

    argv = ["-q", "plan", "--urdf", HEAD, "--n", "5", "--out", tmp_path / "p.json"]
    code, _out, err = run_cli([*argv, "--plot", tmp_path / plot], capsys)
    assert code == 2
    message = err.split("error: ", 1)[1].strip()
    assert message.startswith(f"--plot {tmp_path / plot}: {what}; give a suffix matplotlib")
    assert all(f".{f}" in message for f in FigureCanvasBase.get_supported_filetypes())
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    code, _out, err = run_cli([*argv, "--plot", tmp_path / "p.SVG"], capsys)
    assert code == 0, err
    assert (tmp_path / "p.SVG").read_text().lstrip().startswith("<?xml")


def test_verify_refuses_the_sidecar_of_another_calibration(poses, plates, tmp_path, capsys):
    """Two calibrations of the head (on the plates and cameras, on the plates alone):
    the first one's sidecar with the second one's URDF is refused, naming both files
    and their SHA-256s (it said "using the calibration sidecar ...", then refitted)."""
    for name, data in (("a", poses), ("b", plates)):
        (tmp_path / name).mkdir()
        argv = ["-q", "calibrate", data, "--urdf", HEAD, "--out", tmp_path / name / "c.urdf"]
        code, _out, err = run_cli([*argv, "--params", "full"], capsys)
        assert code == 0, err
    mine, foreign = tmp_path / "b" / "c.urdf", tmp_path / "a" / "c.kinfw.json"
    sha = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in (mine, tmp_path / "a/c.urdf")}
    assert json.loads(foreign.read_text())["calibrated_urdf_sha256"] == sha[tmp_path / "a/c.urdf"]
    code, out, err = run_cli(["-q", "verify", mine, poses, "--sidecar", foreign], capsys)
    assert code == 2 and out == ""
    first, *details = err.split("error: ", 1)[1].strip().splitlines()
    assert first.startswith(f"{foreign}: the calibration of another URDF, not {mine}")
    assert len(first.replace(str(foreign), "S").replace(str(mine), "U")) < 160
    assert f"  {mine}: sha256 {sha[mine]}" in details
    assert any(
        line.startswith("  calibrated URDF c.urdf") and sha[tmp_path / "a/c.urdf"] in line
        for line in details
    )
    nominal = hashlib.sha256(Path(HEAD).read_bytes()).hexdigest()
    assert any(str(HEAD) in line and nominal in line for line in details)
    for urdf in (tmp_path / "a" / "c.urdf", HEAD):  # its own calibrated URDF, its nominal
        code, out, err = run_cli(["-q", "verify", urdf, poses, "--sidecar", foreign], capsys)
        assert code == 0, err
        assert f"using the calibration sidecar {foreign}" in out


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda s: s["q"].__setitem__(0, 1e300), "samples[3].q[0]"),
        (
            lambda s: s["observations"][0]["xyz"].__setitem__(1, -1e300),
            "samples[3].observations[0].xyz[1]",
        ),
    ],
)
def test_a_number_of_1e300_is_named_where_it_is_read(edit, key, poses, tmp_path, capsys):
    """It overflowed numpy (warnings) and was blamed on joint 'x_table''s unit."""
    doc = json.loads(poses.read_text())
    edit(doc["samples"][3])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    code, _out, err = run_cli(
        ["-q", "calibrate", bad, "--urdf", HEAD, "--out", tmp_path / "c.urdf"], capsys
    )
    assert code == 2
    assert err.startswith(f"kinfw calibrate: error: {bad}: {key}: ")
    assert "e+300 is no measurement (its magnitude is above 1e+09" in err
    assert len(err.splitlines()) == 1, err  # no numpy warning, no unit blamed
