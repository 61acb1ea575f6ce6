"""Circle grids and AprilTag grids in an image, numbered by the board (used by
:class:`kinfw.camera.Detector`; OpenCV imported when used).

Circle grids
------------
``cv2.findCirclesGrid`` (``CALIB_CB_SYMMETRIC_GRID`` / ``CALIB_CB_ASYMMETRIC_GRID``) with
a ``SimpleBlobDetector`` of dark blobs of 9 px to 1/50 of the image's area (OpenCV's
default of at most 5000 px misses near boards; a larger limit takes the grey surround
of a board for a blob). It returns the ``cols x rows`` centres row by row, in an order
that follows the image: measured on rendered images (OpenCV 4.14), an asymmetric grid
with an odd number of rows comes in the board's order, a symmetric grid turned by 180
degrees (or 90) with the board; an asymmetric grid with an even number of rows in an
order no turn of the layout gives (pairs of rows swapped), which
:class:`kinfw.camera.Detector` refuses.
kinfw relies on neither: each numbering the grid's shape allows (as found, its rows or
columns reversed, both, and for a square grid transposed) is fitted by a homography
from the board's points to the centres, and those seen from behind (x cross y towards
the camera) are dropped. The best fit is the board's numbering, unless another fits as
well (the grid looks the same turned: :attr:`CircleGrid.symmetric`): then the image is
``ambiguous`` (:attr:`Found.symmetric`) unless ``allow_symmetric`` (the numbering whose x
axis points most to the image's right is kept). A grid with a larger origin disc
(``origin_diameter_m``, the modified circle grid of industrial_calibration) keeps the
numbering whose disc 0 is that disc: the blob detector's size at each candidate's disc 0
(the largest, and at least :data:`ORIGIN_SIZE_RATIO` times the median disc; else
``ambiguous``). A symmetric grid whose spec has no origin disc but whose image shows one
(a corner disc that large) is ``ambiguous`` asking for ``ORIGIN_DIAMETER_M``, not for
``allow_symmetric``. Before that, discs at every place the layout puts a row or column
beyond the grid found (in the image, at least :data:`MIN_BEYOND_FRACTION` of the side)
mean the grid is part of a larger one (``findCirclesGrid`` finds a 6 x 5 or 9 x 9 grid
in a 7 x 5 or 10 x 10 board): ``not found``, naming the wrong count. Each centre is
then checked against the homography of its neighbours (up to two rows and columns
away): one off by more than :data:`MAX_LOCAL_ERROR` of the distance between neighbours
(a stray blob taken for a disc) makes the image ``not found``.

AprilTag grids
--------------
``cv2.aruco.ArucoDetector`` with the board's AprilTag dictionary and border width finds
the tags and their ids; tags whose ids are not the board's, and ids seen twice, are
dropped. The corners of a tag printed as Kalibr prints it touch the black squares at
its corners, which bends the tag's outline found by OpenCV (its corners ~2 px off on
rendered images); each corner, an X junction of the tag and a square, is refined by
``cv2.cornerSubPix``, as Kalibr refines them, with a half window of 0.8 times the
smaller of the gap and the tag's black border (2 to 10 px: a larger window reaches the
square's far edges or the tag's bits and biases the corner), and dropped when it is off
the homography of its neighbours (the corners within two tag pitches) by more than
:data:`MAX_CORNER_ERROR` of a tag's side (``cornerSubPix`` drawn to another corner). The tags
are then checked against the board's layout: a homography from the board's corners to
the image (RANSAC, threshold a third of the median tag side) must keep every tag; a
tag off the layout (a tag of another board, a misread id) is dropped and named, and
when half the tags or more are off (another layout: wrong ``COLSxROWS`` or first id,
tags printed in another orientation) the image is ``not found``. An image is
``found`` with at least ``min_corners`` corners.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from kinfw.camera._boards import AprilGrid, CircleGrid

#: A disc's centre off the homography of its neighbours by more than this fraction of
#: the distance between neighbouring centres is not the board's.
MAX_LOCAL_ERROR = 0.2

#: A tag corner off the homography of its neighbours by more than this fraction of the
#: tag's side (at least 0.5 px) is dropped (``cornerSubPix`` drawn to another corner).
MAX_CORNER_ERROR = 0.05

#: A grid's points found beyond one of its sides, at every place the layout predicts
#: there and in the image, at least this fraction of the side's points: the grid found
#: is part of a larger one (a wrong ``COLSxROWS``).
MIN_BEYOND_FRACTION = 0.5


class Found(NamedTuple):
    """What one image shows of a grid.

    Attributes
    ----------
    status : {"found", "not found", "ambiguous"}
    reason : str
        Why not found or ambiguous ("" when found).
    uv : ndarray, shape (k, 2)
        The points' pixels.
    ids : ndarray of int, shape (k,)
        Their numbers in the board's numbering.
    symmetric : bool
        Ambiguous because the grid found looks the same turned (``allow_symmetric``
        would accept it), not for another reason.
    """

    status: str
    reason: str
    uv: NDArray[np.float64]
    ids: NDArray[np.int64]
    symmetric: bool = False


def _nothing(status: str, reason: str, *, symmetric: bool = False) -> Found:
    return Found(status, reason, np.zeros((0, 2)), np.zeros(0, dtype=np.int64), symmetric)


def mirrored(grid: NDArray[np.float64]) -> bool:
    """True when a grid's x (along a row) and y (down the columns), shape (rows, cols, 2),
    are left-handed in the image (u right, v down), i.e. the board would face away from
    the camera."""
    x_axis = (grid[:, -1] - grid[:, 0]).mean(axis=0)
    y_axis = (grid[-1, :] - grid[0, :]).mean(axis=0)
    return bool(x_axis[0] * y_axis[1] - x_axis[1] * y_axis[0] < 0.0)


def most_upright(grids: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    """Of the numberings a symmetric board allows, each shape (rows, cols, 2), the one
    whose x axis (point 0 to point ``cols - 1``) points most to the image's right."""

    def rightness(g: NDArray[np.float64]) -> float:
        x_axis = (g[:, -1] - g[:, 0]).mean(axis=0)
        return float(x_axis[0] / (np.linalg.norm(x_axis) + 1e-12))

    return max(grids, key=rightness)


