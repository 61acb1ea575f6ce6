"""The proof of the design: a new observation kind defined entirely in this file.

"ball" (a smaller twin of the built-in ``sphere`` kind): a probe point on a robot frame
(unknown offset) touches a fixed sphere of unknown centre and known radius (a ball bar
of known length: the distance from the probe to the ball's centre is the radius).
Residual: ``radius - |w_p_probe - centre|``, one row in metres. The kind is registered,
written to and read from a ``kinfw-measurements`` file, and calibrates the 6R arm
through the public ``refine``; with its numpy prediction and its drawing (and the
default Gaussian simulation) it is simulated by ``kinfw.simulation.simulate_at`` and drawn
by ``kinfw.view.scene``, whose code names no kind.

Truth: contacts are simulated on a perturbed arm by solving for the joint angle that puts
the probe on the sphere. A rigid motion of the world moves the model and the centre
together without changing any distance, so the data determine everything but those 6
directions: the test checks the rank, and that the calibrated model predicts the
probe-to-centre distance at held-out configurations (not on the sphere) to 1e-9 m.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest
from numpy.typing import NDArray

from kinfw.identification import refine
from kinfw.identification.problem import NoiseModel
from kinfw.measurements import Measurements, read_measurements, write_measurements
from kinfw.model import BlockKey, PointBlock, load_robot
from kinfw.observations import (
    Drawing,
    NoiseComponent,
    ObservationKind,
    UnknownRequest,
    data_array,
    node_name,
    register_kind,
    sample_array,
    unregister_kind,
)
from kinfw.simulation import perturb_robot, simulate_at
from kinfw.verification.evaluation import random_joint_values
from tests.robots import ARM_6R


# -- the new kind: one group dataclass and one ObservationKind --------------------------
@dataclass(frozen=True, slots=True, eq=False)
class SphereContacts:
    """Contacts of a probe on ``frame`` with the fixed sphere ``sphere``.

    sample : (m,) sample indices; radius_m : (m,) the sphere's radius at each contact.
    """

    kind: ClassVar[str] = "ball"
    frame: str
    sample: NDArray[np.int64]
    radius_m: NDArray[np.float64]
    sphere: str = "sphere"

    def __post_init__(self) -> None:
        sample = sample_array(self.sample, "SphereContacts.sample")
        object.__setattr__(self, "sample", sample)
        object.__setattr__(
            self, "radius_m", data_array(self.radius_m, (len(sample),), "SphereContacts.radius_m")
        )


def probe_key(frame: str) -> BlockKey:
    return BlockKey("probe", frame)


def sphere_closed_form(w_T_frames: NDArray, radius_m: NDArray) -> NDArray:
    """Probe offset (0:3) and centre (3:6) from |R_i o + t_i - c|^2 = r_i^2, linear in
    (o, c, c o^T, |o|^2 + |c|^2) once c^T R_i o is written <R_i, c o^T>: 16 unknowns by
    least squares."""
    R, t = w_T_frames[:, :3, :3], w_T_frames[:, :3, 3]
    A = np.concatenate(
        [
            2 * np.einsum("nji,nj->ni", R, t),
            -2 * t,
            -2 * R.reshape(len(R), 9),
            np.ones((len(R), 1)),
        ],
        axis=1,
    )
    b = radius_m**2 - np.sum(t**2, axis=1)
    return np.linalg.lstsq(A, b, rcond=None)[0]


class SphereKind(ObservationKind):
    """``{"frame": f, "kind": "ball", "sphere": name, "radius": r}``."""

    name = "ball"
    group_type = SphereContacts
    row_fields = ("radius_m",)
    components = (NoiseComponent("distance", 1, "m"),)

    def parse(self, reader, obs, at, frame):
        radius = reader.number(obs, "radius", at, "the sphere's radius (a positive length)")
        sphere = reader.optional_string(obs, "sphere", at) or "sphere"
        return (("frame", frame), ("sphere", sphere)), reader.lengths([radius])

    def group_from_rows(self, key, sample, rows):
        return SphereContacts(sample=sample, radius_m=rows[:, 0], **dict(key))

    def to_dicts(self, group, top_measured_in):
        return [
            {"frame": group.frame, "kind": "ball", "sphere": group.sphere, "radius": r}
            for r in group.radius_m.tolist()
        ]

    def frames(self, group):
        return (group.frame,)

    def unknowns(self, group, start):
        """Closed form (:func:`sphere_closed_form`)."""
        sol = sphere_closed_form(start.w_T(group.frame, group.sample), group.radius_m)
        return (
            UnknownRequest(
                probe_key(group.frame),
                sol[None, 0:3],
                PointBlock.from_estimates,
                f"probe on {group.frame!r}",
            ),
            UnknownRequest(
                BlockKey("sphere", group.sphere),
                sol[None, 3:6],
                PointBlock.from_estimates,
                f"centre of {group.sphere!r}",
            ),
        )

    def data(self, group):
        return group.radius_m[:, None]

    def residual(self, group, model, m):
        T = model.w_T(group.frame)
        p = T[0:3, 0:3] @ model.value(probe_key(group.frame)) + T[0:3, 3]
        return m[0] - model.ca.norm_2(p - model.value(BlockKey("sphere", group.sphere)))

    # numpy: the prediction (simulate() adds the Gaussian noise of "distance"), the drawing
    def _probe_and_centre(self, group, model):
        T = model.w_T(group.frame, group.sample)
        return (
            T[:, :3, :3] @ model.value(probe_key(group.frame)) + T[:, :3, 3],
            model.value(BlockKey("sphere", group.sphere)),
        )

    def predict(self, group, model):
        p, c = self._probe_and_centre(group, model)
        return np.linalg.norm(p - c, axis=1)[:, None]

    def drawing(self, group, model):
        """Predicted: the probe; measured: the point at the measured radius from the
        centre on the line through the probe."""
        p, c = self._probe_and_centre(group, model)
        u = (p - c) / np.linalg.norm(p - c, axis=1)[:, None]
        return Drawing(
            node_name("spheres", group.frame, group.sphere),
            c + group.radius_m[:, None] * u,
            None,
            p,
        )


@pytest.fixture
def sphere_kind():
    kind = register_kind(SphereKind())
    yield kind
    unregister_kind(kind.name)


# -- simulated contacts on a perturbed arm ------------------------------------------------
NAMES = ("j1", "j2", "j3", "j4", "j5", "j6")
RADIUS = 0.15


def _probe(robot, qs, offset):
    T = robot.frame_poses(qs, "flange", NAMES)
    return T[:, :3, :3] @ offset + T[:, :3, 3]


def _contacts(truth, offset, centre, n, rng):
    """n configurations with the probe on the sphere: random joints, then j2 solved by
    bisection between two grid angles where the distance crosses the radius."""
    out = []
    grid = np.linspace(-3.0, 3.0, 241)
    while sum(map(len, out)) < n:
        q = random_joint_values(truth, NAMES, 200, rng)
        f = np.stack(
            [
                np.linalg.norm(
                    _probe(truth, np.column_stack([q[:, :1], np.full(len(q), a), q[:, 2:]]), offset)
                    - centre,
                    axis=1,
                )
                - RADIUS
                for a in grid
            ],
            axis=1,
        )
        cross = np.argmax(np.sign(f[:, :-1]) != np.sign(f[:, 1:]), axis=1)
        ok = np.sign(f[np.arange(len(q)), cross]) != np.sign(f[np.arange(len(q)), cross + 1])
        q, lo, hi = q[ok], grid[cross[ok]], grid[cross[ok] + 1]
        f_lo = f[ok, cross[ok]]
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            q[:, 1] = mid
            f_mid = np.linalg.norm(_probe(truth, q, offset) - centre, axis=1) - RADIUS
            left = np.sign(f_mid) == np.sign(f_lo)
            lo, f_lo = np.where(left, mid, lo), np.where(left, f_mid, f_lo)
            hi = np.where(left, hi, mid)
        q[:, 1] = 0.5 * (lo + hi)
        out.append(q)
    return np.concatenate(out)[:n]


@pytest.mark.slow
def test_a_kind_defined_in_a_test_file_round_trips_and_calibrates(sphere_kind, tmp_path):
    nominal = load_robot(ARM_6R)
    rng = np.random.default_rng(11)
    truth = load_robot(perturb_robot(nominal, rng))
    offset = np.array([0.02, -0.01, 0.04])  # probe in the flange frame
    centre = _probe(truth, np.full((1, 6), 0.3), offset)[0] + [0.05, 0.1, -0.05]
    qs = _contacts(truth, offset, centre, 120, rng)
    np.testing.assert_allclose(
        np.linalg.norm(_probe(truth, qs, offset) - centre, axis=1), RADIUS, atol=1e-12
    )
    data = Measurements(
        NAMES,
        qs,
        others=(
            SphereContacts("flange", np.arange(len(qs)), np.full(len(qs), RADIUS), sphere="ball"),
        ),
    )

    # the file edge: written and read back through the registry, in mm too
    path = tmp_path / "contacts.json"
    write_measurements(path, data)
    back = read_measurements(path)
    (group,) = back.groups("ball")
    assert isinstance(group, SphereContacts) and group.sphere == "ball"
    np.testing.assert_array_equal(back.qs, qs)
    np.testing.assert_array_equal(group.radius_m, RADIUS)
    assert back.observed_frames == ("flange",)

    result = refine(nominal, back, noise=NoiseModel(sigmas={"distance": 1e-4}))
    assert result.converged
    ident = result.identifiability
    assert ident.rank == ident.n_parameters - 6  # a rigid motion of the world is free
    (g,) = result.residuals
    assert g.kind == "ball" and np.abs(g.component("distance")).max() < 1e-10
    found = {u.kind: u.value for u in result.unknowns}

    # what the data determines: the probe-to-centre distance anywhere in joint space
    q_test = random_joint_values(nominal, NAMES, 200, np.random.default_rng(12))
    model_qs = q_test[:, [NAMES.index(j) for j in result.model.topology.joint_names]]
    T = result.model.frame_poses(model_qs, "flange")
    predicted = np.linalg.norm(
        T[:, :3, :3] @ found["probe"] + T[:, :3, 3] - found["sphere"], axis=1
    )
    true = np.linalg.norm(_probe(truth, q_test, offset) - centre, axis=1)
    assert np.abs(true - RADIUS).max() > 0.05  # held out: off the sphere
    np.testing.assert_allclose(predicted, true, rtol=0, atol=1e-9)


def test_the_new_kind_reads_from_a_hand_written_file_and_names_bad_keys(sphere_kind, tmp_path):
    doc = (
        '{"format": "kinfw-measurements", "version": 1, '
        '"units": {"length": "mm", "angle": "deg"}, "joint_names": ["j1"], "samples": ['
        '{"q": [10], "observations": [{"frame": "flange", "kind": "ball", '
        '"sphere": "ball", "radius": 150}]},'
        '{"q": [20], "observations": [{"frame": "flange", "kind": "ball", '
        '"radius": "big"}]}]}'
    )
    path = tmp_path / "bad.json"
    path.write_text(doc)
    from kinfw.observations import DatasetError

    with pytest.raises(
        DatasetError,
        match=r"bad\.json: samples\[1\]\.observations\[0\]"
        r"\.radius: expected the sphere's radius",
    ):
        read_measurements(path)
    path.write_text(doc.replace('"big"', "120"))
    m = read_measurements(path)
    by_sphere = {g.sphere: g for g in m.groups("ball")}
    np.testing.assert_array_equal(by_sphere["ball"].radius_m, [0.15])  # mm -> m
    np.testing.assert_array_equal(by_sphere["sphere"].sample, [1])


def test_without_the_kind_registered_the_file_is_refused(tmp_path):
    path = tmp_path / "x.json"
    path.write_text(
        '{"format": "kinfw-measurements", "version": 1, "units": {"length": '
        '"m", "angle": "rad"}, "joint_names": ["j1"], "samples": [{"q": [0], '
        '"observations": [{"frame": "f", "kind": "ball", "radius": 1}]}]}'
    )
    from kinfw.observations import DatasetError

    with pytest.raises(
        DatasetError,
        match="kind: expected one of 'pose', 'target', 'point', 'plane', 'sphere', 'divot', "
        "'pixels', got 'ball'",
    ):
        read_measurements(path)


@pytest.mark.slow
def test_the_new_kind_simulates_and_draws_through_its_hooks(sphere_kind):
    from kinfw.view import OfflineWindow, scene

    nominal = load_robot(ARM_6R)
    rng = np.random.default_rng(11)
    truth = load_robot(perturb_robot(nominal, rng))
    offset = np.array([0.02, -0.01, 0.04])
    centre = _probe(truth, np.full((1, 6), 0.3), offset)[0] + [0.05, 0.1, -0.05]
    unknowns = {probe_key("flange"): offset, BlockKey("sphere", "ball"): centre}

    def template(n):  # what is observed and when; simulate() fills in the radii
        return SphereContacts("flange", np.arange(n), np.zeros(n), sphere="ball")

    # noise-free: contacts found by bisection on the sphere measure its radius
    qs = _contacts(truth, offset, centre, 30, rng)
    data = simulate_at(
        truth, qs, NAMES, groups=[template(30)], unknowns=unknowns, rng=np.random.default_rng(0)
    )
    (g,) = data.groups("ball")
    assert g.sphere == "ball" and not data.poses and not data.points
    np.testing.assert_allclose(g.radius_m, RADIUS, rtol=0, atol=1e-12)

    # noisy, anywhere: the distance plus N(0, noise_m) (the "distance" component is in m)
    n, sigma = 4000, 1e-3
    q_any = random_joint_values(truth, NAMES, n, rng)
    noisy = simulate_at(
        truth,
        q_any,
        NAMES,
        groups=[template(n)],
        unknowns=unknowns,
        rng=np.random.default_rng(1),
        noise_m=sigma,
    ).groups("ball")[0]
    error = noisy.radius_m - np.linalg.norm(_probe(truth, q_any, offset) - centre, axis=1)
    assert abs(error.std() / sigma - 1) < 0.05 and abs(error.mean()) < 4 * sigma / np.sqrt(n)
    by_name = simulate_at(
        truth,
        q_any[:5],
        NAMES,
        groups=[template(5)],
        unknowns=unknowns,
        rng=np.random.default_rng(1),
        sigmas={"distance": 0.0},
        noise_m=sigma,
    )
    np.testing.assert_allclose(
        by_name.groups("ball")[0].radius_m,
        np.linalg.norm(_probe(truth, q_any[:5], offset) - centre, axis=1),
        rtol=0,
        atol=1e-15,
    )
    with pytest.raises(
        ValueError, match="needs the true value of sphere:ball; give it in unknowns"
    ):
        simulate_at(
            truth, qs, NAMES, groups=[template(30)], rng=rng, unknowns={probe_key("flange"): offset}
        )

    # drawn: a ball where the measured radius puts the probe, a line from the probe
    data = Measurements(
        NAMES,
        q_any[:3],
        others=(SphereContacts("flange", np.arange(3), noisy.radius_m[:3] + 0.01, sphere="ball"),),
    )
    window = OfflineWindow()
    scene(truth, data=data, sample=2, window=window, residual_scale=10.0, unknowns=unknowns)
    objects = {c["path"]: c["object"] for c in window.commands if c["type"] == "set_object"}
    transforms = {
        c["path"]: np.array(c["matrix"], float).reshape(4, 4).T
        for c in window.commands
        if c["type"] == "set_transform"
    }
    probe = _probe(truth, q_any[2:3], offset)[0]
    u = (probe - centre) / np.linalg.norm(probe - centre)
    measured = centre + data.others[0].radius_m[2] * u
    base = "/meshcat/kinfw/"
    assert (
        objects[base + "measured/spheres/flange/ball"]["geometries"][0]["type"] == "SphereGeometry"
    )
    np.testing.assert_allclose(
        transforms[base + "measured/spheres/flange/ball"][:3, 3], measured, rtol=0, atol=1e-12
    )
    line = transforms[base + "residuals/spheres/flange/ball"]
    height = objects[base + "residuals/spheres/flange/ball/stick"]["geometries"][0]["height"]
    np.testing.assert_allclose(line[:3, 3], probe, rtol=0, atol=1e-12)
    np.testing.assert_allclose(height * line[:3, 1], 10.0 * (measured - probe), rtol=0, atol=1e-12)
    assert abs(height - 10.0 * (0.01 + error[2])) < 1e-9  # 10 x the radius error


# -- its errors read in its own metric everywhere, with no library change for it ----------
def _distance_errors(robot, qs, radius_m, offset, centre):
    """Hand computation: measured radius minus the probe-to-centre distance (m), with
    the robot's Pinocchio forward kinematics."""
    return radius_m - np.linalg.norm(_probe(robot, qs, offset) - centre, axis=1)


