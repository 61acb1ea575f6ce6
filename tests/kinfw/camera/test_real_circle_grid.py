"""Real images of industrial_calibration's modified circle grid (``tests/data/
industrial_calibration_circles``: 15 wrist-camera images, the logged flange poses, nominal
intrinsics; Apache-2.0).

Truths: the board's own layout (10 x 10 dots at 25.4 mm, one larger origin dot), which
every image shows whole; and the source's own check that a fit of the camera mount and
board pose converges to about 1.5 px (its cost). Through ``kinfw pose-chain``, ``detect``
and the default ``calibrate``: every image found with all 100 dots; a spec one row and
column short is "part of a larger grid" on every image; without the origin dot's diameter
the error asks for it; the default fits the frames alone (the chain is exact) and the
per-coordinate reprojection RMS is within the source's level (measured 1.63 px). The
intrinsics (nominal Kinect values) are wrong: the default warns, and refined they predict
held-out images better.
"""

from __future__ import annotations

import json

import pytest

from kinfw.cli._main import main
from tests.paths import DATA

SET = DATA / "industrial_calibration_circles"
SPEC = "circles:10x10:0.0254:0.01:0.02"


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    """The pose chain's URDF and joints file, and the 15 images."""
    root = tmp_path_factory.mktemp("circles")
    argv = ["-q", "pose-chain", str(SET / "flange_poses.csv"), "--camera-frame", "camera"]
    argv += ["--urdf-out", str(root / "chain.urdf"), "--joints-out", str(root / "joints.csv")]
    assert main(argv) == 0
    images = sorted((SET / "images").glob("*.png"), key=lambda p: int(p.stem))
    assert len(images) == 15
    return root, images


def _detect(chain, spec, out, capsys):
    root, images = chain
    argv = ["-q", "detect", *map(str, images), "--board", spec, "--joints"]
    argv += [str(root / "joints.csv"), "--camera", str(SET / "camera.yaml"), "--frame", "camera"]
    code = main([*argv, "--out", str(out)])
    captured = capsys.readouterr()
    return code, captured.out + captured.err


@pytest.mark.slow
def test_every_real_image_shows_the_whole_board_and_the_default_fits_the_mount(chain, capsys):
    root, _ = chain
    code, text = _detect(chain, SPEC, root / "all.json", capsys)
    assert code == 0, text
    data = json.loads((root / "all.json").read_text())
    corners = [len(o["uv"]) for s in data["samples"] for o in s["observations"]]
    assert corners == [100] * 15
    argv = ["calibrate", str(root / "all.json"), "--urdf", str(root / "chain.urdf")]
    assert main([*argv, "--out", str(root / "cal.urdf")]) == 0
    said = capsys.readouterr()
    out = said.out
    sidecar = json.loads((root / "cal.kinfw.json").read_text())
    assert sidecar["model"]["parameters"] == ["frames"]
    # the reprojection table's row: camera, images, points, RMS px (of the norm), max px
    row = next(r for r in map(str.split, out.splitlines()) if r[:3] == ["camera", "15", "1500"])
    rms_norm_px = float(row[3])
    assert rms_norm_px / 2**0.5 < 2.0, out  # per coordinate; the source: < 1.5 (its cost)
    assert "camera_joint" in out  # the mount, in the table of changed origins
    # the worst images by file name, their one folder said once
    assert f"worst images (RMS px, in {SET / 'images'}/): 2.png (camera, samples[2])" in out
    # the nominal Kinect intrinsics are wrong, and the check says so with its evidence
    assert "refining the camera intrinsics (9 parameters) lowers the pixel noise" in said.err
    assert "moves camera_joint by" in said.err


@pytest.mark.slow
def test_refined_intrinsics_predict_held_out_real_images_better(chain, capsys):
    """What the warning claims, on images the fits never saw: 5-fold by image (seed 0),
    the frames fit with the intrinsics refined predicts the held-out dots better than
    with the nominal intrinsics (measured 2.36 vs 3.40 px, RMS of the error norm)."""
    import numpy as np

    from kinfw.identification import identify
    from kinfw.measurements import read_measurements
    from kinfw.model import load_robot
    from kinfw.verification.evaluation import fitted_unknowns, held_out_errors

    root, _ = chain
    assert _detect(chain, SPEC, root / "cv.json", capsys)[0] == 0
    nominal, data = load_robot(root / "chain.urdf"), read_measurements(root / "cv.json")
    folds = np.array_split(np.random.default_rng(0).permutation(data.n_samples), 5)
    errors = {False: [], True: []}
    for test_ids in folds:
        train = data.subset(np.setdiff1d(np.arange(data.n_samples), test_ids))
        test = data.subset(np.sort(test_ids))
        for refined in errors:
            fit = identify(nominal, train, parameters="frames", refine_intrinsics=refined)
            held = held_out_errors(nominal, fit.urdf_xml, fitted_unknowns(fit), test)
            errors[refined] += [np.ravel(g.of("pixel").shown()) for g in held.groups]
    rms = {k: float(np.sqrt(np.mean(np.square(np.concatenate(v))))) for k, v in errors.items()}
    assert rms[True] < 0.8 * rms[False], rms


@pytest.mark.slow
def test_a_short_spec_and_a_missing_origin_dot_are_named_on_the_real_images(chain, capsys):
    root, _ = chain
    code, text = _detect(chain, "circles:9x9:0.0254:0.01:0.02", root / "x.json", capsys)
    assert code == 2 and "part of a larger grid" in text and "--allow-symmetric" not in text
    code, text = _detect(chain, "circles:10x10:0.0254:0.01", root / "y.json", capsys)
    assert code == 2 and "give its diameter" in text and "--allow-symmetric" not in text


@pytest.mark.slow
def test_the_hand_eye_cost_printed_ends_at_the_redundancy(chain, capsys):
    """``kinfw handeye``'s Levenberg-Marquardt whitens its cost by noise scales
    re-estimated after every step, each the weighted residual sum over its redundancy, so
    at convergence the cost is the redundancy itself: 6 x 15 pose pairs - 12 unknowns =
    78 (no pose down-weighted here). Printed with six significant digits, trailing zeros
    kept (``78.0000``, not ``78`` after ``77.9994``, which read as a rise), under a title
    that says the noise is re-estimated."""
    import re

    root, _ = chain
    assert _detect(chain, SPEC, root / "lm.json", capsys)[0] == 0
    argv = ["handeye", str(root / "lm.json"), "--urdf", str(root / "chain.urdf")]
    assert main(argv) == 0
    err = capsys.readouterr().err
    costs = re.findall(
        r"Levenberg-Marquardt, noise re-estimated each step: step \d+, cost (\S+)", err
    )
    assert len(costs) >= 2, err
    assert all(len(c.replace(".", "")) == 6 for c in costs), costs
    assert float(costs[-1]) == pytest.approx(6 * 15 - 12, rel=1e-3), costs
