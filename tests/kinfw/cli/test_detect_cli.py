"""``kinfw detect`` as a new user meets it after ``kinfw pose-chain``: a wrong board size
or an incomplete spec, the hand poses given as the joints file, a long list of rejected
images, an ``--out`` that is not a measurement file, and a subset of the images detected
from one joints file (the others held out).

Truths: the images are rendered here from known boards (:func:`kinfw.simulation.
render_board`, noise-free) or blank, the files written here; the messages, exit codes and
files must be exactly what those imply.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from kinfw.camera import CameraIntrinsics, Chessboard, CircleGrid
from kinfw.cli._main import main
from kinfw.simulation import render_board
from tests.paths import HEAD_URDF
from tests.rendered_head import render_left_camera

CAMERA = CameraIntrinsics(480, 360, 400.0, 404.0, 241.3, 178.9, k1=-0.1, name="cam")
CHESS = Chessboard(9, 6, 0.03)
#: camera_T_board rotations (rotation vectors) of the rendered views.
TILTS = ([0.0, 0.0, 0.0], [0.25, -0.3, 0.4], [-0.3, 0.1, -0.2])


def _pose(board, rotvec, distance=0.5):
    """camera_T_board: the board's centre ``distance`` m ahead, turned by ``rotvec``."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = np.array([0.0, 0.0, distance]) - T[:3, :3] @ board.points.mean(axis=0)
    return T


def _images(folder: Path, board, n: int = len(TILTS), distance: float = 0.5) -> list[Path]:
    """``n`` noise-free images ``img_K.png`` of ``board`` (the views of :data:`TILTS`,
    repeated), and ``cam.json`` with the camera's intrinsics."""
    import cv2

    folder.mkdir(exist_ok=True)
    (folder / "cam.json").write_text(json.dumps(CAMERA.to_dict()))
    paths = []
    for k in range(n):
        paths.append(folder / f"img_{k}.png")
        pose = _pose(board, TILTS[k % len(TILTS)], distance)
        cv2.imwrite(str(paths[-1]), render_board(board, CAMERA, pose))
    return paths


def _detect(images, joints, board_spec, out, capsys, *extra, verbose=False):
    """Exit code, stdout and stderr of ``kinfw -q|-v detect``."""
    argv = ["-v" if verbose else "-q", "detect", *map(str, images), "--board", board_spec]
    argv += ["--joints", str(joints), "--camera", str(Path(images[0]).parent / "cam.json")]
    code = main([*argv, "--frame", "cam", "--out", str(out), *extra])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _ordered_joints(path: Path, n: int) -> Path:
    path.write_text("pan\n" + "".join(f"{0.1 * k}\n" for k in range(n)))
    return path


# -- the board not found: what was expected, and --allow-symmetric only when it helps ------
@pytest.mark.slow
def test_a_grid_size_smaller_than_the_board_says_so_never_allow_symmetric(tmp_path, capsys):
    """A 7 x 5 circle grid given as circles:6x5: OpenCV finds 6 x 5 discs inside it
    (symmetric: the old message offered --allow-symmetric, which would number a part of
    the board). Each image is listed as part of a larger grid; the error says what was
    expected, and no --allow-symmetric anywhere."""
    board = CircleGrid(7, 5, 0.03, diameter_m=0.012)
    images = _images(tmp_path, board)
    joints = _ordered_joints(tmp_path / "q.csv", len(images))
    code, out, err = _detect(images, joints, "circles:6x5:0.03", tmp_path / "o.json", capsys)
    assert code == 2 and not (tmp_path / "o.json").exists()
    assert "--allow-symmetric" not in out + err
    listed = [line for line in out.splitlines() if line.startswith("  not found: ")]
    assert len(listed) == 3
    assert all(
        "part of a larger grid (discs continue past it: more than 6 circles" in x for x in listed
    )
    assert err.startswith(
        "kinfw detect: error: the board circles:6x5:0.03:0.012 was found in none of the "
        "images: 3 image(s) show no 6x5 circles (6x5: circles per row x rows; first: "
        "img_0.png: the 6x5 circles grid found is part of a larger grid"
    )
    assert err.rstrip().endswith("check --board and the images; nothing written")


@pytest.mark.slow
def test_an_origin_disc_the_spec_lacks_is_asked_for_not_allow_symmetric(tmp_path, capsys):
    """industrial_calibration's modified grid (10 x 10, a larger disc 0) given without
    ORIGIN_DIAMETER_M: ambiguous, and the error asks for that field."""
    board = CircleGrid(10, 10, 0.0254, False, 0.01, 0.02)
    images = _images(tmp_path, board, n=2, distance=0.6)
    joints = _ordered_joints(tmp_path / "q.csv", 2)
    spec = "circles:10x10:0.0254:0.01"
    code, out, err = _detect(images, joints, spec, tmp_path / "o.json", capsys)
    assert code == 2 and "--allow-symmetric" not in out + err
    assert "0 found, 0 not found, 2 ambiguous" in out
    assert (
        f"the spec gives no ORIGIN_DIAMETER_M: give its diameter, {spec}:ORIGIN_DIAMETER_M" in err
    )
    code, out, err = _detect(images, joints, f"{spec}:0.02", tmp_path / "o.json", capsys)
    assert code == 0, err