def _stats_mm(e):
    a = 1e3 * np.abs(e)
    return a.mean(), np.sqrt(np.mean(a**2)), a.max()


@pytest.fixture
def sphere_files(sphere_kind, tmp_path):
    """A 6R arm (5 mm / 1 deg errors) whose probe touches a ball: 90 training contacts
    and 30 held-out ones, the radii read with 0.1 mm noise."""
    nominal = load_robot(ARM_6R)
    rng = np.random.default_rng(21)
    truth = load_robot(perturb_robot(nominal, rng))
    offset = np.array([0.02, -0.01, 0.04])
    centre = _probe(truth, np.full((1, 6), 0.3), offset)[0] + [0.05, 0.1, -0.05]
    qs = _contacts(truth, offset, centre, 120, rng)
    radius = RADIUS + rng.normal(0.0, 1e-4, len(qs))
    paths = {}
    for name, rows in (("train", slice(0, 90)), ("held", slice(90, 120))):
        n = len(qs[rows])
        group = SphereContacts("flange", np.arange(n), radius[rows], sphere="ball")
        paths[name] = tmp_path / f"{name}.json"
        write_measurements(paths[name], Measurements(NAMES, qs[rows], others=(group,)))
    paths["urdf"] = tmp_path / "arm.urdf"
    paths["urdf"].write_text(ARM_6R)
    return paths, nominal, qs, radius


