"""``--model``: what the URDF cannot hold, through the shell commands.

A UR10 (example-robot-data, with its link inertias) measured by three tracker reflectors
on the flange: ``kinfw simulate --compliance`` makes the truth; ``kinfw calibrate --model
compliance`` must recover it exactly from noise-free data and predict held-out data at the
noise floor from noisy data, where the URDF alone cannot; the sidecar records it so that
``verify`` and ``export`` re-apply it with no flags.
"""

import json

import numpy as np
import pytest
import yaml

from kinfw.measurements import read_measurements, write_measurements
from tests.cli_run import run_cli
from tests.erd import urdf_path

UR10 = urdf_path("ur_description/urdf/ur10_robot.urdf")
REFLECTORS = ("tool0:0.1,0,0.05", "tool0:0,0.1,0.05", "tool0:0,0,0.15")
C_TRUE = 5e-6  # rad/Nm on every joint: 1.2 mm at the flange under the arm's own weight


def _simulate(tmp_path, capsys, name: str, *extra) -> tuple[str, dict]:
    """``kinfw simulate`` of the tracked UR10; its file and JSON summary."""
    markers = [a for r in REFLECTORS for a in ("--markers", r)]
    out = tmp_path / f"{name}.json"
    code, text, _ = run_cli(
        [
            *("simulate", "--urdf", UR10, *markers, "--out", out),
            *("--truth-out", tmp_path / f"{name}.urdf"),
            *("--json", *extra),
        ],
        capsys,
    )
    assert code == 0
    return str(out), json.loads(text)


def _calibrate_compliant(data, cal, capsys) -> tuple[int, str, str]:
    """``kinfw calibrate DATA --urdf UR10 --out CAL --params full --model compliance``."""
    return run_cli(
        [
            "calibrate",
            data,
            "--urdf",
            UR10,
            "--out",
            cal,
            "--params",
            "full",
            "--model",
            "compliance",
        ],
        capsys,
    )


def _true_compliance(summary: dict) -> dict[str, float]:
    (block,) = summary["truth_model"]
    return {n.split(":")[0]: v for n, v in zip(block["names"], block["values"], strict=True)}


@pytest.mark.slow
def test_compliance_is_recovered_exactly_and_reapplied_by_verify_and_export(tmp_path, capsys):
    # the true geometry is the nominal's: the gravity torque the fit computes from the
    # nominal URDF is then the truth's (with millimetre errors it is off by ~0.2 %, and
    # so is the compliance: see docs/model.md)
    data, summary = _simulate(
        tmp_path,
        capsys,
        "exact",
        *("--compliance", str(C_TRUE), "--noise-mm", "0", "--mocap-samples", "80"),
        *("--error-mm", "0", "--error-deg", "0"),
    )
    truth = _true_compliance(summary)
    cal = tmp_path / "cal.urdf"
    code, out, _ = run_cli(
        [
            "calibrate",
            data,
            "--urdf",
            UR10,
            "--out",
            cal,
            "--model",
            "compliance",
            "--params",
            "full",
        ],
        capsys,
    )
    assert code == 0, out
    assert "what no URDF holds (compliance) is in the sidecar and" in out
    (record,) = json.loads(cal.with_suffix(".kinfw.json").read_text())["robot_blocks"]
    estimate = dict(zip(record["names"], record["values"], strict=True))
    std = dict(zip(record["names"], record["std"], strict=True))
    # the joints gravity loads (shoulder lift, elbow, wrist 1): the true compliance; the
    # vertical shoulder pan and the unloaded wrist 2 and 3 are not estimated
    for joint in ("shoulder_lift_joint", "elbow_joint", "wrist_1_joint"):
        assert estimate[f"{joint}:compliance"] == pytest.approx(truth[joint], rel=1e-5), joint
        assert std[f"{joint}:compliance"] > 0
    assert std["shoulder_pan_joint:compliance"] == 0.0
    # the per-joint YAML: stiffness the inverse of the compliance
    joints = yaml.safe_load(cal.with_suffix(".joints.yaml").read_text())["joints"]
    lift = joints["shoulder_lift_joint"]
    assert lift["stiffness"]["value"] == pytest.approx(1.0 / C_TRUE, rel=1e-5)
    assert lift["stiffness"]["unit"] == "Nm/rad" and lift["compliance"]["unit"] == "rad/Nm"
    # verify re-applies the sidecar's compliance with no flag: the errors are the graph's
    # second-order deflection (1e-8 m), not the millimetre the URDF alone misses by
    code, out, _ = run_cli(["verify", cal, data, "--json"], capsys)
    assert code == 0
    worst = max(g["position_max_mm"] for g in json.loads(out)["groups"])
    assert worst < 1e-4
    # ... and without the sidecar the rigid URDF misses by the deflection
    code, out, _ = run_cli(["verify", cal, data, "--json", "--no-sidecar"], capsys)
    assert max(g["position_max_mm"] for g in json.loads(out)["groups"]) > 0.1
    code, out, _ = run_cli(["export", "robot-description", cal, "--out", tmp_path / "rd"], capsys)
    assert code == 0
    assert "leaves out compliance (6 entries), which no URDF holds" in out


