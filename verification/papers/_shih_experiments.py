"""The experiments of Shih et al. (1992), section 6, in simulation: the set-up and Fig. 11.

Both studies follow the paper's simulation (its Fig. 10) over the built-in IIS-head (or
any URDF with two or more measured end frames):

1. a *true* robot: the nominal URDF with random geometric errors
   (:func:`kinfw.simulation.perturb_robot`, ``error_mm`` on every origin
   translation component, ``error_deg`` on every origin rotation and axis direction);
2. one-joint-at-a-time plate poses of the truth (the paper's section 4.1 protocol,
   :func:`kinfw.simulation.one_joint_at_a_time`), ``M`` values per joint inside
   the centred ``fraction`` of each joint's range;
3. measurement noise as in Fig. 10 (:func:`kinfw.simulation.perturb_poses`): each
   position component gets ``N(0, sigma)``; the orientation is turned about a uniformly
   random axis by an angle ``N(0, sigma_rad)`` with ``sigma_rad = sigma_mm *
   rot_per_mm_rad`` (default 1/50 rad per mm: 0.01 rad = 0.57 deg at sigma = 0.5 mm);
   joint values are exact, as in the paper;
4. the closed-form identification of section 4
   (:func:`kinfw.identification.identify_closed_form`);
5. the identified CPC model tested on configurations drawn from the same calibration
   range but not used to calibrate.

Forward kinematics of the truth is the CPC model converted from its URDF
(:func:`kinfw.model.cpc_from_robot`, equal to Pinocchio's FK to 1e-12, see
:mod:`kinfw.verification.evaluation`), vectorised over configurations.

Random numbers. Every random trial has its own ``numpy.random.Generator`` seeded with
``(seed, study, sigma in nm, M, trial)``: a trial's result does not depend on which
other cells of a study are run, so a small study reproduces the corresponding cells of
a large one exactly. Each trial draws a new true robot.

This module holds the simulation both studies share and Fig. 11 (:func:`fig11_study`);
``_shih_table4.py`` holds Table 4, ``_shih_figures.py`` their
tables, figures and command line.

Standard deviations over trials or pooled samples are sample standard deviations
(``ddof = 1``; ``0`` for a single value).

References
----------
S.-W. Shih, J.-S. Jin, K.-H. Wei, Y.-P. Hung, "Kinematic identification of an active
binocular head", 1992, section 6, Fig. 10, Fig. 11 and Table 4.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.identification import identify_closed_form
from kinfw.measurements import Measurements
from kinfw.model import CPCModel, Robot, cpc_from_robot, load_robot
from kinfw.observations import PoseObservations
from kinfw.simulation import (
    one_joint_at_a_time,
    perturb_poses,
    perturb_robot,
    random_configurations,
)
from kinfw.verification.evaluation import check_count, run_trials
from kinfw.verification.studies import FieldsJSON, freeze, sample_std

log = logging.getLogger(__name__)


#: The paper's accuracy requirement on the positioning error, mm (section 6).
PAPER_ACCURACY_MM = 1.0


#: Measurements per joint the paper chose from its Fig. 11 (section 6).
PAPER_PER_JOINT = 9


_FIG11_TAG = 11  # study tags in the seeds, so the two studies draw different numbers


# -- set-up shared by both studies -----------------------------------------------------


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
        return (
            f"truth = nominal + N(0, {self.error_mm:g} mm) origins, N(0, "
            f"{self.error_deg:g} deg) rotations and axes; noise: position N(0, sigma) per "
            f"axis, rotation N(0, sigma x {self.rot_per_mm_rad:.4g} rad/mm) about a random "
            f"axis; central {100 * self.fraction:g} % of each joint range"
        )


def setup_study(
    nominal: Robot,
    frames: Sequence[str] | None,
    *,
    error_mm: float,
    error_deg: float,
    rot_per_mm_rad: float,
    fraction: float,
    seed: int,
) -> StudySetup:
    """The checked set-up of a study on ``nominal`` (``frames`` default to its
    ``<kinfw frames>`` hint); the arguments are :class:`StudySetup`'s fields."""
    if frames is None:
        frames = nominal.default_frames
    if isinstance(frames, str):
        raise TypeError("frames: expected a sequence of frame names, not a string")
    frames = tuple(frames)
    if not frames:
        raise ValueError(
            f"{nominal.source}: give frames (the measured plates); this URDF has "
            'no <kinfw frames="..."/> hint'
        )
    for name, value in (
        ("error_mm", error_mm),
        ("error_deg", error_deg),
        ("rot_per_mm_rad", rot_per_mm_rad),
    ):
        if not (np.isfinite(value) and value >= 0.0):
            raise ValueError(f"{name}: expected a finite value >= 0, got {value}")
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction: expected 0 < fraction <= 1, got {fraction}")
    return StudySetup(
        urdf=nominal.source,
        frames=frames,
        joint_names=nominal.topology(frames).joint_names,
        error_mm=float(error_mm),
        error_deg=float(error_deg),
        rot_per_mm_rad=float(rot_per_mm_rad),
        fraction=float(fraction),
        seed=int(seed),
    )


