"""The meshcat view of a calibration: scene content, offline HTML, headless screenshot.

Scene tests draw into a recording window (DESIGN.md: ``meshcat.Visualizer(window=...)``
takes any object with ``send`` and ``get_scene``), so no server and no browser is
needed; expectations are recomputed from the URDFs with Pinocchio. The screenshot test
renders the demo's HTML in headless Chromium: without ``chromium`` on the PATH it skips,
unless ``KINFW_REQUIRE_BROWSER=1`` (set by ``.ci/run``, which installs Chromium) makes that
a failure.
"""

import contextlib
import io
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest

from kinfw.model import builtin_head_urdf, load_robot
from kinfw.simulation import perturb_robot, random_configurations, simulate_at
from kinfw.view import (
    GHOST_RGBA,
    SOLID_RGBA,
    TRIAD_LENGTH,
    OfflineWindow,
    residual_color,
    scene,
    targets_from_sidecar,
    write_html,
)
from tests.meshcat_scene import KINFW, RecordingWindow, scene_objects, scene_transforms

HEAD = builtin_head_urdf()
CHROMIUM_NAMES = ("chromium", "chromium-browser")  # Debian, Ubuntu
REQUIRE_BROWSER = "KINFW_REQUIRE_BROWSER"
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def _properties(commands, path):
    return {
        c["property"]: c["value"]
        for c in commands
        if c["type"] == "set_property" and c["path"] == path
    }


def _children(paths, prefix):
    """Names of the nodes directly below ``prefix``."""
    return {p[len(prefix) :].split("/")[0] for p in paths if p.startswith(prefix)}


def _pin_fk(urdf_xml, joint_names, q):
    """{frame name: oMf} of a URDF at joint values q, Pinocchio only."""
    model = pin.buildModelFromXML(urdf_xml)
    data = model.createData()
    config = pin.neutral(model)
    for name, value in zip(joint_names, q, strict=True):
        config[model.joints[model.getJointId(name)].idx_q] = value
    pin.framesForwardKinematics(model, data, config)
    return {f.name: data.oMf[i].homogeneous for i, f in enumerate(model.frames)}


def _pin_color(rgba):
    """Pinocchio's MeshcatVisualizer colour integer of an RGBA list."""
    return int(rgba[0] * 255) * 256**2 + int(rgba[1] * 255) * 256 + int(rgba[2] * 255)


@pytest.fixture(scope="module")
def head():
    return load_robot(HEAD)


@pytest.fixture(scope="module")
def head_up(head):
    # the head stands on its table: up is -x of the table frame "base" (the root link
    # "world" is the stereo rig: y down, z forward)
    return -head.frame_poses(np.zeros(len(head.joint_names)), "base")[:3, 0]


@pytest.fixture(scope="module")
def case(head):
    """A nominal head, a different 'calibrated' one, and noise-free data of a third."""
    rng = np.random.default_rng(7)
    truth = load_robot(perturb_robot(head, rng, origin_mm=5.0, origin_deg=1.0))
    calibrated = load_robot(perturb_robot(head, rng, origin_mm=3.0, origin_deg=0.5))
    names = head.joint_names
    lower, upper = head.joint_limits(names)
    qs = random_configurations(lower, upper, 3, rng, fraction=0.8)
    w_T_target = np.eye(4)
    w_T_target[:3, 3] = [0.6, 0.4, 1.2]
    w_T_target[:3, :3] = pin.rpy.rpyToMatrix(0.3, -2.5, 0.2)
    data = simulate_at(
        truth,
        qs,
        names,
        frames=head.default_frames,
        cameras=head.default_cameras,
        rng=rng,
        w_T_target=w_T_target,
    )
    return {"calibrated": calibrated, "data": data, "targets": [("target", w_T_target)]}


@pytest.fixture(scope="module")
def drawn(head, head_up, case):
    window = RecordingWindow()
    vis = scene(
        head,
        case["calibrated"],
        case["data"],
        sample=1,
        targets=case["targets"],
        window=window,
        residual_scale=25.0,
        up=head_up,
    )
    assert vis.window is window
    return window.commands


