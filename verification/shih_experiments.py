"""The experiments of Shih et al. (1992), section 6, in simulation: Fig. 11 and Table 4.

Both studies follow the paper's simulation (its Fig. 10) over the built-in IIS-head (or
any URDF with two or more measured end frames):

1. a *true* robot: the nominal URDF with random geometric errors
   (:func:`verification.simulate.perturb_robot`, ``error_mm`` on every origin
   translation component, ``error_deg`` on every origin rotation and axis direction);
2. one-joint-at-a-time plate poses of the truth (the paper's section 4.1 protocol,
   :func:`verification.simulate.one_joint_at_a_time`), ``M`` values per joint inside
   the centred ``fraction`` of each joint's range;
3. measurement noise as in Fig. 10 (:func:`verification.simulate.perturb_poses`): each
   position component gets ``N(0, sigma)``; the orientation is turned about a uniformly
   random axis by an angle ``N(0, sigma_rad)`` with ``sigma_rad = sigma_mm *
   rot_per_mm_rad`` (default 1/50 rad per mm: 0.01 rad = 0.57 deg at sigma = 0.5 mm);
   joint values are exact, as in the paper;
4. the closed-form identification of section 4
   (:func:`identification.closed_form.identify_closed_form`);
5. the identified CPC model tested on configurations drawn from the same calibration
   range but not used to calibrate.

Forward kinematics of the truth is the CPC model converted from its URDF
(:func:`kinfw.cpc.cpc_from_robot`, equal to Pinocchio's FK to 1e-12, see
:mod:`verification.crosscheck`), vectorised over configurations.

Random numbers. Every random trial has its own ``numpy.random.Generator`` seeded with
``(seed, study, sigma in nm, M, trial)``: a trial's result does not depend on which
other cells of a study are run, so a small study reproduces the corresponding cells of
a large one exactly. Each trial draws a new true robot.

Standard deviations over trials or pooled samples are sample standard deviations
(``ddof = 1``; ``0`` for a single value).

References
----------
S.-W. Shih, J.-S. Jin, K.-H. Wei, Y.-P. Hung, "Kinematic identification of an active
binocular head", 1992, section 6, Fig. 10, Fig. 11 and Table 4.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Iterable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from identification.closed_form import identify_closed_form
from kinfw.cpc import CPCModel, cpc_from_robot
from kinfw.measurements import Measurements, PoseObservations
from kinfw.robot import Robot, load_robot
from verification.simulate import (
    one_joint_at_a_time,
    perturb_poses,
    perturb_robot,
    random_configurations,
)
from verification.studies import (
    FieldsJSON,
    Progress,
    check_count,
    choice_main,
    freeze,
    log_axes,
    new_figure,
    readonly,
    run_on_head,
    run_trials,
    sample_std,
    save_figure,
    shared_legend,
)

__all__ = [
    "PAPER_ACCURACY_MM",
    "PAPER_PER_JOINT",
    "PAPER_TABLE4_FRAMES",
    "PAPER_TABLE4_MU_MM",
    "PAPER_TABLE4_SIGMA_MM",
    "Fig11Result",
    "StudySetup",
    "Table4Result",
    "fig11_study",
    "format_fig11",
    "format_table4",
    "plot_fig11",
    "plot_table4",
    "run_fig11",
    "run_table4",
    "table4_study",
]

log = logging.getLogger(__name__)

#: The paper's accuracy requirement on the positioning error, mm (section 6).
PAPER_ACCURACY_MM = 1.0
#: Measurements per joint the paper chose from its Fig. 11 (section 6).
PAPER_PER_JOINT = 9
#: End frames of the rows of the paper's Table 4: left branch, right branch.
PAPER_TABLE4_FRAMES = ("left_plate", "right_plate")
#: Table 4 of the paper (real data, nine test configurations): mean of ``|error|`` in
#: x, y, z, mm; rows ``PAPER_TABLE4_FRAMES``.
PAPER_TABLE4_MU_MM = readonly([[0.65, 0.23, 0.35], [0.28, 0.13, 0.11]])
#: Table 4 of the paper: standard deviation of ``|error|`` in x, y, z, mm.
PAPER_TABLE4_SIGMA_MM = readonly([[0.24, 0.12, 0.30], [0.31, 0.21, 0.35]])

_FIG11_TAG = 11  # study tags in the seeds, so the two studies draw different numbers
_TABLE4_TAG = 4


# -- set-up shared by both studies -------------------------------------------------------


@dataclass(frozen=True, slots=True)
class StudySetup(FieldsJSON):
    """What every trial of a study shares: robot, frames, truth errors, noise, range.

    Attributes
    ----------
    urdf : str
        Source of the nominal URDF (file path or ``"<urdf string>"``), for the record.
    frames : tuple of str
        Measured end frames (the plates).
    joint_names : tuple of str
        Joints that carry ``frames``, column order of every configuration.
    error_mm : float
        Standard deviation of each origin translation component of the true robot, mm.
    error_deg : float
        Standard deviation of each origin rotation angle and axis tilt of the true robot,
        degrees.
    rot_per_mm_rad : float
        Rotation noise per unit of position noise, rad/mm: ``sigma_rad = sigma_mm *
        rot_per_mm_rad`` (1/50: 0.01 rad = 0.57 deg at 0.5 mm).
    fraction : float
        Part of each joint's range used for calibration and test configurations.
    seed : int
        Base seed of the study.
    """

    urdf: str
    frames: tuple[str, ...]
    joint_names: tuple[str, ...]
    error_mm: float
    error_deg: float
    rot_per_mm_rad: float
    fraction: float
    seed: int

    def sigma_rad(self, sigma_mm: float | NDArray[np.float64]) -> Any:
        """Rotation noise (rad) that goes with position noise ``sigma_mm`` (mm)."""
        return np.asarray(sigma_mm, dtype=float) * self.rot_per_mm_rad

    def describe(self) -> str:
        """One line: truth errors, noise model and range, for headers and titles."""
        return (f"truth = nominal + N(0, {self.error_mm:g} mm) origins, N(0, "
                f"{self.error_deg:g} deg) rotations and axes; noise: position N(0, sigma) per "
                f"axis, rotation N(0, sigma x {self.rot_per_mm_rad:.4g} rad/mm) about a random "
                f"axis; central {100 * self.fraction:g} % of each joint range")



def _setup(nominal: Robot, frames: Sequence[str] | None, *, error_mm: float, error_deg: float,
           rot_per_mm_rad: float, fraction: float, seed: int) -> StudySetup:
    if frames is None:
        frames = nominal.default_frames
    if isinstance(frames, str):
        raise TypeError("frames: expected a sequence of frame names, not a string")
    frames = tuple(frames)
    if not frames:
        raise ValueError(f"{nominal.source}: give frames (the measured plates); this URDF has "
                         'no <kinfw frames="..."/> hint')
    for name, value in (("error_mm", error_mm), ("error_deg", error_deg),
                        ("rot_per_mm_rad", rot_per_mm_rad)):
        if not (np.isfinite(value) and value >= 0.0):
            raise ValueError(f"{name}: expected a finite value >= 0, got {value}")
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction: expected 0 < fraction <= 1, got {fraction}")
    return StudySetup(urdf=nominal.source, frames=frames,
                      joint_names=nominal.topology(frames).joint_names,
                      error_mm=float(error_mm), error_deg=float(error_deg),
                      rot_per_mm_rad=float(rot_per_mm_rad), fraction=float(fraction),
                      seed=int(seed))


def _check_sigmas_mm(values: Iterable[float], name: str) -> NDArray[np.float64]:
    out = np.array(list(values) if not np.isscalar(values) else [values], dtype=float)
    if out.ndim != 1 or not out.size or not (np.isfinite(out).all() and (out >= 0.0).all()):
        raise ValueError(f"{name}: expected finite noise levels >= 0 (mm), got {out.tolist()}")
    return out


def _trial_rng(setup: StudySetup, study: int, sigma_mm: float, per_joint: int, trial: int
               ) -> np.random.Generator:
    """The generator of one trial (module docstring: seeds)."""
    sigma_nm = round(float(sigma_mm) * 1e6)
    return np.random.default_rng([setup.seed, study, sigma_nm, per_joint, trial])


@dataclass(frozen=True, slots=True)
class _Trial:
    """One calibration: the truth's and the identified CPC models, and the generator
    positioned after the calibration draws (for the test draws)."""

    truth: CPCModel
    identified: CPCModel
    rng: np.random.Generator


def _calibrate_once(nominal: Robot, setup: StudySetup, lower: NDArray, upper: NDArray, *,
                    per_joint: int, sigma_mm: float, rng: np.random.Generator) -> _Trial:
    """Steps 1-4 of the module docstring: a new truth, noisy one-joint data, closed form."""
    truth_xml = perturb_robot(nominal, rng, origin_mm=setup.error_mm,
                              origin_deg=setup.error_deg, axis_deg=setup.error_deg)
    truth = cpc_from_robot(load_robot(truth_xml), setup.frames)
    qs, _ = one_joint_at_a_time(lower, upper, per_joint=per_joint, fraction=setup.fraction)
    w_T_plates = truth.frame_poses(qs)  # (n, E, 4, 4)
    sample = np.arange(len(qs))
    poses = tuple(
        PoseObservations(frame=f, sample=sample,
                         meas_T_frame=perturb_poses(w_T_plates[:, e], rng, 1e-3 * sigma_mm,
                                                    float(setup.sigma_rad(sigma_mm))))
        for e, f in enumerate(truth.topology.frames))
    data = Measurements(joint_names=setup.joint_names, qs=qs, poses=poses,
                        source=f"<simulated: M = {per_joint}, sigma = {sigma_mm:g} mm>")
    identified = identify_closed_form(nominal, data, frames=setup.frames).model
    return _Trial(truth, identified, rng)


def _positions_m(model: CPCModel, qs: NDArray, frames: tuple[str, ...]) -> NDArray[np.float64]:
    """Positions of ``frames`` in the measurement frame, (n, E, 3), metres."""
    return np.stack([model.frame_poses(qs, f)[:, :3, 3] for f in frames], axis=1)


# -- Fig. 11 -----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Fig11Result:
    """Positioning error versus measurements per joint and noise (Shih et al. Fig. 11).

    Attributes
    ----------
    setup : StudySetup
    per_joint : ndarray of int64, shape (K,)
        Measurements per joint, ``M``.
    sigmas_mm : ndarray, shape (S,)
        Position noise per axis, mm; the rotation noise is ``setup.sigma_rad(sigmas_mm)``.
    n_test : int
        Held-out test configurations per trial.
    errors_mm : ndarray, shape (S, K, T, E)
        Per noise level, ``M``, trial and end frame: the mean over the test
        configurations of the positioning error ``|p_true - p_identified|``, mm.
    """

    setup: StudySetup
    per_joint: NDArray[np.int64]
    sigmas_mm: NDArray[np.float64]
    n_test: int
    errors_mm: NDArray[np.float64]

    @property
    def trials(self) -> int:
        return int(self.errors_mm.shape[2])

    @property
    def sigmas_rad(self) -> NDArray[np.float64]:
        """Rotation noise of each level, rad."""
        return self.setup.sigma_rad(self.sigmas_mm)

    @property
    def trial_mean_mm(self) -> NDArray[np.float64]:
        """Mean positioning error of each trial over test configurations and frames,
        shape (S, K, T), mm."""
        return self.errors_mm.mean(axis=3)

    @property
    def mean_mm(self) -> NDArray[np.float64]:
        """Mean over trials of :attr:`trial_mean_mm`, shape (S, K), mm (Fig. 11's points)."""
        return self.trial_mean_mm.mean(axis=2)

    @property
    def std_mm(self) -> NDArray[np.float64]:
        """Standard deviation over trials of :attr:`trial_mean_mm`, shape (S, K), mm."""
        return sample_std(self.trial_mean_mm, axis=2)

    def smallest_per_joint(self, requirement_mm: float = PAPER_ACCURACY_MM
                           ) -> NDArray[np.float64]:
        """Per noise level, the smallest ``M`` from which on every mean error is below
        ``requirement_mm`` (NaN if none), shape (S,)."""
        ok = self.mean_mm < requirement_mm
        out = np.full(len(self.sigmas_mm), np.nan)
        for s, row in enumerate(ok):
            bad = np.flatnonzero(~row)
            first = 0 if not bad.size else bad[-1] + 1
            if first < len(row):
                out[s] = self.per_joint[first]
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: set-up, raw per-trial errors and the summary (mm, rad)."""
        return {
            "study": "Shih et al. 1992, Fig. 11 (simulation)",
            "setup": self.setup.to_dict(),
            "per_joint": self.per_joint.tolist(),
            "sigmas_mm": self.sigmas_mm.tolist(),
            "sigmas_rad": self.sigmas_rad.tolist(),
            "n_test": self.n_test,
            "trials": self.trials,
            "errors_mm": self.errors_mm.tolist(),
            "mean_mm": self.mean_mm.tolist(),
            "std_mm": self.std_mm.tolist(),
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> Fig11Result:
        """The result written by :meth:`to_dict` (the summary is recomputed)."""
        return cls(setup=StudySetup.from_dict(doc["setup"]),
                   per_joint=np.array(doc["per_joint"], dtype=np.int64),
                   sigmas_mm=np.array(doc["sigmas_mm"], dtype=float),
                   n_test=int(doc["n_test"]),
                   errors_mm=np.array(doc["errors_mm"], dtype=float))


def _fig11_trial(nominal: Robot, setup: StudySetup, lower: NDArray, upper: NDArray,
                 sigma: float, m: int, t: int, n_test: int) -> NDArray[np.float64]:
    """One trial of :func:`fig11_study` (a task: module level, picklable arguments): the
    mean held-out position error per frame, mm."""
    rng = _trial_rng(setup, _FIG11_TAG, sigma, m, t)
    trial = _calibrate_once(nominal, setup, lower, upper, per_joint=m, sigma_mm=sigma,
                            rng=rng)
    qs = random_configurations(lower, upper, n_test, trial.rng, fraction=setup.fraction)
    d = (_positions_m(trial.truth, qs, setup.frames)
         - _positions_m(trial.identified, qs, setup.frames))
    return 1e3 * np.linalg.norm(d, axis=-1).mean(axis=0)


def fig11_study(nominal: Robot, *, per_joint: Iterable[int] = range(2, 16),
                sigmas_mm: Iterable[float] = (0.1, 0.25, 0.5, 1.0), trials: int = 10,
                n_test: int = 200, rot_per_mm_rad: float = 1.0 / 50.0, error_mm: float = 5.0,
                error_deg: float = 1.0, fraction: float = 0.8, seed: int = 0,
                frames: Sequence[str] | None = None,
                progress: Progress | None = None,
                executor: Executor | None = None) -> Fig11Result:
    """Shih et al. (1992) Fig. 11: positioning error vs measurements per joint and noise.

    For each noise level ``sigma`` and each ``M`` in ``per_joint``, ``trials`` random
    trials; each draws a new true robot, measures its plates one joint at a time with
    ``M`` values per joint and Fig. 10 noise, identifies the CPC model in closed form and
    evaluates it on ``n_test`` random configurations of the calibration range.

    Parameters
    ----------
    nominal : Robot
        The nominal robot (e.g. the built-in IIS-head); its topology is all the
        identification uses.
    per_joint : iterable of int, optional
        Measurements per joint, ``M`` (each >= 1).
    sigmas_mm : iterable of float, optional
        Position noise, standard deviation per axis, mm.
    trials : int, optional
        Random trials per ``(sigma, M)`` (the paper: ten).
    n_test : int, optional
        Held-out test configurations per trial.
    rot_per_mm_rad : float, optional
        Rotation noise per mm of position noise: the rotation error angle is
        ``N(0, sigma_mm * rot_per_mm_rad)`` rad (default: 0.01 rad = 0.57 deg at 0.5 mm).
    error_mm, error_deg : float, optional
        Geometric errors of the true robot: standard deviation of each origin
        translation component (mm) and of each origin rotation and axis tilt (deg).
    fraction : float, optional
        Centred part of each joint range used for calibration and test.
    seed : int, optional
        Base seed (module docstring).
    frames : sequence of str, optional
        Measured end frames; default the URDF's ``<kinfw frames>`` hint (the plates).
    progress : callable, optional
        Called as ``progress(done, total)`` after each trial.

    Returns
    -------
    Fig11Result

    Notes
    -----
    The positioning error is the paper's error measure, the Euclidean distance between
    the true and the model's end-frame positions; each trial records its mean over the
    test configurations, per frame. Noise-free data (``sigma = 0``) recovers the truth
    exactly, whatever ``M``.
    """
    setup = _setup(nominal, frames, error_mm=error_mm, error_deg=error_deg,
                   rot_per_mm_rad=rot_per_mm_rad, fraction=fraction, seed=seed)
    ms = np.array([check_count(m, "per_joint", 1) for m in per_joint], dtype=np.int64)
    if not ms.size:
        raise ValueError("per_joint: expected at least one number of measurements per joint")
    sigmas = _check_sigmas_mm(sigmas_mm, "sigmas_mm")
    trials = check_count(trials, "trials", 1)
    n_test = check_count(n_test, "n_test", 1)
    lower, upper = nominal.joint_limits(setup.joint_names)
    errors = np.empty((len(sigmas), len(ms), trials, len(setup.frames)))
    cells = [(s, k, t) for s in range(len(sigmas)) for k in range(len(ms))
             for t in range(trials)]
    results = run_trials(_fig11_trial, [(nominal, setup, lower, upper, float(sigmas[s]),
                                         int(ms[k]), t, n_test) for s, k, t in cells],
                         executor=executor, progress=progress)
    for (s, k, t), error in zip(cells, results, strict=True):
        errors[s, k, t] = error
    for s, sigma in enumerate(sigmas):
        for k, m in enumerate(ms):
            log.info("fig11: sigma %.3g mm, M = %d: mean error %.3g mm", sigma, m,
                     errors[s, k].mean())
    freeze(ms, sigmas, errors)
    return Fig11Result(setup=setup, per_joint=ms, sigmas_mm=sigmas, n_test=n_test,
                       errors_mm=errors)


# -- Table 4 -----------------------------------------------------------------------------


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
        return [PAPER_TABLE4_FRAMES.index(f) if f in PAPER_TABLE4_FRAMES else None
                for f in self.setup.frames]

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
                f: {"measured_mu_mm": self.measured_mu_mm[e].tolist(),
                    "measured_sigma_mm": self.measured_sigma_mm[e].tolist(),
                    "truth_mu_mm": self.truth_mu_mm[e].tolist(),
                    "truth_sigma_mm": self.truth_sigma_mm[e].tolist(),
                    **({} if row is None else
                       {"paper_mu_mm": PAPER_TABLE4_MU_MM[row].tolist(),
                        "paper_sigma_mm": PAPER_TABLE4_SIGMA_MM[row].tolist()})}
                for e, (f, row) in enumerate(zip(self.setup.frames, self.paper_rows(),
                                                 strict=True))
            },
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> Table4Result:
        """The result written by :meth:`to_dict` (the summary is recomputed)."""
        return cls(setup=StudySetup.from_dict(doc["setup"]), per_joint=int(doc["per_joint"]),
                   sigma_mm=float(doc["sigma_mm"]), n_test=int(doc["n_test"]),
                   error_vs_measured_mm=np.array(doc["error_vs_measured_mm"], dtype=float),
                   error_vs_truth_mm=np.array(doc["error_vs_truth_mm"], dtype=float))


def _table4_trial(nominal: Robot, setup: StudySetup, lower: NDArray, upper: NDArray,
                  sigma: float, per_joint: int, t: int, n_test: int
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One trial of :func:`table4_study` (a task): held-out errors against the noisy
    measurements and against the truth, (n_test, E, 3) mm."""
    rng = _trial_rng(setup, _TABLE4_TAG, sigma, per_joint, t)
    trial = _calibrate_once(nominal, setup, lower, upper, per_joint=per_joint,
                            sigma_mm=sigma, rng=rng)
    qs = random_configurations(lower, upper, n_test, trial.rng, fraction=setup.fraction)
    true_p = _positions_m(trial.truth, qs, setup.frames)
    measured_p = true_p + trial.rng.normal(0.0, 1e-3 * sigma, size=true_p.shape)
    predicted_p = _positions_m(trial.identified, qs, setup.frames)
    return 1e3 * (measured_p - predicted_p), 1e3 * (true_p - predicted_p)


def table4_study(nominal: Robot, *, per_joint: int = PAPER_PER_JOINT, sigma_mm: float = 0.5,
                 trials: int = 20, n_test: int = 9, rot_per_mm_rad: float = 1.0 / 50.0,
                 error_mm: float = 5.0, error_deg: float = 1.0, fraction: float = 0.8,
                 seed: int = 0, frames: Sequence[str] | None = None,
                 progress: Progress | None = None,
                 executor: Executor | None = None) -> Table4Result:
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
    rot_per_mm_rad, error_mm, error_deg, fraction, seed, frames, progress
        As for :func:`fig11_study`.

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
    setup = _setup(nominal, frames, error_mm=error_mm, error_deg=error_deg,
                   rot_per_mm_rad=rot_per_mm_rad, fraction=fraction, seed=seed)
    per_joint = check_count(per_joint, "per_joint", 1)
    sigma = float(_check_sigmas_mm([sigma_mm], "sigma_mm")[0])
    trials = check_count(trials, "trials", 1)
    n_test = check_count(n_test, "n_test", 1)
    lower, upper = nominal.joint_limits(setup.joint_names)
    shape = (trials, n_test, len(setup.frames), 3)
    vs_measured, vs_truth = np.empty(shape), np.empty(shape)
    results = run_trials(_table4_trial, [(nominal, setup, lower, upper, sigma, per_joint, t,
                                          n_test) for t in range(trials)],
                         executor=executor, progress=progress)
    for t, (measured, truth) in enumerate(results):
        vs_measured[t], vs_truth[t] = measured, truth
    freeze(vs_measured, vs_truth)
    return Table4Result(setup=setup, per_joint=per_joint, sigma_mm=sigma, n_test=n_test,
                        error_vs_measured_mm=vs_measured, error_vs_truth_mm=vs_truth)


# -- text tables -------------------------------------------------------------------------


def _sigma_label(sigma_mm: float, sigma_rad: float) -> str:
    return f"σ = {sigma_mm:g} mm (rotation σ = {np.degrees(sigma_rad):.2f}°)"


def format_fig11(result: Fig11Result) -> str:
    """Markdown table of Fig. 11: mean ± std over trials of the positioning error (mm).

    Rows are ``M`` (measurements per joint), columns the noise levels; below it the
    paper's conclusion beside ours.
    """
    r = result
    head = [f"σ = {s:g} mm ({np.degrees(a):.2f}°)" for s, a in
            zip(r.sigmas_mm, r.sigmas_rad, strict=True)]
    lines = [
        "Shih et al. (1992) Fig. 11 in simulation: mean positioning error (mm) of the "
        f"closed-form model on {r.n_test} held-out configurations, mean ± std over "
        f"{r.trials} trials ({', '.join(r.setup.frames)}).",
        r.setup.describe() + ".",
        "",
        "| M per joint | " + " | ".join(head) + " |",
        "|---:|" + "---:|" * len(head),
    ]
    for k, m in enumerate(r.per_joint):
        cells = [f"{r.mean_mm[s, k]:.3g} ± {r.std_mm[s, k]:.2g}" for s in range(len(head))]
        mark = " (paper's choice)" if m == PAPER_PER_JOINT else ""
        lines.append(f"| {m}{mark} | " + " | ".join(cells) + " |")
    smallest = r.smallest_per_joint(PAPER_ACCURACY_MM)
    ours = "; ".join(
        f"σ = {s:g} mm: {'none of the M tried' if np.isnan(m) else f'M >= {int(m)}'}"
        for s, m in zip(r.sigmas_mm, smallest, strict=True))
    lines += [
        "",
        f"Paper: for {PAPER_ACCURACY_MM:g} mm accuracy the observation error must stay below "
        "0.5 mm and more than five measurements per joint are needed; it chose "
        f"{PAPER_PER_JOINT} (its Fig. 11 gives no numbers).",
        f"Ours: mean error below {PAPER_ACCURACY_MM:g} mm for {ours}.",
    ]
    return "\n".join(lines)


def format_table4(result: Table4Result) -> str:
    """Markdown table of Table 4: mu and sigma of ``|error|`` per axis and branch (mm),
    the paper's real-data values beside ours (vs noisy measurements and vs truth)."""
    r = result
    floor = r.sigma_mm * np.sqrt(2.0 / np.pi)
    lines = [
        f"Shih et al. (1992) Table 4 in simulation: calibrated with {r.per_joint} measurements "
        f"per joint, {_sigma_label(r.sigma_mm, r.sigma_rad)}; {r.n_test} test configurations "
        f"x {r.trials} trials pooled. mu, sigma: mean and std of |error| (mm).",
        r.setup.describe() + ".",
        "",
        "| branch | axis | paper mu | paper sigma | ours vs measured mu | sigma "
        "| ours vs truth mu | sigma |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for e, (frame, row) in enumerate(zip(r.setup.frames, r.paper_rows(), strict=True)):
        for a, axis in enumerate("xyz"):
            paper = (["–", "–"] if row is None else
                     [f"{PAPER_TABLE4_MU_MM[row, a]:.2f}", f"{PAPER_TABLE4_SIGMA_MM[row, a]:.2f}"])
            ours = [r.measured_mu_mm[e, a], r.measured_sigma_mm[e, a], r.truth_mu_mm[e, a],
                    r.truth_sigma_mm[e, a]]
            lines.append(f"| {frame} | {axis} | " + " | ".join(paper)
                         + " | " + " | ".join(f"{v:.2f}" for v in ours) + " |")
    lines += [
        "",
        "Paper: real data (stereo rig, about 0.5 mm), nine test configurations; its errors "
        "include the measurement noise, like 'vs measured'.",
        f"Noise floor vs measured: E|N(0, σ)| = σ sqrt(2/π) = {floor:.2f} mm per axis.",
    ]
    return "\n".join(lines)


# -- plots -------------------------------------------------------------------------------


def plot_fig11(result: Fig11Result, path: str | Path) -> Path:
    """Write Fig. 11 as a PNG: mean positioning error vs measurements per joint.

    One line per noise level with ± std (over trials) error bars, log-scale error axis,
    the paper's 1 mm requirement dashed and its choice ``M = 9`` dotted.

    Returns
    -------
    Path
        ``path``.
    """
    r = result
    fig = new_figure((8.0, 6.2))
    ax = fig.add_subplot()
    mean, std = r.mean_mm, r.std_mm
    for s, (sigma, sigma_rad) in enumerate(zip(r.sigmas_mm, r.sigmas_rad, strict=True)):
        # On a log axis, a lower bar below zero cannot be drawn: stop it at 5 % of the mean.
        lower = np.minimum(std[s], 0.95 * mean[s])
        ax.errorbar(r.per_joint, mean[s], yerr=np.stack([lower, std[s]]), marker="o",
                    markersize=4, capsize=3, linewidth=1.5,
                    label=_sigma_label(sigma, sigma_rad))
    ax.axhline(PAPER_ACCURACY_MM, color="0.2", linestyle="--", linewidth=1.2,
               label=f"paper's requirement: {PAPER_ACCURACY_MM:g} mm")
    if r.per_joint.min() <= PAPER_PER_JOINT <= r.per_joint.max():
        ax.axvline(PAPER_PER_JOINT, color="0.5", linestyle=":", linewidth=1.2,
                   label=f"paper's choice: M = {PAPER_PER_JOINT}")
    positive = mean[mean > 0]
    if positive.size and positive.max() / positive.min() > 8.0:
        log_axes(ax, "y")
    ax.set_xticks(r.per_joint)
    ax.set_xlabel("measurements per joint, M")
    ax.set_ylabel("mean positioning error (mm), ± std over trials")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(
        "Reproduction of Shih et al. (1992) Fig. 11: closed-form CPC identification\n"
        f"{r.trials} random trials per point (new true robot each), {r.n_test} held-out "
        f"test configurations, {' + '.join(r.setup.frames)}", fontsize=10)
    fig.legend(fontsize=8.5, loc="outside lower center", ncols=3)
    return save_figure(fig, path)


def plot_table4(result: Table4Result, path: str | Path) -> Path:
    """Write Table 4 as a PNG: mu ± sigma of ``|error|`` per axis, one panel per branch,
    the paper's real-data values beside ours (vs noisy measurements and vs truth).

    Returns
    -------
    Path
        ``path``.
    """
    r = result
    frames = r.setup.frames
    fig = new_figure((4.2 * len(frames) + 1.0, 5.0))
    axes = fig.subplots(1, len(frames), sharey=True, squeeze=False)[0]
    x = np.arange(3)
    series = [
        ("paper (real data)", PAPER_TABLE4_MU_MM, PAPER_TABLE4_SIGMA_MM, "0.55"),
        ("ours vs noisy measurements", r.measured_mu_mm, r.measured_sigma_mm, "tab:blue"),
        ("ours vs truth", r.truth_mu_mm, r.truth_sigma_mm, "tab:orange"),
    ]
    width = 0.8 / len(series)
    rows = r.paper_rows()
    for e, (ax, frame) in enumerate(zip(axes, frames, strict=True)):
        for i, (label, mu, sigma, color) in enumerate(series):
            if i == 0 and rows[e] is None:
                continue
            k = rows[e] if i == 0 else e
            # |error| >= 0: a lower bar that would cross zero stops there.
            yerr = np.stack([np.minimum(sigma[k], mu[k]), sigma[k]])
            ax.bar(x + (i - 1) * width, mu[k], width, yerr=yerr, capsize=3, color=color,
                   label=label,
                   error_kw={"elinewidth": 1.0})
        ax.axhline(r.sigma_mm * np.sqrt(2.0 / np.pi), color="0.2", linestyle=":",
                   linewidth=1.0, label="measurement noise alone, σ√(2/π)")
        ax.set_xticks(x, ["x", "y", "z"])
        ax.set_title(frame)
        ax.set_xlabel("axis of the measurement frame")
        ax.set_ylim(bottom=0.0)
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].set_ylabel("|error| (mm): bar = mean, whisker = ± std")
    shared_legend(fig, axes)
    fig.suptitle(
        f"Reproduction of Shih et al. (1992) Table 4: {r.per_joint} measurements per joint, "
        f"{_sigma_label(r.sigma_mm, r.sigma_rad)}\n"
        f"{r.n_test} held-out test configurations × {r.trials} trials (new true robot each); "
        "paper: real data", fontsize=10)
    return save_figure(fig, path)


# -- runs on the built-in head -----------------------------------------------------------


def run_fig11(out_dir: str | Path, *, urdf: str | Path | None = None, **kwargs: Any
              ) -> Fig11Result:
    """Run :func:`fig11_study` (on the built-in IIS-head unless ``urdf``) and write
    ``fig11.png`` and ``fig11.json`` into ``out_dir``; ``kwargs`` go to the study."""
    return run_on_head(fig11_study, plot_fig11, out_dir, "fig11", urdf, kwargs)


def run_table4(out_dir: str | Path, *, urdf: str | Path | None = None, **kwargs: Any
               ) -> Table4Result:
    """Run :func:`table4_study` (on the built-in IIS-head unless ``urdf``) and write
    ``table4.png`` and ``table4.json`` into ``out_dir``; ``kwargs`` go to the study."""
    return run_on_head(table4_study, plot_table4, out_dir, "table4", urdf, kwargs)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m verification.shih_experiments {fig11,table4} --out DIR [--trials N]
    [--seed S]``: run one study on the built-in head, write its PNG and JSON, print the
    table."""
    return choice_main(
        argv, prog="python -m verification.shih_experiments",
        description="Shih et al. (1992) section 6 in simulation: Fig. 11 or Table 4.",
        trials_help="random trials (default: 10 per Fig. 11 point, 20 for Table 4)",
        studies={"fig11": (run_fig11, format_fig11), "table4": (run_table4, format_table4)})

if __name__ == "__main__":
    sys.exit(main())
