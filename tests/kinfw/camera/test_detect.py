"""kinfw detect: board models, corner detection on rendered images against the true
projection of the board's corners, the symmetric-board ambiguity, the joints CSV and the
command end to end.

Truth: the images are rendered by kinfw.simulation from a known camera (with
distortion) and a known camera_T_board; the true corner pixels are
CameraIntrinsics.project(camera_T_board @ board.points) (tested against cv2.projectPoints
in test_camera_model.py). "RMS error" below is the root mean square over the corners of
the distance in pixels between the detected and the true pixel of the same corner id.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinfw.camera import BoardError, CameraIntrinsics, Charuco, Chessboard, Detector, parse_board
from kinfw.cli._detect import read_joint_rows
from kinfw.cli._main import main
from kinfw.measurements import measurements_to_dict, read_measurements
from kinfw.simulation import render_board, true_corners

CAMERA = CameraIntrinsics(
    480, 360, 400.0, 404.0, 241.3, 178.9, k1=-0.18, k2=0.04, p1=0.0008, p2=-0.0005, k3=0.0,
    name="left",
)  # fmt: skip
CHESS = Chessboard(9, 6, 0.03)
CHARUCO = Charuco(7, 5, 0.04, 0.03)


def board_pose(board, tilt_rotvec, roll, distance=0.5, shift=(0.0, 0.0)):
    """camera_T_board: the board's centre ``distance`` m ahead (plus ``shift``), facing the
    camera, turned by ``roll`` about its normal and tilted by ``tilt_rotvec``."""
    R = Rotation.from_rotvec(tilt_rotvec).as_matrix() @ Rotation.from_euler("z", roll).as_matrix()
    camera_T_board = np.eye(4)
    camera_T_board[:3, :3] = R
    centre = board.points.mean(axis=0)
    camera_T_board[:3, 3] = np.array([shift[0], shift[1], distance]) - R @ centre
    return camera_T_board


POSES = [
    ([0.0, 0.0, 0.0], 0.0),
    ([0.25, -0.3, 0.0], 0.4),
    ([-0.3, 0.1, 0.0], np.pi),  # upside down
    ([0.1, 0.35, 0.0], -np.pi / 2),
    ([0.4, 0.0, 0.1], np.pi + 0.6),
]


def rms(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


# -- board models and specs ---------------------------------------------------------------
def test_chessboard_points_follow_opencv_numbering():
    board = Chessboard(4, 3, 0.02)
    assert board.points.shape == (12, 3)
    np.testing.assert_allclose(board.points[5], [0.02, 0.02, 0.0], atol=0)  # col 1, row 1
    np.testing.assert_allclose(board.points[11], [0.06, 0.04, 0.0], atol=1e-15)
    assert not board.symmetric and Chessboard(8, 6, 0.02).symmetric
    assert Chessboard(7, 5, 0.02).symmetric and Chessboard(5, 5, 0.02).symmetric


def test_charuco_points_are_opencvs():
    np.testing.assert_allclose(
        CHARUCO.points, CHARUCO.opencv_board().getChessboardCorners(), atol=1e-7
    )


def test_parse_board_specs():
    assert parse_board("chessboard:9x6:0.025") == Chessboard(9, 6, 0.025)
    assert parse_board("charuco:7x5:0.04:0.03") == Charuco(7, 5, 0.04, 0.03, "DICT_5X5_100")
    assert parse_board("charuco:7X5:0.04:0.03:dict_4x4_50").dictionary == "DICT_4X4_50"
    assert parse_board(CHARUCO.spec()) == CHARUCO


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ("chess:9x6:0.02", "unknown board type 'chess'"),
        ("chessboard:9by6:0.02", "size '9by6' is not COLSxROWS"),
        ("chessboard:9x6:abc", "SQUARE_M 'abc' is not a number"),
        ("charuco:7x5:0.04", "wrong number of ':' fields"),
        ("chessboard:9x6:25", "more than 2 m"),
        ("chessboard:1x6:0.02", "cols must be an integer >= 3"),
        ("chessboard:2x2:0.04", "cols must be an integer >= 3"),
        ("charuco:7x5:0.04:0.05", "marker_m .* must be smaller than square_m"),
        ("charuco:7x5:0.04:0.03:FOO", "unknown ArUco dictionary 'FOO'"),
    ],
)
def test_parse_board_errors(spec, match):
    with pytest.raises(BoardError, match=match):
        parse_board(spec)


def test_charuco_dictionary_too_small():
    with pytest.raises(BoardError, match="DICT_4X4_50 has 50 markers, a 12x10 board needs 60"):
        Charuco(12, 10, 0.02, 0.015, "DICT_4X4_50").opencv_board()


# -- the renderer ---------------------------------------------------------------------------
@pytest.mark.slow
def test_render_puts_squares_where_the_camera_model_projects_them():
    """Centres of squares of the chessboard, projected by CameraIntrinsics.project, land on
    dark pixels for black squares and bright ones for white squares."""
    camera_T_board = board_pose(CHESS, [0.3, -0.2, 0.0], 0.7)
    image = render_board(CHESS, CAMERA, camera_T_board)
    j, i = np.mgrid[-1:6, -1:9]
    board_ps = np.stack([(i.ravel() + 0.5) * 0.03, (j.ravel() + 0.5) * 0.03, 0 * i.ravel()], 1)
    uv = CAMERA.project(board_ps @ camera_T_board[:3, :3].T + camera_T_board[:3, 3])
    grey = image[np.rint(uv[:, 1]).astype(int), np.rint(uv[:, 0]).astype(int)]
    black = (i.ravel() + j.ravel()) % 2 == 0
    assert grey[black].max() < 20 and grey[~black].min() > 235


# -- detection ------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize(("tilt", "roll"), POSES)
def test_chessboard_corners_subpixel_and_numbered_by_the_board(tilt, roll):
    camera_T_board = board_pose(CHESS, tilt, roll)
    rng = np.random.default_rng(7)
    image = render_board(CHESS, CAMERA, camera_T_board, noise_sigma=1.0, rng=rng)
    detection = Detector(CHESS).detect(image, "x.png")
    assert detection.status == "found", detection.reason
    np.testing.assert_array_equal(detection.ids, np.arange(54))
    np.testing.assert_array_equal(detection.points, CHESS.points)
    truth = true_corners(CHESS, CAMERA, camera_T_board)
    assert rms(detection.uv, truth) < 0.1  # the turned numbering would be ~100 px off


@pytest.mark.parametrize(("tilt", "roll"), POSES)
def test_charuco_corners_subpixel_with_the_right_ids(tilt, roll):
    camera_T_board = board_pose(CHARUCO, tilt, roll)
    image = render_board(CHARUCO, CAMERA, camera_T_board, noise_sigma=1.0)
    detection = Detector(CHARUCO).detect(image, "x.png")
    assert detection.status == "found", detection.reason
    np.testing.assert_array_equal(detection.ids, np.arange(CHARUCO.count))  # all seen
    np.testing.assert_allclose(detection.points, CHARUCO.points[detection.ids], atol=0)
    truth = true_corners(CHARUCO, CAMERA, camera_T_board)
    assert rms(detection.uv, truth[detection.ids]) < 0.1


def test_charuco_partly_in_view_keeps_the_ids_it_sees():
    camera_T_board = board_pose(CHARUCO, [0.0, 0.2, 0.0], 0.2, distance=0.45, shift=(0.17, 0.0))
    truth = true_corners(CHARUCO, CAMERA, camera_T_board)
    inside = CAMERA.in_view(
        CHARUCO.points @ camera_T_board[:3, :3].T + camera_T_board[:3, 3], margin_px=0
    )
    assert 6 <= inside.sum() < CHARUCO.count  # the pose does cut the board
    detection = Detector(CHARUCO).detect(render_board(CHARUCO, CAMERA, camera_T_board))
    assert detection.found and set(detection.ids) <= set(np.flatnonzero(inside))
    assert rms(detection.uv, truth[detection.ids]) < 0.1


@pytest.mark.parametrize("board", [CHESS, CHARUCO])
def test_board_out_of_view_is_not_found(board):
    camera_T_board = board_pose(board, [0.0, 0.0, 0.0], 0.0, shift=(1.0, 0.0))
    detection = Detector(board).detect(render_board(board, CAMERA, camera_T_board), "far.png")
    assert detection.status == "not found" and detection.reason
    assert detection.uv.shape == (0, 2) and detection.ids.shape == (0,)


@pytest.mark.slow
def test_chessboard_cut_by_the_border_is_not_numbered_one_square_off():
    """A pose (found by benchmarks/bench_detect.py) where two corners fall below the image
    and OpenCV's findChessboardCornersSB returns a 9x6 grid shifted by one square (its
    corner 0 ~40 px from the true one): the squares around the grid are checked and the
    image is reported not found instead of numbered wrongly."""
    import kinfw.camera._detect as kd

    camera = CameraIntrinsics(
        640, 480, 500.0, 500.0, 322.0, 237.0, k1=-0.25, k2=0.08, p1=0.001, p2=-0.001
    )
    camera_T_board = np.eye(4)
    camera_T_board[:3, :3] = Rotation.from_rotvec([-0.1521, -0.6884, -0.2899]).as_matrix()
    camera_T_board[:3, 3] = [-0.2124, 0.0465, 0.3175]
    image = render_board(CHESS, camera, camera_T_board)
    truth = true_corners(CHESS, camera, camera_T_board)
    assert (truth[:, 1] > camera.height).sum() == 2
    raw = kd._find_chessboard(image, (9, 6))
    if raw is not None:  # the OpenCV behaviour this guards against (4.14)
        assert min(rms(raw, truth), rms(raw[::-1], truth)) > 10.0
    detection = Detector(CHESS).detect(image, "cut.png")
    assert detection.status == "not found"
    assert "squares around them have the wrong colour" in detection.reason


@pytest.mark.slow
@pytest.mark.parametrize("spec", [(8, 6), (7, 6)])
def test_a_spec_smaller_than_the_chessboard_is_not_found_saying_so(spec):
    """A 9 x 6 board (POSES[1], noise-free) read as 8 x 6 or 7 x 6: OpenCV finds that
    many corners inside it (measured, OpenCV 4.x), symmetric for 8 x 6. The squares
    continuing past them make the image not found, naming the count; never ambiguous
    (allow_symmetric would number a part of the board), never found."""
    image = render_board(CHESS, CAMERA, board_pose(CHESS, *POSES[1]))
    board = Chessboard(*spec, 0.03)
    for allow in (False, True):
        detection = Detector(board, allow_symmetric=allow).detect(image, "x.png")
        assert detection.status == "not found" and not detection.symmetric, detection.reason
        assert detection.reason.startswith(
            f"the {spec[0]}x{spec[1]} corners found are part of a larger chessboard (its "
            f"squares continue past them: more than {spec[0]} inner corners per row)"
        )
        assert "check COLSxROWS" in detection.reason
    assert Detector(CHESS).detect(image).found  # the right spec


@pytest.mark.parametrize(
    "board", [Chessboard(8, 6, 0.03), Chessboard(7, 5, 0.03), Chessboard(5, 5, 0.04)]
)
@pytest.mark.slow
def test_symmetric_chessboard_is_ambiguous_unless_allowed(board):
    upright = board_pose(board, [0.2, -0.2, 0.0], 0.3)
    turned = board_pose(board, [0.2, -0.2, 0.0], 0.3 + np.pi)
    for camera_T_board in (upright, turned):
        image = render_board(board, CAMERA, camera_T_board)
        detection = Detector(board).detect(image, "sym.png")
        assert detection.status == "ambiguous" and detection.symmetric
        assert "looks the same turned by 180 degrees" in detection.reason
    allowed = Detector(board, allow_symmetric=True)
    up = allowed.detect(render_board(board, CAMERA, upright))
    assert rms(up.uv, true_corners(board, CAMERA, upright)) < 0.1
    # turned: the same picture, so the numbering follows the image, i.e. is the board's
    # turned by 180 degrees -- what --allow-symmetric accepts
    down = allowed.detect(render_board(board, CAMERA, turned))
    assert rms(down.uv, true_corners(board, CAMERA, turned)[::-1]) < 0.1


def test_min_corners_is_at_least_four():
    with pytest.raises(ValueError, match="min_corners must be >= 4"):
        Detector(CHARUCO, min_corners=3)


# -- joints CSV -----------------------------------------------------------------------------
def test_joint_rows_in_order_and_by_image_name(tmp_path):
    images = [tmp_path / "b.png", tmp_path / "a.png"]
    ordered = tmp_path / "q.csv"
    ordered.write_text("pan,tilt\n0.1,0.2\n0.3,0.4\n")
    assert read_joint_rows(ordered, images) == (["pan", "tilt"], [[0.1, 0.2], [0.3, 0.4]])
    keyed = tmp_path / "k.csv"
    keyed.write_text("image,pan,tilt\na.png,1,2\nb.png,3,4\n")
    assert read_joint_rows(keyed, images) == (["pan", "tilt"], [[3.0, 4.0], [1.0, 2.0]])
    # keyed: rows of images not given (held out) are left out, the others matched
    keyed.write_text("image,pan,tilt\na.png,1,2\nc.png,5,6\nb.png,3,4\n")
    assert read_joint_rows(keyed, images) == (["pan", "tilt"], [[3.0, 4.0], [1.0, 2.0]])
    # joints named like a pose chain's are joints, not a hand pose
    chain = tmp_path / "c.csv"
    chain.write_text("pose_x,pose_y,pose_z,pose_yaw,pose_pitch,pose_roll,x\n1,2,3,4,5,6,7\n")
    assert read_joint_rows(chain, images[:1])[1] == [[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("pan,tilt\n0.1,0.2\n", r"1 rows of joint values for 2 images"),
        ("image,pan\na.png,1\n", r"no row for image .*b\.png"),
        ("image,pan\na.png,1\na.png,2\n", r"lines 2 and 3 both name image 'a\.png'"),
        ("pan,tilt\n0.1,x\n0.3,0.4\n", r"line 2, column 'tilt': expected a finite number"),
        ("pan,tilt\n0.1\n0.3,0.4\n", r"line 2: 1 values, the header has 2 columns"),
        ("pan,pan\n1,2\n3,4\n", r"\['pan'\] appear twice"),
        ("", r"empty"),
        (
            "image,x,y,z,qx,qy,qz,qw\na.png,0,0,0,0,0,0,1\nb.png,0,0,0,0,0,0,1\n",
            r"line 1: the columns x, y, z, qx, qy, qz, qw are a hand pose, not joint values: "
            r"this looks like hand poses; run kinfw pose-chain .*q\.csv --camera-frame",
        ),
        (
            "hand_x,hand_y,hand_z,hand_qx,hand_qy,hand_qz,hand_qw\n0,0,0,0,0,0,1\n0,0,0,0,0,0,1\n",
            r"the columns hand_x, .*, hand_qw are a hand pose, .* kinfw pose-chain",
        ),
    ],
)
def test_joint_rows_errors(tmp_path, text, match):
    path = tmp_path / "q.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        read_joint_rows(path, [tmp_path / "a.png", tmp_path / "b.png"])


# -- the command ----------------------------------------------------------------------------
def _write_images(tmp_path, board, poses):
    import cv2

    paths = []
    for k, camera_T_board in enumerate(poses):
        path = tmp_path / f"img_{k}.png"
        cv2.imwrite(str(path), render_board(board, CAMERA, camera_T_board, noise_sigma=1.0))
        paths.append(path)
    return paths


@pytest.mark.slow
@pytest.mark.parametrize("board", [CHESS, CHARUCO])
def test_detect_command_end_to_end(tmp_path, capsys, board):
    poses = [board_pose(board, tilt, roll) for tilt, roll in POSES[:3]]
    poses.append(board_pose(board, [0.0, 0.0, 0.0], 0.0, shift=(1.0, 0.0)))  # not seen
    images = _write_images(tmp_path, board, poses)
    camera_file = tmp_path / "cam.json"
    camera_file.write_text(json.dumps(CAMERA.to_dict()))
    joints = tmp_path / "q.csv"
    qs = np.arange(8.0).reshape(4, 2) / 10
    # rows keyed by file name, in another order than the images
    joints.write_text("tilt,image,pan\n" + "".join(
        f"{q[1]},{images[k].name},{q[0]}\n" for k, q in reversed(list(enumerate(qs)))
    ))  # fmt: skip
    out = tmp_path / "data.json"
    code = main(
        ["detect", *map(str, images), "--board", board.spec(), "--joints", str(joints),
         "--camera", str(camera_file), "--frame", "left_camera", "--out", str(out)]
    )  # fmt: skip
    stdout = capsys.readouterr().out
    assert code == 0
    assert "3 found, 1 not found, 0 ambiguous" in stdout
    # one line per rejected image, by its file name
    (line,) = [x for x in stdout.splitlines() if "not found:" in x]
    assert line.startswith(f"  not found: {images[3].name}: ") and str(tmp_path) not in line
    doc = json.loads(out.read_text())
    assert doc["format"] == "kinfw-measurements" and doc["version"] == 1
    assert doc["units"] == {"length": "m", "angle": "rad"}
    assert doc["joint_names"] == ["tilt", "pan"]
    assert doc["cameras"] == {"left_camera": CAMERA.to_dict()}
    assert len(doc["samples"]) == 3
    for k, sample in enumerate(doc["samples"]):
        np.testing.assert_allclose(sample["q"], qs[k][::-1], atol=0)
        (obs,) = sample["observations"]
        assert obs["frame"] == "left_camera" and obs["kind"] == "pixels"
        assert obs["target"] == "board" and obs["image"] == str(images[k])
        uv, points, ids = np.array(obs["uv"]), np.array(obs["points"]), np.array(obs["ids"])
        assert uv.shape == (len(ids), 2) and points.shape == (len(ids), 3)
        assert len(ids) >= 4 and len(set(ids.tolist())) == len(ids)
        camera_T_board = poses[k]
        reprojected = CAMERA.project(points @ camera_T_board[:3, :3].T + camera_T_board[:3, 3])
        assert rms(uv, reprojected) < 0.1
    # the pixels kind reads it: cameras, points and pixels as written, one image per sample
    data = read_measurements(out)
    assert dict(data.cameras) == {"left_camera": CAMERA}
    assert data.joint_names == ("tilt", "pan") and len(data.qs) == 3
    assert measurements_to_dict(data) == doc


def test_detect_command_errors(tmp_path, capsys):
    images = _write_images(tmp_path, CHESS, [board_pose(CHESS, [0.0, 0.0, 0.0], 0.0)])
    camera_file = tmp_path / "cam.json"
    camera_file.write_text(json.dumps(CAMERA.to_dict()))
    joints = tmp_path / "q.csv"
    joints.write_text("pan\n0.1\n")

    def run(*extra, board=None, out=tmp_path / "o.json"):
        board = CHESS.spec() if board is None else board
        code = main(
            ["detect", *map(str, images), "--board", board, "--joints", str(joints),
             "--camera", str(camera_file), "--frame", "cam", "--out", str(out), *extra]
        )  # fmt: skip
        return code, capsys.readouterr().err

    code, err = run(board="chessboard:9x6")
    assert code == 2 and err.startswith("kinfw detect: error: board 'chessboard:9x6'")
    code, err = run(out=joints)
    assert code == 2 and "same file as --joints" in err
    code, err = run(out=images[0])
    assert code == 2 and "refusing to overwrite an input" in err
    code, err = run(board="chessboard:8x6:0.03")
    assert code == 2
    assert (
        "was found in none of the images: 1 image(s) show no 8x6 chessboard (8x6: inner "
        "corners per row x rows; first: img_0.png: "
    ) in err
    assert "check --board and the images" in err and "--allow-symmetric" not in err
    assert not (tmp_path / "o.json").exists()
    code, err = run("--min-corners", "3", board=CHARUCO.spec())
    assert code == 2 and "--min-corners" in err
    joints.write_text("pan\n0.1\n0.2\n")
    code, err = run()
    assert code == 2 and "2 rows of joint values for 1 images" in err
    joints.write_text("pan\n0.1\n")
    small = CameraIntrinsics(320, 240, 400.0, 400.0, 160.0, 120.0)
    camera_file.write_text(json.dumps(small.to_dict()))
    code, err = run()
    assert code == 2 and "image is 480x360 pixels, the camera" in err


def test_detect_command_when_every_image_is_ambiguous_says_why(tmp_path, capsys):
    board = Chessboard(8, 6, 0.03)
    images = _write_images(tmp_path, board, [board_pose(board, [0.2, -0.2, 0.0], 0.3)])
    (tmp_path / "cam.json").write_text(json.dumps(CAMERA.to_dict()))
    (tmp_path / "q.csv").write_text("pan\n0.1\n")
    out = tmp_path / "o.json"
    code = main(
        ["detect", str(images[0]), "--board", board.spec(), "--joints", str(tmp_path / "q.csv"),
         "--camera", str(tmp_path / "cam.json"), "--frame", "cam", "--out", str(out)]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and "found in none of the images: in 1 a symmetric 8x6 chessboard was " in err
    assert "--allow-symmetric if it is never turned" in err and not out.exists()
    assert "show no" not in err  # the board was found: not a wrong spec
    code = main(
        ["detect", str(images[0]), "--board", board.spec(), "--joints", str(tmp_path / "q.csv"),
         "--camera", str(tmp_path / "cam.json"), "--frame", "cam", "--out", str(images[0])]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and f"same file as IMAGES[0] {images[0]}:" in err


def test_detect_takes_either_image_files_or_folders(tmp_path, capsys):
    """``--images DIR:FRAME`` excludes IMAGE..., --joints, --camera and --frame; without
    it all four are needed; a folder needs its joints.csv with an image column."""
    from kinfw.cli._main import main

    base = ["detect", "--board", "chessboard:9x6:0.04", "--out", str(tmp_path / "o.json")]
    assert main([*base, str(tmp_path / "a.png"), "--frame", "cam"]) == 2
    assert "missing: --joints, --camera" in capsys.readouterr().err
    assert main([*base, "--images", f"{tmp_path}:cam", "--frame", "cam"]) == 2
    assert "give no --frame with it" in capsys.readouterr().err
    assert main([*base, "--images", f"{tmp_path}:cam", "--images", f"{tmp_path}:cam"]) == 2
    assert "a camera frame is given twice" in capsys.readouterr().err
    assert main([*base, "--images", str(tmp_path)]) == 2
    assert "expected DIR:FRAME" in capsys.readouterr().err
    (tmp_path / "joints.csv").write_text("pan,tilt\n0.1,0.2\n")
    assert main([*base, "--images", f"{tmp_path}:cam"]) == 2
    assert "no 'image' column" in capsys.readouterr().err
