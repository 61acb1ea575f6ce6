"""The pixel workflow as a new user runs it (issue 14): simulate --pixels, then
calibrate, verify and crossval on the file, with wrong or overriding intrinsics."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from kinfw.cli import main
from kinfw.robot import builtin_head_urdf
from verification.simulate import default_intrinsics

HEAD = builtin_head_urdf()


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def _strict_json(text: str):
    """Parse ``text`` as strict JSON: NaN and Infinity are errors."""

    def refuse(token):
        raise ValueError(f"not strict JSON: {token}")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def px(tmp_path_factory) -> Path:
    """``kinfw simulate --pixels`` (stage 1 poses and stage 2 images of the IIS-head,
    true intrinsics 640x480, fx = fy = 600 px), a camera file with fx, fy 8 % too
    large (``wrong.json``) and one with the true intrinsics (``right.json``)."""
    root = tmp_path_factory.mktemp("px")
    argv = ["simulate", "--pixels", "--seed", "1", "--out", root / "px.json"]
    assert main([str(a) for a in [*argv, "--truth-out", root / "true.urdf"]]) == 0
    true = default_intrinsics("left_camera").to_dict()
    (root / "right.json").write_text(json.dumps(true))
    wrong = {**true, "fx": 1.08 * true["fx"], "fy": 1.08 * true["fy"]}
    (root / "wrong.json").write_text(json.dumps(wrong))
    return root


def test_stage_table_uses_the_refined_intrinsics(px, capsys):
    """With --refine-intrinsics from fx 8 % off, the refine column of the stage table is
    the reprojection RMS of the calibrated model (as the reprojection section computes it
    from the refined unknowns), not the error under the start intrinsics."""
    argv = ["calibrate", px / "px.json", "--urdf", HEAD, "--out", px / "ri.urdf"]
    argv += ["--camera", f"left_camera={px / 'wrong.json'}", "--refine-intrinsics"]
    code, _, err = _run([*argv, "--report", px / "ri.json"], capsys)
    assert code == 0, err
    report = json.loads((px / "ri.json").read_text())
    stages = report["position_rms_mm_by_stage"]
    by_camera = {c["camera"]: c["rms_px"] for c in report["reprojection_px"]["cameras"]}
    for camera, rms in by_camera.items():
        refine = stages["refine"][f"{camera} (pixels) [px]"]
        # the stage table refits each image's target pose: within 5 % of the calibrated one
        assert refine == pytest.approx(rms, rel=0.05), (camera, refine, rms)
        assert refine < 1.0  # 0.5 px noise, 2 coordinates: 0.71 px expected
    # the start intrinsics are wrong: the hand-eye stage (before the refinement) is not
    assert stages["hand-eye"]["left_camera (pixels) [px]"] > 2.0
