"""Closed-form leave-one-sample-out predictions against refits without each sample."""

import warnings

import numpy as np
import pytest

from kinfw.identification import identify
from kinfw.identification.problem import Unknown
from kinfw.model import load_robot
from kinfw.simulation import perturb_robot, random_configurations, simulate_at
from kinfw.verification.evaluation import held_out_errors, leave_one_out
from kinfw.verification.evaluation._loo import _held_out_rows

PLATES = ("left_plate", "right_plate")


def test_the_closed_form_is_the_leave_one_out_of_weighted_ridge_regression():
    """A linear model: the prediction of each sample's rows equals the refit without it
    (numpy's lstsq on the other rows, weighted, with the ridge rows of the prior), to
    1e-10; a parameter only one sample sees makes that sample's prediction undefined."""
    rng = np.random.default_rng(0)
    n, rows, P = 9, 3, 5
    J = rng.normal(size=(n * rows, P))
    x_true = rng.normal(size=P)
    y = J @ x_true + 0.1 * rng.normal(size=n * rows)
    w = rng.uniform(0.3, 1.0, size=n * rows)
    prior = np.array([0.0, 2.0, 0.0, 0.5, 0.0])  # ridge 1/sigma^2 on two parameters
    sample = np.repeat(np.arange(n), rows)
    sw = np.sqrt(w)

    def fit(keep):
        A = np.vstack([J[keep] * sw[keep, None], np.diag(np.sqrt(prior))])
        b = np.concatenate([y[keep] * sw[keep], np.zeros(P)])
        return np.linalg.lstsq(A, b, rcond=None)[0]

    x_hat = fit(np.ones(n * rows, bool))
    r = J @ x_hat - y  # residuals at the fit (its gradient, prior included, is zero)
    A = J.T @ (w[:, None] * J) + np.diag(prior)
    predicted, undetermined = _held_out_rows(A, r, J, w, sample)
    by_refit = np.concatenate(
        [J[sample == i] @ fit(sample != i) - y[sample == i] for i in range(n)]
    )
    assert undetermined == ()
    np.testing.assert_allclose(predicted, by_refit, atol=1e-10)
    # a column only sample 4 sees: without it that parameter is undetermined
    J2 = np.hstack([J, np.where(sample[:, None] == 4, 1.0, 0.0)])
    A2 = J2.T @ (w[:, None] * J2) + np.diag([*prior, 0.0])
    predicted2, undetermined2 = _held_out_rows(A2, r, J2, w, sample)
    assert undetermined2 == (4,)
    assert np.isnan(predicted2[sample == 4]).all() and np.isfinite(predicted2[sample != 4]).all()


def _refit_without_each(head, data, **options):
    """Position errors (m) of every held-out plate pose, each sample predicted by the
    calibration refitted without it, in the order of the closed form's ``values``."""
    out = {}
    for i in range(data.n_samples):
        keep = np.setdiff1d(np.arange(data.n_samples), [i])
        refit = identify(head, data.subset(keep), **options)
        unknowns = refit.refined.unknowns
        if refit.refined.model_frame is not None:
            unknowns = (*unknowns, Unknown("frame", refit.refined.model_frame, refit.w_T_root))
        held = held_out_errors(head, refit.urdf_xml, unknowns, data.subset([i]))
        out[i] = held.values("position")[0]
    return out


@pytest.mark.slow
@pytest.mark.parametrize("parameters, prior", [("frames", None), ("full", None)])
def test_the_closed_form_predicts_each_sample_as_a_refit_without_it(head, parameters, prior):
    """The IIS head (a truth 3 mm / 0.5 deg off), 16 noisy samples of both plates. With the
    weights fixed (noise given, least squares) every held-out plate position is the
    refit's to 2 % of the noise: what is left is the model's curvature. With the
    defaults (noise re-estimated by each refit, Huber) the closed form holds the full
    fit's weights, and its RMS is the refits' to 5 %."""
    from kinfw.identification.problem import NoiseModel

    truth = load_robot(
        perturb_robot(head, np.random.default_rng(2), origin_mm=3.0, origin_deg=0.5, axis_deg=0.3)
    )
    rng = np.random.default_rng(3)
    names = truth.topology(PLATES).joint_names
    qs = random_configurations(*truth.joint_limits(names), 16, rng, fraction=0.8)
    data = simulate_at(truth, qs, names, frames=PLATES, rng=rng, noise_m=1e-3, noise_rad=0.005)
    fixed = {"noise": NoiseModel(1e-3, 0.005), "loss": "linear"}
    for options in (fixed, {"loss": "huber"}):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            fit = identify(head, data, parameters=parameters, prior=prior, **options)
            loo = leave_one_out(
                head, data, fit, parameters=parameters, prior=prior, loss=options["loss"]
            )
            refits = _refit_without_each(head, data, parameters=parameters, prior=prior, **options)
        closed, samples = loo.held.values("position")
        refit = np.empty_like(closed)
        for i, values in refits.items():
            refit[samples == i] = values
        assert loo.undetermined == () and np.all(np.isfinite(closed))
        if options is fixed:
            assert np.max(np.abs(closed - refit)) < 0.02 * 1e-3
        else:
            rms = np.sqrt(np.mean(closed**2)), np.sqrt(np.mean(refit**2))
            assert rms[0] == pytest.approx(rms[1], rel=0.05)
