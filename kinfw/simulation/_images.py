"""Rendered board images of a simulation, laid out for ``kinfw detect``
(``kinfw simulate --pixels --images DIR``).

For each camera with ``pixels`` observations, a directory ``DIR/CAMERA`` holds

- one PNG per image of the simulation, ``IMAGE.png`` (``IMAGE`` its label in the
  measurement file), the board at its true pose (in the world, or on its
  ``target_frame`` moved by the true robot) seen by the camera through the true robot
  (:func:`kinfw.simulation.render_board`: the exact projection, distortion included,
  anti-aliased);
- ``joints.csv``: a header ``image,JOINT,...`` and one row per PNG, the configuration
  (rad, m) it was taken at (``kinfw detect --joints``, keyed by the ``image`` column);
- ``camera.json``: the camera's intrinsics (``kinfw detect --camera``,
  :meth:`kinfw.camera.CameraIntrinsics.to_dict`).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from kinfw.files import write_text_atomic
from kinfw.geometry import inverse_transform
from kinfw.simulation._board_images import render_board
from kinfw.simulation._measurements import SimulatedMeasurements

JOINTS_FILE = "joints.csv"
CAMERA_FILE = "camera.json"


def write_board_images(
    directory: str | Path,
    sim: SimulatedMeasurements,
    board: Any,
    *,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
) -> dict[str, Path]:
    """Render every image of ``sim``'s ``pixels`` observations (module docstring).

    Parameters
    ----------
    directory : str or Path
        Created if needed; one sub-directory per camera.
    sim : SimulatedMeasurements
        A simulation with ``pixels`` (its ``w_T_board`` and true robot).
    board : board object
        The board simulated (:func:`kinfw.camera.parse_board` of ``sim.board``), any
        type :func:`kinfw.simulation.render_board` draws.
    noise_sigma : float
        Gaussian noise added to each pixel, grey levels (0..255).
    rng : numpy.random.Generator, optional
        For the noise (default: seed 0).

    Returns
    -------
    dict of str to Path
        The directory of each camera.
    """
    if sim.w_T_board is None:
        raise ValueError("write_board_images: the simulation has no board images (pixels)")
    import cv2

    rng = np.random.default_rng(0) if rng is None else rng
    data, out = sim.data, {}
    for group in data.groups("pixels"):
        folder = Path(directory) / group.camera
        folder.mkdir(parents=True, exist_ok=True)
        samples = group.images()[0].tolist()
        labels = group.image_labels()
        root_T_cameras = sim.truth.frame_poses(data.qs[samples], group.camera, data.joint_names)
        root_T_boards = np.broadcast_to(sim.w_T_board, root_T_cameras.shape)
        if sim.target_frame is not None:
            on = sim.truth.frame_poses(data.qs[samples], sim.target_frame, data.joint_names)
            root_T_boards = on @ sim.w_T_board
        table = io.StringIO()
        writer = csv.writer(table, lineterminator="\n")
        writer.writerow(["image", *data.joint_names])
        for label, sample, root_T_camera, root_T_board in zip(
            labels, samples, root_T_cameras, root_T_boards, strict=True
        ):
            camera_T_board = inverse_transform(root_T_camera) @ root_T_board
            image = render_board(
                board, group.intrinsics, camera_T_board, noise_sigma=noise_sigma, rng=rng
            )
            name = f"{label}.png"
            if not cv2.imwrite(str(folder / name), image):
                raise OSError(f"{folder / name}: cannot write the image")
            writer.writerow([name, *(repr(float(v)) for v in data.qs[sample])])
        write_text_atomic(folder / JOINTS_FILE, table.getvalue())
        write_text_atomic(folder / CAMERA_FILE, json.dumps(group.intrinsics.to_dict(), indent=2))
        out[group.camera] = folder
    return out
