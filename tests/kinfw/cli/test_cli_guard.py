"""The plausibility guard on what ``kinfw calibrate`` and ``kinfw fleet`` write (issue 35):
a UR10 simulated with mocap markers and calibrated with the UR5's URDF (the same joint
names) is refused, naming the UR5 and the moves, before anything is written;
``--allow-large-changes`` writes it and the report and sidecar say so; the UR10's own
URDF on the same data passes. Simulated board images whose board is given 1.25 times
its size are refused under a 1 mm prior; the true size passes."""

import json
import shutil

import pytest

from kinfw.cli._main import main
from kinfw.records import read_report, read_sidecar
from tests.cli_run import run_cli, without_dirs
from tests.erd import urdf_path
from tests.paths import DATA, HEAD_URDF

UR5 = urdf_path("ur_description/urdf/ur5_robot.urdf")
UR10 = urdf_path("ur_description/urdf/ur10_robot.urdf")
#: UR10 - UR5 link lengths (upper arm, forearm: a2, a3 of their DH tables), m
A2, A3 = 0.612 - 0.425, 0.5723 - 0.39225


@pytest.fixture(scope="module")
def ur10_data(tmp_path_factory):
    out = tmp_path_factory.mktemp("guard")
    argv = ["-q", "simulate", "--urdf", UR10, "--markers", "tool0"]
    argv += ["--markers", "tool0:0,0.05,0.02", "--markers", "tool0:0.04,0,0.03"]
    argv += ["--mocap-frame", "vicon", "--mocap-samples", "40", "--noise-mm", "0.2"]
    argv += ["--out", out / "ur10.json", "--truth-out", out / "ur10_true.urdf"]
    assert main([str(a) for a in argv]) == 0
    return out / "ur10.json"


@pytest.mark.slow
def test_another_robots_urdf_is_refused_before_anything_is_written(ur10_data, tmp_path, capsys):
    out, report = tmp_path / "c.urdf", tmp_path / "r.json"
    argv = ["-q", "calibrate", ur10_data, "--urdf", UR5, "--out", out, "--report", report]
    code, _, err = run_cli(argv, capsys)
    assert code == 2
    lines = err.strip().splitlines()
    first = lines[0]
    assert first.startswith("kinfw calibrate: error: ") and len(without_dirs(first)) < 200
    assert "implausible calibration, not written" in first and "--allow-large-changes" in first
    assert 'the URDF (<robot name="ur5">) may be another robot\'s' in err
    # the moves named are the link lengths the UR10 has and the UR5 lacks, to 5 mm
    moves = {ln.split()[2]: float(ln.split()[4]) for ln in lines if ln.startswith("  joint ")}
    assert moves["elbow_joint"] == pytest.approx(1e3 * A2, abs=5.0)
    assert moves["wrist_1_joint"] == pytest.approx(1e3 * A3, abs=5.0)
    assert not out.exists() and not (tmp_path / "c.kinfw.json").exists() and not report.exists()


@pytest.mark.slow
def test_large_changes_allowed_are_written_and_said(ur10_data, tmp_path, capsys):
    out, report = tmp_path / "c.urdf", tmp_path / "r.json"
    argv = ["-q", "calibrate", ur10_data, "--urdf", UR5, "--out", out, "--report", report]
    code, _, err = run_cli([*argv, "--allow-large-changes"], capsys)
    assert code == 0
    assert "large changes allowed (--allow-large-changes): joint origin elbow_joint" in err
    side, rep = read_sidecar(tmp_path / "c.kinfw.json"), read_report(report)
    assert side.guard == rep.guard
    assert side.guard.allowed and side.guard.largest_ratio > 5.0
    assert side.guard.largest.startswith("joint origin elbow_joint moved")
    assert any(n.startswith("large changes allowed") for n in rep.notes)
    assert "not on the URDF's origins" in side.guard.prior_bounds or "no prior" in (
        side.guard.prior_bounds
    )


