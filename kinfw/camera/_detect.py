"""Find a calibration board's corners in images (OpenCV), numbered by the board's model.

Each image gives a :class:`Detection`: ``found`` with the corners' pixels ``uv``, their
ids (the board's numbering, :mod:`kinfw.camera`) and their points in the board frame;
or ``not found`` / ``ambiguous`` with the reason. Nothing is guessed: an image whose
numbering cannot be told is reported, never numbered at random.

Chessboard
----------
The corners come from ``cv2.findChessboardCornersSB`` (OpenCV >= 4.0, sub-pixel by
itself; with ``CALIB_CB_ACCURACY``, without ``CALIB_CB_NORMALIZE_IMAGE``, which biases the
corners by 0.1-0.2 px on rendered images) or, if it is missing or fails, from
``cv2.findChessboardCorners`` refined by ``cv2.cornerSubPix``. Both return the
``cols x rows`` inner corners row by row, but **which corner is first** is OpenCV's
choice, and it differs between the two detectors and with the board's parity:

- when ``cols`` and ``rows`` have different parity (9 x 6, 7 x 4), the board looks
  different turned by 180 degrees (the square beside corner 0 and the one beside the last
  corner have opposite colours). OpenCV then starts from a corner of a given colour --
  ``findChessboardCorners`` from one colour, ``findChessboardCornersSB`` from the other
  (measured on rendered images with OpenCV 4.14). kinfw relies on neither: it reads the
  colours itself (below) and keeps the numbering in which the square between corners
  ``0, 1, cols, cols+1`` is black (:mod:`kinfw.camera`), turning OpenCV's by 180 degrees
  otherwise.
- when ``cols`` and ``rows`` have the same parity (8 x 6, 7 x 5, any square board), the
  board turned by 180 degrees (a square one also by 90) is the same picture, and OpenCV
  orders the corners by their position **in the image** (``findChessboardCorners``:
  corner 0 above the last row's first corner), so the numbering follows the camera, not
  the board: a board seen upside down gets the numbering of a board turned by 180
  degrees. No image can tell; every such image is reported ``ambiguous`` unless
  ``allow_symmetric=True`` (the user vouches that the board is never seen turned by more
  than 90 degrees). Then, of the numberings with the right colours, the one whose x axis
  (corner 0 to corner ``cols - 1``) points most to the image's right is kept. Only such
  an image is flagged :attr:`Detection.symmetric` (``allow_symmetric`` would accept it).

The colours: through the homography of the found corners (grid indices to pixels), the
image is sampled at the centres of the ``(cols-1) x (rows-1)`` squares between the inner
corners, for each numbering the grid's shape allows (as found, turned by 180 degrees,
for a square grid by 90 and 270); a numbering is right when its should-be-white squares
are brighter than its should-be-black ones by at least :data:`MIN_COLOUR_CONTRAST` of
the grey range (none right: ``ambiguous``). Then the ring of the board's outer squares
around the inner corners, where it is in the image, must have the chessboard's colours
too: otherwise the corners are not the board's inner corners (``findChessboardCornersSB``
returns, for a board cut by the image border, a grid shifted by one square onto the white
margin; ``tests/kinfw/camera/test_detect.py``) and the image is ``not found``. And beyond
that ring, along each side (where in the image), the squares must not continue the
chessboard (each the other colour than the outer square beside it): otherwise the corners
are part of a larger board (OpenCV finds a 7 x 6 or 8 x 6 grid in a 9 x 6 board), the
spec's ``COLSxROWS`` is wrong, and the image is ``not found`` saying so, not numbered (nor
refused as symmetric, which ``allow_symmetric`` would then number by the wrong layout).

In every case a numbering that is mirrored in the image (x cross y pointing towards the
camera; a printed board seen from its front has x, y right-handed in the image, as u, v)
is reversed along its rows first.

ChArUco
-------
``cv2.aruco.CharucoDetector``: the markers' ids number the corners, so there is no
ambiguity; an image is ``found`` with at least ``min_corners`` (default 6) corners that
are not all on one line (``CharucoBoard.checkCharucoCornersCollinear``).

Circle grids and AprilTag grids
-------------------------------
:mod:`kinfw.camera._grids`: a circle grid is numbered by fitting each numbering its
shape allows (symmetric grids are ``ambiguous`` as symmetric chessboards are); an
AprilTag grid's corners by the tags' ids, partial views allowed (``min_corners`` as for
ChArUco), every tag checked against the board's layout.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from kinfw.camera._boards import AprilGrid, Board, BoardError, Charuco, CircleGrid
from kinfw.camera._grids import AprilGridFinder, find_circle_grid, mirrored, most_upright

log = logging.getLogger(__name__)

Status = Literal["found", "not found", "ambiguous"]

#: Smallest contrast between the two colour classes of squares, as a fraction of the
#: grey range of the squares seen, to tell a chessboard's orientation from its colours.
MIN_COLOUR_CONTRAST = 0.25


@dataclass(frozen=True, slots=True)
class Detection:
    """The board's corners in one image.

    Attributes
    ----------
    image : str
        The image's label (its file name).
    status : {"found", "not found", "ambiguous"}
    reason : str
        Why not found or ambiguous ("" when found).
    uv : ndarray, shape (k, 2)
        Pixels of the corners (OpenCV's convention: (0, 0) the centre of the top-left
        pixel); shape (0, 2) unless found.
    ids : ndarray of int, shape (k,)
        The corners' numbers in the board's numbering (:mod:`kinfw.camera`).
    points : ndarray, shape (k, 3)
        ``board_ps`` of those corners, metres.
    symmetric : bool
        Ambiguous because the board was found but looks the same turned by 180 degrees
        (``allow_symmetric`` would accept it); False for every other outcome.
    """

    image: str
    status: Status
    reason: str = ""
    uv: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2)))
    ids: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    points: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    symmetric: bool = False

    @property
    def found(self) -> bool:
        return self.status == "found"


def read_gray(path: str | Path) -> NDArray[np.uint8]:
    """An image file as a grey image (``cv2.imread``).

    Raises
    ------
    OSError
        Naming the file when it is missing or not an image OpenCV can read.
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such image file")
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise OSError(f"{path}: not an image OpenCV can read")
    return image


