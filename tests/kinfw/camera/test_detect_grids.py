"""Circle grids and AprilTag grids: board models against OpenCV's tutorial and Kalibr's
definitions (hand-computed points), detection on rendered images against the true
projection of the board's points (kinfw.simulation.render_board; see test_detect.py),
numbering by the board when the board is turned in the image, ambiguity and the errors.

"Error" below is the distance in pixels between the detected and the true pixel of the
same point id; a wrong numbering would be tens of pixels off.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinfw.camera import (
    APRILTAG_FAMILIES,
    AprilGrid,
    BoardError,
    CircleGrid,
    Detector,
    parse_board,
)
from kinfw.cli._main import main
from kinfw.simulation import render_board, true_corners
from tests.kinfw.camera.test_detect import CAMERA, POSES, board_pose

ACIRCLES = CircleGrid(4, 11, 0.015, asymmetric=True)  # OpenCV's acircles pattern shape
APRILGRID = AprilGrid(4, 3, 0.04, 0.3)  # 36h11, 2-bit border: Kalibr's defaults

#: Measured on these rendered poses (grey noise 1): median 0.018-0.029 px (circles),
#: 0.037-0.081 px (tags), max 0.086 and 0.133 px; the bounds leave a margin of ~2x.
MEDIAN_BOUND_PX = 0.1
MAX_BOUND_PX = 0.3


def errors(detection, board, camera_T_board):
    return np.linalg.norm(
        detection.uv - true_corners(board, CAMERA, camera_T_board)[detection.ids], axis=1
    )


# -- board models ---------------------------------------------------------------------------
def test_circle_grid_points_follow_opencvs_tutorial():
    """calcBoardCornerPositions: symmetric (j, i) * s; asymmetric ((2j + i % 2) s, i s)."""
    sym = CircleGrid(3, 3, 0.02)
    np.testing.assert_allclose(
        sym.points[:6, :2],
        [[0, 0], [0.02, 0], [0.04, 0], [0, 0.02], [0.02, 0.02], [0.04, 0.02]],
        atol=1e-15,
    )
    asym = CircleGrid(3, 3, 0.01, asymmetric=True)
    expected = [[0, 0], [2, 0], [4, 0], [1, 1], [3, 1], [5, 1], [0, 2], [2, 2], [4, 2]]
    np.testing.assert_allclose(asym.points[:, :2], np.array(expected) * 0.01, atol=1e-15)
    assert sym.diameter_m == pytest.approx(0.008)  # gen_pattern.py: radius spacing / 5
    assert sym.symmetric and not asym.symmetric and CircleGrid(4, 10, 0.01, True).symmetric
    assert not sym.partial and not APRILGRID.symmetric and APRILGRID.partial


def test_aprilgrid_points_are_kalibrs_with_y_down():
    """Kalibr's createGridPoints for 2 x 2 tags of 1 m, spacing 0.5 (its diagram: corners
    0-1-5-4 are tag 0 at the bottom left, y up), with y negated."""
    grid = AprilGrid(2, 2, 1.0, 0.5)
    kalibr_x = [0, 1, 1.5, 2.5] * 4
    kalibr_y = [0] * 4 + [1] * 4 + [1.5] * 4 + [2.5] * 4
    np.testing.assert_allclose(
        grid.points, np.stack([kalibr_x, np.negative(kalibr_y), [0] * 16], 1), atol=0
    )
    # OpenCV's corner order of a Kalibr tag: printed bottom-right, bottom-left, top-left, top-right
    np.testing.assert_array_equal(grid.corner_ids([0, 3]), [[1, 0, 4, 5], [11, 10, 14, 15]])
    np.testing.assert_array_equal(
        AprilGrid(2, 2, 1.0, 0.5, first_id=7).corner_ids([7]), [[1, 0, 4, 5]]
    )


def test_kalibr_draws_opencvs_marker_turned_by_180_degrees():
    """Kalibr's generateAprilTag: black where bit 6 i + j of the code is 0, the matrix
    turned by np.rot90(., 2), row i drawn at the top; a 2-bit border. Tag 0 of tag36h11
    is 0xd5d628584 in the AprilTag C++ library Kalibr copies its codes from."""
    import cv2

    code = 0xD5D628584
    black = np.array([[not code & (1 << (6 * i + j)) for j in range(6)] for i in range(6)])
    bits = np.ones((10, 10), dtype=bool)  # black border
    bits[2:8, 2:8] = np.rot90(black, 2)
    dictionary = APRILGRID.opencv_dictionary()
    opencv = cv2.aruco.generateImageMarker(dictionary, 0, 10, borderBits=2) < 128
    np.testing.assert_array_equal(bits, opencv[::-1, ::-1])


def test_apriltag_dictionary_sizes_are_opencvs():
    import cv2

    for name in APRILTAG_FAMILIES:
        size = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).bytesList.shape[0]
        with pytest.raises(BoardError, match=f"{name} has {size} tags"):
            AprilGrid(1, 1, 0.01, 0.3, name, first_id=size)
        AprilGrid(1, 1, 0.01, 0.3, name, first_id=size - 1)


def test_parse_grid_specs():
    assert parse_board("circles:4x5:0.02") == CircleGrid(4, 5, 0.02, False, 0.008)
    assert parse_board("ACIRCLES:4x11:0.015:0.005") == CircleGrid(4, 11, 0.015, True, 0.005)
    assert parse_board("aprilgrid:6x6:0.088:0.3") == AprilGrid(6, 6, 0.088, 0.3)
    assert parse_board("aprilgrid:5x5:0.088:0.3:t25h9:5:1") == AprilGrid(
        5, 5, 0.088, 0.3, "DICT_APRILTAG_25h9", 5, 1
    )
    assert (
        parse_board("aprilgrid:2x2:0.05:0.25:dict_apriltag_16H5").dictionary == "DICT_APRILTAG_16h5"
    )
    for board in (ACIRCLES, APRILGRID, CircleGrid(3, 3, 0.05)):
        assert parse_board(board.spec()) == board


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ("circles:4x5", "wrong number of ':' fields"),
        ("acircles:4x11:0.02:0.03", r"diameter_m \(0.03\) must be smaller than .* \(0.028"),
        ("circles:2x5:0.02", "cols must be an integer >= 3"),
        ("circles:4x5:20", "more than 2 m"),
        ("aprilgrid:6x6:0.088", "wrong number of ':' fields"),
        ("aprilgrid:6x6:0.088:1.5", r"spacing must be in \(0, 1\]"),
        ("aprilgrid:6x6:0.088:0.3:DICT_5X5_100", "unknown AprilTag family 'DICT_5X5_100'"),
        ("aprilgrid:6x6:0.088:0.3:t36h11:x", "FIRST_ID 'x' is not an integer"),
        ("aprilgrid:6x6:0.088:0.3:t36h11:0:0", "border_bits must be an integer >= 1"),
        ("aprilgrid:6x6:0.088:0.3:t16h5", r"has 30 tags .* needs ids up to 35"),
    ],
)
def test_parse_grid_spec_errors(spec, match):
    with pytest.raises(BoardError, match=match):
        parse_board(spec)


# -- detection on rendered images ---------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("board", [ACIRCLES, APRILGRID], ids=["acircles", "aprilgrid"])
@pytest.mark.parametrize(("tilt", "roll"), POSES)
def test_grid_points_subpixel_and_numbered_by_the_board(board, tilt, roll):
    """Turned by any roll (upside down too): every point carries the board's number."""
    camera_T_board = board_pose(board, tilt, roll)
    image = render_board(board, CAMERA, camera_T_board, noise_sigma=1.0)
    detection = Detector(board).detect(image, "x.png")
    assert detection.status == "found", detection.reason
    np.testing.assert_array_equal(detection.ids, np.arange(board.count))  # all seen
    np.testing.assert_array_equal(detection.points, board.points)
    e = errors(detection, board, camera_T_board)
    assert np.median(e) < MEDIAN_BOUND_PX and e.max() < MAX_BOUND_PX


