"""Table 4 of Shih et al. (1992), section 6, in simulation.

The set-up, the seeds and the calibration of every trial are those of
:mod:`kinfw.verification.papers` (the paper's Fig. 10 simulation);
:mod:`kinfw.verification.papers` writes the table and the figure.

References
----------
S.-W. Shih, J.-S. Jin, K.-H. Wei, Y.-P. Hung, "Kinematic identification of an active
binocular head", 1992, section 6, Table 4.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.model import Robot
from kinfw.simulation import random_configurations
from kinfw.verification.evaluation import check_count, run_trials
from kinfw.verification.papers._shih_experiments import (
    PAPER_PER_JOINT,
    StudySetup,
    calibrate_once,
    check_sigmas_mm,
    positions_m,
    setup_study,
    trial_rng,
)
from kinfw.verification.studies import freeze, readonly, sample_std

#: End frames of the rows of the paper's Table 4: left branch, right branch.
PAPER_TABLE4_FRAMES = ("left_plate", "right_plate")


#: Table 4 of the paper (real data, nine test configurations): mean of ``|error|`` in
#: x, y, z, mm; rows ``PAPER_TABLE4_FRAMES``.
PAPER_TABLE4_MU_MM = readonly([[0.65, 0.23, 0.35], [0.28, 0.13, 0.11]])


#: Table 4 of the paper: standard deviation of ``|error|`` in x, y, z, mm.
PAPER_TABLE4_SIGMA_MM = readonly([[0.24, 0.12, 0.30], [0.31, 0.21, 0.35]])


_TABLE4_TAG = 4  # the study's tag in the seeds (Fig. 11's is 11)


@dataclass(frozen=True, slots=True)
class Table4Result:
    """Per-axis errors on held-out configurations (Shih et al. Table 4, in simulation).

    Attributes
    ----------
    setup : StudySetup
    per_joint : int
        Calibration measurements per joint (the paper: nine).
    sigma_mm : float
        Position noise per axis of calibration and test measurements, mm.
    n_test : int
        Test configurations per trial (the paper: nine).
    error_vs_measured_mm : ndarray, shape (T, n_test, E, 3)
        Noisy measured minus predicted position of each end frame, x, y, z of the
        measurement frame, mm (what the paper computes from real data: it includes the
        measurement noise of the test poses).
    error_vs_truth_mm : ndarray, shape (T, n_test, E, 3)
        True minus predicted position, mm (the model's own error).
    """

    setup: StudySetup
    per_joint: int
    sigma_mm: float
    n_test: int
    error_vs_measured_mm: NDArray[np.float64]
    error_vs_truth_mm: NDArray[np.float64]

    @property
    def trials(self) -> int:
        return int(self.error_vs_measured_mm.shape[0])

    @property
    def sigma_rad(self) -> float:
        """Rotation noise, rad."""
        return float(self.setup.sigma_rad(self.sigma_mm))

    @property
    def measured_mu_mm(self) -> NDArray[np.float64]:
        """Mean of ``|error|`` vs the noisy measurements per frame and axis, (E, 3), mm,
        pooled over trials and test configurations (Table 4's mu)."""
        return np.abs(self.error_vs_measured_mm).mean(axis=(0, 1))

    @property
    def measured_sigma_mm(self) -> NDArray[np.float64]:
        """Standard deviation of ``|error|`` vs the noisy measurements, (E, 3), mm
        (Table 4's sigma)."""
        return sample_std(np.abs(self.error_vs_measured_mm), axis=(0, 1))

    @property
    def truth_mu_mm(self) -> NDArray[np.float64]:
        """Mean of ``|error|`` vs the truth, (E, 3), mm."""
        return np.abs(self.error_vs_truth_mm).mean(axis=(0, 1))

    @property
    def truth_sigma_mm(self) -> NDArray[np.float64]:
        """Standard deviation of ``|error|`` vs the truth, (E, 3), mm."""
        return sample_std(np.abs(self.error_vs_truth_mm), axis=(0, 1))

    def paper_rows(self) -> list[int | None]:
        """Per frame, its row in the paper's Table 4 (``PAPER_TABLE4_FRAMES``), or None."""
        return [
            PAPER_TABLE4_FRAMES.index(f) if f in PAPER_TABLE4_FRAMES else None
            for f in self.setup.frames
        ]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: set-up, raw errors, our statistics and the paper's (mm)."""
        return {
            "study": "Shih et al. 1992, Table 4 (simulation)",
            "setup": self.setup.to_dict(),
            "per_joint": self.per_joint,
            "sigma_mm": self.sigma_mm,
            "sigma_rad": self.sigma_rad,
            "n_test": self.n_test,
            "trials": self.trials,
            "error_vs_measured_mm": self.error_vs_measured_mm.tolist(),
            "error_vs_truth_mm": self.error_vs_truth_mm.tolist(),
            "summary": {
                f: {
                    "measured_mu_mm": self.measured_mu_mm[e].tolist(),
                    "measured_sigma_mm": self.measured_sigma_mm[e].tolist(),
                    "truth_mu_mm": self.truth_mu_mm[e].tolist(),
                    "truth_sigma_mm": self.truth_sigma_mm[e].tolist(),
                    **(
                        {}
                        if row is None
                        else {
                            "paper_mu_mm": PAPER_TABLE4_MU_MM[row].tolist(),
                            "paper_sigma_mm": PAPER_TABLE4_SIGMA_MM[row].tolist(),
                        }
                    ),
                }
                for e, (f, row) in enumerate(zip(self.setup.frames, self.paper_rows(), strict=True))
            },
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> Table4Result:
        """The result written by :meth:`to_dict` (the summary is recomputed)."""
        return cls(
            setup=StudySetup.from_dict(doc["setup"]),
            per_joint=int(doc["per_joint"]),
            sigma_mm=float(doc["sigma_mm"]),
            n_test=int(doc["n_test"]),
            error_vs_measured_mm=np.array(doc["error_vs_measured_mm"], dtype=float),
            error_vs_truth_mm=np.array(doc["error_vs_truth_mm"], dtype=float),
        )


def _table4_trial(
    nominal: Robot,
    setup: StudySetup,
    lower: NDArray,
    upper: NDArray,
    sigma: float,
    per_joint: int,
    t: int,
    n_test: int,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One trial of :func:`table4_study` (a task): held-out errors against the noisy
    measurements and against the truth, (n_test, E, 3) mm."""
    rng = trial_rng(setup, _TABLE4_TAG, sigma, per_joint, t)
    trial = calibrate_once(
        nominal, setup, lower, upper, per_joint=per_joint, sigma_mm=sigma, rng=rng
    )
    qs = random_configurations(lower, upper, n_test, trial.rng, fraction=setup.fraction)
    true_p = positions_m(trial.truth, qs, setup.frames)
    measured_p = true_p + trial.rng.normal(0.0, 1e-3 * sigma, size=true_p.shape)
    predicted_p = positions_m(trial.identified, qs, setup.frames)
    return 1e3 * (measured_p - predicted_p), 1e3 * (true_p - predicted_p)


def table4_study(
    nominal: Robot,
    *,
    per_joint: int = PAPER_PER_JOINT,
    sigma_mm: float = 0.5,
    trials: int = 20,
    n_test: int = 9,
    rot_per_mm_rad: float = 1.0 / 50.0,
    error_mm: float = 5.0,
    error_deg: float = 1.0,
    fraction: float = 0.8,
    seed: int = 0,
    frames: Sequence[str] | None = None,
    executor: Executor | None = None,
) -> Table4Result:
    """Shih et al. (1992) Table 4's protocol in simulation.

    Each trial calibrates a new true robot in closed form from ``per_joint`` one-joint
    measurements per joint with Fig. 10 noise ``sigma_mm``, then draws ``n_test`` test
    configurations from the calibration range (not used to calibrate), measures the
    plates there with the same noise, and records the identified model's per-axis
    position error against those noisy measurements (as the paper does with real data)
    and against the noise-free truth.

    Parameters
    ----------
    nominal : Robot
        The nominal robot (its topology is all the identification uses).
    per_joint : int, optional
        Calibration measurements per joint (the paper: nine).
    sigma_mm : float, optional
        Position noise per axis, mm (the paper's stereo rig: about 0.5 mm); the rotation
        error angle is ``N(0, sigma_mm * rot_per_mm_rad)`` rad (0.01 rad = 0.57 deg at
        0.5 mm by default).
    trials : int, optional
        Random trials; the statistics pool every trial's test configurations.
    n_test : int, optional
        Test configurations per trial (the paper: nine).
    rot_per_mm_rad, error_mm, error_deg, fraction, seed, frames
        As for :func:`kinfw.verification.papers.fig11_study`.

    Returns
    -------
    Table4Result
        ``measured_mu_mm`` / ``measured_sigma_mm`` compare with the paper's Table 4
        (``PAPER_TABLE4_MU_MM``, ``PAPER_TABLE4_SIGMA_MM``).

    Notes
    -----
    Against noisy measurements, ``|error|`` per axis cannot average below the noise
    alone, ``E|N(0, sigma)| = sigma sqrt(2 / pi)`` (0.40 mm at sigma = 0.5 mm).
    """
    setup = setup_study(
        nominal,
        frames,
        error_mm=error_mm,
        error_deg=error_deg,
        rot_per_mm_rad=rot_per_mm_rad,
        fraction=fraction,
        seed=seed,
    )
    per_joint = check_count(per_joint, "per_joint", 1)
    sigma = float(check_sigmas_mm([sigma_mm], "sigma_mm")[0])
    trials = check_count(trials, "trials", 1)
    n_test = check_count(n_test, "n_test", 1)
    lower, upper = nominal.joint_limits(setup.joint_names)
    shape = (trials, n_test, len(setup.frames), 3)
    vs_measured, vs_truth = np.empty(shape), np.empty(shape)
    results = run_trials(
        _table4_trial,
        [(nominal, setup, lower, upper, sigma, per_joint, t, n_test) for t in range(trials)],
        executor=executor,
    )
    for t, (measured, truth) in enumerate(results):
        vs_measured[t], vs_truth[t] = measured, truth
    freeze(vs_measured, vs_truth)
    return Table4Result(
        setup=setup,
        per_joint=per_joint,
        sigma_mm=sigma,
        n_test=n_test,
        error_vs_measured_mm=vs_measured,
        error_vs_truth_mm=vs_truth,
    )
