"""The ``sphere`` and ``divot`` kinds: a probe on the robot touches a fixed ball, or is
placed on a fixed point, of unknown position.

Truth: a perturbed 6R arm (``tests/robots.py``) with a probe on its flange; contact
configurations are random ones projected onto the contact (Gauss-Newton,
:func:`kinfw.simulation.contact_configurations`) and checked here by Pinocchio forward
kinematics of the true URDF (on the ball, on the point, to 1e-12 m). What the contacts
determine is checked against that truth at held-out configurations: the signed distance
from the ball with its radius given (exact, 1e-9 m); with the radius unknown, and for a
point, distances up to the one common scale those contacts leave free (a contact stays
a contact when every length grows). The noise tests check the held-out RMS against
``sigma sqrt(1 + p / n)`` (p determined parameters, n residual rows).
"""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

from kinfw.identification import refine
from kinfw.identification.problem import WORLD_MOTION, NoiseModel, build_problem
from kinfw.measurements import Measurements, read_measurements, write_measurements
from kinfw.model import load_robot
from kinfw.observations import (
    DatasetError,
    DivotContacts,
    NumericContext,
    SphereContacts,
    divot_key,
    fit_sphere,
    kind_of,
    lifted_sphere_probe,
    offset_key,
    pivot_calibration,
    sphere_key,
)
from kinfw.simulation import contact_configurations, perturb_robot
from kinfw.verification.evaluation import random_joint_values
from tests.robots import ARM_6R

NAMES = ("j1", "j2", "j3", "j4", "j5", "j6")
OFFSET = np.array([0.03, -0.02, 0.09])  # the probe on the flange, metres
RADIUS = 0.025  # the ball's, metres


def _probe(robot, qs, offset=OFFSET):
    """The probe (n, 3) in the root by Pinocchio FK, metres."""
    T = robot.frame_poses(qs, "flange", NAMES)
    return T[:, :3, :3] @ offset + T[:, :3, 3]


def _on(truth, n, seed, **surface):
    """n configurations of the true robot with the probe on ``surface`` (sphere= or
    point=)."""
    lower, upper = truth.joint_limits(NAMES)
    return contact_configurations(
        truth,
        NAMES,
        lower,
        upper,
        n,
        np.random.default_rng(seed),
        frame="flange",
        offset=OFFSET,
        **surface,
    )


@pytest.fixture(scope="module")
def scene():
    """The nominal, the truth, the ball (c, r), the point, and contacts with each."""
    nominal = load_robot(ARM_6R)
    truth = load_robot(perturb_robot(nominal, np.random.default_rng(5), joints=NAMES))
    reach = _probe(truth, np.array([[0.3, 0.2, -0.4, 0.5, 0.6, 0.1]]))[0]
    ball = np.append(reach + np.array([0.02, -0.01, -0.03]), RADIUS)
    point = reach + np.array([-0.03, 0.02, 0.0])
    return (
        nominal,
        truth,
        ball,
        point,
        _on(truth, 60, 1, sphere=ball),
        _on(truth, 40, 2, point=point),
    )


def _spheres(qs, *, radius=RADIUS, marker="tip", distance=None):
    n = len(qs)
    group = SphereContacts(
        "flange",
        np.arange(n),
        np.zeros(n) if distance is None else distance,
        sphere="ball",
        radius=radius,
        marker=marker,
        offset=None if marker else OFFSET,
    )
    return Measurements(NAMES, qs, others=(group,))


def _divots(qs, *, gap=None):
    n = len(qs)
    group = DivotContacts(
        "flange", np.arange(n), np.zeros((n, 3)) if gap is None else gap, marker="tip"
    )
    return Measurements(NAMES, qs, others=(group,))


def _found(result):
    return {(u.kind, u.name): u.value for u in result.unknowns}


def _model_probe(result, qs, offset):
    cols = [NAMES.index(j) for j in result.model.topology.joint_names]
    T = result.model.frame_poses(qs[:, cols], "flange")
    return T[:, :3, :3] @ offset + T[:, :3, 3]