@pytest.mark.slow
@pytest.mark.parametrize("board", [CircleGrid(7, 5, 0.03), CircleGrid(5, 5, 0.03)])
def test_symmetric_circle_grid_is_ambiguous_unless_allowed(board):
    upright = board_pose(board, [0.2, -0.2, 0.0], 0.3)
    turned = board_pose(board, [0.2, -0.2, 0.0], 0.3 + np.pi)
    for camera_T_board in (upright, turned):
        detection = Detector(board).detect(render_board(board, CAMERA, camera_T_board))
        assert detection.status == "ambiguous" and detection.symmetric
        assert "looks the same turned by 180 degrees" in detection.reason
        assert ("(and 90)" in detection.reason) == (board.cols == board.rows)
    allowed = Detector(board, allow_symmetric=True)
    up = allowed.detect(render_board(board, CAMERA, upright))
    assert np.median(errors(up, board, upright)) < MEDIAN_BOUND_PX
    # turned: the same picture, numbered as the board turned by 180 degrees
    down = allowed.detect(render_board(board, CAMERA, turned))
    truth = true_corners(board, CAMERA, turned)[::-1]
    assert np.median(np.linalg.norm(down.uv - truth, axis=1)) < MEDIAN_BOUND_PX


SEVEN_BY_FIVE = CircleGrid(7, 5, 0.03, diameter_m=0.012)


