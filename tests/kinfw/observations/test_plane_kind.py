"""The ``plane`` kind: a probe on the robot touches planes of unknown pose.

Truth: a perturbed 6R arm (``tests/robots.py``) with a probe at a known offset on its
flange touches two tilted planes; each contact configuration is random but for ``j2``,
solved by bisection so that the true probe lies on the plane (to 1e-15 m). Plane contacts
alone leave 7 directions free (a rigid motion of the world, and a common scale of every
length, since a contact stays a contact when everything grows): the tests check that
rank, that what the data do determine is recovered exactly from noise-free data (the
distances at held-out configurations up to that one scale, the angle between the
planes), and that a few ``point`` observations of the same probe in the root frame fix
the rest (held-out distances, the planes' normals and offsets to 1e-9).
"""

from __future__ import annotations

import json
from functools import partial

import numpy as np
import pytest

from kinfw.geometry import inverse_transform
from kinfw.identification import refine
from kinfw.identification.problem import NoiseModel, build_problem
from kinfw.measurements import Measurements, read_measurements, write_measurements
from kinfw.model import geometry_from_cpc, load_robot
from kinfw.observations import (
    DISTANCE,
    DatasetError,
    NumericContext,
    PlaneBlock,
    PlaneContacts,
    PointObservations,
    fit_plane,
    kind_of,
    lifted_probe_offset,
    offset_key,
    plane_key,
)
from kinfw.simulation import perturb_robot, simulate_at
from kinfw.urdf import export_urdf
from kinfw.verification.evaluation import random_joint_values
from tests.contacts import contact_configurations, probe_distances
from tests.robots import ARM_6R

NAMES = ("j1", "j2", "j3", "j4", "j5", "j6")
OFFSET = np.array([0.03, -0.02, 0.09])  # the probe on the flange, metres


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _probe(robot, qs, offset=OFFSET):
    T = robot.frame_poses(qs, "flange", NAMES)
    return T[:, :3, :3] @ offset + T[:, :3, 3]


def _distance(robot, qs, plane, offset=OFFSET):
    return _probe(robot, qs, offset) @ plane[:3] - plane[3]


def _contacts(truth, plane, n, rng, offset=OFFSET):
    """n configurations with the true probe on ``plane`` (n, d): random joints, then j2
    solved by bisection (:func:`tests.contacts.contact_configurations`)."""
    return contact_configurations(truth, NAMES, "flange", offset, plane, "j2", n, rng)


@pytest.fixture(scope="module")
def scene():
    """The nominal, the truth, two tilted planes (n, d) through points the probe reaches."""
    nominal = load_robot(ARM_6R)
    rng = np.random.default_rng(5)
    # the movable joints are perturbed; the flange's mounting on l6 stays the URDF's (the
    # given-offset case means "the probe is at OFFSET in the URDF's flange")
    truth = load_robot(perturb_robot(nominal, rng, joints=NAMES))
    reach = _probe(truth, np.array([[0.3, 0.2, -0.4, 0.5, 0.6, 0.1]]))[0]
    n_table = _unit([0.15, -0.1, 1.0])  # nearly horizontal
    n_wall = _unit([1.0, 0.3, -0.2])  # nearly vertical
    planes = {
        "table": np.append(n_table, n_table @ (reach - np.array([0.0, 0.0, 0.05]))),
        "wall": np.append(n_wall, n_wall @ (reach + np.array([0.05, 0.0, 0.0]))),
    }
    # the kind's sign convention: the normal points towards the root (d < 0)
    planes = {k: p if p[3] < 0 else -p for k, p in planes.items()}
    contacts = {k: _contacts(truth, p, 60, rng) for k, p in planes.items()}
    return nominal, truth, planes, contacts


def _dataset(contacts, *, offset=None, marker="tip", points=None):
    """Plane contacts (distance 0) of the probe, and optionally ``points`` (q, xyz)."""
    names = list(contacts)
    qs = np.concatenate([contacts[k] for k in names])
    groups, k0 = [], 0
    for k in names:
        m = len(contacts[k])
        groups.append(
            PlaneContacts(
                "flange",
                np.arange(k0, k0 + m),
                np.zeros(m),
                plane=k,
                offset=offset,
                marker=None if offset is not None else marker,
            )
        )
        k0 += m
    point_groups = ()
    if points is not None:
        q_pts, xyz = points
        point_groups = (
            PointObservations(
                "flange", np.arange(len(qs), len(qs) + len(q_pts)), xyz, marker=marker
            ),
        )
        qs = np.concatenate([qs, q_pts])
    return Measurements(NAMES, qs, points=point_groups, others=tuple(groups))


def _found(result):
    return {(u.kind, u.name): u.value for u in result.unknowns}


def _model_probe(result, qs, offset):
    cols = [NAMES.index(j) for j in result.model.topology.joint_names]
    T = result.model.frame_poses(qs[:, cols], "flange")
    return T[:, :3, :3] @ offset + T[:, :3, 3]


# -- the block and the closed form ---------------------------------------------------------


