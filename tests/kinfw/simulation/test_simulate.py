"""Tests of kinfw.simulation against independent Pinocchio forward kinematics."""

from __future__ import annotations

from xml.etree import ElementTree

import numpy as np
import pinocchio as pin
import pytest

from kinfw.geometry import inverse_transform, rotation_angle, rotation_vector_from_matrix
from kinfw.measurements import Measurements
from kinfw.model import load_robot
from kinfw.observations import PoseObservations
from kinfw.simulation import (
    default_target_pose,
    nine_circle_plate,
    one_joint_at_a_time,
    perturb_poses,
    perturb_robot,
    random_configurations,
    simulate_at,
    stereo_measure,
)
from tests.paths import HEAD_URDF
from tests.pin_se3 import pin_fk

IIS_HEAD = HEAD_URDF

# A 3-joint arm (continuous, revolute, prismatic) on a fixed base, with an intermediate
# fixed mount, a fixed flange and a fixed camera on the flange.
ARM_URDF = """<?xml version="1.0"?>
<robot name="arm3">
  <link name="world"/>
  <link name="base_link"/>
  <link name="link1"/>
  <link name="link2"/>
  <link name="mount"/>
  <link name="link3"/>
  <link name="flange"/>
  <link name="camera"/>
  <joint name="world_to_base" type="fixed">
    <parent link="world"/><child link="base_link"/>
    <origin xyz="0.2 -0.1 0.05" rpy="0.0 0.0 0.3"/>
  </joint>
  <joint name="j1" type="continuous">
    <parent link="base_link"/><child link="link1"/>
    <origin xyz="0.0 0.0 0.1" rpy="0.0 0.0 0.0"/>
    <axis xyz="0 0 1"/>
  </joint>
  <joint name="j2" type="revolute">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="0.05 0.0 0.3" rpy="0.1 0.0 0.0"/>
    <axis xyz="0 1 0"/>
    <limit lower="-1.5" upper="1.2" effort="10" velocity="1"/>
  </joint>
  <joint name="mount_joint" type="fixed">
    <parent link="link2"/><child link="mount"/>
    <origin xyz="0.2 0.0 0.0" rpy="0.0 0.2 0.0"/>
  </joint>
  <joint name="j3" type="prismatic">
    <parent link="mount"/><child link="link3"/>
    <origin xyz="0.2 0.01 0.0" rpy="0.0 0.0 0.0"/>
    <axis xyz="1 0 0"/>
    <limit lower="0.0" upper="0.2" effort="10" velocity="1"/>
  </joint>
  <joint name="flange_joint" type="fixed">
    <parent link="link3"/><child link="flange"/>
    <origin xyz="0.1 0.0 0.0" rpy="0.0 1.5707963267948966 0.0"/>
  </joint>
  <joint name="camera_joint" type="fixed">
    <parent link="flange"/><child link="camera"/>
    <origin xyz="0.05 0.03 0.04" rpy="0.0 0.0 -1.5707963267948966"/>
  </joint>
</robot>
"""
ARM_JOINTS = ("j1", "j2", "j3")
ARM_PERTURBED = ("world_to_base", "j1", "j2", "j3", "flange_joint", "camera_joint")


@pytest.fixture(scope="module")
def arm():
    return load_robot(ARM_URDF)


def random_qs(robot, n: int, seed: int) -> np.ndarray:
    return random_configurations(*robot.joint_limits(ARM_JOINTS), n, np.random.default_rng(seed))


# -- protocols ----------------------------------------------------------------------------


