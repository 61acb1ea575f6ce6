"""``kinfw simulate`` for every kind (issue 24 item 5): motion-capture markers in an
unknown frame, plane contacts and rendered board images, each checked against Pinocchio
forward kinematics of the written true URDF, then calibrated from the written file:
``simulate -> calibrate -> verify`` on held-out samples of the same truth, and
``simulate --images -> detect -> calibrate`` end to end."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from kinfw.cli._main import main
from kinfw.measurements import read_measurements, write_measurements
from kinfw.model import load_robot
from kinfw.simulation import random_configurations
from tests.paths import HEAD_URDF
from tests.pin_se3 import angle, inverse, pin_fk
from tests.robots import ARM_6R


def _kinfw(argv: list) -> tuple[int, str, str]:
    """``(exit code, stdout, stderr)`` of ``kinfw ARGV`` run in this process (usable in
    module fixtures, where ``capsys`` is not)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def _simulate(root: Path, argv: list) -> dict:
    """Run ``kinfw simulate ARGV --json`` (noise-free, into ``root``): its summary."""
    argv = ["simulate", *argv, "--noise-mm", "0", "--noise-deg", "0", "--json"]
    code, out, err = _kinfw([*argv, "--out", root / "data.json", "--truth-out", root / "true.urdf"])
    assert code == 0, err
    return json.loads(out)


def _holdout(root: Path) -> tuple[Path, Path]:
    """Split ``data.json``: every third sample is held out (``test.json``), the others
    calibrate (``train.json``)."""
    data = read_measurements(root / "data.json")
    train, test = root / "train.json", root / "test.json"
    held_out = np.arange(data.n_samples) % 3 == 0
    write_measurements(train, data.subset(np.flatnonzero(~held_out)))
    write_measurements(test, data.subset(np.flatnonzero(held_out)))
    return train, test


def _calibrate_and_verify(root: Path, urdf: Path) -> dict:
    """``calibrate train.json`` then ``verify`` the calibrated URDF (with its sidecar's
    mocap frame, offsets, plane) on ``test.json``: verify's JSON."""
    train, test = _holdout(root)
    argv = ["-q", "calibrate", train, "--urdf", urdf, "--out", root / "cal.urdf"]
    code, out, err = _kinfw(argv)
    assert code == 0, err
    code, out, err = _kinfw(["-q", "verify", root / "cal.urdf", test, "--json"])
    assert code == 0, err
    doc = json.loads(out)
    assert not doc["fitted"]  # every nuisance (frame, offsets, plane) from the calibration
    return doc


