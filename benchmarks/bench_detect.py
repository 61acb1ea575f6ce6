"""``kinfw detect``'s point finder on rendered images, per board type: detection rate,
point error against the truth, time per image.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_detect.py [--images N] [--quick] [--seed S]

Boards: a 9 x 6 chessboard of 30 mm squares; a 7 x 5 ChArUco board of 40 mm squares,
30 mm DICT_5X5_100 markers; OpenCV's asymmetric circle grid 4 x 11 (spacing 20 mm, 8 mm
discs); a symmetric circle grid 7 x 5 (spacing 30 mm, 12 mm discs: ambiguous whenever
found); Kalibr's aprilgrid 5 x 4 of 36h11 tags of 45 mm, spacing 0.3. Conditions: a
640 x 480, f = 500 px camera without distortion or with barrel distortion (k1 = -0.25,
k2 = 0.08, p1 = 0.001, p2 = -0.001), Gaussian image noise (sigma in grey levels of
0..255) and Gaussian blur (sigma in px). N random poses per row: the board's centre
0.35-1.0 m ahead, within the central 60 % of the field of view, tilted up to 45 degrees,
turned by any angle about its normal. Images are rendered by
``kinfw.simulation.render_board`` (3 x 3 supersampling).

Columns:

- ``seen``: images in which every point projects inside the image 3 px from its border
  (chessboard, circle grids) / at least 6 points do (ChArUco, aprilgrid), of N;
- ``found``: ``seen`` images where the board was found (rate = found / seen);
- ``also``: images found though not ``seen`` (a point within 3 px of the border);
- ``ambig.``: images reported ambiguous (a symmetric board);
- ``wrong``: found images whose numbering is wrong (RMS error over 3 px): must be 0;
- ``median px`` / ``p95 px``: per-point distance between the detected and the true
  pixel (``CameraIntrinsics.project(camera_T_board @ board_p)``), over all found points;
- ``ms/image``: median wall time of ``Detector.detect`` on one image (reading the file
  not included).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import format_table, machine_info
from scipy.spatial.transform import Rotation

from kinfw.camera import AprilGrid, CameraIntrinsics, Charuco, Chessboard, CircleGrid, Detector
from kinfw.simulation import render_board, true_corners

CAMERAS = {
    "none": CameraIntrinsics(640, 480, 500.0, 500.0, 319.5, 239.5),
    "barrel": CameraIntrinsics(
        640, 480, 500.0, 500.0, 322.0, 237.0, k1=-0.25, k2=0.08, p1=0.001, p2=-0.001
    ),
}
BOARDS = {
    "chessboard 9x6": Chessboard(9, 6, 0.03),
    "charuco 7x5": Charuco(7, 5, 0.04, 0.03),
    "acircles 4x11": CircleGrid(4, 11, 0.02, asymmetric=True),
    "circles 7x5": CircleGrid(7, 5, 0.03),
    "aprilgrid 5x4": AprilGrid(5, 4, 0.045, 0.3),
}
#: (distortion, noise sigma in grey levels, blur sigma in px)
CONDITIONS = (
    ("none", 0.0, 0.0),
    ("none", 2.0, 0.0),
    ("barrel", 2.0, 0.0),
    ("barrel", 5.0, 0.0),
    ("barrel", 2.0, 1.0),
)


def random_pose(board, camera, rng):
    """camera_T_board: centre 0.35-1.0 m ahead within the central 60 % of the view, tilted
    up to 45 degrees, turned by any angle about the normal."""
    distance = rng.uniform(0.35, 1.0)
    u = camera.cx + rng.uniform(-0.3, 0.3) * camera.width
    v = camera.cy + rng.uniform(-0.3, 0.3) * camera.height
    centre = distance * np.array([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1])
    axis = rng.normal(size=3)
    axis[2] = 0.0
    tilt = np.radians(rng.uniform(0.0, 45.0)) * axis / np.linalg.norm(axis)
    R = (
        Rotation.from_rotvec(tilt).as_matrix()
        @ Rotation.from_euler("z", rng.uniform(-np.pi, np.pi)).as_matrix()
    )
    camera_T_board = np.eye(4)
    camera_T_board[:3, :3] = R
    camera_T_board[:3, 3] = centre - R @ board.points.mean(axis=0)
    return camera_T_board


def run(board, camera, noise, blur, n, rng):
    detector = Detector(board)
    seen = found = also = ambiguous = wrong = 0
    errors, times = [], []
    for _ in range(n):
        camera_T_board = random_pose(board, camera, rng)
        truth = true_corners(board, camera, camera_T_board)
        camera_ps = board.points @ camera_T_board[:3, :3].T + camera_T_board[:3, 3]
        inside = camera.in_view(camera_ps, margin_px=3.0)
        visible = inside.sum() >= 6 if board.partial else inside.all()
        image = render_board(
            board, camera, camera_T_board, blur_sigma_px=blur, noise_sigma=noise, rng=rng
        )
        start = time.perf_counter()
        detection = detector.detect(image)
        times.append(time.perf_counter() - start)
        seen += bool(visible)
        ambiguous += detection.status == "ambiguous"
        if not detection.found:
            continue
        found += bool(visible)
        also += not visible
        distance = np.linalg.norm(detection.uv - truth[detection.ids], axis=1)
        if np.sqrt(np.mean(distance**2)) > 3.0:
            wrong += 1
            continue
        errors.append(distance)
    errors = np.concatenate(errors) if errors else np.array([np.nan])
    return [
        f"{seen}",
        f"{found} ({found / max(seen, 1):.0%})",
        f"{also}",
        f"{ambiguous}",
        f"{wrong}",
        f"{np.median(errors):.3f}",
        f"{np.percentile(errors, 95):.3f}",
        f"{1e3 * np.median(times):.0f}",
    ]


def main() -> None:
    import cv2

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=40, help="images per row (default 40)")
    parser.add_argument("--quick", action="store_true", help="8 images per row")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    n = 8 if args.quick else args.images
    print(machine_info([("opencv", cv2.__version__)]))
    print(f"images per row: {n}, seed {args.seed}\n")
    rows = []
    for board_name, board in BOARDS.items():
        for camera_name, noise, blur in CONDITIONS:
            rng = np.random.default_rng([args.seed, len(rows)])
            result = run(board, CAMERAS[camera_name], noise, blur, n, rng)
            rows.append([board_name, camera_name, f"{noise:g}", f"{blur:g}", *result])
    headers = ["board", "distortion", "noise", "blur", "seen", "found", "also", "ambig.", "wrong"]
    print(format_table([*headers, "median px", "p95 px", "ms/image"], rows))


if __name__ == "__main__":
    main()
