"""``kinfw handeye`` checks its pose pairs before any fit or output: quaternions stored
scalar first under qx..qw headers, millimetres read as metres and metres read as
millimetres are refused (exit 2, nothing written) naming the file and the fix; pairs
recorded twice count once, with one warning naming them. Truth: pose pairs simulated
with Pinocchio from a known mount (tests/kinfw/cli/test_cli_handeye.py)."""

import json

import numpy as np
import pinocchio as pin
import pytest

from kinfw.measurements import PosePairs, pose_pairs_text
from tests.cli_run import run_cli
from tests.kinfw.cli.test_cli_handeye import X_TRUE, _pairs, _write


def _scalar_first(text: str, sides: tuple[str, ...]) -> str:
    """The CSV with the quaternions of ``sides`` written (w, x, y, z) under qx..qw."""
    lines = text.splitlines()
    header = lines[0].split(",")
    out = [lines[0]]
    for line in lines[1:]:
        v = line.split(",")
        for side in sides:
            k = header.index(f"{side}_qx")
            v[k : k + 4] = [v[k + 3], *v[k : k + 3]]
        out.append(",".join(v))
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("sides", [("hand",), ("sensor",), ("hand", "sensor")])
def test_scalar_first_quaternions_are_refused_naming_the_poses(tmp_path, capsys, sides):
    path = tmp_path / "p.csv"
    path.write_text(_scalar_first(pose_pairs_text(_pairs(0, 12, noise=5e-4), "csv"), sides))
    ros = tmp_path / "ros"
    code, stdout, stderr = run_cli(["-q", "handeye", path, "--ros-out", ros], capsys)
    assert code == 2 and stdout == "" and not ros.exists()
    assert stderr.startswith(f"kinfw handeye: error: {path}: quaternions look ")
    named = " and ".join(sides)
    assert f"scalar-first (w, x, y, z) under qx..qw headers ({named} poses)" in stderr
    assert "reorder them to qx, qy, qz, qw (scalar last)" in stderr
    first = str(stderr).split(" read so,")[0]
    assert len(first) - len(str(path)) < 170


def test_millimetres_read_as_metres_are_refused_and_read_with_unit_mm(tmp_path, capsys):
    p = _pairs(1, 12, noise=5e-4)
    mm = _write(tmp_path / "mm.csv", p.scaled(1e3), "csv")
    ros = tmp_path / "ros"
    code, _, stderr = run_cli(["-q", "handeye", mm, "--ros-out", ros], capsys)
    assert code == 2 and not ros.exists()
    assert f"{mm} (read in m): positions look like millimetres read as metres" in stderr
    assert "read them in mm (kinfw handeye --unit mm)" in stderr
    code, stdout, stderr = run_cli(["-q", "handeye", mm, "--unit", "mm", "--json"], capsys)
    assert code == 0, stderr
    got = np.array(json.loads(stdout)["calibration"]["hand_T_camera"])
    np.testing.assert_allclose(got[:3, :3], X_TRUE[:3, :3], atol=1e-3)
    np.testing.assert_allclose(got[:3, 3], X_TRUE[:3, 3], atol=2e-3)


def test_metres_read_as_millimetres_are_refused(tmp_path, capsys):
    m = _write(tmp_path / "m.yaml", _pairs(2, 10, "eye-to-hand"), "yaml")
    code, _, stderr = run_cli(["-q", "handeye", m, "--unit", "mm"], capsys)
    assert code == 2
    assert f"{m} (read in mm): positions look like metres read as millimetres" in stderr
    assert "(kinfw handeye --unit m)" in stderr


def test_a_matrix_file_with_hand_positions_in_mm_is_refused(tmp_path, capsys):
    p = _pairs(3, 10)
    hands = p.base_T_hands.copy()
    hands[:, :3, 3] *= 1e3
    path = _write(tmp_path / "p.json", PosePairs(hands, p.sensor_T_targets, "x"), "json")
    code, _, stderr = run_cli(["-q", "handeye", path], capsys)
    assert code == 2
    assert "the hand positions look like millimetres read as metres, the others not" in stderr


def _sigmas(path, capsys, *extra):
    code, stdout, stderr = run_cli(["-q", "handeye", path, "--json", *extra], capsys)
    assert code == 0, stderr
    doc = json.loads(stdout)
    return np.array(doc["sigma_translation_mm"] + doc["sigma_rotation_deg"]), stderr


