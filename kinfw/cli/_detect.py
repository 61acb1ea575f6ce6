"""``kinfw detect``: find a board's corners in images and write them, paired with the
robot's joint values, as ``pixels`` observations of a ``kinfw-measurements`` file.

::

    kinfw detect IMAGES... --board SPEC --joints JOINTS.csv --camera CAM.yaml
                 --frame CAMERA_FRAME [--target NAME] [--allow-symmetric]
                 [--min-corners N] [--angle-unit rad|deg] --out DATA.json
    kinfw detect --images DIR:CAMERA_FRAME [--images DIR2:FRAME2 ...] --board SPEC ...

``SPEC`` names a chessboard, a ChArUco board, a symmetric or asymmetric circle grid or
Kalibr's AprilTag grid (:func:`kinfw.camera.parse_board`).

``JOINTS.csv``: a header of joint names and one row of joint values per image, either in
the order of ``IMAGES`` (as many rows as images) or, with a column named ``image``, keyed
by the image's path as given or its file name: every image needs exactly one row, and
rows naming images not given are left out with a note (detect a subset, hold out the
others: ``kinfw calibrate train.json --holdout test.json``). A file with the columns of a
hand pose (``hand_x ... hand_qw``, ``x ... qw``) is refused: ``kinfw pose-chain`` turns it
into a joints file. Spreadsheet dialects (a byte-order mark, ``;`` or tab separators,
decimal commas) are read as ``import-csv`` reads them (:func:`kinfw.measurements.csv_table`).

The output (format: ``docs/measurements.md``, the ``pixels`` kind) has the camera's
intrinsics under ``"cameras"`` and one sample per image where the board was found; the
images where it was not found, or found ambiguously (:mod:`kinfw.camera`), are listed on
stdout, one line each by file name (the first :data:`MAX_LISTED`, all with ``kinfw -v``),
and left out. ``--out`` must not be a URDF or xacro name, nor an existing file other than
a kinfw measurement file.

``--images DIR:FRAME`` (repeatable) reads a folder laid out as ``kinfw simulate --images``
writes it (:mod:`kinfw.simulation`): ``DIR/joints.csv`` keyed by an ``image`` column,
``DIR/camera.json`` and the images it names, seen by camera frame ``FRAME``. Several
folders (a stereo pair, cameras on several links) are merged into one file: images whose
joint values are equal (the same configuration, bit for bit as read) are one sample with
one observation per camera. Like :mod:`kinfw.cli`, this module imports only the standard library
at start-up; numpy and OpenCV are imported by the command.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from kinfw.cli._args import number
from kinfw.files import OutputPathError, check_outputs, write_text_atomic

IMAGE_COLUMN = "image"
#: ``--board``'s help.
BOARD_HELP = (
    "chessboard:COLSxROWS:SQUARE_M (inner corners), "
    "charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT] (squares; DICT default DICT_5X5_100), "
    "circles:COLSxROWS:SPACING_M[:DIAMETER_M[:ORIGIN_DIAMETER_M]] or "
    "acircles:COLSxROWS:SPACING_M[:DIAMETER_M[:ORIGIN_DIAMETER_M]] (OpenCV's symmetric and "
    "asymmetric circle grids: circles per row x rows; ORIGIN_DIAMETER_M: a larger disc 0 "
    "marks the origin), "
    "aprilgrid:COLSxROWS:TAG_M:SPACING[:FAMILY[:FIRST_ID[:BORDER_BITS]]] (Kalibr's "
    "aprilgrid: tags, SPACING a fraction of TAG_M, FAMILY default DICT_APRILTAG_36h11 "
    "(t36h11), first id 0, 2-bit borders); lengths in metres"
)


def add_detect_parser(sub: Any) -> None:
    """Add ``kinfw detect`` to the command line's sub-parsers."""
    p = sub.add_parser(
        "detect",
        help="find a board's corners in images and write pixel observations",
        description="Find a board's points in each image (OpenCV: a chessboard's or ChArUco "
        "board's corners, a circle grid's centres, an AprilTag grid's tag corners), numbered "
        "by the board, pair each image with its row of joint values and write a "
        "kinfw-measurements file of 'pixels' observations, with the camera's intrinsics and "
        "the points' board coordinates. Images where the board is not found, or found "
        "ambiguously (a symmetric chessboard's or circle grid's point 0 cannot be told), are "
        "listed and skipped.",
    )
    p.add_argument("images", type=Path, nargs="*", metavar="IMAGE", help="image files")
    p.add_argument(
        "--images",
        dest="folders",
        type=_folder_arg,
        action="append",
        default=[],
        metavar="DIR:FRAME",
        help="instead of IMAGE..., --joints, --camera and --frame: a folder as kinfw simulate "
        "--images writes it (DIR/joints.csv with an 'image' column, DIR/camera.json, the "
        "images), seen by camera frame FRAME; repeat for several cameras: images taken at "
        "equal joint values become one sample with an observation per camera",
    )
    p.add_argument(
        "--board",
        required=True,
        help=BOARD_HELP,
    )
    p.add_argument(
        "--joints",
        type=Path,
        help="CSV: a header of joint names, one row per image (in the images' order, or "
        "keyed by an 'image' column, whose rows for images not given are left out)",
    )
    p.add_argument(
        "--camera",
        type=Path,
        metavar="INTRINSICS.yaml",
        help="the camera's intrinsics (ROS camera_info YAML, OpenCV YAML/XML or JSON)",
    )
    p.add_argument(
        "--frame",
        help="URDF frame of the camera's optical frame (z forward, x right, y down)",
    )
    p.add_argument("--target", default="board", help="the board's target name (default board)")
    p.add_argument(
        "--target-frame",
        metavar="LINK",
        default=None,
        help="the URDF frame the board is fixed to (eye-to-hand: the flange; written as each "
        'observation\'s "target_frame"); default fixed in the world',
    )
    p.add_argument(
        "--allow-symmetric",
        action="store_true",
        help="accept a chessboard or circle grid that looks the same turned by 180 degrees "
        "(a chessboard with both counts of one parity, a symmetric circle grid): you vouch it "
        "is never seen turned by more than 90 degrees",
    )
    p.add_argument(
        "--min-corners",
        type=number(int, low=4),
        default=6,
        help="ChArUco, aprilgrid: fewest corners for an image to count (default 6, at least 4)",
    )
    p.add_argument(
        "--angle-unit",
        choices=("rad", "deg"),
        default="rad",
        help="unit of the joint values in --joints (default rad; prismatic joints in m)",
    )
    p.add_argument("--out", type=Path, required=True, help="measurement file to write (JSON)")
    p.set_defaults(func=cmd_detect, check_outputs=check_detect_outputs)


