"""Tests of the Cramér-Rao bound (kinfw.verification.evaluation), the CRLB study and the robustness
study (kinfw.verification.studies, kinfw.verification.studies, kinfw.verification.studies)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinfw.geometry import matrix_from_rotation_vector, rotation_angle
from kinfw.identification.problem import NoiseModel, build_problem
from kinfw.measurements import concatenate_measurements
from kinfw.model import cpc_from_robot, load_robot
from kinfw.simulation import (
    default_target_pose,
    one_joint_at_a_time,
    perturb_robot,
    plant_outliers,
    random_configurations,
    simulate_at,
)
from kinfw.verification.evaluation import (
    cramer_rao,
    position_jacobians,
    predicted_position_rms,
    true_chart_coordinates,
)
from kinfw.verification.studies import (
    CRLBStudy,
    RobustStudy,
    crlb_study,
    format_crlb,
    format_robustness,
    plot_crlb,
    plot_robustness,
    robustness_study,
)
from kinfw.verification.studies import head_studies_main as main
from tests.paths import HEAD_URDF as IIS_HEAD

PLATES = ("left_plate", "right_plate")
CAMERAS = ("left_camera", "right_camera")
FRAMES = (*PLATES, *CAMERAS)
NOISE = NoiseModel(0.5e-3, np.radians(0.5) / np.sqrt(3.0))


@pytest.fixture(scope="module")
def head():
    return load_robot(IIS_HEAD)


@pytest.fixture(scope="module")
def experiment(head):
    """A small two-stage experiment built here: truth, data, true target pose."""
    rng = np.random.default_rng(3)
    truth = load_robot(perturb_robot(head, rng, origin_mm=5.0, origin_deg=1.0, axis_deg=1.0))
    names = head.topology(FRAMES).joint_names
    lower, upper = head.joint_limits(names)
    qs1, _ = one_joint_at_a_time(lower, upper, per_joint=3, fraction=0.8)
    qs2 = random_configurations(lower, upper, 10, rng, fraction=0.8)
    w_T_target = default_target_pose(truth, qs2, names, CAMERAS)
    noise = {"noise_m": 0.5e-3, "noise_rad": np.radians(0.5)}
    data = concatenate_measurements(
        simulate_at(truth, qs1, names, frames=PLATES, rng=rng, **noise),
        simulate_at(truth, qs2, names, cameras=CAMERAS, rng=rng, w_T_target=w_T_target, **noise),
    )
    test_qs = random_configurations(lower, upper, 25, rng, fraction=0.8)
    return {
        "truth": truth,
        "data": data,
        "w_T_target": w_T_target,
        "names": names,
        "test_qs": test_qs,
    }


@pytest.fixture(scope="module")
def bound(experiment):
    return cramer_rao(
        experiment["truth"],
        experiment["data"],
        FRAMES,
        noise=NOISE,
        targets={"target": experiment["w_T_target"]},
    )


@pytest.fixture(scope="module")
def small_study(head):
    return crlb_study(head, trials=4)


@pytest.fixture(scope="module")
def small_robust(head):
    return robustness_study(
        head,
        trials=2,
        n_test=60,
        variants=(
            ("linear", "given"),
            ("huber", "given"),
            ("cauchy", "given"),
            ("huber", "estimated"),
        ),
    )


def _model_qs(experiment, model):
    names = list(experiment["names"])
    return experiment["test_qs"][:, [names.index(j) for j in model.topology.joint_names]]


# -- the bound -------------------------------------------------------------------------


def test_casadi_position_jacobians_match_central_differences(bound, experiment):
    qs = _model_qs(experiment, bound.model)
    exact = position_jacobians(bound.model, qs, FRAMES, method="casadi")
    numeric = position_jacobians(bound.model, qs, FRAMES, method="finite_difference")
    assert exact.shape == (len(qs), 4, 3, bound.model.n_parameters)
    np.testing.assert_allclose(exact, numeric, atol=1e-8)


def test_predicted_rms_by_casadi_equals_finite_differences(bound, experiment):
    qs = _model_qs(experiment, bound.model)
    by_casadi = predicted_position_rms(bound, bound.model, qs, FRAMES)
    by_differences = predicted_position_rms(
        bound, bound.model, qs, FRAMES, method="finite_difference"
    )
    assert 1e-5 < by_casadi < 5e-3  # a fraction of a millimetre
    assert by_casadi == pytest.approx(by_differences, rel=1e-6)


def test_predicted_rms_is_the_root_mean_trace(bound, experiment):
    qs = _model_qs(experiment, bound.model)
    G = position_jacobians(bound.model, qs, FRAMES[:1], method="finite_difference")
    C = bound.model_covariance
    expected = np.sqrt(np.mean([np.trace(g @ C @ g.T) for g in G[:, 0]]))
    assert predicted_position_rms(bound, bound.model, qs, FRAMES[:1]) == pytest.approx(
        expected, rel=1e-6
    )


def test_bound_inverts_the_fisher_information(bound, experiment):
    # Independent information: J^T J of the whitened residuals at the truth, from a
    # problem built here (not through cramer_rao).
    problem = build_problem(
        experiment["truth"],
        experiment["data"],
        start=experiment["truth"],
        targets={"target": experiment["w_T_target"]},
    )
    _, J = problem.evaluate(np.zeros(problem.n_parameters), NOISE, True)
    free = problem.free  # the base and zero-offset blocks are fixed in the full set
    information = J[:, free].T @ J[:, free]
    assert bound.rank == free.sum() == 50
    assert bound.parameter_names == problem.names
    np.testing.assert_allclose(
        bound.covariance[np.ix_(free, free)] @ information, np.eye(50), atol=1e-6
    )
    np.testing.assert_allclose(bound.covariance, bound.covariance.T, rtol=0, atol=1e-18)


def test_bound_scales_with_the_noise_variance(bound, experiment):
    doubled = cramer_rao(
        experiment["truth"],
        experiment["data"],
        FRAMES,
        noise=NoiseModel(2 * NOISE.position_m, 2 * NOISE.rotation_rad),
        targets={"target": experiment["w_T_target"]},
    )
    np.testing.assert_allclose(doubled.covariance, 4.0 * bound.covariance, rtol=1e-6, atol=1e-20)


def test_cramer_rao_needs_the_true_target(experiment):
    with pytest.raises(ValueError, match="missing \\['target'\\]"):
        cramer_rao(experiment["truth"], experiment["data"], FRAMES, noise=NOISE, targets={})


def test_cramer_rao_checks_the_frames(experiment):
    with pytest.raises(ValueError, match="frames: expected the observed end frames"):
        cramer_rao(
            experiment["truth"],
            experiment["data"],
            PLATES,
            noise=NOISE,
            targets={"target": experiment["w_T_target"]},
        )
    with pytest.raises(TypeError, match="not a string"):
        cramer_rao(
            experiment["truth"],
            experiment["data"],
            "left_plate",
            noise=NOISE,
            targets={"target": experiment["w_T_target"]},
        )


def test_cramer_rao_checks_the_noise(experiment):
    with pytest.raises(ValueError, match=r"noise\.position_m"):
        cramer_rao(
            experiment["truth"],
            experiment["data"],
            FRAMES,
            noise=NoiseModel(0.0, 1e-3),
            targets={"target": experiment["w_T_target"]},
        )


def test_predicted_rms_rejects_another_chart(bound, experiment, head):
    plates_only = cpc_from_robot(head, PLATES)
    qs = np.zeros((3, plates_only.n_joints))
    with pytest.raises(ValueError, match="does not match the bound"):
        predicted_position_rms(bound, plates_only, qs, PLATES)
    with pytest.raises(ValueError, match="method"):
        predicted_position_rms(
            bound, bound.model, _model_qs(experiment, bound.model), FRAMES, method="complex_step"
        )
    with pytest.raises(ValueError, match="qs: expected"):
        predicted_position_rms(bound, bound.model, np.zeros((3, 2)), FRAMES)
    with pytest.raises(ValueError, match="frames: expected end frames"):
        predicted_position_rms(bound, bound.model, np.zeros((3, 6)), ("base",))


def test_true_chart_coordinates_reproduce_the_truth(head, experiment):
    # Chart around the nominal head and a target 3 cm / 2 deg off: the coordinates of
    # the truth must give back Pinocchio's FK of the true URDF and the true target.
    w_T_target = experiment["w_T_target"]
    rotvec = np.radians(2.0) * np.array([0.6, 0.0, 0.8])
    start_target = w_T_target.copy()
    start_target[:3, :3] = w_T_target[:3, :3] @ matrix_from_rotation_vector(rotvec)
    start_target[:3, 3] += [0.03, -0.01, 0.02]
    problem = build_problem(head, experiment["data"], targets={"target": start_target})
    x = true_chart_coordinates(problem, experiment["truth"], {"target": w_T_target})
    model = problem.model_at(x)
    qs = experiment["test_qs"]
    for frame in FRAMES:
        q_model = _model_qs(experiment, model)
        np.testing.assert_allclose(
            model.frame_poses(q_model, frame),
            experiment["truth"].frame_poses(qs, frame, experiment["names"]),
            atol=1e-9,
        )
    (target,) = problem.unknowns_at(x)
    np.testing.assert_allclose(target.value, w_T_target, atol=1e-12)


# -- the CRLB study --------------------------------------------------------------------


@pytest.mark.slow
def test_refined_error_reaches_the_bound(small_study):
    s = small_study
    assert s.crlb_rms_mm.shape == (4, 4)
    assert 0.7 <= s.pooled_ratio() <= 1.4
    assert 0.7 <= s.pooled_ratio("estimated_noise") <= 1.4
    # the refinement improves on its start, and the bound is below the start
    assert np.all(s.trial_rms_mm("refined") < s.trial_rms_mm("start"))


@pytest.mark.slow
def test_reported_covariance_covers_the_truth(small_study):
    s = small_study
    assert s.n_parameters == 50
    assert s.coverage(3.0) >= 0.9
    assert s.coverage(3.0, estimated_noise=True) >= 0.9
    assert 0.5 <= s.coverage(1.0) <= 0.85
    assert 0.7 <= s.nees.mean() / s.n_parameters <= 1.4


@pytest.mark.slow
def test_noise_estimate_is_within_20_percent(small_study):
    np.testing.assert_allclose(small_study.noise_ratio, 1.0, atol=0.2)


@pytest.mark.slow
def test_crlb_study_round_trips_through_json(small_study, tmp_path):
    doc = json.loads(json.dumps(small_study.to_dict()))
    again = CRLBStudy.from_dict(doc)
    np.testing.assert_array_equal(again.z, small_study.z)
    assert again.parameter_names == small_study.parameter_names
    assert format_crlb(again) == format_crlb(small_study)
    text = format_crlb(small_study)
    assert "| **all frames** |" in text and "NEES" in text
    path = plot_crlb(small_study, tmp_path / "crlb.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# -- outliers and the robust losses ----------------------------------------------------


def test_plant_outliers_moves_exactly_the_planted_observations(experiment):
    data = experiment["data"]
    corrupted, planted = plant_outliers(
        data, np.random.default_rng(0), fraction=0.1, distance_m=0.05, angle_rad=np.radians(5.0)
    )
    total = sum(len(g.sample) for g in (*data.poses, *data.targets))
    assert len(planted) == round(0.1 * total)
    moved = set()
    pairs = [
        ("pose", a.frame, a.sample, a.meas_T_frame, b.meas_T_frame)
        for a, b in zip(data.poses, corrupted.poses, strict=True)
    ]
    pairs += [
        ("target", a.camera, a.sample, a.camera_T_target, b.camera_T_target)
        for a, b in zip(data.targets, corrupted.targets, strict=True)
    ]
    for kind, frame, sample, before, after in pairs:
        distance = np.linalg.norm(after[:, :3, 3] - before[:, :3, 3], axis=1)
        angle = rotation_angle(np.swapaxes(before[:, :3, :3], 1, 2) @ after[:, :3, :3])
        for s, d, a in zip(sample, distance, angle, strict=True):
            if d > 0.0:
                moved.add((kind, frame, int(s)))
                assert d == pytest.approx(0.05, abs=1e-12)
                assert a == pytest.approx(np.radians(5.0), abs=1e-9)
            else:
                assert a == 0.0
    assert moved == planted


@pytest.mark.slow
def test_robust_losses_resist_planted_outliers(small_robust):
    s = small_robust
    clean = np.sqrt(np.mean(s.clean_rms_mm**2))
    pooled = np.sqrt(np.mean(s.rms_mm**2, axis=0))
    assert pooled[s.variant("huber")] < 1.5 * clean
    assert pooled[s.variant("cauchy")] < 1.5 * clean
    assert pooled[s.variant("linear")] > 3.0 * clean
    assert s.recall[s.variant("huber")] >= 0.8
    assert s.recall[s.variant("cauchy")] >= 0.8
    assert s.recall[s.variant("linear")] == 0.0
    assert s.false_alarm_rate[s.variant("huber")] < 0.03  # threshold: 1 % of clean ones


@pytest.mark.slow
def test_huber_with_estimated_noise_resists_planted_outliers(small_robust):
    s = small_robust
    clean = np.sqrt(np.mean(s.clean_rms_mm**2))
    pooled = np.sqrt(np.mean(s.rms_mm**2, axis=0))
    assert pooled[s.variant("huber", "estimated")] < 1.5 * clean


@pytest.mark.slow
def test_robust_study_reports_and_round_trips(small_robust, tmp_path):
    again = RobustStudy.from_dict(json.loads(json.dumps(small_robust.to_dict())))
    np.testing.assert_array_equal(again.flagged_clean, small_robust.flagged_clean)
    assert format_robustness(again) == format_robustness(small_robust)
    assert "| huber |" in format_robustness(small_robust)
    path = plot_robustness(small_robust, tmp_path / "robust.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_robustness_study_rejects_unknown_losses(head):
    with pytest.raises(ValueError, match="variants"):
        robustness_study(head, trials=1, variants=(("tukey", "given"),))
    with pytest.raises(ValueError, match="outlier_fraction"):
        robustness_study(head, trials=1, outlier_fraction=1.5)


@pytest.mark.slow
def test_main_writes_png_and_json_and_trials_do_not_depend_on_the_count(
    tmp_path, capsys, small_study
):
    assert main(["crlb", "--out", str(tmp_path), "--trials", "1"]) == 0
    out = capsys.readouterr().out
    assert "refined / CRLB" in out
    doc = json.loads((tmp_path / "crlb.json").read_text())
    assert doc["summary"]["trials"] == 1
    assert (tmp_path / "crlb.png").read_bytes()[:4] == b"\x89PNG"
    # trial 0 of a one-trial run is trial 0 of the four-trial study
    np.testing.assert_allclose(doc["refined_rms_mm"][0], small_study.refined_rms_mm[0], rtol=1e-9)