def test_the_plane_chart_is_minimal_unit_and_its_casadi_twin_agrees():
    import casadi as ca

    rng = np.random.default_rng(0)
    block = PlaneBlock(plane_key("p"), start=np.append(_unit([0.2, -0.9, 0.3]), -0.4))
    assert block.size == 3 and block.units == ("rad", "rad", "m")
    d = ca.SX.sym("d", 3)
    c = ca.SX.sym("c", len(block.constants()))
    f = ca.Function("f", [d, c], [block.casadi_value(d, c)])
    for x in rng.normal(0.0, 1.0, size=(20, 3)):
        value = block.numpy_value(x)
        np.testing.assert_allclose(np.linalg.norm(value[:3]), 1.0, rtol=0, atol=1e-15)
        np.testing.assert_allclose(
            np.array(f(x, block.constants())).ravel(), value, rtol=0, atol=1e-15
        )
        np.testing.assert_allclose(block.coordinates(value), x, rtol=0, atol=1e-12)
    # at zero: the start; the derivative turns the normal about the tangent basis
    np.testing.assert_array_equal(block.numpy_value(np.zeros(3)), block.start)
    eps = 1e-7
    dn = (block.numpy_value([eps, 0, 0]) - block.numpy_value([-eps, 0, 0]))[:3] / (2 * eps)
    u, v, n0 = block.constants()[0:3], block.constants()[3:6], block.start[:3]
    np.testing.assert_allclose(dn, np.cross(u, n0), rtol=0, atol=1e-8)  # = -v
    np.testing.assert_allclose(u @ n0, 0.0, atol=1e-15)
    np.testing.assert_allclose(np.cross(u, v), n0, rtol=0, atol=1e-15)


def test_the_closed_form_recovers_the_probe_and_the_plane_on_the_truth(scene):
    _, truth, planes, contacts = scene
    T = truth.frame_poses(contacts["table"], "flange", NAMES)
    o = lifted_probe_offset(T[:, :3, :3], T[:, :3, 3])
    np.testing.assert_allclose(o, OFFSET, rtol=0, atol=1e-9)
    plane = fit_plane(T[:, :3, :3] @ o + T[:, :3, 3])
    np.testing.assert_allclose(plane, planes["table"], rtol=0, atol=1e-9)
    # a fixed orientation cannot tell the offset from the plane: no answer, not a wrong one
    R = np.repeat(T[:1, :3, :3], len(T), axis=0)
    assert lifted_probe_offset(R, T[:, :3, 3]) is None


# -- the numeric twin, the file ----------------------------------------------------------


def test_numpy_prediction_equals_the_casadi_residual(scene):
    nominal, _, planes, contacts = scene
    for offset in (None, OFFSET):
        data = _dataset(contacts, offset=offset)
        problem = build_problem(nominal, data)
        rng = np.random.default_rng(3)
        x = rng.normal(0.0, 1e-2, size=problem.n_parameters)
        model = problem.model_at(x)
        values = {(u.kind, u.name): u.value for u in problem.unknowns_at(x)}
        known = {plane_key(k): values["plane", k] for k in planes}
        if offset is None:
            known[offset_key("flange", "tip")] = values["offset", "flange:tip"]
        qs = data.q_of(model.topology.joint_names)
        ctx = NumericContext(partial(model.frame_poses, qs), known)
        r, _ = problem.evaluate(x, NoiseModel(sigmas={"distance": 1.0}), with_jacobian=False)
        k = 0
        for grp in problem.groups:
            m = len(grp.sample)
            predicted = kind_of(grp.group).predict(grp.group, ctx)
            np.testing.assert_allclose(
                r[k : k + m], grp.group.distance_m - predicted[:, 0], rtol=0, atol=1e-12
            )
            k += m
        assert k == len(r)


