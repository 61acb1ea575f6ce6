"""The ``pixels`` observation kind: file edge, residual vs OpenCV, exact recovery."""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinfw.camera import CameraIntrinsics
from kinfw.geometry import inverse_transform, transform_from_rotation_translation
from kinfw.identification import refine
from kinfw.identification.problem import NoiseModel, build_problem
from kinfw.measurements import measurements_from_dict, read_measurements, write_measurements
from kinfw.model import BlockKey, load_robot
from kinfw.observations import (
    DatasetError,
    NumericContext,
    PixelObservations,
    kind_of,
    pnp_camera_T_targets,
)
from kinfw.simulation import perturb_robot, simulate_at
from kinfw.verification.evaluation import pose_discrepancy
from tests.robots import ARM_6R

NAMES = ("j1", "j2", "j3", "j4", "j5", "j6")
Q0 = np.array([0.3, -0.4, 0.9, 0.2, 0.7, -0.3])
CAMERA = CameraIntrinsics(
    640, 480, 510.0, 505.0, 322.5, 236.0, k1=-0.12, k2=0.05, p1=1e-3, p2=-5e-4, k3=-0.01,
    name="flange_cam",
)  # fmt: skip
BOARD_P = np.array(
    [[0.03 * i - 0.105, 0.03 * j - 0.06, 0.0] for j in range(5) for i in range(8)]
)  # 8 x 5 corners of a board, 30 mm squares, in the board's frame


def _board_pose(robot) -> np.ndarray:
    """The board 0.6 m in front of the flange camera at Q0, facing it, a little tilted."""
    w_T_c = robot.frame_poses(Q0[None], "flange", NAMES)[0]
    tilt = transform_from_rotation_translation(
        np.array([[1, 0, 0], [0, np.cos(0.3), -np.sin(0.3)], [0, np.sin(0.3), np.cos(0.3)]]),
        [0.02, -0.01, 0.6],
    )
    return w_T_c @ tilt


def _in_view(robot, w_T_board, qs, board=BOARD_P):
    """The configurations whose camera sees every board point (in the image, 20 px in)."""
    c_T_b = inverse_transform(robot.frame_poses(qs, "flange", NAMES)) @ w_T_board
    c_p = np.einsum("nij,kj->nki", c_T_b[:, :3, :3], board) + c_T_b[:, None, :3, 3]
    return qs[CAMERA.in_view(c_p, margin_px=20).all(axis=1)]


def _template(n: int, board=BOARD_P, intrinsics=CAMERA) -> PixelObservations:
    k = len(board)
    return PixelObservations(
        camera="flange",
        intrinsics=intrinsics,
        sample=np.repeat(np.arange(n), k),
        uv=np.zeros((n * k, 2)),
        target_p=np.tile(board, (n, 1)),
        point_id=np.tile(np.arange(k), n),
        shot=np.zeros(n * k, dtype=np.int64),
        image=np.array([f"img_{i:03d}.png" for i in range(n) for _ in range(k)], dtype=object),
        sigma_px=np.full(n * k, np.nan),
        target="board",
    )


def _scene(n: int, seed: int, spread: float = 0.35, sigma_px: float = 0.0, board=BOARD_P):
    nominal = load_robot(ARM_6R)
    rng = np.random.default_rng(seed)
    truth = load_robot(perturb_robot(nominal, rng))
    w_T_board = _board_pose(truth)
    qs = Q0 + rng.uniform(-spread, spread, size=(20 * n, 6))
    qs = _in_view(truth, w_T_board, qs, board)[:n]
    assert len(qs) == n
    data = simulate_at(
        truth,
        qs,
        NAMES,
        groups=[_template(n, board)],
        unknowns={BlockKey("target", "board"): w_T_board},
        rng=rng,
        sigmas={"pixel": sigma_px},
    )
    return nominal, truth, w_T_board, data


# -- the file edge -----------------------------------------------------------------------


