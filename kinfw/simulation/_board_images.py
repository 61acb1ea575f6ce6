"""Synthetic images of a calibration board seen by a camera with known intrinsics and pose,
for the tests and benchmarks of :mod:`kinfw.camera`.

:func:`render_board` traces every output pixel back to the board: the pixel centre is
undistorted (OpenCV's model inverted iteratively, the inverse checked against
:meth:`kinfw.camera.CameraIntrinsics.project` to 1e-6 px), its ray is intersected
with the board plane ``z = 0`` and the board's texture is sampled there (``cv2.remap``,
bilinear, on a texture of ``texels_per_square`` texels per square). This is done on a grid
``supersample`` times finer than the image, which is then averaged down
(``cv2.INTER_AREA``): an anti-aliased image of the exact projection, distortion included.
The true corner pixels are ``camera.project(camera_T_board @ board.points)``
(:func:`true_corners`).

The texture (:func:`board_texture`): the board as printed, a white margin around it, a grey
(128) background elsewhere. Every edge of the print falls on a texel edge (so that the
bilinear sampling does not move it), except the discs' round edges, whose texels hold
the disc's coverage (16 samples per texel).

- Chessboard: ``cols + 1`` by ``rows + 1`` squares, the top-left one black
  (:mod:`kinfw.camera`), a margin of one square;
- ChArUco: ``CharucoBoard.generateImage``, a margin of one square;
- circle grids: black discs of ``diameter_m`` (disc 0 of ``origin_diameter_m`` when the
  grid has one) at the board's points, a margin of two
  spacings from the outer centres;
- AprilTag grid: as Kalibr's ``kalibr_create_target_pdf`` prints it: each tag is
  OpenCV's ``generateImageMarker`` (the real bit pattern, ``border_bits`` wide border)
  turned by 180 degrees, with a black square of the gap's size beyond each of its four
  corners; a margin of one tag. The texel is ``tag_m / (b k)`` (``b`` bits across a tag)
  with the smallest ``k`` that puts the gaps on texel edges too.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.camera import (
    AprilGrid,
    Board,
    CameraIntrinsics,
    Chessboard,
    CircleGrid,
    project_normalized,
)

BACKGROUND = 128


def true_corners(
    board: Board, camera: CameraIntrinsics, camera_T_board: ArrayLike
) -> NDArray[np.float64]:
    """Pixels of all the board's points (corners, disc centres), shape (board.count, 2)
    (NaN behind the camera)."""
    camera_T_board = np.asarray(camera_T_board, dtype=float)
    camera_ps = board.points @ camera_T_board[:3, :3].T + camera_T_board[:3, 3]
    return camera.project(camera_ps)


def board_texture(
    board: Board, texels_per_square: int = 64
) -> tuple[NDArray[np.uint8], float, float]:
    """The board's printed face as an image (module docstring).

    Parameters
    ----------
    board : Chessboard, Charuco, CircleGrid or AprilGrid
    texels_per_square : int
        Texels per square (chessboard, ChArUco), per spacing (circle grids), at least per
        tag (AprilTag grid).

    Returns
    -------
    texture : ndarray of uint8, shape (h, w)
    texel_m : float
        Side of a texel, metres.
    origin_m : (float, float)
        Board coordinates ``(x, y)`` of the texture's top-left corner (not a texel
        centre), metres; texel ``(c, r)`` covers ``origin + [c, c+1] x [r, r+1] * texel_m``.
    """
    p = int(texels_per_square)
    if isinstance(board, CircleGrid):
        return _circle_grid_texture(board, p)
    if isinstance(board, AprilGrid):
        return _april_grid_texture(board, p)
    s = board.square_m
    if isinstance(board, Chessboard):
        squares_x, squares_y = board.cols + 1, board.rows + 1
        i = np.arange(squares_x * p) // p
        j = np.arange(squares_y * p) // p
        printed = np.where((i[None, :] + j[:, None]) % 2 == 0, 0, 255).astype(np.uint8)
        printed_origin = (-s, -s)  # the top-left printed square is [-s, 0] x [-s, 0]
    else:
        squares_x, squares_y = board.cols, board.rows
        printed = board.opencv_board().generateImage((squares_x * p, squares_y * p), marginSize=0)
        printed_origin = (0.0, 0.0)
    texture = np.full((printed.shape[0] + 2 * p, printed.shape[1] + 2 * p), 255, np.uint8)
    texture[p:-p, p:-p] = printed
    return texture, s / p, (printed_origin[0] - s, printed_origin[1] - s)


def _circle_grid_texture(
    board: CircleGrid, p: int
) -> tuple[NDArray[np.uint8], float, tuple[float, float]]:
    """Black discs on white, two spacings of margin around the outer centres."""
    s = board.spacing_m
    x_max, y_max = board.points[:, :2].max(axis=0)
    texel = s / p
    origin = (-2.0 * s, -2.0 * s)
    width = round((x_max / s + 4.0) * p)
    height = round((y_max / s + 4.0) * p)
    samples = 4  # per texel along each axis, for the discs' coverage
    offsets = (np.arange(samples) + 0.5) / samples
    u = origin[0] + (np.arange(width)[:, None] + offsets[None, :]).ravel() * texel
    v = origin[1] + (np.arange(height)[:, None] + offsets[None, :]).ravel() * texel
    x, y = np.meshgrid(u, v)
    # the nearest centre: its row first (discs are less than half a row apart in y)
    row = np.clip(np.rint(y / s), 0, board.rows - 1)
    shift = row % 2 if board.asymmetric else 0.0
    step = 2.0 if board.asymmetric else 1.0
    col = np.clip(np.rint((x / s - shift) / step), 0, board.cols - 1)
    diameter = np.where(
        (row == 0) & (col == 0), board.origin_diameter_m or board.diameter_m, board.diameter_m
    )
    inside = np.hypot(x - (step * col + shift) * s, y - row * s) <= 0.5 * diameter
    coverage = inside.reshape(height, samples, width, samples).mean(axis=(1, 3))
    texture = np.rint(255.0 * (1.0 - coverage)).astype(np.uint8)
    return texture, texel, origin


def _april_grid_texture(
    board: AprilGrid, p: int
) -> tuple[NDArray[np.uint8], float, tuple[float, float]]:
    """Kalibr's print: tags turned by 180 degrees, corner squares, one tag of margin."""
    import cv2

    dictionary = board.opencv_dictionary()
    bits = dictionary.markerSize + 2 * board.border_bits
    k = max(1, -(-p // bits))
    for candidate in range(k, 50 * k):  # the gap on texel edges too, if it can be
        if abs(board.spacing * bits * candidate - round(board.spacing * bits * candidate)) < 1e-9:
            k = candidate
            break
    n = bits * k  # texels per tag
    g = round(board.spacing * n)  # texels per gap
    texel = board.tag_m / n
    width = board.cols * n + (board.cols - 1) * g + 2 * (g + n)
    height = board.rows * n + (board.rows - 1) * g + 2 * (g + n)
    texture = np.full((height, width), 255, np.uint8)
    for t in range(board.tags):
        from_bottom, col = divmod(t, board.cols)
        left = g + n + col * (n + g)
        top = height - (g + n) - from_bottom * (n + g) - n
        for dr in (-g, n):
            for dc in (-g, n):
                texture[top + dr : top + dr + g, left + dc : left + dc + g] = 0
        tag = cv2.aruco.generateImageMarker(
            dictionary, board.first_id + t, n, borderBits=board.border_bits
        )
        texture[top : top + n, left : left + n] = tag[::-1, ::-1]
    # board (0, 0), tag first_id's bottom-left corner, is g + n texels in from the left
    # and from the bottom
    origin = (-(g + n) * texel, -(height - (g + n)) * texel)
    return texture, texel, origin


@functools.lru_cache(maxsize=8)
def _rays(camera: CameraIntrinsics, supersample: int) -> NDArray[np.float64]:
    """Normalized image coordinates ``(x, y)`` (z = 1) of the supersampled pixel centres,
    shape (H, W, 2); NaN where the inverse of the distortion does not converge."""
    import cv2

    n = supersample
    u = (np.arange(camera.width * n) + 0.5) / n - 0.5
    v = (np.arange(camera.height * n) + 0.5) / n - 0.5
    uv = np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    xy = cv2.undistortPointsIter(
        uv, camera.matrix, camera.distortion, None, None, criteria
    ).reshape(-1, 2)
    back_u, back_v = project_normalized(xy[:, 0], xy[:, 1], camera.parameters)
    error = np.hypot(back_u - uv[:, 0, 0], back_v - uv[:, 0, 1])
    xy[~(error < 1e-6)] = np.nan
    return xy.reshape(camera.height * n, camera.width * n, 2)


def render_board(
    board: Board,
    camera: CameraIntrinsics,
    camera_T_board: ArrayLike,
    *,
    supersample: int = 3,
    blur_sigma_px: float = 0.0,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
    texels_per_square: int = 64,
) -> NDArray[np.uint8]:
    """A grey image of ``board`` seen by ``camera`` (module docstring).

    Parameters
    ----------
    board : Chessboard, Charuco, CircleGrid or AprilGrid
    camera : CameraIntrinsics
    camera_T_board : array_like, shape (4, 4)
        Pose of the board in the camera's optical frame, metres.
    supersample : int
        Samples per pixel along each axis (anti-aliasing), default 3.
    blur_sigma_px : float
        Standard deviation of a Gaussian blur of the image (defocus), pixels; before the
        noise.
    noise_sigma : float
        Standard deviation of Gaussian noise added to the grey levels (0..255 scale).
    rng : numpy Generator, optional
        For the noise (default: seed 0).

    Returns
    -------
    ndarray of uint8, shape (camera.height, camera.width)
    """
    import cv2

    camera_T_board = np.asarray(camera_T_board, dtype=float)
    texture, texel_m, (x0, y0) = board_texture(board, texels_per_square)
    xy = _rays(camera, int(supersample))
    rays = np.concatenate([xy, np.ones((*xy.shape[:2], 1))], axis=-1)  # camera frame
    R, t = camera_T_board[:3, :3], camera_T_board[:3, 3]
    board_origin = -R.T @ t  # the camera's centre in the board frame
    board_rays = rays @ R  # R.T @ ray for each ray
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = -board_origin[2] / board_rays[..., 2]
        board_xy = board_origin[:2] + depth[..., None] * board_rays[..., :2]
    bad = ~(depth > 0.0) | ~np.isfinite(board_xy).all(axis=-1)
    map_x = ((board_xy[..., 0] - x0) / texel_m - 0.5).astype(np.float32)
    map_y = ((board_xy[..., 1] - y0) / texel_m - 0.5).astype(np.float32)
    map_x[bad] = -1e6
    map_y[bad] = -1e6
    fine = cv2.remap(
        texture,
        map_x,
        map_y,
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=BACKGROUND,
    ).astype(np.float32)
    image = cv2.resize(fine, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
    if blur_sigma_px > 0.0:
        image = cv2.GaussianBlur(image, (0, 0), blur_sigma_px)
    if noise_sigma > 0.0:
        rng = np.random.default_rng(0) if rng is None else rng
        image = image + rng.normal(0.0, noise_sigma, image.shape)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)
