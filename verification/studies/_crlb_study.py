"""Is the refined calibration as good as the data allows? The CRLB study.

Each trial of :func:`crlb_study` repeats the two-stage head experiment
(:mod:`kinfw.verification.studies`), refines with the true noise given and again with
the noise estimated, and records the held-out error of the refined model beside the error
the Cramér-Rao bound implies (:func:`~kinfw.verification.evaluation.cramer_rao`; their ratio
should be 1), whether
the reported covariance covers the truth (``|estimate - truth| <= k sigma`` for 68.3 %,
95.4 % and 99.7 % of the parameters at ``k = 1, 2, 3``), and the estimated noise beside
the true one. :func:`kinfw.verification.studies.format_crlb` writes the tables,
:func:`kinfw.verification.studies.plot_crlb` the figure.
"""

from __future__ import annotations

import logging
import time
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.identification import refine
from kinfw.identification.problem import build_problem
from kinfw.model import Robot, cpc_from_robot
from kinfw.verification.evaluation import (
    NORMAL_COVERAGE,
    check_count,
    cramer_rao,
    position_jacobians,
    predicted_position_ms,
    run_trials,
    true_chart_coordinates,
)
from kinfw.verification.studies._common import arrays_from, freeze, json_lists
from kinfw.verification.studies._head_experiment import (
    ExperimentSetup,
    in_model_order,
    pipeline_start,
    position_ms,
    rms_over,
    setup_experiment,
    simulate_experiment,
)

log = logging.getLogger(__name__)

_BAND_TAG = 9  # seeds (kinfw.verification.studies's docstring)


#: The per-trial arrays of :class:`CRLBStudy`, in the order its JSON lists them, and their
#: dtypes.
_CRLB_ARRAYS = dict.fromkeys(
    (
        "start_rms_mm",
        "refined_rms_mm",
        "estimated_noise_rms_mm",
        "crlb_rms_mm",
        "z",
        "z_estimated_noise",
        "nees",
        "ratio_band",
        "noise_estimates",
        "sigma_hat2",
        "seconds",
    ),
    float,
)


