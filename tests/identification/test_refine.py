"""Joint nonlinear least squares: exactness, the CasADi graph, statistics, robustness."""

import warnings
from dataclasses import replace

import numpy as np
import pytest

from kinfw.geometry import inverse_transform, matrix_from_rotation_vector
from kinfw.identification import refine
from kinfw.identification.problem import NoiseModel, build_problem
from kinfw.measurements import Measurements, concatenate_measurements
from kinfw.model import cpc_from_robot, geometry_from_cpc, load_robot
from kinfw.simulation import default_target_pose, perturb_robot, random_configurations, simulate_at
from kinfw.urdf import export_urdf
from kinfw.verification.evaluation import pose_discrepancy, random_joint_values
from tests.paths import HEAD_URDF as HEAD
from tests.robots import ARM_6R

PLATES = ("left_plate", "right_plate")
CAMERAS = ("left_camera", "right_camera")
SIGMA = NoiseModel(0.5e-3, np.radians(0.5) / np.sqrt(3.0))


def _head_data(seed=0, n=40, noise_m=0.0, noise_rad=0.0, error_mm=5.0, error_deg=1.0):
    nominal = load_robot(HEAD)
    rng = np.random.default_rng(seed)
    truth = load_robot(
        perturb_robot(nominal, rng, origin_mm=error_mm, origin_deg=error_deg, axis_deg=error_deg)
    )
    names = nominal.topology((*PLATES, *CAMERAS)).joint_names
    lower, upper = nominal.joint_limits(names)
    qs = random_configurations(lower, upper, n, rng, fraction=0.8)
    w_T_target = default_target_pose(truth, qs, names, CAMERAS)
    data = simulate_at(
        truth,
        qs,
        names,
        frames=PLATES,
        cameras=CAMERAS,
        rng=rng,
        w_T_target=w_T_target,
        noise_m=noise_m,
        noise_rad=noise_rad,
    )
    return nominal, truth, data, w_T_target


def test_noise_free_data_from_the_nominal_gives_the_truth_through_the_urdf():
    nominal, truth, data, w_T_target = _head_data()
    result = refine(nominal, data, noise=SIGMA)
    assert result.converged
    calibrated = load_robot(export_urdf(nominal, geometry_from_cpc(result.model)).urdf_xml)
    names = result.model.topology.joint_names
    qs = random_joint_values(nominal, names, 100, np.random.default_rng(1))
    for frame in (*PLATES, *CAMERAS):
        dp, dr = pose_discrepancy(
            calibrated.frame_poses(qs, frame, names), truth.frame_poses(qs, frame, names)
        )
        assert dp < 1e-9 and dr < 1e-9, (frame, dp, dr)
    (target,) = [u for u in result.unknowns if u.kind == "target"]
    np.testing.assert_allclose(target.value, w_T_target, atol=1e-9)
    assert result.identifiability.rank == result.identifiability.n_parameters == 50


def test_casadi_residuals_equal_an_independent_numpy_computation():
    nominal, _, data, _ = _head_data(noise_m=1e-3, noise_rad=0.01)
    problem = build_problem(nominal, data)
    r, _ = problem.evaluate(np.zeros(problem.n_parameters), SIGMA, False)
    model = cpc_from_robot(nominal, data.observed_frames)
    q = data.q_of(model.topology.joint_names)
    pose = data.poses[0]
    T = model.frame_poses(q[pose.sample], pose.frame)
    expected_p = (pose.meas_T_frame[:, :3, 3] - T[:, :3, 3]) / SIGMA.position_m
    E = np.swapaxes(T[:, :3, :3], 1, 2) @ pose.meas_T_frame[:, :3, :3]
    expected_r = (
        0.5
        * np.stack(
            [E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]], axis=1
        )
        / SIGMA.rotation_rad
    )
    block = r[: 6 * len(pose.sample)].reshape(-1, 6)
    np.testing.assert_allclose(block[:, :3], expected_p, atol=1e-9)
    np.testing.assert_allclose(block[:, 3:], expected_r, atol=1e-9)