class Detector:
    """Finds one board's corners; build once, call :meth:`detect` per image.

    Parameters
    ----------
    board : Chessboard, Charuco, CircleGrid or AprilGrid
    allow_symmetric : bool
        Accept a chessboard or circle grid that looks the same turned by 180 degrees
        (module docstring).
    min_corners : int
        ChArUco, AprilTag grid: fewest corners for an image to count as found (default
        6; >= 4).

    Raises
    ------
    BoardError
        For an asymmetric circle grid with an even number of rows (OpenCV does not
        number it by its layout).
    """

    def __init__(
        self, board: Board, *, allow_symmetric: bool = False, min_corners: int = 6
    ) -> None:
        if min_corners < 4:
            raise ValueError(f"min_corners must be >= 4 (PnP needs 4), got {min_corners}")
        if isinstance(board, CircleGrid) and board.asymmetric and board.rows % 2 == 0:
            raise BoardError(
                f"{board.spec()}: an asymmetric circle grid with an even number of rows looks "
                f"the same turned by 180 degrees, and OpenCV's findCirclesGrid numbers its rows "
                f"out of the layout's order (measured, OpenCV 4.14); use an odd number of rows "
                f"(OpenCV's acircles 4x11)"
            )
        self.board = board
        self.allow_symmetric = allow_symmetric
        self.min_corners = int(min_corners)
        self._charuco: Any = None
        self._tags = AprilGridFinder(board) if isinstance(board, AprilGrid) else None
        if isinstance(board, Charuco):
            import cv2

            self._opencv_board = board.opencv_board()
            self._charuco = cv2.aruco.CharucoDetector(self._opencv_board)

    def detect(self, image: NDArray[np.uint8], label: str = "<image>") -> Detection:
        """The board's corners in a grey image, shape (h, w), uint8."""
        image = np.asarray(image)
        if image.ndim != 2 or image.dtype != np.uint8:
            raise ValueError(
                f"{label}: expected a grey uint8 image, got {image.dtype} {image.shape}"
            )
        if isinstance(self.board, Charuco):
            return self._detect_charuco(image, label)
        if isinstance(self.board, CircleGrid):
            grid = find_circle_grid(image, self.board, allow_symmetric=self.allow_symmetric)
            points = self.board.points[grid.ids]
            return Detection(
                label, grid.status, grid.reason, grid.uv, grid.ids, points, grid.symmetric
            )
        if self._tags is not None:
            return self._detect_tags(image, label)
        return self._detect_chessboard(image, label)

    # -- AprilTag grid ---------------------------------------------------------------
    def _detect_tags(self, image: NDArray[np.uint8], label: str) -> Detection:
        (status, reason, uv, ids, _), notes = self._tags.find(image)
        if status == "found" and len(ids) < self.min_corners:
            status = "not found"
            reason = f"{len(ids)} tag corners, fewer than {self.min_corners}"
        if status != "found":
            return Detection(label, "not found", "; ".join([reason, *notes]))
        for note in notes:
            log.info("%s: %s (dropped)", label, note)
        return Detection(label, "found", "", uv, ids, self.board.points[ids])

    # -- ChArUco ---------------------------------------------------------------------
    def _detect_charuco(self, image: NDArray[np.uint8], label: str) -> Detection:
        corners, ids, _, _ = self._charuco.detectBoard(image)
        count = 0 if ids is None else len(ids)
        if count < self.min_corners:
            return Detection(
                label, "not found", f"{count} ChArUco corners, fewer than {self.min_corners}"
            )
        ids = np.asarray(ids, dtype=np.int64).ravel()
        if self._opencv_board.checkCharucoCornersCollinear(ids.reshape(-1, 1).astype(np.int32)):
            return Detection(label, "not found", f"the {count} ChArUco corners are on one line")
        order = np.argsort(ids)
        uv = np.asarray(corners, dtype=float).reshape(-1, 2)[order]
        ids = ids[order]
        return Detection(label, "found", "", uv, ids, self.board.points[ids])

    # -- chessboard ------------------------------------------------------------------
    def _detect_chessboard(self, image: NDArray[np.uint8], label: str) -> Detection:
        board = self.board
        uv = _find_chessboard(image, (board.cols, board.rows))
        if uv is None:
            return Detection(label, "not found", f"no {board.cols}x{board.rows} chessboard")
        grid = uv.reshape(board.rows, board.cols, 2)
        if mirrored(grid):
            grid = grid[:, ::-1]
        greys = _SquareGreys(image, grid)
        contrasts = [greys.contrast(turn) for turn in range(greys.turns)]
        right = [turn for turn, c in enumerate(contrasts) if c >= MIN_COLOUR_CONTRAST]
        if not right:
            return Detection(
                label,
                "ambiguous",
                f"black and white squares differ by only {max(np.abs(contrasts)):.0%} of the "
                f"grey range: cannot tell the board's orientation",
            )
        wrong = greys.wrong_border_squares(right[0])
        if wrong:
            return Detection(
                label,
                "not found",
                f"the {board.cols}x{board.rows} corners found are not the board's inner corners: "
                f"{wrong} of the squares around them have the wrong colour (a board cut by the "
                f"image border, or its outer squares hidden?)",
            )
        beyond = greys.continues()
        if beyond:
            return Detection(
                label,
                "not found",
                f"the {board.cols}x{board.rows} corners found are part of a larger chessboard "
                f"(its squares continue past them: {beyond}); check COLSxROWS, the inner "
                f"corners per row x rows",
            )
        if len(right) > 1 and not self.allow_symmetric:
            return Detection(
                label,
                "ambiguous",
                f"a {board.cols}x{board.rows} chessboard looks the same turned by 180 degrees"
                f"{' (and 90)' if board.cols == board.rows else ''}: its corner 0 cannot be told "
                f"(use a board with one odd and one even count, a ChArUco board, or "
                f"--allow-symmetric)",
                symmetric=True,
            )
        grid = most_upright([greys.turned(turn) for turn in right])
        ids = np.arange(board.count, dtype=np.int64)
        return Detection(label, "found", "", grid.reshape(-1, 2).copy(), ids, board.points)


