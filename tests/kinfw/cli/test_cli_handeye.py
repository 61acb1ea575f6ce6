"""``kinfw handeye`` end to end on pose pairs simulated with Pinocchio from a known camera
mount: the printed and written transforms equal the truth, the comparison table and the
held-out errors are there, and bad input exits 2 with one line naming the cause."""

import json

import numpy as np
import pinocchio as pin
import pytest

from kinfw.identification.handeye import ROS_FILES, read_handeye_calibration
from kinfw.measurements import PosePairs, pose_pairs_text
from tests.cli_run import run_cli

X_TRUE = pin.SE3(pin.exp3(np.array([0.4, -0.3, 1.1])), np.array([0.02, -0.05, 0.11])).homogeneous
TARGET = pin.SE3(pin.exp3(np.array([0.1, 2.0, -0.3])), np.array([0.7, 0.1, 0.2])).homogeneous


def _pairs(seed, n, setup="eye-in-hand", noise=0.0):
    """base_T_hands and camera_T_targets: eye-in-hand base_T_target = base_T_hand X B,
    eye-to-hand hand_T_target = hand_T_base X B (X the camera in the hand / the base)."""
    rng = np.random.default_rng(seed)
    hands = np.stack(
        [
            pin.SE3(pin.exp3(rng.normal(size=3) * 0.7), rng.normal(scale=0.2, size=3)).homogeneous
            for _ in range(n)
        ]
    )
    A = hands if setup == "eye-in-hand" else np.stack([np.linalg.inv(h) for h in hands])
    B = np.stack([np.linalg.inv(X_TRUE) @ np.linalg.inv(a) @ TARGET for a in A])
    B[:, :3, 3] += rng.normal(scale=noise, size=(n, 3))
    return PosePairs(hands, B, "sim", setup)


def _write(path, pairs, fmt):
    path.write_text(pose_pairs_text(pairs, fmt))
    return path


def test_eye_in_hand_csv_prints_and_writes_the_true_mount(tmp_path, capsys):
    pairs = _write(tmp_path / "pairs.csv", _pairs(0, 10), "csv")
    out, ros = tmp_path / "result.yaml", tmp_path / "ros"
    code, stdout, stderr = run_cli(
        ["-q", "handeye", pairs, "--out", out, "--ros-out", ros, "--camera-frame", "cam"], capsys
    )
    assert code == 0, stderr
    xyz_mm = " ".join(f"{v:.3f}" for v in 1e3 * X_TRUE[:3, 3])
    assert "10 pose pairs" in stdout and "0 rejected" in stdout
    assert "hand_T_camera: xyz [mm] [" in stdout and "verdict: determined" in stdout
    printed = stdout.split("hand_T_camera: xyz [mm] [")[1].split("]")[0].split()
    assert " ".join(f"{float(v):.3f}" for v in printed) == xyz_mm
    cal = read_handeye_calibration(out)
    np.testing.assert_allclose(cal.mount_T_camera, X_TRUE, atol=1e-9)
    np.testing.assert_allclose(cal.holder_T_target, TARGET, atol=1e-9)
    assert (cal.setup, cal.mount_frame, cal.camera_frame) == ("eye-in-hand", "tool0", "cam")
    assert sorted(p.name for p in ros.iterdir()) == sorted(ROS_FILES.values())


def test_eye_to_hand_from_easy_handeye2_samples_takes_the_files_setup(tmp_path, capsys):
    pairs = _write(tmp_path / "s.yaml", _pairs(1, 8, "eye-to-hand"), "yaml")
    code, stdout, stderr = run_cli(["-q", "handeye", pairs, "--json"], capsys)
    assert code == 0, stderr
    data = json.loads(stdout)
    assert data["calibration"]["setup"] == "eye-to-hand"
    np.testing.assert_allclose(data["calibration"]["base_T_camera"], X_TRUE, atol=1e-9)
    np.testing.assert_allclose(data["calibration"]["hand_T_target"], TARGET, atol=1e-9)


def test_method_all_tables_every_method_with_held_out_errors(tmp_path, capsys):
    pairs = _write(tmp_path / "p.json", _pairs(2, 12, noise=1e-3), "json")
    held = _write(tmp_path / "h.json", _pairs(3, 6, noise=1e-3), "json")
    argv = ["-q", "handeye", pairs, "--method", "all", "--holdout", held, "--k", "3"]
    code, stdout, stderr = run_cli(argv, capsys)
    assert code == 0, stderr
    table = stdout.split("held-out:")[1]
    for m in ("kinfw", "tsai", "park", "horaud", "andreff", "daniilidis", "shah", "li"):
        assert f"\n{m} " in table
    assert "holdout mm" in table and "3-fold mm" in table
    code, stdout, _ = run_cli([*argv, "--json"], capsys)
    rows = {r["method"]: r for r in json.loads(stdout)["methods"]}
    assert len(rows) == 8 and rows["kinfw"]["k"] == 3
    # 1 mm noise per axis: RMS held-out distance near sqrt(3) mm, not more than twice
    assert 0.5 < rows["kinfw"]["holdout"]["rms_translation_mm"] < 3.5


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda d: d / "missing.csv", "missing.csv: cannot read"),
        (lambda d: _write(d / "two.json", _pairs(0, 2), "json"), "at least 3"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, make, message):
    code, stdout, stderr = run_cli(["-q", "handeye", make(tmp_path)], capsys)
    assert code == 2 and stdout == ""
    assert stderr.startswith("kinfw handeye: error: ") and message in stderr
    assert stderr.count("\n") == 1


