"""Calibration report: units of every parameter, fixed parameters, down-weighted
observations named (in the JSON and on screen)."""

import contextlib
import io
import json
import re
from dataclasses import replace

import numpy as np
import pytest

from kinfw.cli._main import main
from kinfw.identification.problem import build_problem
from kinfw.measurements import read_measurements, write_measurements
from kinfw.model import cpc_from_robot, load_robot
from kinfw.simulation import default_target_pose, perturb_robot, random_configurations, simulate_at
from tests.paths import HEAD_URDF as HEAD

PLATES = ("left_plate", "right_plate")
CAMERAS = ("left_camera", "right_camera")
#: Gross position errors added to left_plate pose observations (mm), in file order.
OUTLIERS_MM = (20.0, 70.0, 40.0, 80.0, 30.0, 60.0, 50.0)

# Units by hand, from what each parameter is (docstrings of kinfw.model and refine).
HAND_UNITS = {
    ("pan", "zero_offset"): "rad",  # revolute: an angle
    ("tilt", "zero_offset"): "rad",
    ("vergence_left", "zero_offset"): "rad",
    ("x_table", "zero_offset"): "m",  # prismatic: a length
    ("y_table", "zero_offset"): "m",
    ("pan", "b_tilt_1"): "rad",  # tilt of the CPC axis
    ("x_table", "b_tilt_2"): "rad",
    ("pan", "l_x"): "m",
    ("tilt", "l_y"): "m",
    ("left_plate", "rot_y"): "rad",  # tool transform of an end frame
    ("left_plate", "z"): "m",
    ("base", "rot_x"): "rad",
    ("base", "x"): "m",
    ("target:target", "rot_z"): "rad",
    ("target:target", "y"): "m",
}
# The kinematic rows of CPCModel.describe, by hand.
HAND_KINEMATIC_UNITS = {
    ("pan", "b_x"): "unitless",  # component of the CPC unit axis b
    ("x_table", "b_z"): "unitless",
    ("pan", "beta"): "rad",
    ("pan", "l_z"): "m",
    ("pan", "sign"): "unitless",
    ("left_camera", "roll"): "rad",  # URDF rpy of an end frame
    ("left_camera", "yaw"): "rad",
    ("left_camera", "x"): "m",
}


@pytest.fixture(scope="module")
def head():
    return load_robot(HEAD)


@pytest.fixture(scope="module")
def problem(head):
    rng = np.random.default_rng(0)
    names = head.topology((*PLATES, *CAMERAS)).joint_names
    lower, upper = head.joint_limits(names)
    qs = random_configurations(lower, upper, 8, rng, fraction=0.8)
    data = simulate_at(
        head,
        qs,
        names,
        frames=PLATES,
        cameras=CAMERAS,
        rng=rng,
        w_T_target=default_target_pose(head, qs, names, CAMERAS),
    )
    return build_problem(head, data, parameters="offsets")


def test_parameter_units_of_the_head_match_the_hand_list(problem):
    assert problem.model0.topology.revolute == (False, False, True, True, True, True)
    unit = dict(zip(problem.names, problem.units, strict=True))
    for name, expected in HAND_UNITS.items():
        assert unit[name] == expected, name
    assert set(problem.units) == {"rad", "m"}


def test_every_zero_offset_has_the_unit_of_its_urdf_joint_type(head, problem):
    offsets = [
        (o, u) for (o, f), u in zip(problem.names, problem.units, strict=True) if f == "zero_offset"
    ]
    assert [o for o, _ in offsets] == list(problem.model0.topology.joint_names)
    for owner, unit in offsets:  # the URDF joint itself says revolute or prismatic
        assert unit == ("rad" if head.joint(owner).is_revolute else "m"), owner


def test_the_kinematic_rows_carry_their_units(head):
    model = cpc_from_robot(head, (*PLATES, *CAMERAS))
    unit = {(o, n): u for o, n, _, u in model.describe()}
    for name, expected in HAND_KINEMATIC_UNITS.items():
        assert unit[name] == expected, name
    assert set(unit.values()) == {"rad", "m", "unitless"}