# -- circle grids ---------------------------------------------------------------------------
def find_circle_grid(
    image: NDArray[np.uint8], board: CircleGrid, *, allow_symmetric: bool
) -> Found:
    """The grid's centres in the board's numbering (module docstring)."""
    import cv2

    params = cv2.SimpleBlobDetector_Params()
    params.minArea = 9.0
    params.maxArea = image.size / 50.0
    blobs = cv2.SimpleBlobDetector_create(params)
    flags = cv2.CALIB_CB_ASYMMETRIC_GRID if board.asymmetric else cv2.CALIB_CB_SYMMETRIC_GRID
    ok, centres = cv2.findCirclesGrid(
        image, (board.cols, board.rows), flags=flags, blobDetector=blobs
    )
    name = f"{board.cols}x{board.rows} {board.kind} grid"
    if not ok:
        return _nothing("not found", f"no {name}")
    uv = np.asarray(centres, dtype=float).reshape(-1, 2)
    spacing_px = _neighbour_distance(uv.reshape(board.rows, board.cols, 2), board)
    same = _best_numberings(uv, board, spacing_px)
    if not same:
        return _nothing("not found", f"the centres found do not fit the {name}'s layout")
    keypoints = blobs.detect(image)
    discs = (np.array([k.pt for k in keypoints]), np.array([k.size for k in keypoints]))
    beyond = _grid_continues(image.shape, discs[0], same[0], board, spacing_px)
    if beyond:
        return _nothing(
            "not found",
            f"the {name} found is part of a larger grid (discs continue past it: {beyond}); "
            f"check COLSxROWS, circles per row x rows",
        )
    if len(same) > 1:
        same, refusal = _one_numbering(same, discs, board, spacing_px, allow_symmetric)
        if refusal is not None:
            return refusal
    grid = most_upright(same)
    worst, k = _local_error(grid, board)
    if worst > MAX_LOCAL_ERROR * spacing_px:
        return _nothing(
            "not found",
            f"disc {k} of the {name} is {worst:.1f} px off the homography of its neighbours "
            f"(a stray blob taken for a disc?)",
        )
    return Found("found", "", grid.reshape(-1, 2).copy(), np.arange(board.count, dtype=np.int64))