def _doc(observation: dict, cameras: dict | None = None) -> dict:
    return {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "mm", "angle": "rad"},
        "joint_names": list(NAMES),
        "cameras": {"flange": CAMERA.to_dict()} if cameras is None else cameras,
        "samples": [{"q": Q0.tolist(), "observations": [observation]}],
    }


GOOD = {
    "frame": "flange",
    "kind": "pixels",
    "target": "board",
    "image": "img_0003.png",
    "uv": [[10.0, 20.0], [30.5, 20.0], [30.0, 40.0], [10.0, 41.0]],
    "points": [[0, 0, 0], [30, 0, 0], [30, 30, 0], [0, 30, 0]],
    "ids": [0, 1, 2, 3],
    "sigma_px": 0.5,
}


def test_a_file_with_pixels_round_trips_exactly(tmp_path):
    _, _, _, data = _scene(6, seed=1, sigma_px=0.3)
    data = data.with_cameras({"unused_camera": CAMERA})  # kept though nothing uses it
    path = tmp_path / "px.json"
    write_measurements(path, data)
    doc = json.loads(path.read_text())
    assert set(doc["cameras"]) == {"flange", "unused_camera"}
    assert len(doc["samples"][0]["observations"]) == 1  # one dict per image
    assert doc["samples"][2]["observations"][0]["image"] == "img_002.png"
    back = read_measurements(path)
    (g0,), (g1,) = data.groups("pixels"), back.groups("pixels")
    for f in ("sample", "uv", "target_p", "point_id", "shot", "image"):
        np.testing.assert_array_equal(getattr(g1, f), getattr(g0, f))
    assert g1.intrinsics == CAMERA and back.cameras["unused_camera"] == CAMERA
    # write -> read -> write is the same text; a subset keeps images whole
    write_measurements(tmp_path / "again.json", back)
    assert (tmp_path / "again.json").read_text() == path.read_text()
    sub = back.subset([4, 1, 1])
    (gs,) = sub.groups("pixels")
    assert len(gs.sample) == 3 * len(BOARD_P) and sub.n_samples == 3
    np.testing.assert_array_equal(gs.uv[: len(BOARD_P)], g0.uv[g0.sample == 4])


def test_hand_written_pixels_are_read_in_the_files_length_unit():
    m = measurements_from_dict(_doc(GOOD), "f.json")
    (g,) = m.groups("pixels")
    np.testing.assert_array_equal(g.target_p[1], [0.03, 0.0, 0.0])  # mm -> m
    np.testing.assert_array_equal(g.uv[1], [30.5, 20.0])
    assert list(g.image) == ["img_0003.png"] * 4 and (g.sigma_px == 0.5).all()
    np.testing.assert_array_equal(g.point_id, [0, 1, 2, 3])


@pytest.mark.parametrize(
    ("change", "cameras", "message"),
    [
        (
            {"uv": GOOD["uv"][:3], "points": GOOD["points"][:3]},
            None,
            r"observations\[0\]\.uv: expected at least 4 points",
        ),
        ({"points": GOOD["points"][:3]}, None, r"\.points: expected 4 points \(one per uv"),
        ({"uv": [[1.0, 2.0, 3.0]] * 4}, None, r"\.uv\[0\]: expected 2 numbers"),
        ({"uv": [[1.0, float("nan")]] * 4}, None, r"\.uv\[0\]\[1\]: expected a finite number"),
        ({"ids": [0, 1, 1, 2]}, None, r"\.ids: ids must be distinct"),
        ({"sigma_px": -1}, None, r"\.sigma_px: expected a positive number"),
        ({}, {}, r"f\.json: samples\[0\]\.observations\[0\]\.frame: camera 'flange' has no "),
        ({}, {"flange": {"width": 640}}, r"f\.json: cameras\.flange: missing 'height'"),
    ],
)
def test_bad_pixel_observations_are_named(change, cameras, message):
    with pytest.raises(DatasetError, match=message):
        measurements_from_dict(_doc({**GOOD, **change}, cameras), "f.json")


