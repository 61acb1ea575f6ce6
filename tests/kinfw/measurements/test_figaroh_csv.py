"""``kinfw import-csv``: FIGAROH calibration CSVs into kinfw measurement files.

Truths: the CSV itself read independently (``numpy.loadtxt``: rows, joint values and
marker positions equal to the file's, bit for bit); Pinocchio's own ``rpyToMatrix`` for
FIGAROH's ``phix, phiy, phiz``; and the nominal TIAGo's forward kinematics (Pinocchio),
which must explain the real Vicon marker up to one rigid transform (tracker frame) and one
marker offset, fitted here by alternating :func:`kinfw.geometry.register_points` and a
linear least squares for the offset -- at the centimetre level a real uncalibrated TIAGo
shows, not the metres a wrong joint column, unit or frame would give.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from kinfw.cli._main import main
from kinfw.geometry import average_transform, inverse_transform, register_points, rotation_angle
from kinfw.measurements import (
    matrix_from_figaroh_rpy,
    measurements_from_figaroh_csv,
    read_measurements,
)
from kinfw.model import load_robot
from kinfw.observations import DatasetError
from tests.erd import urdf_path
from tests.paths import DATA as TEST_DATA

DATA = TEST_DATA / "tiago_figaroh"
# The nominal TIAGo (PAL's URDF, CC BY-NC-ND): taken from example-robot-data (a test
# dependency), not shipped here.
URDF = urdf_path("tiago_description/robots/tiago_no_hand.urdf")
VICON_CSV = DATA / "vicon_calibration_gripper3_base1.csv"
VICON_JSON = DATA / "vicon_gripper3_base1.json"
EYE_HAND_CSV = DATA / "eye_hand_calibration_recorded_data_48c_hey5_12_test1.csv"
ARM = ("torso_lift_joint", *(f"arm_{i}_joint" for i in range(1, 8)))


@pytest.fixture(scope="module")
def tiago():
    return load_robot(URDF)


def _vicon(tiago):
    return measurements_from_figaroh_csv(
        VICON_CSV, robot=tiago, frame="arm_7_link", measured_in="vicon"
    )


def _fit_marker(tiago, frame, joint_names, qs, meas_p):
    """Tracker pose and marker offset of ``meas_p = W (R_i m + t_i)``: alternation."""
    root_T_frames = tiago.frame_poses(qs, frame, tuple(joint_names))
    R, t = root_T_frames[:, :3, :3], root_T_frames[:, :3, 3]
    m = np.zeros(3)
    for _ in range(2000):
        meas_T_root = register_points(np.einsum("nij,j->ni", R, m) + t, meas_p)
        root_p = np.einsum("ji,nj->ni", meas_T_root[:3, :3], meas_p - meas_T_root[:3, 3])
        m_next = np.linalg.lstsq(R.reshape(-1, 3), (root_p - t).reshape(-1), rcond=None)[0]
        done = np.linalg.norm(m_next - m) < 1e-10
        m = m_next
        if done:
            break
    root_p = np.einsum("nij,j->ni", R, m) + t
    meas_T_root = register_points(root_p, meas_p)
    res = meas_p - (root_p @ meas_T_root[:3, :3].T + meas_T_root[:3, 3])
    return m, np.sqrt((res**2).sum(axis=1).mean())


def test_vicon_rows_joints_and_points_equal_the_csv(tiago):
    table = np.loadtxt(VICON_CSV, delimiter=",", skiprows=1)
    header = VICON_CSV.read_text().splitlines()[0].split(",")
    m = _vicon(tiago)
    assert m.n_samples == len(table) == 21
    assert m.joint_names == tuple(header[3:]) == ARM
    np.testing.assert_array_equal(m.qs, table[:, 3:])
    (group,) = m.points
    assert (group.frame, group.marker, group.measured_in, group.offset) == (
        "arm_7_link",
        "marker1",
        "vicon",
        None,
    )
    np.testing.assert_array_equal(group.sample, np.arange(21))
    np.testing.assert_array_equal(group.meas_p_point, table[:, :3])
    assert not m.poses and not m.targets


def test_vicon_marker_follows_the_nominal_tiago_up_to_a_rigid_transform(tiago):
    m = _vicon(tiago)
    (group,) = m.points
    offset, rms = _fit_marker(tiago, "arm_7_link", m.joint_names, m.qs, group.meas_p_point)
    # 23.1 mm RMS measured: an uncalibrated TIAGo, not a wrong column (metres)
    assert 0.010 < rms < 0.030
    assert 0.15 < np.linalg.norm(offset) < 0.30  # on the gripper, ~0.24 m past the wrist
    # the same data on a link before the wrist does not fit: the check discriminates
    _, rms_wrong = _fit_marker(tiago, "arm_4_link", m.joint_names, m.qs, group.meas_p_point)
    assert rms_wrong > 0.1


def test_committed_json_is_what_import_csv_writes(tmp_path, capsys):
    out = tmp_path / "vicon.json"
    argv = ["import-csv", str(VICON_CSV), "--urdf", str(URDF), "--frame", "arm_7_link"]
    assert main([*argv, "--measured-in", "vicon", "--out", str(out)]) == 0
    assert "21 samples" in capsys.readouterr().out
    assert out.read_bytes() == VICON_JSON.read_bytes()
    back = read_measurements(VICON_JSON)
    np.testing.assert_array_equal(back.qs, np.loadtxt(VICON_CSV, delimiter=",", skiprows=1)[:, 3:])


def test_rpy_is_pinocchios_rpy_to_matrix():
    rng = np.random.default_rng(3)
    rpy = rng.uniform(-3, 3, size=(50, 3))
    expected = np.stack([pin.rpy.rpyToMatrix(*a) for a in rpy])
    np.testing.assert_allclose(matrix_from_figaroh_rpy(rpy), expected, atol=1e-14)


def test_eye_hand_poses_equal_the_csv_and_close_the_head_hand_loop(tiago):
    # the file ends every line with a comma (an empty 16th column)
    table = np.genfromtxt(EYE_HAND_CSV, delimiter=",", skip_header=1)[:, :15]
    m = measurements_from_figaroh_csv(
        EYE_HAND_CSV, robot=tiago, frame="arm_7_link", measured_in="head_camera"
    )
    assert m.n_samples == 12
    np.testing.assert_array_equal(m.qs, table[:, 6:])
    (group,) = m.poses
    cam_T_markers = group.meas_T_frame
    expected_R = np.stack([pin.rpy.rpyToMatrix(*a) for a in table[:, 3:6]])
    np.testing.assert_allclose(cam_T_markers[:, :3, :3], expected_R, atol=1e-12)
    np.testing.assert_allclose(cam_T_markers[:, :3, 3], table[:, :3], atol=0)
    # camera on the head (xtion_rgb_optical_frame), board on the wrist: the board's pose
    # on arm_7_link, through the nominal FK, is constant to a few cm / degrees
    names = m.joint_names
    root_T_cam = tiago.frame_poses(m.qs, "xtion_rgb_optical_frame", names)
    root_T_wrist = tiago.frame_poses(m.qs, "arm_7_link", names)
    wrist_T_boards = inverse_transform(root_T_wrist) @ root_T_cam @ cam_T_markers
    spread = inverse_transform(average_transform(wrist_T_boards)) @ wrist_T_boards
    pos_rms = np.sqrt((spread[:, :3, 3] ** 2).sum(axis=1).mean())
    rot_rms = np.sqrt((rotation_angle(spread[:, :3, :3]) ** 2).mean())
    assert pos_rms < 0.05 and np.degrees(rot_rms) < 8  # measured 29.6 mm, 5.2 deg
    # the same poses read as the camera's inverse (board_T_cam) do not close the loop
    wrong = inverse_transform(root_T_wrist) @ root_T_cam @ inverse_transform(cam_T_markers)
    spread = inverse_transform(average_transform(wrong)) @ wrong
    assert np.sqrt((spread[:, :3, 3] ** 2).sum(axis=1).mean()) > 0.1


def _csv(tmp_path, text, name="data.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_pandas_index_and_trailing_commas_are_ignored(tiago, tmp_path):
    plain = _csv(tmp_path, "x1,y1,z1,arm_1_joint\n1,2,3,0.5\n4,5,6,0.25\n", "plain.csv")
    # as in eye_hand_calibration_recorded_data_palhey5_13_optimal_from_500.csv
    pandas = _csv(
        tmp_path,
        "   ,x1 ,y1 , z1,arm_1_joint ,Unnamed: 5\n  0 ,1,2,3,0.5,\n\n  5 ,4,5,6,0.25 ,\n",
        "pandas.csv",
    )
    a = measurements_from_figaroh_csv(plain, robot=tiago, frame="arm_7_link")
    b = measurements_from_figaroh_csv(pandas, robot=tiago, frame="arm_7_link")
    np.testing.assert_array_equal(b.qs, a.qs)
    np.testing.assert_array_equal(b.points[0].meas_p_point, [[1, 2, 3], [4, 5, 6]])
    bad = _csv(tmp_path, " ,x1,y1,z1,arm_1_joint\n0,1,2,3,4\n\n1,1,2,x,4\n", "bad.csv")
    with pytest.raises(DatasetError, match=r"row 1 \(line 4\), column 'z1'"):
        measurements_from_figaroh_csv(bad, robot=tiago, frame="arm_7_link")


@pytest.mark.parametrize(
    ("dialect", "encoding"),
    [("bom", "utf-8-sig"), ("semicolon, decimal comma", "utf-8"), ("tab", "utf-8-sig")],
)
def test_spreadsheet_dialects_read_as_the_plain_csv(tiago, tmp_path, dialect, encoding):
    """The real Vicon session as a spreadsheet in Europe exports it (a byte-order mark,
    ';' separators, decimal commas) or as tab-separated text: the same measurements as
    the plain file, every number equal."""
    text = VICON_CSV.read_text()
    if dialect.startswith("semicolon"):
        text = text.replace(",", ";").replace(".", ",")
    elif dialect == "tab":
        text = text.replace(",", "\t")
    path = tmp_path / "vicon.csv"
    path.write_text(text, encoding=encoding)
    a = _vicon(tiago)
    b = measurements_from_figaroh_csv(path, robot=tiago, frame="arm_7_link", measured_in="vicon")
    assert b.joint_names == a.joint_names
    np.testing.assert_array_equal(b.qs, a.qs)
    np.testing.assert_array_equal(b.points[0].meas_p_point, a.points[0].meas_p_point)


def test_units_convert_lengths_angles_and_prismatic_joints(tiago, tmp_path):
    si = _csv(
        tmp_path,
        "x1,y1,z1,phix1,phiy1,phiz1,torso_lift_joint,arm_1_joint\n"
        "0.5,0.25,1.0,0.1,-0.2,0.3,0.25,1.5\n1.0,0.5,1.5,0.2,0.1,-0.3,0.1,0.5\n",
    )
    mm_deg = _csv(
        tmp_path,
        "x1,y1,z1,phix1,phiy1,phiz1,torso_lift_joint,arm_1_joint\n"
        + "\n".join(
            ",".join(repr(float(v)) for v in row)
            for row in (
                [500.0, 250.0, 1000.0, *np.degrees([0.1, -0.2, 0.3]), 250.0, np.degrees(1.5)],
                [1000.0, 500.0, 1500.0, *np.degrees([0.2, 0.1, -0.3]), 100.0, np.degrees(0.5)],
            )
        ),
        "mm.csv",
    )
    a = measurements_from_figaroh_csv(si, robot=tiago, frame="arm_7_link")
    b = measurements_from_figaroh_csv(
        mm_deg, robot=tiago, frame="arm_7_link", length_unit="mm", angle_unit="deg"
    )
    np.testing.assert_allclose(b.qs, a.qs, atol=1e-12)
    np.testing.assert_allclose(b.poses[0].meas_T_frame, a.poses[0].meas_T_frame, atol=1e-12)
    expected_R = np.stack([pin.rpy.rpyToMatrix(*a) for a in ([0.1, -0.2, 0.3], [0.2, 0.1, -0.3])])
    np.testing.assert_allclose(a.poses[0].meas_T_frame[:, :3, :3], expected_R, atol=1e-12)
    np.testing.assert_allclose(a.qs, [[0.25, 1.5], [0.1, 0.5]], atol=0)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("x1,z1,arm_1_joint\n1,2,3\n", r"marker 1 lacks column\(s\) \['y1'\]"),
        ("x1,y1,z1,phix1,arm_1_joint\n1,2,3,4,5\n", r"lacks column\(s\) \['phiy1', 'phiz1'\]"),
        ("a,b\n1,2\n", "no marker columns"),
        ("x1,y1,z1,elbow\n1,2,3,4\n", "column 'elbow' is neither a marker column.*arm_1_joint"),
        ("x1,y1,z1,arm_1_joint\n1,2,3,4\n1,2,oops,4\n", r"row 1 \(line 3\), column 'z1'.*'oops'"),
        ("x1,y1,z1,arm_1_joint\n1,2,nan,4\n", r"row 0 \(line 2\), column 'z1'.*occluded"),
        ("x1,y1,z1,arm_1_joint\n1,2,3\n", "line 2: 3 values separated by ',', expected 4"),
        ("x1;y1;z1;arm_1_joint\n1,5;2.5;3;4\n", "both decimal commas and decimal points"),
        ("x1,y1,z1,x1,arm_1_joint\n1,2,3,4,5\n", "column 'x1' appears twice"),
        ("x1,y1,z1,arm_1_joint\n", "no data rows"),
        ("", "empty file"),
    ],
)
def test_bad_files_name_the_file_row_and_column(tiago, tmp_path, text, match):
    path = _csv(tmp_path, text)
    with pytest.raises(DatasetError, match=match) as info:
        measurements_from_figaroh_csv(path, robot=tiago, frame="arm_7_link")
    assert str(path) in str(info.value)


def test_cli_user_error_exits_2_and_writes_nothing(tmp_path, capsys):
    path = _csv(tmp_path, "x1,y1,z1,arm_1_joint\n1,2,x,4\n")
    out = tmp_path / "out.json"
    # -q: no progress lines (loading the URDF), the error alone on stderr
    argv = ["-q", "import-csv", str(path), "--urdf", str(URDF), "--frame", "arm_7_link"]
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("kinfw import-csv: error: ") and "column 'z1'" in err
    assert not out.exists()
    # measured in the observed frame itself: refused
    # (tests/kinfw/observations/test_measured_in_robot.py
    # converts the eye-hand session in the head camera, a frame of the URDF)
    eye_hand = ["-q", "import-csv", str(EYE_HAND_CSV), *argv[3:]]
    code = main([*eye_hand, "--measured-in", "arm_7_link", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("kinfw import-csv: error: ")
    assert "frame 'arm_7_link' is measured in 'arm_7_link' itself" in err
    assert not out.exists()
    # an output that is an input is refused before any work
    assert main([*argv, "--out", str(path)]) == 2
    assert "kinfw import-csv: error:" in capsys.readouterr().err


def _camera_csv(path, robot, names, qs, flange_T_camera, root_T_board):
    """A FIGAROH CSV of ``camera_T_board`` (x1..phiz1, Pinocchio's RPY) for a camera on
    the 6R arm's flange (Pinocchio's forward kinematics of the truth)."""
    root_T_flange = robot.frame_poses(qs, "flange", names)
    lines = [",".join(["x1", "y1", "z1", "phix1", "phiy1", "phiz1", *names])]
    for q, T in zip(qs, root_T_flange, strict=True):
        camera_T_board = inverse_transform(T @ flange_T_camera) @ root_T_board
        rpy = pin.rpy.matrixToRpy(camera_T_board[:3, :3])
        lines.append(",".join(repr(float(v)) for v in (*camera_T_board[:3, 3], *rpy, *q)))
    path.write_text("\n".join(lines) + "\n")


def _flange_camera_and_board() -> tuple[np.ndarray, np.ndarray]:
    """The true ``flange_T_camera`` and ``root_T_board`` of the flange-camera tests."""
    from kinfw.geometry import matrix_from_rotation_vector

    flange_T_camera = np.eye(4)
    flange_T_camera[:3, :3] = matrix_from_rotation_vector([0.1, -0.2, 0.3])
    flange_T_camera[:3, 3] = [0.03, -0.05, 0.08]
    root_T_board = np.eye(4)
    root_T_board[:3, :3] = matrix_from_rotation_vector([3.0, 0.2, -0.1])
    root_T_board[:3, 3] = [0.6, 0.1, -0.2]
    return flange_T_camera, root_T_board


def _check_flange_kept_and_held_out(nominal, robot, result, test) -> None:
    """Held-out board poses of ``result`` (calibrated from ``robot``) to 1e-8, and the
    flange's joint at the nominal origin but for the shift of l6 onto its calibrated axis
    (re-expressed: the flange does not move with it), to 1e-12."""
    from kinfw.identification.problem import Unknown
    from kinfw.verification.evaluation import held_out_errors

    unknowns = result.refined.unknowns
    if result.refined.model_frame is not None:
        unknowns = (*unknowns, Unknown("frame", result.refined.model_frame, result.w_T_root))
    held = held_out_errors(robot, result.urdf_xml, unknowns, test)
    assert held.values("position")[0].max() < 1e-8 and held.values("rotation")[0].max() < 1e-8
    old_T_new = dict(result.export.link_shifts).get("l6", np.eye(4))
    np.testing.assert_allclose(
        load_robot(result.urdf_xml).joint("flange_joint").parent_T_child,
        inverse_transform(old_T_new) @ nominal.joint("flange_joint").parent_T_child,
        rtol=0,
        atol=1e-12,
    )


CAMERA_LINK = """  <joint name="camera_joint" type="fixed">
    <parent link="flange"/><child link="camera"/>
  </joint>
  <link name="camera"/>