def _best_numberings(
    uv: NDArray[np.float64], board: CircleGrid, spacing_px: float
) -> list[NDArray[np.float64]]:
    """The numberings of OpenCV's centres ``uv`` (each shape (rows, cols, 2); the grid's
    shape allows its rows or columns reversed, both, and for a square grid transposed)
    that fit the layout best by a homography, those seen from behind dropped; none when
    the best is off by more than half a spacing."""
    import cv2

    index = np.arange(board.count).reshape(board.rows, board.cols)
    orders = [index, index[::-1], index[:, ::-1], index[::-1, ::-1]]
    if board.rows == board.cols:
        orders += [o.T for o in orders]
    board_xy = board.points[:, :2]
    fits = []
    for order in orders:
        grid = uv[order.ravel()].reshape(board.rows, board.cols, 2)
        if mirrored(grid):
            continue
        H, _ = cv2.findHomography(board_xy, grid.reshape(-1, 2), 0)
        if H is None:
            continue
        predicted = cv2.perspectiveTransform(board_xy.reshape(-1, 1, 2), H).reshape(-1, 2)
        fits.append(
            (float(np.sqrt(np.mean(np.sum((predicted - grid.reshape(-1, 2)) ** 2, 1)))), grid)
        )
    if not fits or min(f[0] for f in fits) > 0.5 * spacing_px:
        return []
    best = min(f[0] for f in fits)
    return [grid for residual, grid in fits if residual <= best * (1.0 + 1e-6) + 1e-9]


def _one_numbering(
    grids: list[NDArray[np.float64]],
    discs: tuple[NDArray[np.float64], NDArray[np.float64]],
    board: CircleGrid,
    spacing_px: float,
    allow_symmetric: bool,
) -> tuple[list[NDArray[np.float64]], Found | None]:
    """Of the numberings a grid that looks the same turned allows, the one its origin
    disc tells (``origin_diameter_m``), or all of them with ``allow_symmetric``; else
    the refusal: ``ambiguous``, flagged ``symmetric`` only when ``allow_symmetric``
    would be the remedy (not when a corner disc is larger, an origin disc the spec
    lacks)."""
    name = f"{board.cols}x{board.rows} {board.kind} grid"
    if board.origin_diameter_m is not None:
        told, why = _by_origin_disc(discs, grids, spacing_px)
        return told, (None if told else _nothing("ambiguous", f"{name}: {why}"))
    if allow_symmetric:
        return grids, None
    told, _ = _by_origin_disc(discs, grids, spacing_px)
    if told:
        return [], _nothing(
            "ambiguous",
            f"a corner disc of the {name} is larger than the others (an origin disc?), but "
            f"the spec gives no ORIGIN_DIAMETER_M: give its diameter, "
            f"{board.spec()}:ORIGIN_DIAMETER_M (metres)",
        )
    turns = "180 degrees" + (" (and 90)" if len(grids) > 2 else "")
    return [], _nothing(
        "ambiguous",
        f"a {name} looks the same turned by {turns}: its disc 0 cannot be told (use an "
        f"asymmetric grid with an odd number of rows, or --allow-symmetric)",
        symmetric=True,
    )


def _grid_continues(
    shape: tuple[int, ...],
    centres: NDArray[np.float64],
    grid: NDArray[np.float64],
    board: CircleGrid,
    spacing_px: float,
) -> str:
    """Which way the grid ``grid`` (one numbering, shape (rows, cols, 2)) continues past
    its sides: the blobs ``centres`` hold a disc within a quarter spacing of every place
    the layout predicts beyond a side and inside the image, at least
    :data:`MIN_BEYOND_FRACTION` of the side's discs ("" when on no side)."""
    import cv2

    rows, cols = board.rows, board.cols
    xy = board.points[:, :2].reshape(rows, cols, 2)
    # one more row or column on each side: two steps out from the second one (an
    # asymmetric grid's rows alternate)
    sides = {
        f"more than {rows} rows": (xy[1] - (xy[2] - xy[0]), xy[-2] + (xy[-1] - xy[-3])),
        f"more than {cols} circles per row": (
            xy[:, 1] - (xy[:, 2] - xy[:, 0]),
            xy[:, -2] + (xy[:, -1] - xy[:, -3]),
        ),
    }
    H, _ = cv2.findHomography(xy.reshape(-1, 2), grid.reshape(-1, 2), 0)
    if H is None or len(centres) == 0:
        return ""
    h, w = shape[:2]
    for what, beyond in sides.items():
        for side in beyond:
            uv = cv2.perspectiveTransform(side.reshape(-1, 1, 2), H).reshape(-1, 2)
            inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
            if inside.sum() < max(2, MIN_BEYOND_FRACTION * len(uv)):
                continue
            nearest = np.linalg.norm(uv[inside, None] - centres[None], axis=-1).min(axis=1)
            if (nearest < 0.25 * spacing_px).all():
                return what
    return ""