def test_both_models_are_drawn_under_their_root_names(head, case, drawn):
    objects = scene_objects(drawn)
    n_visuals = len(ET.fromstring(head.urdf_xml).findall("link/visual"))
    for root, robot, rgba in (
        ("nominal", head, GHOST_RGBA),
        ("calibrated", case["calibrated"], SOLID_RGBA),
    ):
        prefix = f"{KINFW}/{root}/visuals/"
        meshes = {p: o for p, o in objects.items() if p.startswith(prefix)}
        assert len(meshes) == n_visuals
        for obj in meshes.values():
            material = obj["materials"][0]
            assert material["color"] == _pin_color(rgba)
            assert material["opacity"] == pytest.approx(rgba[3])
            assert material["transparent"] == (rgba[3] < 1.0)
        # both at the configuration of sample 1: the left plate's board (the first
        # visual of link left_plate, at the link origin) sits where Pinocchio puts it
        q = case["data"].qs[1]
        oMf = _pin_fk(robot.urdf_xml, case["data"].joint_names, q)
        T = scene_transforms(drawn)[prefix + "left_plate_0"]
        np.testing.assert_allclose(T, oMf["left_plate"], atol=1e-12)
    ghost = next(o for p, o in objects.items() if p.startswith(f"{KINFW}/nominal/"))
    assert ghost["materials"][0]["opacity"] < 1.0
    # the two models really differ where the data is measured
    assert not np.allclose(
        scene_transforms(drawn)[f"{KINFW}/nominal/visuals/left_plate_0"],
        scene_transforms(drawn)[f"{KINFW}/calibrated/visuals/left_plate_0"],
        atol=1e-3,
    )


def test_one_triad_per_measured_pose_of_the_sample(case, drawn):
    data = case["data"]
    measured = {g.frame: g.meas_T_frame[np.flatnonzero(g.sample == 1)[0]] for g in data.poses}
    assert set(measured) == {"left_plate", "right_plate"}
    paths = {c["path"] for c in drawn}
    prefix = f"{KINFW}/measured/poses/"
    assert _children(paths, prefix) == set(measured)
    objects, transforms = scene_objects(drawn), scene_transforms(drawn)
    for frame, meas_T_frame in measured.items():
        np.testing.assert_allclose(transforms[prefix + frame], meas_T_frame, atol=1e-12)
        for axis, (name, color) in enumerate(
            zip("xyz", (0xFF0000, 0x00FF00, 0x0000FF), strict=True)
        ):
            stick = objects[f"{prefix}{frame}/{name}/stick"]
            assert stick["geometries"][0]["height"] == pytest.approx(TRIAD_LENGTH)
            assert stick["materials"][0]["color"] == color
            # the stick runs along the frame's axis
            node = transforms[f"{prefix}{frame}/{name}"]
            np.testing.assert_allclose(node[:3, 1], np.eye(3)[axis], atol=1e-12)
    # a triad where each camera saw the target, one triad per camera frame
    assert _children(paths, f"{KINFW}/measured/targets/") == {"left_camera", "right_camera"}
    assert _children(paths, f"{KINFW}/cameras/") == {"left_camera", "right_camera"}


def test_fixed_targets_are_a_flat_board_and_a_triad(case, drawn):
    ((name, root_T_target),) = case["targets"]
    node = f"{KINFW}/targets/{name}"
    np.testing.assert_allclose(scene_transforms(drawn)[node], root_T_target, atol=1e-12)
    board = scene_objects(drawn)[node + "/board"]["geometries"][0]
    assert board["type"] == "BoxGeometry"
    width, height, depth = board["width"], board["height"], board["depth"]
    assert depth < 0.1 * min(width, height)  # flat along the target's z
    assert {f"{node}/triad/{axis}/stick" for axis in "xyz"} <= set(scene_objects(drawn))


