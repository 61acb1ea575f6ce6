"""Calibration boards: the point model of a chessboard, a ChArUco board, a circle grid or
an AprilTag grid, and the command-line spec that names one.

The board frame (``board``): ``z = 0`` is the printed face, ``x`` along the board's
columns, ``y`` along its rows, ``z = x cross y`` into the board (away from a camera that
sees the printed face); metres.

- :class:`Chessboard` ``(cols, rows, square_m)``: ``cols x rows`` **inner** corners, in
  OpenCV's numbering (row by row: corner ``i`` is at column ``i % cols``, row
  ``i // cols``); the origin is the first inner corner, so corner ``i`` is at
  ``(i % cols, i // cols, 0) * square_m``. The square whose corners are inner corners
  ``0, 1, cols, cols + 1`` is **black** (with a black top-left square printed, as OpenCV's
  ``gen_pattern.py`` and ``CharucoBoard.generateImage`` do, the top-left inner corner is
  corner 0 and this square is black whatever the parity).
- :class:`Charuco` ``(cols, rows, square_m, marker_m, dictionary)``: ``cols x rows``
  **squares** (OpenCV's ``cv2.aruco.CharucoBoard((cols, rows), ...)``), so
  ``(cols - 1) x (rows - 1)`` corners with OpenCV's ChArUco ids; the points are
  ``CharucoBoard.getChessboardCorners()``: the origin is the board's outer top-left
  corner (of the printed squares), corner ``id`` at
  ``((id % (cols-1)) + 1, (id // (cols-1)) + 1, 0) * square_m``.
- :class:`CircleGrid` ``(cols, rows, spacing_m, asymmetric, diameter_m)``: dark discs
  on a light background, OpenCV's ``findCirclesGrid`` patterns, ``patternSize = (cols,
  rows)``, numbered row by row as in OpenCV's calibration tutorial
  (``calcBoardCornerPositions``): symmetric, centre ``i`` at
  ``(i % cols, i // cols, 0) * spacing_m``; asymmetric, centre ``i`` (row
  ``r = i // cols``, column ``j = i % cols``) at ``(2 j + r % 2, r, 0) * spacing_m``
  (so ``spacing_m`` is half the distance between neighbours in a row). The discs'
  diameter defaults to ``0.4 * spacing_m``, the one of OpenCV's ``gen_pattern.py``
  (radius ``spacing / 5``); it matters only to draw the board. ``origin_diameter_m``: disc
  0 is larger (industrial_calibration's modified circle grid, whose large dot is its
  origin), which tells a square or symmetric grid's numbering (the detector reads the
  blobs' sizes).
- :class:`AprilGrid` ``(cols, rows, tag_m, spacing, dictionary, first_id,
  border_bits)``: Kalibr's ``aprilgrid``: ``cols x rows`` AprilTags of side ``tag_m``
  (edge to edge of the black border), ``spacing * tag_m`` apart, tag ids row by row
  from ``first_id`` starting at the **bottom**-left tag as printed (Kalibr's
  ``kalibr_create_target_pdf``, which draws on a page with y up). The points are the
  tags' corners in Kalibr's numbering: a grid of ``2 rows x 2 cols`` corners numbered
  row by row from the bottom-left corner of tag ``first_id``; corner ``r * 2 cols + c``
  at ``x = (c // 2) * pitch + (c % 2) * tag_m``, ``y = -((r // 2) * pitch + (r % 2) *
  tag_m)`` with ``pitch = (1 + spacing) * tag_m``. The frame is Kalibr's target frame
  (origin at the bottom-left corner of tag ``first_id``, x right, y **up** the page)
  turned by 180 degrees about x, so that y runs down the page and z into the board as
  for the other boards: a Kalibr point ``(x, y, 0)`` is kinfw's ``(x, -y, 0)``.

Specs (:func:`parse_board`): ``chessboard:COLSxROWS:SQUARE_M`` (inner corners),
``charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT]`` (squares; ``DICT`` an OpenCV predefined
ArUco dictionary, default ``DICT_5X5_100``, the one of OpenCV's ChArUco tutorial),
``circles:COLSxROWS:SPACING_M[:DIAMETER_M[:ORIGIN_DIAMETER_M]]`` and
``acircles:COLSxROWS:SPACING_M[:DIAMETER_M[:ORIGIN_DIAMETER_M]]``
(circles per row x rows, OpenCV's names), and
``aprilgrid:COLSxROWS:TAG_M:SPACING[:FAMILY[:FIRST_ID[:BORDER_BITS]]]`` (tags; Kalibr's
``tagCols x tagRows``, ``tagSize`` in metres and ``tagSpacing`` as a fraction of the tag
size; ``FAMILY`` one of OpenCV's AprilTag dictionaries, ``DICT_APRILTAG_36h11`` (default,
Kalibr's), ``_36h10``, ``_25h9``, ``_16h5``, or Kalibr's names ``t36h11`` ...;
``BORDER_BITS`` the black border's width in bits, 2 as Kalibr prints it, 1 as OpenCV and
the AprilTag library's images). Lengths in metres.

This module imports OpenCV only inside the ``opencv_*`` methods.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: The ArUco dictionary of a ChArUco spec that names none (OpenCV's ChArUco tutorial's).
DEFAULT_DICTIONARY = "DICT_5X5_100"

_DICTIONARY = re.compile(r"DICT_(\d+)X\1_(\d+)|DICT_ARUCO_ORIGINAL|DICT_APRILTAG_\w+")

#: OpenCV's AprilTag dictionaries (``cv2.aruco.DICT_APRILTAG_*``), the families an
#: :class:`AprilGrid` may use; the first is the default (Kalibr's).
APRILTAG_FAMILIES = (
    "DICT_APRILTAG_36h11",
    "DICT_APRILTAG_36h10",
    "DICT_APRILTAG_25h9",
    "DICT_APRILTAG_16h5",
)


class BoardError(ValueError):
    """A board spec or board model that cannot be used; the message says what is wrong."""


@dataclass(frozen=True, slots=True)
class Chessboard:
    """A chessboard of ``cols x rows`` inner corners with squares of ``square_m`` metres.

    Attributes
    ----------
    cols, rows : int
        Inner corners along x and along y (OpenCV's ``patternSize = (cols, rows)``), >= 3
        (OpenCV's detectors refuse fewer).
    square_m : float
        Side of a square, metres.
    """

    cols: int
    rows: int
    square_m: float

    def __post_init__(self) -> None:
        _check_size("chessboard", self.cols, self.rows, 3, "inner corners; OpenCV needs 3")
        _check_length("chessboard", "square_m", self.square_m)

    @property
    def count(self) -> int:
        """Number of corners, ``cols * rows``."""
        return self.cols * self.rows

    @property
    def points(self) -> NDArray[np.float64]:
        """``board_ps``, shape (cols * rows, 3): corner ``i`` at
        ``(i % cols, i // cols, 0) * square_m``, metres (module docstring)."""
        i = np.arange(self.count)
        return np.stack(
            [(i % self.cols) * self.square_m, (i // self.cols) * self.square_m, 0.0 * i], axis=1
        )

    @property
    def symmetric(self) -> bool:
        """True when the board looks the same turned by 180 degrees about its normal
        (``cols`` and ``rows`` of equal parity; a square board also by 90 degrees), so
        that an image cannot tell its corner 0 from its last corner."""
        return (self.cols - self.rows) % 2 == 0

    partial = False  # OpenCV finds the inner corners only all at once

    def spec(self) -> str:
        """The command-line spec of this board."""
        return f"chessboard:{self.cols}x{self.rows}:{self.square_m!r}"


@dataclass(frozen=True, slots=True)
class Charuco:
    """A ChArUco board of ``cols x rows`` squares (OpenCV's ``CharucoBoard``).

    Attributes
    ----------
    cols, rows : int
        Squares along x and along y, >= 2 each (corners: ``(cols-1) x (rows-1)``).
    square_m, marker_m : float
        Side of a square and of an ArUco marker, metres (``marker_m < square_m``).
    dictionary : str
        OpenCV's predefined dictionary name, e.g. ``"DICT_5X5_100"``.
    """

    cols: int
    rows: int
    square_m: float
    marker_m: float
    dictionary: str = DEFAULT_DICTIONARY

    def __post_init__(self) -> None:
        _check_size("charuco", self.cols, self.rows, 2, "squares")
        _check_length("charuco", "square_m", self.square_m)
        _check_length("charuco", "marker_m", self.marker_m)
        if self.marker_m >= self.square_m:
            raise BoardError(
                f"charuco: marker_m ({self.marker_m!r}) must be smaller than square_m "
                f"({self.square_m!r})"
            )
        if not _DICTIONARY.fullmatch(self.dictionary):
            raise BoardError(
                f"charuco: unknown ArUco dictionary {self.dictionary!r}; expected an OpenCV "
                f"name such as DICT_4X4_50, DICT_5X5_100, DICT_6X6_250"
            )

    @property
    def count(self) -> int:
        """Number of ChArUco corners, ``(cols - 1) * (rows - 1)``."""
        return (self.cols - 1) * (self.rows - 1)

    @property
    def points(self) -> NDArray[np.float64]:
        """``board_ps``, shape (count, 3), row ``id`` = corner ``id``, metres (module
        docstring; equal to OpenCV's ``getChessboardCorners()``)."""
        i = np.arange(self.count)
        n = self.cols - 1
        return np.stack(
            [(i % n + 1) * self.square_m, (i // n + 1) * self.square_m, 0.0 * i], axis=1
        )

    symmetric = False  # the markers number every corner
    partial = True  # each corner is numbered by the markers beside it

    def opencv_board(self) -> Any:
        """OpenCV's ``cv2.aruco.CharucoBoard`` of this board.

        Raises
        ------
        BoardError
            When OpenCV does not know the dictionary, or the dictionary has fewer markers
            than the board needs (``cols * rows // 2``).
        """
        import cv2

        code = getattr(cv2.aruco, self.dictionary, None)
        if not isinstance(code, int):
            raise BoardError(f"charuco: OpenCV has no ArUco dictionary {self.dictionary!r}")
        dictionary = cv2.aruco.getPredefinedDictionary(code)
        needed = self.cols * self.rows // 2
        if dictionary.bytesList.shape[0] < needed:
            raise BoardError(
                f"charuco: {self.dictionary} has {dictionary.bytesList.shape[0]} markers, a "
                f"{self.cols}x{self.rows} board needs {needed}"
            )
        return cv2.aruco.CharucoBoard(
            (self.cols, self.rows), float(self.square_m), float(self.marker_m), dictionary
        )

    def spec(self) -> str:
        """The command-line spec of this board."""
        return (
            f"charuco:{self.cols}x{self.rows}:{self.square_m!r}:{self.marker_m!r}:{self.dictionary}"
        )


@dataclass(frozen=True, slots=True)
class CircleGrid:
    """A grid of ``cols x rows`` dark discs on a light background (OpenCV's symmetric or
    asymmetric circle grid, ``cv2.findCirclesGrid`` with ``patternSize = (cols, rows)``).

    Attributes
    ----------
    cols, rows : int
        Discs per row and rows (OpenCV's ``patternSize``), >= 3 each.
    spacing_m : float
        Symmetric: distance between neighbouring centres; asymmetric: half the distance
        between neighbours in a row, the distance between rows (module docstring); metres.
    asymmetric : bool
        OpenCV's asymmetric grid (odd rows shifted by ``spacing_m``).
    diameter_m : float, optional
        The discs' diameter, metres (default ``0.4 * spacing_m``, OpenCV's
        ``gen_pattern.py``); smaller than the distance between neighbouring centres.
    origin_diameter_m : float, optional
        The diameter of disc 0 when it is larger than the others and so marks the
        origin (industrial_calibration's "modified circle grid": one large dot), metres;
        between ``diameter_m`` and ``spacing_m``. None: every disc is alike.
    """

    cols: int
    rows: int
    spacing_m: float
    asymmetric: bool = False
    diameter_m: float | None = None
    origin_diameter_m: float | None = None

    def __post_init__(self) -> None:
        kind = self.kind
        _check_size(kind, self.cols, self.rows, 3, "circles")
        _check_length(kind, "spacing_m", self.spacing_m)
        if self.diameter_m is None:
            object.__setattr__(self, "diameter_m", 0.4 * self.spacing_m)
        _check_length(kind, "diameter_m", self.diameter_m)
        nearest = self.spacing_m * (math.sqrt(2.0) if self.asymmetric else 1.0)
        if self.diameter_m >= nearest:
            raise BoardError(
                f"{kind}: diameter_m ({self.diameter_m!r}) must be smaller than the distance "
                f"between neighbouring centres ({nearest!r} m)"
            )
        origin = self.origin_diameter_m
        if origin is not None:
            _check_length(kind, "origin_diameter_m", origin)
            if not self.diameter_m < origin < self.spacing_m:
                raise BoardError(
                    f"{kind}: origin_diameter_m ({origin!r}) must be larger than diameter_m "
                    f"({self.diameter_m!r}) and smaller than spacing_m ({self.spacing_m!r})"
                )

    @property
    def kind(self) -> str:
        """The spec's board type: ``"circles"`` or ``"acircles"`` (OpenCV's names)."""
        return "acircles" if self.asymmetric else "circles"

    @property
    def count(self) -> int:
        """Number of discs, ``cols * rows``."""
        return self.cols * self.rows

    @property
    def points(self) -> NDArray[np.float64]:
        """``board_ps``, shape (cols * rows, 3): the discs' centres row by row, metres
        (module docstring)."""
        i = np.arange(self.count)
        row, col = i // self.cols, i % self.cols
        x = 2 * col + row % 2 if self.asymmetric else col
        return np.stack([x * self.spacing_m, row * self.spacing_m, 0.0 * i], axis=1)

    @property
    def symmetric(self) -> bool:
        """True when the grid looks the same turned by 180 degrees about its normal (every
        symmetric grid, a square one also by 90 degrees; an asymmetric grid with an even
        number of rows), so that an image cannot tell its disc 0 from its last disc. A grid
        whose disc 0 is larger (``origin_diameter_m``) is told by that disc: not
        symmetric."""
        if self.origin_diameter_m is not None:
            return False
        return not self.asymmetric or self.rows % 2 == 0

    partial = False  # OpenCV finds the grid only whole

    def spec(self) -> str:
        """The command-line spec of this board."""
        origin = "" if self.origin_diameter_m is None else f":{self.origin_diameter_m!r}"
        return f"{self.kind}:{self.cols}x{self.rows}:{self.spacing_m!r}:{self.diameter_m!r}{origin}"


@dataclass(frozen=True, slots=True)
class AprilGrid:
    """Kalibr's AprilTag grid (``aprilgrid``): ``cols x rows`` tags, four corners each.

    Attributes
    ----------
    cols, rows : int
        Tags along x and along y (Kalibr's ``tagCols``, ``tagRows``), >= 1 each.
    tag_m : float
        Side of a tag, edge to edge of its black border (Kalibr's ``tagSize``), metres.
    spacing : float
        Gap between neighbouring tags as a fraction of ``tag_m`` (Kalibr's
        ``tagSpacing``), in (0, 1].
    dictionary : str
        OpenCV's AprilTag dictionary, one of :data:`APRILTAG_FAMILIES`.
    first_id : int
        Id of the bottom-left tag as printed; the others follow row by row.
    border_bits : int
        Width of the tags' black border in bits: 2 as Kalibr prints it, 1 as OpenCV's
        ``generateImageMarker`` and the AprilTag library's images.
    """

    cols: int
    rows: int
    tag_m: float
    spacing: float
    dictionary: str = APRILTAG_FAMILIES[0]
    first_id: int = 0
    border_bits: int = 2

    def __post_init__(self) -> None:
        _check_size("aprilgrid", self.cols, self.rows, 1, "tags")
        _check_length("aprilgrid", "tag_m", self.tag_m)
        spacing = self.spacing
        if (
            isinstance(spacing, bool)
            or not isinstance(spacing, int | float)
            or not 0 < spacing <= 1
        ):
            raise BoardError(
                f"aprilgrid: spacing must be in (0, 1] (the gap between tags as a fraction of "
                f"the tag size, Kalibr's tagSpacing), got {spacing!r}"
            )
        family = {name.lower(): name for name in APRILTAG_FAMILIES}
        family.update({"t" + name.split("_")[-1].lower(): name for name in APRILTAG_FAMILIES})
        name = family.get(str(self.dictionary).lower())
        if name is None:
            raise BoardError(
                f"aprilgrid: unknown AprilTag family {self.dictionary!r}; expected one of "
                f"{', '.join(APRILTAG_FAMILIES)} (or Kalibr's t36h11, t36h10, t25h9, t16h5)"
            )
        object.__setattr__(self, "dictionary", name)
        for field_name, low in (("first_id", 0), ("border_bits", 1)):
            value = getattr(self, field_name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
                raise BoardError(
                    f"aprilgrid: {field_name} must be an integer >= {low}, got {value!r}"
                )
        size = _APRILTAG_SIZES[name]
        if self.first_id + self.tags > size:
            raise BoardError(
                f"aprilgrid: {name} has {size} tags (ids 0-{size - 1}), a {self.cols}x{self.rows} "
                f"grid from id {self.first_id} needs ids up to {self.first_id + self.tags - 1}"
            )

    @property
    def tags(self) -> int:
        """Number of tags, ``cols * rows``."""
        return self.cols * self.rows

    @property
    def count(self) -> int:
        """Number of corners, ``4 * cols * rows``."""
        return 4 * self.tags

    @property
    def pitch_m(self) -> float:
        """Distance between the same corners of neighbouring tags, metres."""
        return (1.0 + self.spacing) * self.tag_m

    @property
    def points(self) -> NDArray[np.float64]:
        """``board_ps``, shape (4 * cols * rows, 3), in Kalibr's numbering, metres (module
        docstring)."""
        i = np.arange(self.count)
        r, c = i // (2 * self.cols), i % (2 * self.cols)
        x = (c // 2) * self.pitch_m + (c % 2) * self.tag_m
        y = (r // 2) * self.pitch_m + (r % 2) * self.tag_m
        return np.stack([x, 0.0 - y, 0.0 * x], axis=1)

    def corner_ids(self, tag_ids: ArrayLike) -> NDArray[np.int64]:
        """The board's numbers of the corners of tags ``tag_ids``, shape (n, 4), in
        OpenCV's order of a marker's corners (``detectMarkers``: its top-left, top-right,
        bottom-right, bottom-left, clockwise, as the marker's bits read upright).

        Kalibr draws each tag turned by 180 degrees from OpenCV's upright marker
        (``np.rot90(code, 2)``; measured: a tag drawn as Kalibr draws it is OpenCV's
        ``generateImageMarker`` turned by 180 degrees), so OpenCV's first corner is the
        printed bottom-right one.
        """
        t = np.asarray(tag_ids, dtype=np.int64) - self.first_id
        base = (t // self.cols) * 4 * self.cols + (t % self.cols) * 2
        up = 2 * self.cols  # from a bottom corner to the top corner above it
        return np.stack([base + 1, base, base + up, base + up + 1], axis=-1)

    symmetric = False  # the tags' ids number every corner
    partial = True  # each tag is identified by its id

    def opencv_dictionary(self) -> Any:
        """OpenCV's ``cv2.aruco.Dictionary`` of the tags."""
        import cv2

        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))

    def spec(self) -> str:
        """The command-line spec of this board."""
        return (
            f"aprilgrid:{self.cols}x{self.rows}:{self.tag_m!r}:{self.spacing!r}:"
            f"{self.dictionary}:{self.first_id}:{self.border_bits}"
        )


#: Tags in each of OpenCV's AprilTag dictionaries (``bytesList.shape[0]``, OpenCV 4.x).
_APRILTAG_SIZES = {
    "DICT_APRILTAG_36h11": 587,
    "DICT_APRILTAG_36h10": 2320,
    "DICT_APRILTAG_25h9": 35,
    "DICT_APRILTAG_16h5": 30,
}

Board = Chessboard | Charuco | CircleGrid | AprilGrid

_SPEC_HELP = (
    "expected chessboard:COLSxROWS:SQUARE_M (inner corners, e.g. chessboard:9x6:0.025), "
    "charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT] (squares, e.g. "
    "charuco:7x5:0.04:0.03:DICT_5X5_100), circles:COLSxROWS:SPACING_M[:DIAMETER_M"
    "[:ORIGIN_DIAMETER_M]] or acircles:COLSxROWS:SPACING_M[:DIAMETER_M[:ORIGIN_DIAMETER_M]] "
    "(circles per row x rows; ORIGIN_DIAMETER_M: a larger disc 0 marks the origin; e.g. "
    "acircles:4x11:0.02), aprilgrid:COLSxROWS:TAG_M:SPACING[:FAMILY[:FIRST_ID[:BORDER_BITS]]] "
    "(tags, SPACING a fraction of TAG_M, e.g. aprilgrid:6x6:0.088:0.3); lengths in metres"
)

#: Each board type's spec fields after ``COLSxROWS``: the required ones, then the optional.
_FIELDS = {
    "chessboard": (("SQUARE_M",), ()),
    "charuco": (("SQUARE_M", "MARKER_M"), ("DICT",)),
    "circles": (("SPACING_M",), ("DIAMETER_M", "ORIGIN_DIAMETER_M")),
    "acircles": (("SPACING_M",), ("DIAMETER_M", "ORIGIN_DIAMETER_M")),
    "aprilgrid": (("TAG_M", "SPACING"), ("FAMILY", "FIRST_ID", "BORDER_BITS")),
}


def parse_board(spec: str) -> Board:
    """The board a command-line spec names (module docstring).

    Raises
    ------
    BoardError
        Naming the spec and the part that is wrong, with the expected forms.
    """
    parts = spec.strip().split(":")
    kind = parts[0].strip().lower()
    if kind not in _FIELDS:
        raise BoardError(f"board {spec!r}: unknown board type {parts[0]!r}; {_SPEC_HELP}")
    required, optional = _FIELDS[kind]
    if not 2 + len(required) <= len(parts) <= 2 + len(required) + len(optional):
        raise BoardError(f"board {spec!r}: wrong number of ':' fields; {_SPEC_HELP}")
    size = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", parts[1])
    if size is None:
        raise BoardError(f"board {spec!r}: size {parts[1]!r} is not COLSxROWS; {_SPEC_HELP}")
    cols, rows = int(size[1]), int(size[2])
    fields = dict(zip((*required, *optional), (p.strip() for p in parts[2:]), strict=False))
    values = {
        name: _number(spec, name, text, int if name in ("FIRST_ID", "BORDER_BITS") else float)
        for name, text in fields.items()
        if name not in ("DICT", "FAMILY")
    }
    try:
        if kind == "chessboard":
            return Chessboard(cols, rows, values["SQUARE_M"])
        if kind == "charuco":
            dictionary = fields.get("DICT", DEFAULT_DICTIONARY).upper()
            return Charuco(cols, rows, values["SQUARE_M"], values["MARKER_M"], dictionary)
        if kind in ("circles", "acircles"):
            asymmetric = kind == "acircles"
            return CircleGrid(
                cols,
                rows,
                values["SPACING_M"],
                asymmetric,
                values.get("DIAMETER_M"),
                values.get("ORIGIN_DIAMETER_M"),
            )
        return AprilGrid(
            cols,
            rows,
            values["TAG_M"],
            values["SPACING"],
            fields.get("FAMILY", APRILTAG_FAMILIES[0]),
            values.get("FIRST_ID", 0),
            values.get("BORDER_BITS", 2),
        )
    except BoardError as exc:
        raise BoardError(f"board {spec!r}: {exc}") from None


def _number(spec: str, name: str, text: str, kind: type) -> Any:
    try:
        return kind(text)
    except ValueError:
        unit = (
            "an integer"
            if kind is int
            else "a number" + (" (metres)" if name.endswith("_M") else "")
        )
        raise BoardError(f"board {spec!r}: {name} {text!r} is not {unit}; {_SPEC_HELP}") from None


def _check_size(kind: str, cols: object, rows: object, low: int, what: str) -> None:
    for name, value in (("cols", cols), ("rows", rows)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
            raise BoardError(f"{kind}: {name} must be an integer >= {low} ({what}), got {value!r}")


def _check_length(kind: str, name: str, value: object) -> None:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or value <= 0.0
    ):
        raise BoardError(f"{kind}: {name} must be a positive length in metres, got {value!r}")
    if value > 2.0:
        raise BoardError(
            f"{kind}: {name} = {value!r} m is more than 2 m; give the size in metres "
            f"(millimetres divided by 1000)"
        )