def test_the_file_round_trips_and_reads_a_hand_written_contact(scene, tmp_path):
    contacts = scene[3]
    data = _dataset(contacts)
    noisy = data.with_groups(
        [
            g
            if i
            else PlaneContacts(
                "flange",
                g.sample,
                np.linspace(-1e-3, 1e-3, len(g.sample)),
                plane=g.plane,
                marker="tip",
            )
            for i, g in enumerate(data.others)
        ]
    )
    for d in (data, noisy):
        path = tmp_path / "contacts.json"
        write_measurements(path, d)
        back = read_measurements(path)
        np.testing.assert_array_equal(back.qs, d.qs)
        for a, b in zip(d.groups("plane"), back.groups("plane"), strict=True):
            assert (a.frame, a.plane, a.marker, a.offset) == (b.frame, b.plane, b.marker, b.offset)
            np.testing.assert_array_equal(a.sample, b.sample)
            np.testing.assert_array_equal(a.distance_m, b.distance_m)
    written = json.loads(path.read_text())["samples"][0]["observations"][0]
    assert written["kind"] == "plane" and "xyz" not in written

    doc = {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "mm", "angle": "deg"},
        "joint_names": ["j1"],
        "samples": [
            {
                "q": [10],
                "observations": [
                    {"frame": "flange", "kind": "plane", "plane": "table", "offset": [0, 0, 100]}
                ],
            },
            {"q": [20], "observations": [{"frame": "flange", "kind": "plane"}]},
        ],
    }
    path.write_text(json.dumps(doc))
    m = read_measurements(path)
    by_plane = {g.plane: g for g in m.groups("plane")}
    np.testing.assert_array_equal(by_plane["table"].offset, [0, 0, 0.1])  # mm -> m
    np.testing.assert_array_equal(by_plane["table"].distance_m, [0.0])
    assert by_plane["plane"].offset is None and list(by_plane["plane"].sample) == [1]

    bad = [
        ({"xyz": [1, 2, 3]}, r"observations\[0\]\.xyz: not allowed on a 'plane' observation"),
        ({"marker": "tip"}, r"observations\[0\]\.offset: an offset and a marker \('tip'\)"),
        ({"distance": "far"}, r"observations\[0\]\.distance: expected the probe's signed"),
        ({"offset": [0, 0]}, r"observations\[0\]\.offset: expected 3 numbers"),
    ]
    for extra, match in bad:
        d2 = json.loads(json.dumps(doc))
        d2["samples"][0]["observations"][0].update(extra)
        path.write_text(json.dumps(d2))
        with pytest.raises(DatasetError, match=r"contacts\.json: samples\[0\]\." + match):
            read_measurements(path)


# -- calibration --------------------------------------------------------------------------


def _held_out(result, truth, planes, offset_found):
    """Predicted and true distances (200, k) of held-out configurations from each plane."""
    q = random_joint_values(truth, NAMES, 200, np.random.default_rng(12))
    found = _found(result)
    p = _model_probe(result, q, offset_found)
    pred = np.column_stack([p @ found["plane", k][:3] - found["plane", k][3] for k in planes])
    true = np.column_stack([_distance(truth, q, planes[k]) for k in planes])
    assert np.abs(true).max() > 0.1  # held out: off the planes
    return pred, true


@pytest.mark.parametrize(
    ("which", "given", "n_free"),
    [
        (("table", "wall"), False, 7),  # a world motion (6) and the scale (1)
        (("table",), False, 7),
        (("table", "wall"), True, 10),  # and the tool's orientation about the probe (3)
    ],
)
def test_contacts_alone_determine_the_robot_up_to_a_world_motion_and_a_scale(
    scene, which, given, n_free
):
    nominal, truth, planes, contacts = scene
    planes = {k: planes[k] for k in which}
    data = _dataset({k: contacts[k] for k in which}, offset=OFFSET if given else None)
    result = refine(nominal, data, noise=NoiseModel(sigmas={"distance": 1e-4}))
    assert result.converged
    ident = result.identifiability
    assert ident.rank == ident.n_parameters - n_free
    assert len(ident.unidentifiable) == n_free
    assert {g.kind for g in result.residuals} == {"plane"}
    assert max(np.abs(g.component("distance")).max() for g in result.residuals) < 1e-10

    # what the data determine: every held-out distance up to one common scale
    offset = OFFSET if given else _found(result)["offset", "flange:tip"]
    pred, true = _held_out(result, truth, planes, offset)
    scale = float(np.sum(pred * true) / np.sum(true * true))
    assert 0.8 < scale < 1.2
    np.testing.assert_allclose(pred, scale * true, rtol=0, atol=1e-9)
    if len(which) == 2:  # the angle between the planes
        found = _found(result)
        np.testing.assert_allclose(
            found["plane", "table"][:3] @ found["plane", "wall"][:3],
            planes["table"][:3] @ planes["wall"][:3],
            rtol=0,
            atol=1e-9,
        )


def _exported_distances(nominal, problem, x, data, offset=None):
    """Each contact's distance (m,) of the probe from its plane for the problem's
    parameters ``x``, through the exported URDF and Pinocchio (not the CasADi model)."""
    urdf = load_robot(export_urdf(nominal, geometry_from_cpc(problem.model_at(x))).urdf_xml)
    found = {(u.kind, u.name): u.value for u in problem.unknowns_at(x)}
    offset = found["offset", "flange:tip"] if offset is None else offset
    return np.concatenate(
        [
            _distance(urdf, data.qs[g.sample], found["plane", g.plane], offset)
            for g in data.groups("plane")
        ]
    )