# -- the truth of the data, the closed forms -----------------------------------------------


def test_the_contacts_are_on_the_ball_and_the_point_by_pinocchio(scene):
    _, truth, ball, point, on_ball, on_point = scene
    p = _probe(truth, on_ball)
    np.testing.assert_allclose(np.linalg.norm(p - ball[:3], axis=1), RADIUS, rtol=0, atol=1e-12)
    np.testing.assert_allclose(_probe(truth, on_point), np.tile(point, (40, 1)), rtol=0, atol=1e-12)
    # the orientations vary (what tells the probe's offset from the point)
    R = truth.frame_poses(on_point, "flange", NAMES)[:, :3, :3]
    assert np.degrees(np.arccos((np.trace(R[0].T @ R[1:], axis1=1, axis2=2) - 1) / 2)).max() > 20


def test_the_closed_forms_recover_the_probe_the_ball_and_the_point_on_the_truth(scene):
    _, truth, ball, point, on_ball, on_point = scene
    T = truth.frame_poses(on_ball, "flange", NAMES)
    o = lifted_sphere_probe(T[:, :3, :3], T[:, :3, 3])
    np.testing.assert_allclose(o, OFFSET, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fit_sphere(_probe(truth, on_ball)), ball, rtol=0, atol=1e-9)
    assert fit_sphere(np.eye(3)) is None  # 3 points: no sphere determined
    T = truth.frame_poses(on_point, "flange", NAMES)
    o, c = pivot_calibration(T[:, :3, :3], T[:, :3, 3])
    np.testing.assert_allclose(o, OFFSET, rtol=0, atol=1e-9)
    np.testing.assert_allclose(c, point, rtol=0, atol=1e-9)
    o, c = pivot_calibration(T[:, :3, :3], T[:, :3, 3], centre=point)
    np.testing.assert_allclose(o, OFFSET, rtol=0, atol=1e-9)
    # a fixed orientation cannot tell the offset from the ball: no answer, not a wrong one
    R = np.repeat(T[:1, :3, :3], len(T), axis=0)
    assert lifted_sphere_probe(R, T[:, :3, 3]) is None


def test_the_residual_is_the_hand_computed_distance_and_placement(scene):
    """At random parameters, the problem's residuals (CasADi) and each kind's numpy
    prediction equal ``measured - (|p - c| - r)`` and ``measured - (p - c)`` computed
    here from the model's flange poses and the unknowns' values."""
    nominal, _, _, _, on_ball, on_point = scene
    rng = np.random.default_rng(3)
    cases = [
        (_spheres(on_ball, radius=None, distance=rng.normal(0, 1e-3, 60)), "distance"),
        (_spheres(on_ball, distance=rng.normal(0, 1e-3, 60)), "distance"),
        (_divots(on_point, gap=rng.normal(0, 1e-3, (40, 3))), "placement"),
    ]
    for data, component in cases:
        problem = build_problem(nominal, data)
        x = rng.normal(0.0, 1e-2, size=problem.n_parameters)
        model = problem.model_at(x)
        values = {(u.kind, u.name): u.value for u in problem.unknowns_at(x)}
        (g,) = data.others
        p = _model_probe_at(model, data.qs, values["offset", "flange:tip"])
        if isinstance(g, SphereContacts):
            c = values["sphere", "ball"]
            r = c[3] if g.radius is None else g.radius
            assert c.shape == ((4,) if g.radius is None else (3,))
            hand = g.distance_m - (np.linalg.norm(p - c[:3], axis=1) - r)
            known = {sphere_key("ball"): c}
        else:
            c = values["divot", "divot"]
            hand = (g.gap_m - (p - c)).reshape(-1)
            known = {divot_key("divot"): c}
        known[offset_key("flange", "tip")] = values["offset", "flange:tip"]
        r, _ = problem.evaluate(x, NoiseModel(sigmas={component: 1.0}), with_jacobian=False)
        np.testing.assert_allclose(r, hand, rtol=0, atol=1e-12)
        ctx = NumericContext(
            partial(model.frame_poses, data.q_of(model.topology.joint_names)), known
        )
        predicted = kind_of(g).predict(g, ctx)
        np.testing.assert_allclose(
            kind_of(g).data(g) - predicted, hand.reshape(len(g.sample), -1), rtol=0, atol=1e-12
        )