def _folder_arg(text: str) -> tuple[Path, str]:
    """``DIR:FRAME`` of ``--images`` (the last ``:`` splits, so DIR may hold one)."""
    folder, sep, frame = text.rpartition(":")
    if not sep or not folder or not frame.strip():
        raise argparse.ArgumentTypeError(
            f"expected DIR:FRAME (a folder of images and the camera frame), got {text!r}"
        )
    return Path(folder), frame.strip()


@dataclass(frozen=True, slots=True)
class _CameraImages:
    """One camera's images with their joints file, intrinsics file and frame."""

    images: tuple[Path, ...]
    joints: Path
    camera: Path
    frame: str


def _camera_images(args: argparse.Namespace) -> list[_CameraImages]:
    """The cameras of the command: ``IMAGE... --joints --camera --frame``, or one per
    ``--images DIR:FRAME`` (its images those its ``joints.csv`` names, in its order)."""
    from kinfw.simulation import CAMERA_FILE, JOINTS_FILE

    single = {"--joints": args.joints, "--camera": args.camera, "--frame": args.frame}
    if not args.folders:
        missing = [flag for flag, value in single.items() if value is None]
        if not args.images or missing:
            raise ValueError(
                "give the images, --joints, --camera and --frame (missing: "
                f"{', '.join(['IMAGE...'] * (not args.images) + missing)}), or --images DIR:FRAME"
            )
        return [_CameraImages(tuple(args.images), args.joints, args.camera, args.frame)]
    given = [flag for flag, value in single.items() if value is not None]
    if args.images or given:
        raise ValueError(
            f"--images DIR:FRAME reads each folder's {JOINTS_FILE} and {CAMERA_FILE}: give "
            f"no {', '.join(['IMAGE...'] * bool(args.images) + given)} with it"
        )
    frames = [frame for _, frame in args.folders]
    if len(set(frames)) != len(frames):
        raise ValueError(f"--images: a camera frame is given twice in {frames}")
    return [
        _CameraImages(
            _folder_images(folder / JOINTS_FILE), folder / JOINTS_FILE, folder / CAMERA_FILE, frame
        )
        for folder, frame in args.folders
    ]