@pytest.mark.slow
def test_the_robots_own_urdf_passes_and_the_fleet_refuses_the_other_alone(
    ur10_data, tmp_path, capsys
):
    fleet = tmp_path / "robots"
    for name, urdf in (("right", UR10), ("wrong", UR5)):
        (fleet / name).mkdir(parents=True)
        shutil.copy(urdf, fleet / name / "robot.urdf")
        shutil.copy(ur10_data, fleet / name / "data.json")
    code, _, _ = run_cli(["-q", "fleet", fleet, "--out", tmp_path / "out"], capsys)
    assert code == 3  # a robot failed
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    rows = {r["robot"]: r for r in summary["robots"]}
    assert rows["right"]["status"] == "calibrated"
    assert "implausible calibration, not written" in rows["wrong"]["error"]
    assert "\n" not in rows["wrong"]["error"]  # the first line; calibrate gives the rest
    assert not (tmp_path / "out" / "wrong").exists()
    guard = read_sidecar(tmp_path / "out" / "right" / "calibrated.kinfw.json").guard
    assert not guard.allowed and guard.beyond == () and guard.largest_ratio < 1.0


def test_a_sidecar_and_report_written_before_the_guard_read_without_it():
    folder = DATA / "calibration_v1"
    assert read_sidecar(folder / "calibrated.kinfw.json").guard is None
    assert read_report(folder / "report.json").guard is None


@pytest.fixture(scope="module")
def board_images(tmp_path_factory):
    """Simulated images of a 40 mm chessboard seen by the head's left camera, and the same
    file with the board's points 50 mm apart (a board size given wrong)."""
    out = tmp_path_factory.mktemp("guard_board")
    argv = ["-q", "simulate", "--pixels", "--cameras", "left_camera", "--stage", "2"]
    argv += ["--stage2-samples", "20", "--board", "chessboard:9x6:0.04"]
    argv += ["--out", out / "px.json", "--truth-out", out / "px_true.urdf"]
    assert main([str(a) for a in argv]) == 0
    doc = json.loads((out / "px.json").read_text())
    for sample in doc["samples"]:
        for o in sample["observations"]:
            o["points"] = [[1.25 * c for c in p] for p in o["points"]]
    (out / "wrong.json").write_text(json.dumps(doc))
    return out / "px.json", out / "wrong.json"


@pytest.mark.slow
def test_a_wrong_board_size_under_a_1_mm_prior_is_refused(board_images, tmp_path, capsys):
    right, wrong = board_images
    options = ["--params", "full", "--prior-mm", "1", "--prior-deg", "0.573"]
    argv = ["-q", "calibrate", "--urdf", HEAD_URDF, *options, "--report", tmp_path / "r.json"]
    code, _, _ = run_cli([*argv, right, "--out", tmp_path / "right.urdf"], capsys)
    assert code == 0
    guard = read_report(tmp_path / "r.json").guard
    assert guard.largest_ratio < 1.0 and guard.beyond == ()
    # the prior is on the CPC parameters; the bound is 5 x its 1 mm or the 20 mm floor
    assert guard.bound_m == pytest.approx(0.020)
    assert guard.prior_bounds.startswith("the prior (1 mm / 0.573 deg) is on the CPC")
    code, _, err = run_cli([*argv, wrong, "--out", tmp_path / "wrong.urdf"], capsys)
    assert code == 2
    first = next(line for line in err.splitlines() if ": error: " in line)
    assert "implausible calibration, not written" in first and len(without_dirs(first)) < 200
    assert "1. the target's geometry or the board's size is wrong" in err
    assert not (tmp_path / "wrong.urdf").exists()


@pytest.mark.slow
def test_crossval_leaves_a_default_that_calibrate_would_refuse_unscored(ur10_data, capsys):
    code, out, _ = run_cli(["-q", "crossval", ur10_data, "--urdf", UR5, "--k", "2"], capsys)
    assert code == 0
    header = next(line for line in out.splitlines() if line.startswith("fold"))
    assert "default" not in header and "full" in header
    assert (
        "warning: --params auto not scored: refused on the training samples of fold 0: "
        "implausible calibration: joint origin elbow_joint moved"
    ) in out
