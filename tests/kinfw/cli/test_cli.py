"""The kinfw command line: simulate -> verify round trip, and user errors (exit 2)."""

import json
import math
import re
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest

from kinfw.cli._main import main
from kinfw.identification.checks import ChangeBound
from kinfw.measurements import read_measurements
from tests.paths import HEAD_URDF
from tests.robots import ARM_6R

HEAD = HEAD_URDF
#: The plausibility guard's bound for the demo's true head, 5 mm / 1 deg off per axis
_DEMO = ChangeBound.for_known_error(5e-3, math.radians(1.0))
DEMO_BOUND_ARGS = ("--max-change-mm", str(1e3 * _DEMO.max_m))
DEMO_BOUND_ARGS += ("--max-change-deg", str(math.degrees(_DEMO.max_rad)))


def _run(argv, capsys):
    """Exit code, stdout and stderr of ``kinfw -q ARGV`` (-q: no progress lines, so
    stderr holds only what the command says: its warnings and errors)."""
    code = main(["-q", *(str(a) for a in argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def noise_free(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    code = main(
        [
            "simulate",
            "--urdf",
            str(HEAD),
            "--out",
            str(d / "data.json"),
            "--truth-out",
            str(d / "true.urdf"),
            "--noise-mm",
            "0",
            "--noise-deg",
            "0",
            "--stage",
            "both",
            "--seed",
            "3",
        ]
    )
    assert code == 0
    return d


def test_simulate_without_noise_writes_pinocchio_fk_of_the_written_truth(noise_free):
    data = read_measurements(noise_free / "data.json")
    model = pin.buildModelFromXML((noise_free / "true.urdf").read_text())
    pdata = model.createData()
    assert {g.frame for g in data.poses} == {"left_plate", "right_plate"}
    assert {g.camera for g in data.targets} == {"left_camera", "right_camera"}
    checked = 0
    for k, q_urdf in enumerate(data.qs):
        q = pin.neutral(model)
        for name, value in zip(data.joint_names, q_urdf, strict=True):
            q[model.joints[model.getJointId(name)].idx_q] = value
        pin.framesForwardKinematics(model, pdata, q)
        for g in data.poses:
            rows = np.flatnonzero(g.sample == k)
            for r in rows:
                expected = pdata.oMf[model.getFrameId(g.frame)].homogeneous
                np.testing.assert_allclose(g.meas_T_frame[r], expected, atol=1e-12)
                checked += 1
    assert checked == 2 * (6 * 9 + 1)


def test_verify_of_the_truth_reports_zero(noise_free, capsys):
    code, out, _ = _run(
        ["verify", noise_free / "true.urdf", noise_free / "data.json", "--json"], capsys
    )
    assert code == 0
    report = json.loads(out)
    assert len(report["groups"]) == 4
    for g in report["groups"]:
        assert g["position_max_mm"] < 1e-9
        assert g["rotation_max_deg"] < 1e-9
    assert any("target" in f for f in report["fitted"])


def test_verify_of_the_nominal_shows_the_simulated_errors(noise_free, capsys):
    code, out, _ = _run(["verify", HEAD, noise_free / "data.json", "--json"], capsys)
    assert code == 0
    plates = [g for g in json.loads(out)["groups"] if g["kind"] == "pose"]
    # 2 mm / 0.5 deg errors on ~11 joints over ~0.5 m lever arms: several mm, not metres
    for g in plates:
        assert 1.0 < g["position_rms_mm"] < 100.0


def test_verify_prints_a_table_in_mm_and_degrees(noise_free, capsys):
    code, out, _ = _run(["verify", noise_free / "true.urdf", noise_free / "data.json"], capsys)
    assert code == 0
    assert "position RMS mm" in out and "rotation RMS deg" in out and "left_plate" in out


def test_crosscheck_of_the_head_passes(capsys):
    code, out, _ = _run(["crosscheck", HEAD, "-n", "50"], capsys)
    assert code == 0
    assert "passed" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["verify", "missing.urdf", "x.json"], r"missing\.urdf: cannot read URDF"),
        (["verify", HEAD, "missing.json"], r"missing\.json"),
        (
            ["simulate", "--urdf", "ARM", "--out", "d.json", "--truth-out", "t.urdf"],
            r"give --frames",
        ),
        (
            [
                "simulate",
                "--urdf",
                "ARM",
                "--out",
                "d.json",
                "--truth-out",
                "t.urdf",
                "--frames",
                "flang",
            ],
            r"no frame 'flang'",
        ),
        (["crosscheck", HEAD, "--frames", "left_plate,nose"], r"no frame 'nose'"),
    ],
)
def test_bad_input_exits_2_with_one_line(argv, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "ARM").write_text(ARM_6R, encoding="utf-8")
    code, _, err = _run(argv, capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert err.startswith("kinfw ")
    assert re.search(message, err), err


def test_bad_measurement_file_names_sample_and_key(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text(
        json.dumps(
            {
                "format": "kinfw-measurements",
                "version": 1,
                "units": {"length": "m", "angle": "rad"},
                "joint_names": ["pan"],
                "samples": [
                    {
                        "q": [0.1],
                        "observations": [
                            {
                                "frame": "left_plate",
                                "kind": "pose",
                                "xyz": [0, 0, 1],
                                "quat_xyzw": [0, 0, 0, 2],
                            }
                        ],
                    }
                ],
            }
        ),
        encoding="utf-8",
    )
    code, _, err = _run(["verify", HEAD, bad], capsys)
    assert code == 2
    assert "samples[0].observations[0].quat_xyzw" in err


def test_installed_entry_point_runs():
    result = subprocess.run(
        [sys.executable, "-m", "kinfw.cli", "--help"], capture_output=True, text=True, check=False
    )
    assert result.returncode == 0
    assert "simulate" in result.stdout and "verify" in result.stdout


def test_calibrate_noise_free_recovers_the_truth_far_from_the_nominal(tmp_path, capsys):
    code, _, _ = _run(
        [
            "simulate",
            "--out",
            tmp_path / "d.json",
            "--truth-out",
            tmp_path / "t.urdf",
            "--noise-mm",
            "0",
            "--noise-deg",
            "0",
            "--error-mm",
            "20",
            "--error-deg",
            "3",
            "--seed",
            "4",
        ],
        capsys,
    )
    assert code == 0
    bound = ChangeBound.for_known_error(20e-3, math.radians(3.0))  # the truth's error
    code, out, _ = _run(
        [
            "calibrate",
            tmp_path / "d.json",
            "--urdf",
            HEAD,
            "--out",
            tmp_path / "cal.urdf",
            "--report",
            tmp_path / "r.json",
            "--max-change-mm",
            1e3 * bound.max_m,
            "--max-change-deg",
            math.degrees(bound.max_rad),
        ],
        capsys,
    )
    assert code == 0, out
    truth = pin.buildModelFromXML((tmp_path / "t.urdf").read_text())
    cal = pin.buildModelFromXML((tmp_path / "cal.urdf").read_text())
    rng = np.random.default_rng(0)
    worst, nominal_err = 0.0, 0.0
    nominal = pin.buildModelFromUrdf(str(HEAD))
    for _ in range(100):
        q = pin.neutral(truth)
        for name in ("x_table", "y_table", "pan", "tilt", "vergence_left", "vergence_right"):
            j = truth.joints[truth.getJointId(name)]
            q[j.idx_q] = rng.uniform(
                truth.lowerPositionLimit[j.idx_q], truth.upperPositionLimit[j.idx_q]
            )
        poses = []
        for model in (truth, cal, nominal):
            data = model.createData()
            pin.framesForwardKinematics(model, data, q)
            poses.append(data.oMf[model.getFrameId("right_plate")])
        worst = max(worst, np.linalg.norm(pin.log6(poses[0].inverse() * poses[1]).vector))
        nominal_err = max(nominal_err, np.linalg.norm(poses[0].translation - poses[2].translation))
    assert worst < 1e-9  # 1e-6 mm and 1e-9 rad
    assert nominal_err > 0.02  # the nominal was centimetres off
    report = json.loads((tmp_path / "r.json").read_text())
    for row in report["errors_in_sample"]:
        assert row["before_position_rms_mm"] > 10.0
        assert row["after_position_rms_mm"] < 1e-6
    assert report["kinematics"]["parameters"]["n_identifiable"] == 32
    assert len(report["data"]["sha256"]) == 64


@pytest.mark.slow
def test_random_configurations_need_the_refinement(tmp_path, capsys):
    code, _, _ = _run(["demo", "--out", tmp_path, "--json"], capsys)
    assert code == 0
    # the demo's held-out data: plate poses and targets at random configurations
    code, _, err = _run(
        [
            "calibrate",
            tmp_path / "held_out.json",
            "--urdf",
            HEAD,
            "--out",
            tmp_path / "cal.urdf",
            "--method",
            "closed-form",
        ],
        capsys,
    )
    assert code == 2
    assert "differs from the common configuration q0 in joints" in err
    assert not (tmp_path / "cal.urdf").exists()
    code, out, _ = _run(
        [
            "calibrate",
            tmp_path / "held_out.json",
            "--urdf",
            HEAD,
            "--out",
            tmp_path / "cal.urdf",
            "--json",
            *DEMO_BOUND_ARGS,
        ],
        capsys,
    )
    assert code == 0
    report = json.loads(out)
    assert report["notes"][0].startswith("closed form skipped")
    truth = report["position_rms_mm_by_stage"]
    assert list(truth) == ["nominal", "hand-eye", "refine"]
    for group, rms in truth["refine"].items():
        assert rms < truth["nominal"][group] / 10


@pytest.mark.slow
def test_calibrate_target_only_data_on_trusted_kinematics(tmp_path, capsys):
    code, _, _ = _run(
        [
            "simulate",
            "--out",
            tmp_path / "d.json",
            "--truth-out",
            tmp_path / "t.urdf",
            "--stage",
            "2",
            "--error-mm",
            "0",
            "--error-deg",
            "0",
            "--noise-mm",
            "0",
            "--noise-deg",
            "0",
        ],
        capsys,
    )
    assert code == 0
    code, out, _ = _run(
        [
            "calibrate",
            tmp_path / "d.json",
            "--urdf",
            HEAD,
            "--out",
            tmp_path / "cal.urdf",
            "--json",
        ],
        capsys,
    )
    assert code == 0
    report = json.loads(out)
    assert "kinematics" not in report
    assert {c["camera"] for c in report["hand_eye"]["cameras"]} == {"left_camera", "right_camera"}
    for row in report["errors_in_sample"]:
        assert row["after_position_rms_mm"] < 1e-6


@pytest.mark.slow
def test_demo_calibrates_the_head_below_a_millimetre_held_out(tmp_path, capsys):
    code, out, _ = _run(["demo", "--out", tmp_path / "demo", "--json"], capsys)
    assert code == 0
    report = json.loads(out)
    for row in report["errors_vs_truth_held_out"]:
        assert row["before_position_rms_mm"] > 5.0
        if "(pose)" in row["group"]:  # plates: the paper's sub-millimetre result
            assert row["after_position_rms_mm"] < 1.0
        else:  # camera_T_target of a target ~0.8 m away: 0.2 deg is ~3 mm there
            assert row["after_position_rms_mm"] < row["before_position_rms_mm"] / 3
            assert row["after_rotation_rms_deg"] < 0.3
    for name in (
        "calibrated.urdf",
        "calibrated.kinfw.json",
        "report.json",
        "data.json",
        "held_out.json",
        "true.urdf",
        "errors.png",
        "scene.html",
    ):
        assert (tmp_path / "demo" / name).is_file()


@pytest.mark.slow
def test_reproduce_table4_writes_png_and_json(tmp_path, capsys):
    code, out, _ = _run(["reproduce", "table4", "--out", tmp_path, "--trials", "2"], capsys)
    assert code == 0
    assert (tmp_path / "table4.png").stat().st_size > 10_000
    assert json.loads((tmp_path / "table4.json").read_text())
    assert "0.65" in out  # the paper's left-branch mu_x printed beside ours


@pytest.mark.slow
def test_reproduce_hirsh_writes_png_and_json(tmp_path, capsys):
    code, out, _ = _run(["reproduce", "hirsh", "--out", tmp_path, "--trials", "2"], capsys)
    assert code == 0
    assert (tmp_path / "hirsh_fig3_fig4.png").stat().st_size > 10_000
    assert json.loads((tmp_path / "hirsh.json").read_text())
    assert "below the line" in out


@pytest.mark.parametrize("command", ["simulate", "reproduce"])
def test_json_output_is_valid_json(command, tmp_path, capsys):
    argv = {
        "simulate": [
            "simulate",
            "--out",
            tmp_path / "d.json",
            "--truth-out",
            tmp_path / "t.urdf",
            "--json",
        ],
        "reproduce": ["reproduce", "table4", "--out", tmp_path, "--trials", "1", "--json"],
    }[command]
    code, out, _ = _run(argv, capsys)
    assert code == 0
    assert isinstance(json.loads(out), dict)


@pytest.mark.slow
def test_view_writes_a_self_contained_html(tmp_path, capsys):
    code, _, _ = _run(["demo", "--out", tmp_path, "--json"], capsys)
    assert code == 0
    code, out, _ = _run(
        [
            "view",
            HEAD,
            "--calibrated",
            tmp_path / "calibrated.urdf",
            "--data",
            tmp_path / "data.json",
            "--sample",
            "60",
            "--html",
            tmp_path / "v.html",
        ],
        capsys,
    )
    assert code == 0, out
    html = (tmp_path / "v.html").read_text(encoding="utf-8")
    assert "no network needed" in out
    assert "https://" not in html
    assert len(html) > 900_000  # the viewer (~0.85 MB) plus both robots' geometry


@pytest.mark.slow
def test_verify_uses_the_sidecar_and_gives_per_sample_errors(tmp_path, capsys):
    code, _, _ = _run(["demo", "--out", tmp_path, "--json"], capsys)
    assert code == 0
    code, out, _ = _run(
        ["verify", tmp_path / "calibrated.urdf", tmp_path / "held_out.json", "--json"], capsys
    )
    assert code == 0
    report = json.loads(out)
    assert report["sidecar"].endswith("calibrated.kinfw.json")
    assert report["fitted"] == []  # the target pose comes from the calibration
    camera = next(g for g in report["groups"] if g["kind"] == "target")
    assert len(camera["samples"]) == camera["n"] == 100
    rms = np.sqrt(np.mean([s["position_mm"] ** 2 for s in camera["samples"]]))
    assert rms == pytest.approx(camera["position_rms_mm"], rel=1e-9)
    code, out, _ = _run(
        [
            "verify",
            tmp_path / "calibrated.urdf",
            tmp_path / "held_out.json",
            "--json",
            "--no-sidecar",
        ],
        capsys,
    )
    assert json.loads(out)["sidecar"] is None
    assert len(json.loads(out)["fitted"]) == 2


@pytest.mark.slow
def test_crossval_command_prints_folds_and_selects(tmp_path, capsys):
    code, _, _ = _run(["demo", "--out", tmp_path, "--json"], capsys)
    assert code == 0
    crossval = ["crossval", tmp_path / "data.json", "--urdf", HEAD, "--k", "3", *DEMO_BOUND_ARGS]
    code, out, _ = _run([*crossval, "--json"], capsys)
    assert code == 0
    cv = json.loads(out)
    means = cv["mean_position_rms_mm"]
    assert means["full"] < means["frames"] < means["none"]
    assert len(cv["folds"]) == 3 * 4  # nominal, frames, full and the default
    assert means["auto"] == means["full"]  # plentiful data: the default fits full
    code, out, _ = _run([*crossval, "--select"], capsys)
    assert code == 0 and "selected: full ('full')" in out