def test_pairs_recorded_twice_count_once_with_one_warning(tmp_path, capsys):
    p = _pairs(4, 15, noise=1e-3)
    once = _write(tmp_path / "once.csv", p, "csv")
    both = PosePairs(
        np.concatenate([p.base_T_hands] * 2), np.concatenate([p.sensor_T_targets] * 2), "x"
    )
    twice = _write(tmp_path / "twice.csv", both, "csv")
    sigma_once, said = _sigmas(once, capsys)
    assert "warning" not in said
    sigma, said = _sigmas(twice, capsys)
    np.testing.assert_allclose(sigma, sigma_once, rtol=1e-9)
    assert said.count("warning:") == 1
    assert "15 of the 30 pose pairs repeat an earlier one: 15 (= 0), 16 (= 1)" in said
    assert "and 10 more" in said
    kept, said = _sigmas(twice, capsys, "--keep-duplicates")
    assert "warning" not in said
    np.testing.assert_allclose(kept / sigma_once, 1 / np.sqrt(2), rtol=0.05)


def test_a_measurement_file_in_mm_read_as_m_and_its_duplicates(tmp_path, capsys):
    """Target views of the IIS head's left camera with --urdf: calibrate's unit check
    refuses positions in mm under "length": "m"; samples recorded twice count once."""
    from kinfw.measurements import Measurements, write_measurements
    from kinfw.model import builtin_head_urdf
    from kinfw.observations import TargetObservations

    urdf = builtin_head_urdf()
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    rng = np.random.default_rng(0)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    qs = np.stack([lo + (hi - lo) * rng.uniform(0.1, 0.9, size=model.nq) for _ in range(12)])
    cam = model.getFrameId("left_camera")
    target = pin.SE3(np.eye(3), np.array([0.0, 0.0, 2.0]))
    views = []
    for q in qs:
        pin.framesForwardKinematics(model, data, q)
        views.append((data.oMf[cam].inverse() * target).homogeneous)
    views = np.stack(views)
    names = tuple(model.names[1:])
    twice = Measurements(
        joint_names=names,
        qs=np.concatenate([qs, qs]),
        targets=(TargetObservations("left_camera", np.arange(24), np.concatenate([views] * 2)),),
    )
    path = tmp_path / "twice.json"
    write_measurements(path, twice)
    code, _, stderr = run_cli(["-q", "handeye", path, "--urdf", urdf], capsys)
    assert code == 0, stderr
    assert "12 of the 24 samples repeat an earlier one: 12 (= 0), 13 (= 1)" in stderr
    mm = views.copy()
    mm[:, :3, 3] *= 1e3
    m = Measurements(names, qs, targets=(TargetObservations("left_camera", np.arange(12), mm),))
    write_measurements(tmp_path / "mm.json", m)
    code, _, stderr = run_cli(["-q", "handeye", tmp_path / "mm.json", "--urdf", urdf], capsys)
    assert code == 2 and "look like millimetres read as metres" in stderr


@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
def test_a_board_of_the_wrong_size_is_named_with_its_factor(tmp_path, capsys, setup):
    """Target translations 1.25 times too long (a square of 0.05 m given for 0.04): the
    true ones are 0.8 times the measured; exact pairs say so, the true size says nothing."""
    p = _pairs(4, 15, setup, noise=2e-4)
    right = _write(tmp_path / "right.csv", p, "csv")  # a CSV does not record the setup
    code, _, stderr = run_cli(["-q", "handeye", right, "--setup", setup], capsys)
    assert code == 0 and "stated size" not in stderr, stderr
    long = p.sensor_T_targets.copy()
    long[:, :3, 3] *= 1.25
    wrong = _write(tmp_path / "wrong.csv", PosePairs(p.base_T_hands, long, "x", setup), "csv")
    code, _, stderr = run_cli(["-q", "handeye", wrong, "--setup", setup], capsys)
    assert f"{wrong}: target 'target' seen by 'camera_link' looks " in stderr, stderr
    factor = float(stderr.split(" looks ")[1].split(" times")[0])
    assert factor == pytest.approx(0.8, abs=0.005)


def test_eye_to_hand_pairs_read_as_eye_in_hand_are_named(tmp_path, capsys):
    """A CSV records no setup: eye-to-hand pairs read with the default (eye-in-hand) fit
    A X = X B only with the hand's poses inverted, which the error says (it blamed the
    quaternions' order)."""
    path = _write(tmp_path / "e2h.csv", _pairs(4, 15, "eye-to-hand", noise=2e-4), "csv")
    code, _, stderr = run_cli(["-q", "handeye", path], capsys)
    assert code == 2
    assert f"{path}: the pose pairs look eye-to-hand, read as eye-in-hand" in stderr
    assert "give --setup eye-to-hand" in stderr and "scalar-first" not in stderr