def test_jacobian_equals_central_differences():
    nominal, _, data, _ = _head_data(n=10, noise_m=1e-3, noise_rad=0.01)
    problem = build_problem(nominal, data)
    x = np.random.default_rng(2).normal(size=problem.n_parameters) * 1e-3
    _, J = problem.evaluate(x, SIGMA, True)
    h = 1e-6
    for k in range(0, problem.n_parameters, 7):
        e = np.zeros(problem.n_parameters)
        e[k] = h
        numeric = (
            problem.evaluate(x + e, SIGMA, False)[0] - problem.evaluate(x - e, SIGMA, False)[0]
        ) / (2 * h)
        np.testing.assert_allclose(J[:, k], numeric, rtol=1e-5, atol=1e-4)


def test_the_estimate_does_not_depend_on_sample_order():
    nominal, _, data, _ = _head_data(noise_m=0.5e-3, noise_rad=0.01)
    perm = np.random.default_rng(3).permutation(data.n_samples)
    a = refine(nominal, data, noise=SIGMA)
    b = refine(nominal, data.subset(perm), noise=SIGMA)
    qs = random_joint_values(nominal, a.model.topology.joint_names, 50, np.random.default_rng(0))
    dp, dr = pose_discrepancy(a.model.frame_poses(qs), b.model.frame_poses(qs))
    assert dp < 1e-9 and dr < 1e-9


def test_the_noise_is_estimated_and_the_fit_is_consistent():
    nominal, _, data, _ = _head_data(n=150, noise_m=0.5e-3, noise_rad=np.radians(0.5))
    result = refine(nominal, data)
    assert result.noise.estimated
    assert result.noise.position_m == pytest.approx(0.5e-3, rel=0.1)
    assert result.noise.rotation_rad == pytest.approx(np.radians(0.5) / np.sqrt(3), rel=0.1)
    assert result.sigma_hat2 == pytest.approx(1.0, abs=0.05)
    assert np.all(result.std[: result.model.n_parameters] > 0)


@pytest.mark.slow
@pytest.mark.parametrize("loss", ["linear", "huber"])
def test_the_noise_rounds_stop_at_their_fixed_point(loss):
    """The noise rounds stop once the estimate settles (fewer than five when it does):
    then the estimate is the fit under its own noise estimate, to a small fraction of its
    standard errors, and that noise is what the fit's residuals estimate again."""
    nominal, _, data, _ = _head_data(n=150, noise_m=0.5e-3, noise_rad=np.radians(0.5))
    result = refine(nominal, data, loss=loss, reject=None)
    again = refine(nominal, data, noise=result.noise, loss=loss, reject=None)
    free = result.std > 0
    moved = np.abs(again.estimate - result.estimate)[free] / result.std[free]
    assert moved.max() < 1e-2, moved.max()
    longer = refine(nominal, data, loss=loss, reject=None, noise_rounds=20)
    assert dict(longer.noise.sigmas) == pytest.approx(dict(result.noise.sigmas), rel=1e-3)


@pytest.mark.slow
def test_gross_outliers_are_downweighted_by_the_robust_loss():
    nominal, truth, data, _ = _head_data(n=100, noise_m=0.5e-3, noise_rad=0.005)
    rng = np.random.default_rng(4)
    pose = data.poses[0]
    bad = rng.choice(len(pose.sample), 5, replace=False)
    T = pose.meas_T_frame.copy()
    T[bad, :3, 3] += rng.normal(size=(5, 3)) * 0.03  # ~50 mm
    corrupt = replace(data, poses=(replace(pose, meas_T_frame=T), *data.poses[1:]))
    qs = random_joint_values(nominal, data.joint_names, 200, np.random.default_rng(5))
    truth_model = cpc_from_robot(truth, corrupt.observed_frames)

    def held_out_rms(result):
        d = result.model.frame_poses(qs)[..., :3, 3] - truth_model.frame_poses(qs)[..., :3, 3]
        return float(np.sqrt(np.mean(np.sum(d**2, axis=-1))))

    clean = held_out_rms(refine(nominal, data, noise=SIGMA))
    linear = held_out_rms(refine(nominal, corrupt, noise=SIGMA))
    # down-weighting alone (no rejection: tests/identification/test_rejection.py)
    robust = refine(nominal, corrupt, noise=SIGMA, loss="cauchy", reject=None)
    flagged = {
        s for kind, frame, s, _ in robust.downweighted if kind == "pose" and frame == pose.frame
    }
    assert set(pose.sample[bad]) <= flagged
    assert held_out_rms(robust) < 1.3 * clean < linear