@pytest.mark.slow
@pytest.mark.parametrize("given", [False, True])
def test_what_contacts_leave_undetermined_stays_at_the_nominal(scene, given):
    """The export differs from the nominal only along determined directions: the null
    space of the contacts' Jacobian, by central differences through the exported URDF and
    Pinocchio (the world motion, the scale, and with a given offset the tool's
    orientation about the probe), holds none of the estimate (the robot's chart
    coordinates in m and rad, the unknowns' weighted by UNKNOWN_WEIGHT), while the
    held-out distances are the truth's up to the scale: the truth along what is
    determined."""
    from kinfw.identification.problem._refine import UNKNOWN_WEIGHT

    nominal, truth, planes, contacts = scene
    data = _dataset(contacts, offset=OFFSET if given else None)
    result = refine(nominal, data, noise=NoiseModel(sigmas={"distance": 1e-4}))
    problem = build_problem(nominal, data)
    assert problem.names == result.parameter_names
    offset = OFFSET if given else None
    cols = np.flatnonzero(result.free)
    robot = np.concatenate([np.full(b.size, b in problem.robot_blocks) for b in problem.blocks])[
        cols
    ]
    scale = np.where(robot, 1.0, UNKNOWN_WEIGHT)
    h, x = 1e-6, result.estimate
    J = (
        np.stack(
            [
                (
                    _exported_distances(nominal, problem, x + h * e, data, offset)
                    - _exported_distances(nominal, problem, x - h * e, data, offset)
                )
                / (2 * h)
                for e in np.eye(len(x))[cols]
            ],
            axis=1,
        )
        / scale
    )
    c = np.linalg.norm(J, axis=0)
    _, s, Vt = np.linalg.svd(J / c)
    null = Vt[s < 1e-7 * s[0]]
    assert len(null) == (10 if given else 7)
    Q = np.linalg.qr((null / c).T)[0]
    y = scale * x[cols]
    assert np.linalg.norm(y) > 5e-3  # the fit moved
    assert np.linalg.norm(Q.T @ y) < 1e-9 * np.linalg.norm(y)
    probe = OFFSET if given else _found(result)["offset", "flange:tip"]
    pred, true = _held_out(result, truth, planes, probe)
    ratio = float(np.sum(pred * true) / np.sum(true * true))
    np.testing.assert_allclose(pred, ratio * true, rtol=0, atol=1e-9)


def _points(truth, n, seed):
    q = random_joint_values(truth, NAMES, n, np.random.default_rng(seed))
    return q, _probe(truth, q)


def test_a_few_points_of_the_probe_fix_the_world_and_the_scale(scene):
    """8 tracker positions of the probe (the same marker: one offset) in the root frame:
    every parameter is determined; the planes, the probe and held-out distances exactly."""
    nominal, truth, planes, contacts = scene
    data = _dataset(contacts, points=_points(truth, 8, 21))
    assert len(data.points) == 1 and len(data.groups("plane")) == 2
    result = refine(nominal, data, noise=NoiseModel(sigmas={"distance": 1e-4, "position": 1e-4}))
    assert result.converged
    ident = result.identifiability
    assert ident.rank == ident.n_parameters and not ident.unidentifiable
    found = _found(result)
    assert [k for k in found if k[0] == "offset"] == [("offset", "flange:tip")]
    for k, plane in planes.items():
        np.testing.assert_allclose(found["plane", k], plane, rtol=0, atol=1e-9)
    pred, true = _held_out(result, truth, planes, found["offset", "flange:tip"])
    np.testing.assert_allclose(pred, true, rtol=0, atol=1e-9)
    q, p = _points(truth, 50, 22)
    np.testing.assert_allclose(
        _model_probe(result, q, found["offset", "flange:tip"]), p, rtol=0, atol=1e-9
    )


@pytest.mark.slow
def test_simulated_distance_noise_is_estimated_within_10_percent(scene):
    """Contacts whose distances carry N(0, sigma) noise (simulated by the kind, through
    ``kinfw.simulation``): the estimated sigma of "distance" is within 10 %."""
    nominal, truth, planes, _ = scene
    rng = np.random.default_rng(8)
    contacts = {k: _contacts(truth, p, 300, rng) for k, p in planes.items()}
    clean = _dataset(contacts, points=_points(truth, 8, 21))
    sigma = 2e-4
    unknowns = {plane_key(k): p for k, p in planes.items()}
    unknowns[offset_key("flange", "tip")] = OFFSET
    noisy = simulate_at(
        truth,
        clean.qs,
        NAMES,
        groups=[*clean.points, *clean.others],
        unknowns=unknowns,
        rng=np.random.default_rng(9),
        sigmas={"distance": sigma, "position": sigma},
    )
    errors = np.concatenate([g.distance_m for g in noisy.groups("plane")])
    assert abs(errors.std() / sigma - 1) < 0.1  # the simulation: distances N(0, sigma)
    result = refine(nominal, noisy)
    assert result.converged and result.noise.estimated
    assert abs(result.noise.sigma(DISTANCE) / sigma - 1) < 0.1
    found = _found(result)
    for k, plane in planes.items():  # and the planes within a few sigma of the truth
        assert np.abs(found["plane", k] - plane).max() < 10 * sigma