def test_noisy_held_out_errors_are_at_the_noise_floor_with_compliance_only(tmp_path, capsys):
    """0.02 mm reflectors, joint errors of 1 mm / 0.2 deg: the compliant model predicts
    held-out points at the noise floor (sqrt(3) sigma), the URDF alone at several times
    it; the default (the model choice) takes the compliance."""
    sigma_mm = 0.02
    both, _ = _simulate(
        tmp_path,
        capsys,
        "noisy",
        *("--error-mm", "1", "--error-deg", "0.2"),
        "--compliance",
        str(C_TRUE),
        "--noise-mm",
        str(sigma_mm),
        "--mocap-samples",
        "240",
    )
    data = read_measurements(both)
    train, test = tmp_path / "train.json", tmp_path / "test.json"
    write_measurements(train, data.subset(np.arange(0, 240, 2)))
    write_measurements(test, data.subset(np.arange(1, 240, 2)))
    held = {}
    runs = {
        "compliant": ["--params", "full", "--model", "compliance"],
        "rigid": ["--params", "full"],
        "default": [],  # the model choice: compliance, on held-out evidence
    }
    warned = {}
    for label, model in runs.items():
        out = tmp_path / f"{label}.urdf"
        code, text, err = run_cli(
            ["calibrate", train, "--urdf", UR10, "--out", out, "--holdout", test, "--json", *model],
            capsys,
        )
        assert code == 0
        rows = json.loads(text)["errors_held_out"]
        held[label] = max(r["after_position_rms_mm"] for r in rows)
        warned[label] = "add --model compliance" in err
    # the rigid fit's residuals follow the gravity torque, and kinfw says so
    assert warned == {"compliant": False, "rigid": True, "default": False}
    floor = np.sqrt(3.0) * sigma_mm
    assert held["compliant"] < 1.15 * floor, held
    assert held["rigid"] > 3.0 * floor, held
    assert held["default"] == pytest.approx(held["compliant"], rel=1e-6), held


def test_rigid_data_keep_the_rigid_model_and_get_no_compliance_warning(tmp_path, capsys):
    data, _ = _simulate(tmp_path, capsys, "rigid", "--noise-mm", "0.02", "--mocap-samples", "120")
    for params in (["--params", "full"], []):
        out = tmp_path / "cal.urdf"
        code, _, err = run_cli(
            ["calibrate", data, "--urdf", UR10, "--out", out, "--json", *params], capsys
        )
        assert code == 0 and "add --model compliance" not in err, err
        assert "robot_blocks" not in json.loads(out.with_suffix(".kinfw.json").read_text())
        assert not out.with_suffix(".joints.yaml").exists()
        out.unlink()
        out.with_suffix(".kinfw.json").unlink()