@pytest.fixture(scope="module")
def arm6(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("arm6") / "arm6.urdf"
    path.write_text(ARM_6R)
    return path


# -- markers -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def mocap(arm6, tmp_path_factory):
    """60 noise-free samples of two markers (one of random offset on the flange, one
    given on l4) measured in the external frame 'vicon'."""
    root = tmp_path_factory.mktemp("mocap")
    argv = ["--urdf", arm6, "--markers", "flange", "--markers", "l4:0.02,0.03,0"]
    argv += ["--mocap-frame", "vicon", "--mocap-samples", "60", "--seed", "4"]
    return root, _simulate(root, argv)


def test_markers_are_fk_plus_offset_in_the_mocap_frame(mocap):
    """Each written point is ``vicon_T_root @ root_T_frame(q) @ offset`` with the true
    URDF's Pinocchio FK and the summary's true pose and offsets; offsets are not in
    the file (unknown to the calibration), the frame is 'vicon' (not in the URDF)."""
    root, summary = mocap
    truth = (root / "true.urdf").read_text()
    data = read_measurements(root / "data.json")
    vicon_T_root = np.array(summary["mocap_T_root"])
    assert summary["mocap_frame"] == "vicon" and angle(vicon_T_root[:3, :3]) > 0.1
    markers = {m["name"]: m for m in summary["markers"]}
    assert markers["marker2"]["offset_m"] == [0.02, 0.03, 0.0]
    assert np.linalg.norm(markers["marker1"]["offset_m"]) == pytest.approx(0.05)
    groups = data.groups("point")
    assert len(groups) == 2
    for g in groups:
        assert g.measured_in == "vicon" and g.offset is None
        marker = markers[g.marker]
        assert marker["frame"] == g.frame
        root_T_frame = pin_fk(truth, data.joint_names, data.qs[g.sample], g.frame)
        expected = root_T_frame @ np.append(marker["offset_m"], 1.0)[:, None]
        expected = (vicon_T_root @ expected)[:, :3, 0]
        np.testing.assert_allclose(g.meas_p_point, expected, rtol=0, atol=1e-12)


@pytest.mark.slow
def test_markers_calibrate_to_the_truth_held_out(mocap, arm6):
    """Calibrated on 40 of the 60 noise-free samples, the URDF and its sidecar (vicon frame,
    marker offsets) predict the 20 held-out samples of the true robot to 1e-6 mm."""
    root, _ = mocap
    doc = _calibrate_and_verify(root, arm6)
    for g in doc["groups"]:
        assert g["kind"] == "point" and g["n"] == 20
        assert g["position_max_mm"] < 1e-6, g


def test_known_offsets_in_the_root_frame(arm6, tmp_path):
    """--offsets-known writes each offset (markers: ``offset``, no ``marker``; probes the
    same); --mocap-frame naming the URDF root measures the markers in it: the points are
    Pinocchio FK + offset, no frame to estimate; a --mocap-frame of another URDF link is
    refused (the tracker is external)."""
    argv = ["--urdf", arm6, "--markers", "flange:0.01,0.02,0.03", "--mocap-frame", "world"]
    argv += ["--contacts", "flange:0,0,0.1", "--offsets-known", "--seed", "9"]
    summary = _simulate(tmp_path, argv)
    assert summary["mocap_T_root"] is None and summary["mocap_frame"] is None
    data = read_measurements(tmp_path / "data.json")
    (points,) = data.groups("point")
    (contacts,) = data.groups("plane")
    assert points.marker is None and points.measured_in is None
    np.testing.assert_array_equal(points.offset, [0.01, 0.02, 0.03])
    assert contacts.marker is None
    np.testing.assert_array_equal(contacts.offset, [0.0, 0.0, 0.1])
    truth = (tmp_path / "true.urdf").read_text()
    root_T_flange = pin_fk(truth, data.joint_names, data.qs[points.sample], "flange")
    expected = (root_T_flange @ np.array([0.01, 0.02, 0.03, 1.0]))[:, :3]
    np.testing.assert_allclose(points.meas_p_point, expected, rtol=0, atol=1e-12)
    argv = ["--urdf", arm6, "--markers", "flange", "--mocap-frame", "l3"]
    code, _, err = _kinfw(
        ["simulate", *argv, "--out", tmp_path / "x.json", "--truth-out", tmp_path / "x.urdf"]
    )
    assert code == 2 and "'l3' is a frame of the URDF" in err, err


# -- plane contacts -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def contacts(arm6, tmp_path_factory):
    """Two probes (the flange's at a random offset, one given on l5) touching a tilted
    plane, 45 noise-free contacts each."""
    root = tmp_path_factory.mktemp("contacts")
    argv = ["--urdf", arm6, "--contacts", "flange", "--contacts", "l5:0.03,0,0.08"]
    argv += ["--plane", "0.1,-0.2,1,0.5", "--contact-samples", "45", "--seed", "5"]
    return root, _simulate(root, argv)


def test_contacts_lie_on_the_plane(contacts):
    """Pinocchio FK of the true URDF puts every probe on the plane (n normalised from
    --plane) to 1e-9 m; the file's distances are 0 (noise-free) and the offsets unknown."""
    root, summary = contacts
    truth = (root / "true.urdf").read_text()
    data = read_measurements(root / "data.json")
    n = np.array([0.1, -0.2, 1.0])
    d = 0.5 / np.linalg.norm(n)
    n /= np.linalg.norm(n)
    np.testing.assert_allclose(summary["plane"], [*n, d], rtol=0, atol=1e-15)
    probes = {p["name"]: p for p in summary["probes"]}
    assert probes["probe2"]["offset_m"] == [0.03, 0.0, 0.08]
    groups = data.groups("plane")
    assert sorted(g.marker for g in groups) == ["probe1", "probe2"]
    for g in groups:
        assert g.offset is None and g.plane == "table" and len(g.sample) == 45
        np.testing.assert_array_equal(g.distance_m, 0.0)  # contacts, measured without noise
        root_T_frame = pin_fk(truth, data.joint_names, data.qs[g.sample], g.frame)
        probe = (root_T_frame @ np.append(probes[g.marker]["offset_m"], 1.0))[:, :3]
        np.testing.assert_allclose(probe @ n - d, 0.0, rtol=0, atol=1e-9)
        # contacts spread over the plane, not one configuration repeated
        assert np.ptp(probe, axis=0).max() > 0.1


@pytest.mark.slow
def test_contacts_calibrate_to_the_truth_held_out(contacts, arm6):
    """Calibrated on 60 of the 90 contacts, the 30 held-out contacts of the true robot are on
    the calibrated plane to 1e-6 mm (what contacts determine: distances from the plane;
    the world motion and scale they leave free change none)."""
    root, _ = contacts
    doc = _calibrate_and_verify(root, arm6)
    assert sorted(g["marker"] for g in doc["groups"]) == ["probe1", "probe2"]
    assert sum(g["n"] for g in doc["groups"]) == 30
    for g in doc["groups"]:
        assert g["kind"] == "plane" and g["height_max_mm"] < 1e-6, g


# -- ball and point contacts -----------------------------------------------------------------


@pytest.fixture(scope="module", params=["sphere", "point"])
def touching(request, arm6, tmp_path_factory):
    """A probe of random offset on the flange touching a ball (``--sphere``, radius 25 mm)
    or placed on a point (``--point``), 60 noise-free contacts."""
    root = tmp_path_factory.mktemp(request.param)
    where = "0.3,0.1,0.4,0.025" if request.param == "sphere" else "0.3,0.1,0.4"
    argv = ["--urdf", arm6, "--contacts", "flange", f"--{request.param}", where]
    argv += ["--contact-samples", "60", "--seed", "3"]
    return request.param, root, _simulate(root, argv)


@pytest.mark.slow
def test_ball_and_point_contacts_are_on_them_by_pinocchio(touching):
    """Pinocchio FK of the true URDF puts the probe on the ball (at the radius from the
    centre) or on the point, to 1e-9 m; the file gives the radius (a tooling ball's is
    known), not the centre nor the probe's offset."""
    which, root, summary = touching
    truth = (root / "true.urdf").read_text()
    data = read_measurements(root / "data.json")
    (probe,) = summary["probes"]
    kind = "sphere" if which == "sphere" else "divot"
    (g,) = data.groups(kind)
    assert g.offset is None and g.marker == "probe1" and len(g.sample) == 60
    root_T_frame = pin_fk(truth, data.joint_names, data.qs[g.sample], "flange")
    p = (root_T_frame @ np.append(probe["offset_m"], 1.0))[:, :3]
    if which == "sphere":
        assert summary["sphere"] == [0.3, 0.1, 0.4, 0.025] and g.radius == 0.025
        assert g.sphere == "ball"
        np.testing.assert_array_equal(g.distance_m, 0.0)
        np.testing.assert_allclose(
            np.linalg.norm(p - [0.3, 0.1, 0.4], axis=1), 0.025, rtol=0, atol=1e-9
        )
    else:
        assert summary["point"] == [0.3, 0.1, 0.4] and g.centre is None and g.divot == "divot"
        np.testing.assert_array_equal(g.gap_m, 0.0)
        np.testing.assert_allclose(p, np.tile([0.3, 0.1, 0.4], (60, 1)), rtol=0, atol=1e-9)


@pytest.mark.slow
def test_ball_and_point_contacts_calibrate_verify_and_crossvalidate(touching, arm6):
    """simulate -> calibrate (default options: the model choice) -> verify on 20
    held-out contacts of the true robot: on the calibrated ball to 1e-6 mm (point: placed
    on it); crossval: finite held-out RMS per fold in the kind's metric, the calibrated
    model's below 1e-6 mm where the nominal's is millimetres."""
    which, root, _ = touching
    doc = _calibrate_and_verify(root, arm6)
    (g,) = doc["groups"]
    metric = "height" if which == "sphere" else "placement"
    assert g["kind"] == ("sphere" if which == "sphere" else "divot") and g["n"] == 20
    assert g[f"{metric}_max_mm"] < 1e-6, g
    code, out, err = _kinfw(["-q", "crossval", root / "data.json", "--urdf", arm6, "--json"])
    assert code == 0, err
    cv = json.loads(out)
    rms = [f[f"{metric}_rms_mm"] for f in cv["folds"]]
    assert len(rms) == 20 and np.isfinite(rms).all()  # 5 folds x nominal, frames, full, default
    means = cv[f"mean_{metric}_rms_mm"]
    assert means["none"] > 1.0 and means["full"] < 1e-6 and means["auto"] < 1e-6, means


# -- rendered images ------------------------------------------------------------------------


def _render_and_detect(root: Path, board: str, n: int, seed: int) -> dict:
    """``simulate --images`` of the IIS-head's left camera (``n`` stage 2 images of
    ``board``) into ``root/img/left_camera/``, then ``kinfw detect`` of the PNGs into
    ``root/det.json``: the simulation's summary."""
    argv = ["--images", root / "img", "--cameras", "left_camera", "--stage", "2"]
    argv += ["--board", board, "--stage2-samples", str(n), "--seed", str(seed)]
    summary = _simulate(root, argv)
    cam = root / "img" / "left_camera"
    argv = ["-q", "detect", *sorted(cam.glob("*.png")), "--board", board]
    argv += ["--joints", cam / "joints.csv", "--camera", cam / "camera.json"]
    code, _, err = _kinfw([*argv, "--frame", "left_camera", "--out", root / "det.json"])
    assert code == 0, err
    return summary


def _corner_errors(root: Path, summary: dict, camera_frame: str = "left_camera") -> np.ndarray:
    """Per detected corner of ``root/det.json``: its distance (px) from the board's point
    at the board's true pose (on its ``target_frame`` moved by the truth, if any), seen
    through the true URDF (Pinocchio FK) and projected by ``cv2.projectPoints`` with the
    written intrinsics."""
    truth = (root / "true.urdf").read_text()
    camera = json.loads((root / "img" / camera_frame / "camera.json").read_text())
    K = np.array([[camera["fx"], 0, camera["cx"]], [0, camera["fy"], camera["cy"]], [0, 0, 1]])
    dist = np.array([camera[k] for k in ("k1", "k2", "p1", "p2", "k3")])
    root_T_board = np.array(summary["pixels"]["root_T_board"])
    on = summary["pixels"]["target_frame"]
    doc = json.loads((root / "det.json").read_text())
    errors = []
    for sample in doc["samples"]:
        (obs,) = sample["observations"]
        assert obs.get("target_frame") == on
        names, q = tuple(doc["joint_names"]), sample["q"]
        root_T_camera = pin_fk(truth, names, q, camera_frame)[0]
        w_T_board = root_T_board if on is None else pin_fk(truth, names, q, on)[0] @ root_T_board
        camera_T_board = inverse(root_T_camera) @ w_T_board
        rvec = cv2.Rodrigues(camera_T_board[:3, :3])[0]
        points = np.array(obs["points"], dtype=float)
        uv, _ = cv2.projectPoints(points, rvec, camera_T_board[:3, 3], K, dist)
        errors.append(np.linalg.norm(uv[:, 0] - np.array(obs["uv"]), axis=1))
    return np.concatenate(errors)


@pytest.fixture(scope="module")
def images(tmp_path_factory):
    """20 rendered images of the default chessboard, detected, then ``kinfw calibrate``
    of what ``kinfw detect`` found (``cal.urdf``)."""
    root = tmp_path_factory.mktemp("images")
    summary = _render_and_detect(root, "chessboard:9x6:0.04", 20, 6)
    argv = ["-q", "calibrate", root / "det.json", "--urdf", HEAD_URDF, "--out", root / "cal.urdf"]
    code, _, err = _kinfw(argv)
    assert code == 0, err
    return root, summary


@pytest.mark.slow
def test_rendered_chessboard_images_show_the_true_corners(images):
    """Every image is found whole (a chessboard is simulated only where all its corners
    are in view) and its corners are where the truth puts them (:func:`_corner_errors`):
    median below 0.1 px, none above 0.5 px (the renderer's anti-aliasing, 2 grey levels
    of noise and the detector's sub-pixel fit)."""
    root, summary = images
    errors = _corner_errors(root, summary)
    assert len(errors) == 20 * 54
    assert np.median(errors) < 0.1 and errors.max() < 0.5, (np.median(errors), errors.max())


@pytest.mark.slow
def test_rendered_charuco_images_show_the_true_corners(tmp_path):
    """A ChArUco board (the renderer draws every board ``kinfw detect`` reads): partial
    views, corners numbered by the board; the detected corners agree with the truth as
    the chessboard's do, and most images are found (ChArUco needs 6 corners)."""
    summary = _render_and_detect(tmp_path, "charuco:8x6:0.04:0.03", 8, 8)
    errors = _corner_errors(tmp_path, summary)
    found = len(json.loads((tmp_path / "det.json").read_text())["samples"])
    assert found >= 6 and len(errors) >= 6 * 6
    assert np.median(errors) < 0.1 and errors.max() < 0.5, (np.median(errors), errors.max())


@pytest.mark.slow
def test_images_detect_calibrate_recovers_the_camera_motion(images):
    """``simulate --images -> detect -> calibrate``: the calibrated URDF moves the left
    camera as the true one does. Compared on 30 random configurations (0.8 of the
    ranges) by the camera's motion from the first, ``inv(T(q_0)) T(q_i)`` (what images of
    a board of unknown pose determine; the root's pose relative to the board is not):
    within 0.5 mm and 0.05 deg of the truth (measured: 0.35 mm, 0.019 deg; the
    nominal is off by millimetres)."""
    root, _ = images
    names = ("x_table", "y_table", "pan", "tilt", "vergence_left")
    lower, upper = load_robot(HEAD_URDF).joint_limits(names)
    qs = random_configurations(lower, upper, 30, np.random.default_rng(7), fraction=0.8)

    def motions(xml: str) -> np.ndarray:
        T = pin_fk(xml, names, qs, "left_camera")
        return inverse(T[0]) @ T[1:]

    truth = motions((root / "true.urdf").read_text())
    for urdf, bound_mm, bound_deg in (("cal.urdf", 0.5, 0.05), (HEAD_URDF, None, None)):
        model = motions(Path(urdf if urdf == HEAD_URDF else root / urdf).read_text())
        mm = 1e3 * np.linalg.norm(model[:, :3, 3] - truth[:, :3, 3], axis=1).max()
        deg = max(
            np.degrees(angle(a[:3, :3].T @ b[:3, :3])) for a, b in zip(model, truth, strict=True)
        )
        if bound_mm is None:  # the nominal: the errors calibrated away are real
            assert mm > 1.0, mm
        else:
            assert mm < bound_mm and deg < bound_deg, (mm, deg)


@pytest.mark.slow
def test_a_stereo_pairs_folders_detect_into_one_file_and_calibrate_both_cameras(tmp_path):
    """``simulate --images`` of the IIS-head's two cameras (20 configurations, each seen
    by one camera or both) -> ``detect --images DIR:FRAME`` twice -> one file: one sample
    per configuration, an observation per camera that saw the board there, ``q`` the
    joints.csv row of each of its images. ``calibrate`` then moves both cameras as the
    truth does: each camera's motion from the first of 30 random configurations and the
    pair's ``left_T_right`` within 0.5 mm and 0.05 deg (measured 0.36 mm / 0.011 deg;
    the nominal is off by more than 10 mm)."""
    board = "chessboard:9x6:0.04"
    argv = ["--images", tmp_path / "img", "--cameras", "left_camera,right_camera"]
    _simulate(tmp_path, [*argv, "--stage", "2", "--board", board, "--stage2-samples", "20"])
    argv = ["-q", "detect", "--board", board, "--out", tmp_path / "det.json"]
    for camera in ("left_camera", "right_camera"):
        argv += ["--images", f"{tmp_path / 'img' / camera}:{camera}"]
    code, _, err = _kinfw(argv)
    assert code == 0, err
    doc = json.loads((tmp_path / "det.json").read_text())
    rows = {}
    for camera in ("left_camera", "right_camera"):
        lines = (tmp_path / "img" / camera / "joints.csv").read_text().splitlines()
        assert lines[0].split(",")[1:] == doc["joint_names"]
        rows |= {
            str(tmp_path / "img" / camera / line.split(",")[0]): [
                float(v) for v in line.split(",")[1:]
            ]
            for line in lines[1:]
        }
    assert len(doc["samples"]) == 20 and set(doc["cameras"]) == {"left_camera", "right_camera"}
    seen = [obs["image"] for sample in doc["samples"] for obs in sample["observations"]]
    assert sorted(seen) == sorted(rows)  # every image once
    for sample in doc["samples"]:
        frames = [obs["frame"] for obs in sample["observations"]]
        assert len(set(frames)) == len(frames)
        for obs in sample["observations"]:
            assert rows[obs["image"]] == sample["q"]
    assert max(len(sample["observations"]) for sample in doc["samples"]) == 2
    argv = ["-q", "calibrate", tmp_path / "det.json", "--urdf", HEAD_URDF]
    code, _, err = _kinfw([*argv, "--out", tmp_path / "cal.urdf"])
    assert code == 0, err
    names = tuple(doc["joint_names"])
    lower, upper = load_robot(HEAD_URDF).joint_limits(names)
    qs = random_configurations(lower, upper, 30, np.random.default_rng(7), fraction=0.8)

    def relative_poses(xml: str) -> list[np.ndarray]:
        left, right = (pin_fk(xml, names, qs, frame) for frame in ("left_camera", "right_camera"))
        return [inverse(left[0]) @ left[1:], inverse(right[0]) @ right[1:], inverse(left) @ right]

    truth = relative_poses((tmp_path / "true.urdf").read_text())
    for urdf in (tmp_path / "cal.urdf", HEAD_URDF):
        for model, true in zip(relative_poses(Path(urdf).read_text()), truth, strict=True):
            mm = 1e3 * np.linalg.norm(model[:, :3, 3] - true[:, :3, 3], axis=1).max()
            pairs = zip(model, true, strict=True)
            deg = max(np.degrees(angle(a[:3, :3].T @ b[:3, :3])) for a, b in pairs)
            if urdf == HEAD_URDF:
                assert mm > 10.0, mm
            else:
                assert mm < 0.5 and deg < 0.05, (mm, deg)


@pytest.mark.slow
def test_a_board_on_the_flange_seen_by_a_static_camera_is_rendered_where_the_truth_puts_it(
    tmp_path,
):
    """Eye-to-hand rehearsal: ``simulate --target-frame flange`` with a camera on a link
    fixed to the root (the 6R arm of ``test_cameras_anywhere``), 12 rendered images ->
    ``detect --target-frame flange``: every image found, each observation on 'flange',
    and the corners where the board on the true flange projects: median < 0.1 px, p95 <
    0.3 px, max < 1 px (measured: median 0.038 px, max 0.75 px; the flange turns it up to
    70 deg from the camera's axis, where the detector's sub-pixel fit is worse than on
    the head's world board)."""
    from tests.kinfw.observations.test_cameras_anywhere import setup_urdf

    urdf = tmp_path / "arm.urdf"
    urdf.write_text(setup_urdf("eye_to_hand"))
    board = "chessboard:9x6:0.04"
    argv = ["--urdf", urdf, "--images", tmp_path / "img", "--cameras", "camera_link"]
    argv += ["--target-frame", "flange", "--stage", "2", "--board", board, "--fraction", "0.5"]
    summary = _simulate(tmp_path, [*argv, "--stage2-samples", "12"])
    assert summary["pixels"]["target_frame"] == "flange"
    argv = ["-q", "detect", "--images", f"{tmp_path / 'img' / 'camera_link'}:camera_link"]
    argv += ["--board", board, "--target-frame", "flange", "--out", tmp_path / "det.json"]
    code, _, err = _kinfw(argv)
    assert code == 0, err
    errors = _corner_errors(tmp_path, summary, "camera_link")
    assert len(errors) == 12 * 54
    stats = np.median(errors), np.percentile(errors, 95), errors.max()
    assert stats[0] < 0.1 and stats[1] < 0.3 and stats[2] < 1.0, stats