def test_the_contacts_are_drawn_on_the_plane(scene):
    _, truth, planes, contacts = scene
    data = _dataset(contacts)
    group = data.groups("plane")[0]
    qs = data.qs
    ctx = NumericContext.from_robot(
        truth,
        qs,
        NAMES,
        {plane_key(k): p for k, p in planes.items()} | {offset_key("flange", "tip"): OFFSET},
    )
    shifted = PlaneContacts(
        "flange", group.sample, np.full(len(group.sample), 0.01), plane=group.plane, marker="tip"
    )
    drawing = kind_of(group).drawing(shifted, ctx)
    plane = planes[group.plane]
    assert drawing.node == "planes/flange/table@tip"
    np.testing.assert_allclose(drawing.w_p_predicted, _probe(truth, qs[group.sample]), atol=1e-12)
    np.testing.assert_allclose(drawing.w_p_measured @ plane[:3] - plane[3], 0.01, atol=1e-12)


@pytest.mark.slow
def test_kinfw_calibrate_takes_a_contact_file_and_reports_a_gross_contact(scene, tmp_path, capsys):
    """The CLI end to end: contacts with N(0, 0.1 mm) noise and one 5 mm gross error, and 8
    tracked positions of the probe; the robust default fit flags the bad contact and the
    report lists it with its distance residual."""
    from kinfw.cli._main import main

    _, truth, planes, contacts = scene
    clean = _dataset(contacts, points=_points(truth, 8, 21))
    unknowns = {plane_key(k): p for k, p in planes.items()}
    unknowns[offset_key("flange", "tip")] = OFFSET
    noisy = simulate_at(
        truth,
        clean.qs,
        NAMES,
        groups=[*clean.points, *clean.others],
        unknowns=unknowns,
        rng=np.random.default_rng(4),
        sigmas={"distance": 1e-4, "position": 1e-4},
    )
    table = noisy.groups("plane")[0]
    distance = table.distance_m.copy()
    distance[3] += 5e-3
    noisy = noisy.with_groups(
        [
            *noisy.points,
            PlaneContacts("flange", table.sample, distance, plane=table.plane, marker="tip"),
            *noisy.groups("plane")[1:],
        ]
    )
    (tmp_path / "arm.urdf").write_text(ARM_6R)
    write_measurements(tmp_path / "contacts.json", noisy)
    code = main(
        [
            "calibrate",
            "--urdf",
            str(tmp_path / "arm.urdf"),
            str(tmp_path / "contacts.json"),
            "--out",
            str(tmp_path / "out.urdf"),
            "--report",
            str(tmp_path / "report.json"),
        ]
    )
    assert code == 0 and (tmp_path / "out.urdf").exists()
    report = json.loads((tmp_path / "report.json").read_text())
    # a 5 mm error at 0.1 mm noise: beyond the rejection threshold, so rejected (refit
    # without it), the worst first
    worst = report["refine"]["rejected"][0]
    assert (worst["kind"], worst["sample"]) == ("plane", int(table.sample[3]))
    assert abs(worst["height_residual_mm"] - 5.0) < 0.5
    # one probe on two planes: a row per plane, named by it, with its own contacts (the
    # rows were labelled alike, and the tables keyed by label kept one plane's numbers)
    for section in ("errors_before", "errors_after"):
        rows = report[section]
        assert set(rows) == {
            "flange [tip] (plane table)",
            "flange [tip] (plane wall)",
            "flange [tip] (point)",  # the 8 tracked positions
        }
        assert [rows[f"flange [tip] (plane {k})"]["n"] for k in ("table", "wall")] == [60, 60]
        assert rows["flange [tip] (plane table)"]["entity"] == "table"
    heights = report["height_rms_mm_by_stage"]
    assert all(len(stage) == 2 for stage in heights.values()), heights  # no point heights
    # and kinfw verify: a row per plane, the plane named in the kind column
    assert main(["-q", "verify", str(tmp_path / "out.urdf"), str(tmp_path / "contacts.json")]) == 0
    table = capsys.readouterr().out
    assert "plane table" in table and "plane wall" in table, table


# -- errors as a person reads them: height (mm) per contact, tilt (deg) per plane ----------
def _in_plane(n):
    """An orthonormal basis (2, 3) of the plane with normal ``n`` (by SVD)."""
    return np.linalg.svd(np.asarray(n, float)[None, :])[2][1:]


def _height_and_tilt(robot, qs, distance_m, plane, offset=OFFSET):
    """Hand geometry: each contact's height error (m: measured minus predicted distance)
    and the angle (rad) between the plane and the plane the contacts lie on (the heights'
    least-squares slope across the plane)."""
    p = _probe(robot, qs, offset)
    h = distance_m - (p @ plane[:3] - plane[3])
    A = np.column_stack([np.ones(len(p)), p @ _in_plane(plane[:3]).T])
    slope = np.linalg.lstsq(A, h, rcond=None)[0][1:]
    return h, float(np.arctan(np.hypot(*slope)))