def test_motions_about_one_axis_exit_2_naming_the_axis(tmp_path, capsys):
    rng = np.random.default_rng(4)
    hands = np.stack(
        [
            pin.SE3(
                pin.exp3(np.array([0.0, 0.0, rng.uniform(-1, 1)])), rng.normal(size=3)
            ).homogeneous
            for _ in range(6)
        ]
    )
    B = np.stack([np.linalg.inv(X_TRUE) @ np.linalg.inv(a) @ TARGET for a in hands])
    path = _write(tmp_path / "p.csv", PosePairs(hands, B, "x"), "csv")
    code, _, stderr = run_cli(["-q", "handeye", path], capsys)
    assert code == 2 and "about one axis ([0. 0. 1.] in the hand frame" in stderr


def test_a_holdout_repeating_the_fits_pairs_is_warned_about(tmp_path, capsys):
    pairs = _write(tmp_path / "p.csv", _pairs(5, 8, noise=1e-3), "csv")
    code, _, stderr = run_cli(["-q", "handeye", pairs, "--holdout", pairs], capsys)
    assert code == 0
    assert "warning: --holdout" in stderr and "8 of its 8 pairs are also in" in stderr
    held = _write(tmp_path / "h.csv", _pairs(6, 8, noise=1e-3), "csv")
    code, _, stderr = run_cli(["-q", "handeye", pairs, "--holdout", held], capsys)
    assert code == 0 and "warning" not in stderr


def test_a_kinfw_measurement_file_with_a_urdf_gives_the_models_camera_mount(tmp_path, capsys):
    """Target observations of the IIS head's left camera, simulated from the URDF's own
    kinematics (Pinocchio): the camera's pose on its vergence link is the URDF's."""
    from kinfw.measurements import Measurements, write_measurements
    from kinfw.model import builtin_head_urdf, load_robot
    from kinfw.observations import TargetObservations

    urdf = builtin_head_urdf()
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    robot = load_robot(urdf)
    rng = np.random.default_rng(0)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    qs = np.stack([lo + (hi - lo) * rng.uniform(0.1, 0.9, size=model.nq) for _ in range(12)])
    cam, hand = model.getFrameId("left_camera"), model.getFrameId("vergence_left_link")
    target = pin.SE3(np.eye(3), np.array([0.0, 0.0, 2.0]))
    camera_T_target, mount = [], []
    for q in qs:
        pin.framesForwardKinematics(model, data, q)
        camera_T_target.append((data.oMf[cam].inverse() * target).homogeneous)
        mount.append((data.oMf[hand].inverse() * data.oMf[cam]).homogeneous)
    names = tuple(model.names[1:])
    assert names == robot.joint_names[: len(names)]
    m = Measurements(
        joint_names=names,
        qs=qs,
        targets=(TargetObservations("left_camera", np.arange(12), np.stack(camera_T_target)),),
    )
    path = tmp_path / "m.json"
    write_measurements(path, m)
    out = tmp_path / "r.yaml"
    argv = ["-q", "handeye", path, "--urdf", urdf, "--hand-frame", "vergence_left_link"]
    code, _, stderr = run_cli([*argv, "--out", out], capsys)
    assert code == 0, stderr
    np.testing.assert_allclose(read_handeye_calibration(out).mount_T_camera, mount[0], atol=1e-9)
    # without --hand-frame: the link the camera's fixed joint hangs on (left_plate), whose
    # mount is that joint's origin in the URDF
    code, _, stderr = run_cli(["-q", "handeye", path, "--urdf", urdf, "--out", out], capsys)
    assert code == 0, stderr
    np.testing.assert_allclose(
        read_handeye_calibration(out).mount_T_camera,
        robot.joint("left_camera_joint").parent_T_child,
        atol=1e-9,
    )
    views = TargetObservations("wrist_cam", np.arange(12), np.stack(camera_T_target))
    write_measurements(tmp_path / "w.json", Measurements(names, qs, targets=(views,)))
    code, _, stderr = run_cli(["-q", "handeye", tmp_path / "w.json", "--urdf", urdf], capsys)
    assert code == 2 and "['wrist_cam'] is not one link of" in stderr
    assert "--hand-frame LINK" in stderr
    code, _, stderr = run_cli(["-q", "handeye", path], capsys)
    assert code == 2 and "a kinfw measurement file, not pose pairs" in stderr