def _model_probe_at(model, qs, offset):
    cols = [NAMES.index(j) for j in model.topology.joint_names]
    T = model.frame_poses(qs[:, cols], "flange")
    return T[:, :3, :3] @ offset + T[:, :3, 3]


def test_the_file_round_trips_and_reads_hand_written_contacts(scene, tmp_path):
    _, _, _, _, on_ball, on_point = scene
    data = Measurements(
        NAMES,
        np.concatenate([on_ball[:3], on_point[:2]]),
        others=(
            SphereContacts("flange", [0, 1, 2], [0.0, 1e-4, 0.0], radius=RADIUS, marker="tip"),
            DivotContacts(
                "flange",
                [3, 4],
                [[0, 0, 0], [1e-4, 0, -2e-4]],
                centre=[0.1, 0.2, 0.3],
                offset=OFFSET,
                measured_in="l1",
            ),
        ),
    )
    path = tmp_path / "c.json"
    write_measurements(path, data)
    back = read_measurements(path)
    (s,), (d,) = back.groups("sphere"), back.groups("divot")
    assert (s.radius, s.marker, s.sphere) == (RADIUS, "tip", "ball")
    np.testing.assert_array_equal(s.distance_m, [0.0, 1e-4, 0.0])
    assert d.measured_in == "l1" and d.divot == "divot"
    np.testing.assert_array_equal(d.centre, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(d.gap_m, [[0, 0, 0], [1e-4, 0, -2e-4]])
    head = (
        '{"format": "kinfw-measurements", "version": 1, "units": {"length": "mm", '
        '"angle": "rad"}, "joint_names": ["j1"], "samples": [{"q": [0], "observations": ['
    )
    path.write_text(
        head + '{"frame": "flange", "kind": "sphere", "sphere": "b", "radius": 12.5}, '
        '{"frame": "flange", "kind": "divot", "gap": [1, 2, 3], "marker": "tip"}]}]}'
    )
    m = read_measurements(path)
    assert m.groups("sphere")[0].radius == 0.0125  # mm -> m
    np.testing.assert_array_equal(m.groups("divot")[0].gap_m, [[1e-3, 2e-3, 3e-3]])
    for bad, match in (
        ('{"frame": "flange", "kind": "sphere", "radius": -1}', r"radius: a radius is >= 0"),
        ('{"frame": "flange", "kind": "divot", "xyz": [1, 2, 3]}', r"xyz.*no position"),
        (
            '{"frame": "flange", "kind": "sphere", "marker": "m", "offset": [0, 0, 1]}',
            "an offset and a marker",
        ),
    ):
        path.write_text(head + bad + "]}]}")
        with pytest.raises(DatasetError, match=match):
            read_measurements(path)


# -- what the contacts determine, noise-free -------------------------------------------------


def _held_out_distances(result, truth, ball, offset, radius):
    q = random_joint_values(truth, NAMES, 200, np.random.default_rng(12))
    found = _found(result)
    c = found["sphere", "ball"]
    r = c[3] if radius is None else radius
    pred = np.linalg.norm(_model_probe(result, q, offset) - c[:3], axis=1) - r
    true = np.linalg.norm(_probe(truth, q) - ball[:3], axis=1) - ball[3]
    assert np.abs(true).max() > 0.1  # held out: off the ball
    return pred, true


@pytest.mark.parametrize(("radius", "n_free"), [(RADIUS, 6), (None, 7)])
def test_ball_contacts_determine_the_robot_up_to_a_world_motion_and_without_radius_a_scale(
    scene, radius, n_free
):
    """Noise-free: every contact back on the ball; the null directions are the world
    motion (named so) and, with the radius unknown, the scale; held-out distances from
    the ball are the truth's exactly (radius given) or up to that scale."""
    nominal, truth, ball, _, on_ball, _ = scene
    result = refine(
        nominal, _spheres(on_ball, radius=radius), noise=NoiseModel(sigmas={"distance": 1e-4})
    )
    assert result.converged
    assert max(np.abs(g.component("distance")).max() for g in result.residuals) < 1e-10
    ident = result.identifiability
    assert ident.n_parameters - ident.rank == n_free
    named = [why for _, why in ident.unidentifiable if why == WORLD_MOTION]
    assert 0 < len(named) <= 6
    pred, true = _held_out_distances(
        result, truth, ball, _found(result)["offset", "flange:tip"], radius
    )
    if radius is not None:
        np.testing.assert_allclose(pred, true, rtol=0, atol=1e-9)
    else:  # the distances from the centre scale; compare those
        found_r = _found(result)["sphere", "ball"][3]
        scale = found_r / RADIUS
        assert 0.5 < scale < 2.0
        np.testing.assert_allclose(pred + found_r, scale * (true + RADIUS), rtol=0, atol=1e-9)


def test_point_contacts_determine_the_robot_up_to_a_world_motion_and_a_scale(scene):
    """Noise-free: every placement back on the point; the null directions are the world
    motion (a rotation about the point among them; named so) and the scale; held-out
    distances of the probe from the point are the truth's up to that scale."""
    nominal, truth, _, point, _, on_point = scene
    result = refine(nominal, _divots(on_point), noise=NoiseModel(sigmas={"placement": 1e-4}))
    assert result.converged
    assert max(np.abs(g.component("placement")).max() for g in result.residuals) < 1e-10
    ident = result.identifiability
    assert ident.n_parameters - ident.rank == 7
    assert 0 < sum(why == WORLD_MOTION for _, why in ident.unidentifiable) <= 6
    found = _found(result)
    q = random_joint_values(truth, NAMES, 200, np.random.default_rng(12))
    pred = np.linalg.norm(
        _model_probe(result, q, found["offset", "flange:tip"]) - found["divot", "divot"], axis=1
    )
    true = np.linalg.norm(_probe(truth, q) - point, axis=1)
    assert true.max() > 0.1
    scale = float(pred @ true / (true @ true))
    assert 0.5 < scale < 2.0
    np.testing.assert_allclose(pred, scale * true, rtol=0, atol=1e-9)


# -- noise statistics -------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["sphere", "divot"])
def test_the_held_out_rms_is_sigma_sqrt_1_plus_p_over_n(scene, kind):
    """Contacts with N(0, sigma) noise per row (sigma 0.1 mm), three training sets of 120
    contacts: the held-out RMS per row over 600 new noisy contacts (the same
    distribution), pooled, is ``sigma sqrt(1 + p / (n - p - 1))`` within 8 % (p the
    determined parameters, n the training rows: the prediction error of a least-squares
    fit at new points of its design's distribution; ``sqrt(1 + p / n)`` for n >> p, here
    2 % lower for a ball, 0.3 % for a point); the estimated sigma within 10 % of sigma.
    Measured: 1.055 and 1.003 times the expectation, sigma estimated 0.91 and 0.97."""
    nominal, truth, ball, point, _, _ = scene
    sigma, n = 1e-4, 120
    surface = {"sphere": ball} if kind == "sphere" else {"point": point}
    rows = 1 if kind == "sphere" else 3
    component = "distance" if kind == "sphere" else "placement"
    held = _on(truth, 600, 40, **surface)
    squares, ratios = [], []
    for seed in (41, 42, 43):
        rng = np.random.default_rng(seed)
        qs = _on(truth, n, seed, **surface)
        noise = rng.normal(0.0, sigma, (n, rows))
        data = _spheres(qs, distance=noise[:, 0]) if kind == "sphere" else _divots(qs, gap=noise)
        result = refine(nominal, data)
        found = _found(result)
        p_held = _model_probe(result, held, found["offset", "flange:tip"])
        test_noise = rng.normal(0.0, sigma, (len(held), rows))
        if kind == "sphere":
            pred = np.linalg.norm(p_held - found["sphere", "ball"], axis=1, keepdims=True) - RADIUS
        else:
            pred = p_held - found["divot", "divot"]
        squares.append(np.mean((test_noise - pred) ** 2))
        ident = result.identifiability
        p = ident.rank
        ratios.append(dict(result.noise.sigmas)[component] ** 2 / sigma**2)
    expected = sigma * np.sqrt(1 + p / (n * rows - p - 1))
    assert np.sqrt(np.mean(squares)) == pytest.approx(expected, rel=0.08)
    assert np.sqrt(np.mean(ratios)) == pytest.approx(1.0, rel=0.1)


def test_the_contacts_are_drawn_on_the_ball_and_at_the_point(scene):
    """The view's drawing: predicted, the probe (Pinocchio FK); measured, the point at the
    measured distance off the ball's surface (on the ray from its centre), or the point
    plus the measured gap."""
    _, truth, ball, point, on_ball, on_point = scene
    known = {offset_key("flange", "tip"): OFFSET, sphere_key("ball"): ball[:3]}
    ctx = NumericContext.from_robot(truth, on_ball, NAMES, known)
    (g,) = _spheres(on_ball, distance=np.full(60, 0.01)).others
    drawing = kind_of(g).drawing(g, ctx)
    assert drawing.node == "spheres/flange/ball@tip"
    np.testing.assert_allclose(drawing.w_p_predicted, _probe(truth, on_ball), rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        np.linalg.norm(drawing.w_p_measured - ball[:3], axis=1), RADIUS + 0.01, rtol=0, atol=1e-12
    )
    gap = np.random.default_rng(4).normal(0, 1e-3, (40, 3))
    (g,) = _divots(on_point, gap=gap).others
    ctx = NumericContext.from_robot(
        truth, on_point, NAMES, {offset_key("flange", "tip"): OFFSET, divot_key("divot"): point}
    )
    drawing = kind_of(g).drawing(g, ctx)
    assert drawing.node == "divots/flange/divot@tip"
    np.testing.assert_allclose(drawing.w_p_measured, point + gap, rtol=0, atol=1e-12)
    np.testing.assert_allclose(drawing.w_p_predicted, _probe(truth, on_point), rtol=0, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["sphere", "divot"])
def test_the_model_choice_scores_ball_and_point_contacts_in_their_metric(scene, kind):
    """Leave-one-out (closed form) on 60 ball contacts or 40 placements with 0.1 mm
    noise: every candidate scored in the kind's own metric (height mm; placement mm),
    finite, its whitened score the squared metric over the fit's sigma; the chosen candidate
    within 1 % of the best (the simplest such)."""
    from kinfw.identification import identify
    from kinfw.verification.evaluation import choose_parameters, whitening_noise

    nominal, _, _, _, on_ball, on_point = scene
    rng = np.random.default_rng(9)
    if kind == "sphere":
        data, metric = _spheres(on_ball, distance=rng.normal(0, 1e-4, 60)), "height"
    else:
        data, metric = _divots(on_point, gap=rng.normal(0, 1e-4, (40, 3))), "placement"
    prior = (3e-3, np.radians(1.72))
    choice = choose_parameters(nominal, data, prior=prior)
    whitened = [c.whitened for c in choice.candidates]
    assert np.all(np.isfinite(whitened)) and min(whitened) > 0
    for c in choice.candidates:
        assert [m.name for m, _ in c.errors] == [metric]
        assert [m.unit for m, _ in c.errors] == ["mm"]
    best = min(whitened)
    expected = next(c for c in choice.candidates if c.whitened <= 1.01 * best)
    assert (choice.parameters, choice.prior) == (expected.parameters, expected.prior)
    full = identify(nominal, data, parameters="full", prior=prior)
    component = "distance" if kind == "sphere" else "placement"
    (sigma,) = (v for c, v in whitening_noise(full.refined.noise, data) if c.name == component)
    for c in choice.candidates:  # the placement's size is the norm of its 3 rows
        size_mm = dict((m.name, v) for m, v in c.errors)[metric]
        assert c.whitened == pytest.approx((size_mm * 1e-3 / sigma) ** 2, rel=1e-6)