def _find_chessboard(image: NDArray[np.uint8], size: tuple[int, int]) -> NDArray[np.float64] | None:
    """OpenCV's inner corners, shape (cols * rows, 2), in OpenCV's order, or None."""
    import cv2

    if hasattr(cv2, "findChessboardCornersSB"):
        # not CALIB_CB_NORMALIZE_IMAGE: equalising the histogram bends the grey profile
        # across an edge and biases the corners by 0.1-0.2 px (benchmarks/bench_detect.py)
        flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
        ok, corners = cv2.findChessboardCornersSB(image, size, flags=flags)
        if ok:
            return np.asarray(corners, dtype=float).reshape(-1, 2)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, corners = cv2.findChessboardCorners(image, size, flags=flags)
    if not ok:
        return None
    corners = np.asarray(corners, dtype=np.float32).reshape(-1, 1, 2)
    # half-window: a third of the smallest distance between neighbouring corners
    grid = corners.reshape(size[1], size[0], 2)
    spacing = min(
        np.linalg.norm(np.diff(grid, axis=1), axis=-1).min(),
        np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(),
    )
    half = int(np.clip(spacing / 3.0, 2, 11))
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    refined = cv2.cornerSubPix(image, corners, (half, half), (-1, -1), criteria)
    return np.asarray(refined, dtype=float).reshape(-1, 2)