def test_cameras_given_to_the_reader_override_the_files():
    other = CameraIntrinsics(320, 240, 250.0, 250.0, 160.0, 120.0, name="other")
    m = measurements_from_dict(_doc(GOOD, {}), "f.json", cameras={"flange": other})
    assert m.groups("pixels")[0].intrinsics == other
    m2 = measurements_from_dict(_doc(GOOD), "f.json").with_cameras({"flange": other})
    assert m2.groups("pixels")[0].intrinsics == other and m2.cameras["flange"] == other


# -- the prediction against OpenCV -------------------------------------------------------


def test_casadi_residual_numpy_prediction_and_cv2_project_points_agree():
    import cv2

    _, truth, w_T_board, data = _scene(5, seed=2)
    (g,) = data.groups("pixels")
    kind = kind_of(g)
    ctx = NumericContext.from_robot(truth, data.qs, NAMES, {BlockKey("target", "board"): w_T_board})
    predicted = kind.predict(g, ctx)[:, :2]
    # independent truth: OpenCV's projection of the board at the camera's true pose
    c_T_b = inverse_transform(truth.frame_poses(data.qs, "flange", NAMES)) @ w_T_board
    for i in range(data.n_samples):
        rvec, _ = cv2.Rodrigues(c_T_b[i, :3, :3])
        uv, _ = cv2.projectPoints(BOARD_P, rvec, c_T_b[i, :3, 3], CAMERA.matrix, CAMERA.distortion)
        np.testing.assert_allclose(predicted[g.sample == i], uv.reshape(-1, 2), atol=1e-9)
    # the board is in the image, in front of the camera
    assert (predicted > 0).all() and (predicted[:, 0] < 640).all() and (predicted[:, 1] < 480).all()
    # the CasADi residual at the truth is zero on the simulated (noise-free) pixels
    problem = build_problem(truth, data, targets={"board": w_T_board})
    ((r, _),) = problem.raw_residuals(np.zeros(problem.n_parameters), with_jacobian=False)
    assert np.abs(r).max() < 1e-9
    # and equals measured - predicted when the pixels are moved
    moved = kind.with_data(g, kind.data(g) + np.array([0.7, -1.1, 0, 0, 0, 0]))
    problem = build_problem(truth, data.with_groups([moved]), targets={"board": w_T_board})
    ((r, _),) = problem.raw_residuals(np.zeros(problem.n_parameters), with_jacobian=False)
    np.testing.assert_allclose(r, np.tile([0.7, -1.1], (len(g.sample), 1)), atol=1e-9)


def test_pnp_gives_each_images_board_pose():
    _, truth, w_T_board, data = _scene(5, seed=3)
    (g,) = data.groups("pixels")
    samples, c_T_b = pnp_camera_T_targets(g)
    true = inverse_transform(truth.frame_poses(data.qs[samples], "flange", NAMES)) @ w_T_board
    dp, dr = pose_discrepancy(c_T_b, true)
    assert dp < 1e-9 and dr < 1e-9


# -- exact recovery ----------------------------------------------------------------------


@pytest.mark.slow
def test_noise_free_pixels_recover_a_perturbed_arm_exactly():
    nominal, truth, w_T_board, data = _scene(40, seed=4)
    result = refine(nominal, data, noise=NoiseModel(sigmas={"pixel": 0.1}))
    assert result.converged
    (res,) = result.residuals
    assert np.abs(res.component("pixel")).max() < 1e-7
    found = {(u.kind, u.name): u.value for u in result.unknowns}
    # held out: the board in the camera at other configurations, as the truth has it
    q_test = Q0 + np.random.default_rng(40).uniform(-0.35, 0.35, size=(50, 6))  # any
    model_q = q_test[:, [NAMES.index(j) for j in result.model.topology.joint_names]]
    c_T_b = (
        inverse_transform(result.model.frame_poses(model_q, "flange")) @ found[("target", "board")]
    )
    true = inverse_transform(truth.frame_poses(q_test, "flange", NAMES)) @ w_T_board
    dp, dr = pose_discrepancy(c_T_b, true)
    assert dp < 1e-9 and dr < 1e-9
    start = inverse_transform(nominal.frame_poses(q_test, "flange", NAMES)) @ w_T_board
    assert pose_discrepancy(start, true)[0] > 1e-3  # the nominal was off