@dataclass(frozen=True, slots=True)
class CRLBStudy:
    """Refined calibration against the Cramér-Rao bound, per trial.

    Attributes
    ----------
    setup : ExperimentSetup
    parameter_names : tuple of (owner, field)
        The free parameters of the refinement (CPC chart, then the target pose).
    start_rms_mm : ndarray, shape (T, E)
        Held-out RMS position error of each end frame (``setup.frames``) against the
        truth, closed form + hand-eye start, mm.
    refined_rms_mm : ndarray, shape (T, E)
        The same for the refined model, true noise given.
    estimated_noise_rms_mm : ndarray, shape (T, E)
        The same for the refined model, noise estimated.
    crlb_rms_mm : ndarray, shape (T, E)
        RMS position error the bound implies at the same configurations
        (:func:`kinfw.verification.evaluation.predicted_position_rms` per frame), mm.
    z : ndarray, shape (T, P)
        ``(estimate - truth) / std`` of each free parameter, true noise given, with the
        standard deviations ``refine`` reports.
    z_estimated_noise : ndarray, shape (T, P)
        The same with the noise estimated.
    nees : ndarray, shape (T,)
        Normalised estimation error squared ``(x_hat - x)^T C^+ (x_hat - x)`` over the
        free parameters, ``C`` the covariance ``refine`` reports (true noise given):
        chi-square with P degrees of freedom when that covariance is right.
    ratio_band : ndarray, shape (T, 2)
        The 5 % and 95 % quantiles of the per-trial ratio (refined over CRLB RMS error)
        that an estimator with exactly the bound's covariance would show: the mean square
        error is ``sum_i lambda_i chi2_1`` (``lambda`` the eigenvalues of ``C^1/2 M C^1/2``,
        ``M`` the mean of ``G^T G`` over configurations and frames), sampled.
    noise_estimates : ndarray, shape (T, 2)
        Estimated noise: per position component (m), per orientation component (rad).
    sigma_hat2 : ndarray, shape (T,)
        Reduced chi-square of the refinement with the true noise given.
    seconds : ndarray, shape (T,)
        Wall time of each trial.
    """

    setup: ExperimentSetup
    parameter_names: tuple[tuple[str, str], ...]
    start_rms_mm: NDArray[np.float64]
    refined_rms_mm: NDArray[np.float64]
    estimated_noise_rms_mm: NDArray[np.float64]
    crlb_rms_mm: NDArray[np.float64]
    z: NDArray[np.float64]
    z_estimated_noise: NDArray[np.float64]
    nees: NDArray[np.float64]
    ratio_band: NDArray[np.float64]
    noise_estimates: NDArray[np.float64]
    sigma_hat2: NDArray[np.float64]
    seconds: NDArray[np.float64]

    @property
    def trials(self) -> int:
        return int(self.refined_rms_mm.shape[0])

    @property
    def n_parameters(self) -> int:
        """Free parameters per trial, P."""
        return len(self.parameter_names)

    @property
    def within_band(self) -> float:
        """Fraction of trials whose ratio lies in :attr:`ratio_band` (90 % expected)."""
        r = self.ratio
        return float(np.mean((r >= self.ratio_band[:, 0]) & (r <= self.ratio_band[:, 1])))

    def trial_rms_mm(self, which: str) -> NDArray[np.float64]:
        """Per trial, RMS over frames and held-out configurations, (T,), mm; ``which`` is
        ``"start"``, ``"refined"``, ``"estimated_noise"`` or ``"crlb"``."""
        values = {
            "start": self.start_rms_mm,
            "refined": self.refined_rms_mm,
            "estimated_noise": self.estimated_noise_rms_mm,
            "crlb": self.crlb_rms_mm,
        }
        if which not in values:
            raise ValueError(f"which: expected one of {sorted(values)}, got {which!r}")
        return rms_over(values[which], axis=1)

    @property
    def ratio(self) -> NDArray[np.float64]:
        """Refined (true noise) over CRLB RMS error of each trial, (T,)."""
        return self.trial_rms_mm("refined") / self.trial_rms_mm("crlb")

    def pooled_ratio(self, which: str = "refined") -> float:
        """``sqrt(sum of mean square errors / sum of their bounds)`` over trials (1 for an
        efficient estimator)."""
        return float(
            np.sqrt(np.sum(self.trial_rms_mm(which) ** 2) / np.sum(self.trial_rms_mm("crlb") ** 2))
        )

    @property
    def pooled_ratio_per_frame(self) -> NDArray[np.float64]:
        """:meth:`pooled_ratio` of each frame, (E,)."""
        return np.sqrt(np.sum(self.refined_rms_mm**2, axis=0) / np.sum(self.crlb_rms_mm**2, axis=0))

    def parameter_mask(self, kind: str = "all") -> NDArray[np.bool_]:
        """``"all"``, ``"model"`` (CPC chart) or ``"target"`` parameters, (P,)."""
        is_target = np.array([o.startswith("target:") for o, _ in self.parameter_names])
        masks = {"all": np.ones_like(is_target), "model": ~is_target, "target": is_target}
        if kind not in masks:
            raise ValueError(f"kind: expected 'all', 'model' or 'target', got {kind!r}")
        return masks[kind]

    def coverage(self, k: float, *, kind: str = "all", estimated_noise: bool = False) -> float:
        """Fraction of (trial, parameter) pairs with ``|estimate - truth| <= k std``."""
        z = self.z_estimated_noise if estimated_noise else self.z
        return float(np.mean(np.abs(z[:, self.parameter_mask(kind)]) <= k))

    @property
    def true_noise(self) -> NDArray[np.float64]:
        """True per-component noise (m, rad), (2,)."""
        noise = self.setup.noise
        return np.array([noise.position_m, noise.rotation_rad])

    @property
    def noise_ratio(self) -> NDArray[np.float64]:
        """Estimated over true noise, (T, 2): position, orientation."""
        return self.noise_estimates / self.true_noise

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: set-up, raw per-trial values and the summary (mm, m, rad)."""
        return {
            "study": "Cramér-Rao bound of the two-stage head calibration (simulation)",
            "setup": self.setup.to_dict(),
            "frames": list(self.setup.frames),
            "parameter_names": [list(n) for n in self.parameter_names],
            **json_lists(self, _CRLB_ARRAYS),
            "summary": {
                "trials": self.trials,
                "ratio": self.ratio.tolist(),
                "pooled_ratio": self.pooled_ratio(),
                "pooled_ratio_estimated_noise": self.pooled_ratio("estimated_noise"),
                "pooled_ratio_per_frame": self.pooled_ratio_per_frame.tolist(),
                "within_band": self.within_band,
                "mean_nees": float(self.nees.mean()),
                "n_parameters": self.n_parameters,
                "coverage": {
                    f"{k:g}": {
                        kind: self.coverage(k, kind=kind) for kind in ("all", "model", "target")
                    }
                    for k in NORMAL_COVERAGE
                },
                "coverage_estimated_noise": {
                    f"{k:g}": self.coverage(k, estimated_noise=True) for k in NORMAL_COVERAGE
                },
                "true_noise": self.true_noise.tolist(),
                "noise_ratio_mean": self.noise_ratio.mean(axis=0).tolist(),
            },
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> CRLBStudy:
        """The study written by :meth:`to_dict` (the summary is recomputed)."""
        return cls(
            setup=ExperimentSetup.from_dict(doc["setup"]),
            parameter_names=tuple((str(o), str(f)) for o, f in doc["parameter_names"]),
            **arrays_from(doc, _CRLB_ARRAYS),
        )


def _ratio_band(
    covariance: NDArray[np.float64],
    G: NDArray[np.float64],
    rng: np.random.Generator,
    draws: int = 4000,
) -> NDArray[np.float64]:
    """5 % and 95 % quantiles of ``RMS error / CRLB RMS`` for an estimator whose error is
    ``N(0, covariance)`` (see :attr:`CRLBStudy.ratio_band`)."""
    w, U = np.linalg.eigh(covariance)
    half = (U * np.sqrt(np.clip(w, 0.0, None))) @ U.T
    M = np.einsum("nekp,nekq->pq", G, G) / (G.shape[0] * G.shape[1])
    lam = np.clip(np.linalg.eigvalsh(half @ M @ half), 0.0, None)
    ms = rng.chisquare(1.0, size=(draws, len(lam))) @ lam / lam.sum()
    return np.sqrt(np.quantile(ms, [0.05, 0.95]))


def _nees(error: NDArray[np.float64], covariance: NDArray[np.float64]) -> float:
    """``error^T covariance^+ error``."""
    return float(error @ np.linalg.pinv(covariance, rcond=1e-12, hermitian=True) @ error)


def _crlb_trial(nominal: Robot, setup: ExperimentSetup, t: int) -> tuple[tuple, tuple]:
    """Trial ``t`` of :func:`crlb_study` (a task: module level, picklable arguments):
    its per-trial numbers and the names of the free parameters."""
    t0 = time.perf_counter()
    exp = simulate_experiment(nominal, setup, t)
    start, start_targets = pipeline_start(nominal, exp.data)
    fit = refine(nominal, exp.data, start=start, targets=start_targets, noise=setup.noise)
    fit_est = refine(nominal, exp.data, start=start, targets=start_targets)
    truth = cpc_from_robot(exp.truth, setup.frames)
    qs = exp.test_qs
    start_ms = position_ms(
        cpc_from_robot(start, setup.frames), truth, qs, setup.joint_names, setup.frames
    )
    refined_ms = position_ms(fit.model, truth, qs, setup.joint_names, setup.frames)
    estimated_ms = position_ms(fit_est.model, truth, qs, setup.joint_names, setup.frames)
    bound = cramer_rao(
        exp.truth, exp.data, setup.frames, noise=setup.noise, targets=exp.root_T_targets
    )
    G = position_jacobians(
        bound.model, in_model_order(qs, setup.joint_names, bound.model), setup.frames
    )
    crlb_ms = predicted_position_ms(bound.model_covariance, G)
    band = _ratio_band(bound.model_covariance, G, np.random.default_rng([setup.seed, _BAND_TAG, t]))
    # The truth in the refinement's chart: the same problem refine built.
    problem = build_problem(nominal, exp.data, start=start, targets=start_targets)
    if problem.names != fit.parameter_names:
        raise RuntimeError("crlb_study: refine's parameters differ from build_problem's")
    x_true = true_chart_coordinates(problem, exp.truth, exp.root_T_targets)
    free = problem.free
    trial_names = tuple(n for n, f in zip(problem.names, free, strict=True) if f)
    z = ((fit.estimate - x_true) / np.where(fit.std > 0, fit.std, np.nan))[free]
    nees = _nees((fit.estimate - x_true)[free], fit.covariance[np.ix_(free, free)])
    z_est = ((fit_est.estimate - x_true) / np.where(fit_est.std > 0, fit_est.std, np.nan))[free]
    seconds = time.perf_counter() - t0
    log.info(
        "crlb trial %d: refined %.3g mm, CRLB %.3g mm, %.2f s",
        t,
        1e3 * np.sqrt(refined_ms.mean()),
        1e3 * np.sqrt(crlb_ms.mean()),
        seconds,
    )
    return (
        (
            start_ms,
            refined_ms,
            estimated_ms,
            crlb_ms,
            band,
            z,
            nees,
            z_est,
            (fit_est.noise.position_m, fit_est.noise.rotation_rad),
            fit.sigma_hat2,
            seconds,
        ),
        trial_names,
    )


def crlb_study(
    nominal: Robot,
    *,
    trials: int = 30,
    sigma_mm: float = 0.5,
    sigma_deg: float = 0.5,
    per_joint: int = 9,
    stage2_views: int = 30,
    n_test: int = 200,
    seed: int = 0,
    executor: Executor | None = None,
) -> CRLBStudy:
    """The refined two-stage calibration against its Cramér-Rao bound.

    Each trial (module docstring) draws a true head and its data, starts from the
    pipeline (closed form + hand-eye), refines with the true noise given and again with
    the noise estimated, and records: the held-out RMS position error of every end frame
    for the start and both refinements; the error the bound implies at the same
    configurations; the normalised parameter errors ``(estimate - truth) / std`` (truth
    in the refinement's chart: :func:`true_chart_coordinates`); the estimated noise.

    Parameters
    ----------
    nominal : Robot
        The nominal head (plates and cameras from its ``<kinfw>`` hint).
    trials : int
    sigma_mm : float
        Position noise per component, mm.
    sigma_deg : float
        Rotation noise: angle about a random axis, degrees (per component:
        ``sigma_deg / sqrt(3)``).
    per_joint : int
        Stage-1 values per joint.
    stage2_views : int
        Stage-2 configurations.
    n_test : int
        Held-out configurations per trial.
    seed : int
    executor : concurrent.futures.Executor, optional
        Run the trials as its tasks (:func:`kinfw.verification.studies._common.run_trials`); default
        serially here. The numbers do not depend on it (each trial seeds its own).

    Returns
    -------
    CRLBStudy
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
    E = len(setup.frames)
    start_ms, refined_ms, estimated_ms, crlb_ms = (np.empty((trials, E)) for _ in range(4))
    zs, zs_est, noise_est = [], [], np.empty((trials, 2))
    nees, band = np.empty(trials), np.empty((trials, 2))
    sigma_hat2, seconds = np.empty(trials), np.empty(trials)
    names: tuple[tuple[str, str], ...] | None = None
    trial_results = run_trials(
        _crlb_trial,
        [(nominal, setup, t) for t in range(trials)],
        executor=executor,
    )
    for t, (res, trial_names) in enumerate(trial_results):
        (
            start_ms[t],
            refined_ms[t],
            estimated_ms[t],
            crlb_ms[t],
            band[t],
            z,
            nees[t],
            z_est,
            noise_est[t],
            sigma_hat2[t],
            seconds[t],
        ) = res
        zs.append(z)
        zs_est.append(z_est)
        if names is None:
            names = trial_names
        elif names != trial_names:
            raise RuntimeError("crlb_study: the free parameters differ between trials")
    result = CRLBStudy(
        setup=setup,
        parameter_names=names or (),
        start_rms_mm=1e3 * np.sqrt(start_ms),
        refined_rms_mm=1e3 * np.sqrt(refined_ms),
        estimated_noise_rms_mm=1e3 * np.sqrt(estimated_ms),
        crlb_rms_mm=1e3 * np.sqrt(crlb_ms),
        z=np.array(zs),
        z_estimated_noise=np.array(zs_est),
        nees=nees,
        ratio_band=band,
        noise_estimates=noise_est,
        sigma_hat2=sigma_hat2,
        seconds=seconds,
    )
    freeze(*(getattr(result, name) for name in _CRLB_ARRAYS))
    return result
