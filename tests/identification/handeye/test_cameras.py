"""Stage 2: hand-eye of every camera and the target pose, on simulated data."""

import warnings

import numpy as np
import pytest

from kinfw.identification import identify
from kinfw.identification.handeye import calibrate_cameras, camera_mount
from kinfw.measurements import concatenate_measurements
from kinfw.model import load_robot
from kinfw.observations import DatasetError
from kinfw.simulation import (
    default_target_pose,
    one_joint_at_a_time,
    perturb_robot,
    random_configurations,
    simulate_at,
)
from kinfw.urdf import edit_urdf
from kinfw.verification.evaluation import pose_discrepancy, random_joint_values
from tests.paths import HEAD_URDF as HEAD

CAMERAS = ("left_camera", "right_camera")

ARM_WITH_CAMERA = """<?xml version="1.0"?>
<robot name="arm_cam">
  <link name="world"/>
  <joint name="j1" type="revolute"><parent link="world"/><child link="l1"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <link name="l1"/>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.2" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <link name="l2"/>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="flange"/>
    <origin xyz="0.4 0 0" rpy="0 1.5707963267948966 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <link name="flange"/>
  <joint name="camera_joint" type="fixed"><parent link="flange"/><child link="camera"/>
    <origin xyz="0.05 0 0.03" rpy="0 0 0.2"/></joint>
  <link name="camera"/>
</robot>
"""


def test_a_camera_on_an_arm_with_trusted_kinematics_gives_its_mount_and_the_target():
    """The everyday hand-eye job: only target observations, nominal kinematics exact."""
    nominal = load_robot(ARM_WITH_CAMERA)
    rng = np.random.default_rng(0)
    mount = np.eye(4)
    mount[:3, 3] = [0.03, -0.02, 0.06]
    mount[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    truth = load_robot(edit_urdf(nominal.urdf_xml, joint_origins={"camera_joint": mount}))
    names = nominal.joint_names
    lower, upper = nominal.joint_limits(names)
    qs = random_configurations(lower, upper, 12, rng, fraction=0.5)
    w_T_target = default_target_pose(truth, qs, names, ("camera",))
    data = simulate_at(truth, qs, names, cameras=("camera",), rng=rng, w_T_target=w_T_target)
    result = calibrate_cameras(nominal, data)
    (cam,) = result.cameras
    assert (cam.joint, cam.hand) == ("camera_joint", "flange")
    np.testing.assert_allclose(cam.hand_T_camera, mount, atol=1e-9)
    np.testing.assert_allclose(cam.root_T_target, w_T_target, atol=1e-9)


@pytest.mark.slow
def test_both_stages_give_the_true_cameras_through_the_urdf():
    nominal = load_robot(HEAD)
    rng = np.random.default_rng(1)
    truth = load_robot(perturb_robot(nominal, rng, origin_mm=10.0, origin_deg=2.0, axis_deg=2.0))
    plates = ("left_plate", "right_plate")
    names = nominal.topology((*plates, *CAMERAS)).joint_names
    lower, upper = nominal.joint_limits(names)
    qs1, _ = one_joint_at_a_time(lower, upper, per_joint=4)
    qs2 = random_configurations(lower, upper, 15, rng, fraction=0.8)
    w_T_target = default_target_pose(truth, qs2, names, CAMERAS)
    data = concatenate_measurements(
        simulate_at(truth, qs1, names, frames=plates, rng=rng),
        simulate_at(truth, qs2, names, cameras=CAMERAS, rng=rng, w_T_target=w_T_target),
    )
    result = identify(nominal, data)
    calibrated = load_robot(result.urdf_xml)
    qs = random_joint_values(nominal, names, 100, np.random.default_rng(2))
    for frame in (*plates, *CAMERAS):
        dp, dr = pose_discrepancy(
            calibrated.frame_poses(qs, frame, names), truth.frame_poses(qs, frame, names)
        )
        assert dp < 1e-9 and dr < 1e-9, (frame, dp, dr)
    ((_, pose),) = result.cameras.root_T_targets
    np.testing.assert_allclose(pose, w_T_target, atol=1e-9)
    assert result.cameras.target_spread[0][1] < 1e-9


def test_nothing_to_calibrate_is_explained():
    nominal = load_robot(ARM_WITH_CAMERA)
    data = simulate_at(
        nominal,
        np.zeros((3, 3)),
        nominal.joint_names,
        markers=(("flange", np.zeros(3)),),
        rng=np.random.default_rng(0),
    )
    with pytest.raises(DatasetError, match="nothing to calibrate"):
        identify(nominal, data, method="closed-form")
    with pytest.raises(DatasetError, match="joint 'j1' moves through 1 distinct value"):
        identify(nominal, data)


def test_a_camera_without_a_fixed_mount_is_refused():
    robot = load_robot(ARM_WITH_CAMERA)
    with pytest.raises(
        DatasetError, match="camera frame 'flange' must be a link attached by a fixed joint"
    ):
        camera_mount(robot, "flange")
    assert camera_mount(robot, "camera") == ("camera_joint", "flange")


def test_a_hand_eye_the_motions_barely_determine_is_warned_with_its_sigma():
    """Issue 13, "never silently wrong": the same arm turned by at most ~1 deg between
    views, with 0.5 deg + 1 mm camera noise: the mount comes with a warning that it is
    poorly determined, with its sigma; well-spread views of the same camera give none."""
    nominal = load_robot(ARM_WITH_CAMERA)
    names = nominal.joint_names
    lower, upper = nominal.joint_limits(names)

    def views(fraction, seed):
        rng = np.random.default_rng(seed)
        qs = random_configurations(lower, upper, 10, rng, fraction=fraction)
        w_T_target = default_target_pose(nominal, qs, names, ("camera",))
        data = simulate_at(
            nominal,
            qs,
            names,
            cameras=("camera",),
            rng=rng,
            w_T_target=w_T_target,
            noise_m=1e-3,
            noise_rad=np.radians(0.5),
        )
        return data

    poorly = r"camera 'camera': hand-eye poorly determined \(camera_T_hand: sigma"
    with pytest.warns(UserWarning, match=poorly):
        calibrate_cameras(nominal, views(0.01, 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        calibrate_cameras(nominal, views(0.8, 2))
