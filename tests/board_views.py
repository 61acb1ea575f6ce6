"""Configurations at which a camera sees a whole board, for tests that render images."""

from __future__ import annotations

import numpy as np

from kinfw.geometry import inverse_transform


def board_in_view(w_T_cameras, w_T_board, board, camera, *, margin_px=25.0, max_tilt_deg=50.0):
    """Mask, shape (n,), of the camera poses ``w_T_cameras`` (n, 4, 4) that see every
    point of ``board`` (at ``w_T_board``) at least ``margin_px`` inside the image, with the
    board's normal less than ``max_tilt_deg`` off the optical axis."""
    c_T_b = inverse_transform(w_T_cameras) @ w_T_board
    c_p = np.einsum("nij,kj->nki", c_T_b[:, :3, :3], board.points) + c_T_b[:, None, :3, 3]
    tilt = np.degrees(np.arccos(np.clip(c_T_b[:, 2, 2], -1.0, 1.0)))
    return camera.in_view(c_p, margin_px=margin_px).all(axis=1) & (tilt < max_tilt_deg)