def _folder_images(joints: Path) -> tuple[Path, ...]:
    """The images a folder's joints file names (its ``image`` column), beside it."""
    from kinfw.measurements import csv_table

    try:
        text = joints.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise OSError(f"{joints}: cannot read the joints CSV ({exc.strerror})") from None
    rows = [row for _, row in csv_table(text, str(joints)).rows]
    header = [c.strip() for c in rows[0]] if rows else []
    if IMAGE_COLUMN not in header:
        raise ValueError(
            f"{joints}: line 1: no '{IMAGE_COLUMN}' column naming each row's image "
            f"(header {header})"
        )
    column = header.index(IMAGE_COLUMN)
    return tuple(joints.parent / row[column].strip() for row in rows[1:] if len(row) > column)


def detect_inputs(args: argparse.Namespace) -> dict[str, Path]:
    """The input files of ``kinfw detect``, keyed by how the user gave them (for the
    check that ``--out`` overwrites none)."""
    inputs = {"--joints": args.joints, "--camera": args.camera}
    inputs.update({f"IMAGES[{k}]": path for k, path in enumerate(args.images)})
    for folder, frame in args.folders:
        inputs[f"--images {folder}:{frame}"] = folder
    return {flag: path for flag, path in inputs.items() if path is not None}


def read_joint_rows(path: Path, images: Sequence[Path]) -> tuple[list[str], list[list[float]]]:
    """The joint names and one row of joint values per image, in the order of ``images``.

    Parameters
    ----------
    path : Path
        The joints CSV: a header of joint names, one row per image, in the order of
        ``images`` or keyed by an ``image`` column (its path as given or its file name).
    images : sequence of Path
        The images given.

    Returns
    -------
    joints : list of str
        The joint names (the header less ``image``).
    rows : list of list of float
        One row per image. With an ``image`` column, rows naming images not given are
        left out (a subset of the images, the others held out).

    Raises
    ------
    ValueError
        Naming the file, line and column: no header, an empty or repeated joint name,
        the columns of a hand pose (``kinfw pose-chain``'s input, not joint values), a
        value that is not a finite number, a row of the wrong length; rows in order but
        not as many as images; an ``image`` column naming an image twice, or an image
        without a row.
    """
    joints, rows, _ = _joint_rows(path, images)
    return joints, rows


def _joint_rows(
    path: Path, images: Sequence[Path]
) -> tuple[list[str], list[list[float]], list[str]]:
    """:func:`read_joint_rows`, and the image names of the rows no image given uses."""
    header, rows = _read_joint_table(path)
    joints = [n for n in header if n != IMAGE_COLUMN]
    if IMAGE_COLUMN in header:
        ordered, unused = _rows_by_image(path, rows, images)
        return joints, ordered, unused
    if len(rows) != len(images):
        raise ValueError(
            f"{path}: {len(rows)} rows of joint values for {len(images)} images; give one "
            f"row per image in the images' order, or an '{IMAGE_COLUMN}' column naming each "
            f"row's image"
        )
    return joints, [values for _, values in rows], []


