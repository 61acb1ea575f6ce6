"""The camera model against OpenCV's own projection, its files and its errors."""

import json

import cv2
import numpy as np
import pytest

from kinfw.camera import (
    PARAMETER_NAMES,
    CameraError,
    CameraIntrinsics,
    intrinsics_from_dict,
    project_normalized,
    read_camera,
)

CAMERA = CameraIntrinsics(640, 480, 500.0, 510.0, 320.5, 240.2, 0.1, -0.2, 0.001, 0.002, 0.05)

# A ROS camera_info file as camera_calibration writes it (ROS wiki, camera_calibration).
ROS_YAML = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [500.0, 0.0, 320.5, 0.0, 510.0, 240.2, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.1, -0.2, 0.001, 0.002, 0.05]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
projection_matrix:
  rows: 3
  cols: 4
  data: [500.0, 0.0, 320.5, 0.0, 0.0, 510.0, 240.2, 0.0, 0.0, 0.0, 1.0, 0.0]
"""


def test_projection_equals_opencv_project_points():
    rng = np.random.default_rng(0)
    camera_ps = rng.uniform([-0.4, -0.3, 0.3], [0.4, 0.3, 2.0], (200, 3))
    uv_cv, _ = cv2.projectPoints(
        camera_ps, np.zeros(3), np.zeros(3), CAMERA.matrix, CAMERA.distortion
    )
    np.testing.assert_allclose(CAMERA.project(camera_ps), uv_cv[:, 0], atol=1e-9)


def test_a_point_on_the_optical_axis_lands_on_the_principal_point():
    np.testing.assert_allclose(CAMERA.project([0.0, 0.0, 1.7]), [320.5, 240.2], atol=1e-12)
    # behind the camera: no pixel
    assert np.isnan(CAMERA.project([0.0, 0.0, -1.0])).all()


def test_casadi_projection_is_the_same_formula():
    import casadi as ca

    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    k = ca.SX.sym("k", 9)
    f = ca.Function("f", [x, y, k], [ca.vertcat(*project_normalized(x, y, k))])
    rng = np.random.default_rng(1)
    for xy in rng.uniform(-0.6, 0.6, (20, 2)):
        got = np.array(f(xy[0], xy[1], CAMERA.parameters)).ravel()
        want = CAMERA.project([xy[0], xy[1], 1.0])
        np.testing.assert_allclose(got, want, atol=1e-10)


def test_in_view_checks_depth_field_and_image_border():
    inside = [0.0, 0.0, 1.0]
    behind = [0.0, 0.0, -1.0]
    off_image = [2.0, 0.0, 1.0]  # u far beyond 640
    wide = [1e3, 0.0, 1.0]  # 89.9 deg off axis
    assert CAMERA.in_view([inside, behind, off_image, wide]).tolist() == [True, False, False, False]
    corner = [(639.4 - 320.5) / 500.0, 0.0, 1.0]
    plain = CameraIntrinsics(640, 480, 500.0, 510.0, 320.5, 240.2)
    assert plain.in_view([corner]).tolist() == [True]
    assert plain.in_view([corner], margin_px=5.0).tolist() == [False]


def test_reads_ros_camera_info(tmp_path):
    path = tmp_path / "left.yaml"
    path.write_text(ROS_YAML)
    cam = read_camera(path)
    assert cam.name == "narrow_stereo" and (cam.width, cam.height) == (640, 480)
    np.testing.assert_array_equal(cam.parameters, CAMERA.parameters)


@pytest.mark.parametrize("suffix", [".yml", ".xml"])
def test_reads_what_opencv_filestorage_writes(tmp_path, suffix):
    path = tmp_path / f"cam{suffix}"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("camera_matrix", CAMERA.matrix)
    fs.write("distortion_coefficients", CAMERA.distortion.reshape(1, 5))
    fs.release()
    np.testing.assert_array_equal(read_camera(path).parameters, CAMERA.parameters)


def test_json_round_trip_is_exact(tmp_path):
    path = tmp_path / "cam.json"
    path.write_text(json.dumps(CAMERA.to_dict()))
    assert read_camera(path) == CAMERA
    assert CAMERA.with_parameters(CAMERA.parameters) == CAMERA
    assert set(PARAMETER_NAMES) <= set(CAMERA.to_dict())


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('{"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320}', "missing 'cy'"),
        (
            '{"width": 640, "height": 480, "fx": -5, "fy": 500, "cx": 1, "cy": 1}',
            "fx must be positive",
        ),
        (
            '{"width": 64.5, "height": 480, "fx": 5, "fy": 5, "cx": 1, "cy": 1}',
            "integer number of pixels",
        ),
        (
            '{"width": 640, "height": 480, "fx": 5, "fy": 5, "cx": 1, "cy": 1, "k4": 0}',
            r"unknown key\(s\) \['k4'\]",
        ),
        ("{not json", "not valid JSON"),
    ],
)
def test_bad_json_camera_names_file_and_key(tmp_path, text, match):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(CameraError, match=match) as err:
        read_camera(path)
    assert "bad.json" in str(err.value)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (("plumb_bob", "equidistant"), "distortion_model 'equidistant' is not supported"),
        (("[500.0, 0.0, 320.5", "[500.0, 3.0, 320.5"), "no skew"),
        (("image_width: 640\n", ""), "missing 'image_width'"),
        (
            (
                "  data: [0.1, -0.2, 0.001, 0.002, 0.05]",
                "  data: [0.1, -0.2, 0.001, 0.002, 0.05, 0.3, 0, 0]",
            ),
            "rational model",
        ),
    ],
)
def test_bad_ros_camera_names_the_problem(tmp_path, change, match):
    path = tmp_path / "cam.yaml"
    path.write_text(ROS_YAML.replace(*change))
    with pytest.raises(CameraError, match=match):
        read_camera(path)


def test_missing_file_is_a_camera_error(tmp_path):
    with pytest.raises(CameraError, match="cannot read the camera file"):
        read_camera(tmp_path / "nope.yaml")
    with pytest.raises(CameraError, match="expected a JSON object"):
        intrinsics_from_dict([1, 2], "x.json")


@pytest.mark.parametrize(
    "text",
    ["garbage: [\n", '<?xml version="1.0"?>\n<robot name="r"><link name="a"/></robot>\n'],
)
def test_unparsable_camera_file_is_a_camera_error(tmp_path, text):
    """A YAML syntax error or a URDF given as a camera file: OpenCV raises (cv2.error or
    a SystemError wrapping it); kinfw names the file instead of a traceback."""
    path = tmp_path / "cam.yaml"
    path.write_text(text)
    with pytest.raises(CameraError, match=r"cam\.yaml: not a camera file OpenCV can read"):
        read_camera(path)
