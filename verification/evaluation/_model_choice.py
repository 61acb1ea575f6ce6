"""Model choice by default: the parameter set and prior that predict held-out data best.

``kinfw calibrate`` (``--params auto``, the default) asks :func:`choose_parameters`
which model to fit. When the data is plentiful -- at least :data:`ROWS_PER_PARAMETER`
residual rows per free parameter of the full set -- every parameter can be estimated
and ``"full"`` is chosen without cross-validation (fast: ``kinfw demo``'s 85 samples give
about 20 rows per parameter). Otherwise the candidates are scored by k-fold
cross-validation (:func:`kinfw.verification.evaluation.crossvalidate`) and the one with the
lowest mean whitened held-out error wins (each observed kind's error in its own metric,
every noise component in units of its noise, so poses, points, image points, plane
contacts and registered kinds mix: :meth:`kinfw.verification.evaluation.CrossValidation.
whitened`):

- ``"frames"``: nominal joints, base and tool frames fitted;
- ``"offsets"``: frames plus joint zero offsets;
- ``"full"``: every identifiable CPC parameter;
- ``"full"`` with a Gaussian prior on the deviations from the nominal, its scale chosen
  by the same cross-validation from :data:`PRIOR_GRID_M` (lengths, m) and
  :data:`PRIOR_LEVERS_M` (angles ``sigma / lever`` rad): 8 priors.

The observations the robust full-data fit rejects as gross errors are left out of every
score (they stay in the training folds, where each fit rejects them itself): one 68 mm
sample in a fold of seven moves that fold's RMS more than the candidates differ.

Ties (within 1 %) go to the simpler model, in the order above. Identification does not
import this module; the CLI wires them.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from kinfw.identification import Calibration, calibrate
from kinfw.identification.problem import NoiseModel, build_problem
from kinfw.measurements import Measurements
from kinfw.model import Robot
from kinfw.observations import DatasetError, Metric
from kinfw.verification.evaluation._crossval import crossvalidate, whitening_noise

__all__ = [
    "PRIOR_GRID_M",
    "PRIOR_LEVERS_M",
    "ROWS_PER_PARAMETER",
    "Candidate",
    "ModelChoice",
    "choose_parameters",
]

#: Residual rows per free parameter of the full set from which "full" is chosen without
#: cross-validation (a least-squares rule of thumb: ten observations per unknown keep the
#: parameter scatter well below the model's bias for a well-excited robot).
ROWS_PER_PARAMETER = 10.0

#: Prior sigmas of lengths tried with "full", m.
PRIOR_GRID_M = (0.3e-3, 1e-3, 3e-3, 10e-3)

#: Lever arms converting a length sigma to an angle sigma (rad = m / lever): angles as
#: loose as lengths over 0.1 m (a joint zero off by 0.6 deg for 1 mm), or tight as over
#: 0.5 m (FIGAROH's default sizes: 1 mm, 2 mrad). Chosen on simulated data (five regimes
#: of three robots, ``benchmarks/study_model_choice.py``, 6 trials each): the picks of
#: this grid are 4-12 % closer to the truth than those of the 0.1 m lever alone over 1-10
#: mm in three regimes, within 1 % in the other two; 9-18 % closer than the parameter
#: sets without a prior where small data meets real errors.
PRIOR_LEVERS_M = (0.1, 0.5)


@dataclass(frozen=True, slots=True)
class Candidate:
    """One model scored by cross-validation.

    Attributes
    ----------
    parameters : str
        ``"frames"``, ``"offsets"`` or ``"full"``.
    prior : (float, float) or None
        ``(sigma_m, sigma_rad)`` of the Gaussian prior on deviations from the nominal.
    whitened : float
        Mean over folds of the whitened held-out error (about 6 for poses predicted to
        the noise, 3 for points, 1 for plane contacts; lower is better).
    errors : tuple of (Metric, float)
        Per metric of the data the mean over folds of its held-out RMS (display unit).
    failed : str or None
        Why the candidate could not be scored (a training fold too small for its
        parameters or its cameras: the fit's error message); its scores are then NaN
        and it is not chosen.
    """

    parameters: str
    prior: tuple[float, float] | None
    whitened: float
    errors: tuple[tuple[Metric, float], ...] = ()
    failed: str | None = None

    @property
    def label(self) -> str:
        """E.g. ``"full"`` or ``"full, prior 3 mm / 1.72 deg"``."""
        if self.prior is None:
            return self.parameters
        return (
            f"{self.parameters}, prior {1e3 * self.prior[0]:.3g} mm / "
            f"{np.degrees(self.prior[1]):.3g} deg"
        )


@dataclass(frozen=True, slots=True)
class ModelChoice:
    """The chosen parameter set and prior, and why.

    Attributes
    ----------
    parameters : str
        Set to calibrate with.
    prior : (float, float) or None
        ``(sigma_m, sigma_rad)`` to calibrate with.
    reason : str
        One line.
    candidates : tuple of Candidate
        Scores of every candidate, in the order tried; empty when cross-validation was
        skipped.
    rows_per_parameter : float
        Residual rows per free parameter of the full set on all the data.
    k : int
        Folds (0 when cross-validation was skipped).
    excluded : tuple of (sample, kind, frame, marker)
        Observations left out of every held-out score: those the full-data fit rejected
        as gross errors (:attr:`kinfw.verification.evaluation.CrossValidation.excluded`).
    """

    parameters: str
    prior: tuple[float, float] | None
    reason: str
    candidates: tuple[Candidate, ...]
    rows_per_parameter: float
    k: int
    excluded: tuple[tuple[int, str, str, str | None], ...] = ()

    @property
    def label(self) -> str:
        return Candidate(self.parameters, self.prior, np.nan).label

    def to_dict(self) -> dict:
        return {
            "parameters": self.parameters,
            "prior": None
            if self.prior is None
            else {"sigma_m": self.prior[0], "sigma_rad": self.prior[1]},
            "reason": self.reason,
            "rows_per_parameter": self.rows_per_parameter,
            "k": self.k,
            "excluded": [list(e) for e in self.excluded],
            "candidates": [
                {
                    "label": c.label,
                    "whitened": c.whitened,
                    **{m.headline: v for m, v in c.errors},
                    "failed": c.failed,
                }
                for c in self.candidates
            ],
        }


def rows_per_parameter(nominal: Robot, data: Measurements) -> float:
    """Residual rows of ``data`` per free parameter of the full set (inf without any)."""
    with warnings.catch_warnings():  # the data's warnings come once, from the calibration
        warnings.simplefilter("ignore")
        problem = build_problem(nominal, data, parameters="full")
    rows = sum(len(g.sample) * g.rows for g in problem.groups)
    return rows / problem.n_parameters if problem.n_parameters else float("inf")


def choose_parameters(
    nominal: Robot,
    data: Measurements,
    *,
    noise: NoiseModel | None = None,
    loss: str = "huber",
    k: int = 5,
    seed: int = 0,
    prior: tuple[float, float] | None = None,
) -> ModelChoice:
    """Choose the parameter set and prior that predict held-out data best.

    Parameters
    ----------
    nominal : Robot
    data : Measurements
    noise, loss
        As for :func:`kinfw.identification.calibrate` (``noise`` also whitens the
        scores; default: the noise the full-data fit estimates).
    k, seed : int
        Folds (at most the samples) and the seed of their partition.
    prior : (sigma_m, sigma_rad), optional
        A prior given by the user: every set is scored with it and no prior scale is
        searched.

    Returns
    -------
    ModelChoice
    """
    ratio = rows_per_parameter(nominal, data)
    if ratio >= ROWS_PER_PARAMETER:
        return ModelChoice(
            "full",
            prior,
            f"{ratio:.1f} residual rows per free parameter: enough to estimate every parameter",
            (),
            ratio,
            0,
        )
    k = min(k, data.n_samples)
    if k < 2:
        raise ValueError(
            f"choosing the parameters needs at least 2 samples for cross-validation, got "
            f"{data.n_samples}; give --params"
        )
    # the full-data fit: its noise whitens every score (the same scale for all), and the
    # observations it rejects as gross errors are left out of every score (one 68 mm
    # sample in a fold moves its RMS more than the models differ)
    reference = calibrate(nominal, data, parameters="full", noise=noise, loss=loss, prior=prior)
    sigma = whitening_noise(reference.refined.noise if noise is None else noise, data)
    candidates, excluded = [], ()
    for parameters, p in _runs(prior):
        candidate, cv_excluded = _score(
            nominal,
            data,
            parameters,
            p,
            k=k,
            seed=seed,
            noise=noise,
            loss=loss,
            reference=reference,
            sigma=sigma,
        )
        candidates.append(candidate)
        if cv_excluded is not None:
            excluded = cv_excluded
    _check_any_fitted(candidates, data.source, k)
    scored = [c.whitened for c in candidates if np.isfinite(c.whitened)]
    if not scored:  # no noise component with a held-out error to whiten
        return ModelChoice(
            "full",
            prior,
            f"{k}-fold cross-validation could not score these observations (no held-out "
            "error in a metric of the noise): the full set, as before",
            tuple(candidates),
            ratio,
            k,
        )
    chosen, why = _simplest_best(candidates, min(scored))
    if excluded:
        samples = ", ".join(str(e[0]) for e in excluded)
        why += f"; {len(excluded)} rejected observation(s) not scored (sample(s) {samples})"
    return ModelChoice(
        chosen.parameters,
        chosen.prior,
        f"{k}-fold cross-validation, {ratio:.1f} residual rows per free parameter of the "
        f"full set (< {ROWS_PER_PARAMETER:g}): {why}",
        tuple(candidates),
        ratio,
        k,
        excluded,
    )


def _check_any_fitted(candidates: list[Candidate], source: str, k: int) -> None:
    """Refuse data on which no candidate can be fitted on a training fold."""
    failed = [c for c in candidates if c.failed is not None]
    if len(failed) == len(candidates):
        raise DatasetError(
            f"{source}: too few samples to choose the parameters by {k}-fold "
            f"cross-validation: no candidate can be fitted on a training fold "
            f"({failed[0].label}: {failed[0].failed}); give --params (e.g. frames)"
        )


def _runs(prior: tuple[float, float] | None) -> list[tuple[str, tuple[float, float] | None]]:
    """The candidates ``(parameters, prior)`` in the order tried: frames, offsets, full
    (with the user's ``prior``), then, without one, full under each prior of the grid,
    strongest first."""
    runs = [(p, prior) for p in ("frames", "offsets", "full")]
    if prior is None:
        priors = [(s, s / lever) for s in PRIOR_GRID_M for lever in PRIOR_LEVERS_M]
        runs += [("full", p) for p in sorted(priors)]  # strongest first
    return runs


def _score(
    nominal: Robot,
    data: Measurements,
    parameters: str,
    prior: tuple[float, float] | None,
    *,
    k: int,
    seed: int,
    noise: NoiseModel | None,
    loss: str,
    reference: Calibration,
    sigma: NoiseModel,
) -> tuple[Candidate, tuple[tuple[int, str, str, str | None], ...] | None]:
    """One candidate scored by ``k``-fold cross-validation, whitened by ``sigma``, and the
    observations left out of its scores (None when it failed)."""
    try:
        cv = crossvalidate(
            nominal,
            data,
            k=k,
            seed=seed,
            sets=(parameters,),
            noise=noise,
            loss=loss,
            prior=prior,
            exclude_flagged=True,
            reference=reference,
        )
    except ValueError as exc:
        # the full data fit above: a training fold too small for these parameters
        # (a DatasetError), or to place a camera (three views per hand-eye)
        return Candidate(parameters, prior, np.nan, failed=str(exc)), None
    cv = replace(cv, noise=sigma)
    candidate = Candidate(
        parameters,
        prior,
        cv.whitened(parameters),
        tuple((m, cv.mean(parameters, m.name)) for m in cv.metrics),
    )
    return candidate, cv.excluded


def _simplest_best(candidates: list[Candidate], best: float) -> tuple[Candidate, str]:
    """The simplest candidate within 1 % of the ``best`` whitened error and why (against
    full alone, the third of :func:`_runs`)."""
    # simplest first: frames, offsets, full with the strongest prior ... full alone
    order = [0, 1, *range(3, len(candidates)), 2]
    full = candidates[2]
    chosen = next(candidates[i] for i in order if candidates[i].whitened <= 1.01 * best)
    if chosen is full:
        why = f"lowest held-out error ({chosen.whitened:.3g} whitened)"
    elif full.failed is not None:
        why = (
            f"lowest held-out error ({chosen.whitened:.3g} whitened); full alone cannot be "
            "fitted on a training fold (too few residuals for its parameters)"
        )
    else:
        (metric, mine), (_, theirs) = chosen.errors[0], full.errors[0]
        why = (
            f"lowest held-out error: {chosen.whitened:.3g} whitened vs {full.whitened:.3g} "
            f"for full alone ({metric.name} {mine:.3g} vs {theirs:.3g} {metric.unit})"
        )
    return chosen, why