def _read_joint_table(path: Path) -> tuple[list[str], list[tuple[str, list[float]]]]:
    """The joints CSV's header and, per row, its ``image`` cell ("" without the column)
    and joint values (errors: :func:`read_joint_rows`)."""
    from kinfw.measurements import csv_table

    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise OSError(f"{path}: cannot read the joints CSV ({exc.strerror})") from None
    table = csv_table(text, str(path))
    if not table.rows:
        raise ValueError(f"{path}: empty; expected a header of joint names and one row per image")
    header = [c.strip() for c in table.rows[0][1]]
    if any(not name for name in header):
        raise ValueError(f"{path}: line 1: an empty column name in the header {header}")
    repeated = sorted({n for n in header if header.count(n) > 1})
    if repeated:
        raise ValueError(f"{path}: line 1: column(s) {repeated} appear twice in the header")
    if not [n for n in header if n != IMAGE_COLUMN]:
        raise ValueError(f"{path}: line 1: no joint columns in the header {header}")
    _refuse_hand_poses(path, header)
    rows: list[tuple[str, list[float]]] = []
    for line_number, row in table.rows[1:]:
        if len(row) != len(header):
            raise ValueError(
                f"{path}: line {line_number}: {len(row)} values, "
                f"the header has {len(header)} columns"
            )
        values, name = [], ""
        for column, cell in zip(header, row, strict=True):
            if column == IMAGE_COLUMN:
                name = cell.strip()
                continue
            try:
                value = table.number(cell)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise ValueError(
                    f"{path}: line {line_number}, column {column!r}: expected a finite number, "
                    f"got {cell!r}"
                )
            values.append(value)
        rows.append((name, values))
    return header, rows


def _refuse_hand_poses(path: Path, header: list[str]) -> None:
    """Refuse a header holding a hand pose's columns (``hand_x ... hand_qw`` or ``x ...
    qw``): the poses ``kinfw pose-chain`` reads, not joint values."""
    from kinfw.measurements import HAND_POSE_COLUMNS, PLAIN_POSE_COLUMNS

    for columns in (HAND_POSE_COLUMNS, PLAIN_POSE_COLUMNS):
        if set(columns) <= set(header):
            raise ValueError(
                f"{path}: line 1: the columns {', '.join(columns)} are a hand pose, not "
                f"joint values: this looks like hand poses; run kinfw pose-chain {path} "
                f"--camera-frame FRAME --urdf-out CHAIN.urdf --joints-out JOINTS.csv first "
                f"to get the joints file, and give that to --joints"
            )


def _rows_by_image(
    path: Path, rows: list[tuple[str, list[float]]], images: Sequence[Path]
) -> tuple[list[list[float]], list[str]]:
    """The rows of an ``image``-keyed joints file in the order of ``images`` (each
    matched by its path as given or its file name), and the names of the rows left
    over."""
    by_name: dict[str, int] = {}
    for index, (name, _) in enumerate(rows):
        if not name:
            raise ValueError(f"{path}: line {index + 2}: empty '{IMAGE_COLUMN}' cell")
        if name in by_name:
            raise ValueError(
                f"{path}: lines {by_name[name] + 2} and {index + 2} both name image {name!r}"
            )
        by_name[name] = index
    ordered, used = [], set()
    for image in images:
        index = by_name.get(str(image), by_name.get(image.name))
        if index is None:
            raise ValueError(
                f"{path}: no row for image {str(image)!r} (its '{IMAGE_COLUMN}' column names "
                f"neither {str(image)!r} nor {image.name!r})"
            )
        if index in used:
            raise ValueError(
                f"{path}: line {index + 2} ({rows[index][0]!r}) matches two of the images given"
            )
        used.add(index)
        ordered.append(rows[index][1])
    return ordered, [rows[i][0] for i in range(len(rows)) if i not in used]