def test_verify_reads_contacts_as_height_and_tilt_by_hand_geometry(scene, tmp_path, capsys):
    """Contacts whose measured distances rise by tan(0.5 deg) across the calibration's
    plane, 0.2 mm above it where the plane's coordinates are zero: verify (the sidecar's
    plane, the given probe offset) reads each contact's height in mm and the contacts'
    tilt as 0.5 deg, in the text and the JSON."""
    from kinfw.cli._main import main
    from kinfw.records import CalibratedUnknown, CalibrationSidecar, DataProvenance, write_sidecar

    nominal, _, planes, contacts = scene
    qs, plane = contacts["table"], planes["table"]
    p = _probe(nominal, qs)
    theta, phi = np.radians(0.5), 0.7
    uv = p @ _in_plane(plane[:3]).T
    measured = (p @ plane[:3] - plane[3]) + 2e-4 + np.tan(theta) * uv @ [np.cos(phi), np.sin(phi)]
    data = Measurements(
        NAMES,
        qs,
        others=(PlaneContacts("flange", np.arange(len(qs)), measured, "table", OFFSET),),
    )
    h, tilt = _height_and_tilt(nominal, qs, measured, plane)
    assert tilt == pytest.approx(theta, rel=1e-9)  # the hand geometry itself
    write_measurements(tmp_path / "contacts.json", data)
    (tmp_path / "arm.urdf").write_text(ARM_6R)
    side = CalibrationSidecar(
        created="2025-01-01T00:00:00+00:00",
        kinfw_version="test",
        method="refine",
        calibrated_urdf="arm.urdf",
        nominal_urdf=None,
        nominal_urdf_sha256=None,
        data=DataProvenance("contacts.json", len(qs)),
        w_T_root=np.eye(4),
        unknowns=(CalibratedUnknown("plane", "table", plane),),
    )
    write_sidecar(tmp_path / "arm.kinfw.json", side)
    argv = ["verify", str(tmp_path / "arm.urdf"), str(tmp_path / "contacts.json")]
    assert main([*argv, "--json"]) == 0
    (g,) = json.loads(capsys.readouterr().out)["groups"]
    a = 1e3 * np.abs(h)
    assert g["kind"] == "plane" and "position_rms_mm" not in g
    assert g["height_mean_mm"] == pytest.approx(a.mean(), rel=1e-9)
    assert g["height_rms_mm"] == pytest.approx(np.sqrt(np.mean(a**2)), rel=1e-9)
    assert g["height_max_mm"] == pytest.approx(a.max(), rel=1e-9)
    assert g["tilt_deg"] == pytest.approx(0.5, rel=1e-9)
    assert main(argv) == 0
    text = capsys.readouterr().out
    head, row = (line for line in text.splitlines() if "tilt" in line or "flange" in line)
    assert head.split()[-2:] == ["tilt", "deg"] and row.split()[-1] == "0.5000"
    assert "nan" not in text.lower()


@pytest.fixture(scope="module")
def noisy_contacts(scene):
    """The two planes' contacts with the given probe offset, 0.1 mm distance noise."""
    _, truth, planes, contacts = scene
    clean = _dataset(contacts, offset=OFFSET)
    return simulate_at(
        truth,
        clean.qs,
        NAMES,
        groups=list(clean.others),
        unknowns={plane_key(k): p for k, p in planes.items()},
        rng=np.random.default_rng(8),
        sigmas={"distance": 1e-4},
    )


@pytest.mark.slow
def test_crossval_scores_height_and_tilt_against_the_trained_planes(scene, noisy_contacts):
    """Held out, the trained planes stay fixed: per fold the RMS height (mm) over the
    test contacts and the RMS over the planes of their tilt (deg), equal to the hand
    geometry with the fold's trained robot and planes; selection whitens the height by
    the distance noise."""
    from kinfw.identification import identify
    from kinfw.verification.evaluation import crossvalidate

    nominal = scene[0]
    data = noisy_contacts
    cv = crossvalidate(nominal, data, k=3, sets=("frames", "offsets"), select=True)
    doc = cv.to_dict()
    assert [m.headline for m in cv.metrics] == ["height_rms_mm", "tilt_deg"]
    (sigma,) = doc["noise"].values()
    for p in cv.sets:
        folds = [f for f in doc["folds"] if f["parameters"] == p]
        whitened = np.mean([(f["height_rms_mm"] * 1e-3 / sigma) ** 2 for f in folds])
        assert doc["mean_whitened"][p] == pytest.approx(whitened, rel=1e-9)
    assert cv.whitened("frames") != cv.whitened("offsets")
    assert cv.selected == min(cv.sets, key=cv.whitened)
    # fold 0 of "offsets" by hand
    test_ids = np.sort(np.array_split(np.random.default_rng(0).permutation(data.n_samples), 3)[0])
    train = data.subset(np.setdiff1d(np.arange(data.n_samples), test_ids))
    result = identify(nominal, train, parameters="offsets")
    trained = load_robot(result.urdf_xml)
    found = {u.name: u.value for u in result.refined.unknowns if u.kind == "plane"}
    heights, tilts = [], []
    for g in data.groups("plane"):
        keep = np.isin(g.sample, test_ids)
        h, tilt = _height_and_tilt(
            trained, data.qs[g.sample[keep]], g.distance_m[keep], found[g.plane]
        )
        heights.append(h)
        tilts.append(tilt)
    fold = next(s for s in cv.scores if (s.fold, s.parameters) == (0, "offsets"))
    assert fold.of("height") == pytest.approx(
        1e3 * np.sqrt(np.mean(np.concatenate(heights) ** 2)), rel=1e-6
    )
    assert fold.of("tilt") == pytest.approx(
        np.degrees(np.sqrt(np.mean(np.square(tilts)))), rel=1e-5
    )