def check_sigmas_mm(values: Iterable[float], name: str) -> NDArray[np.float64]:
    """Noise levels (mm) as a 1-D array; a ``ValueError`` naming ``name`` unless finite
    and >= 0."""
    out = np.array(list(values) if not np.isscalar(values) else [values], dtype=float)
    if out.ndim != 1 or not out.size or not (np.isfinite(out).all() and (out >= 0.0).all()):
        raise ValueError(f"{name}: expected finite noise levels >= 0 (mm), got {out.tolist()}")
    return out


def trial_rng(
    setup: StudySetup, study: int, sigma_mm: float, per_joint: int, trial: int
) -> np.random.Generator:
    """The generator of one trial (module docstring: seeds)."""
    sigma_nm = round(float(sigma_mm) * 1e6)
    return np.random.default_rng([setup.seed, study, sigma_nm, per_joint, trial])


@dataclass(frozen=True, slots=True)
class Trial:
    """One calibration: the truth's and the identified CPC models, and the generator
    positioned after the calibration draws (for the test draws)."""

    truth: CPCModel
    identified: CPCModel
    rng: np.random.Generator


def calibrate_once(
    nominal: Robot,
    setup: StudySetup,
    lower: NDArray,
    upper: NDArray,
    *,
    per_joint: int,
    sigma_mm: float,
    rng: np.random.Generator,
) -> Trial:
    """Steps 1-4 of the module docstring: a new truth, noisy one-joint data, closed form."""
    truth_xml = perturb_robot(
        nominal, rng, origin_mm=setup.error_mm, origin_deg=setup.error_deg, axis_deg=setup.error_deg
    )
    truth = cpc_from_robot(load_robot(truth_xml), setup.frames)
    qs, _ = one_joint_at_a_time(lower, upper, per_joint=per_joint, fraction=setup.fraction)
    w_T_plates = truth.frame_poses(qs)  # (n, E, 4, 4)
    sample = np.arange(len(qs))
    poses = tuple(
        PoseObservations(
            frame=f,
            sample=sample,
            meas_T_frame=perturb_poses(
                w_T_plates[:, e], rng, 1e-3 * sigma_mm, float(setup.sigma_rad(sigma_mm))
            ),
        )
        for e, f in enumerate(truth.topology.frames)
    )
    data = Measurements(
        joint_names=setup.joint_names,
        qs=qs,
        poses=poses,
        source=f"<simulated: M = {per_joint}, sigma = {sigma_mm:g} mm>",
    )
    identified = identify_closed_form(nominal, data, frames=setup.frames).model
    return Trial(truth, identified, rng)


