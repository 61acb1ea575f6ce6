"""``kinfw import-bag`` end to end: a bag written here (rosbags' writers) from a simulated
arm (``tests/bags.py``: a perturbed ``ARM_6R``, joint states at 100 Hz, mocap at 30 Hz
stamped 23 ms late, 0.1 mm / 0.2 mrad noise) -> measurements -> calibrate. The truth is
the simulation: the printed offset is the delay, the calibrated arm predicts the
marker's pose at new configurations as the true arm does."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from kinfw.geometry import quat_xyzw_from_matrix
from kinfw.measurements import measurements_from_dict, read_measurements
from tests.bags import (
    DELAY_S,
    FLANGE_T_MARKER,
    ROOT_T_MOCAP,
    simulated_recording,
    trajectory,
    write_bag,
)
from tests.cli_run import run_cli
from tests.robots import ARM_6R


@pytest.fixture(scope="module")
def recording():
    return simulated_recording()


@pytest.fixture
def urdf(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(ARM_6R)
    return path


def _held_out(recording, n=40):
    """Noise-free mocap poses of the true arm at ``n`` configurations off the recorded
    path (other instants of other sines)."""
    qs = trajectory(np.linspace(0.0, 40.0, n))[:, ::-1]
    mocap_T_markers = (
        np.linalg.inv(ROOT_T_MOCAP)
        @ recording.truth.frame_poses(qs, "flange", recording.joint_names)
        @ FLANGE_T_MARKER
    )
    obs = {"frame": "flange", "kind": "pose", "marker": "m", "measured_in": "mocap"}
    samples = [
        {"q": q, "observations": [{**obs, "xyz": T[:3, 3].tolist(), "quat_xyzw": o}]}
        for q, T, o in zip(
            qs.tolist(),
            mocap_T_markers,
            quat_xyzw_from_matrix(mocap_T_markers[:, :3, :3]).tolist(),
            strict=True,
        )
    ]
    doc = {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "m", "angle": "rad"},
        "joint_names": list(recording.joint_names),
        "samples": samples,
    }
    return measurements_from_dict(doc, source="held-out")


@pytest.mark.slow
def test_bag_to_measurements_to_calibration_recovers_offset_and_arm(
    recording, urdf, tmp_path, capsys
):
    """ROS 1 bag, ``--time-offset auto``: the 23 ms delay found to 1 ms; calibrated from
    the file (every third sample), the marker's pose at 40 new configurations within
    0.2 mm and 0.3 mrad of the truth's (measured: 0.09 mm, 0.11 mrad; with offset 0,
    33 mm and 98 mrad) (perturb_robot: origins 2 mm and 0.5 deg off, axes 0.5 deg)."""
    from kinfw.identification import identify
    from kinfw.identification.problem import Unknown
    from kinfw.verification.evaluation import held_out_errors

    bag = write_bag(tmp_path / "rec.bag", recording, ros=1)
    out = tmp_path / "data.json"
    argv = ["-q", "import-bag", bag, "--urdf", urdf, "--pose", "/mocap/pose"]
    argv += ["--frame", "flange", "--marker", "m", "--time-offset", "auto", "--out", out]
    code, stdout, stderr = run_cli(argv, capsys)
    assert code == 0, stderr
    assert "(ROS 1)" in stdout and "/joint_states: 1200 messages, 100.0 Hz" in stdout
    assert "(not in the URDF, not read: gripper_finger_joint)" in stdout
    assert "/mocap/pose (geometry_msgs/msg/PoseStamped): 349 poses, 30.0 Hz, in 'mocap'" in stdout
    (found,) = re.findall(
        r"paired at time offset ([+-][0-9.]+) s: kept 349 of 349 measurements\n", stdout
    )
    assert abs(float(found) - DELAY_S) <= 1e-3
    data = read_measurements(out)
    assert data.n_samples == 349 and data.joint_names == recording.joint_names
    (group,) = data.poses
    assert (group.marker, group.measured_in) == ("m", "mocap")

    nominal = recording.nominal
    result = identify(nominal, data.subset(np.arange(0, 349, 3)))  # 117 of the 349: faster
    unknowns = result.refined.unknowns
    if result.refined.model_frame is not None:
        unknowns = (*unknowns, Unknown("frame", result.refined.model_frame, result.w_T_root))
    test = _held_out(recording)
    held = held_out_errors(nominal, result.urdf_xml, unknowns, test)
    assert held.values("position")[0].max() < 2e-4
    assert held.values("rotation")[0].max() < 3e-4


@pytest.mark.slow
def test_gaps_in_the_joint_states_are_dropped_and_counted(recording, urdf, tmp_path, capsys):
    """Joint states missing from 3.01 s to 3.52 s (ROS 2 bag, offset given): the mocap
    samples whose instant falls in the gap are dropped as ``gap``, the rest kept."""
    keep = (recording.t_joints <= 3.01 + 1e-9) | (recording.t_joints >= 3.52 - 1e-9)
    gappy = dataclasses.replace(
        recording, t_joints=recording.t_joints[keep], q_joints=recording.q_joints[keep]
    )
    bag = write_bag(tmp_path / "gappy", gappy)
    t_true = recording.t_mocap - DELAY_S
    n_gap = int(np.count_nonzero((t_true > 3.01) & (t_true < 3.52)))
    assert n_gap == 15  # 3.033 ... 3.5 s at 30 Hz
    argv = ["-q", "import-bag", bag, "--urdf", urdf, "--pose", "/mocap/pose", "--frame"]
    argv += ["flange", "--time-offset", DELAY_S, "--out", tmp_path / "d.json"]
    code, stdout, stderr = run_cli(argv, capsys)
    assert code == 0, stderr
    assert (
        f"kept {349 - n_gap} of 349 measurements, dropped {n_gap}: {n_gap} gap (joint "
        "states more than 0.05 s apart)" in stdout
    )
    assert read_measurements(tmp_path / "d.json").n_samples == 349 - n_gap


def test_user_errors_exit_2_naming_the_bag_and_topic(recording, urdf, tmp_path, capsys):
    bag = write_bag(tmp_path / "rec", recording)
    out = tmp_path / "d.json"
    base = ["-q", "import-bag", bag, "--urdf", urdf, "--frame", "flange", "--out", out]
    cases = [
        (["--pose", "/vicon/pose"], f"{bag}: no topic '/vicon/pose' (expected geometry_msgs/"),
        (["--pose", "/mocap/pose", "--joint-states", "/js"], "the bag has: /joint_states ("),
        (["--point", "/mocap/point", "--time-offset", "auto"], "estimated from poses"),
        (["--pose", "/mocap/pose", "--time-offset", "30"], "lies within the joint states"),
        (["--pose", "/mocap/pose", "--still", "0.001"], "every measurement of /mocap/pose was"),
        (["--tf", "room", "camera"], "no TF frame 'camera'; the TF tree has ['mocap', 'rigid"),
        (["--pose", "/mocap/pose", "--time-offset", "soon"], "expected 'auto' or seconds"),
    ]
    for extra, message in cases:
        code, _, stderr = run_cli([*base, *extra], capsys)
        assert code == 2, (extra, stderr)
        assert stderr.startswith("kinfw import-bag: error: ") and message in stderr, stderr
        assert not out.exists()


@pytest.mark.slow
def test_images_go_to_a_folder_that_detect_reads(recording, urdf, tmp_path, capsys):
    """``--images``: the PNGs, joints.csv and images.json in --out; the still filter
    keeps the images where no joint moved faster than the threshold."""
    import json

    from kinfw.measurements import IMAGE_JOINTS_CSV, IMAGE_STAMPS_JSON

    bag = write_bag(tmp_path / "cam", recording, images=True)
    out = tmp_path / "images"
    argv = ["-q", "import-bag", bag, "--urdf", urdf, "--images", "/camera/rgb", "--out", out]
    code, stdout, stderr = run_cli([*argv, "--time-offset", "0.05"], capsys)
    assert code == 0, stderr
    record = json.loads((out / IMAGE_STAMPS_JSON).read_text())
    n = len(record["images"])
    assert f"wrote {out}: {n} images, {IMAGE_JOINTS_CSV} (joints j1, " in stdout
    assert sorted(p.name for p in out.glob("image_*.png")) == [i["file"] for i in record["images"]]
    # offset 5 ms: image k (0.1 k + 0.05 s) pairs with the joints mid-way between samples
    # 10 k + 4 and 10 k + 5; kept when every joint's speed there is at most 1 rad/s
    still = [*argv[:-1], tmp_path / "still", "--time-offset", "0.005", "--still", "1.0"]
    code, stdout, stderr = run_cli(still, capsys)
    assert code == 0, stderr
    j = 10 * np.arange(n) + 4
    speeds = np.abs(recording.q_joints[j + 1] - recording.q_joints[j]).max(axis=1) / 0.01
    n_still = int(np.count_nonzero(speeds <= 1.0))
    assert 0 < n_still < n
    assert (
        f"kept {n_still} of {n} measurements, dropped {n - n_still}: {n - n_still} moving (a "
        in stdout
    )
    code, _, stderr = run_cli([*argv[:-1], tmp_path / "x", "--time-offset", "auto"], capsys)
    assert code == 2 and "--time-offset auto needs poses" in stderr
    no_frame = ["-q", "import-bag", bag, "--urdf", urdf, "--pose", "/mocap/pose", "--out", out]
    code, _, stderr = run_cli([*no_frame[:-1], tmp_path / "y.json"], capsys)
    assert code == 2 and "--frame is required with --pose" in stderr