def test_gear_scale_and_coupling_are_recovered_exactly_through_the_shell(tmp_path, capsys):
    """The IIS-head, one joint at a time: the tilt's encoder reads 1 % short, and the
    right vergence's reading lacks 5 % of the left's; both recovered to rounding."""
    data, out_urdf = tmp_path / "g.json", tmp_path / "g.urdf"
    code, text, _ = run_cli(
        [
            *("simulate", "--out", data, "--truth-out", out_urdf, "--json"),
            *("--noise-mm", "0", "--noise-deg", "0", "--truth-model", "gear-scale:tilt@0.01"),
            *("--truth-model", "coupling:vergence_right=0.05*vergence_left"),
        ],
        capsys,
    )
    assert code == 0
    assert [b["values"] for b in json.loads(text)["truth_model"]] == [[0.01], [0.05]]
    cal = tmp_path / "cal.urdf"
    code, out, _ = run_cli(
        [
            *("calibrate", data, "--urdf", _head(), "--out", cal, "--params", "full"),
            *("--model", "gear-scale:tilt", "--model", "coupling:vergence_right=?*vergence_left"),
        ],
        capsys,
    )
    assert code == 0, out
    records = json.loads(cal.with_suffix(".kinfw.json").read_text())["robot_blocks"]
    assert records[0]["block"] == "gear-scale:tilt"
    values = {r["names"][0]: r["values"][0] for r in records}
    assert values["tilt:gear_scale"] == pytest.approx(0.01, abs=1e-10)
    assert values["vergence_right:coupling:vergence_left"] == pytest.approx(0.05, abs=1e-10)
    code, out, _ = run_cli(["verify", cal, data, "--json"], capsys)
    assert max(g["position_max_mm"] for g in json.loads(out)["groups"]) < 1e-6


def _head() -> str:
    import kinfw

    return str(kinfw.builtin_head_urdf())


def test_model_errors_name_the_block_and_what_is_expected(tmp_path, capsys):
    data = tmp_path / "d.json"
    run_cli(["simulate", "--out", data, "--truth-out", tmp_path / "t.urdf"], capsys)
    for spec, message in [
        ("spring:tilt", "unknown block 'spring'; known blocks: compliance, coupling, gear-scale"),
        ("gear-scale:elbow", "joint 'elbow' is not a movable joint on the measured paths"),
    ]:
        code, _, err = run_cli(
            ["calibrate", data, "--urdf", _head(), "--out", tmp_path / "c.urdf", "--model", spec],
            capsys,
        )
        assert code != 0 and message in err, err
        assert not (tmp_path / "c.urdf").exists()
    model_file = tmp_path / "model.yaml"
    model_file.write_text("model: [gear-scale:tilt, 3]\n")
    code, _, err = run_cli(
        ["calibrate", data, "--urdf", _head(), "--out", tmp_path / "c.urdf", "--model", model_file],
        capsys,
    )
    assert code != 0 and "expected a list of specs" in err


