"""Simulated images: a board's corners seen by cameras on the robot, in pixels
(``kinfw simulate --pixels``, ``kinfw demo --pixels``, the planner's visibility).

The board's points are projected through the true robot into each camera
(:func:`simulate_pixels`, with Gaussian pixel noise); a point is kept only when the camera
sees it and an image only when its board is seen well enough (:func:`visible_points`, the
rules of the constants below); :func:`pixel_views` draws configurations until each camera
has its images. The measurement dataset itself is built by
:func:`kinfw.simulation.simulate_at`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.camera import CameraIntrinsics
from kinfw.geometry import check_transform, inverse_transform, transform_from_rotation_translation
from kinfw.measurements import Measurements
from kinfw.model import BlockKey, Robot
from kinfw.simulation._perturb import check_sigma, random_configurations
from kinfw.simulation._simulate import default_target_pose, frame_from_z_and_x, simulate_at

#: Default intrinsics of a simulated camera with none given: a plausible 640 x 480 VGA
#: camera with a ~56 deg horizontal field of view (fx = fy = 600 px), principal point at
#: the image centre, no distortion.
DEFAULT_CAMERA = CameraIntrinsics(640, 480, 600.0, 600.0, 319.5, 239.5, name="simulated")
#: Default board of ``kinfw simulate --pixels``: 9 x 6 inner corners, 40 mm squares.
DEFAULT_BOARD = "chessboard:9x6:0.04"
#: A point is seen when it is in front of the camera, within this angle of the optical
#: axis and at least :data:`VIEW_MARGIN_PX` inside the image.
MAX_POINT_ANGLE_DEG = 60.0
VIEW_MARGIN_PX = 5.0
#: A whole image is dropped when the line of sight to the board's centre makes more than
#: this angle with the board's normal (a board seen edge-on, or from behind) ...
MAX_BOARD_ANGLE_DEG = 70.0
#: ... or when fewer than this many of its corners are seen (PnP needs 4; a board that
#: OpenCV finds only whole, a chessboard or a circle grid, needs all of them:
#: ``min_corners=board.count``, see ``board.partial``) ...
MIN_CORNERS = 4
#: ... or when the seen corners are (nearly) on one line: the second singular value of
#: their centred positions is below this fraction of the first.
MIN_SPREAD = 0.1


def default_intrinsics(camera: str) -> CameraIntrinsics:
    """:data:`DEFAULT_CAMERA` named after the camera frame ``camera``."""
    return replace(DEFAULT_CAMERA, name=str(camera))


def board_pose_facing(
    robot: Robot,
    q: ArrayLike,
    joint_names: Sequence[str] | None,
    cameras: Sequence[str],
    board_p: ArrayLike,
    distance: float = 0.8,
    *,
    target_frame: str | None = None,
) -> NDArray[np.float64]:
    """A board pose ``w_T_board`` in front of the cameras at one configuration ``q``.

    With ``target_frame`` (a board on the robot seen by a static camera): the board's
    pose in that frame, its points' centre at the frame's origin and its z axis along
    the line from the cameras' mean position to it (facing them) at ``q``.

    The centre of the board's points is ``distance`` metres along the cameras' mean
    optical axis (z) from their mean position; the board's z axis is that axis (a
    :mod:`kinfw.camera` board's z points away from the camera that sees its printed face),
    its x axis the mean camera x axis made perpendicular to it.

    Parameters
    ----------
    robot : Robot
    q : array_like, shape (k,)
        Joint values in ``joint_names`` order (rad, m).
    joint_names : sequence of str or None
    cameras : sequence of str
        Camera optical frames (z forward, x right, y down).
    board_p : array_like, shape (m, 3)
        The board's points in its frame, metres.
    distance : float
        Metres.

    Returns
    -------
    w_T_board : ndarray, shape (4, 4)
    """
    board_p = np.asarray(board_p, dtype=float)
    centre_T_board = transform_from_rotation_translation(np.eye(3), -board_p.mean(axis=0))
    if target_frame is not None:
        qs = np.atleast_2d(q)
        w_T_frame = robot.frame_poses(qs, target_frame, joint_names)[0]
        w_T_cams = np.stack([robot.frame_poses(qs, c, joint_names)[0] for c in cameras])
        z = w_T_frame[:3, 3] - w_T_cams[:, :3, 3].mean(axis=0)
        if np.linalg.norm(z) < 1e-6:
            raise ValueError(
                f"board_pose_facing: {target_frame!r} is at the cameras' mean position; "
                "give the board's pose"
            )
        w_T_centre = frame_from_z_and_x(z, w_T_cams[:, :3, 0].mean(axis=0), w_T_frame[:3, 3])
        return inverse_transform(w_T_frame) @ w_T_centre @ centre_T_board
    w_T_centre = default_target_pose(robot, np.atleast_2d(q), joint_names, cameras, distance)
    # default_target_pose's z points back at the cameras: turn about x (z -> -z, y -> -y)
    w_T_centre = w_T_centre @ np.diag([1.0, -1.0, -1.0, 1.0])
    return w_T_centre @ centre_T_board


def visible_points(
    intrinsics: CameraIntrinsics,
    camera_T_board: ArrayLike,
    board_p: ArrayLike,
    *,
    margin_px: float = VIEW_MARGIN_PX,
    max_point_angle_deg: float = MAX_POINT_ANGLE_DEG,
    max_board_angle_deg: float = MAX_BOARD_ANGLE_DEG,
    min_corners: int = MIN_CORNERS,
) -> NDArray[np.bool_]:
    """Which board points each image sees.

    A point is seen when :meth:`~kinfw.camera.CameraIntrinsics.in_view` says so
    (in front of the camera, within ``max_point_angle_deg`` of the optical axis, inside
    the image at least ``margin_px`` from its border). An image sees nothing when the
    line of sight from the camera to the centre of the board's points makes more than
    ``max_board_angle_deg`` with the board's normal (edge-on, or seen from behind: the
    printed face is the one whose normal, board -z, points at the camera), or when it
    sees fewer than ``min_corners`` points, or its seen points are nearly on one line
    (:data:`MIN_SPREAD`).

    Parameters
    ----------
    intrinsics : CameraIntrinsics
    camera_T_board : array_like, shape (n, 4, 4)
        Board poses in the camera's optical frame, metres.
    board_p : array_like, shape (m, 3)
        Board points in the board frame, metres.

    Returns
    -------
    ndarray of bool, shape (n, m)
    """
    c_T_b = np.asarray(camera_T_board, dtype=float).reshape(-1, 4, 4)
    board_p = np.asarray(board_p, dtype=float)
    c_p = np.einsum("nij,kj->nki", c_T_b[:, :3, :3], board_p) + c_T_b[:, None, :3, 3]
    seen = intrinsics.in_view(c_p, margin_px=margin_px, max_angle_deg=max_point_angle_deg)
    centre = c_T_b[:, :3, :3] @ board_p.mean(axis=0) + c_T_b[:, :3, 3]
    sight = centre / np.linalg.norm(centre, axis=1, keepdims=True)
    # the printed face looks along board -z: towards the camera when sight . z_board > 0
    cos_angle = np.einsum("ni,ni->n", sight, c_T_b[:, :3, 2])
    facing = cos_angle >= np.cos(np.radians(max_board_angle_deg))
    keep = facing & (seen.sum(axis=1) >= max(int(min_corners), 3))
    for i in np.flatnonzero(keep):  # PnP needs points off one line
        p = board_p[seen[i]] - board_p[seen[i]].mean(axis=0)
        sv = np.linalg.svd(p, compute_uv=False)
        keep[i] = sv[1] > MIN_SPREAD * sv[0]
    return seen & keep[:, None]


def simulate_pixels(
    robot: Robot,
    qs: ArrayLike,
    joint_names: Sequence[str] | None,
    *,
    cameras: Mapping[str, CameraIntrinsics],
    board_p: ArrayLike,
    w_T_board: ArrayLike,
    rng: np.random.Generator,
    sigma_px: float = 0.0,
    target: str = "board",
    point_ids: ArrayLike | None = None,
    target_frame: str | None = None,
    **visibility: float,
) -> tuple[Measurements, NDArray[np.int64]]:
    """``pixels`` observations of a board by cameras on the robot (the board fixed in
    the world, or on the URDF frame ``target_frame``: a static camera watching a board
    on the flange).

    Each camera's image of the board at each configuration: the board's points seen
    (:func:`visible_points`), projected through the true robot by the ``pixels`` kind
    (:meth:`kinfw.observations.PixelKind.simulate`), plus independent Gaussian
    noise ``N(0, sigma_px^2)`` on each pixel coordinate.

    Parameters
    ----------
    robot : Robot
        The true robot.
    qs : array_like, shape (n, k)
        Joint values (rad, m) in ``joint_names`` order.
    joint_names : sequence of str or None
    cameras : mapping of str to CameraIntrinsics
        Camera optical frames and their intrinsics.
    board_p : array_like, shape (m, 3)
        The board's points in its frame, metres.
    w_T_board : array_like, shape (4, 4)
        The board's true pose in the root frame ``w`` (in ``target_frame`` when given).
    rng : numpy.random.Generator
    sigma_px : float
        Pixel noise per coordinate, px.
    target : str
        The board's target name.
    point_ids : array_like of int, shape (m,), optional
        The points' ids (default ``0 .. m-1``).
    target_frame : str, optional
        The URDF frame the board is fixed to (default: fixed in the world).
    **visibility
        ``margin_px``, ``max_point_angle_deg``, ``max_board_angle_deg``,
        ``min_corners`` of :func:`visible_points`.

    Returns
    -------
    data : Measurements
        Only the configurations where at least one camera sees the board (images
        labelled ``"<camera>_<sample>"``), with the cameras' intrinsics.
    kept : ndarray of int64
        Row of ``qs`` of each of ``data``'s samples.
    """
    from kinfw.observations import PixelObservations

    names = tuple(robot.joint_names if joint_names is None else joint_names)
    qs = np.atleast_2d(np.asarray(qs, dtype=float))
    board_p = np.asarray(board_p, dtype=float)
    w_T_board = check_transform(w_T_board, name="w_T_board")
    sigma_px = check_sigma(sigma_px, "sigma_px")
    ids = np.arange(len(board_p)) if point_ids is None else np.asarray(point_ids, np.int64)
    w_T_boards = np.broadcast_to(w_T_board, (len(qs), 4, 4))
    if target_frame is not None:
        w_T_boards = robot.frame_poses(qs, target_frame, names) @ w_T_board
    masks = {
        camera: visible_points(
            intr,
            inverse_transform(robot.frame_poses(qs, camera, names)) @ w_T_boards,
            board_p,
            **visibility,
        )
        for camera, intr in cameras.items()
    }
    kept = np.flatnonzero(np.any([m.any(axis=1) for m in masks.values()], axis=0))
    if not len(kept):
        raise ValueError(
            f"simulate_pixels: no camera ({', '.join(cameras)}) sees the board at any of "
            f"the {len(qs)} configurations"
        )
    templates = []
    for camera, mask in masks.items():
        mask = mask[kept]
        sample, point = np.nonzero(mask)
        if not len(sample):
            continue
        templates.append(
            PixelObservations(
                camera=camera,
                intrinsics=cameras[camera],
                sample=sample,
                uv=np.zeros((len(sample), 2)),
                target_p=board_p[point],
                point_id=ids[point],
                shot=np.zeros(len(sample), np.int64),
                image=np.array([f"{camera}_{int(kept[s]):03d}" for s in sample], dtype=object),
                sigma_px=np.full(len(sample), np.nan),
                target=target,
                target_frame=target_frame,
            )
        )
    data = simulate_at(
        robot,
        qs[kept],
        names,
        groups=templates,
        unknowns={BlockKey("target", target): w_T_board},
        rng=rng,
        sigmas={"pixel": sigma_px},
    )
    return data.with_cameras(dict(cameras)), kept


def pixel_views(
    robot: Robot,
    joint_names: Sequence[str],
    lower: ArrayLike,
    upper: ArrayLike,
    n: int,
    rng: np.random.Generator,
    *,
    cameras: Mapping[str, CameraIntrinsics],
    board_p: ArrayLike,
    sigma_px: float,
    fraction: float = 0.8,
    w_T_board: ArrayLike | None = None,
    target: str = "board",
    distance: float = 0.8,
    max_rounds: int = 50,
    min_corners: int = MIN_CORNERS,
    target_frame: str | None = None,
) -> tuple[Measurements, NDArray[np.float64]]:
    """``n`` random configurations at which some camera sees a fixed board (or a board
    on ``target_frame``), and the images (:func:`simulate_pixels`).

    Configurations are drawn by :func:`random_configurations` (``fraction`` of each
    joint range), ``2 n`` at a time, and kept when at least one camera sees the board
    (:func:`visible_points`), in draw order, until ``n`` are kept.

    Parameters
    ----------
    robot : Robot
        The true robot.
    joint_names : sequence of str
    lower, upper : array_like, shape (k,)
        Joint limits in ``joint_names`` order.
    n : int
        Configurations wanted.
    rng : numpy.random.Generator
    cameras : mapping of str to CameraIntrinsics
    board_p : array_like, shape (m, 3)
        The board's points in its frame, metres.
    sigma_px : float
        Pixel noise per coordinate, px.
    fraction : float
    w_T_board : array_like, shape (4, 4), optional
        The board's pose; default :func:`board_pose_facing` at the middle of the
        joint ranges, ``distance`` metres away.
    min_corners : int
        Fewest corners an image must see (:func:`visible_points`).
    target_frame : str, optional
        The URDF frame the board is fixed to (``w_T_board`` is then its pose in that
        frame; default :func:`board_pose_facing` with ``target_frame``).

    Returns
    -------
    data : Measurements
    w_T_board : ndarray, shape (4, 4)
        In the root frame, or in ``target_frame``.

    Raises
    ------
    ValueError
        When fewer than ``n`` of ``2 n max_rounds`` draws see the board.
    """
    names = tuple(joint_names)
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    board_p = np.asarray(board_p, dtype=float)
    if w_T_board is None:
        w_T_board = board_pose_facing(
            robot,
            0.5 * (lower + upper),
            names,
            tuple(cameras),
            board_p,
            distance,
            target_frame=target_frame,
        )
    w_T_board = check_transform(w_T_board, name="w_T_board")
    found: list[NDArray[np.float64]] = []
    count = 0
    for _ in range(max_rounds):
        qs = random_configurations(lower, upper, 2 * n, rng, fraction=fraction)
        seen = np.zeros(len(qs), bool)
        w_T_boards = np.broadcast_to(w_T_board, (len(qs), 4, 4))
        if target_frame is not None:
            w_T_boards = robot.frame_poses(qs, target_frame, names) @ w_T_board
        for camera, intr in cameras.items():
            c_T_b = inverse_transform(robot.frame_poses(qs, camera, names)) @ w_T_boards
            seen |= visible_points(intr, c_T_b, board_p, min_corners=min_corners).any(axis=1)
        found.append(qs[seen])
        count += int(seen.sum())
        if count >= n:
            break
    else:
        raise ValueError(
            f"pixel_views: the cameras {list(cameras)} see the board in only {count} of "
            f"{2 * n * max_rounds} random configurations; {n} wanted"
        )
    qs = np.concatenate(found)[:n]
    data, _ = simulate_pixels(
        robot,
        qs,
        names,
        cameras=cameras,
        board_p=board_p,
        w_T_board=w_T_board,
        rng=rng,
        sigma_px=sigma_px,
        target=target,
        min_corners=min_corners,
        target_frame=target_frame,
    )
    return data, w_T_board