@pytest.mark.parametrize(
    ("spec", "more"),
    [
        (CircleGrid(6, 5, 0.03), "more than 6 circles per row"),
        (CircleGrid(7, 4, 0.03), "more than 4 rows"),
        (CircleGrid(9, 9, 0.0254, False, 0.01), "more than 9"),
    ],
    ids=["6x5", "7x4", "9x9"],
)
@pytest.mark.slow
def test_a_spec_smaller_than_the_circle_grid_is_not_found_saying_so(spec, more):
    """A 7 x 5 grid read as 6 x 5 or 7 x 4, the 10 x 10 modified grid as 9 x 9
    (noise-free, POSES[:3]): OpenCV's findCirclesGrid finds that many discs inside the
    board (measured, OpenCV 4.x), a symmetric grid. The discs continuing past them make
    each image not found, naming the count; never ambiguous (allow_symmetric would
    number a part of the board)."""
    board = MODIFIED if spec.cols == 9 else SEVEN_BY_FIVE
    distance = 0.6 if board is MODIFIED else 0.5
    for tilt, roll in POSES[:3]:
        image = render_board(board, CAMERA, board_pose(board, tilt, roll, distance=distance))
        assert Detector(board, allow_symmetric=True).detect(image).found  # the right size
        for allow in (False, True):
            detection = Detector(spec, allow_symmetric=allow).detect(image)
            assert detection.status == "not found" and not detection.symmetric
            assert detection.reason.startswith(
                f"the {spec.cols}x{spec.rows} circles grid found is part of a larger grid "
                f"(discs continue past it: {more}"
            ), detection.reason


def test_asymmetric_grid_with_even_rows_is_refused():
    with pytest.raises(BoardError, match=r"even number of rows .* use an odd number of rows"):
        Detector(CircleGrid(4, 10, 0.015, asymmetric=True))


def test_aprilgrid_partly_in_view_keeps_the_tags_it_sees():
    camera_T_board = board_pose(APRILGRID, [0.0, 0.2, 0.0], 0.2, distance=0.4, shift=(0.15, 0.0))
    camera_ps = APRILGRID.points @ camera_T_board[:3, :3].T + camera_T_board[:3, 3]
    inside = CAMERA.in_view(camera_ps, margin_px=0)
    assert 8 <= inside.sum() < APRILGRID.count  # the pose does cut the board
    detection = Detector(APRILGRID).detect(render_board(APRILGRID, CAMERA, camera_T_board))
    assert detection.found and set(detection.ids) <= set(np.flatnonzero(inside))
    assert len(detection.ids) >= 16
    e = errors(detection, APRILGRID, camera_T_board)
    assert np.median(e) < MEDIAN_BOUND_PX and e.max() < MAX_BOUND_PX


def test_aprilgrid_wrong_family_first_id_or_border_is_not_found():
    camera_T_board = board_pose(APRILGRID, [0.1, 0.2, 0.0], 0.3)
    image = render_board(APRILGRID, CAMERA, camera_T_board)
    other_family = Detector(AprilGrid(4, 3, 0.04, 0.3, "DICT_APRILTAG_25h9")).detect(image)
    assert other_family.status == "not found"
    assert "no tag of DICT_APRILTAG_25h9 (2-bit border)" in other_family.reason
    other_ids = Detector(AprilGrid(4, 3, 0.04, 0.3, first_id=100)).detect(image)
    assert other_ids.status == "not found"
    assert "are not the board's" in other_ids.reason and "ids 100-111" in other_ids.reason
    one_bit = Detector(AprilGrid(4, 3, 0.04, 0.3, border_bits=1)).detect(image)
    assert one_bit.status == "not found" and "1-bit border" in one_bit.reason


def test_aprilgrid_of_the_wrong_shape_is_not_found():
    """A 4 x 3 print read as 3 x 4: only a row of three tags fits the wrong layout (up to a
    shift of the whole board, which one image cannot tell): the image is refused, not
    numbered by the wrong layout."""
    camera_T_board = board_pose(APRILGRID, [0.1, 0.2, 0.0], 0.3)
    image = render_board(APRILGRID, CAMERA, camera_T_board)
    detection = Detector(AprilGrid(3, 4, 0.04, 0.3)).detect(image)
    assert detection.status == "not found"
    assert "of the 12 tags seen do not fit the board's layout" in detection.reason


