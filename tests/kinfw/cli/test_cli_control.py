"""``kinfw gaze`` and ``kinfw reach``: the printed joint values checked by Pinocchio FK
(the camera's optical axis or pixel ray through the point, the frame at the target),
cv2.projectPoints for --pixel, the Meshcat scene's rays against FK, and user errors."""

import base64
import json
import math
import re

import cv2
import numpy as np
import pytest
import umsgpack

from kinfw.camera import read_camera
from kinfw.cli._main import main
from kinfw.model import load_robot
from tests.paths import HEAD_URDF
from tests.robots import ARM_6R

# A point the left camera of the IIS head can fixate (about 1 m in front of it).
POINT = (0.754, 0.503, 0.897)
CAMERA = {"width": 640, "height": 480, "fx": 600.0, "fy": 610.0, "cx": 318.0, "cy": 243.0}


def _run(argv, capsys):
    """Exit code, stdout and stderr of ``kinfw -q ARGV`` (-q: no progress lines, so
    stderr holds only what the command says: its warnings and errors)."""
    code = main(["-q", *(str(a) for a in argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def head():
    return load_robot(HEAD_URDF)


@pytest.fixture(scope="module")
def arm_urdf(tmp_path_factory):
    path = tmp_path_factory.mktemp("arm") / "arm.urdf"
    path.write_text(ARM_6R)
    return path


@pytest.fixture
def camera_file(tmp_path):
    path = tmp_path / "left.json"
    path.write_text(json.dumps({**CAMERA, "k1": -0.12, "k2": 0.03, "p1": 1e-3}))
    return path


def _axis_angle_rad(robot, q, camera, root_p_point, joint_names):
    """Angle between the camera's optical axis (FK) and the direction to the point."""
    root_T_camera = robot.frame_poses(q, camera, joint_names)
    toward = np.asarray(root_p_point) - root_T_camera[:3, 3]
    cos = root_T_camera[:3, 2] @ toward / np.linalg.norm(toward)
    return math.acos(min(1.0, cos))


# -- gaze ----------------------------------------------------------------------------------
def test_gaze_puts_the_point_on_the_optical_axis_by_fk(head, capsys):
    code, out, err = _run(
        ["gaze", HEAD_URDF, "--point", *POINT, "--cameras", "left_camera", "--json"], capsys
    )
    assert code == 0, err
    doc = json.loads(out)
    q, names = np.array(doc["q"]), tuple(doc["joint_names"])
    assert doc["fixated"] is True and doc["closest_achievable"] is False
    assert _axis_angle_rad(head, q, "left_camera", POINT, names) < 1e-8
    # the point is in front of the camera, not behind it
    root_T_camera = head.frame_poses(q, "left_camera", names)
    assert root_T_camera[:3, 2] @ (np.array(POINT) - root_T_camera[:3, 3]) > 0.5
    # one camera: its vergence and the tilt are solved, the rest stay mid-range
    assert doc["free_joints"] == ["tilt", "vergence_left"]
    lower, upper = head.joint_limits()
    held = [i for i, n in enumerate(names) if n not in doc["free_joints"]]
    np.testing.assert_allclose(q[held], 0.5 * (lower + upper)[held], atol=0)
    assert doc["joints"]["tilt"]["deg"] == pytest.approx(
        math.degrees(doc["joints"]["tilt"]["value"])
    )


def test_gaze_text_reports_joints_in_degrees_and_millimetres(capsys):
    code, out, _ = _run(
        ["gaze", HEAD_URDF, "--point", *POINT, "--cameras", "left_camera", "--q", "x_table=120mm"],
        capsys,
    )
    assert code == 0
    assert re.search(r"x_table\s+120\.0000\s+mm\s+held", out)
    assert re.search(r"vergence_left\s+-?\d+\.\d+\s+deg\s+free", out)
    assert "fixated: yes" in out and "closest achievable" not in out


def test_gaze_mm_unit_and_held_joint_values_are_used(head, capsys):
    point_mm = [1e3 * v for v in POINT]
    argv = ["gaze", HEAD_URDF, "--point", *point_mm, "--unit", "mm", "--cameras", "left_camera"]
    code, out, err = _run([*argv, "--q", "y_table=0.1", "--q", "pan=80deg", "--json"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    names = tuple(doc["joint_names"])
    q = np.array(doc["q"])
    assert q[names.index("y_table")] == pytest.approx(0.1, abs=0)
    assert q[names.index("pan")] == pytest.approx(math.radians(80.0), rel=1e-15)
    np.testing.assert_allclose(doc["point_m"], POINT, rtol=1e-15)
    assert _axis_angle_rad(head, q, "left_camera", POINT, names) < 1e-8


def test_gaze_pixel_projects_the_point_to_that_pixel_by_opencv(head, camera_file, capsys):
    u, v = 401.5, 297.25
    code, out, err = _run(
        [
            "gaze",
            HEAD_URDF,
            "--point",
            *POINT,
            "--cameras",
            "left_camera",
            "--pixel",
            u,
            v,
            "--camera",
            f"left_camera={camera_file}",
            "--json",
        ],
        capsys,
    )
    assert code == 0, err
    doc = json.loads(out)
    root_T_camera = head.frame_poses(np.array(doc["q"]), "left_camera", tuple(doc["joint_names"]))
    camera_p = root_T_camera[:3, :3].T @ (np.array(POINT) - root_T_camera[:3, 3])
    intrinsics = read_camera(camera_file)
    uv, _ = cv2.projectPoints(
        camera_p.reshape(1, 1, 3), np.zeros(3), np.zeros(3), intrinsics.matrix,
        intrinsics.distortion,
    )  # fmt: skip
    np.testing.assert_allclose(uv.reshape(2), [u, v], atol=1e-5)
    assert camera_p[2] > 0


def test_gaze_both_cameras_of_the_head_gives_the_closest_fixation(head, capsys):
    # the built-in head cannot fixate a point 1 m away with both cameras (vertical
    # disparity): exit 3, the remaining angles match FK at the printed joint values
    code, out, err = _run(["gaze", HEAD_URDF, "--point", *POINT, "--json"], capsys)
    assert code == 3, err
    doc = json.loads(out)
    assert doc["fixated"] is False and doc["closest_achievable"] is True
    q, names = np.array(doc["q"]), tuple(doc["joint_names"])
    for camera in ("left_camera", "right_camera"):
        fk_deg = math.degrees(_axis_angle_rad(head, q, camera, POINT, names))
        assert doc["error_deg"][camera] == pytest.approx(fk_deg, abs=1e-9)
        assert 1.0 < fk_deg < 10.0
    lower, upper = head.joint_limits()
    assert np.all(q >= lower) and np.all(q <= upper)
    code, out, _ = _run(["gaze", HEAD_URDF, "--point", *POINT], capsys)
    assert code == 3
    assert "fixated: no" in out
    assert "closest achievable fixation" in out


def _scene_commands(html):
    packed = re.findall(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)", html)
    return [umsgpack.unpackb(base64.b64decode(p)) for p in packed]


def test_gaze_html_draws_the_rays_and_the_point_where_fk_puts_them(head, tmp_path, capsys):
    html = tmp_path / "gaze.html"
    code, out, err = _run(
        [
            "gaze",
            HEAD_URDF,
            "--point",
            *POINT,
            "--cameras",
            "left_camera",
            "--html",
            html,
            "--json",
        ],
        capsys,
    )
    assert code == 0, err
    doc = json.loads(out)
    commands = _scene_commands(html.read_text(encoding="utf-8"))
    objects = {c["path"]: c["object"] for c in commands if c["type"] == "set_object"}
    transforms = {
        c["path"]: np.array(c["matrix"]).reshape(4, 4).T
        for c in commands
        if c["type"] == "set_transform"
    }
    base = "/meshcat/kinfw/gaze"
    assert f"{base}/point" in objects and f"{base}/rays/left_camera/stick" in objects
    assert any(p.startswith("/meshcat/kinfw/robot/") for p in objects)
    np.testing.assert_allclose(transforms[f"{base}/point"][:3, 3], POINT, atol=1e-12)
    root_T_camera = head.frame_poses(np.array(doc["q"]), "left_camera", tuple(doc["joint_names"]))
    ray = transforms[f"{base}/rays/left_camera"]  # y axis along the ray, origin at the camera
    np.testing.assert_allclose(ray[:3, 3], root_T_camera[:3, 3], atol=1e-12)
    np.testing.assert_allclose(ray[:3, 1], root_T_camera[:3, 2], atol=1e-9)
    distance = np.linalg.norm(np.array(POINT) - root_T_camera[:3, 3])
    stick = objects[f"{base}/rays/left_camera/stick"]
    height = next(g for g in stick["geometries"] if g["type"] == "CylinderGeometry")["height"]
    assert height == pytest.approx(distance, rel=1e-12)
    assert f"{base}/to_point/left_camera" not in transforms  # fixated: no miss line


# -- reach ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def arm_target(arm_urdf):
    arm = load_robot(arm_urdf)
    q_true = np.array([0.7, -0.4, 1.1, 2.0, -0.9, 0.5])
    return arm, arm.frame_poses(q_true, "flange")


def test_reach_pose_reaches_the_target_by_fk(arm_target, arm_urdf, capsys):
    from kinfw.geometry import xyz_quat_xyzw_from_transform

    arm, root_T_target = arm_target
    xyz, quat = xyz_quat_xyzw_from_transform(root_T_target)
    code, out, err = _run(
        ["reach", arm_urdf, "--frame", "flange", "--pose", *xyz, *quat, "--json"], capsys
    )
    assert code == 0, err
    doc = json.loads(out)
    assert doc["reached"] is True and doc["starts"] >= 1
    root_T_flange = arm.frame_poses(np.array(doc["q"]), "flange", tuple(doc["joint_names"]))
    np.testing.assert_allclose(root_T_flange, root_T_target, atol=1e-8)
    assert doc["position_error_mm"] < 1e-3 and doc["rotation_error_deg"] < 1e-4


def test_reach_point_in_mm_text_output(arm_target, arm_urdf, capsys):
    arm, root_T_target = arm_target
    p_mm = 1e3 * root_T_target[:3, 3]
    code, out, err = _run(
        ["reach", arm_urdf, "--frame", "flange", "--point", *p_mm, "--unit", "mm"], capsys
    )
    assert code == 0, err
    assert "reached: yes" in out and "rotation error" not in out
    assert re.search(r"position error: 0\.0000\d* mm", out)
    values = dict(re.findall(r"^\s*(j\d)\s+(-?\d+\.\d+)\s+deg", out, flags=re.MULTILINE))
    q = np.radians([float(values[f"j{k}"]) for k in range(1, 7)])
    # 4 printed decimals of a degree: the flange within 0.1 mm of the target
    np.testing.assert_allclose(arm.frame_poses(q, "flange")[:3, 3], root_T_target[:3, 3], atol=1e-4)


def test_reach_out_of_range_exits_3_with_the_closest_configuration(arm_urdf, capsys):
    arm = load_robot(arm_urdf)
    target = [3.0, 2.0, 1.0]  # links total about 1.2 m
    code, out, err = _run(
        ["reach", arm_urdf, "--frame", "flange", "--point", *target, "--restarts", "3", "--json"],
        capsys,
    )
    assert code == 3, err
    doc = json.loads(out)
    assert doc["reached"] is False and doc["starts"] == 4
    fk = arm.frame_poses(np.array(doc["q"]), "flange", tuple(doc["joint_names"]))[:3, 3]
    assert doc["position_error_mm"] == pytest.approx(1e3 * np.linalg.norm(fk - target), rel=1e-9)


def _scene(html):
    """The scene's objects and transforms (root-link coordinates: 4x4, row-major) by path."""
    commands = _scene_commands(html.read_text(encoding="utf-8"))
    objects = {c["path"]: c["object"] for c in commands if c["type"] == "set_object"}
    transforms = {
        c["path"]: np.array(c["matrix"]).reshape(4, 4).T
        for c in commands
        if c["type"] == "set_transform"
    }
    return objects, transforms


# ARM_6R with a box on link l6, offset from the link frame: the drawn robot checked by FK
L6_P_BOX = (0.01, 0.02, 0.03)
L6_BOX = (
    f'<link name="l6"><visual><origin xyz="{" ".join(map(str, L6_P_BOX))}"/>'
    '<geometry><box size="0.02 0.02 0.02"/></geometry></visual></link>'
)


def test_reach_html_draws_the_target_pose_and_the_frame_where_fk_puts_it(
    arm_target, tmp_path, capsys
):
    from kinfw.geometry import xyz_quat_xyzw_from_transform

    arm, root_T_target = arm_target
    arm_urdf = tmp_path / "arm_box.urdf"
    arm_urdf.write_text(ARM_6R.replace('<link name="l6"/>', L6_BOX))
    xyz, quat = xyz_quat_xyzw_from_transform(root_T_target)
    html = tmp_path / "reach.html"
    argv = ["reach", arm_urdf, "--frame", "flange", "--pose", *xyz, *quat, "--html", html]
    code, out, err = _run([*argv, "--json"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert doc["reached"] is True and doc["html"] == str(html)
    objects, transforms = _scene(html)
    base = "/meshcat/kinfw/reach"
    q, joint_names = np.array(doc["q"]), tuple(doc["joint_names"])
    box = transforms["/meshcat/kinfw/robot/visuals/l6_0"]  # the robot drawn at the answer
    np.testing.assert_allclose(
        box, arm.frame_poses(q, "l6", joint_names) @ _translation(L6_P_BOX), atol=1e-9
    )
    for axis in "xyz":  # both triads drawn, axis by axis, with a ball at their origins
        assert f"{base}/target/{axis}/stick" in objects and f"{base}/frame/{axis}/stick" in objects
    assert f"{base}/target/origin" in objects and f"{base}/frame/origin" in objects
    np.testing.assert_allclose(transforms[f"{base}/target"], root_T_target, atol=1e-9)
    root_T_flange = arm.frame_poses(q, "flange", joint_names)
    np.testing.assert_allclose(transforms[f"{base}/frame"], root_T_flange, atol=1e-9)
    # each triad axis is a stick along that axis of its frame (the node's y onto the axis)
    for k, axis in enumerate("xyz"):
        stick_T = transforms[f"{base}/target/{axis}"]
        np.testing.assert_allclose(stick_T[:3, 1], np.eye(3)[k], atol=1e-12)
    assert not any(p.startswith(f"{base}/to_target") for p in {**objects, **transforms})
    # text output names the file
    code, out, err = _run(argv, capsys)
    assert code == 0 and f"wrote {html}" in out


def test_reach_html_not_reached_draws_the_point_and_the_line_to_it(arm_urdf, tmp_path, capsys):
    arm = load_robot(arm_urdf)
    target = np.array([3.0, 2.0, 1.0])  # links total about 1.2 m
    html = tmp_path / "miss.html"
    argv = ["reach", arm_urdf, "--frame", "flange", "--point", *target, "--restarts", "1"]
    code, out, err = _run([*argv, "--html", html, "--json"], capsys)
    assert code == 3, err
    doc = json.loads(out)
    objects, transforms = _scene(html)
    base = "/meshcat/kinfw/reach"
    sphere = objects[f"{base}/target"]
    assert any(g["type"] == "SphereGeometry" for g in sphere["geometries"])
    assert f"{base}/target/x/stick" not in objects  # a point: no triad
    np.testing.assert_allclose(transforms[f"{base}/target"], _translation(target), atol=1e-12)
    root_T_flange = arm.frame_poses(np.array(doc["q"]), "flange", tuple(doc["joint_names"]))
    np.testing.assert_allclose(transforms[f"{base}/frame"], root_T_flange, atol=1e-9)
    # the line: from the flange's origin, its y axis toward the target, as long as the miss
    line = transforms[f"{base}/to_target"]
    toward = target - root_T_flange[:3, 3]
    distance = np.linalg.norm(toward)
    np.testing.assert_allclose(line[:3, 3], root_T_flange[:3, 3], atol=1e-9)
    np.testing.assert_allclose(line[:3, 1], toward / distance, atol=1e-9)
    stick = objects[f"{base}/to_target/stick"]
    height = next(g for g in stick["geometries"] if g["type"] == "CylinderGeometry")["height"]
    assert height == pytest.approx(distance, rel=1e-9)
    assert 1e3 * distance == pytest.approx(doc["position_error_mm"], rel=1e-9)


def _translation(p):
    T = np.eye(4)
    T[:3, 3] = p
    return T


# -- user errors ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["gaze", HEAD_URDF, "--point", *POINT, "--pixel", 1, 2], "give --camera FRAME=FILE for"),
        (["gaze", HEAD_URDF, "--point", *POINT, "--q", "tilt_x=1"], "no movable joint 'tilt_x'"),
        (["gaze", HEAD_URDF, "--point", *POINT, "--free", "pan,nope"], "no movable joint 'nope'"),
        (["gaze", HEAD_URDF, "--point", *POINT, "--cameras", "eye"], "no frame 'eye'"),
        (["gaze", HEAD_URDF, "--point", *POINT, "--q", "pan=2mm"], "'pan' is revolute"),
        (["gaze", HEAD_URDF, "--point", *POINT, "--html", HEAD_URDF], "refusing to overwrite"),
        (["reach", "ARM", "--frame", "hand", "--point", 0, 0, 0], "no frame 'hand'"),
        (
            ["reach", "ARM", "--frame", "flange", "--point", 0, 0, 0.5, "--html", "ARM"],
            "refusing to overwrite",
        ),
        (["reach", "ARM", "--frame", "flange", "--q", "j7=0", "--point", 0, 0, 0], "'j7'"),
        (
            ["reach", "ARM", "--frame", "flange", "--pose", 0, 0, 0, 0, 0, 0, 1.5],
            "expected a unit quaternion",
        ),
        (["reach", "ARM", "--frame", "flange", "--pose", 0, 0, 0, 0, 0, 1], "expected 7 arguments"),
        # a held joint outside its limits (250 m of a 1 m table: mm given as m)
        (
            [
                "gaze",
                HEAD_URDF,
                "--point",
                *POINT,
                "--cameras",
                "left_camera",
                "--q",
                "x_table=250",
            ],
            "joint 'x_table' is held (not solved for) at 250000 mm, outside its limits [0, 1000]",
        ),
        (
            [
                "reach",
                "ARM",
                "--frame",
                "flange",
                "--free",
                "j2,j3",
                "--q",
                "j1=20",
                "--point",
                0,
                0,
                0,
            ],
            "joint 'j1' is held (not solved for) at 1145.92 deg",
        ),
        (["gaze", HEAD_URDF, "--point", *POINT, "--free", "pan,pan"], "'pan' given twice"),
        (["gaze", HEAD_URDF, "--point", *POINT, "--q", "pan=1", "--q", "pan=2"], "given twice"),
        (["gaze", HEAD_URDF, "--point", 1e200, 0, 0], "1e+200 m from the root frame"),
        (["reach", "ARM", "--frame", "flange", "--point", 0, 0, 2e6], "2e+06 m from the root"),
    ],
)
def test_user_errors_exit_2_with_one_line(argv, message, arm_urdf, capsys):
    argv = [arm_urdf if a == "ARM" else a for a in argv]
    code, out, err = _run(argv, capsys)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1
    assert err.startswith(f"kinfw {argv[0]}: error: ") and message in err


def test_gaze_camera_without_pixel_or_for_another_frame_is_an_error(camera_file, capsys):
    base = ["gaze", HEAD_URDF, "--point", *POINT, "--cameras", "left_camera"]
    code, _, err = _run([*base, "--camera", f"left_camera={camera_file}"], capsys)
    assert code == 2 and "only used with --pixel" in err
    code, _, err = _run([*base, "--pixel", 3, 4, "--camera", f"right_camera={camera_file}"], capsys)
    assert code == 2 and "'right_camera' is not one of the cameras ['left_camera']" in err


def test_repeated_camera_is_an_error(camera_file, capsys):
    argv = ["gaze", HEAD_URDF, "--point", *POINT, "--cameras", "left_camera", "--pixel", 3, 4]
    code, _, err = _run(
        [*argv, "--camera", f"left_camera={camera_file}", "--camera", f"left_camera={camera_file}"],
        capsys,
    )
    assert code == 2 and "camera 'left_camera' is given twice" in err


def test_far_targets_warn_about_millimetres(arm_urdf, capsys):
    """A point 1.3 km from the head or a target 750 m from a 1 m arm: solved, with one
    warning that names the likely slip."""
    code, _, err = _run(["gaze", HEAD_URDF, "--point", 754, 503, 897], capsys)
    assert code == 3
    assert "warning: --point is 1275 m from the root frame; were millimetres given" in err
    code, _, err = _run(
        ["reach", arm_urdf, "--frame", "flange", "--point", 600, 200, 400, "--restarts", 0], capsys
    )
    assert code == 3 and "--point position is 748.3 m from the root frame" in err
    code, _, err = _run(["reach", arm_urdf, "--frame", "flange", "--point", 0.3, 0.2, 0.4], capsys)
    assert "warning" not in err


@pytest.mark.parametrize(
    ("extra", "reason"),
    [
        (["--cameras", "left_camera", "--free", "pan"], "1 free joint(s) for 1 camera(s)"),
        ([], "turn the rays in only 3 of 4 directions"),
    ],
)
def test_gaze_says_why_a_point_is_not_fixated(extra, reason, capsys):
    """Too few free joints, or (the IIS head with both cameras) joints that move the rays
    in 3 directions only (Fixation.rank) for 4 needed."""
    code, out, _ = _run(["gaze", HEAD_URDF, "--point", *POINT, *extra], capsys)
    assert code == 3
    assert reason in out