# -- the joints file -------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("prefix", ["hand_", ""])
def test_hand_poses_given_as_the_joints_file_are_refused_with_the_next_step(
    tmp_path, capsys, prefix
):
    images = _images(tmp_path, CHESS, n=1)
    joints = tmp_path / "poses.csv"
    columns = [f"{prefix}{c}" for c in ("x", "y", "z", "qx", "qy", "qz", "qw")]
    joints.write_text(f"image,{','.join(columns)}\nimg_0.png,0.1,0.2,0.3,0,0,0,1\n")
    code, out, err = _detect(images, joints, CHESS.spec(), tmp_path / "o.json", capsys)
    assert code == 2 and out == "" and not (tmp_path / "o.json").exists()
    assert err == (
        f"kinfw detect: error: {joints}: line 1: the columns {', '.join(columns)} are a hand "
        f"pose, not joint values: this looks like hand poses; run kinfw pose-chain {joints} "
        "--camera-frame FRAME --urdf-out CHAIN.urdf --joints-out JOINTS.csv first to get "
        "the joints file, and give that to --joints\n"
    )


def test_keyed_rows_of_images_not_given_are_a_note_not_an_error(tmp_path, capsys):
    """An image-keyed joints file with rows for 5 images, 3 of them given: one note, the
    3 detected with their own rows. Unkeyed, a count mismatch is still refused."""
    images = _images(tmp_path, CHESS)
    joints = tmp_path / "joints.csv"
    joints.write_text("image,pan\n" + "".join(f"img_{k}.png,{0.1 * k}\n" for k in (4, 0, 3, 1, 2)))
    out_file = tmp_path / "o.json"
    code, out, err = _detect(images, joints, CHESS.spec(), out_file, capsys)
    assert code == 0, err
    notes = [line for line in out.splitlines() if line.startswith("note:")]
    assert notes == [f"note: 2 rows of {joints} name images not given here (not used)"]
    doc = json.loads(out_file.read_text())
    assert [s["q"] for s in doc["samples"]] == [[0.0], [0.1], [0.2]]
    assert [s["observations"][0]["image"] for s in doc["samples"]] == list(map(str, images))
    code, _, err = _detect(images, _ordered_joints(joints, 5), CHESS.spec(), out_file, capsys)
    assert code == 2 and "5 rows of joint values for 3 images" in err


def test_a_missing_image_is_named_not_blamed_on_the_joints_file(tmp_path, capsys):
    """A typo in an image's name was reported as the joints file's: 'no row for image'
    (keyed by image) or '3 rows of joint values for 4 images' (in order)."""
    images = _images(tmp_path, CHESS)
    typo = tmp_path / "img_O.png"
    keyed = tmp_path / "keyed.csv"
    keyed.write_text("image,pan\n" + "".join(f"img_{k}.png,{0.1 * k}\n" for k in range(3)))
    ordered = _ordered_joints(tmp_path / "ordered.csv", 3)
    for joints in (keyed, ordered):
        given = [*images, typo]
        code, _, err = _detect(given, joints, CHESS.spec(), tmp_path / "o.json", capsys)
        assert code == 2
        assert err == f"kinfw detect: error: {typo}: no such image file\n"
    assert not (tmp_path / "o.json").exists()


def test_a_spreadsheet_joints_file_is_read_as_import_csv_reads_it(tmp_path, capsys):
    """``image;pan;tilt`` with decimal commas and a byte-order mark (read as one column
    and refused: 'expected a finite number') gives the samples of the plain file."""
    images = _images(tmp_path, CHESS)
    rows = [(f"img_{k}.png", 0.125 * k, -0.5 + k / 8) for k in (2, 0, 1)]
    plain = tmp_path / "plain.csv"
    plain.write_text("image,pan,tilt\n" + "".join(f"{n},{a!r},{b!r}\n" for n, a, b in rows))
    sheet = tmp_path / "sheet.csv"
    text = "image;pan;tilt\n" + "".join(f"{n};{a!r};{b!r}\n" for n, a, b in rows)
    sheet.write_text("\ufeff" + re.sub(r"(\d)\.(\d)", r"\1,\2", text), encoding="utf-8")
    docs = []
    for joints in (plain, sheet):
        code, _, err = _detect(
            images, joints, CHESS.spec(), tmp_path / f"{joints.stem}.json", capsys
        )
        assert code == 0, err
        docs.append(json.loads((tmp_path / f"{joints.stem}.json").read_text()))
    assert docs[1]["joint_names"] == ["pan", "tilt"]
    assert [s["q"] for s in docs[1]["samples"]] == [[0.0, -0.5], [0.125, -0.375], [0.25, -0.25]]
    assert docs[1]["samples"] == docs[0]["samples"]