def cmd_detect(args: argparse.Namespace) -> int:
    import time

    from kinfw.camera import Detector, parse_board

    board = parse_board(args.board)
    detector = Detector(board, allow_symmetric=args.allow_symmetric, min_corners=args.min_corners)
    if not args.target.strip():
        raise ValueError("--target: empty target name")
    cameras = _camera_images(args)
    if any(not c.frame.strip() for c in cameras):
        raise ValueError("--frame: empty camera frame name")
    start = time.perf_counter()
    per_camera = [_detect_camera(c, detector) for c in cameras]
    elapsed = time.perf_counter() - start
    n_images = sum(len(c.images) for c in cameras)
    joints = per_camera[0].joints
    for c, result in zip(cameras, per_camera, strict=True):
        if result.joints != joints:
            raise ValueError(
                f"{c.joints}: joint columns {result.joints} differ from "
                f"{cameras[0].joints}'s {joints}; the cameras' files must name the same joints"
            )
    found = [(c, d, q) for c, r in zip(cameras, per_camera, strict=True) for d, q in r.found]
    missed = [d for r in per_camera for d in r.missed]
    ambiguous = sum(d.status == "ambiguous" for d in missed)
    print(
        f"{n_images} images ({elapsed / n_images * 1e3:.0f} ms each): {len(found)} found, "
        f"{len(missed) - ambiguous} not found, {ambiguous} ambiguous"
    )
    _print_rejected(cameras, per_camera, verbose=getattr(args, "verbose", False))
    if not found:
        raise _found_in_none(board, missed)
    samples: dict[tuple[float, ...], list[dict[str, Any]]] = {}
    for camera, d, q in found:
        samples.setdefault(tuple(q), []).append(
            {
                "frame": camera.frame,
                "kind": "pixels",
                "target": args.target,
                **({} if args.target_frame is None else {"target_frame": args.target_frame}),
                "image": d.image,
                "uv": d.uv.tolist(),
                "points": d.points.tolist(),
                "ids": d.ids.tolist(),
            }
        )
    doc = {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "m", "angle": args.angle_unit},
        "joint_names": joints,
        "cameras": {
            c.frame: r.intrinsics.to_dict() for c, r in zip(cameras, per_camera, strict=True)
        },
        "samples": [{"q": list(q), "observations": obs} for q, obs in samples.items()],
    }
    write_text_atomic(args.out, _dumps(doc))
    corners = sum(len(d.ids) for _, d, _ in found)
    frames = ", ".join(repr(c.frame) for c in cameras)
    print(
        f"wrote {args.out}: {len(samples)} samples, {len(found)} images, {corners} corners of "
        f"target {args.target!r}"
        + ("" if args.target_frame is None else f" on {args.target_frame!r}")
        + f" seen by camera frame{'s' * (len(cameras) > 1)} {frames}"
    )
    return 0


#: Rejected images listed, one line each, before "... and N more" (all with -v).
MAX_LISTED = 10
#: What a board spec's ``COLSxROWS`` counts, by its type.
GRID_COUNTS = {
    "chessboard": "inner corners per row x rows",
    "charuco": "squares per row x rows",
    "circles": "circles per row x rows",
    "acircles": "circles per row x rows",
    "aprilgrid": "tags per row x rows",
}


def _print_rejected(
    cameras: list[_CameraImages], per_camera: list[_CameraDetections], *, verbose: bool
) -> None:
    """One line per image where the board was not found or is ambiguous: the image's
    file name (and camera frame, with several cameras) and why; the first
    :data:`MAX_LISTED`, then how many more, unless ``verbose``."""
    lines = [
        f"  {d.status}: {c.frame + ' ' if len(cameras) > 1 else ''}{Path(d.image).name}: {d.reason}"
        for c, r in zip(cameras, per_camera, strict=True)
        for d in r.missed
    ]
    shown = lines if verbose else lines[:MAX_LISTED]
    for line in shown:
        print(line)
    if len(lines) > len(shown):
        print(f"  ... and {len(lines) - len(shown)} more (kinfw -v detect lists them all)")


