"""The pixel workflow as a new user runs it (issue 14): simulate --pixels, then
calibrate, verify and crossval on the file, with wrong or overriding intrinsics."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from kinfw.cli._main import main
from kinfw.files import sidecar_path
from kinfw.model import builtin_head_urdf
from kinfw.records import read_sidecar
from kinfw.simulation import default_intrinsics

HEAD = builtin_head_urdf()


def _run(argv, capsys):
    """Exit code, stdout and stderr of ``kinfw -q ARGV`` (-q: no progress lines, so
    stderr holds only what the command says: its warnings and errors)."""
    code = main(["-q", *(str(a) for a in argv)])
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


@pytest.fixture(scope="module")
def refined(px) -> Path:
    """``kinfw calibrate`` of ``px.json`` from the wrong intrinsics with
    ``--refine-intrinsics``: ``ri.urdf``, its sidecar and report ``ri.json``."""
    argv = ["calibrate", px / "px.json", "--urdf", HEAD, "--out", px / "ri.urdf"]
    argv += ["--camera", f"left_camera={px / 'wrong.json'}", "--refine-intrinsics"]
    assert main([str(a) for a in [*argv, "--report", px / "ri.json"]]) == 0
    return px / "ri.urdf"


@pytest.mark.slow
def test_stage_table_uses_the_refined_intrinsics(px, refined):
    """With --refine-intrinsics from fx 8 % off, the refine column of the stage table is
    the reprojection RMS of the calibrated model (as the reprojection section computes it
    from the refined unknowns), not the error under the start intrinsics."""
    report = _strict_json((px / "ri.json").read_text())
    # px groups under their own key with the unit, not in the mm table
    assert not any("pixels" in g for g in report["position_rms_mm_by_stage"]["refine"])
    stages = report["pixel_rms_px_by_stage"]
    by_camera = {c["camera"]: c["rms_px"] for c in report["reprojection_px"]["cameras"]}
    for camera, rms in by_camera.items():
        refine = stages["refine"][f"{camera} (pixels)"]
        # the stage table refits each image's target pose: within 5 % of the calibrated one
        assert refine == pytest.approx(rms, rel=0.05), (camera, refine, rms)
        assert refine < 1.0  # 0.5 px noise, 2 coordinates: 0.71 px expected
    # the start intrinsics are wrong: the hand-eye stage (before the refinement) is not
    assert stages["hand-eye"]["left_camera (pixels)"] > 2.0


def _pixel_rms(text: str, camera: str) -> float:
    """The ``pixel RMS px`` column of verify's table on the camera's row."""
    lines = text.splitlines()
    head = next(line for line in lines if "pixel RMS px" in line)
    row = next(line for line in lines if line.strip().startswith(camera))
    end = head.index("pixel RMS px") + len("pixel RMS px")
    return float(row[:end].split()[-1])


@pytest.mark.slow
def test_verify_camera_overrides_the_sidecar_and_says_so(px, refined, capsys):
    """The sidecar holds the refined intrinsics (near the truth): the images reproject
    to the noise level; --camera with fx 8 % off must be used instead (tens of px at the
    board's 0.1-0.2 m offsets from the axis at 0.8 m: ~ 0.08 * 150 px), with a note."""
    code, out, err = _run(["verify", refined, px / "px.json"], capsys)
    assert code == 0, err
    assert _pixel_rms(out, "left_camera") < 1.0
    assert "intrinsics" not in out  # the sidecar's are used, not fitted
    wrong = f"left_camera={px / 'wrong.json'}"
    code, out, err = _run(["verify", refined, px / "px.json", "--camera", wrong], capsys)
    assert code == 0, err
    assert _pixel_rms(out, "left_camera") > 5.0
    assert _pixel_rms(out, "right_camera") < 1.0  # not overridden: the sidecar's
    assert (
        f"note: intrinsics of camera 'left_camera' from --camera {wrong}, not the sidecar's" in out
    )
    code, out, err = _run(["verify", refined, px / "px.json", "--camera", wrong, "--json"], capsys)
    assert _strict_json(out)["intrinsics_from_camera_option"] == ["left_camera"]


@pytest.mark.parametrize("command", ["calibrate", "verify", "crossval"])
def test_camera_option_for_a_frame_no_observation_uses_is_an_error(px, command, capsys):
    cam = f"left_plate={px / 'right.json'}"
    argv = {
        "calibrate": ["calibrate", px / "px.json", "--urdf", HEAD, "--out", px / "x.urdf"],
        "verify": ["verify", HEAD, px / "px.json"],
        "crossval": ["crossval", px / "px.json", "--urdf", HEAD],
    }[command]
    code, out, err = _run([*argv, "--camera", cam], capsys)
    assert code == 2 and out == ""
    assert err == (
        f"kinfw {command}: error: --camera {cam}: no observation of {px / 'px.json'} uses "
        "camera frame 'left_plate' (the camera frames of its 'pixels' observations: "
        "right_camera, left_camera)\n"
    )


def test_pnp_skips_images_with_fewer_than_4_points_and_names_failures(px):
    """A rejection of gross errors can leave an image with < 4 corners: the PnP start
    skips it (the others still give the pose); none left is a DatasetError naming the
    camera, never a cv2.error."""
    from kinfw.measurements import read_measurements
    from kinfw.observations import DatasetError, kind_of, pnp_camera_T_targets

    (g, *_) = read_measurements(px / "px.json").groups("pixels")
    kind = kind_of(g)
    _, rows = g.images()
    full_samples, full_poses = pnp_camera_T_targets(g)
    # the first image keeps 3 of its corners
    keep = np.concatenate([rows[0][:3], *rows[1:]])
    cut = kind.take(g, keep, g.sample[keep])
    cut_samples, cut_poses = pnp_camera_T_targets(cut)
    np.testing.assert_array_equal(cut_samples, full_samples[1:])
    np.testing.assert_allclose(cut_poses, full_poses[1:], atol=1e-9)
    only = kind.take(g, rows[0][:3], g.sample[rows[0][:3]])
    with pytest.raises(DatasetError, match=rf"camera '{g.camera}': none of its 1 images has 4"):
        pnp_camera_T_targets(only)


@pytest.mark.slow
def test_crossval_on_pixel_data_scores_held_out_images_in_px(px):
    """Folds by sample keep images whole; the held-out images are scored by their RMS
    reprojection error under the fold's model and training-fold target pose. Truth: the
    simulated noise, 0.5 px per coordinate, so the norm's RMS is 0.5 sqrt(2) = 0.71 px
    (a little more held out); the pose groups keep their mm scores, with no NaN."""
    from kinfw.measurements import read_measurements
    from kinfw.model import load_robot
    from kinfw.verification.evaluation import crossvalidate

    data = read_measurements(px / "px.json")
    cv = crossvalidate(load_robot(HEAD), data, k=2, sets=("full",))
    doc = _strict_json(json.dumps(cv.to_dict(), allow_nan=False))
    for fold in doc["folds"]:
        assert 0.65 < fold["pixel_rms_px"] < 0.85, fold
        assert 0.5 < fold["position_rms_mm"] < 1.5, fold  # 0.5 mm per axis: 0.87 mm
    assert cv.scores[0].n_test + cv.scores[1].n_test == data.n_samples


@pytest.mark.slow
def test_reports_are_strict_json_and_verify_carries_pixel_residuals(px, refined, capsys):
    """report.json, the sidecar and verify --json parse with a strict parser (an
    undefined number is null) and read back; verify's per-point entries of an image
    group carry the pixel error, whose RMS is the group's; the text table prints '-'
    for the undefined position and rotation of image points, never 'nan'."""
    from kinfw.records import read_report, read_sidecar

    _strict_json((px / "ri.json").read_text())
    _strict_json(refined.with_suffix(".kinfw.json").read_text())
    report = read_report(px / "ri.json")
    read_sidecar(refined.with_suffix(".kinfw.json"))
    pixel_groups = [g for g in report.errors_after if g.kind == "pixels"]
    # an image point's error is its pixel error alone: no position or rotation metric
    assert pixel_groups and all(g.rms("position") is None for g in pixel_groups)
    assert all(g.rms("pixel") > 0 for g in pixel_groups)
    code, out, err = _run(["verify", refined, px / "px.json", "--json"], capsys)
    assert code == 0, err
    doc = _strict_json(out)
    groups = [g for g in doc["groups"] if g["kind"] == "pixels"]
    assert groups
    for g in groups:
        assert "position_rms_mm" not in g and len(g["samples"]) == g["n"]
        e = np.array([s["pixel_px"] for s in g["samples"]])
        uv = np.array([s["pixel_uv_px"] for s in g["samples"]])
        np.testing.assert_allclose(e, np.linalg.norm(uv, axis=1), rtol=1e-12)
        assert np.sqrt(np.mean(e**2)) == pytest.approx(g["pixel_rms_px"], rel=1e-12)
    code, out, err = _run(["verify", refined, px / "px.json"], capsys)
    assert "nan" not in out.lower()
    assert "fitted from the data: intrinsics" not in out


@pytest.fixture(scope="module")
def px_only(tmp_path_factory) -> Path:
    """Stage 2 images only (no poses): 30 configurations of the IIS-head, 0.5 px."""
    root = tmp_path_factory.mktemp("px_only")
    argv = ["simulate", "--pixels", "--stage", "2", "--seed", "2", "--out", root / "p2.json"]
    assert main([str(a) for a in [*argv, "--truth-out", root / "true.urdf"]]) == 0
    return root / "p2.json"


def test_simulate_pixels_only_prints_no_pose_noise(tmp_path, capsys):
    argv = ["simulate", "--pixels", "--stage", "2", "--stage2-samples", "4"]
    argv += ["--out", tmp_path / "a.json", "--truth-out", tmp_path / "t.urdf"]
    code, out, err = _run(argv, capsys)
    assert code == 0, err
    first = out.splitlines()[0]
    assert " mm" not in first and " deg" not in first, first
    assert "pixel noise 0.5 px" in out


@pytest.mark.slow
def test_held_out_images_are_named_worst_first(px_only, tmp_path, capsys):
    """``calibrate --holdout`` with images: the held-out reprojection table per camera and
    the worst held-out images by name. One held-out image's points moved 30 px along u (a
    frame grabbed with the wrong joint values) is named first, at 30 px RMS; the others
    stay near the simulated 0.5 px noise."""
    doc = json.loads(px_only.read_text())
    train, held = dict(doc), dict(doc)
    train["samples"], held["samples"] = doc["samples"][:22], doc["samples"][22:]
    moved = held["samples"][2]["observations"][0]
    moved["uv"] = [[u + 30.0, v] for u, v in moved["uv"]]
    for name, part in (("train", train), ("held", held)):
        (tmp_path / f"{name}.json").write_text(json.dumps(part))
    argv = ["calibrate", tmp_path / "train.json", "--urdf", HEAD, "--out", tmp_path / "c.urdf"]
    code, out, err = _run([*argv, "--params", "full", "--holdout", tmp_path / "held.json"], capsys)
    assert code == 0, err
    section = out[out.index("reprojection error on the held-out data, px:") :]
    line = re.search(r"worst images \(RMS px\): (.*)", section)[1]
    worst = re.findall(r"(\S+) \((\w+), samples\[(\d+)\]\) ([\d.]+)", line)
    assert len(worst) == 5, line
    assert worst[0][1] == moved["frame"] and int(worst[0][2]) == 2, worst
    assert float(worst[0][3]) == pytest.approx(30.0, rel=0.02), worst
    assert all(float(w[3]) < 1.0 for w in worst[1:]), worst


@pytest.mark.slow
def test_noise_line_names_only_the_components_the_data_has(px_only, capsys):
    """Pixel-only data: the noise line and the report give the pixel sigma alone, near
    the simulated 0.5 px; no default 1 mm / 0.5 deg of components without rows."""
    out_urdf = px_only.with_name("c2.urdf")
    argv = ["calibrate", px_only, "--urdf", HEAD, "--out", out_urdf, "--params", "full"]
    code, out, err = _run([*argv, "--report", px_only.with_name("r2.json")], capsys)
    assert code == 0, err
    line = next(x for x in out.splitlines() if x.startswith("refine: noise sigma"))
    assert " mm" not in line and " deg" not in line, line
    sigma = float(line.split("noise sigma pixel ")[1].split(" px")[0])
    assert 0.45 < sigma < 0.55, line
    noise = _strict_json(px_only.with_name("r2.json").read_text())["refine"]["noise"]
    assert list(noise["sigma_per_component"]) == ["pixel"]
    assert noise["position_sigma_mm"] is None


@pytest.mark.slow
def test_wrong_intrinsics_are_named_not_listed_as_a_hundred_gross_errors(px, capsys):
    """fx, fy 8 % too large on one camera: many corners are rejected. At most 10 lines
    (each naming the image label and corner id, which exist in the data at that sample)
    and a count; the inconsistency warning once; a hint at the intrinsics with its
    evidence (the refit with them refined). With the true intrinsics: no hint."""
    from kinfw.measurements import read_measurements
    from kinfw.records import read_report

    argv = ["calibrate", px / "px.json", "--urdf", HEAD, "--out", px / "w.urdf"]
    argv += ["--params", "full", "--report", px / "w.json"]
    # the wrong intrinsics move the camera's mount 33 mm: the plausibility guard's cause
    # (its error names them first), allowed here to read the rest of the output
    argv += ["--allow-large-changes"]
    code, out, err = _run([*argv, "--camera", f"left_camera={px / 'wrong.json'}"], capsys)
    assert code == 0, err
    lines = [x for x in out.splitlines() if "rejected as a gross error" in x]
    rejected = read_report(px / "w.json").refine.rejected
    assert len(rejected) > 20 and len(lines) == 10
    assert f"... and {len(rejected) - 10} more rejected ({len(rejected)} in all" in out
    assert all(re.search(r"\(pixels\) image left_camera_\d+ corner \d+: ", x) for x in lines)
    # each line gives the threshold in px: the 99.9 % quantile of a clean 2-D residual's
    # norm, sigma sqrt(-2 ln 0.001), under the estimated pixel noise
    sigma_px = dict(read_report(px / "w.json").refine.noise.sigmas)["pixel"]
    for x in lines:
        threshold_px = float(re.search(r"x the threshold of ([\d.]+) px", x)[1])
        assert threshold_px == pytest.approx(sigma_px * np.sqrt(-2 * np.log(1e-3)), rel=0.01)
    # and the Huber loss bends at its 99 % quantile, sigma sqrt(-2 ln 0.01)
    bends = [float(b) for b in re.findall(r"the loss bends at ([\d.]+) px", out)]
    assert bends, out
    assert bends == pytest.approx([sigma_px * np.sqrt(-2 * np.log(1e-2))] * len(bends), rel=0.01)
    # every rejected corner is where the report says: that image, that corner, that sample
    data = read_measurements(px / "px.json")
    where = {
        (str(im), int(pid)): int(s)
        for g in data.groups("pixels")
        for im, pid, s in zip(g.image, g.point_id, g.sample, strict=True)
    }
    assert any(row.kind == "pixels" for row in rejected)
    for row in rejected:
        if row.kind != "pixels":
            assert row.where is None
            continue
        _, label, _, corner = row.where.split()
        assert where[(label, int(corner))] == row.sample, row
    assert (out + err).count("observations lie beyond the") == 1
    # the hint names its evidence: the refit with the intrinsics refined lowers the
    # pixel noise (8 % on fx, fy: several px at the image border)
    hint = re.search(
        r"refining the camera intrinsics \((\d+) parameters\) lowers the pixel noise "
        r"from ([\d.]+) to ([\d.]+) px and moves (\w+) by [\d.]+ mm / [\d.]+ deg: "
        r"the intrinsics are probably wrong",
        err,
    )
    assert hint, err
    # 9 intrinsics per camera; refined, the noise is the simulated 0.5 px
    assert int(hint[1]) == 18 and float(hint[2]) > 1.3 * float(hint[3]), hint[0]
    assert hint[4] in {"left_camera_joint", "right_camera_joint", "world_to_base"}, hint[0]
    assert abs(float(hint[3]) - 0.5) < 0.05, hint[0]
    assert read_report(px / "w.json").notes[-1].startswith("the image points' residuals")
    code, out, err = _run([*argv, "--camera", f"left_camera={px / 'right.json'}"], capsys)
    assert code == 0, err
    assert "intrinsics" not in out + err


@pytest.mark.slow
def test_exact_intrinsics_stay_silent_when_the_pixel_noise_is_large(tmp_path):
    """1.5 px corner noise with the true intrinsics: the residuals are large enough to
    check the intrinsics (the refit with them refined runs), and the check, a chi-square
    test of the drop, finds nothing: no warning, no note."""
    from kinfw import calibrate, load_robot, read_measurements

    argv = ["-q", "simulate", "--pixels", "--pixel-sigma", "1.5", "--seed", "4"]
    argv += ["--error-mm", "0", "--error-deg", "0"]  # the nominal is true: frames is exact
    argv += ["--stage", "2", "--stage2-samples", "20", "--out", str(tmp_path / "px.json")]
    assert main([*argv, "--truth-out", str(tmp_path / "true.urdf")]) == 0
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        result = calibrate(
            load_robot(HEAD), read_measurements(tmp_path / "px.json"), parameters="frames"
        )
    evidence = result.intrinsics
    assert evidence is not None and evidence.sigma_px > 1.0  # checked
    assert abs(evidence.sigma_px - 1.5) < 0.2 and abs(evidence.refined_sigma_px - 1.5) < 0.2
    assert not evidence.significant, evidence
    assert not any("intrinsics" in n for n in result.report.notes)
    assert not any("intrinsics" in str(w.message) for w in said)


@pytest.mark.slow
def test_model_choice_on_few_images_scores_them_in_pixels_or_asks_for_params(px_only, capsys):
    """Three configurations seen by both cameras (< 10 residual rows per parameter): the
    automatic choice scores held-out image points in px like any kind (no special case;
    the closed-form leave-one-out needs no refit from two images, which could not place
    the cameras) and calibrates with the chosen fit: the same URDF as asking for that set
    and prior. Two images are too few to cross-validate: it says so and asks for
    --params."""
    from kinfw.measurements import read_measurements, write_measurements
    from kinfw.model import load_robot
    from kinfw.verification.evaluation import ROWS_PER_PARAMETER, rows_per_parameter

    data = read_measurements(px_only)
    left, right = ({int(s) for s in g.sample} for g in data.groups("pixels"))
    both = sorted(left & right)
    small_data = data.subset(np.array(both[:3]))
    assert rows_per_parameter(load_robot(HEAD), small_data) < ROWS_PER_PARAMETER
    small = px_only.with_name("small.json")
    write_measurements(small, small_data)
    auto = px_only.with_name("auto.urdf")
    code, out, err = _run(["calibrate", small, "--urdf", HEAD, "--out", auto], capsys)
    assert code == 0, err
    assert "leave-one-out held-out error of each candidate" in out and "px" in out
    (line,) = [x for x in out.splitlines() if x.endswith("<- chosen")]
    note = next(x for x in out.splitlines() if x.startswith("note: parameters: "))
    label = note.removeprefix("note: parameters: ").split(" (")[0]
    model = read_sidecar(sidecar_path(auto)).model
    given = ["--params", model.parameters[0]]
    if model.prior is not None:  # chosen by group: the table names it so
        given += model.prior.options.split()
        label = "full, prior by group" if model.prior.how != "given" else label
    assert line.startswith(f"  {label} ")
    forced = px_only.with_name("forced.urdf")
    code, _, err = _run(["calibrate", small, "--urdf", HEAD, "--out", forced, *given], capsys)
    assert code == 0, err
    if "prior" not in label:  # a printed prior is rounded to 3 digits
        assert forced.read_text() == auto.read_text()
    two = px_only.with_name("two.json")
    write_measurements(two, data.subset(np.array(both[:2])))
    argv = ["calibrate", two, "--urdf", HEAD, "--out", px_only.with_name("t.urdf")]
    code, _, err = _run(argv, capsys)
    assert code != 0 and "at least 3 samples for cross-validation" in err
    assert "give --params" in err