def test_residual_lines_are_the_scaled_prediction_errors(case, drawn):
    data, calibrated = case["data"], case["calibrated"]
    oMf = _pin_fk(calibrated.urdf_xml, data.joint_names, data.qs[1])
    objects, transforms = scene_objects(drawn), scene_transforms(drawn)
    errors = []
    for g in data.poses:
        root_p_measured = g.meas_T_frame[np.flatnonzero(g.sample == 1)[0], :3, 3]
        root_p_predicted = oMf[g.frame][:3, 3]
        node = transforms[f"{KINFW}/residuals/poses/{g.frame}"]
        length = objects[f"{KINFW}/residuals/poses/{g.frame}/stick"]["geometries"][0]["height"]
        np.testing.assert_allclose(node[:3, 3], root_p_predicted, atol=1e-12)
        np.testing.assert_allclose(
            length * node[:3, 1], 25.0 * (root_p_measured - root_p_predicted), atol=1e-12
        )
        errors.append(np.linalg.norm(root_p_measured - root_p_predicted))
    assert min(errors) > 1e-4  # millimetres: the lines are centimetres long
    # the target residual: from the given target to where the calibrated camera saw it
    ((name, root_T_target),) = case["targets"]
    for g in data.targets:
        root_T_seen = oMf[g.camera] @ g.camera_T_target[np.flatnonzero(g.sample == 1)[0]]
        path = f"{KINFW}/residuals/targets/{g.camera}/{name}"
        length = objects[path + "/stick"]["geometries"][0]["height"]
        np.testing.assert_allclose(transforms[path][:3, 3], root_T_target[:3, 3], atol=1e-12)
        np.testing.assert_allclose(
            length * transforms[path][:3, 1],
            25.0 * (root_T_seen[:3, 3] - root_T_target[:3, 3]),
            atol=1e-12,
        )


def test_residual_colour_runs_from_green_to_magenta():
    assert residual_color(0.0) == pytest.approx((0.0, 0.7, 0.2))
    assert residual_color(2e-3) == pytest.approx((1.0, 0.6, 0.0))
    assert residual_color(0.05) == pytest.approx((0.85, 0.0, 0.85))
    assert residual_color(1e-3) == pytest.approx((0.5, 0.65, 0.1))


def test_camera_looks_at_the_robot_with_up_upwards(head, head_up, case, drawn):
    display_T_root = scene_transforms(drawn)[KINFW]
    root_T_display = np.linalg.inv(display_T_root)
    target = root_T_display[:3, 3]  # the orbit camera looks at the display origin
    # the robot's bounding box: every link frame of the calibrated robot and the
    # measured poses, at the drawn configuration
    oMf = _pin_fk(case["calibrated"].urdf_xml, case["data"].joint_names, case["data"].qs[1])
    ps = np.array([T[:3, 3] for T in oMf.values()])
    assert np.all(target > ps.min(axis=0)) and np.all(target < ps.max(axis=0))
    # up (in the root frame) is the display's z axis
    np.testing.assert_allclose(
        display_T_root[:3, :3] @ head_up, [0.0, 0.0, np.linalg.norm(head_up)], atol=1e-12
    )
    camera = _properties(drawn, "/Cameras/default/rotated/<object>")
    x, y, z = camera["position"]  # three.js y-up: display (x, -z, y)
    display_p_camera = np.array([x, -z, y])
    assert display_p_camera[2] > 0  # from above the horizon
    assert 0.5 < np.linalg.norm(display_p_camera) < 10.0
    assert _properties(drawn, "/Axes")["visible"] is False
    assert _properties(drawn, "/Grid")["visible"] is False