def positions_m(model: CPCModel, qs: NDArray, frames: tuple[str, ...]) -> NDArray[np.float64]:
    """Positions of ``frames`` in the measurement frame, (n, E, 3), metres."""
    return np.stack([model.frame_poses(qs, f)[:, :3, 3] for f in frames], axis=1)


# -- Fig. 11 ---------------------------------------------------------------------------


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

    def smallest_per_joint(self, requirement_mm: float = PAPER_ACCURACY_MM) -> NDArray[np.float64]:
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
        return cls(
            setup=StudySetup.from_dict(doc["setup"]),
            per_joint=np.array(doc["per_joint"], dtype=np.int64),
            sigmas_mm=np.array(doc["sigmas_mm"], dtype=float),
            n_test=int(doc["n_test"]),
            errors_mm=np.array(doc["errors_mm"], dtype=float),
        )


def _fig11_trial(
    nominal: Robot,
    setup: StudySetup,
    lower: NDArray,
    upper: NDArray,
    sigma: float,
    m: int,
    t: int,
    n_test: int,
) -> NDArray[np.float64]:
    """One trial of :func:`fig11_study` (a task: module level, picklable arguments): the
    mean held-out position error per frame, mm."""
    rng = trial_rng(setup, _FIG11_TAG, sigma, m, t)
    trial = calibrate_once(nominal, setup, lower, upper, per_joint=m, sigma_mm=sigma, rng=rng)
    qs = random_configurations(lower, upper, n_test, trial.rng, fraction=setup.fraction)
    d = positions_m(trial.truth, qs, setup.frames) - positions_m(trial.identified, qs, setup.frames)
    return 1e3 * np.linalg.norm(d, axis=-1).mean(axis=0)


def fig11_study(
    nominal: Robot,
    *,
    per_joint: Iterable[int] = range(2, 16),
    sigmas_mm: Iterable[float] = (0.1, 0.25, 0.5, 1.0),
    trials: int = 10,
    n_test: int = 200,
    rot_per_mm_rad: float = 1.0 / 50.0,
    error_mm: float = 5.0,
    error_deg: float = 1.0,
    fraction: float = 0.8,
    seed: int = 0,
    frames: Sequence[str] | None = None,
    executor: Executor | None = None,
) -> Fig11Result:
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
    setup = setup_study(
        nominal,
        frames,
        error_mm=error_mm,
        error_deg=error_deg,
        rot_per_mm_rad=rot_per_mm_rad,
        fraction=fraction,
        seed=seed,
    )
    ms = np.array([check_count(m, "per_joint", 1) for m in per_joint], dtype=np.int64)
    if not ms.size:
        raise ValueError("per_joint: expected at least one number of measurements per joint")
    sigmas = check_sigmas_mm(sigmas_mm, "sigmas_mm")
    trials = check_count(trials, "trials", 1)
    n_test = check_count(n_test, "n_test", 1)
    lower, upper = nominal.joint_limits(setup.joint_names)
    errors = np.empty((len(sigmas), len(ms), trials, len(setup.frames)))
    cells = [(s, k, t) for s in range(len(sigmas)) for k in range(len(ms)) for t in range(trials)]
    results = run_trials(
        _fig11_trial,
        [
            (nominal, setup, lower, upper, float(sigmas[s]), int(ms[k]), t, n_test)
            for s, k, t in cells
        ],
        executor=executor,
    )
    for (s, k, t), error in zip(cells, results, strict=True):
        errors[s, k, t] = error
    for s, sigma in enumerate(sigmas):
        for k, m in enumerate(ms):
            log.info(
                "fig11: sigma %.3g mm, M = %d: mean error %.3g mm", sigma, m, errors[s, k].mean()
            )
    freeze(ms, sigmas, errors)
    return Fig11Result(setup=setup, per_joint=ms, sigmas_mm=sigmas, n_test=n_test, errors_mm=errors)
