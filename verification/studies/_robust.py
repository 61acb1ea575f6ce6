"""Robustness to outliers: refinement of the head experiment with planted gross errors.

:func:`robustness_study` plants gross errors in a fraction of the observations of the
two-stage head experiment (:mod:`kinfw.verification.studies`;
:func:`kinfw.simulation.plant_outliers`: a fixed distance in a random direction and
a fixed angle about a random axis) and compares the held-out error of the linear, Huber
and Cauchy losses with the result on the clean data, and counts how many planted outliers
the robust loss down-weights (``refine``'s ``downweighted``: weight below 0.5) and how
many clean observations it down-weights too.
:func:`kinfw.verification.studies.format_robustness` writes the table,
:func:`kinfw.verification.studies.plot_robustness` the figure.

References
----------
P. J. Huber, "Robust estimation of a location parameter", 1964 (the Huber loss).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.identification import refine
from kinfw.model import CPCModel, Robot, cpc_from_robot
from kinfw.simulation import plant_outliers
from kinfw.verification.evaluation import check_count, run_trials
from kinfw.verification.studies._common import arrays_from, freeze, json_lists
from kinfw.verification.studies._head_experiment import (
    ExperimentSetup,
    check_positive,
    pipeline_start,
    position_ms,
    setup_experiment,
    simulate_experiment,
)

log = logging.getLogger(__name__)

_OUTLIER_TAG = 8  # seeds (kinfw.verification.studies's docstring)


#: Default variants of the robustness study: (loss, "given" | "estimated" noise).
ROBUST_VARIANTS = (
    ("linear", "given"),
    ("huber", "given"),
    ("cauchy", "given"),
    ("huber", "estimated"),
    ("cauchy", "estimated"),
)


#: The per-trial arrays of :class:`RobustStudy`, in the order its JSON lists them, and
#: their dtypes.
_ROBUST_ARRAYS = {
    "clean_rms_mm": float,
    "start_rms_mm": float,
    "rms_mm": float,
    "n_observations": np.int64,
    "n_planted": np.int64,
    "flagged_planted": np.int64,
    "flagged_clean": np.int64,
    "noise_used": float,
    "seconds": float,
}


@dataclass(frozen=True, slots=True)
class RobustStudy:
    """Refinement with planted gross errors, per loss.

    Attributes
    ----------
    setup : ExperimentSetup
    outlier_fraction : float
        Fraction of the observations (pose or target, each one sample of one frame)
        corrupted.
    outlier_mm, outlier_deg : float
        Each outlier's position error (mm, random direction) and rotation error (deg,
        random axis).
    variants : tuple of (loss, noise)
        ``noise`` is ``"given"`` (the true noise) or ``"estimated"``.
    clean_rms_mm : ndarray, shape (T,)
        Held-out RMS position error (frames and configurations) of the linear
        refinement on the clean data, true noise given, mm: the reference.
    start_rms_mm : ndarray, shape (T,)
        The same for the pipeline start computed from the corrupted data.
    rms_mm : ndarray, shape (T, V)
        The same for each variant on the corrupted data.
    n_observations, n_planted : ndarray of int64, shape (T,)
    flagged_planted, flagged_clean : ndarray of int64, shape (T, V)
        Planted outliers and clean observations in ``refine``'s ``downweighted``.
    noise_used : ndarray, shape (T, V, 2)
        The whitening of each variant (given or estimated): m, rad per component.
    seconds : ndarray, shape (T,)
    """

    setup: ExperimentSetup
    outlier_fraction: float
    outlier_mm: float
    outlier_deg: float
    variants: tuple[tuple[str, str], ...]
    clean_rms_mm: NDArray[np.float64]
    start_rms_mm: NDArray[np.float64]
    rms_mm: NDArray[np.float64]
    n_observations: NDArray[np.int64]
    n_planted: NDArray[np.int64]
    flagged_planted: NDArray[np.int64]
    flagged_clean: NDArray[np.int64]
    noise_used: NDArray[np.float64]
    seconds: NDArray[np.float64]

    @property
    def trials(self) -> int:
        return int(self.rms_mm.shape[0])

    @property
    def labels(self) -> tuple[str, ...]:
        """A short label per variant."""
        return tuple(
            loss if noise == "given" else f"{loss}, σ estimated" for loss, noise in self.variants
        )

    def variant(self, loss: str, noise: str = "given") -> int:
        """Index of a variant."""
        try:
            return self.variants.index((loss, noise))
        except ValueError:
            raise KeyError(f"no variant {(loss, noise)}; the study has {self.variants}") from None

    @property
    def ratio_to_clean(self) -> NDArray[np.float64]:
        """Held-out RMS error of each variant over the clean-data result, (T, V)."""
        return self.rms_mm / self.clean_rms_mm[:, None]

    @property
    def recall(self) -> NDArray[np.float64]:
        """Planted outliers down-weighted, pooled over trials, (V,)."""
        return self.flagged_planted.sum(axis=0) / max(int(self.n_planted.sum()), 1)

    @property
    def false_alarm_rate(self) -> NDArray[np.float64]:
        """Clean observations down-weighted, pooled over trials, (V,)."""
        clean = int((self.n_observations - self.n_planted).sum())
        return self.flagged_clean.sum(axis=0) / max(clean, 1)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: set-up, raw per-trial values and the summary (mm)."""
        return {
            "study": "Robust refinement with planted outliers (simulation)",
            "setup": self.setup.to_dict(),
            "outlier_fraction": self.outlier_fraction,
            "outlier_mm": self.outlier_mm,
            "outlier_deg": self.outlier_deg,
            "variants": [list(v) for v in self.variants],
            **json_lists(self, _ROBUST_ARRAYS),
            "summary": {
                label: {
                    "median_ratio_to_clean": float(np.median(ratio)),
                    "max_ratio_to_clean": float(np.max(ratio)),
                    "recall": float(rec),
                    "false_alarm_rate": float(fa),
                }
                for label, ratio, rec, fa in zip(
                    self.labels,
                    self.ratio_to_clean.T,
                    self.recall,
                    self.false_alarm_rate,
                    strict=True,
                )
            },
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> RobustStudy:
        """The study written by :meth:`to_dict` (the summary is recomputed)."""
        return cls(
            setup=ExperimentSetup.from_dict(doc["setup"]),
            outlier_fraction=float(doc["outlier_fraction"]),
            outlier_mm=float(doc["outlier_mm"]),
            outlier_deg=float(doc["outlier_deg"]),
            variants=tuple((str(a), str(b)) for a, b in doc["variants"]),
            **arrays_from(doc, _ROBUST_ARRAYS),
        )


def _robust_trial(
    nominal: Robot,
    setup: ExperimentSetup,
    t: int,
    variants: tuple[tuple[str, str], ...],
    outlier_fraction: float,
    outlier_mm: float,
    outlier_deg: float,
) -> tuple:
    """Trial ``t`` of :func:`robustness_study` (a task: module level, picklable
    arguments)."""
    t0 = time.perf_counter()
    exp = simulate_experiment(nominal, setup, t)
    truth = cpc_from_robot(exp.truth, setup.frames)

    def held_out_ms(model: CPCModel) -> float:
        return float(position_ms(model, truth, exp.test_qs, setup.joint_names, setup.frames).mean())

    V = len(variants)
    rms_ms, noise_used = np.empty(V), np.empty((V, 2))
    flagged_planted, flagged_clean = np.zeros(V, np.int64), np.zeros(V, np.int64)
    start, start_targets = pipeline_start(nominal, exp.data)
    clean_ms = held_out_ms(
        refine(nominal, exp.data, start=start, targets=start_targets, noise=setup.noise).model
    )
    rng = np.random.default_rng([setup.seed, _OUTLIER_TAG, t])
    data, planted = plant_outliers(
        exp.data,
        rng,
        fraction=outlier_fraction,
        distance_m=1e-3 * outlier_mm,
        angle_rad=float(np.radians(outlier_deg)),
    )
    n_obs = sum(len(g.sample) for g in (*data.poses, *data.targets))
    start, start_targets = pipeline_start(nominal, data)
    start_ms = held_out_ms(cpc_from_robot(start, setup.frames))
    for v, (loss, noise) in enumerate(variants):
        fit = refine(
            nominal,
            data,
            start=start,
            targets=start_targets,
            loss=loss,
            noise=setup.noise if noise == "given" else None,
        )
        rms_ms[v] = held_out_ms(fit.model)
        flagged = {(kind, frame, sample) for kind, frame, sample, _ in fit.downweighted} | {
            (o.kind, o.frame, o.sample) for o in fit.rejected
        }
        flagged_planted[v] = len(flagged & planted)
        flagged_clean[v] = len(flagged - planted)
        noise_used[v] = fit.noise.position_m, fit.noise.rotation_rad
    seconds = time.perf_counter() - t0
    log.info(
        "robust trial %d: clean %.3g mm, %s, %.2f s",
        t,
        1e3 * np.sqrt(clean_ms),
        ", ".join(
            f"{loss}/{noise} {1e3 * np.sqrt(m):.3g} mm"
            for (loss, noise), m in zip(variants, rms_ms, strict=True)
        ),
        seconds,
    )
    return (
        clean_ms,
        start_ms,
        rms_ms,
        n_obs,
        len(planted),
        flagged_planted,
        flagged_clean,
        noise_used,
        seconds,
    )


def robustness_study(
    nominal: Robot,
    *,
    trials: int = 20,
    outlier_fraction: float = 0.05,
    outlier_mm: float = 50.0,
    outlier_deg: float = 5.0,
    variants: Sequence[tuple[str, str]] = ROBUST_VARIANTS,
    sigma_mm: float = 0.5,
    sigma_deg: float = 0.5,
    per_joint: int = 9,
    stage2_views: int = 30,
    n_test: int = 200,
    seed: int = 0,
    executor: Executor | None = None,
) -> RobustStudy:
    """Refinement of data with planted gross errors, linear vs robust losses.

    Each trial takes the data of the same trial of
    :func:`kinfw.verification.studies.crlb_study`, refines the clean data (pipeline start,
    linear loss, true noise: the reference), then corrupts ``outlier_fraction`` of the
    observations (:func:`kinfw.simulation.plant_outliers`: ``outlier_mm`` in a random
    direction and ``outlier_deg`` about a random axis), restarts the pipeline
    from the corrupted data and refines with each variant ``(loss, noise)``; it records
    the held-out RMS position error against the truth and which observations
    ``refine`` down-weighted.

    Parameters
    ----------
    nominal : Robot
    trials : int
    outlier_fraction : float
        Fraction of observations corrupted (at least one when > 0).
    outlier_mm, outlier_deg : float
        Size of each gross error.
    variants : sequence of (loss, noise)
        ``loss`` in ``("linear", "huber", "cauchy")``; ``noise`` ``"given"`` (the true
        noise) or ``"estimated"`` (by ``refine`` from the residuals).
    sigma_mm, sigma_deg, per_joint, stage2_views, n_test, seed, executor
        As for :func:`kinfw.verification.studies.crlb_study`.

    Returns
    -------
    RobustStudy

    Notes
    -----
    ``refine`` applies the robust loss to the norm ``s`` of each observation's whitened
    residual (6 rows for a pose, 3 for a point) with ``loss_scale = 3`` and reports
    weights below 0.5: ``s > 6`` for Huber but ``s > 3`` for Cauchy, which a clean pose
    observation exceeds with probability ``P(chi2_6 > 9) = 17 %`` — the Cauchy variants'
    "clean down-weighted" counts those, not misfits.
    """
    setup = setup_experiment(
        nominal,
        sigma_mm=sigma_mm,
        sigma_deg=sigma_deg,
        per_joint=per_joint,
        stage2_views=stage2_views,
        n_test=n_test,
        seed=seed,
    )
    trials = check_count(trials, "trials", 1)
    variants = _check_variants(variants)
    if not 0.0 <= float(outlier_fraction) <= 1.0:
        raise ValueError(f"outlier_fraction: expected 0 <= fraction <= 1, got {outlier_fraction}")
    outlier_mm = check_positive(outlier_mm, "outlier_mm")
    outlier_deg = float(outlier_deg)
    if not (np.isfinite(outlier_deg) and outlier_deg >= 0.0):
        raise ValueError(f"outlier_deg: expected a finite angle >= 0, got {outlier_deg}")
    trial_results = run_trials(
        _robust_trial,
        [
            (nominal, setup, t, variants, float(outlier_fraction), outlier_mm, outlier_deg)
            for t in range(trials)
        ],
        executor=executor,
    )
    result = RobustStudy(
        setup=setup,
        outlier_fraction=float(outlier_fraction),
        outlier_mm=outlier_mm,
        outlier_deg=outlier_deg,
        variants=variants,
        **_stacked_trials(trial_results, trials, len(variants)),
    )
    freeze(*(getattr(result, name) for name in _ROBUST_ARRAYS))
    return result


def _check_variants(variants: Sequence[tuple[str, str]]) -> tuple[tuple[str, str], ...]:
    """The ``(loss, noise)`` variants as strings; raise on an unknown or empty one."""
    variants = tuple((str(loss), str(noise)) for loss, noise in variants)
    for loss, noise in variants:
        if loss not in ("linear", "huber", "cauchy") or noise not in ("given", "estimated"):
            raise ValueError(
                f"variants: expected (loss, noise) with loss linear, huber or "
                f"cauchy and noise given or estimated, got {(loss, noise)}"
            )
    if not variants:
        raise ValueError("variants: give at least one (loss, noise)")
    return variants


def _stacked_trials(trial_results: Iterable[Any], trials: int, V: int) -> dict[str, Any]:
    """The per-trial results of :func:`_robust_trial` as :class:`RobustStudy` arrays
    (RMS in mm), keyed by field."""
    clean_ms, start_ms, seconds = np.empty(trials), np.empty(trials), np.empty(trials)
    rms_ms = np.empty((trials, V))
    n_obs, n_planted = np.empty(trials, np.int64), np.empty(trials, np.int64)
    flagged_planted, flagged_clean = (
        np.zeros((trials, V), np.int64),
        np.zeros((trials, V), np.int64),
    )
    noise_used = np.empty((trials, V, 2))
    for t, res in enumerate(trial_results):
        (
            clean_ms[t],
            start_ms[t],
            rms_ms[t],
            n_obs[t],
            n_planted[t],
            flagged_planted[t],
            flagged_clean[t],
            noise_used[t],
            seconds[t],
        ) = res
    return {
        "clean_rms_mm": 1e3 * np.sqrt(clean_ms),
        "start_rms_mm": 1e3 * np.sqrt(start_ms),
        "rms_mm": 1e3 * np.sqrt(rms_ms),
        "n_observations": n_obs,
        "n_planted": n_planted,
        "flagged_planted": flagged_planted,
        "flagged_clean": flagged_clean,
        "noise_used": noise_used,
        "seconds": seconds,
    }