def test_unobserved_orientation_is_reported_not_identifiable():
    """Points at the flange origin say nothing about the flange's orientation."""
    nominal = load_robot(ARM_6R)
    rng = np.random.default_rng(6)
    truth = load_robot(perturb_robot(nominal, rng))
    names = nominal.joint_names
    qs = random_configurations(*nominal.joint_limits(names), 60, rng, fraction=0.5)
    data = simulate_at(truth, qs, names, markers=(("flange", np.zeros(3)),), rng=rng)
    result = refine(nominal, data, noise=SIGMA)
    reasons = dict((frozenset(p), why) for p, why in result.identifiability.unidentifiable)
    rot = frozenset({("flange", "rot_x"), ("flange", "rot_y"), ("flange", "rot_z")})
    assert any(k <= rot and "only positions" in why for k, why in reasons.items())
    assert result.identifiability.rank == result.identifiability.n_parameters - 3


@pytest.mark.parametrize(("loss", "noise"), [("linear", SIGMA), ("huber", None)])
def test_no_free_parameter_gives_the_nominal_and_undefined_conditioning(loss, noise):
    """Plates in the root frame with ``parameters="none"``: nothing to estimate."""
    nominal, _, data, _ = _head_data(n=10, noise_m=0.5e-3, noise_rad=0.005)
    data = replace(data, targets=())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = refine(nominal, data, noise=noise, loss=loss, parameters="none")
    ident = result.identifiability
    assert (ident.rank, ident.n_parameters) == (0, 0)
    assert np.isnan(ident.condition) and np.isnan(ident.observability_o1)
    assert not np.any(result.estimate) and not np.any(result.covariance)
    for group, res in zip(data.poses, result.residuals, strict=True):
        nominal_p = nominal.frame_poses(
            data.q_of(data.joint_names)[group.sample], group.frame, data.joint_names
        )[:, :3, 3]
        np.testing.assert_allclose(
            res.position_m, group.meas_T_frame[:, :3, 3] - nominal_p, atol=1e-12
        )