def test_calibrate_holdout_and_report_give_height_and_tilt(scene, noisy_contacts, tmp_path, capsys):
    """calibrate --holdout: the held-out height RMS and tilt before and after, each
    model's contacts scored against its trained plane (the calibration's, in its
    sidecar; for the nominal, the least-squares plane of the training contacts with the
    nominal robot), equal to the hand geometry; report.json carries them, and the
    in-sample errors in the same keys."""
    from kinfw.cli._main import main
    from kinfw.records import read_sidecar

    nominal = scene[0]
    table = noisy_contacts.groups("plane")[0]
    assert table.plane == "table"
    data = noisy_contacts.with_groups([table]).subset(table.sample)
    train, held = data.subset(np.arange(48)), data.subset(np.arange(48, 60))
    write_measurements(tmp_path / "train.json", train)
    write_measurements(tmp_path / "held.json", held)
    (tmp_path / "arm.urdf").write_text(ARM_6R)
    argv = ["calibrate", tmp_path / "train.json", "--urdf", tmp_path / "arm.urdf"]
    argv += [
        "--out",
        tmp_path / "out.urdf",
        "--params",
        "offsets",
        "--holdout",
        tmp_path / "held.json",
    ]
    assert main([str(a) for a in [*argv, "--report", tmp_path / "r.json"]]) == 0
    out = capsys.readouterr().out
    report = json.loads((tmp_path / "r.json").read_text())
    (row,) = report["errors_held_out"]

    def least_squares_plane(p, m):
        """(n, d) minimising sum (m - (n . p - d))^2: Gauss-Newton on the normal's two
        tangent angles and d, from the total least-squares plane of the points."""
        c = p.mean(axis=0)
        n = np.linalg.svd(p - c)[2][-1]
        n = -n if n @ c > 0 else n
        d = float(np.mean(p @ n - m))
        for _ in range(50):
            u, v = _in_plane(n)
            r = m - (p @ n - d)
            J = np.column_stack([-(p @ u), -(p @ v), np.ones(len(p))])
            step = np.linalg.lstsq(J, -r, rcond=None)[0]
            n = n + step[0] * u + step[1] * v
            n /= np.linalg.norm(n)
            d += step[2]
        return np.append(n, d)

    (g_train,) = train.groups("plane")
    nominal_plane = least_squares_plane(
        _probe(nominal, train.qs[g_train.sample]), g_train.distance_m
    )
    side = read_sidecar(tmp_path / "out.kinfw.json")
    (trained_plane,) = (u.value for u in side.unknowns if u.kind == "plane")
    (g,) = held.groups("plane")
    qs = held.qs[g.sample]
    models = (
        (nominal, nominal_plane, "before"),
        (load_robot(tmp_path / "out.urdf"), trained_plane, "after"),
    )
    for robot, plane, when in models:
        h, tilt = _height_and_tilt(robot, qs, g.distance_m, plane)
        rms = 1e3 * np.sqrt(np.mean(h**2))
        assert row[f"{when}_height_rms_mm"] == pytest.approx(rms, rel=1e-6), when
        assert row[f"{when}_tilt_deg"] == pytest.approx(np.degrees(tilt), rel=1e-5), when
        assert row[f"{when}_tilt_deg"] > 0.0
    assert row["before_height_rms_mm"] > row["after_height_rms_mm"]
    held_table = out.split("held-out errors:")[1]
    assert "before RMS mm" in held_table and "after tilt deg" in held_table
    (after,) = report["errors_after"].values()
    assert list(after)[4:] == ["height_mean_mm", "height_rms_mm", "height_max_mm", "tilt_deg"]
    assert "height_rms_mm_by_stage" in report and "position_rms_mm_by_stage" not in report


@pytest.mark.slow
def test_the_model_choice_on_plane_contacts_ranks_by_the_whitened_height(scene, noisy_contacts):
    """On plane contacts the candidates' held-out heights differ (no longer all 0): each
    candidate's whitened score is (held-out height RMS / sigma)^2 under the full fit's
    distance noise (that fit's own estimate) and the choice is the simplest within 1 %
    of the lowest."""
    from kinfw.identification import identify
    from kinfw.verification.evaluation import choose_parameters, whitening_noise

    nominal, prior = scene[0], (1e-3, 1e-2)
    choice = choose_parameters(nominal, noisy_contacts, prior=prior)
    assert choice.k == noisy_contacts.n_samples and len(choice.candidates) == 3
    whitened = [c.whitened for c in choice.candidates]
    assert np.all(np.isfinite(whitened)) and len(set(whitened)) == 3 and min(whitened) > 0
    for c in choice.candidates:
        assert [m.headline for m, _ in c.errors] == ["height_rms_mm", "tilt_deg"]
    best = min(whitened)
    expected = next(c for c in choice.candidates if c.whitened <= 1.01 * best)  # simplest first
    assert (choice.parameters, choice.prior) == (expected.parameters, expected.prior)
    full = identify(nominal, noisy_contacts, parameters="full", prior=prior)
    (sigma,) = (
        v for c, v in whitening_noise(full.refined.noise, noisy_contacts) if c.name == "distance"
    )
    for c in choice.candidates:
        height_mm = dict((m.name, v) for m, v in c.errors)["height"]
        assert c.whitened == pytest.approx((height_mm * 1e-3 / sigma) ** 2, rel=1e-9)