def _cli(argv, capsys):
    from kinfw.cli._main import main

    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    return out


def _row(text, start):
    return next(line for line in text.splitlines() if line.strip().startswith(start)).split()


@pytest.mark.slow
def test_the_new_kind_is_read_in_its_own_metric_by_verify_calibrate_and_the_report(
    sphere_files, tmp_path, capsys
):
    """verify (text, --json), calibrate --holdout and report.json give the sphere's
    distance error in mm (its component's metric: no library code names it), equal to
    the hand computation: radius minus |probe - centre| with Pinocchio FK, the probe and
    centre from the sidecar (verify, and the calibration's "after": scored with what it
    was trained with) or, for the nominal ("before"), from the kind's closed form on the
    held-out contacts."""
    from kinfw.records import read_report, read_sidecar

    paths, nominal, qs, radius = sphere_files
    out_urdf, report_path = tmp_path / "cal.urdf", tmp_path / "report.json"
    argv = ["calibrate", paths["train"], "--urdf", paths["urdf"], "--out", out_urdf]
    out = _cli(
        [*argv, "--params", "full", "--holdout", paths["held"], "--report", report_path], capsys
    )
    calibrated = load_robot(out_urdf)
    q_held, r_held = qs[90:], radius[90:]

    # before / after on the held-out contacts: probe and centre by the closed form
    def refitted(robot):
        sol = sphere_closed_form(robot.frame_poses(q_held, "flange", NAMES), r_held)
        return _distance_errors(robot, q_held, r_held, sol[0:3], sol[3:6])

    # after: the calibration with the probe and centre it was trained with (the sidecar's)
    side = read_sidecar(out_urdf.with_suffix(".kinfw.json"))
    known = side.known_frames()
    e = _distance_errors(
        calibrated, q_held, r_held, known[("probe", "flange")], known[("sphere", "ball")]
    )
    before, after = _stats_mm(refitted(nominal)), _stats_mm(e)
    assert before[1] > 10 * after[1]  # the calibration helps
    held_table = out.split("held-out errors:")[1]
    assert "before RMS mm" in held_table.splitlines()[1]
    row = _row(held_table, "flange (ball)")
    assert float(row[3]) == pytest.approx(before[1], abs=6e-4)
    assert float(row[4]) == pytest.approx(after[1], abs=6e-4)
    report = json.loads(report_path.read_text())
    (held,) = report["errors_held_out"]
    assert held["before_distance_rms_mm"] == pytest.approx(before[1], rel=1e-9)
    assert held["after_distance_rms_mm"] == pytest.approx(after[1], rel=1e-9)
    assert list(report["distance_rms_mm_by_stage"]) == ["nominal", "refine"]
    assert read_report(report_path).errors_held_out[0].of("distance") == (
        held["before_distance_rms_mm"],
        held["after_distance_rms_mm"],
    )
    assert side.errors_held_out[0].of("distance") == pytest.approx((before[1], after[1]), rel=1e-9)

    # verify of the calibration on the held-out contacts: the sidecar's probe and centre
    doc = json.loads(_cli(["verify", out_urdf, paths["held"], "--json"], capsys))
    (g,) = doc["groups"]
    mean, rms, worst = _stats_mm(e)
    assert g["kind"] == "ball" and "position_rms_mm" not in g
    for key, value in (("mean", mean), ("rms", rms), ("max", worst)):
        assert g[f"distance_{key}_mm"] == pytest.approx(value, rel=1e-9), key
    np.testing.assert_allclose(
        [x["distance_mm"] for x in g["samples"]], 1e3 * np.abs(e), rtol=1e-9, atol=1e-12
    )
    text = _cli(["verify", out_urdf, paths["held"]], capsys)
    assert "distance RMS mm" in text and "nan" not in text.lower()
    assert float(_row(text, "flange")[4]) == pytest.approx(rms, abs=6e-4)