def test_one_joint_at_a_time_structure(arm) -> None:
    lower, upper = arm.joint_limits(ARM_JOINTS)
    per_joint, fraction = 9, 0.8
    qs, moved = one_joint_at_a_time(lower, upper, per_joint=per_joint, fraction=fraction)
    n_joints = len(ARM_JOINTS)
    assert qs.shape == (per_joint * n_joints + 1, n_joints)
    assert moved.shape == (per_joint * n_joints + 1,)
    assert moved.dtype == np.int64
    lo = np.where(np.isinf(lower), -np.pi, lower)
    hi = np.where(np.isinf(upper), np.pi, upper)
    q0 = qs[0]
    np.testing.assert_allclose(q0, 0.5 * (lo + hi), rtol=0, atol=1e-15)
    assert moved[0] == -1
    differs = ~np.isclose(qs, q0, rtol=0, atol=1e-12)
    assert not differs[0].any()
    np.testing.assert_array_equal(differs[1:].sum(axis=1), 1)  # exactly one joint moved
    np.testing.assert_array_equal(np.argmax(differs[1:], axis=1), moved[1:])
    assert np.all((qs >= lo) & (qs <= hi))
    for i in range(n_joints):
        values = qs[moved == i, i]
        assert len(values) == per_joint
        assert len(np.unique(values)) == per_joint  # distinct, none equal to q0
        half = 0.5 * fraction * (hi[i] - lo[i])
        np.testing.assert_allclose(
            [values.min(), values.max()], [q0[i] - half, q0[i] + half], rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(
            np.diff(np.sort(np.append(values, q0[i])))[[0, -1]], 2 * half / per_joint, rtol=1e-9
        )


def test_one_joint_at_a_time_given_q0_and_continuous_limits() -> None:
    lower, upper = np.array([-np.inf, 0.0]), np.array([np.inf, 0.5])
    q0 = np.array([0.3, 0.1])
    qs, moved = one_joint_at_a_time(lower, upper, per_joint=4, fraction=1.0, q0=q0)
    assert qs.shape == (9, 2)
    np.testing.assert_array_equal(qs[0], q0)
    np.testing.assert_array_equal(moved, [-1, 0, 0, 0, 0, 1, 1, 1, 1])
    assert np.all(np.abs(qs[:, 0]) <= np.pi)
    np.testing.assert_array_equal(qs[moved == 0, 1], 0.1)
    np.testing.assert_array_equal(qs[moved == 1, 0], 0.3)
    assert 0.1 not in qs[moved == 1, 1]
    assert 0.3 not in qs[moved == 0, 0]


def test_one_joint_at_a_time_errors() -> None:
    with pytest.raises(ValueError, match="joint 1 has an empty range"):
        one_joint_at_a_time([0.0, 1.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="fraction: expected 0 < fraction <= 1"):
        one_joint_at_a_time([0.0], [1.0], fraction=1.5)
    with pytest.raises(ValueError, match="per_joint: expected at least 1"):
        one_joint_at_a_time([0.0], [1.0], per_joint=0)
    with pytest.raises(ValueError, match="joint 0 has lower 2 > upper 1"):
        one_joint_at_a_time([2.0], [1.0])
    with pytest.raises(ValueError, match="q0: expected 2 finite values"):
        one_joint_at_a_time([0.0, 0.0], [1.0, 1.0], q0=[0.5])


def test_random_configurations_within_limits(arm) -> None:
    lower, upper = arm.joint_limits(ARM_JOINTS)
    lo = np.where(np.isinf(lower), -np.pi, lower)
    hi = np.where(np.isinf(upper), np.pi, upper)
    qs = random_configurations(lower, upper, 5000, np.random.default_rng(0), fraction=0.5)
    assert qs.shape == (5000, 3)
    mid, half = 0.5 * (lo + hi), 0.25 * (hi - lo)
    assert np.all(np.abs(qs - mid) <= half)
    np.testing.assert_allclose(qs.min(axis=0), mid - half, rtol=0, atol=0.01 * half.max())
    np.testing.assert_allclose(qs.max(axis=0), mid + half, rtol=0, atol=0.01 * half.max())
    again = random_configurations(lower, upper, 5000, np.random.default_rng(0), fraction=0.5)
    np.testing.assert_array_equal(qs, again)


# -- noise --------------------------------------------------------------------------------


def test_perturb_poses_statistics() -> None:
    rng = np.random.default_rng(11)
    n, sigma_m, sigma_rad = 20000, 1e-3, np.deg2rad(0.5)
    truth = np.tile(np.eye(4), (n, 1, 1))
    truth[:, :3, 3] = rng.normal(size=(n, 3))
    truth[:, :3, :3] = pin.exp3(np.array([0.3, -1.0, 2.0]))
    noisy = perturb_poses(truth, rng, sigma_m, sigma_rad)
    assert noisy.shape == (n, 4, 4)
    dp = noisy[:, :3, 3] - truth[:, :3, 3]
    np.testing.assert_allclose(dp.std(axis=0), sigma_m, rtol=0.03)
    np.testing.assert_allclose(dp.mean(axis=0), 0.0, rtol=0, atol=4 * sigma_m / np.sqrt(n))
    dR = np.swapaxes(truth[:, :3, :3], 1, 2) @ noisy[:, :3, :3]
    np.testing.assert_allclose(np.linalg.det(noisy[:, :3, :3]), 1.0, rtol=0, atol=1e-12)
    angles = rotation_angle(dR)
    np.testing.assert_allclose(np.sqrt(np.mean(angles**2)), sigma_rad, rtol=0.03)
    np.testing.assert_allclose(angles.mean(), sigma_rad * np.sqrt(2 / np.pi), rtol=0.03)
    rotvecs = rotation_vector_from_matrix(dR)
    axes = rotvecs / np.linalg.norm(rotvecs, axis=1, keepdims=True)
    np.testing.assert_allclose(axes.mean(axis=0), 0.0, rtol=0, atol=0.02)
    np.testing.assert_allclose(axes.T @ axes / n, np.eye(3) / 3, rtol=0, atol=0.02)


def test_perturb_poses_zero_noise_and_single_pose() -> None:
    T = np.eye(4)
    T[:3, :3] = pin.exp3(np.array([0.1, 0.2, 0.3]))
    T[:3, 3] = [1.0, 2.0, 3.0]
    out = perturb_poses(T, np.random.default_rng(0), 0.0, 0.0)
    assert out.shape == (4, 4)
    np.testing.assert_array_equal(out, T)
    with pytest.raises(ValueError, match="sigma_m: expected a finite standard deviation"):
        perturb_poses(T, np.random.default_rng(0), -1.0, 0.0)


def test_nine_circle_plate() -> None:
    plate = nine_circle_plate(0.03)
    assert plate.shape == (9, 3)
    np.testing.assert_array_equal(plate[4], 0.0)
    np.testing.assert_array_equal(plate[:, 2], 0.0)
    np.testing.assert_allclose(plate.mean(axis=0), 0.0, rtol=0, atol=1e-15)
    dist = np.linalg.norm(plate[:, None] - plate[None], axis=-1)
    np.testing.assert_allclose(np.sort(dist[4])[1:5], 0.03, rtol=1e-12)
    np.testing.assert_allclose(dist.max(), 0.06 * np.sqrt(2), rtol=1e-12)


def test_stereo_measure_statistics() -> None:
    rng = np.random.default_rng(12)
    n, sigma = 4000, 5e-4
    truth = np.tile(np.eye(4), (n, 1, 1))
    truth[:, :3, :3] = pin.exp3(np.array([0.5, 0.2, -0.4]))
    truth[:, :3, 3] = [0.1, 0.0, 1.4]
    exact = stereo_measure(truth, rng, 0.0)
    np.testing.assert_allclose(exact, truth, rtol=0, atol=1e-12)
    meas = stereo_measure(truth, rng, sigma)
    err = meas[:, :3, 3] - truth[:, :3, 3]
    # The plate is centred on its origin: the position error is the mean of 9 point errors.
    np.testing.assert_allclose(np.sqrt(np.mean(err**2, axis=0)), sigma / 3, rtol=0.1)
    angles = rotation_angle(np.swapaxes(truth[:, :3, :3], 1, 2) @ meas[:, :3, :3])
    assert np.sqrt(np.mean(angles**2)) < 5 * sigma / 0.02


# -- the true robot -----------------------------------------------------------------------


def test_perturb_robot_zero_sigmas_keeps_kinematics(arm) -> None:
    xml = perturb_robot(arm, np.random.default_rng(0), origin_mm=0.0, origin_deg=0.0, axis_deg=0.0)
    qs = random_qs(arm, 20, 1)
    for frame in ("flange", "camera", "link2"):
        np.testing.assert_allclose(
            pin_fk(xml, ARM_JOINTS, qs, frame),
            pin_fk(ARM_URDF, ARM_JOINTS, qs, frame),
            rtol=0,
            atol=1e-12,
        )


def test_perturb_robot_error_sizes(arm) -> None:
    origin_mm, origin_deg, axis_deg = 2.0, 0.5, 0.3
    rng = np.random.default_rng(21)
    nominal = {j.name: j for j in arm.joints}
    dps, angles, tilts = [], [], []
    for _ in range(150):
        true = load_robot(
            perturb_robot(arm, rng, origin_mm=origin_mm, origin_deg=origin_deg, axis_deg=axis_deg)
        )
        for j in true.joints:
            nom = nominal[j.name]
            if j.name not in ARM_PERTURBED:  # the intermediate fixed mount stays nominal
                np.testing.assert_allclose(j.parent_T_child, nom.parent_T_child, rtol=0, atol=1e-12)
                continue
            dps.append(j.parent_T_child[:3, 3] - nom.parent_T_child[:3, 3])
            angles.append(rotation_angle(nom.parent_T_child[:3, :3].T @ j.parent_T_child[:3, :3]))
            if j.is_movable:
                # The origin rotation turns the axis with the child frame, so the tilt is
                # the angle between the axes in child coordinates.
                tilts.append(np.arccos(np.clip(j.axis @ nom.axis, -1.0, 1.0)))
        for axis in ElementTree.fromstring(true.urdf_xml).iter("axis"):  # as written
            xyz = np.array(axis.get("xyz").split(), dtype=float)
            assert abs(np.linalg.norm(xyz) - 1.0) < 1e-12
    dps = np.array(dps)
    np.testing.assert_allclose(dps.std(axis=0), origin_mm * 1e-3, rtol=0.1)
    np.testing.assert_allclose(
        np.sqrt(np.mean(np.square(angles))), np.deg2rad(origin_deg), rtol=0.1
    )
    np.testing.assert_allclose(np.sqrt(np.mean(np.square(tilts))), np.deg2rad(axis_deg), rtol=0.12)


def test_perturb_robot_changes_fk_by_about_the_requested_size(arm) -> None:
    qs = random_qs(arm, 50, 2)
    nominal = pin_fk(ARM_URDF, ARM_JOINTS, qs, "flange")
    rng = np.random.default_rng(22)
    rms = []
    for _ in range(20):
        xml = perturb_robot(arm, rng, origin_mm=1.0, origin_deg=0.0, axis_deg=0.0)
        diff = pin_fk(xml, ARM_JOINTS, qs, "flange")[:, :3, 3] - nominal[:, :3, 3]
        rms.append(np.sqrt(np.mean(np.sum(diff**2, axis=1))))
    # Translations only: the 5 perturbed joints before the flange add 15 independent
    # N(0, 1 mm) components, rotated but not scaled: E|error|^2 = 15 mm^2.
    np.testing.assert_allclose(np.sqrt(np.mean(np.square(rms))), np.sqrt(15) * 1e-3, rtol=0.15)


def test_perturb_robot_given_joints_only(arm) -> None:
    xml = perturb_robot(arm, np.random.default_rng(3), joints=["j2"])
    true = load_robot(xml)
    for j, nom in zip(true.joints, arm.joints, strict=True):
        same = np.allclose(j.parent_T_child, nom.parent_T_child, rtol=0, atol=1e-12)
        assert same == (j.name != "j2")
    with pytest.raises(KeyError, match="no joint 'nope'"):
        perturb_robot(arm, np.random.default_rng(3), joints=["nope"])


# -- datasets -----------------------------------------------------------------------------


def test_simulate_zero_noise_matches_pinocchio(arm) -> None:
    qs = random_qs(arm, 25, 3)
    w_T_target = default_target_pose(arm, qs, ARM_JOINTS, ["camera"])
    offset = np.array([0.01, -0.02, 0.03])
    m = simulate_at(
        arm,
        qs,
        ARM_JOINTS,
        frames=["flange", "link2"],
        cameras=["camera"],
        markers=[("flange", offset), ("link3", [0.0, 0.0, 0.05], "ball")],
        rng=np.random.default_rng(0),
    )
    assert isinstance(m, Measurements)
    assert m.joint_names == ARM_JOINTS
    np.testing.assert_array_equal(m.qs, qs)
    assert [g.frame for g in m.poses] == ["flange", "link2"]
    for g in m.poses:
        np.testing.assert_array_equal(g.sample, np.arange(25))
        assert g.measured_in is None and g.marker is None
        np.testing.assert_allclose(
            g.meas_T_frame, pin_fk(ARM_URDF, ARM_JOINTS, qs, g.frame), rtol=0, atol=1e-12
        )
    (tg,) = m.targets
    assert tg.camera == "camera" and tg.target == "target"
    w_T_cams = pin_fk(ARM_URDF, ARM_JOINTS, qs, "camera")
    np.testing.assert_allclose(
        tg.camera_T_target, inverse_transform(w_T_cams) @ w_T_target, rtol=0, atol=1e-12
    )
    known, named = m.points
    w_T_flanges = pin_fk(ARM_URDF, ARM_JOINTS, qs, "flange")
    np.testing.assert_allclose(
        known.meas_p_point,
        w_T_flanges[:, :3, :3] @ offset + w_T_flanges[:, :3, 3],
        rtol=0,
        atol=1e-12,
    )
    np.testing.assert_array_equal(known.offset, offset)
    assert known.marker is None
    assert named.offset is None and named.marker == "ball"
    w_T_link3s = pin_fk(ARM_URDF, ARM_JOINTS, qs, "link3")
    np.testing.assert_allclose(
        named.meas_p_point,
        w_T_link3s[:, :3, :3] @ [0.0, 0.0, 0.05] + w_T_link3s[:, :3, 3],
        rtol=0,
        atol=1e-12,
    )


def test_simulate_noise_statistics(arm) -> None:
    n, noise_m, noise_rad = 4000, 1e-3, np.deg2rad(0.2)
    qs = random_qs(arm, n, 4)
    w_T_target = default_target_pose(arm, qs[:10], ARM_JOINTS, ["camera"])
    m = simulate_at(
        arm,
        qs,
        ARM_JOINTS,
        frames=["flange"],
        cameras=["camera"],
        markers=[("flange", [0.0, 0.0, 0.02])],
        rng=np.random.default_rng(5),
        noise_m=noise_m,
        noise_rad=noise_rad,
        w_T_target=w_T_target,
    )
    truth = pin_fk(ARM_URDF, ARM_JOINTS, qs, "flange")
    expected_target = inverse_transform(pin_fk(ARM_URDF, ARM_JOINTS, qs, "camera")) @ w_T_target
    for meas, true in (
        (m.poses[0].meas_T_frame, truth),
        (m.targets[0].camera_T_target, expected_target),
    ):
        dp = meas[:, :3, 3] - true[:, :3, 3]
        np.testing.assert_allclose(dp.std(axis=0), noise_m, rtol=0.05)
        np.testing.assert_allclose(dp.mean(axis=0), 0.0, rtol=0, atol=4 * noise_m / np.sqrt(n))
        angles = rotation_angle(np.swapaxes(true[:, :3, :3], 1, 2) @ meas[:, :3, :3])
        np.testing.assert_allclose(np.sqrt(np.mean(angles**2)), noise_rad, rtol=0.05)
    dp = m.points[0].meas_p_point - (truth[:, :3, :3] @ [0.0, 0.0, 0.02] + truth[:, :3, 3])
    np.testing.assert_allclose(dp.std(axis=0), noise_m, rtol=0.05)


def test_simulate_stereo_rig(arm) -> None:
    n, sigma = 3000, 5e-4
    qs = random_qs(arm, n, 6)
    m = simulate_at(
        arm, qs, ARM_JOINTS, frames=["flange"], rng=np.random.default_rng(7), stereo_sigma_m=sigma
    )
    err = m.poses[0].meas_T_frame[:, :3, 3] - pin_fk(ARM_URDF, ARM_JOINTS, qs, "flange")[:, :3, 3]
    np.testing.assert_allclose(np.sqrt(np.mean(err**2, axis=0)), sigma / 3, rtol=0.1)


def test_simulate_is_reproducible_and_defaults_to_robot_joints(arm) -> None:
    qs = random_qs(arm, 5, 8)
    a = simulate_at(arm, qs, None, frames=["flange"], rng=np.random.default_rng(1), noise_m=1e-3)
    b = simulate_at(
        arm, qs, ARM_JOINTS, frames=["flange"], rng=np.random.default_rng(1), noise_m=1e-3
    )
    assert a.joint_names == arm.joint_names
    np.testing.assert_array_equal(a.poses[0].meas_T_frame, b.poses[0].meas_T_frame)


def test_simulate_keeps_its_random_stream(arm) -> None:
    """Draw by draw as before the kinds simulated their groups: each frame's pose noise
    (perturb_poses), then each camera's, then each marker's N(0, noise_m) (n, 3)."""
    qs = random_qs(arm, 6, 10)
    offset = np.array([0.0, 0.01, 0.02])
    m = simulate_at(
        arm,
        qs,
        ARM_JOINTS,
        frames=["flange", "link2"],
        cameras=["camera"],
        markers=[("flange", offset), ("link3", offset, "ball")],
        rng=np.random.default_rng(4),
        noise_m=1e-3,
        noise_rad=2e-3,
    )
    rng = np.random.default_rng(4)
    w_T = {f: pin_fk(ARM_URDF, ARM_JOINTS, qs, f) for f in ("flange", "link2", "link3", "camera")}
    for g, frame in zip(m.poses, ("flange", "link2"), strict=True):
        np.testing.assert_allclose(
            g.meas_T_frame, perturb_poses(w_T[frame], rng, 1e-3, 2e-3), rtol=0, atol=1e-12
        )
    w_T_target = default_target_pose(arm, qs, ARM_JOINTS, ["camera"])
    np.testing.assert_allclose(
        m.targets[0].camera_T_target,
        perturb_poses(inverse_transform(w_T["camera"]) @ w_T_target, rng, 1e-3, 2e-3),
        rtol=0,
        atol=1e-12,
    )
    for g, frame in zip(m.points, ("flange", "link3"), strict=True):
        expected = w_T[frame][:, :3, :3] @ offset + w_T[frame][:, :3, 3]
        np.testing.assert_allclose(
            g.meas_p_point, expected + rng.normal(0.0, 1e-3, (6, 3)), rtol=0, atol=1e-12
        )


def test_simulate_errors(arm) -> None:
    qs = random_qs(arm, 2, 9)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="nothing to observe"):
        simulate_at(arm, qs, ARM_JOINTS, rng=rng)
    with pytest.raises(ValueError, match=r"expected \(frame, offset\) or \(frame, offset, name\)"):
        simulate_at(arm, qs, ARM_JOINTS, markers=["flange"], rng=rng)
    with pytest.raises(ValueError, match="offset of a marker on 'flange'"):
        simulate_at(arm, qs, ARM_JOINTS, markers=[("flange", [1.0, 2.0])], rng=rng)
    with pytest.raises(KeyError, match="no frame 'nope'"):
        simulate_at(arm, qs, ARM_JOINTS, frames=["nope"], rng=rng)
    with pytest.raises(ValueError, match="noise_rad: expected a finite standard deviation"):
        simulate_at(arm, qs, ARM_JOINTS, frames=["flange"], rng=rng, noise_rad=np.nan)
    with pytest.raises(ValueError, match=r"sigmas\['distance'\]: expected a finite"):
        simulate_at(arm, qs, ARM_JOINTS, frames=["flange"], rng=rng, sigmas={"distance": -1.0})
    template = PoseObservations("flange", [0, 2], np.tile(np.eye(4), (2, 1, 1)))
    with pytest.raises(ValueError, match="refers to sample 2, but qs has 2 rows"):
        simulate_at(arm, qs, ARM_JOINTS, groups=[template], rng=rng)
    with pytest.raises(TypeError, match="not the group of a registered observation kind"):
        simulate_at(arm, qs, ARM_JOINTS, groups=[object()], rng=rng)
    marked = PoseObservations("flange", [0, 1], np.tile(np.eye(4), (2, 1, 1)), marker="m")
    with pytest.raises(ValueError, match="needs the true value of marker:m; give it in"):
        simulate_at(arm, qs, ARM_JOINTS, groups=[marked], rng=rng)


def test_default_target_pose_faces_the_cameras(arm) -> None:
    qs = random_qs(arm, 30, 10) * np.array([0.1, 0.1, 1.0])  # a small working region
    w_T_target = default_target_pose(arm, qs, ARM_JOINTS, ["camera"], distance=0.8)
    R = w_T_target[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=0, atol=1e-12)
    w_T_cams = pin_fk(ARM_URDF, ARM_JOINTS, qs, "camera")
    mean_z = w_T_cams[:, :3, 2].mean(axis=0)
    mean_z /= np.linalg.norm(mean_z)
    np.testing.assert_allclose(
        w_T_target[:3, 3], w_T_cams[:, :3, 3].mean(axis=0) + 0.8 * mean_z, rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(R[:, 2], -mean_z, rtol=0, atol=1e-12)
    camera_T_targets = inverse_transform(w_T_cams) @ w_T_target
    assert np.all(camera_T_targets[:, 2, 3] > 0.5)  # in front of every camera
    assert np.all(camera_T_targets[:, 2, 2] < -0.9)  # facing back at it
    with pytest.raises(ValueError, match="at least one camera frame"):
        default_target_pose(arm, qs, ARM_JOINTS, [])


# -- the IIS-head -------------------------------------------------------------------------


def test_iis_head_one_joint_at_a_time_zero_noise() -> None:
    head = load_robot(IIS_HEAD)
    xml = IIS_HEAD.read_text(encoding="utf-8")
    names = head.joint_names
    qs, moved = one_joint_at_a_time(*head.joint_limits(names), per_joint=9, fraction=0.8)
    assert qs.shape == (9 * len(names) + 1, len(names))
    np.testing.assert_array_equal(np.bincount(moved[1:]), 9)
    frames, cameras = ("left_plate", "right_plate"), ("left_camera", "right_camera")
    m = simulate_at(head, qs, names, frames=frames, cameras=cameras, rng=np.random.default_rng(0))
    assert [g.frame for g in m.poses] == list(frames)
    for g in m.poses:
        np.testing.assert_allclose(
            g.meas_T_frame, pin_fk(xml, names, qs, g.frame), rtol=0, atol=1e-12
        )
    w_T_target = default_target_pose(head, qs, names, cameras)
    for g in m.targets:
        w_T_cams = pin_fk(xml, names, qs, g.camera)
        np.testing.assert_allclose(
            g.camera_T_target, inverse_transform(w_T_cams) @ w_T_target, rtol=0, atol=1e-12
        )
        assert np.median(g.camera_T_target[:, 2, 3]) > 0.0  # mostly in front of the camera


def test_iis_head_perturbed_truth() -> None:
    head = load_robot(IIS_HEAD)
    names = head.joint_names
    qs = random_configurations(*head.joint_limits(names), 30, np.random.default_rng(1))
    true = load_robot(perturb_robot(head, np.random.default_rng(2)))
    assert true.joint_names == names
    changed = {
        j.name
        for j, nom in zip(true.joints, head.joints, strict=True)
        if not np.allclose(j.parent_T_child, nom.parent_T_child, rtol=0, atol=1e-12)
    }
    assert changed == {
        "world_to_base",
        *names,
        "left_plate_joint",
        "right_plate_joint",
        "left_camera_joint",
        "right_camera_joint",
    }
    for frame in ("left_plate", "right_plate"):
        diff = (
            pin_fk(true.urdf_xml, names, qs, frame)[:, :3, 3]
            - pin_fk(head.urdf_xml, names, qs, frame)[:, :3, 3]
        )
        assert 1e-3 < np.sqrt(np.mean(np.sum(diff**2, axis=1))) < 0.05
