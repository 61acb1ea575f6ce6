"""``kinfw fleet``: each robot calibrated as ``kinfw calibrate`` calibrates it, a summary
of them all, and a robot whose data is bad failing alone."""

import json
import math
import re

import pytest

from tests.cli_run import run_cli
from tests.fleet_data import without_run_details, write_fleet


@pytest.fixture(scope="module")
def robots(tmp_path_factory):
    root = tmp_path_factory.mktemp("fleet") / "robots"
    write_fleet(root, 3, per_joint=4)
    return root


@pytest.mark.slow
def test_each_robot_gets_what_kinfw_calibrate_writes_and_the_summary_pools_its_rms(
    robots, tmp_path, capsys
):
    argv = ["fleet", robots, "--out", tmp_path / "fleet", "--params", "full"]
    code, out, _ = run_cli(argv, capsys)
    assert code == 0, out
    summary = json.loads((tmp_path / "fleet" / "summary.json").read_text())
    assert (summary["n_robots"], summary["n_failed"]) == (3, 0)
    for row in summary["robots"]:
        name = row["robot"]
        own = tmp_path / "own" / name
        own.mkdir(parents=True)
        argv = ["calibrate", robots / name / "data.json", "--urdf", robots / name / "robot.urdf"]
        argv += ["--out", own / "calibrated.urdf", "--report", own / "report.json"]
        assert run_cli([*argv, "--params", "full"], capsys)[0] == 0
        mine = tmp_path / "fleet" / name
        for file in ("calibrated.urdf",):
            assert (mine / file).read_bytes() == (own / file).read_bytes()
        for file in ("calibrated.kinfw.json", "report.json"):
            a, b = (json.loads((d / file).read_text()) for d in (mine, own))
            assert without_run_details(a) == without_run_details(b)
        report = json.loads((own / "report.json").read_text())
        assert row["status"] == "calibrated" and row["error"] is None
        assert row["n_samples"] == report["data"]["n_samples"] == 25
        assert row["model"]["parameters"] == ["full"] and row["model"]["reason"] == "given"
        assert (row["calibrated_urdf"], row["report"]) == (
            f"{name}/calibrated.urdf",
            f"{name}/report.json",
        )
        # per metric: the RMS over every observation of both plates, from the report's groups
        groups = report["errors_in_sample"]
        assert len(groups) == 2
        n = sum(g["n"] for g in groups)
        expected = {
            key: math.sqrt(sum(g["n"] * g[key] ** 2 for g in groups) / n)
            for key in (
                "before_position_rms_mm",
                "after_position_rms_mm",
                "before_rotation_rms_deg",
                "after_rotation_rms_deg",
            )
        }
        assert row["rms_in_sample"].keys() == expected.keys()
        for key, value in expected.items():
            assert row["rms_in_sample"][key] == pytest.approx(value, rel=1e-12)
        rms = row["rms_in_sample"]
        assert rms["after_position_rms_mm"] < 1.0 < 5.0 < rms["before_position_rms_mm"]
    # the printed table: a row per robot with its numbers, in the summary's order
    lines = out.splitlines()
    assert lines[0] == "calibrated 3 of 3 robots (RMS on each one's calibration data):"
    assert lines[1].split() == [
        "robot", "samples", "parameters",
        "before", "position", "RMS", "mm", "after", "position", "RMS", "mm",
        "before", "rotation", "RMS", "deg", "after", "rotation", "RMS", "deg", "status",
    ]  # fmt: skip
    for line, row in zip(lines[2:5], summary["robots"], strict=True):
        cells = line.split()
        assert cells[:3] == [row["robot"], "25", "full"] and cells[-1] == "ok"
        after_mm = row["rms_in_sample"]["after_position_rms_mm"]
        assert float(cells[4]) == pytest.approx(after_mm, abs=1e-3)


