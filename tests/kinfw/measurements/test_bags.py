"""ROS 1 and ROS 2 bags into measurements (:mod:`kinfw.measurements`: ``_bag_read.py``,
``_bag_align.py``, ``_bag_images.py``).

The bags are written here with rosbags' writers from a simulated arm (``tests/bags.py``):
what is read back is compared with what was written, interpolation with hand-computed
values, the time offset with the simulated stamp delay."""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest

from kinfw.identification.handeye import best_time_offset
from kinfw.measurements import (
    JointStates,
    joint_values_at,
    measurements_from_bag,
    mounted_robot,
    read_bag,
    time_offset_streams,
)
from kinfw.model import load_robot
from kinfw.observations import DatasetError
from tests.bags import DELAY_S, EPOCH_S, ROOM_T_MOCAP, simulated_recording, write_bag


@pytest.fixture(scope="module")
def recording():
    return simulated_recording()


@pytest.fixture(scope="module")
def bags(recording, tmp_path_factory):
    root = tmp_path_factory.mktemp("bags")
    return {
        1: write_bag(root / "r1.bag", recording, ros=1),
        2: write_bag(root / "r2", recording),
        "mcap": write_bag(root / "r2_mcap", recording, mcap=True),
    }


@pytest.mark.parametrize("ros", [1, 2, "mcap"])
def test_bags_read_back_the_written_streams(recording, bags, ros):
    """ROS 1, ROS 2 (SQLite and MCAP storage): joints in URDF order whatever the message
    order, the extra joint ignored; stamps from the first message; the poses as written."""
    bag = read_bag(bags[ros], robot=recording.nominal, pose="/mocap/pose")
    assert bag.ros_version == (1 if ros == 1 else 2)
    assert bag.t0_ns == EPOCH_S * 10**9  # the first joint state, at t = 0
    joints = bag.joints
    assert joints.names == recording.joint_names and joints.ignored == ("gripper_finger_joint",)
    assert joints.n_messages == len(recording.t_joints)
    for j in range(6):
        np.testing.assert_allclose(joints.t_s[j], recording.t_joints, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(joints.qs[j], recording.q_joints[:, j])
    measured = bag.measured
    assert (measured.kind, measured.parent, measured.source) == ("pose", "mocap", "/mocap/pose")
    np.testing.assert_allclose(measured.t_s, recording.t_mocap, rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        measured.parent_T_childs, recording.mocap_T_markers, rtol=0, atol=1e-12
    )
    assert ("/mocap/pose", "geometry_msgs/msg/PoseStamped", len(recording.t_mocap)) in bag.topics


def test_tf_chain_composes_the_static_and_the_moving_edge(recording, bags):
    """``room -> rigid_body``: the static ``room -> mocap`` times the moving mocap pose."""
    bag = read_bag(bags[2], robot=recording.nominal, tf=("room", "rigid_body"))
    np.testing.assert_allclose(
        bag.measured.parent_T_childs, ROOM_T_MOCAP @ recording.mocap_T_markers, atol=1e-12
    )
    assert (bag.measured.parent, bag.measured.source) == ("room", "/tf room -> rigid_body")
    # the other way round is the inverse
    back = read_bag(bags[2], robot=recording.nominal, tf=("rigid_body", "room"))
    np.testing.assert_allclose(
        back.measured.parent_T_childs @ bag.measured.parent_T_childs,
        np.broadcast_to(np.eye(4), bag.measured.parent_T_childs.shape),
        atol=1e-12,
    )
    with pytest.raises(DatasetError, match=r"no TF frame 'camera'; the TF tree has \['mocap'"):
        read_bag(bags[2], robot=recording.nominal, tf=("room", "camera"))


def test_points_are_the_positions_and_measured_in_the_stamped_frame(recording, bags):
    bag = read_bag(bags[1], robot=recording.nominal, point="/mocap/point")
    assert bag.measured.kind == "point"
    np.testing.assert_allclose(
        bag.measured.parent_T_childs[:, :3, 3], recording.mocap_T_markers[:, :3, 3], atol=1e-12
    )
    data, alignment = measurements_from_bag(
        bag, robot=recording.nominal, frame="flange", marker="m", offset_s=DELAY_S
    )
    (group,) = data.points
    assert (group.marker, group.measured_in) == ("m", "mocap")
    assert len(alignment.kept) == alignment.n_measured == data.n_samples
    with pytest.raises(DatasetError, match="estimated from poses"):
        time_offset_streams(bag, recording.nominal, "flange")


def _line(slope: float, t: np.ndarray) -> JointStates:
    return JointStates("/js", ("j1",), (t,), (slope * t,), len(t), ())


def test_linear_joints_interpolate_exactly_and_drops_say_why():
    """Hand computation: a joint at 2 rad/s sampled at 0, 0.01, ..., 0.1, then 0.3."""
    t = np.r_[np.arange(11) * 0.01, 0.3]
    joints = _line(2.0, t)
    queries = np.array([0.005, 0.0731, 0.1, 0.2, 0.31, -0.01])
    qs, reasons = joint_values_at(joints, queries, max_gap_s=0.05)
    np.testing.assert_allclose(qs[:3, 0], 2.0 * queries[:3], rtol=0, atol=1e-15)
    assert reasons.tolist() == ["", "", "", "gap", "outside", "outside"]
    assert np.isnan(qs[3:]).all()
    _, reasons = joint_values_at(joints, queries[:3], still_speed=1.9)
    assert reasons.tolist() == ["moving"] * 3
    _, reasons = joint_values_at(joints, queries[:3], still_speed=2.1)
    assert reasons.tolist() == [""] * 3


def test_interpolation_error_estimate_is_exact_for_a_parabola():
    """q = t^2 (q'' = 2): between stamps h apart, the chord errs by s (1 - s) h^2."""
    t = np.arange(0.0, 1.0, 0.1)
    joints = JointStates("/js", ("j1",), (t,), (t**2,), len(t), ())
    query = np.array([0.45])  # s = 1/2, h = 0.1: error 0.0025
    qs, reasons = joint_values_at(joints, query, max_gap_s=None, max_interpolation_error=0.00251)
    assert reasons.tolist() == [""]
    np.testing.assert_allclose(qs[0, 0] - query[0] ** 2, 0.0025, rtol=1e-9)
    _, reasons = joint_values_at(joints, query, max_gap_s=None, max_interpolation_error=0.00249)
    assert reasons.tolist() == ["fast"]


def test_time_offset_recovered_from_the_nominal_urdf(recording, bags):
    """The estimator on the bag's streams (nominal FK, a few mm off the truth; 44 mocap
    samples) finds the simulated delay to its fine grid step, 1 ms."""
    bag = read_bag(bags[2], robot=recording.nominal, pose="/mocap/pose")
    streams = time_offset_streams(bag, recording.nominal, "flange")
    result = best_time_offset(*streams, step=8)
    assert abs(result.offset_s - DELAY_S) <= 1e-3


def test_an_offset_shifts_which_joint_values_pair_with_a_measurement(recording, bags):
    """At the true offset the joint values are the trajectory at the true instants."""
    from tests.bags import trajectory

    bag = read_bag(bags[2], robot=recording.nominal, pose="/mocap/pose")
    data, alignment = measurements_from_bag(
        bag, robot=recording.nominal, frame="flange", marker="m", offset_s=DELAY_S
    )
    assert alignment.dropped == {"outside": 0, "gap": 0, "fast": 0, "moving": 0}
    q_true = trajectory(recording.t_mocap - DELAY_S)
    # linear interpolation at 100 Hz of sines up to 0.7 Hz: error below h^2 max|q''| / 8
    np.testing.assert_allclose(data.qs, q_true, rtol=0, atol=0.01**2 * 20.0 / 8)
    (group,) = data.poses
    assert (group.marker, group.measured_in) == ("m", "mocap")
    with pytest.raises(DatasetError, match=r"no measurement of /mocap/pose .* lies within"):
        measurements_from_bag(bag, robot=recording.nominal, frame="flange", offset_s=30.0)
    with pytest.raises(DatasetError, match=r"every measurement .* dropped: 0 outside, 0 gap"):
        measurements_from_bag(bag, robot=recording.nominal, frame="flange", still_speed=1e-3)


def test_bag_errors_name_the_bag_topic_and_what_was_expected(recording, bags, tmp_path):
    robot = recording.nominal
    with pytest.raises(DatasetError, match=r"no topic '/vicon' .* the bag has: /joint_states"):
        read_bag(bags[1], robot=robot, pose="/vicon")
    with pytest.raises(DatasetError, match=r"'/mocap/point' is geometry_msgs/msg/PointStamped, "):
        read_bag(bags[1], robot=robot, pose="/mocap/point")
    with pytest.raises(DatasetError, match=r"no topic '/js'"):
        read_bag(bags[1], robot=robot, joint_states="/js", pose="/mocap/pose")
    other = load_robot(
        '<robot name="r"><link name="a"/><link name="b"/><joint name="q" type="revolute">'
        '<parent link="a"/><child link="b"/><limit lower="-1" upper="1" effort="1" '
        'velocity="1"/></joint></robot>'
    )
    with pytest.raises(DatasetError, match=r"publishes no joint of .* it has \['gripper_finger"):
        read_bag(bags[1], robot=other, pose="/mocap/pose")
    with pytest.raises(DatasetError, match="no such bag"):
        read_bag(tmp_path / "missing.bag", robot=robot, pose="/mocap/pose")
    with pytest.raises(DatasetError, match="exactly one measurement stream"):
        read_bag(bags[1], robot=robot, pose="/mocap/pose", point="/mocap/point")
    bag = read_bag(bags[1], robot=robot, pose="/mocap/pose")
    five = dataclasses.replace(
        bag.joints, names=bag.joints.names[:5], t_s=bag.joints.t_s[:5], qs=bag.joints.qs[:5]
    )
    with pytest.raises(DatasetError, match=r"joints \['j6'\] move 'flange' but are not on"):
        measurements_from_bag(dataclasses.replace(bag, joints=five), robot=robot, frame="flange")
    in_l3 = dataclasses.replace(bag, measured=dataclasses.replace(bag.measured, parent="l3"))
    with pytest.raises(DatasetError, match="measured in 'l3', a frame of the URDF other than"):
        measurements_from_bag(in_l3, robot=robot, frame="flange")


def test_missing_rosbags_names_the_extra(recording, bags, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)
    with pytest.raises(DatasetError, match=r'needs the rosbags package \(pip install "kinfw\[ros'):
        read_bag(bags[1], robot=recording.nominal, pose="/mocap/pose")


def test_images_are_written_with_their_joint_values_for_detect(recording, tmp_path):
    """rgb8 and big-endian mono16 images back pixel for pixel (PNG, BGR order on disk);
    each image's joint values are the trajectory at its stamp minus the offset (an
    offset of 0.05 s: image k, stamped 0.1 k + 0.05 s, pairs with the joints at 0.1 k);
    the CSV is what ``kinfw detect --joints`` reads."""
    import cv2

    from kinfw.cli._detect import read_joint_rows
    from kinfw.measurements import IMAGE_JOINTS_CSV, write_bag_images
    from tests.bags import image_pixels

    bag = write_bag(tmp_path / "cam", recording, images=True)
    rgb = write_bag_images(
        bag, tmp_path / "rgb", robot=recording.nominal, images="/camera/rgb", offset_s=0.05
    )
    n = len(np.arange(0.05, recording.t_joints[-1], 0.1))
    assert rgb.alignment.dropped == {"outside": 0, "gap": 0, "fast": 0, "moving": 0}
    assert len(rgb.files) == n and rgb.files[0] == "image_00000.png"
    k = np.arange(n)
    np.testing.assert_allclose(rgb.t_s, 0.1 * k + 0.05, rtol=0, atol=1e-9)
    np.testing.assert_allclose(rgb.qs, recording.q_joints[10 * k], rtol=0, atol=1e-9)
    for i in (0, 7, n - 1):
        on_disk = cv2.imread(str(tmp_path / "rgb" / rgb.files[i]), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(on_disk[..., ::-1], image_pixels(i)[0])
    images = [tmp_path / "rgb" / f for f in rgb.files]
    names, rows = read_joint_rows(tmp_path / "rgb" / IMAGE_JOINTS_CSV, images)
    assert tuple(names) == recording.joint_names
    np.testing.assert_array_equal(rows, rgb.qs)  # repr: exact
    depth = write_bag_images(bag, tmp_path / "d", robot=recording.nominal, images="/camera/depth")
    on_disk = cv2.imread(str(tmp_path / "d" / depth.files[3]), cv2.IMREAD_UNCHANGED)
    assert on_disk.dtype == np.uint16
    np.testing.assert_array_equal(on_disk, image_pixels(3)[1])
    with pytest.raises(DatasetError, match=r"'/mocap/pose' is geometry_msgs/msg/PoseStamped, "):
        write_bag_images(bag, tmp_path / "p", robot=recording.nominal, images="/mocap/pose")


def test_a_camera_seeing_a_board_reads_as_target_and_its_offset_is_found(recording, bags):
    """Read backwards, the mocap chain is a camera on the flange (at the marker) seeing a
    fixed board (the mocap frame): ``rigid_body -> room`` is ``camera_T_board``; target
    observations of the camera link, and the delay found from them as from the marker."""
    from tests.robots import ARM_6R

    camera = (
        '<joint name="camera_joint" type="fixed"><parent link="flange"/>'
        '<child link="camera"/></joint><link name="camera"/></robot>'
    )
    robot = load_robot(ARM_6R.replace("</robot>", camera))
    bag = read_bag(bags[2], robot=robot, tf=("rigid_body", "room"))
    data, _ = measurements_from_bag(
        bag, robot=robot, frame="flange", target="board", camera_frame="camera", offset_s=DELAY_S
    )
    (group,) = data.targets
    assert (group.camera, group.target) == ("camera", "board")
    camera_T_boards = np.linalg.inv(ROOM_T_MOCAP @ recording.mocap_T_markers)
    np.testing.assert_allclose(group.camera_T_target, camera_T_boards, rtol=0, atol=1e-9)
    streams = time_offset_streams(bag, robot, "camera", target=True)
    assert abs(best_time_offset(*streams, step=8).offset_s - DELAY_S) <= 1e-3
    with pytest.raises(DatasetError, match="would make calibrate redefine 'flange'"):
        measurements_from_bag(bag, robot=robot, frame="flange", target="board")
    # a camera frame the URDF lacks: the same observations, the camera mounted on the flange
    bare = load_robot(ARM_6R)
    bag = read_bag(bags[2], robot=bare, tf=("rigid_body", "room"))
    data, _ = measurements_from_bag(
        bag, robot=bare, frame="flange", target="board", camera_frame="hand_cam", offset_s=DELAY_S
    )
    (group,) = data.targets
    assert (group.camera, group.target) == ("hand_cam", "board")
    np.testing.assert_allclose(group.camera_T_target, camera_T_boards, rtol=0, atol=1e-9)
    assert list(data.mounts) == ["hand_cam"] and data.mounts["hand_cam"].parent == "flange"
    mounted = mounted_robot(bare, data.mounts, data.source)
    assert mounted.movable_path("hand_cam") == mounted.movable_path("flange")


def test_two_moving_tf_edges_compose_at_the_sparser_ones_stamps(recording, tmp_path):
    """``a -> b`` turns about z at 1 rad/s (50 Hz, from 0.1 s), ``b -> c`` slides along x
    at 0.2 m/s (20 Hz, from 0 s): SLERP and linear interpolation are exact for them, so
    ``a_T_c`` at ``b -> c``'s stamps is the closed form; the stamps before ``a -> b``
    starts (0 and 0.05 s) are dropped."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    from kinfw.geometry import matrix_from_rotation_vector

    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    Vector3, Quaternion = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    TransformStamped, Transform = (
        T["geometry_msgs/msg/TransformStamped"],
        T["geometry_msgs/msg/Transform"],
    )
    TFMessage, JointState = T["tf2_msgs/msg/TFMessage"], T["sensor_msgs/msg/JointState"]

    def header(t, frame):
        ns = round(t * 1e9)
        return Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame), ns

    def tf(t, parent, child, xyz, quat_xyzw):
        h, ns = header(t, parent)
        v, q = Vector3(*xyz), Quaternion(*quat_xyzw)
        return ns, TFMessage([TransformStamped(h, child, Transform(v, q))])

    path = tmp_path / "two"
    with Writer(path, version=9) as writer:
        c_tf = writer.add_connection("/tf", TFMessage.__msgtype__, typestore=store)
        c_js = writer.add_connection("/joint_states", JointState.__msgtype__, typestore=store)
        messages = [
            tf(t, "a", "b", (0, 0, 0), (0, 0, np.sin(t / 2), np.cos(t / 2)))
            for t in 0.1 + 0.02 * np.arange(100)
        ]
        messages += [tf(t, "b", "c", (0.2 * t, 0, 0), (0, 0, 0, 1)) for t in 0.05 * np.arange(40)]
        for t in (0.0, 2.5):
            h, ns = header(t, "")
            js = JointState(h, list(recording.joint_names), np.zeros(6), np.zeros(0), np.zeros(0))
            messages.append((ns, js))
        for ns, msg in sorted(messages, key=lambda m: m[0]):
            conn = c_js if isinstance(msg, JointState) else c_tf
            writer.write(conn, ns, store.serialize_cdr(msg, type(msg).__msgtype__))
    bag = read_bag(path, robot=recording.nominal, tf=("a", "c"), max_gap_s=None)
    t = 0.05 * np.arange(2, 40)  # 0.1 s on: inside a -> b's stream (0.1 to 2.08 s)
    np.testing.assert_allclose(bag.measured.t_s, t, rtol=0, atol=1e-9)
    a_T_c = np.broadcast_to(np.eye(4), (len(t), 4, 4)).copy()
    a_T_c[:, :3, :3] = matrix_from_rotation_vector(t[:, None] * [0.0, 0.0, 1.0])
    a_T_c[:, :3, 3] = a_T_c[:, :3, 0] * 0.2 * t[:, None]
    np.testing.assert_allclose(bag.measured.parent_T_childs, a_T_c, rtol=0, atol=1e-9)