@pytest.mark.slow
def test_payloads_are_calibrated_verified_and_compensated_by_reach(tmp_path, capsys):
    """Reflectors with known offsets measured in the root, 0-10 kg on the flange per
    sample: the compliance is recovered exactly from noise-free data; verify applies each
    held-out sample's payload (errors at rounding, the URDF alone misses by the payload's
    deflection); ``kinfw reach --payload`` gives the command that puts the true compliant
    arm's flange on the target under that payload, where the rigid command misses."""
    from kinfw.model import load_robot

    data, summary = _simulate(
        tmp_path,
        capsys,
        "loaded",
        *("--compliance", str(C_TRUE), "--noise-mm", "0", "--mocap-samples", "160"),
        *("--error-mm", "0", "--error-deg", "0", "--payloads", "tool0:10:0,0,0.1"),
        *("--mocap-frame", "world", "--offsets-known"),
    )
    measured = read_measurements(data)
    assert measured.payloads is not None and 0 < measured.payloads.mass_kg.max() <= 10
    train, test = tmp_path / "train.json", tmp_path / "test.json"
    write_measurements(train, measured.subset(np.arange(0, 160, 2)))
    write_measurements(test, measured.subset(np.arange(1, 160, 2)))
    cal = tmp_path / "cal.urdf"
    code, out, _ = _calibrate_compliant(train, cal, capsys)
    assert code == 0, out
    (record,) = json.loads(cal.with_suffix(".kinfw.json").read_text())["robot_blocks"]
    truth = _true_compliance(summary)
    estimate = dict(zip(record["names"], record["values"], strict=True))
    for joint in ("shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint"):
        assert estimate[f"{joint}:compliance"] == pytest.approx(truth[joint], rel=1e-4), joint
    code, out, _ = run_cli(["verify", cal, test, "--json"], capsys)
    assert max(g["position_max_mm"] for g in json.loads(out)["groups"]) < 1e-4
    # compensation: a target the true arm reaches, a payload of 8 kg
    true_robot = load_robot(tmp_path / "loaded.urdf")
    names = true_robot.joint_names
    q = np.array([0.3, -1.0, 1.2, -0.9, 1.1, 0.4])
    from kinfw.model import ModelSpec, Payloads

    spec = ModelSpec.from_list(summary["truth_model"])
    payload = Payloads.constant(1, "tool0", 8.0, (0.0, 0.0, 0.1))
    target = true_robot.frame_poses(q, "tool0", names)[:3, 3]
    achieved = {}
    for label, flags in (("compensated", []), ("rigid", ["--no-sidecar"])):
        code, out, err = run_cli(
            [
                *("reach", cal, "--frame", "tool0", "--point", *target),
                *("--payload", "tool0:8:0,0,0.1", "--json", *flags),
                *(f"--q={n}={v}" for n, v in zip(names, q, strict=True)),
            ],
            capsys,
        )
        assert code == 0, err
        command = np.array(json.loads(out)["command"])
        physical = spec.joint_values(true_robot, names, command[None], payload)[0]
        achieved[label] = np.linalg.norm(
            true_robot.frame_poses(physical, "tool0", names)[:3, 3] - target
        )
    assert achieved["compensated"] < 1e-7, achieved
    assert achieved["rigid"] > 1e-4, achieved


def test_reach_takes_targets_as_the_tracker_sees_them(tmp_path, capsys):
    """``--measured-in mocap``: the target is placed in the root by the sidecar's pose of
    the tracker frame (the calibration's root is gauge); another frame, or no sidecar,
    is refused naming what is there."""
    data, _ = _simulate(tmp_path, capsys, "tracked", "--noise-mm", "0", "--mocap-samples", "60")
    cal = tmp_path / "cal.urdf"
    assert (
        run_cli(["calibrate", data, "--urdf", UR10, "--out", cal, "--params", "full"], capsys)[0]
        == 0
    )
    sidecar = json.loads(cal.with_suffix(".kinfw.json").read_text())
    assert sidecar["measurement_frame"] == "mocap"
    meas_T_root = np.array(sidecar["w_T_root"])
    root_p = np.array([0.6, 0.2, 0.5])
    mocap_p = meas_T_root[:3, :3] @ root_p + meas_T_root[:3, 3]
    code, out, _ = run_cli(
        ["reach", cal, "--frame", "tool0", "--point", *mocap_p, "--measured-in", "mocap", "--json"],
        capsys,
    )
    assert code == 0
    np.testing.assert_allclose(
        np.array(json.loads(out)["root_T_target"])[:3, 3], root_p, atol=1e-12
    )
    code, _, err = run_cli(
        ["reach", cal, "--frame", "tool0", "--point", 0, 0, 1, "--measured-in", "vicon"], capsys
    )
    assert code == 2 and "was measured in mocap" in err
    cal.with_suffix(".kinfw.json").unlink()
    code, _, err = run_cli(
        ["reach", cal, "--frame", "tool0", "--point", 0, 0, 1, "--measured-in", "mocap"], capsys
    )
    assert code == 2 and "no calibration sidecar" in err