@pytest.mark.slow
def test_markers_measured_in_an_external_frame_are_recovered():
    """Mocap markers of unknown offset on the flange, measured in 'mocap' (not in the URDF):
    the model lives in the mocap frame and the root's pose comes from the export."""
    nominal = load_robot(ARM_6R)
    rng = np.random.default_rng(7)
    truth = load_robot(perturb_robot(nominal, rng))
    names = nominal.joint_names
    qs = random_configurations(*nominal.joint_limits(names), 80, rng, fraction=0.6)
    mocap_T_root = np.eye(4)
    mocap_T_root[:3, :3] = matrix_from_rotation_vector([0.3, -0.2, 1.0])
    mocap_T_root[:3, 3] = [1.0, -0.5, 0.2]
    offsets = {"m1": [0.05, 0.0, 0.0], "m2": [0.0, 0.04, 0.01], "m3": [0.0, 0.0, 0.06]}
    data = simulate_at(
        truth,
        qs,
        names,
        markers=[("flange", np.array(o), name) for name, o in offsets.items()],
        rng=rng,
    )
    known = simulate_at(
        truth, qs, names, markers=(("flange", np.array([0.02, 0.02, 0.0])),), rng=rng
    )
    data = concatenate_measurements(data, known)
    moved = tuple(
        replace(
            g,
            meas_p_point=g.meas_p_point @ mocap_T_root[:3, :3].T + mocap_T_root[:3, 3],
            measured_in="mocap",
        )
        for g in data.points
    )
    data = Measurements(data.joint_names, data.qs, points=moved)
    result = refine(nominal, data, noise=SIGMA)
    assert result.model_frame == "mocap"
    export = export_urdf(nominal, geometry_from_cpc(result.model), root_is_measurement_frame=False)
    calibrated = load_robot(export.urdf_xml)
    for name, offset in offsets.items():
        (u,) = [u for u in result.unknowns if u.name == f"flange:{name}"]
        q_test = random_joint_values(nominal, names, 30, np.random.default_rng(8))
        pred = export.w_T_root @ calibrated.frame_poses(q_test, "flange", names)
        true = mocap_T_root @ truth.frame_poses(q_test, "flange", names)
        np.testing.assert_allclose(
            pred[:, :3, :3] @ u.value + pred[:, :3, 3],
            true[:, :3, :3] @ offset + true[:, :3, 3],
            atol=1e-9,
        )
    assert inverse_transform(export.w_T_root).shape == (4, 4)


def test_a_bad_loss_is_refused():
    nominal, _, data, _ = _head_data(n=5)
    with pytest.raises(ValueError, match="loss: expected one of"):
        refine(nominal, data, loss="l1")


def test_under_a_prior_joint_zero_offsets_are_estimated_as_offsets():
    """A truth that differs from the nominal 6R arm only in two encoder zeros (joint
    origins turned about their own axes by 1 and -2 deg). With a prior, "full" estimates
    the zero offsets too: the least-prior-cost fit of noise-free flange poses puts most
    of each correction (> 50 %) in the one offset angle rather than spreading it over
    every axis below the joint, and predicts the truth's flange at new configurations
    to 1e-6 m. Without a prior the offsets are redundant with the chart and not free."""
    from kinfw.geometry import matrix_from_rotation_vector as rotvec
    from kinfw.urdf import edit_urdf

    nominal = load_robot(ARM_6R)
    offsets = {"j2": np.radians(1.0), "j4": np.radians(-2.0)}
    origins = {}
    for name, delta in offsets.items():
        j = nominal.joint(name)
        T = j.parent_T_child.copy()
        T[:3, :3] = T[:3, :3] @ rotvec(delta * np.asarray(j.axis))
        origins[name] = T
    truth = load_robot(edit_urdf(nominal.urdf_xml, joint_origins=origins))
    names = nominal.topology(("flange",)).joint_names
    rng = np.random.default_rng(3)
    qs = random_configurations(*nominal.joint_limits(names), 30, rng, fraction=0.8)
    data = simulate_at(truth, qs, names, frames=("flange",), rng=rng)
    noise = NoiseModel(1e-6, 1e-6)
    fit = refine(nominal, data, parameters="full", prior=(1e-3, 1e-2), noise=noise)
    estimate = dict(zip(fit.parameter_names, fit.estimate, strict=True))
    for name, delta in offsets.items():
        assert 0.5 < estimate[(name, "zero_offset")] / delta <= 1.0
    q = random_configurations(*nominal.joint_limits(names), 20, rng, fraction=0.8)
    err = fit.model.frame_poses(q)[:, 0, :3, 3] - truth.frame_poses(q, "flange", names)[:, :3, 3]
    assert np.abs(err).max() < 1e-6
    plain = refine(nominal, data, parameters="full", noise=noise)
    free = dict(zip(plain.parameter_names, plain.free, strict=True))
    assert not any(free[(name, "zero_offset")] for name in offsets)
    free = dict(zip(fit.parameter_names, fit.free, strict=True))
    assert all(free[(name, "zero_offset")] for name in offsets)