class _SquareGreys:
    """Grey levels at the centres of a found chessboard's squares, for each numbering the
    grid's shape allows (turn 0: as found; 1: turned by 180 degrees; for a square grid,
    2 and 3: turned by 90 and 270 degrees).

    The square centres are mapped through the homography of the found corners (grid
    indices to pixels); greys from the image blurred by 3 x 3. A square ``(i, j)`` is the
    one between corners ``(i, j)`` and ``(i + 1, j + 1)`` (column, row); it should be
    black when ``i + j`` is even (:mod:`kinfw.camera`).
    """

    def __init__(self, image: NDArray[np.uint8], grid: NDArray[np.float64]) -> None:
        import cv2

        self.grid = grid
        rows, cols = grid.shape[:2]
        self.turns = 4 if rows == cols else 2
        j, i = np.mgrid[0:rows, 0:cols]
        board_xy = np.stack([i.ravel(), j.ravel()], axis=1).astype(np.float64)
        H, _ = cv2.findHomography(board_xy, grid.reshape(-1, 2), 0)
        # all the printed squares, i in -1 .. cols-1, j in -1 .. rows-1, and a ring of
        # squares around them (the margin, unless the board is larger than its spec)
        sj, si = np.mgrid[-2 : rows + 1, -2 : cols + 1]
        centres = np.stack([si.ravel() + 0.5, sj.ravel() + 0.5, np.ones(si.size)], axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            uvw = centres @ (H.T if H is not None else np.full((3, 3), np.nan))
            uv = uvw[:, :2] / uvw[:, 2:]
        h, w = image.shape
        inside = (uv[:, 0] >= 1) & (uv[:, 0] <= w - 2) & (uv[:, 1] >= 1) & (uv[:, 1] <= h - 2)
        blurred = cv2.blur(image, (3, 3)).astype(np.float64)
        greys = np.full(len(uv), np.nan)
        u = np.rint(uv[inside, 0]).astype(int)
        v = np.rint(uv[inside, 1]).astype(int)
        greys[inside] = blurred[v, u]
        self.outer = greys.reshape(rows + 3, cols + 3)  # [j + 2, i + 2]
        self.greys = self.outer[1:-1, 1:-1]  # [j + 1, i + 1]: the printed squares

    def _turned_greys(self, turn: int) -> NDArray[np.float64]:
        g = self.greys
        if turn >= 2:
            g = np.transpose(g)[:, ::-1]
        return g[::-1, ::-1] if turn % 2 else g

    def turned(self, turn: int) -> NDArray[np.float64]:
        """The grid of corners, shape (rows, cols, 2), in numbering ``turn``."""
        g = self.grid
        if turn >= 2:
            g = np.transpose(g, (1, 0, 2))[:, ::-1]
        return g[::-1, ::-1] if turn % 2 else g

    def _black(self, shape: tuple[int, int]) -> NDArray[np.bool_]:
        a, b = np.mgrid[0 : shape[0], 0 : shape[1]]  # a = j + 1, b = i + 1
        return (a + b) % 2 == 0  # black: i + j even

    def contrast(self, turn: int) -> float:
        """Mean grey of the inner squares that should be white minus that of those that
        should be black in numbering ``turn``, as a fraction of their grey range: near +1
        right, near -1 wrong (NaN-free; 0 without contrast)."""
        g = self._turned_greys(turn)
        inner = g[1:-1, 1:-1]
        black = self._black(g.shape)[1:-1, 1:-1]
        spread = np.nanmax(inner) - np.nanmin(inner) if np.isfinite(inner).any() else 0.0
        if not spread > 0.0 or not np.isfinite(inner).all():
            return 0.0
        return float((inner[~black].mean() - inner[black].mean()) / spread)

    def _threshold(self) -> float:
        """The middle of the inner squares' two grey levels (either numbering)."""
        inner = self.greys[1:-1, 1:-1]
        black = self._black(self.greys.shape)[1:-1, 1:-1]
        return float(0.5 * (inner[black].mean() + inner[~black].mean()))

    def continues(self) -> str:
        """Which way the chessboard continues past its printed squares: on a side of
        the grid, the squares of the ring around them that are in the image (at least
        two, and half the side's) each of the other colour than the outer square beside
        it, as a chessboard's squares are; "" when on no side (a board whose
        ``COLSxROWS`` is right has its margin or the background there)."""
        dark = self.outer < self._threshold()
        seen = np.isfinite(self.outer)
        rows, cols = self.grid.shape[:2]
        more_rows = f"more than {rows} rows of inner corners"
        more_cols = f"more than {cols} inner corners per row"
        sides = (  # the ring beyond a side, the printed outer squares beside it
            (more_rows, np.s_[0, 1:-1], np.s_[1, 1:-1]),
            (more_rows, np.s_[-1, 1:-1], np.s_[-2, 1:-1]),
            (more_cols, np.s_[1:-1, 0], np.s_[1:-1, 1]),
            (more_cols, np.s_[1:-1, -1], np.s_[1:-1, -2]),
        )
        for what, beyond, beside in sides:
            both = seen[beyond] & seen[beside]
            enough = both.sum() >= max(2, 0.5 * both.size)
            if enough and (dark[beyond] != dark[beside])[both].all():
                return what
        return ""

    def wrong_border_squares(self, turn: int) -> int:
        """How many of the squares around the inner corners (the printed board's outer
        squares) that are in the image have the wrong colour in numbering ``turn``, judged
        against the middle of the inner squares' two grey levels."""
        g = self._turned_greys(turn)
        black = self._black(g.shape)
        threshold = self._threshold()
        ring = np.ones(g.shape, dtype=bool)
        ring[1:-1, 1:-1] = False
        seen = ring & np.isfinite(g)
        return int(np.sum((g[seen] < threshold) != black[seen]))