@pytest.mark.slow
def test_noisy_gear_scale_and_coupling_predict_held_out_poses_at_the_noise_floor(tmp_path, capsys):
    """The IIS-head's plates one joint at a time (30 values per joint, 0.05 mm / 0.05 deg),
    its tilt 1 % off and its right vergence coupled by 5 %: with the two blocks the held-out
    position RMS is at the floor sqrt(3) sigma, without them well above it."""
    data = tmp_path / "d.json"
    code, _, _ = run_cli(
        [
            *("simulate", "--out", data, "--truth-out", tmp_path / "t.urdf", "--stage", "1"),
            *("--per-joint", "30", "--noise-mm", "0.05", "--noise-deg", "0.05"),
            *("--truth-model", "gear-scale:tilt@0.01"),
            *("--truth-model", "coupling:vergence_right=0.05*vergence_left"),
        ],
        capsys,
    )
    assert code == 0
    measured = read_measurements(data)
    n = measured.n_samples
    train, test = tmp_path / "train.json", tmp_path / "test.json"
    write_measurements(train, measured.subset(np.arange(0, n, 2)))
    write_measurements(test, measured.subset(np.arange(1, n, 2)))
    held = {}
    models = ["--model", "gear-scale:tilt", "--model", "coupling:vergence_right=?*vergence_left"]
    for label, model in (("blocks", models), ("urdf", [])):
        out = tmp_path / f"{label}.urdf"
        code, text, _ = run_cli(
            [
                *("calibrate", train, "--urdf", _head(), "--out", out, "--holdout", test),
                *("--params", "full", "--json", *model),
            ],
            capsys,
        )
        assert code == 0
        held[label] = max(r["after_position_rms_mm"] for r in json.loads(text)["errors_held_out"])
    floor = np.sqrt(3.0) * 0.05
    assert held["blocks"] < 1.15 * floor, held
    assert held["urdf"] > 2.0 * floor, held


@pytest.mark.slow
def test_crossval_report_and_view_take_the_model(tmp_path, capsys):
    """``kinfw crossval --model compliance`` scores the compliant model on held-out folds
    (at the noise floor where full alone is far above it); the report lists the
    compliances with their unit; ``kinfw view`` draws the calibrated arm deflected (its
    scene differs from the same URDF's without the sidecar's compliance)."""
    data, _ = _simulate(
        tmp_path,
        capsys,
        "cv",
        *("--compliance", str(C_TRUE), "--noise-mm", "0.02", "--mocap-samples", "150"),
        *("--error-mm", "1", "--error-deg", "0.2"),
    )
    code, out, _ = run_cli(
        ["crossval", data, "--urdf", UR10, "--json", "--model", "compliance"], capsys
    )
    assert code == 0
    cv = json.loads(out)["mean_position_rms_mm"]
    floor = np.sqrt(3.0) * 0.02
    assert cv["full"] < 1.2 * floor and cv["auto"] < 1.2 * floor, cv
    cal, report = tmp_path / "cal.urdf", tmp_path / "report.json"
    code, _, _ = run_cli(
        [
            "calibrate",
            data,
            "--urdf",
            UR10,
            "--out",
            cal,
            "--report",
            report,
            "--model",
            "compliance",
        ],
        capsys,
    )
    assert code == 0
    rows = [
        p
        for p in json.loads(report.read_text())["refine"]["parameters"]
        if p["field"] == "compliance"
    ]
    assert {r["unit"] for r in rows} == {"rad/Nm"} and len(rows) == 6
    lift = next(r for r in rows if r["owner"] == "shoulder_lift_joint")
    assert lift["delta_from_start"] == pytest.approx(C_TRUE, rel=0.05)
    code, _, err = run_cli(
        ["view", UR10, "--calibrated", cal, "--data", data, "--html", tmp_path / "v.html"], capsys
    )
    assert code == 0 and (tmp_path / "v.html").stat().st_size > 0, err


