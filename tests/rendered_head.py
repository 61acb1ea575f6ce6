"""Rendered chessboard images of the IIS head's left camera, as ``kinfw simulate
--images`` writes them (shared by the pose-chain and held-out-image tests)."""

from __future__ import annotations

from pathlib import Path

from kinfw.cli._main import main
from tests.paths import HEAD_URDF

#: The board the helper renders.
BOARD = "chessboard:9x6:0.04"


def render_left_camera(root: Path, n: int, seed: int) -> Path:
    """Simulate stage 2 of the head with ``n`` rendered images of :data:`BOARD` seen by
    ``left_camera`` (``root/sim.json``, the truth ``root/true.urdf``); return the images'
    folder (``root/img/left_camera``: PNGs, ``joints.csv``, ``camera.json``)."""
    argv = ["-q", "simulate", "--urdf", str(HEAD_URDF), "--images", str(root / "img")]
    argv += ["--cameras", "left_camera", "--stage", "2", "--board", BOARD]
    argv += ["--stage2-samples", str(n), "--seed", str(seed), "--out", str(root / "sim.json")]
    assert main([*argv, "--truth-out", str(root / "true.urdf")]) == 0
    return root / "img" / "left_camera"
