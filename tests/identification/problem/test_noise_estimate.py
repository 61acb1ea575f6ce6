"""The noise that ``refine`` estimates, against the simulator's known sigma."""

from types import SimpleNamespace

import numpy as np
import pytest

from kinfw.geometry import rotation_vector_from_matrix
from kinfw.identification import refine
from kinfw.identification.problem import NoiseModel, estimate_noise, noise_shape
from kinfw.model import load_robot
from kinfw.observations import POSITION, ROTATION
from kinfw.simulation import (
    default_target_pose,
    perturb_poses,
    perturb_robot,
    plant_outliers,
    random_configurations,
    simulate_at,
)
from tests.paths import HEAD_URDF as HEAD

PLATES = ("left_plate", "right_plate")
CAMERAS = ("left_camera", "right_camera")
NOISE_M, NOISE_RAD = 0.5e-3, np.radians(0.5)
#: The truth per orientation component: an angle N(0, NOISE_RAD) about a random axis.
ROTATION_PER_COMPONENT = NOISE_RAD / np.sqrt(3.0)
SEEDS = (0, 1, 2, 3)


def _head_data(seed, n=120):
    nominal = load_robot(HEAD)
    rng = np.random.default_rng(seed)
    truth = load_robot(perturb_robot(nominal, rng, origin_mm=5.0, origin_deg=1.0, axis_deg=1.0))
    names = nominal.topology((*PLATES, *CAMERAS)).joint_names
    lower, upper = nominal.joint_limits(names)
    qs = random_configurations(lower, upper, n, rng, fraction=0.8)
    data = simulate_at(
        truth,
        qs,
        names,
        frames=PLATES,
        cameras=CAMERAS,
        rng=rng,
        w_T_target=default_target_pose(truth, qs, names, CAMERAS),
        noise_m=NOISE_M,
        noise_rad=NOISE_RAD,
    )
    return nominal, data


@pytest.fixture(scope="module")
def datasets():
    return [_head_data(seed) for seed in SEEDS]


def _mean_ratios(results):
    """Estimated over true sigma, (position, rotation per component), mean over seeds."""
    return np.mean(
        [
            (r.noise.position_m / NOISE_M, r.noise.rotation_rad / ROTATION_PER_COMPONENT)
            for r in results
        ],
        axis=0,
    )


@pytest.mark.slow
def test_robust_constants_match_the_simulated_noise_model():
    """Median, 99.9 % cut and trimmed moment of the whitened squared norms, sampled from
    the simulator's own noise (perturb_poses) rather than derived."""
    rng = np.random.default_rng(0)
    n, s_m, s_rad = 400_000, 1e-3, 1e-3
    noisy = perturb_poses(np.broadcast_to(np.eye(4), (n, 4, 4)), rng, s_m, s_rad)
    x_position = np.sum((noisy[:, :3, 3] / s_m) ** 2, axis=1)
    x_rotation = np.sum(
        (rotation_vector_from_matrix(noisy[:, :3, :3]) / (s_rad / np.sqrt(3.0))) ** 2, axis=1
    )
    for x, shape in ((x_position, noise_shape(POSITION)), (x_rotation, noise_shape(ROTATION))):
        assert np.mean(x) == pytest.approx(3.0, rel=0.01)  # whitened: unit variance per row
        assert np.mean(x < shape.median) == pytest.approx(0.5, abs=0.003)
        assert np.mean(x >= shape.cut) == pytest.approx(1e-3, abs=2e-4)
        assert np.mean(x[x < shape.cut]) / 3.0 == pytest.approx(shape.trimmed, rel=0.005)
    # the two shapes differ where a robust estimate looks: a chi2(3) median would be
    # 1.73 times too large for the orientations
    assert np.median(x_rotation) < 0.6 * noise_shape(POSITION).median


@pytest.mark.parametrize("orientation", ["angle about a random axis", "gaussian components"])
def test_the_robust_rounds_converge_to_the_true_sigma(orientation):
    """Residuals drawn with unit sigma per component, no fit (zero leverage): the robust
    rounds of refine (median, then trimmed moments) from a wrong start find sigma 1."""
    rng = np.random.default_rng(1)
    m = 100_000
    if orientation == "gaussian components":
        rotation = rng.normal(size=(m, 3))
    else:
        axes = rng.normal(size=(m, 3))
        axes /= np.linalg.norm(axes, axis=1, keepdims=True)
        rotation = axes * rng.normal(0.0, np.sqrt(3.0), size=(m, 1))
    position = rng.normal(size=(m, 3))
    group = SimpleNamespace(sample=np.arange(m), rows=6, components=(POSITION, ROTATION))
    sigma = NoiseModel(2.0, 0.5)
    for first in (True, False, False, False):
        r = np.concatenate([position / sigma.position_m, rotation / sigma.rotation_rad], axis=1)
        sigma = estimate_noise(r.ravel(), [group], sigma, np.zeros(6 * m), robust=True, first=first)
    assert sigma.position_m == pytest.approx(1.0, abs=0.01)
    assert sigma.rotation_rad == pytest.approx(1.0, abs=0.01)


@pytest.fixture(scope="module")
def huber_results(datasets):
    return [refine(nominal, data, loss="huber") for nominal, data in datasets]


@pytest.mark.slow
def test_the_estimated_noise_is_the_simulated_one(datasets, huber_results):
    np.testing.assert_allclose(_mean_ratios(huber_results), 1.0, atol=0.05)
    linear = [refine(nominal, data, loss="linear") for nominal, data in datasets]
    np.testing.assert_allclose(_mean_ratios(linear), 1.0, atol=0.05)


@pytest.mark.slow
def test_huber_flags_one_percent_of_clean_observations(datasets, huber_results):
    """The threshold is the 99 % quantile of a clean residual norm under the simulator's
    noise model (a pose: chi2(3) + 3 chi2(1)), so ~1 % of clean observations are flagged;
    a chi2(6) threshold flagged 3.4 % here. 1,920 observations: binomial sd 0.23 %."""
    n_obs = sum(len(g.sample) for _, data in datasets for g in (*data.poses, *data.targets))
    flagged = sum(len(r.downweighted) for r in huber_results)
    assert 0.003 < flagged / n_obs < 0.02, (flagged, n_obs)


@pytest.mark.slow
def test_the_robust_noise_estimate_resists_5_percent_gross_outliers(datasets):
    results = []
    for seed, (nominal, data) in zip(SEEDS, datasets, strict=True):
        corrupt, planted = plant_outliers(
            data,
            np.random.default_rng(100 + seed),
            fraction=0.05,
            distance_m=0.02,
            angle_rad=np.radians(10.0),
        )
        assert len(planted) >= 20
        results.append(refine(nominal, corrupt, loss="huber"))
    np.testing.assert_allclose(_mean_ratios(results), 1.0, atol=0.1)
