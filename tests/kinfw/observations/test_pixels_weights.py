"""Per-image pixel sigmas (``sigma_px``) weigh the images of a ``pixels`` group against
each other: against the true robot, with half the images 10x noisier, and against the
unweighted fit when the sigmas do not differ."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinfw.camera import CameraIntrinsics, Chessboard
from kinfw.identification import identify
from kinfw.identification.problem import Unknown, build_problem
from kinfw.model import Robot, load_robot
from kinfw.observations import pixel_weights
from kinfw.verification.evaluation import evaluate_model
from kinfw.verification.studies import arm_experiment, camera_target_errors, target_pose
from tests.robots import ARM_6R

BOARD = Chessboard(9, 6, 0.04)
CAMERA = CameraIntrinsics(640, 480, 600.0, 600.0, 319.5, 239.5, name="flange")
Q0 = np.array([0.3, -0.4, 0.9, 0.2, 0.7, -0.3])
SHARP_PX, BLURRY_PX = 0.3, 3.0


def _experiment(seed: int):
    """Noise-free images of the arm's flange camera, then per image N(0, s) pixel noise,
    s alternating 0.3 px and 3 px: the data with and without the stated sigmas, and the
    true (noise-free) pixels."""
    exp = arm_experiment(
        load_robot(ARM_6R), seed, camera="flange", intrinsics=CAMERA, q0=Q0, board=BOARD,
        sigma_px=0.0, n_images=20, n_test=30,
    )  # fmt: skip
    (g,) = exp.data.groups("pixels")
    rng = np.random.default_rng(1000 + seed)
    sigma = np.empty(len(g.sample))
    _, rows = g.images()
    for k, r in enumerate(rows):
        sigma[r] = SHARP_PX if k % 2 == 0 else BLURRY_PX
    uv = g.uv + rng.normal(size=g.uv.shape) * sigma[:, None]
    stated = replace(g, uv=uv, sigma_px=sigma)
    unstated = replace(g, uv=uv, sigma_px=np.full(len(sigma), np.nan))
    return exp, exp.data.with_groups([stated]), exp.data.with_groups([unstated]), g.uv


def _rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


def test_weights_against_hand_values():
    _, stated, _, _ = _experiment(0)
    (g,) = stated.groups("pixels")
    w = pixel_weights(g)
    # 10 sharp and 10 blurry images: the median of the images' sigmas is 1.65 px
    ref = 0.5 * (SHARP_PX + BLURRY_PX)
    np.testing.assert_allclose(w[g.sigma_px == SHARP_PX], ref / SHARP_PX, rtol=1e-15)
    np.testing.assert_allclose(w[g.sigma_px == BLURRY_PX], ref / BLURRY_PX, rtol=1e-15)
    # images without a sigma weigh 1; the median is over the images that state one
    sigma = g.sigma_px.copy()
    _, rows = g.images()
    sigma[rows[0]] = np.nan
    sigma[rows[1]] = 1.0  # sigmas stated: 9 x 0.3, 1 x 1, 9 x 3 -> median 1
    w = pixel_weights(replace(g, sigma_px=sigma))
    assert (w[rows[0]] == 1.0).all() and (w[rows[1]] == 1.0).all()
    np.testing.assert_allclose(w[rows[3]], 1.0 / BLURRY_PX, rtol=1e-15)
    np.testing.assert_allclose(w[rows[2]], 1.0 / SHARP_PX, rtol=1e-15)


@pytest.mark.slow
def test_weighted_images_beat_unweighted_and_are_chi_square_consistent():
    """Over 5 seeds the held-out camera_T_target error with the stated sigmas is at
    least 1.5x smaller (median of the ratios of RMS position and rotation errors) than
    with none; the weighted residual whitened by the median sigma has RMS ~ 1."""
    ratios_p, ratios_r, chi = [], [], []
    for seed in range(5):
        exp, stated, unstated, _ = _experiment(seed)
        errors = {}
        for name, data in (("weighted", stated), ("unweighted", unstated)):
            result = identify(exp.nominal, data, method="refine", loss="linear")
            robot = Robot(result.urdf_xml, name)
            errors[name] = camera_target_errors(exp, robot, target_pose(result.refined.unknowns))
            if name == "weighted":
                (g,) = stated.groups("pixels")
                (res,) = result.refined.residuals
                e = res.component("pixel")  # unweighted pixel errors
                w = pixel_weights(g)[:, None]
                ref = 0.5 * (SHARP_PX + BLURRY_PX)
                n, p = e.size, result.refined.identifiability.n_parameters
                chi.append(float(np.sum((w * e / ref) ** 2) / (n - p)))
        ratios_p.append(np.sqrt(errors["unweighted"][0] / errors["weighted"][0]))
        ratios_r.append(np.sqrt(errors["unweighted"][1] / errors["weighted"][1]))
    print("position ratio", np.round(ratios_p, 2), "rotation ratio", np.round(ratios_r, 2))
    print("chi2 / dof", np.round(chi, 3))
    assert np.median(ratios_p) > 1.5, ratios_p
    assert np.median(ratios_r) > 1.5, ratios_r
    # per seed ~ chi2(n - p) / (n - p) with n - p ~ 2000: std 0.03
    assert all(0.85 < c < 1.15 for c in chi), chi


def test_reported_pixel_errors_are_unweighted():
    """verify's pixel errors and the fit's residuals are measured minus predicted
    pixels, whatever the weights: against the true robot and board, the noise added."""
    exp, stated, _, uv_true = _experiment(1)
    (g,) = stated.groups("pixels")
    noise = g.uv - uv_true
    # kinfw verify with the true robot (the board's pose from the images' PnP, near the
    # truth): each image's errors are of its own noise's size (weighted, the sharp ones
    # would be 5.5x and the blurry ones 0.55x it)
    (ge,) = evaluate_model(exp.truth, stated).groups
    sharp = g.sigma_px == SHARP_PX
    for rows in (sharp, ~sharp):
        ratio = _rms(ge.of("pixel").vectors[rows]) / _rms(noise[rows])
        assert 0.8 < ratio < 1.2, ratio
    # with the true board given, the fit's residual is the weighted noise exactly
    problem = build_problem(
        exp.truth, stated, parameters="none", known=(Unknown("target", "board", exp.w_T_board),)
    )
    ((r, _),) = problem.raw_residuals(np.zeros(problem.n_parameters), with_jacobian=False)
    np.testing.assert_allclose(r, pixel_weights(g)[:, None] * noise, atol=1e-6)


@pytest.mark.slow
def test_equal_or_no_sigmas_change_nothing():
    exp, _, unstated, _ = _experiment(2)
    (g,) = unstated.groups("pixels")
    same = unstated.with_groups([replace(g, sigma_px=np.full(len(g.sample), 0.7))])
    assert (pixel_weights(g) == 1.0).all()
    results = [identify(exp.nominal, d, method="refine", loss="linear") for d in (unstated, same)]
    a, b = (r.refined for r in results)
    for ua, ub in zip(a.unknowns, b.unknowns, strict=True):
        np.testing.assert_allclose(ua.value, ub.value, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.covariance, b.covariance, rtol=1e-12, atol=0)
    assert results[0].urdf_xml == results[1].urdf_xml
