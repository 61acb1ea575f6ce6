"""Leave-one-sample-out predictions of a calibration in closed form, linearised at the fit.

Cross-validation by refitting costs one calibration per fold and candidate (55 for the
default model choice's 11 candidates in 5 folds). At a converged fit the refit without
sample ``i`` is, to first order, one Gauss-Newton step from the full-data estimate
(the robust loss's weights held at the fit):

.. math::

    \\Delta_{-i} = (A - J_i^T W_i J_i)^{-1} J_i^T W_i r_i, \\qquad
    A = J^T W J + \\Lambda,

with ``J`` (N, P) and ``r`` (N,) the whitened Jacobian and residuals of every
observation at the fit (moving parameters only), ``W`` the rows' IRLS weights, ``Lambda``
the prior's Hessian (diagonal, ``1 / sigma^2``) and ``J_i, r_i, W_i`` the rows of sample
``i``. (The gradient ``J^T W r + Lambda (x - mu)`` is zero at the fit, so only the
removed rows' term is left.) The held-out prediction of sample ``i`` is then
``r_i + J_i Delta_{-i}``: exact for a linear model (the leave-one-out identity of
ridge regression, ``(I - H_ii)^{-1} r_i``), and for a calibration as good as the
linearisation over the change one sample makes -- small next to the noise for a fit
whose parameters are determined (``tests/verification/evaluation/test_loo.py`` checks it
against refits: to 2 % of the noise with the weights fixed). What the step holds fixed a
refit would move: the weights (a re-estimated noise, the robust loss's) and, when the
model lives in an external frame, the prior's centre (a refit centres it on its own
start). Every sample is predicted by a model that never saw it, with no random
partition: the score has no fold noise, and it costs one fit per candidate plus a
``(P, P)`` solve per sample (memory ``n P^2`` for ``n`` samples, linear in the samples).

The predictions are scored in each observed kind's metrics by the kinds themselves
(:func:`group_errors` on the predicted residual rows), so
every registered kind is scored as the refitting cross-validation scores it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.identification import Calibration
from kinfw.identification.problem import (
    LOSS_SCALE,
    build_problem,
    negligible_columns,
    row_weights,
    thresholds,
)
from kinfw.measurements import Measurements
from kinfw.model import BlockKey, Robot
from kinfw.observations import NumericContext, kind_of
from kinfw.verification.evaluation._accuracy import AccuracyReport, group_errors
from kinfw.verification.evaluation._crossval import fitted_unknowns

#: A sample whose removal leaves the normal matrix this close to singular (its smallest
#: eigenvalue over the full data's largest) determines a parameter alone: its held-out
#: prediction is undefined (a refit without it would fail).
SINGULAR = 1e-12


@dataclass(frozen=True, slots=True)
class LeaveOneOut:
    """Every sample predicted by the fit without it (linearised).

    Attributes
    ----------
    held : AccuracyReport
        The held-out errors, per observation group in its kind's metrics.
    undetermined : tuple of int
        Samples without which some parameter is undetermined (no prediction: NaN rows).
    """

    held: AccuracyReport
    undetermined: tuple[int, ...]


def leave_one_out(
    nominal: Robot,
    data: Measurements,
    fit: Calibration,
    *,
    parameters: str | tuple[str, ...],
    prior: tuple[float, float] | None,
    loss: str,
    trained_without: set[tuple[str, str, str | None, int]] = frozenset(),
) -> LeaveOneOut:
    """Leave-one-sample-out predictions of ``fit`` on ``data``, in closed form.

    Parameters
    ----------
    nominal : Robot
    data : Measurements
        The observations to predict (the fit's data, perhaps without some observations
        left out of the scores).
    fit : Calibration
        The calibration of ``parameters`` and ``prior`` with ``loss`` on the data
        (:func:`kinfw.identification.identify`, method ``"refine"``).
    parameters, prior, loss
        As the fit was made (they set the moving parameters, the prior's Hessian and the
        weights).
    trained_without : set of (kind, frame, marker, sample)
        Observations of ``data`` the fit did not train on (its rejected gross errors):
        weight zero, predicted by the full fit as they are.

    Returns
    -------
    LeaveOneOut
    """
    unknowns = fitted_unknowns(fit)
    model = Robot(fit.urdf_xml, "<fitted>")
    with warnings.catch_warnings():  # the data's warnings belong to the fit, said once
        warnings.simplefilter("ignore", UserWarning)
        problem = build_problem(
            nominal.with_spec(fit.spec),  # the fit's compliance..., as estimated
            data,
            start=model,
            known=unknowns,
            parameters=parameters,
            prior=prior,
        )
    sigma = fit.refined.noise
    r, J = problem.evaluate(np.zeros(problem.n_parameters), sigma, True, only_free=True)
    n_obs_rows = sum(len(g.sample) * g.rows for g in problem.groups)
    w = row_weights(r, problem.obs_sizes, loss, thresholds(problem.obs_components, LOSS_SCALE))
    w[:n_obs_rows] *= _trained_rows(problem.groups, trained_without)
    moving = problem.free.copy()
    moving[moving] = ~negligible_columns(J[:, moving])
    r_obs, J_obs, w_obs = r[:n_obs_rows], J[:n_obs_rows][:, moving], w[:n_obs_rows]
    hessian = np.zeros(problem.n_parameters)
    k = problem.prior_rows
    hessian[k] = 1.0 / problem.prior_sigma[k] ** 2
    A = J_obs.T @ (w_obs[:, None] * J_obs) + np.diag(hessian[moving])
    row_sample = np.concatenate([np.repeat(g.sample, g.rows) for g in problem.groups])
    predicted, undetermined = _held_out_rows(A, r_obs, J_obs, w_obs, row_sample)
    row_sigma = np.concatenate([np.tile(g.row_sigma(sigma), len(g.sample)) for g in problem.groups])
    raw = predicted * row_sigma
    context = NumericContext.from_robot(
        model, data.qs, data.joint_names, {BlockKey(u.kind, u.name): u.value for u in unknowns}
    )
    groups, o = [], 0
    for g in problem.groups:
        m = len(g.sample) * g.rows
        groups.append(group_errors(g, raw[o : o + m].reshape(len(g.sample), g.rows), context))
        o += m
    return LeaveOneOut(AccuracyReport(tuple(groups), ()), undetermined)


def _trained_rows(groups, trained_without: set[tuple[str, str, str | None, int]]) -> NDArray:
    """1 for each residual row the fit trained on, 0 for the rows of ``trained_without``
    (keyed ``(kind, frame, marker, sample)``), observation-major, group by group."""
    out = []
    for g in groups:
        key = (kind_of(g.group).name, g.frame, g.marker)
        kept = np.array([(*key, int(s)) not in trained_without for s in g.sample], dtype=float)
        out.append(np.repeat(kept, g.rows))
    return np.concatenate(out) if out else np.zeros(0)


def _held_out_rows(
    A: NDArray, r: NDArray, J: NDArray, w: NDArray, row_sample: NDArray
) -> tuple[NDArray, tuple[int, ...]]:
    """Each row's prediction ``r_i + J_i Delta_{-i}`` by the linearised fit without its
    sample (see the module's docstring), shape (N,), and the samples whose removal
    leaves ``A`` singular (their rows NaN)."""
    samples, inverse = np.unique(row_sample, return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    bounds = np.append(np.searchsorted(inverse[order], np.arange(len(samples))), len(order))
    # the directions the full data determine (a structurally redundant parameter, which
    # the fit leaves where its damping put it, is no one sample's to determine)
    values, vectors = np.linalg.eigh(A)
    largest = values[-1] if len(values) else 0.0
    V = vectors[:, values > SINGULAR * largest]
    JV, JwV = J @ V, (J * w[:, None]) @ V
    removed = np.empty((len(samples), V.shape[1], V.shape[1]))
    rhs = np.empty((len(samples), V.shape[1]))
    for i in range(len(samples)):  # one small (P, P) product per sample
        rows = order[bounds[i] : bounds[i + 1]]
        removed[i] = V.T @ A @ V - JV[rows].T @ JwV[rows]
        rhs[i] = JwV[rows].T @ r[rows]
    smallest = np.linalg.eigvalsh(removed)[:, 0] if V.shape[1] else np.ones(len(samples))
    singular = smallest <= SINGULAR * largest
    delta = np.zeros_like(rhs)
    ok = ~singular
    if ok.any():
        delta[ok] = np.linalg.solve(removed[ok], rhs[ok][..., None])[..., 0]
    predicted = r + np.einsum("nk,nk->n", JV, delta[inverse])
    predicted[singular[inverse]] = np.nan
    return predicted, tuple(int(s) for s in samples[singular])
