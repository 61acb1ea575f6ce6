"""Calibration boards: the point model of a chessboard or a ChArUco board, and the
command-line spec that names one.

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

Specs (:func:`parse_board`): ``chessboard:COLSxROWS:SQUARE_M`` (inner corners) and
``charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT]`` (squares; ``DICT`` an OpenCV predefined
ArUco dictionary, default ``DICT_5X5_100``, the one of OpenCV's ChArUco tutorial). Square
and marker sizes in metres.

This module imports OpenCV only inside :meth:`Charuco.opencv_board`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DEFAULT_DICTIONARY",
    "BoardError",
    "Charuco",
    "Chessboard",
    "parse_board",
]

#: The ArUco dictionary of a ChArUco spec that names none (OpenCV's ChArUco tutorial's).
DEFAULT_DICTIONARY = "DICT_5X5_100"

_DICTIONARY = re.compile(r"DICT_(\d+)X\1_(\d+)|DICT_ARUCO_ORIGINAL|DICT_APRILTAG_\w+")


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


Board = Chessboard | Charuco

_SPEC_HELP = (
    "expected chessboard:COLSxROWS:SQUARE_M (inner corners, metres, e.g. "
    "chessboard:9x6:0.025) or charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT] (squares, "
    "metres, e.g. charuco:7x5:0.04:0.03:DICT_5X5_100)"
)


def parse_board(spec: str) -> Chessboard | Charuco:
    """The board a command-line spec names (module docstring).

    Raises
    ------
    BoardError
        Naming the spec and the part that is wrong, with the expected forms.
    """
    parts = spec.strip().split(":")
    kind = parts[0].lower()
    if kind not in ("chessboard", "charuco"):
        raise BoardError(f"board {spec!r}: unknown board type {parts[0]!r}; {_SPEC_HELP}")
    count = 3 if kind == "chessboard" else (4, 5)
    if len(parts) not in ((count,) if isinstance(count, int) else count):
        raise BoardError(f"board {spec!r}: wrong number of ':' fields; {_SPEC_HELP}")
    size = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", parts[1])
    if size is None:
        raise BoardError(f"board {spec!r}: size {parts[1]!r} is not COLSxROWS; {_SPEC_HELP}")
    cols, rows = int(size[1]), int(size[2])
    names = ("SQUARE_M", "MARKER_M")[: len(parts[2:4])]
    lengths = [_length(spec, name, text) for name, text in zip(names, parts[2:4], strict=True)]
    try:
        if kind == "chessboard":
            return Chessboard(cols, rows, lengths[0])
        dictionary = parts[4].strip().upper() if len(parts) == 5 else DEFAULT_DICTIONARY
        return Charuco(cols, rows, lengths[0], lengths[1], dictionary)
    except BoardError as exc:
        raise BoardError(f"board {spec!r}: {exc}") from None


def _length(spec: str, name: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise BoardError(
            f"board {spec!r}: {name} {text!r} is not a number (metres); {_SPEC_HELP}"
        ) from None
    return value


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