def _found_in_none(board: Any, missed: list[Any]) -> ValueError:
    """The error when no image shows the board: what was expected and, apart, the images
    where a symmetric board was found but refused as ambiguous (only these can take
    ``--allow-symmetric``)."""
    kind, size = board.spec().split(":")[:2]
    symmetric = [d for d in missed if d.symmetric]
    others = [d for d in missed if not d.symmetric]
    why = []
    if others:
        first = others[0]
        why.append(
            f"{len(others)} image(s) show no {size} {kind} ({size}: "
            f"{GRID_COUNTS.get(kind, 'COLSxROWS')}; first: {Path(first.image).name}: "
            f"{first.reason}); check --board and the images"
        )
    if symmetric:
        why.append(
            f"in {len(symmetric)} a symmetric {size} {kind} was found but is ambiguous "
            "(its point 0 cannot be told: use a chessboard whose corner counts differ in "
            "parity, an asymmetric circle grid, or --allow-symmetric if it is never turned "
            "by more than 90 degrees)"
        )
    return ValueError(
        f"the board {board.spec()} was found in none of the images: {'; '.join(why)}; "
        "nothing written"
    )


@dataclass(frozen=True, slots=True)
class _CameraDetections:
    """One camera's detections: the joints file's joint names, the images where the
    board was found with their joint values, the others, and the intrinsics."""

    joints: list[str]
    found: list[tuple[Any, list[float]]]
    missed: list[Any]
    intrinsics: Any


def _detect_camera(camera: _CameraImages, detector: Any) -> _CameraDetections:
    """Detect the board in one camera's images (checked against its intrinsics' size)."""
    from kinfw.camera import read_camera, read_gray

    for path in camera.images:  # before the joints file, which would miss its row
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such image file")
    intrinsics = read_camera(camera.camera)
    joints, qs, unused = _joint_rows(camera.joints, camera.images)
    if unused:
        print(f"note: {len(unused)} rows of {camera.joints} name images not given here (not used)")
    detections = []
    for path in camera.images:
        image = read_gray(path)
        if image.shape != (intrinsics.height, intrinsics.width):
            raise ValueError(
                f"{path}: image is {image.shape[1]}x{image.shape[0]} pixels, the camera "
                f"{camera.camera} is {intrinsics.width}x{intrinsics.height}"
            )
        detections.append(detector.detect(image, str(path)))
    found = [(d, q) for d, q in zip(detections, qs, strict=True) if d.found]
    return _CameraDetections(joints, found, [d for d in detections if not d.found], intrinsics)


def _dumps(doc: dict[str, Any]) -> str:
    """JSON text with one sample per line."""

    def dump(value: Any) -> str:
        return json.dumps(value, allow_nan=False, ensure_ascii=False)

    head = ",\n  ".join(f"{dump(k)}: {dump(v)}" for k, v in doc.items() if k != "samples")
    samples = ",\n    ".join(dump(s) for s in doc["samples"])
    return f'{{\n  {head},\n  "samples": [\n    {samples}\n  ]\n}}\n'


def check_detect_outputs(args: argparse.Namespace) -> None:
    """``kinfw detect``'s output: never one of its images or files, never a URDF or
    xacro file name, never over an existing file that is not a kinfw measurement file."""
    check_outputs({"--out": args.out}, inputs=detect_inputs(args))
    _check_measurement_output(args.out)


#: ``--out`` names that are a robot's model, not a measurement file.
MODEL_SUFFIXES = (".urdf", ".xacro")


def _check_measurement_output(path: Path) -> None:
    """Refuse ``--out`` when it ends in a URDF or xacro suffix, or names an existing
    (non-empty) file that is not a ``kinfw-measurements`` JSON document: writing would
    lose it.

    Raises
    ------
    OutputPathError
        Naming ``--out`` and why.
    """
    if path.suffix.lower() in MODEL_SUFFIXES:
        raise OutputPathError(
            f"--out {path}: a {path.suffix} file name; kinfw detect writes a measurement "
            "file (JSON, e.g. data.json): choose another --out"
        )
    if not path.is_file() or path.stat().st_size == 0:
        return
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):  # not UTF-8, not JSON
        doc = None
    if not isinstance(doc, dict) or doc.get("format") != "kinfw-measurements":
        raise OutputPathError(
            f"--out {path}: the existing file is not a kinfw measurement file (no "
            '"format": "kinfw-measurements"): refusing to overwrite it; choose another '
            "--out, or remove the file first"
        )