def _calibrated_transforms(window) -> dict:
    """The last transform sent to each node of the calibrated robot (path -> 4x4)."""
    return {
        c["path"]: np.array(c["matrix"]).reshape(4, 4).T
        for c in window.commands
        if c["type"] == "set_transform" and c["path"].startswith("/meshcat/kinfw/calibrated/")
    }


def test_the_view_draws_the_calibrated_robot_at_its_joint_values():
    """A gear scale on the tilt: the calibrated robot is drawn where the URDF alone would
    be at the scaled joint value, and not at the reading."""
    import kinfw
    from kinfw.model import ModelSpec
    from kinfw.view import OfflineWindow, scene

    head = kinfw.load_robot(_head())
    geared = head.with_spec(ModelSpec.parse(["gear-scale:tilt"]).with_values([[0.3]]))
    q = np.array([0.0, 0.0, 0.2, 0.5, 0.1, -0.1])
    q_scaled = q.copy()
    q_scaled[head.joint_names.index("tilt")] *= 1.3
    drawn = {}
    for label, robot, at in (("spec", geared, q), ("scaled", head, q_scaled), ("read", head, q)):
        window = OfflineWindow()
        scene(head, robot, q=at, window=window)
        drawn[label] = _calibrated_transforms(window)
    assert drawn["spec"].keys() == drawn["scaled"].keys() and drawn["spec"]
    for path, T in drawn["spec"].items():
        np.testing.assert_allclose(T, drawn["scaled"][path], atol=1e-12)
    assert any(not np.allclose(T, drawn["read"][p]) for p, T in drawn["spec"].items())


def test_a_wall_mounted_arm_is_calibrated_and_reached_under_its_gravity(tmp_path, capsys):
    """Gravity along the root's +x (an arm on a wall): the file and the sidecar carry it;
    reach compensates under it by default, and misses when told the standard gravity."""
    from kinfw.model import ModelSpec, load_robot

    data, summary = _simulate(
        tmp_path,
        capsys,
        "wall",
        *("--compliance", str(C_TRUE), "--noise-mm", "0", "--mocap-samples", "80"),
        *("--error-mm", "0", "--error-deg", "0", "--gravity", "9.81", "0", "0"),
        *("--mocap-frame", "world", "--offsets-known"),
    )
    assert read_measurements(data).gravity.tolist() == [9.81, 0.0, 0.0]
    cal = tmp_path / "cal.urdf"
    code, _, _ = _calibrate_compliant(data, cal, capsys)
    assert code == 0
    assert json.loads(cal.with_suffix(".kinfw.json").read_text())["gravity"] == [9.81, 0.0, 0.0]
    truth = load_robot(tmp_path / "wall.urdf")
    spec = ModelSpec.from_list(summary["truth_model"])
    names = truth.joint_names
    q = np.array([0.3, -1.0, 1.2, -0.9, 1.1, 0.4])
    target = truth.frame_poses(q, "tool0", names)[:3, 3]
    missed = {}
    for label, flags in (("sidecar's", []), ("standard", ["--gravity", "0", "0", "-9.81"])):
        code, out, _ = run_cli(
            [
                *("reach", cal, "--frame", "tool0", "--point", *target, "--json", *flags),
                *(f"--q={n}={v}" for n, v in zip(names, q, strict=True)),
            ],
            capsys,
        )
        command = np.array(json.loads(out)["command"])
        physical = spec.joint_values(truth, names, command[None], gravity=(9.81, 0.0, 0.0))[0]
        missed[label] = np.linalg.norm(truth.frame_poses(physical, "tool0", names)[:3, 3] - target)
    assert missed["sidecar's"] < 1e-7 and missed["standard"] > 1e-4, missed