# -- the command line ----------------------------------------------------------------------


@pytest.mark.slow
def test_kinfw_calibrate_on_pixels_with_camera_option_recovers_the_arm(tmp_path, capsys):
    from kinfw.cli._main import main
    from kinfw.records import read_sidecar

    _, truth, w_T_board, data = _scene(30, seed=6)
    write_measurements(tmp_path / "px.json", data)
    doc = json.loads((tmp_path / "px.json").read_text())
    del doc["cameras"]  # the intrinsics come from --camera
    (tmp_path / "nocam.json").write_text(json.dumps(doc))
    (tmp_path / "cam.json").write_text(json.dumps(CAMERA.to_dict()))
    (tmp_path / "arm.urdf").write_text(ARM_6R)
    args = ["calibrate", str(tmp_path / "nocam.json"), "--urdf", str(tmp_path / "arm.urdf")]
    args += ["--out", str(tmp_path / "cal.urdf"), "--params", "full", "--loss", "linear"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "kinfw calibrate: error: " in err and "camera 'flange' has no intrinsics" in err
    camera = ["--camera", f"flange={tmp_path / 'cam.json'}"]
    assert main([*args, *camera, "--sigma-mm", "1", "--sigma-deg", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "no sigma for component 'pixel'" in err and "--sigma-px" in err
    assert main([*args, *camera, "--sigma-px", "0.5"]) == 0
    assert "0.5 px (given)" in capsys.readouterr().out
    assert main([*args, *camera]) == 0
    out = capsys.readouterr().out
    assert "px (estimated)" in out
    calibrated = load_robot(tmp_path / "cal.urdf")
    w_T_b = read_sidecar(tmp_path / "cal.kinfw.json").known_frames()[("target", "board")]
    q_test = Q0 + np.random.default_rng(60).uniform(-0.35, 0.35, size=(50, 6))
    c_T_b = inverse_transform(calibrated.frame_poses(q_test, "flange", NAMES)) @ w_T_b
    true = inverse_transform(truth.frame_poses(q_test, "flange", NAMES)) @ w_T_board
    dp, dr = pose_discrepancy(c_T_b, true)
    assert dp < 1e-8 and dr < 1e-8


# -- intrinsics as a parameter block -------------------------------------------------------


@pytest.mark.slow
def test_freed_intrinsics_are_recovered_from_a_wrong_start_with_the_arm():
    nominal, truth, w_T_board, data = _scene(40, seed=7)
    wrong = CAMERA.with_parameters(
        CAMERA.parameters * [1.02, 1, 1, 1, 1, 1, 1, 1, 1] + [0, 0, 0, 0, 0.03, 0, 0, 0, 0]
    )
    data = data.with_cameras({"flange": wrong})  # the pixels were simulated with CAMERA
    noise = NoiseModel(sigmas={"pixel": 0.1})
    fixed = refine(nominal, data, noise=noise)
    assert np.abs(fixed.residuals[0].component("pixel")).max() > 0.1  # the wrong K shows
    result = refine(nominal, data, noise=noise, refine_intrinsics=("flange",))
    (res,) = result.residuals
    assert np.abs(res.component("pixel")).max() < 1e-7
    found = {(u.kind, u.name): u.value for u in result.unknowns}
    ident = result.identifiability
    # no null direction of the Jacobian involves them (the rank test); their
    # uncertainty under 0.1 px noise is a separate verdict (next test)
    names = [
        ":".join(p)
        for params, why in ident.unidentifiable
        if not why.startswith("the images do not determine")
        for p in params
    ]
    assert not any(n.startswith("intrinsics:") for n in names)
    np.testing.assert_allclose(
        found[("intrinsics", "flange")], CAMERA.parameters, rtol=0, atol=1e-7
    )
    q_test = Q0 + np.random.default_rng(70).uniform(-0.35, 0.35, size=(50, 6))
    model_q = q_test[:, [NAMES.index(j) for j in result.model.topology.joint_names]]
    c_T_b = (
        inverse_transform(result.model.frame_poses(model_q, "flange")) @ found[("target", "board")]
    )
    true = inverse_transform(truth.frame_poses(q_test, "flange", NAMES)) @ w_T_board
    dp, dr = pose_discrepancy(c_T_b, true)
    assert dp < 1e-9 and dr < 1e-9


def test_refine_intrinsics_of_a_camera_without_pixels_is_named():
    nominal, _, _, data = _scene(8, seed=8)
    with pytest.raises(DatasetError, match="no 'pixels' observations of camera 'left'"):
        refine(nominal, data, refine_intrinsics=("left",))


@pytest.mark.slow
def test_intrinsics_the_images_cannot_determine_are_reported():
    # a small board (9 mm squares) that stays near the image centre: the distortion's
    # high orders act only far from the centre, where no point is seen
    nominal, _, _, data = _scene(40, seed=9, spread=0.05, sigma_px=0.3, board=0.3 * BOARD_P)
    radius = np.linalg.norm(data.groups("pixels")[0].uv - [CAMERA.cx, CAMERA.cy], axis=1)
    assert radius.max() < 120  # of a 400 px half-diagonal
    noise = NoiseModel(sigmas={"pixel": 0.3})
    result = refine(nominal, data, noise=noise, loss="linear", refine_intrinsics=True)
    poor = {
        params[0][1]: why
        for params, why in result.identifiability.unidentifiable
        if params[0][0] == "intrinsics:flange"
    }
    assert {"k2", "k3"} <= set(poor) and "the images do not determine it" in poor["k3"]
    # the same uncertainty from the covariance: k3's std times its effect at the border
    names = [tuple(n) for n in result.parameter_names]
    k3_std = np.sqrt(
        result.covariance[names.index(("intrinsics:flange", "k3"))][
            names.index(("intrinsics:flange", "k3"))
        ]
    )
    assert f"{k3_std:.3g} unitless" in poor["k3"]


# -- reports in pixels ---------------------------------------------------------------------


@pytest.mark.slow
def test_the_report_gives_reprojection_rms_per_camera_and_image_and_names_the_worst(tmp_path):
    import cv2

    from kinfw.records import read_report, write_report
    from kinfw.verification.reporting import calibrate_and_report

    nominal, _, _, data = _scene(30, seed=10, sigma_px=0.2)
    (g,) = data.groups("pixels")
    bad = g.sample == 17  # one image off by 3 px (a wrong detection), still below rejection
    data = data.with_groups([kind_of(g).with_data(g, kind_of(g).data(g) + 3.0 * bad[:, None])])
    with pytest.warns(UserWarning, match="pixel residuals of pixels 'flange' follow"):
        result = calibrate_and_report(nominal, data, loss="linear", parameters="full")
    report, calibration = result.write(tmp_path / "cal.urdf"), result.calibration
    rep = report.reprojection
    assert rep.worst[0].sample == 17 and rep.worst[0].image == "img_017.png"
    assert rep.worst[0].rms_px > 2.0 and rep.worst[1].rms_px < 0.5 * rep.worst[0].rms_px
    # independent truth: OpenCV's projection at the calibrated camera poses
    calibrated = load_robot(tmp_path / "cal.urdf")
    found = {(u.kind, u.name): u.value for u in calibration.refined.unknowns}
    c_T_b = (
        inverse_transform(calibrated.frame_poses(data.qs, "flange", NAMES))
        @ found[("target", "board")]
    )
    errs = []
    for i in range(data.n_samples):
        rvec, _ = cv2.Rodrigues(c_T_b[i, :3, :3])
        uv, _ = cv2.projectPoints(BOARD_P, rvec, c_T_b[i, :3, 3], CAMERA.matrix, CAMERA.distortion)
        e = np.linalg.norm(data.groups("pixels")[0].uv[g.sample == i] - uv.reshape(-1, 2), axis=1)
        errs.append(e)
        image = next(im for im in rep.images if im.sample == i)
        assert image.rms_px == pytest.approx(np.sqrt(np.mean(e**2)), rel=1e-6)
    (cam,) = rep.cameras
    all_e = np.concatenate(errs)
    assert cam.camera == "flange" and cam.n_images == 30 and cam.n_points == len(all_e)
    assert cam.rms_px == pytest.approx(np.sqrt(np.mean(all_e**2)), rel=1e-6)
    # the stage table is in px for image points (after the refinement: the calibrated
    # target pose, the reprojection section's); the file reads back
    (after,) = report.errors_after
    assert after.rms("pixel") == pytest.approx(cam.rms_px, rel=1e-9)
    ((group, value),) = report.rms_by_stage[-1].rms
    assert (group, value.key, value.value) == (
        "flange (pixels)",
        "pixel_rms_px",
        after.rms("pixel"),
    )
    write_report(tmp_path / "report.json", report)
    back = read_report(tmp_path / "report.json")
    assert back.reprojection == rep and back.errors_after[0].rms("pixel") == after.rms("pixel")


def test_the_drawing_puts_the_board_points_where_the_truth_has_them():
    _, truth, w_T_board, data = _scene(3, seed=11)
    (g,) = data.groups("pixels")
    kind = kind_of(g)
    moved = kind.with_data(g, kind.data(g) + np.array([2.0, 0.0, 0, 0, 0, 0]))
    ctx = NumericContext.from_robot(truth, data.qs, NAMES, {BlockKey("target", "board"): w_T_board})
    w_p_board = np.tile(BOARD_P @ w_T_board[:3, :3].T + w_T_board[:3, 3], (3, 1))
    exact = kind.drawing(g, ctx)
    np.testing.assert_allclose(exact.w_p_predicted, w_p_board, atol=1e-12)
    np.testing.assert_allclose(exact.w_p_measured, w_p_board, atol=1e-9)
    # 2 px off in u: the measured ray at the point's depth z is about 2 z / fx away
    # (distortion changes the scale by a few per cent)
    drawn = kind.drawing(moved, ctx)
    gap = np.linalg.norm(drawn.w_p_measured - drawn.w_p_predicted, axis=1)
    z = kind.camera_points(g, ctx)[:, 2]
    np.testing.assert_allclose(gap, 2.0 * z / CAMERA.fx, rtol=0.2)


def test_images_group_rows_as_a_scan_of_each_image_does():
    """The rows of each image (stable sort by image) against a hand-written scan."""
    _, _, _, data = _scene(6, seed=8)
    (g,) = data.groups("pixels")
    rng = np.random.default_rng(8)
    order = rng.permutation(len(g.sample))  # the images' rows interleaved
    shuffled = kind_of(g).take(g, order, g.sample[order])
    samples, rows = shuffled.images()
    keys = list(zip(shuffled.sample.tolist(), shuffled.shot.tolist(), strict=True))
    first_seen = list(dict.fromkeys(keys))
    assert samples.tolist() == [s for s, _ in first_seen]
    for key, r in zip(first_seen, rows, strict=True):
        assert r.tolist() == [i for i, k in enumerate(keys) if k == key]


def test_pnp_poses_are_kept_and_found_again_unchanged(monkeypatch):
    import kinfw.observations._pnp as pnp_module

    _, _, _, data = _scene(5, seed=3)
    (g,) = data.groups("pixels")
    monkeypatch.setattr(pnp_module, "_PNP_CACHE", type(pnp_module._PNP_CACHE)())
    samples, fresh = pnp_camera_T_targets(g)
    assert len(pnp_module._PNP_CACHE) == len(samples)
    calls = []
    monkeypatch.setattr(pnp_module, "_is_planar", lambda p: calls.append(p) or True)
    again_samples, again = pnp_camera_T_targets(g)  # every image found in the cache
    assert calls == []
    np.testing.assert_array_equal(again_samples, samples)
    np.testing.assert_array_equal(again, fresh)