"""


def test_a_flange_camera_seeing_a_board_imports_as_target_and_calibrates(tmp_path, capsys):
    """``--target board``: the 6D columns are the board's pose in a camera on the flange
    (mount and board unknown). Noise-free data of a perturbed 6R arm: calibrated, the
    board's pose in the camera at new configurations is the truth's (Pinocchio) to 1e-8."""
    from kinfw.identification import identify
    from kinfw.simulation import perturb_robot, random_configurations
    from tests.robots import ARM_6R

    nominal = load_robot(ARM_6R)
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(5)))
    names = nominal.topology(("flange",)).joint_names
    flange_T_camera, root_T_board = _flange_camera_and_board()
    rng = np.random.default_rng(2)
    qs = random_configurations(*nominal.joint_limits(names), 50, rng, fraction=0.6)
    test_qs = random_configurations(*nominal.joint_limits(names), 20, rng, fraction=0.6)
    for name, q in (("train.csv", qs), ("test.csv", test_qs)):
        _camera_csv(tmp_path / name, truth, names, q, flange_T_camera, root_T_board)
    out = tmp_path / "train.json"
    args = ["import-csv", str(tmp_path / "train.csv"), "--urdf", str(tmp_path / "n.urdf")]
    # the camera's own link on the flange (its nominal mount: the flange itself)
    (tmp_path / "n.urdf").write_text(ARM_6R.replace("</robot>", CAMERA_LINK + "</robot>"))
    nominal = load_robot(tmp_path / "n.urdf")
    args += ["--frame", "flange", "--target", "board", "--out", str(out)]
    assert main([*args, "--camera-frame", "camera"]) == 0
    train = read_measurements(out)
    (group,) = train.targets
    assert (group.camera, group.target) == ("camera", "board")
    result = identify(nominal, train)
    test = measurements_from_figaroh_csv(
        tmp_path / "test.csv", robot=nominal, frame="flange", target="board", camera_frame="camera"
    )
    # the flange stays the flange (the data see the camera, not the flange), and the
    # camera's joint holds the fitted mount
    _check_flange_kept_and_held_out(nominal, nominal, result, test)
    calibrated = load_robot(result.urdf_xml)
    model = result.refined.model
    model_qs = qs[:, [names.index(j) for j in model.topology.joint_names]]
    np.testing.assert_allclose(  # the camera link where the fit put the camera
        calibrated.frame_poses(qs, "camera", names),
        model.frame_poses(model_qs, "camera"),
        rtol=0,
        atol=1e-9,
    )
    # without --camera-frame: refused, saying how
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "would make calibrate redefine 'flange'" in err and "--camera-frame NAME" in err
    # a target needs orientation columns, and is measured in the camera
    with pytest.raises(DatasetError, match="marker 1 has no phix1"):
        measurements_from_figaroh_csv(
            VICON_CSV, robot=load_robot(URDF), frame="arm_7_link", target="board"
        )
    with pytest.raises(ValueError, match="exclude each other"):
        measurements_from_figaroh_csv(
            tmp_path / "test.csv",
            robot=nominal,
            frame="flange",
            target="board",
            measured_in="mocap",
        )


def test_a_camera_the_urdf_lacks_is_mounted_calibrated_and_exported(tmp_path, capsys):
    """``--camera-frame camera`` on a URDF without it: the file mounts ``camera`` on the
    flange, ``calibrate`` adds the link on a fixed joint (identity start) and exports it.

    Noise-free data of the exact arm: the exported URDF keeps every original link and
    joint (same parents and children, origins and axes those of the nominal to 1e-9: the
    data say the arm is nominal) and the new joint's origin is the true flange_T_camera
    to 1e-9. Of a perturbed arm (library): the flange keeps its nominal origin but for
    the shift of l6 onto its calibrated axis (1e-12), and held-out board poses in the
    camera are the truth's to 1e-8 (the split of the last link between flange and camera
    is not determined, their product is)."""
    from kinfw.identification import identify
    from kinfw.measurements import mounted_robot
    from kinfw.simulation import perturb_robot, random_configurations
    from tests.robots import ARM_6R

    nominal = load_robot(ARM_6R)
    names = nominal.topology(("flange",)).joint_names
    flange_T_camera, root_T_board = _flange_camera_and_board()
    rng = np.random.default_rng(2)
    qs = random_configurations(*nominal.joint_limits(names), 40, rng, fraction=0.6)
    test_qs = random_configurations(*nominal.joint_limits(names), 20, rng, fraction=0.6)
    (tmp_path / "n.urdf").write_text(ARM_6R)
    _camera_csv(tmp_path / "exact.csv", nominal, names, qs, flange_T_camera, root_T_board)
    data, out = tmp_path / "exact.json", tmp_path / "cal.urdf"
    args = ["import-csv", tmp_path / "exact.csv", "--urdf", tmp_path / "n.urdf"]
    args += ["--frame", "flange", "--target", "board", "--camera-frame", "camera"]
    assert main([str(a) for a in [*args, "--out", data]]) == 0
    assert "the file mounts it on 'flange'" in capsys.readouterr().out
    train = read_measurements(data)
    assert train.mounts["camera"].parent == "flange"
    argv = ["calibrate", data, "--urdf", tmp_path / "n.urdf", "--out", out, "--params", "full"]
    assert main([str(a) for a in argv]) == 0
    calibrated = load_robot(out)
    assert calibrated.link_names == (*nominal.link_names, "camera")
    for joint in nominal.joints:
        got = calibrated.joint(joint.name)
        assert (got.type, got.parent, got.child) == (joint.type, joint.parent, joint.child)
        np.testing.assert_allclose(got.parent_T_child, joint.parent_T_child, atol=1e-9)
    mount = calibrated.joint("camera_joint")
    assert (mount.type, mount.parent, mount.child) == ("fixed", "flange", "camera")
    np.testing.assert_allclose(mount.parent_T_child, flange_T_camera, rtol=0, atol=1e-9)
    # verify reads the exported URDF as it is (the mount is already there)
    assert main([str(a) for a in ["verify", out, data]]) == 0
    assert "camera (target)" in capsys.readouterr().out

    # a perturbed arm, the same mount through the library
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(5)))
    for name, q in (("train.csv", qs), ("test.csv", test_qs)):
        _camera_csv(tmp_path / name, truth, names, q, flange_T_camera, root_T_board)
    train, test = (
        measurements_from_figaroh_csv(
            tmp_path / name, robot=nominal, frame="flange", target="board", camera_frame="camera"
        )
        for name in ("train.csv", "test.csv")
    )
    mounted = mounted_robot(nominal, train.mounts)
    assert mounted.joint("camera_joint").parent == "flange"
    _check_flange_kept_and_held_out(nominal, mounted, identify(mounted, train), test)


def test_import_csv_writes_repeated_rows_once_and_says_which(tmp_path, capsys):
    """The Vicon session with its first three rows pasted again at the end: the file
    written is the committed one, and stderr names the three copies."""
    lines = VICON_CSV.read_text().splitlines()
    path = _csv(tmp_path, "\n".join([*lines, *lines[1:4]]) + "\n")
    out = tmp_path / "vicon.json"
    argv = ["-q", "import-csv", str(path), "--urdf", str(URDF), "--frame", "arm_7_link"]
    assert main([*argv, "--measured-in", "vicon", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "3 of the 24 samples repeat an earlier one: 21 (= 0), 22 (= 1), 23 (= 2);" in err
    expected = read_measurements(VICON_JSON)
    np.testing.assert_array_equal(read_measurements(out).qs, expected.qs)
    assert main([*argv, "--measured-in", "vicon", "--out", str(out), "--keep-duplicates"]) == 0
    assert "repeat" not in capsys.readouterr().err
    assert read_measurements(out).n_samples == 24