@pytest.mark.slow
def test_the_new_kind_is_scored_and_selected_by_crossval_in_its_own_metric(sphere_files, capsys):
    """crossval --select scores the sphere's held-out distance (mm) per fold, equal to
    the hand computation with the fold's trained model, and whitens it by the distance
    noise (the whitened score of a set is the mean over folds of (RMS / sigma)^2)."""
    from kinfw.identification import identify
    from kinfw.measurements import read_measurements

    paths, nominal, qs, radius = sphere_files
    argv = ["crossval", paths["train"], "--urdf", paths["urdf"], "--k", "3", "--select"]
    doc = json.loads(_cli([*argv, "--json"], capsys))
    assert doc["selected"] in ("none", "frames", "offsets", "full")
    (sigma,) = doc["noise"].values()
    assert list(doc["noise"]) == ["distance_m"]
    for p in doc["sets"]:
        folds = [f for f in doc["folds"] if f["parameters"] == p]
        whitened = np.mean([(f["distance_rms_mm"] * 1e-3 / sigma) ** 2 for f in folds])
        assert doc["mean_whitened"][p] == pytest.approx(whitened, rel=1e-9)
        mean = np.mean([f["distance_rms_mm"] for f in folds])
        assert doc["mean_distance_rms_mm"][p] == pytest.approx(mean, rel=1e-12)
    assert doc["selected"] == min(doc["sets"], key=doc["mean_whitened"].get)
    # one fold by hand: train "full" on the other folds, predict the held-out contacts
    data = read_measurements(paths["train"])
    test_ids = np.sort(np.array_split(np.random.default_rng(0).permutation(90), 3)[0])
    train = data.subset(np.setdiff1d(np.arange(90), test_ids))
    result = identify(nominal, train, parameters="full")
    found = {u.kind: u.value for u in result.refined.unknowns}
    e = _distance_errors(
        load_robot(result.urdf_xml), qs[test_ids], radius[test_ids], found["probe"], found["sphere"]
    )
    (fold,) = [f for f in doc["folds"] if (f["fold"], f["parameters"]) == (0, "full")]
    assert fold["distance_rms_mm"] == pytest.approx(_stats_mm(e)[1], rel=1e-6)
    text = _cli(argv, capsys)
    assert "held-out RMS, distance mm" in text and "nan" not in text.lower()
    assert "selected:" in text and "distance" in text.split("selected:")[1]