#: The origin disc's blob must be this many times the median disc's size (diameter).
ORIGIN_SIZE_RATIO = 1.3


def _by_origin_disc(
    discs: tuple[NDArray[np.float64], NDArray[np.float64]],
    grids: list[NDArray[np.float64]],
    spacing_px: float,
) -> tuple[list[NDArray[np.float64]], str]:
    """Of the numberings a symmetric grid allows, the one whose disc 0 is the larger
    origin disc (its blob's size, from the blob detector's ``discs``: centres and
    sizes, at least :data:`ORIGIN_SIZE_RATIO` times the median disc's and the largest of
    the candidates' disc 0); ``([], why)`` when no candidate's disc 0 is clearly
    larger."""
    centres, sizes = discs
    if len(centres) == 0:
        return [], "no blobs to measure the origin disc"

    def size_at(uv: NDArray[np.float64]) -> float:
        distance = np.linalg.norm(centres - uv, axis=1)
        k = int(np.argmin(distance))
        return float(sizes[k]) if distance[k] < 0.5 * spacing_px else 0.0

    median = float(np.median([size_at(uv) for uv in grids[0].reshape(-1, 2)]))
    origin = [size_at(grid[0, 0]) for grid in grids]
    k = int(np.argmax(origin))
    others = max([size for i, size in enumerate(origin) if i != k], default=0.0)
    if origin[k] < ORIGIN_SIZE_RATIO * median or others >= origin[k] / ORIGIN_SIZE_RATIO:
        return [], (
            f"no corner disc is the larger origin disc (disc 0 candidates {origin[k]:.1f} px "
            f"and {others:.1f} px across, the median disc {median:.1f} px)"
        )
    return [grids[k]], ""


def _neighbour_distance(grid: NDArray[np.float64], board: CircleGrid) -> float:
    """Median distance in pixels between neighbouring centres of a row (an asymmetric
    grid's row neighbours are ``2 spacing`` apart: halved)."""
    along = np.linalg.norm(np.diff(grid, axis=1), axis=-1)
    return float(np.median(along) / (2.0 if board.asymmetric else 1.0))


def _local_error(grid: NDArray[np.float64], board: CircleGrid) -> tuple[float, int]:
    """The largest distance, pixels, between a centre and its prediction by the
    homography of its neighbours up to two rows and columns away; and that centre."""
    import cv2

    rows, cols = board.rows, board.cols
    board_xy = board.points[:, :2].reshape(rows, cols, 2)
    worst, which = 0.0, 0
    for r in range(rows):
        for c in range(cols):
            r0, r1, c0, c1 = max(r - 2, 0), min(r + 3, rows), max(c - 2, 0), min(c + 3, cols)
            keep = np.ones((r1 - r0, c1 - c0), dtype=bool)
            keep[r - r0, c - c0] = False
            H, _ = cv2.findHomography(board_xy[r0:r1, c0:c1][keep], grid[r0:r1, c0:c1][keep], 0)
            if H is None:
                continue
            p = cv2.perspectiveTransform(board_xy[r, c].reshape(1, 1, 2), H).reshape(2)
            error = float(np.linalg.norm(p - grid[r, c]))
            if error > worst:
                worst, which = error, r * cols + c
    return worst, which