def test_a_robot_whose_data_is_bad_fails_alone_with_its_error(robots, tmp_path, capsys):
    bad = tmp_path / "robots"
    write_fleet(bad, 3, per_joint=4)
    (bad / "r01" / "data.json").write_text('{"format": "kinfw-measurements", "version": 1')
    doc = json.loads((bad / "r02" / "data.json").read_text())
    doc["joint_names"][0] = "no_such_joint"
    (bad / "r02" / "data.json").write_text(json.dumps(doc))
    code, out, _ = run_cli(["fleet", bad, "--out", tmp_path / "out", "--params", "full"], capsys)
    assert code == 3
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    status = {r["robot"]: (r["status"], r["error"]) for r in summary["robots"]}
    assert status["r00"] == ("calibrated", None)
    assert (
        status["r01"][0] == "failed"
        and "r01/data.json: invalid JSON at line 1" in (status["r01"][1])
    )
    assert status["r02"][0] == "failed" and "no_such_joint" in status["r02"][1]
    assert summary["n_failed"] == 2
    assert (tmp_path / "out" / "r00" / "calibrated.urdf").is_file()
    assert not (tmp_path / "out" / "r01").exists() and not (tmp_path / "out" / "r02").exists()
    assert "r01: failed: " in out and "r02: failed: " in out
    assert [line.split()[-1] for line in out.splitlines()[2:5]] == ["ok", "FAILED", "FAILED"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--out", "{tmp}/file"], r"--out .*/file: exists and is not a directory"),
        (["--out", "{tmp}/o", "--urdf", "{tmp}/none.urdf"], r"none.urdf: no such URDF file"),
        (["--out", "{tmp}/o", "--jobs", "2", "--executor", "dask://h:1"], "not allowed with"),
    ],
)
def test_bad_outputs_and_options_stop_before_any_work(robots, tmp_path, capsys, argv, message):
    (tmp_path / "file").write_text("")
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code, out, err = run_cli(["fleet", robots, *argv], capsys)
    assert code == 2 and out == ""
    assert err.startswith("kinfw fleet: error: ") and len(err.splitlines()) == 1
    assert re.search(message, err), err


@pytest.mark.slow
def test_each_robots_warnings_are_the_ones_kinfw_calibrate_prints(robots, tmp_path, capsys):
    understated = ["--params", "full", "--sigma-mm", "0.1", "--sigma-deg", "0.1"]
    code, out, err = run_cli(
        ["-q", "fleet", robots, "--out", tmp_path / "fleet", *understated], capsys
    )
    assert code == 0 and err == ""
    summary = json.loads((tmp_path / "fleet" / "summary.json").read_text())
    for row in summary["robots"]:
        name = row["robot"]
        argv = ["calibrate", robots / name / "data.json", "--urdf", robots / name / "robot.urdf"]
        code, _, err = run_cli([*argv, "--out", tmp_path / f"{name}.urdf", *understated], capsys)
        assert code == 0
        prefix = "kinfw calibrate: warning: "
        own = [line.removeprefix(prefix) for line in err.splitlines() if line.startswith(prefix)]
        assert row["warnings"] == own
        assert any("times the stated noise" in w for w in own)  # the noise is understated
        for warning in own:
            assert f"{name}: warning: {warning}" in out


def _with_sticker(robots, out, *, declared):
    """The fleet with each robot's left plate seen as 'left_sticker', a frame its URDF
    lacks, declared in the file's ``"mounts"`` (on 'left_plate') or not."""
    out.mkdir()
    for folder in sorted(robots.iterdir()):
        (out / folder.name).mkdir()
        (out / folder.name / "robot.urdf").write_bytes((folder / "robot.urdf").read_bytes())
        doc = json.loads((folder / "data.json").read_text())
        for sample in doc["samples"]:
            for obs in sample["observations"]:
                if obs["frame"] == "left_plate":
                    obs["frame"] = "left_sticker"
        if declared:
            doc["mounts"] = {"left_sticker": {"parent": "left_plate"}}
        (out / folder.name / "data.json").write_text(json.dumps(doc))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("declared", [True, False])
def test_a_frame_the_urdfs_lack_is_mounted_as_kinfw_calibrate_mounts_it(
    robots, tmp_path, capsys, declared
):
    """The files' "mounts" section, or --mount NAME:PARENT: each robot's calibrated URDF
    is kinfw calibrate's (the sticker a link on a fixed joint of the left plate, its
    origin calibrated); undeclared, every robot fails alone naming the frame."""
    stickers = _with_sticker(robots, tmp_path / "robots", declared=declared)
    code, out, _ = run_cli(["fleet", stickers, "--out", tmp_path / "fleet"], capsys)
    if not declared:
        assert code == 3 and out.count("left_sticker") >= 3, out
        code, out, _ = run_cli(
            ["fleet", stickers, "--out", tmp_path / "fleet", "--mount", "left_sticker:left_plate"],
            capsys,
        )
    assert code == 0, out
    mount = [] if declared else ["--mount", "left_sticker:left_plate"]
    for folder in sorted(stickers.iterdir()):
        own = tmp_path / "own" / folder.name
        own.mkdir(parents=True)
        argv = ["calibrate", folder / "data.json", "--urdf", folder / "robot.urdf"]
        assert run_cli([*argv, "--out", own / "c.urdf", *mount], capsys)[0] == 0
        fleet_urdf = (tmp_path / "fleet" / folder.name / "calibrated.urdf").read_text()
        assert fleet_urdf == (own / "c.urdf").read_text()
        assert re.search(r'<joint name="left_sticker_joint" type="fixed">', fleet_urdf)
        assert re.search(r'<parent link="left_plate"\s*/>', fleet_urdf)