# -- a plane fixed to any URDF frame; several chains on one plane --------------------------


@pytest.mark.slow
def test_a_plane_fixed_to_a_frame_of_the_robot_calibrates_and_round_trips(scene, tmp_path):
    """The table fixed to link ``l1`` (``measured_in``): contacts simulated in l1's frame
    by Pinocchio FK; the file round-trips the frame; the fit leaves every contact on
    the plane, predicts held-out distances in l1 as the truth does up to the scale, and
    leaves j1 (above both frames: it moves probe and plane alike) at the nominal."""
    nominal, truth, _, _ = scene
    rng = np.random.default_rng(31)
    q0 = np.array([[0.3, 0.2, -0.4, 0.5, 0.6, 0.1]])
    l1_T_flange = (
        inverse_transform(truth.frame_poses(q0, "l1", NAMES)[0])
        @ truth.frame_poses(q0, "flange", NAMES)[0]
    )
    reach = l1_T_flange[:3, :3] @ OFFSET + l1_T_flange[:3, 3]
    n = _unit([0.2, 1.0, -0.1])
    plane = np.append(n, n @ (reach + 0.03 * n))
    plane = plane if plane[3] < 0 else -plane
    qs = contact_configurations(
        truth, NAMES, "flange", OFFSET, plane, "j3", 80, rng, measured_in="l1"
    )
    assert np.abs(probe_distances(truth, qs, NAMES, "flange", OFFSET, plane, "l1")).max() < 1e-12
    group = PlaneContacts(
        "flange", np.arange(80), np.zeros(80), "table", marker="tip", measured_in="l1"
    )
    write_measurements(tmp_path / "c.json", Measurements(NAMES, qs, others=(group,)))
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["samples"][0]["observations"][0]["measured_in"] == "l1"
    data = read_measurements(tmp_path / "c.json")
    (read,) = data.groups("plane")
    assert read.measured_in == "l1" and read.marker == "tip"
    result = refine(nominal, data, noise=NoiseModel(sigmas={"distance": 1e-4}))
    assert result.converged
    assert max(np.abs(g.component("distance")).max() for g in result.residuals) < 1e-10
    found = _found(result)
    q = random_joint_values(truth, NAMES, 200, np.random.default_rng(12))
    exported = load_robot(export_urdf(nominal, geometry_from_cpc(result.model)).urdf_xml)
    pred = probe_distances(
        exported, q, NAMES, "flange", found["offset", "flange:tip"], found["plane", "table"], "l1"
    )
    true = probe_distances(truth, q, NAMES, "flange", OFFSET, plane, "l1")
    assert np.abs(true).max() > 0.1
    ratio = float(pred @ true / (true @ true))
    np.testing.assert_allclose(pred, ratio * true, rtol=0, atol=1e-9)
    for name in ("j1",):  # j1 moves probe and plane alike: nominal
        np.testing.assert_allclose(
            exported.joint(name).parent_T_child, nominal.joint(name).parent_T_child, atol=1e-12
        )
        np.testing.assert_allclose(exported.joint(name).axis, nominal.joint(name).axis, atol=1e-12)


@pytest.mark.parametrize("kind", ["plane", "sphere"])
def test_a_null_distance_is_refused_an_absent_one_is_on_the_surface(kind, tmp_path):
    """A contact written without "distance" is on the surface (0, as the writer leaves
    zeros out); an explicit null is a hole in the data, not a zero: refused, naming it."""
    obs = {"frame": "flange", "kind": kind, kind: "s", "marker": "tip"}
    if kind == "sphere":
        obs["radius"] = 0.02
    doc = {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "m", "angle": "rad"},
        "joint_names": list(NAMES),
        "samples": [{"q": [0.1 * i] * len(NAMES), "observations": [dict(obs)]} for i in range(3)],
    }
    path = tmp_path / "c.json"
    path.write_text(json.dumps(doc))
    data = read_measurements(path)
    assert [float(d) for d in data.others[0].distance_m] == [0.0, 0.0, 0.0]
    doc["samples"][1]["observations"][0]["distance"] = None
    path.write_text(json.dumps(doc))
    with pytest.raises(
        DatasetError, match=r"samples\[1\]\.observations\[0\]\.distance: null; expected the probe"
    ):
        read_measurements(path)
