"""The proof of the design: a new observation kind defined entirely in this file.

"sphere": a probe point on a robot frame (unknown offset) touches a fixed sphere of
unknown centre and known radius (a ball bar of known length: the distance from the
probe to the ball's centre is the radius). Residual: ``radius - |w_p_probe - centre|``,
one row in metres. The kind is registered, written to and read from a
``kinfw-measurements`` file, and calibrates the 6R arm through the public ``refine``;
with its numpy prediction and its drawing (and the default Gaussian simulation) it is
simulated by ``kinfw.simulation.simulate`` and drawn by ``kinfw.view.scene``, whose
code names no kind.

Truth: contacts are simulated on a perturbed arm by solving for the joint angle that puts
the probe on the sphere. A rigid motion of the world moves the model and the centre
together without changing any distance, so the data determine everything but those 6
directions: the test checks the rank, and that the calibrated model predicts the
probe-to-centre distance at held-out configurations (not on the sphere) to 1e-9 m.
"""

from __future__ import annotations

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
from kinfw.simulation import perturb_robot, simulate
from kinfw.verification.evaluation import random_joint_values
from tests.robots import ARM_6R


# -- the new kind: one group dataclass and one ObservationKind --------------------------
@dataclass(frozen=True, slots=True, eq=False)
class SphereContacts:
    """Contacts of a probe on ``frame`` with the fixed sphere ``sphere``.

    sample : (m,) sample indices; radius_m : (m,) the sphere's radius at each contact.
    """

    kind: ClassVar[str] = "sphere"
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


class SphereKind(ObservationKind):
    """``{"frame": f, "kind": "sphere", "sphere": name, "radius": r}``."""

    name = "sphere"
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
            {"frame": group.frame, "kind": "sphere", "sphere": group.sphere, "radius": r}
            for r in group.radius_m.tolist()
        ]

    def frames(self, group):
        return (group.frame,)

    def unknowns(self, group, start):
        """Closed form: |R_i o + t_i - c|^2 = r_i^2 is linear in (o, c, c o^T, |o|^2 +
        |c|^2) once c^T R_i o is written <R_i, c o^T>: 16 unknowns by least squares."""
        T = start.w_T(group.frame, group.sample)
        R, t = T[:, :3, :3], T[:, :3, 3]
        A = np.concatenate(
            [
                2 * np.einsum("nji,nj->ni", R, t),
                -2 * t,
                -2 * R.reshape(len(R), 9),
                np.ones((len(R), 1)),
            ],
            axis=1,
        )
        b = group.radius_m**2 - np.sum(t**2, axis=1)
        sol = np.linalg.lstsq(A, b, rcond=None)[0]
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
    (group,) = back.groups("sphere")
    assert isinstance(group, SphereContacts) and group.sphere == "ball"
    np.testing.assert_array_equal(back.qs, qs)
    np.testing.assert_array_equal(group.radius_m, RADIUS)
    assert back.observed_frames == ("flange",)

    result = refine(nominal, back, noise=NoiseModel(sigmas={"distance": 1e-4}))
    assert result.converged
    ident = result.identifiability
    assert ident.rank == ident.n_parameters - 6  # a rigid motion of the world is free
    (g,) = result.residuals
    assert g.kind == "sphere" and np.abs(g.component("distance")).max() < 1e-10
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
        '{"q": [10], "observations": [{"frame": "flange", "kind": "sphere", '
        '"sphere": "ball", "radius": 150}]},'
        '{"q": [20], "observations": [{"frame": "flange", "kind": "sphere", '
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
    by_sphere = {g.sphere: g for g in m.groups("sphere")}
    np.testing.assert_array_equal(by_sphere["ball"].radius_m, [0.15])  # mm -> m
    np.testing.assert_array_equal(by_sphere["sphere"].sample, [1])


def test_without_the_kind_registered_the_file_is_refused(tmp_path):
    path = tmp_path / "x.json"
    path.write_text(
        '{"format": "kinfw-measurements", "version": 1, "units": {"length": '
        '"m", "angle": "rad"}, "joint_names": ["j1"], "samples": [{"q": [0], '
        '"observations": [{"frame": "f", "kind": "sphere", "radius": 1}]}]}'
    )
    from kinfw.observations import DatasetError

    with pytest.raises(
        DatasetError,
        match="kind: expected one of 'pose', 'target', 'point', 'plane', 'pixels', got 'sphere'",
    ):
        read_measurements(path)


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
    data = simulate(
        truth, qs, NAMES, groups=[template(30)], unknowns=unknowns, rng=np.random.default_rng(0)
    )
    (g,) = data.groups("sphere")
    assert g.sphere == "ball" and not data.poses and not data.points
    np.testing.assert_allclose(g.radius_m, RADIUS, rtol=0, atol=1e-12)

    # noisy, anywhere: the distance plus N(0, noise_m) (the "distance" component is in m)
    n, sigma = 4000, 1e-3
    q_any = random_joint_values(truth, NAMES, n, rng)
    noisy = simulate(
        truth,
        q_any,
        NAMES,
        groups=[template(n)],
        unknowns=unknowns,
        rng=np.random.default_rng(1),
        noise_m=sigma,
    ).groups("sphere")[0]
    error = noisy.radius_m - np.linalg.norm(_probe(truth, q_any, offset) - centre, axis=1)
    assert abs(error.std() / sigma - 1) < 0.05 and abs(error.mean()) < 4 * sigma / np.sqrt(n)
    by_name = simulate(
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
        by_name.groups("sphere")[0].radius_m,
        np.linalg.norm(_probe(truth, q_any[:5], offset) - centre, axis=1),
        rtol=0,
        atol=1e-15,
    )
    with pytest.raises(
        ValueError, match="needs the true value of sphere:ball; give it in unknowns"
    ):
        simulate(
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