# -- the command ----------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("board", [ACIRCLES, APRILGRID], ids=["acircles", "aprilgrid"])
def test_detect_command_writes_grid_points(tmp_path, capsys, board):
    import cv2

    poses = [board_pose(board, tilt, roll) for tilt, roll in POSES[:3]]
    poses.append(board_pose(board, [0.0, 0.0, 0.0], 0.0, shift=(1.0, 0.0)))  # not seen
    images = []
    for k, camera_T_board in enumerate(poses):
        images.append(tmp_path / f"img_{k}.png")
        cv2.imwrite(str(images[-1]), render_board(board, CAMERA, camera_T_board, noise_sigma=1.0))
    (tmp_path / "cam.json").write_text(json.dumps(CAMERA.to_dict()))
    (tmp_path / "q.csv").write_text("pan\n0.1\n0.2\n0.3\n0.4\n")
    out = tmp_path / "data.json"
    code = main(
        ["detect", *map(str, images), "--board", board.spec(), "--joints", str(tmp_path / "q.csv"),
         "--camera", str(tmp_path / "cam.json"), "--frame", "cam", "--out", str(out)]
    )  # fmt: skip
    assert code == 0
    assert "3 found, 1 not found, 0 ambiguous" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    for sample, camera_T_board in zip(doc["samples"], poses, strict=False):
        (obs,) = sample["observations"]
        points, uv = np.array(obs["points"]), np.array(obs["uv"])
        np.testing.assert_array_equal(points, board.points[obs["ids"]])  # the board's 3-D points
        reprojected = CAMERA.project(points @ camera_T_board[:3, :3].T + camera_T_board[:3, 3])
        assert np.median(np.linalg.norm(uv - reprojected, axis=1)) < MEDIAN_BOUND_PX


#: industrial_calibration's modified circle grid, 10 x 10: disc 0 twice the others.
MODIFIED = CircleGrid(10, 10, 0.0254, False, 0.01, 0.02)


@pytest.mark.slow
def test_a_larger_origin_disc_numbers_a_square_grid_at_every_roll():
    """A square symmetric grid with a larger disc 0 (the modified circle grid), rendered
    turned by 0, 90, 180 and 270 degrees (and tilted): found without allow_symmetric,
    every centre numbered by the board (its distance from the truth's projection of the
    same board point: median < 0.1 px, max < 0.3 px); the same images read as a grid
    without the origin disc are ambiguous. The spec round-trips, and an origin disc no
    larger than the others, or as wide as the spacing, is refused."""
    plain = CircleGrid(10, 10, 0.0254, False, 0.01)
    for roll in (0.3, 0.3 + np.pi / 2, 0.3 + np.pi, 0.3 - np.pi / 2):
        camera_T_board = board_pose(MODIFIED, [0.2, -0.25, 0.0], roll, distance=0.6)
        image = render_board(MODIFIED, CAMERA, camera_T_board, noise_sigma=1.0)
        detection = Detector(MODIFIED).detect(image, "x.png")
        assert detection.status == "found", detection.reason
        np.testing.assert_array_equal(detection.points, MODIFIED.points)
        e = errors(detection, MODIFIED, camera_T_board)
        assert np.median(e) < MEDIAN_BOUND_PX and e.max() < MAX_BOUND_PX, (roll, e.max())
        # read without the origin disc: ambiguous, asking for the spec's origin field
        # (not for allow_symmetric, which would ignore the disc)
        without = Detector(plain).detect(image)
        assert without.status == "ambiguous" and not without.symmetric
        assert without.reason == (
            "a corner disc of the 10x10 circles grid is larger than the others (an origin "
            "disc?), but the spec gives no ORIGIN_DIAMETER_M: give its diameter, "
            "circles:10x10:0.0254:0.01:ORIGIN_DIAMETER_M (metres)"
        )
    assert not MODIFIED.symmetric and plain.symmetric
    assert parse_board("circles:10x10:0.0254:0.01:0.02") == MODIFIED
    assert parse_board(MODIFIED.spec()) == MODIFIED
    with pytest.raises(BoardError, match=r"origin_diameter_m .* must be larger than diameter_m"):
        parse_board("circles:10x10:0.0254:0.01:0.01")
    with pytest.raises(BoardError, match="smaller than spacing_m"):
        parse_board("circles:10x10:0.0254:0.01:0.03")