@pytest.fixture(scope="module")
def outlier_run(tmp_path_factory, head):
    """Calibrate (huber) on head data with gross errors of known size on 7 observations."""
    rng = np.random.default_rng(11)
    truth = load_robot(perturb_robot(head, rng, origin_mm=5.0, origin_deg=1.0, axis_deg=1.0))
    names = head.topology((*PLATES, *CAMERAS)).joint_names
    lower, upper = head.joint_limits(names)
    qs = random_configurations(lower, upper, 60, rng, fraction=0.8)
    data = simulate_at(
        truth,
        qs,
        names,
        frames=PLATES,
        cameras=CAMERAS,
        rng=rng,
        w_T_target=default_target_pose(truth, qs, names, CAMERAS),
        noise_m=0.3e-3,
        noise_rad=np.radians(0.2),
    )
    (k,) = [k for k, g in enumerate(data.poses) if g.frame == "left_plate"]
    pose = data.poses[k]
    rows = np.arange(3, 3 + 7 * 5, 5)
    directions = rng.normal(size=(7, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    T = pose.meas_T_frame.copy()
    T[rows, :3, 3] += 1e-3 * np.array(OUTLIERS_MM)[:, None] * directions
    poses = list(data.poses)
    poses[k] = replace(pose, meas_T_frame=T)
    out = tmp_path_factory.mktemp("report")
    write_measurements(out / "data.json", replace(data, poses=tuple(poses)))
    screen = io.StringIO()
    with contextlib.redirect_stdout(screen):
        code = main(
            [
                "calibrate",
                str(out / "data.json"),
                "--urdf",
                str(HEAD),
                "--out",
                str(out / "cal.urdf"),
                "--report",
                str(out / "report.json"),
                # the true head is 5 mm / 1 deg off per axis: the guard's bound for that
                "--max-change-mm",
                "43.3",
                "--max-change-deg",
                "8.66",
            ]
        )
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    return {
        "samples": pose.sample[rows],
        "report": report,
        "screen": screen.getvalue(),
        "data": read_measurements(out / "data.json"),
        "dir": out,
    }


@pytest.mark.slow
def test_gross_errors_are_rejected_and_named_worst_first(outlier_run):
    rejected = outlier_run["report"]["refine"]["rejected"]
    excess = [row["excess"] for row in rejected]
    assert excess == sorted(excess, reverse=True) and all(e > 1 for e in excess)
    # the injected errors (20-80 mm on 0.3 mm noise), largest first, are rejected with
    # their own size; clean rejections are rare (0.1 %) and come after them
    assert len(rejected) <= 7 + 2
    order = np.argsort(OUTLIERS_MM)[::-1]
    for row, c in zip(rejected[:7], order, strict=True):
        assert (row["sample"], row["kind"], row["frame"], row["marker"]) == (
            int(outlier_run["samples"][c]),
            "pose",
            "left_plate",
            None,
        )
        assert row["position_residual_mm"] == pytest.approx(OUTLIERS_MM[c], abs=3.0)
        assert row["rotation_residual_deg"] < 1.5  # orientation untouched: noise and fit
    # rejected, so not merely down-weighted
    planted = {int(s) for s in outlier_run["samples"]}
    down = outlier_run["report"]["refine"]["downweighted"]
    assert not planted & {row["sample"] for row in down if row["frame"] == "left_plate"}
    assert all(0 < row["weight"] < 1 for row in down)


@pytest.mark.slow
def test_rejected_residuals_equal_the_calibrated_urdf_against_the_file(outlier_run):
    """Independent of the refine plumbing: the written URDF's FK against the file."""
    calibrated = load_robot(outlier_run["dir"] / "cal.urdf")
    data = outlier_run["data"]
    (pose,) = [g for g in data.poses if g.frame == "left_plate"]
    names = data.joint_names
    for row in outlier_run["report"]["refine"]["rejected"][:7]:
        i = int(np.flatnonzero(pose.sample == row["sample"])[0])
        predicted = calibrated.frame_poses(data.qs[row["sample"]][None], "left_plate", names)
        error_mm = 1e3 * np.linalg.norm(pose.meas_T_frame[i, :3, 3] - predicted[0, :3, 3])
        assert row["position_residual_mm"] == pytest.approx(error_mm, abs=0.05)


@pytest.mark.slow
def test_fixed_parameters_are_written_as_fixed_with_their_units(outlier_run):
    params = outlier_run["report"]["refine"]["parameters"]
    joints = ("x_table", "y_table", "pan", "tilt", "vergence_left", "vergence_right")
    # parameters="full": the base and the joint zero offsets are redundant with the chart
    expected_fixed = {("base", f) for f in ("rot_x", "rot_y", "rot_z", "x", "y", "z")} | {
        (j, "zero_offset") for j in joints
    }
    assert {(p["owner"], p["field"]) for p in params if p["fixed"]} == expected_fixed
    for p in params:
        if p["fixed"]:
            assert p["std"] is None and p["delta_from_start"] == 0.0
        else:
            assert p["std"] > 0
    unit = {(p["owner"], p["field"]): p["unit"] for p in params}
    assert unit[("pan", "zero_offset")] == "rad" and unit[("x_table", "zero_offset")] == "m"
    assert unit[("pan", "b_tilt_1")] == "rad" and unit[("pan", "l_x")] == "m"
    kinematics = {
        (k["owner"], k["name"]): k["unit"] for k in outlier_run["report"]["refine"]["kinematics"]
    }
    assert kinematics[("pan", "b_x")] == "unitless" and kinematics[("pan", "beta")] == "rad"


@pytest.mark.slow
def test_the_screen_names_the_rejected_worst_first(outlier_run):
    screen = outlier_run["screen"]
    rejected = outlier_run["report"]["refine"]["rejected"]
    listed = re.findall(
        r"rejected as a gross error: samples\[(\d+)\] left_plate \(pose\): residual "
        r"([\d.]+) mm",
        screen,
    )
    assert [int(s) for s, _ in listed] == [row["sample"] for row in rejected]
    down = outlier_run["report"]["refine"]["downweighted"]
    if down:
        assert f"{len(down)} observations down-weighted by the huber loss" in screen
    assert "parameters: 50 estimated, 12 fixed" in screen