def test_missing_meshes_are_drawn_as_a_skeleton_with_one_warning(caplog):
    """Missing meshes were one warning each and left nothing of their links on the page:
    now one warning for them all, and a skeleton, a triad per link and a segment per
    joint, where the URDF puts them (the joint's origin 0.4 m above the base: by hand)."""
    urdf = """<robot name="r">
      <link name="base">
        <visual><geometry><mesh filename="package://nowhere/base.stl"/></geometry></visual>
        <visual><geometry><box size="0.1 0.2 0.3"/></geometry></visual>
      </link>
      <joint name="j" type="revolute"><parent link="base"/><child link="arm"/>
        <origin xyz="0 0 0.4" rpy="0 0 0"/>
        <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
      <link name="arm">
        <visual><geometry><mesh filename="meshes/missing.dae"/></geometry></visual>
        <visual><geometry><cylinder radius="0.02" length="0.4"/></geometry></visual>
      </link>
    </robot>"""
    window = RecordingWindow()
    with caplog.at_level("WARNING", logger="kinfw.view"):
        scene(load_robot(urdf), window=window)
    (record,) = [r for r in caplog.records if r.name == "kinfw.view"]
    assert record.getMessage().startswith(
        "<urdf string>: 2 visual mesh(es) not found under package://nowhere, meshes/ "
    )
    assert "drawn as a skeleton; give --package-dir DIR" in record.getMessage()
    objects, transforms = scene_objects(window.commands), scene_transforms(window.commands)
    geometries = [
        o["geometries"][0]["type"]
        for p, o in objects.items()
        if p.startswith(f"{KINFW}/nominal/visuals/")
    ]
    assert sorted(geometries) == ["BoxGeometry", "CylinderGeometry"]
    skeleton = f"{KINFW}/nominal/skeleton"
    for link, z in (("base", 0.0), ("arm", 0.4)):
        assert f"{skeleton}/links/{link}/z/stick" in objects
        np.testing.assert_allclose(
            transforms[f"{skeleton}/links/{link}"][:3, 3], [0, 0, z], atol=1e-12
        )
    segment = objects[f"{skeleton}/joints/j/stick"]["geometries"][0]
    assert segment["type"] == "CylinderGeometry" and segment["height"] == pytest.approx(
        0.4, abs=1e-12
    )
    root_T_segment = transforms[f"{skeleton}/joints/j"]
    np.testing.assert_allclose(root_T_segment[:3, 3], [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(root_T_segment[:3, 1], [0, 0, 1], atol=1e-12)  # along the joint


def test_points_and_frames_measured_elsewhere_are_drawn_through_their_kinds(head, caplog):
    """Points are balls, with a residual line when their offset is known (or given in
    ``unknowns``); observations made in another frame need ``meas_T_root``."""
    from kinfw.measurements import Measurements
    from kinfw.model import BlockKey
    from kinfw.observations import PointObservations, PoseObservations

    names = head.joint_names
    q = np.linspace(0.1, 0.3, len(names))
    oMf = _pin_fk(head.urdf_xml, names, q)
    frame = head.default_frames[0]
    offset, marker_offset = np.array([0.01, 0.02, -0.03]), np.array([0.0, 0.05, 0.0])
    meas_T_root = np.eye(4)
    meas_T_root[:3, :3] = pin.rpy.rpyToMatrix(0.1, 0.2, -0.3)
    meas_T_root[:3, 3] = [1.0, -2.0, 0.5]
    measured = oMf[frame][:3, :3] @ offset + oMf[frame][:3, 3] + [0.002, 0.0, 0.0]
    in_tracker = meas_T_root @ oMf[frame]
    data = Measurements(
        names,
        q[None],
        poses=(PoseObservations(frame, [0], in_tracker[None], measured_in="tracker"),),
        points=(
            PointObservations(frame, [0], measured[None], offset=offset),
            PointObservations(frame, [0], measured[None], marker="m"),
        ),
    )
    window = RecordingWindow()
    with caplog.at_level("WARNING", logger="kinfw.view"):
        scene(head, data=data, sample=0, window=window, residual_scale=10.0)
    assert "frame:tracker" in caplog.text and "pass meas_T_root" in caplog.text
    objects, transforms = scene_objects(window.commands), scene_transforms(window.commands)
    assert not any("/measured/poses/" in p for p in objects)
    ball = f"{KINFW}/measured/points/{frame}"
    assert objects[ball]["geometries"][0]["type"] == "SphereGeometry"
    np.testing.assert_allclose(transforms[ball][:3, 3], measured, atol=1e-12)
    line = f"{KINFW}/residuals/points/{frame}"
    height = objects[line + "/stick"]["geometries"][0]["height"]
    np.testing.assert_allclose(height, 10.0 * 0.002, atol=1e-12)
    assert f"{line}@m/stick" not in objects  # the marker's offset is unknown

    window = RecordingWindow()
    scene(
        head,
        data=data,
        sample=0,
        window=window,
        meas_T_root=meas_T_root,
        unknowns={BlockKey("offset", f"{frame}:m"): marker_offset},
    )
    objects, transforms = scene_objects(window.commands), scene_transforms(window.commands)
    np.testing.assert_allclose(
        transforms[f"{KINFW}/measured/poses/{frame}"], oMf[frame], atol=1e-12
    )
    np.testing.assert_allclose(
        transforms[f"{KINFW}/residuals/points/{frame}@m"][:3, 3],
        oMf[frame][:3, :3] @ marker_offset + oMf[frame][:3, 3],
        atol=1e-12,
    )


def test_bad_arguments_are_refused(head, case):
    data = case["data"]
    with pytest.raises(IndexError, match="sample 3 is out of range for 3 samples"):
        scene(head, data=data, sample=3, window=RecordingWindow())
    with pytest.raises(ValueError, match=r"q: expected shape \(6,\)"):
        scene(head, q=[0.1, 0.2], window=RecordingWindow())
    with pytest.raises(ValueError, match="residual_scale"):
        scene(head, residual_scale=0.0, window=RecordingWindow())


def test_write_html_refuses_a_page_that_needs_the_network(tmp_path):
    class CdnWindow(RecordingWindow):
        def get_scene(self):
            return '<script src="https://cdn.example.org/three.min.js"></script>'

    vis = scene(load_robot(HEAD), window=CdnWindow())
    with pytest.raises(ValueError, match=r"cdn\.example\.org"):
        write_html(vis, tmp_path / "scene.html")
    assert not (tmp_path / "scene.html").exists()


def test_import_kinfw_does_not_load_meshcat():
    code = "import sys, kinfw, kinfw.view; sys.exit('meshcat' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


# -- offline HTML and the screenshot ------------------------------------------------------


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """``kinfw demo`` output: nominal, calibrated URDF + sidecar, data."""
    from kinfw.cli._main import main

    out = tmp_path_factory.mktemp("demo")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["demo", "--out", str(out), "--json"]) == 0
    return out


@pytest.fixture(scope="module")
def demo_html(demo, head, head_up):
    from kinfw.measurements import read_measurements

    vis = scene(
        head,
        load_robot(demo / "calibrated.urdf"),
        read_measurements(demo / "data.json"),
        targets=targets_from_sidecar(demo / "calibrated.kinfw.json"),
        window=OfflineWindow(),
        up=head_up,
    )
    return write_html(vis, demo / "scene.html")


@pytest.mark.slow
def test_offline_html_is_self_contained(demo_html):
    html = demo_html.read_text(encoding="utf-8")
    urls = re.findall(r"https?://[^\s\"'<>)]*", html)
    # only XML namespace names inside three.js, which a browser never fetches
    assert {u.split("/")[2] for u in urls} <= {"www.w3.org"}
    assert not re.search(r"<(script|link|img)[^>]+(src|href)=", html)
    assert "MeshCat.Viewer" in html
    size = demo_html.stat().st_size
    print(f"\noffline HTML: {size / 1e6:.2f} MB")
    assert 0.5e6 < size < 3e6  # meshcat's viewer script is 0.85 MB


def _chromium():
    """Path of a Chromium executable. Without one: skip, or fail when the environment
    variable ``KINFW_REQUIRE_BROWSER`` is set to anything but "" or "0" (CI)."""
    for name in CHROMIUM_NAMES:
        path = shutil.which(name)
        if path is not None:
            return path
    hint = "apt-get install chromium; .ci/run installs it"
    if os.environ.get(REQUIRE_BROWSER, "") not in ("", "0"):
        pytest.fail(
            f"chromium is not installed and {REQUIRE_BROWSER} is set: the screenshot "
            f"test needs headless Chromium ({hint})"
        )
    pytest.skip(
        f"no chromium on PATH, screenshot not checked ({hint}; "
        f"{REQUIRE_BROWSER}=1 makes this a failure)"
    )


@pytest.mark.slow
def test_screenshot_shows_both_models(demo_html, tmp_path):
    chromium = _chromium()
    png = tmp_path / "scene.png"
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as profile:
        run = subprocess.run(
            [
                chromium,
                *CHROMIUM_FLAGS,
                f"--user-data-dir={profile}",
                "--window-size=1000,700",
                "--virtual-time-budget=10000",
                f"--screenshot={png}",
                demo_html.resolve().as_uri(),
            ],
            capture_output=True,
            text=True,
            timeout=180,
            check=False,
        )
    print(f"\nchromium screenshot: {time.perf_counter() - start:.1f} s -> {png}")
    assert png.is_file(), (
        f"chromium wrote no screenshot (exit {run.returncode}):\n{run.stderr[-2000:]}"
    )
    import matplotlib.image

    rgb = np.round(255 * matplotlib.image.imread(png)[..., :3]).astype(int)
    assert rgb.shape == (700, 1000, 3)
    rgb = rgb[30:]  # below meshcat's "Open Controls" bar
    spread = rgb.max(axis=-1) - rgb.min(axis=-1)
    brightness = rgb.mean(axis=-1)
    background = (brightness > 215) & (spread < 25)  # white to light grey-blue gradient
    # the ghost alone over the background: neutral grey, clearly darker than it
    ghost = (spread < 20) & (brightness > 60) & (brightness < 200)
    # the calibrated robot: the direction of its colour, lit or shaded
    solid = np.array(SOLID_RGBA[:3]) / np.linalg.norm(SOLID_RGBA[:3])
    cosine = rgb @ solid / np.maximum(np.linalg.norm(rgb, axis=-1), 1)
    calibrated = (cosine > 0.985) & (brightness > 40) & ~background
    red = (rgb[..., 0] > 200) & (rgb[..., 1] < 60) & (rgb[..., 2] < 60)  # triads' x
    green = (rgb[..., 1] > 200) & (rgb[..., 0] < 60) & (rgb[..., 2] < 60)  # triads' y
    n = rgb.shape[0] * rgb.shape[1]
    print(
        f"pixels: background {background.sum()}, ghost {ghost.sum()}, "
        f"calibrated {calibrated.sum()}, red {red.sum()}, green {green.sum()} of {n}"
    )
    assert ghost.sum() > 2000
    assert calibrated.sum() > 0.1 * n
    assert red.sum() > 30 and green.sum() > 30
    assert background.sum() > 0.2 * n  # framed: the robot does not fill the window
    rows, cols = np.nonzero(calibrated)
    assert 0.25 < cols.mean() / rgb.shape[1] < 0.75  # roughly centred
    assert rows.min() > 0.05 * rgb.shape[0]  # the head's top is in view, with a margin


@pytest.mark.slow
def test_contacts_are_drawn_with_the_sidecars_plane_and_probe(tmp_path, caplog):
    """kinfw view of a contact calibration: the plane and the probe's offset come from
    the calibration's sidecar, as targets and the tracker's pose do (they were left out:
    "cannot draw PlaneContacts(...) (no value for plane:table)")."""
    from kinfw.cli._main import main
    from tests.robots import ARM_6R

    (tmp_path / "arm.urdf").write_text(ARM_6R)
    argv = ["-q", "simulate", "--urdf", tmp_path / "arm.urdf", "--contacts", "flange"]
    argv += ["--contact-samples", "40", "--noise-mm", "0.1", "--seed", "3"]
    argv += ["--out", tmp_path / "c.json", "--truth-out", tmp_path / "t.urdf"]
    assert main([str(a) for a in argv]) == 0
    argv = ["-q", "calibrate", tmp_path / "c.json", "--urdf", tmp_path / "arm.urdf"]
    assert main([str(a) for a in [*argv, "--out", tmp_path / "cal.urdf"]]) == 0
    argv = ["-q", "view", tmp_path / "arm.urdf", "--calibrated", tmp_path / "cal.urdf"]
    argv += ["--data", tmp_path / "c.json", "--html", tmp_path / "v.html"]
    with caplog.at_level("WARNING", logger="kinfw.view"):
        assert main([str(a) for a in argv]) == 0
    assert "cannot draw" not in caplog.text, caplog.text
    assert (tmp_path / "v.html").stat().st_size > 0