# -- the list of rejected images -------------------------------------------------------------
@pytest.mark.slow
def test_rejected_images_are_one_line_each_by_name_ten_at_most(tmp_path, capsys):
    """12 blank images and one of the board: 10 lines, each the file name (not the
    path) and the reason, then '... and 2 more'; with -v all 12."""
    import cv2

    images = _images(tmp_path, CHESS, n=1)
    for k in range(1, 13):
        images.append(tmp_path / f"blank_{k:02d}.png")
        cv2.imwrite(str(images[-1]), np.full((CAMERA.height, CAMERA.width), 128, np.uint8))
    joints = _ordered_joints(tmp_path / "q.csv", len(images))
    code, out, err = _detect(images, joints, CHESS.spec(), tmp_path / "o.json", capsys)
    assert code == 0, err
    listed = [line for line in out.splitlines() if line.startswith("  ")]
    expected = [f"  not found: blank_{k:02d}.png: no 9x6 chessboard" for k in range(1, 13)]
    assert listed == [*expected[:10], "  ... and 2 more (kinfw -v detect lists them all)"]
    code, out, err = _detect(
        images, joints, CHESS.spec(), tmp_path / "o.json", capsys, verbose=True
    )
    assert code == 0, err
    assert [line for line in out.splitlines() if line.startswith("  ")] == expected


# -- --out -----------------------------------------------------------------------------------
def test_out_never_overwrites_a_file_that_is_not_a_measurement_file(tmp_path, capsys):
    """A URDF name (existing or not, .urdf or .xacro) and an existing file that is not a
    kinfw measurement file (a URDF named .json, JSON of something else) are refused
    before any work, exit 2, the file untouched; a measurement file detect wrote is
    overwritten."""
    images = _images(tmp_path, CHESS, n=1)
    joints = _ordered_joints(tmp_path / "q.csv", 1)
    robot = tmp_path / "robot.urdf"
    robot.write_text("<robot name='r'/>")
    for out in (robot, tmp_path / "new.urdf", tmp_path / "robot.urdf.xacro"):
        code, stdout, err = _detect(images, joints, CHESS.spec(), out, capsys)
        assert code == 2 and stdout == ""
        assert err == (
            f"kinfw detect: error: --out {out}: a {out.suffix} file name; kinfw detect writes "
            "a measurement file (JSON, e.g. data.json): choose another --out\n"
        )
    assert robot.read_text() == "<robot name='r'/>" and not (tmp_path / "new.urdf").exists()
    for content in ("<robot name='r'/>", '{"samples": []}', "[1, 2]"):
        other = tmp_path / "other.json"
        other.write_text(content)
        code, stdout, err = _detect(images, joints, CHESS.spec(), other, capsys)
        assert code == 2 and stdout == "" and other.read_text() == content
        assert err == (
            f"kinfw detect: error: --out {other}: the existing file is not a kinfw "
            'measurement file (no "format": "kinfw-measurements"): refusing to overwrite '
            "it; choose another --out, or remove the file first\n"
        )
    data = tmp_path / "data.json"
    assert _detect(images, joints, CHESS.spec(), data, capsys)[0] == 0
    first = data.read_text()
    joints.write_text("pan\n0.7\n")
    assert _detect(images, joints, CHESS.spec(), data, capsys)[0] == 0
    assert json.loads(data.read_text())["samples"][0]["q"] == [0.7] and data.read_text() != first


# -- held-out images from one joints file ----------------------------------------------------
@pytest.mark.slow
def test_two_subsets_of_one_folder_train_and_hold_out(tmp_path, capsys):
    """simulate --images (the IIS head's left camera, 14 images); detect images 0-8 and
    9-13 separately with the folder's joints.csv (a note each); calibrate the first
    --holdout the second: the held-out table has the camera's pixel row, finite and a
    few px (measured 3.8 px: frames alone leave the simulated kinematic error, 2.2 px
    in-sample)."""
    root = tmp_path
    cam = render_left_camera(root, 14, 3)
    images = sorted(cam.glob("*.png"))
    assert len(images) == 14
    joints = cam / "joints.csv"
    for name, part in (("train", images[:9]), ("test", images[9:])):
        argv = ["detect", *map(str, part), "--board", "chessboard:9x6:0.04"]
        argv += ["--joints", str(joints), "--camera", str(cam / "camera.json")]
        assert main([*argv, "--frame", "left_camera", "--out", str(root / f"{name}.json")]) == 0
        note = f"note: {14 - len(part)} rows of {joints} name images not given here (not used)"
        assert note in capsys.readouterr().out
    argv = ["-q", "calibrate", str(root / "train.json"), "--urdf", str(HEAD_URDF)]
    argv += ["--params", "frames", "--out", str(root / "cal.urdf")]
    assert main([*argv, "--holdout", str(root / "test.json")]) == 0
    out = capsys.readouterr().out
    table = out[out.index("held-out errors:") :].splitlines()
    header = next(line for line in table if "after RMS px" in line)
    (row,) = [line for line in table if line.strip().startswith("left_camera (pixels)")]
    end = header.index("after RMS px") + len("after RMS px")
    after = float(re.split(r"\s+", row[:end].strip())[-1])
    assert math.isfinite(after) and 0.0 < after < 10.0, row