# -- AprilTag grids -------------------------------------------------------------------------
class AprilGridFinder:
    """Finds an :class:`AprilGrid`'s tag corners; build once per board (module docstring)."""

    def __init__(self, board: AprilGrid) -> None:
        import cv2

        self.board = board
        params = cv2.aruco.DetectorParameters()
        params.markerBorderBits = board.border_bits
        dictionary = board.opencv_dictionary()
        self._bits = int(dictionary.markerSize)
        self._detector = cv2.aruco.ArucoDetector(dictionary, params)

    def find(self, image: NDArray[np.uint8]) -> tuple[Found, list[str]]:
        """The corners seen, sorted by the board's numbers, and notes on the tags
        dropped."""
        import cv2

        board = self.board
        corners, ids, _ = self._detector.detectMarkers(image)
        if ids is None or len(ids) == 0:
            return _nothing(
                "not found", f"no tag of {board.dictionary} ({board.border_bits}-bit border)"
            ), []
        ids = np.asarray(ids, dtype=np.int64).ravel()
        quads = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2)
        notes = []
        mine = (ids >= board.first_id) & (ids < board.first_id + board.tags)
        if not mine.all():
            notes.append(f"tags {sorted(set(ids[~mine].tolist()))} are not the board's")
        values, counts = np.unique(ids, return_counts=True)
        twice = values[counts > 1]
        if len(twice):
            notes.append(f"tags {twice.tolist()} seen twice")
        keep = mine & ~np.isin(ids, twice)
        ids, quads = ids[keep], quads[keep]
        if len(ids) == 0:
            return _nothing(
                "not found",
                f"{'; '.join(notes)}: none of the board's tags (ids {board.first_id}-"
                f"{board.first_id + board.tags - 1})",
            ), notes
        side = float(np.median(np.linalg.norm(quads - np.roll(quads, 1, axis=1), axis=-1)))
        bits = self._bits + 2 * board.border_bits
        # the window stays inside the gap's corner square and the tag's black border
        reach = min(board.spacing, board.border_bits / bits) * side
        half = int(np.clip(0.8 * reach, 2, 10))
        raw = quads.reshape(-1, 1, 2).astype(np.float32)
        criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
        refined = cv2.cornerSubPix(image, raw.copy(), (half, half), (-1, -1), criteria)
        uv = np.asarray(refined, dtype=np.float64).reshape(-1, 2)
        point_ids = board.corner_ids(ids).ravel()
        moved = _off_neighbours(uv, board.points[point_ids, :2], board.pitch_m, side)
        off = self._off_layout(uv, point_ids, side)
        off_tags = sorted(set(np.repeat(ids, 4)[off].tolist()))
        if 2 * len(off_tags) >= len(ids) > 1:
            return _nothing(
                "not found",
                f"{len(off_tags)} of the {len(ids)} tags seen do not fit the board's layout "
                f"(check COLSxROWS, FIRST_ID, and that the board is printed as Kalibr prints it)",
            ), notes
        if off_tags:
            notes.append(f"tags {off_tags} off the board's layout")
        good = ~moved & ~np.repeat(off.reshape(-1, 4).any(axis=1), 4)
        order = np.argsort(point_ids[good])
        return Found("found", "", uv[good][order], point_ids[good][order]), notes

    def _off_layout(
        self, uv: NDArray[np.float64], point_ids: NDArray[np.int64], side_px: float
    ) -> NDArray[np.bool_]:
        """Corners that the RANSAC homography of all the corners does not keep (all
        kept with fewer than two tags)."""
        import cv2

        if len(uv) < 8:
            return np.zeros(len(uv), dtype=bool)
        board_xy = self.board.points[point_ids, :2]
        _, inliers = cv2.findHomography(board_xy, uv, cv2.RANSAC, max(side_px / 3.0, 1.0))
        if inliers is None:
            return np.ones(len(uv), dtype=bool)
        return ~inliers.ravel().astype(bool)


def _off_neighbours(
    uv: NDArray[np.float64], board_xy: NDArray[np.float64], pitch_m: float, side_px: float
) -> NDArray[np.bool_]:
    """Corners farther than :data:`MAX_CORNER_ERROR` tag sides (at least 0.5 px) from
    their prediction by the homography of the other corners within two tag pitches on
    the board (corners with fewer than 4 such neighbours are kept)."""
    import cv2

    off = np.zeros(len(uv), dtype=bool)
    near = np.linalg.norm(board_xy[:, None] - board_xy[None], axis=-1) <= 2.0 * pitch_m
    for i in range(len(uv)):
        others = near[i].copy()
        others[i] = False
        if others.sum() < 4:
            continue
        H, _ = cv2.findHomography(board_xy[others], uv[others], 0)
        if H is None:
            continue
        predicted = cv2.perspectiveTransform(board_xy[i].reshape(1, 1, 2), H).reshape(2)
        off[i] = np.linalg.norm(predicted - uv[i]) > max(MAX_CORNER_ERROR * side_px, 0.5)
    return off
