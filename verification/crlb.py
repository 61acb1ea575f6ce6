"""How good can the calibration be? The Cramér-Rao bound, and robustness to outliers.

Two simulation studies of the IIS-head's two-stage experiment (the one ``kinfw demo``
runs): stage 1, the stereo rig measures both plates one joint at a time
(:func:`verification.simulate.one_joint_at_a_time`, ``per_joint`` values per joint);
stage 2, both cameras see a fixed target at ``stage2_views`` random configurations.
Every trial draws a new true head (the nominal URDF with 5 mm / 1 deg errors,
:func:`verification.simulate.perturb_robot`), simulates the data with the noise of
Shih et al.'s Fig. 10 (each position component ``N(0, sigma)``; the orientation turned
about a uniformly random axis by an angle ``N(0, sigma_rad)``), starts from the
pipeline (closed form + hand-eye, :func:`identification.pipeline.calibrate`) and
refines everything jointly (:func:`identification.refine.refine`).

:func:`crlb_study` asks whether the refined estimate is as good as the data allows.
The Cramér-Rao lower bound (CRLB) of the experiment, :func:`cramer_rao`, is the inverse
of the Fisher information ``J^T J`` of the whitened residuals at the *true* model and
target pose; :func:`predicted_position_rms` maps it to the RMS positioning error it
implies at held-out configurations, ``sqrt(mean trace(G C G^T))`` with ``G`` the
Jacobian of an end frame's position with respect to the CPC chart. An efficient
estimator reaches it: the study records the held-out error of the refined model beside
the bound (their ratio should be 1), whether the reported covariance covers the truth
(``|estimate - truth| <= k sigma`` for 68.3 %, 95.4 % and 99.7 % of the parameters at
``k = 1, 2, 3``), and the estimated noise beside the true one.

:func:`robustness_study` plants gross errors in a fraction of the observations (a fixed
distance in a random direction and a fixed angle about a random axis) and compares the
held-out error of the linear, Huber and Cauchy losses with the result on the clean data,
and counts how many planted outliers the robust loss down-weights (``refine``'s
``downweighted``: weight below 0.5) and how many clean observations it down-weights too.

Noise. Per-component orientation noise is ``sigma_rad / sqrt(3)``: a rotation by
``N(0, sigma_rad)`` about a uniformly random axis has covariance ``sigma_rad^2 / 3 I``
(:class:`ExperimentSetup.noise` is the whitening ``refine`` is given). Those components
are not Gaussian, so the bound computed under a Gaussian likelihood is, strictly, the
covariance of the best *linear* unbiased estimator (Gauss-Markov), which least squares
reaches to first order for any noise with that covariance; the orientation residual is
``sin(theta) u`` rather than ``theta u``, a difference of order ``theta^3``.

Random numbers. Trial ``t`` draws everything (truth, stage-2 configurations, noise,
held-out configurations) from ``numpy.random.default_rng([seed, 7, t])`` and the outliers
from ``default_rng([seed, 8, t])``: trial ``t`` of the robustness study corrupts exactly
the data of trial ``t`` of the CRLB study, and a study's trials do not depend on how many
are run.

References
----------
C. R. Rao (1945), H. Cramér (1946): the information inequality. S.-W. Shih et al.,
"Kinematic identification of an active binocular head", 1992 (the experiment, Fig. 10).
P. J. Huber, "Robust estimation of a location parameter", 1964 (the Huber loss).
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from identification.pipeline import calibrate
from identification.refine import (
    LeastSquaresProblem,
    NoiseModel,
    build_problem,
    information_matrix,
    refine,
)
from kinfw.cpc import (
    CPCModel,
    cpc_from_geometry,
    cpc_from_robot,
    geometry_from_robot,
)
from kinfw.measurements import Measurements, concatenate_measurements
from kinfw.robot import Robot, load_robot
from kinfw.transforms import matrix_from_rotation_vector
from verification.simulate import (
    default_target_pose,
    one_joint_at_a_time,
    perturb_robot,
    random_configurations,
    simulate,
)
from verification.studies import (
    FieldsJSON,
    Progress,
    arrays_from,
    check_count,
    choice_main,
    freeze,
    json_lists,
    log_axes,
    new_figure,
    run_on_head,
    run_trials,
    sample_std,
    save_figure,
)

__all__ = [
    "CRLB",
    "NORMAL_COVERAGE",
    "ROBUST_VARIANTS",
    "CRLBStudy",
    "ExperimentSetup",
    "RobustStudy",
    "cramer_rao",
    "crlb_study",
    "format_crlb",
    "format_robustness",
    "main",
    "plant_outliers",
    "plot_crlb",
    "plot_robustness",
    "position_jacobians",
    "predicted_position_rms",
    "robustness_study",
    "run_crlb",
    "run_robustness",
    "true_chart_coordinates",
]

log = logging.getLogger(__name__)

#: Probability that a normal variable lies within 1, 2 and 3 standard deviations.
NORMAL_COVERAGE = {1.0: 0.6826894921370859, 2.0: 0.9544997361036416, 3.0: 0.9973002039367398}

_EXPERIMENT_TAG = 7  # seeds (module docstring)
_OUTLIER_TAG = 8
_BAND_TAG = 9
_RANK_TOL = 1e-12  # eigenvalues of the scaled information below this (relative) are null


# -- the bound -------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class CRLB:
    """The Cramér-Rao bound of an experiment, in the chart around the truth.

    Attributes
    ----------
    model : CPCModel
        The true kinematics (canonical CPC model of the observed end frames): the origin
        of the chart the bound is expressed in.
    frames : tuple of str
        The measured end frames.
    parameter_names : tuple of (owner, field)
        Every unknown of the problem, as :func:`identification.refine.build_problem`
        orders them: the CPC chart of ``model`` (``model.n_parameters`` entries), then
        6 per target pose (``("target:<name>", "rot_x" ...)``, Cayley chart: rad, m).
    free : ndarray of bool, shape (P,)
        The entries the problem estimates.
    covariance : ndarray, shape (P, P)
        The bound, SI (rad, m): the pseudo-inverse of the Fisher information on the free
        entries (zeros elsewhere).
    rank : int
        Rank of the information (the number of free entries when every one is
        identifiable).
    noise : NoiseModel
        The whitening: the true measurement noise.
    """

    model: CPCModel
    frames: tuple[str, ...]
    parameter_names: tuple[tuple[str, str], ...]
    free: NDArray[np.bool_]
    covariance: NDArray[np.float64]
    rank: int
    noise: NoiseModel

    @property
    def std(self) -> NDArray[np.float64]:
        """Lower bound on each parameter's standard deviation (rad, m), shape (P,)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def model_covariance(self) -> NDArray[np.float64]:
        """The block of the CPC chart, shape (``model.n_parameters``,) * 2 (the marginal
        bound: the target poses are nuisance parameters)."""
        n = self.model.n_parameters
        return self.covariance[:n, :n]


def _check_noise(noise: NoiseModel) -> NoiseModel:
    if not isinstance(noise, NoiseModel):
        raise TypeError(f"noise: expected a NoiseModel, got {type(noise).__name__}")
    for name in ("position_m", "rotation_rad"):
        value = getattr(noise, name)
        if not (np.isfinite(value) and value > 0.0):
            raise ValueError(f"noise.{name}: expected a positive standard deviation, got {value}")
    return noise


def _pseudo_inverse(information: NDArray[np.float64]) -> tuple[NDArray[np.float64], int]:
    """Inverse of a Fisher information on its identifiable subspace, and the rank.

    The information is scaled to unit diagonal first (as ``refine`` scales the columns
    of its Jacobian), so the rank does not depend on units.
    """
    d = np.sqrt(np.clip(np.diag(information), 0.0, None))
    d[d == 0.0] = 1.0
    scaled = information / np.outer(d, d)
    w, V = np.linalg.eigh(scaled)
    keep = w > _RANK_TOL * max(float(w.max(initial=0.0)), 1e-300)
    inverse = (V[:, keep] / w[keep]) @ V[:, keep].T
    return inverse / np.outer(d, d), int(keep.sum())


def cramer_rao(truth_robot: Robot, measurements: Measurements, frames: Sequence[str], *,
               noise: NoiseModel, targets: dict[str, ArrayLike]) -> CRLB:
    """The Cramér-Rao bound of a simulated experiment.

    The least-squares problem of :func:`identification.refine.refine` is built around
    the *true* model (``start = truth_robot``) and the true target poses, and the bound
    is the inverse of its Fisher information ``J^T J``
    (:func:`identification.refine.information_matrix`; ``J`` the Jacobian of the
    residuals whitened by the true noise) — a pseudo-inverse on the identifiable
    subspace when the data leaves some directions undetermined (:attr:`CRLB.rank` says
    how many are determined; the bound is then that of the identifiable combinations).

    Parameters
    ----------
    truth_robot : Robot
        The true robot the data was simulated from.
    measurements : Measurements
        The experiment (its configurations and which frames and targets are observed;
        the measured values do not enter the bound).
    frames : sequence of str
        The measured end frames: the same set as ``measurements.observed_frames``
        (checked), e.g. the plates and the cameras.
    noise : NoiseModel
        The true measurement noise (per position component, m; per orientation
        component, rad).
    targets : dict of str to ndarray (4, 4)
        True pose ``root_T_target`` of every target the data observes.

    Returns
    -------
    CRLB

    Raises
    ------
    ValueError
        When a target's true pose is missing, or the data has unknowns whose true value
        cannot be given here (external measurement frames, markers, point offsets).

    Notes
    -----
    For any unbiased estimator ``x_hat`` of the chart coordinates,
    ``Cov(x_hat) >= (J^T J)^{-1}``; maximum likelihood (here: whitened least squares)
    reaches it as the noise becomes small against the model's curvature.
    """
    if isinstance(frames, str):
        raise TypeError("frames: expected a sequence of frame names, not a string")
    frames = tuple(frames)
    noise = _check_noise(noise)
    true_targets = {str(k): np.asarray(v, dtype=float) for k, v in targets.items()}
    problem = build_problem(truth_robot, measurements, start=truth_robot, targets=true_targets)
    unknown = [b.key for b in problem.unknown_blocks]
    missing = [k.name for k in unknown if k.kind == "target" and k.name not in true_targets]
    if missing:
        raise ValueError(f"targets: give the true pose of every observed target; missing "
                         f"{missing}")
    others = [f"{k.kind} {k.name!r}" for k in unknown if k.kind != "target"]
    if others or problem.model_frame is not None:
        raise ValueError(
            "cramer_rao: the data has unknowns whose true value cannot be given "
            f"({', '.join(others) or f'external measurement frame {problem.model_frame!r}'})"
            "; the bound is supported for pose observations in the root frame and targets")
    observed = problem.model0.topology.frames
    if set(frames) != set(observed) or len(frames) != len(observed):
        raise ValueError(f"frames: expected the observed end frames {list(observed)} (any "
                         f"order), got {list(frames)}")
    cov_free, rank = _pseudo_inverse(information_matrix(problem, noise))
    P = problem.n_parameters
    covariance = np.zeros((P, P))
    idx = np.flatnonzero(problem.free)
    covariance[np.ix_(idx, idx)] = cov_free
    if rank < len(idx):
        log.warning("cramer_rao: the information has rank %d < %d free parameters; the "
                    "bound covers the identifiable subspace only", rank, len(idx))
    return CRLB(model=problem.model0, frames=frames, parameter_names=problem.names,
                free=problem.free.copy(), covariance=covariance, rank=rank, noise=noise)


# -- what the bound implies for positioning --------------------------------------------


def _check_qs(model: CPCModel, qs: ArrayLike) -> NDArray[np.float64]:
    qs = np.asarray(qs, dtype=float)
    if qs.ndim != 2 or qs.shape[1] != model.n_joints or not np.isfinite(qs).all():
        raise ValueError(f"qs: expected finite joint values of shape (n, {model.n_joints}) "
                         f"in the order {list(model.topology.joint_names)}, got shape "
                         f"{qs.shape}")
    return qs


def _check_frames(model: CPCModel, frames: Sequence[str]) -> tuple[str, ...]:
    if isinstance(frames, str):
        raise TypeError("frames: expected a sequence of frame names, not a string")
    frames = tuple(frames)
    unknown = [f for f in frames if f not in model.topology.frames]
    if not frames or unknown:
        raise ValueError(f"frames: expected end frames of the model "
                         f"{list(model.topology.frames)}, got {list(frames)}")
    return frames


def position_jacobians(model: CPCModel, qs: ArrayLike, frames: Sequence[str], *,
                       method: str = "casadi", step: float = 1e-6) -> NDArray[np.float64]:
    """Jacobians of end-frame positions with respect to the CPC chart at ``model``.

    Parameters
    ----------
    model : CPCModel
        The chart's origin (``delta = 0``, :meth:`kinfw.cpc.CPCModel.perturbed`).
    qs : array_like, shape (n, J)
        Configurations, columns in ``model.topology.joint_names`` order (rad, m).
    frames : sequence of str
        End frames of ``model``.
    method : {"casadi", "finite_difference"}
        Exact derivatives of :func:`kinfw.cpc_casadi.cpc_fk_function`, or central
        differences of :meth:`CPCModel.perturbed` with ``step`` (rad, m).

    Returns
    -------
    G : ndarray, shape (n, E, 3, P)
        ``d w_p_frame / d delta`` (m per rad, or m/m) for each configuration and frame.
    """
    qs = _check_qs(model, qs)
    frames = _check_frames(model, frames)
    n, P, E = len(qs), model.n_parameters, len(frames)
    if method == "casadi":
        import casadi as ca

        from kinfw.cpc_casadi import cpc_fk_function

        fk = cpc_fk_function(model, frames)
        q = ca.SX.sym("q", model.n_joints)
        delta = ca.SX.sym("delta", P)
        out = fk(q, delta)
        w_T_frames = out if isinstance(out, (list, tuple)) else [out]
        positions = ca.vertcat(*[T[0:3, 3] for T in w_T_frames])
        jac = ca.Function("G", [q, delta], [ca.jacobian(positions, delta)]).map(n)
        G = np.array(jac(qs.T, np.zeros((P, n))))  # (3E, n P), config blocks side by side
        return G.reshape(3 * E, n, P).reshape(E, 3, n, P).transpose(2, 0, 1, 3)
    if method == "finite_difference":
        idx = [model.topology.frames.index(f) for f in frames]
        G = np.empty((n, E, 3, P))
        for k in range(P):
            e = np.zeros(P)
            e[k] = step
            plus = model.perturbed(e).frame_poses(qs)[:, idx][..., :3, 3]
            minus = model.perturbed(-e).frame_poses(qs)[:, idx][..., :3, 3]
            G[..., k] = (plus - minus) / (2.0 * step)
        return G
    raise ValueError(f"method: expected 'casadi' or 'finite_difference', got {method!r}")


def _check_bound_model(bound: CRLB, model: CPCModel) -> None:
    n = bound.model.n_parameters
    if model.topology != bound.model.topology or model.parameter_names != bound.parameter_names[:n]:
        raise ValueError("model: its CPC chart does not match the bound's (pass bound.model, "
                         "the model the bound was computed around)")


def _predicted_ms(covariance: NDArray[np.float64], G: NDArray[np.float64]
                  ) -> NDArray[np.float64]:
    """Mean over configurations of ``trace(G C G^T)`` per frame, (E,), m^2."""
    return np.einsum("nekp,pq,nekq->ne", G, covariance, G).mean(axis=0)


def predicted_position_rms(bound: CRLB, model: CPCModel, qs: ArrayLike, frames: Sequence[str],
                           *, method: str = "casadi") -> float:
    """RMS positioning error at configurations ``qs`` that the bound implies, metres.

    Parameters
    ----------
    bound : CRLB
    model : CPCModel
        The model the bound is around (``bound.model``): its chart must be the bound's.
    qs : array_like, shape (n, J)
        Held-out configurations, columns in ``model.topology.joint_names`` order.
    frames : sequence of str
        End frames whose positions count.
    method : {"casadi", "finite_difference"}
        How ``G`` is computed (:func:`position_jacobians`).

    Returns
    -------
    float
        ``sqrt(mean over configurations and frames of trace(G C G^T))``, metres, with
        ``C`` the bound's CPC block (:attr:`CRLB.model_covariance`) and ``G`` the
        Jacobian of the frame's position with respect to the CPC chart at ``model``.

    Notes
    -----
    To first order the position error of an estimate is ``G (x_hat - x)``, whose mean
    square is ``trace(G Cov(x_hat) G^T) >= trace(G C G^T)``.
    """
    _check_bound_model(bound, model)
    G = position_jacobians(model, qs, frames, method=method)
    return float(np.sqrt(_predicted_ms(bound.model_covariance, G).mean()))


# -- the experiment --------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ExperimentSetup(FieldsJSON):
    """The two-stage head experiment every trial of a study repeats.

    Attributes
    ----------
    urdf : str
        Source of the nominal URDF.
    plates, cameras : tuple of str
        Frames the stereo rig measures (stage 1) and camera frames that see the target
        (stage 2).
    joint_names : tuple of str
        Joints carrying those frames: column order of every configuration.
    error_mm, error_deg : float
        Geometric errors of the true robot: each origin translation component, mm; each
        origin rotation angle and axis tilt, degrees.
    sigma_mm : float
        Measurement noise per position component, mm.
    sigma_deg : float
        Measurement noise: rotation angle about a random axis, degrees.
    per_joint : int
        Stage-1 values per joint.
    stage2_views : int
        Stage-2 random configurations.
    n_test : int
        Held-out configurations per trial.
    fraction : float
        Centred part of each joint range used for every configuration.
    seed : int
    """

    urdf: str
    plates: tuple[str, ...]
    cameras: tuple[str, ...]
    joint_names: tuple[str, ...]
    error_mm: float
    error_deg: float
    sigma_mm: float
    sigma_deg: float
    per_joint: int
    stage2_views: int
    n_test: int
    fraction: float
    seed: int

    @property
    def frames(self) -> tuple[str, ...]:
        """Every end frame: plates, then cameras."""
        return (*self.plates, *self.cameras)

    @property
    def noise(self) -> NoiseModel:
        """The true noise as ``refine`` whitens it: per position component (m) and per
        orientation component, ``radians(sigma_deg) / sqrt(3)`` (rad)."""
        return NoiseModel(1e-3 * self.sigma_mm, float(np.radians(self.sigma_deg) / np.sqrt(3.0)))

    def describe(self) -> str:
        """One line for headers and titles."""
        return (f"truth = nominal + N(0, {self.error_mm:g} mm) origins, N(0, "
                f"{self.error_deg:g} deg) rotations and axes; stage 1: {self.per_joint} "
                f"values per joint, {' + '.join(self.plates)}; stage 2: {self.stage2_views} "
                f"random views of a fixed target by {' + '.join(self.cameras)}; noise "
                f"{self.sigma_mm:g} mm per axis, {self.sigma_deg:g} deg about a random axis; "
                f"{self.n_test} held-out configurations")



def _check_positive(value: float, name: str) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"{name}: expected a finite value > 0, got {value}")
    return value


def _setup(nominal: Robot, *, sigma_mm: float, sigma_deg: float, per_joint: int,
           stage2_views: int, n_test: int, seed: int, error_mm: float = 5.0,
           error_deg: float = 1.0, fraction: float = 0.8) -> ExperimentSetup:
    plates, cameras = nominal.default_frames, nominal.default_cameras
    if not plates or not cameras:
        raise ValueError(f"{nominal.source}: the study needs a URDF with a "
                         '<kinfw frames="..." cameras="..."/> hint (plates and cameras)')
    if not 0.0 < float(fraction) <= 1.0:
        raise ValueError(f"fraction: expected 0 < fraction <= 1, got {fraction}")
    return ExperimentSetup(
        urdf=nominal.source, plates=plates, cameras=cameras,
        joint_names=nominal.topology((*plates, *cameras)).joint_names,
        error_mm=_check_positive(error_mm, "error_mm"),
        error_deg=_check_positive(error_deg, "error_deg"),
        sigma_mm=_check_positive(sigma_mm, "sigma_mm"),
        sigma_deg=_check_positive(sigma_deg, "sigma_deg"),
        per_joint=check_count(per_joint, "per_joint", 2),
        stage2_views=check_count(stage2_views, "stage2_views", 3),
        n_test=check_count(n_test, "n_test", 1), fraction=float(fraction), seed=int(seed))


@dataclass(frozen=True, slots=True)
class _Experiment:
    """One trial's truth, data and held-out configurations (``setup.joint_names`` order)."""

    truth: Robot
    data: Measurements
    root_T_targets: dict[str, NDArray[np.float64]]
    test_qs: NDArray[np.float64]


def _simulate_experiment(nominal: Robot, setup: ExperimentSetup, trial: int) -> _Experiment:
    """A new true head, its two-stage data and held-out configurations (module docstring)."""
    rng = np.random.default_rng([setup.seed, _EXPERIMENT_TAG, trial])
    truth = load_robot(perturb_robot(nominal, rng, origin_mm=setup.error_mm,
                                     origin_deg=setup.error_deg, axis_deg=setup.error_deg))
    names = setup.joint_names
    lower, upper = nominal.joint_limits(names)
    qs1, _ = one_joint_at_a_time(lower, upper, per_joint=setup.per_joint,
                                 fraction=setup.fraction)
    qs2 = random_configurations(lower, upper, setup.stage2_views, rng, fraction=setup.fraction)
    w_T_target = default_target_pose(truth, qs2, names, setup.cameras)
    noise = {"noise_m": 1e-3 * setup.sigma_mm, "noise_rad": float(np.radians(setup.sigma_deg))}
    data = concatenate_measurements(
        simulate(truth, qs1, names, frames=setup.plates, rng=rng, **noise),
        simulate(truth, qs2, names, cameras=setup.cameras, rng=rng, w_T_target=w_T_target,
                 **noise))
    test_qs = random_configurations(lower, upper, setup.n_test, rng, fraction=setup.fraction)
    targets = {name: w_T_target for name in dict.fromkeys(g.target for g in data.targets)}
    return _Experiment(truth, data, targets, test_qs)


def _pipeline_start(nominal: Robot, data: Measurements
                    ) -> tuple[Robot, dict[str, NDArray[np.float64]]]:
    """Closed form + hand-eye: the start URDF and target poses ``refine`` begins from."""
    cal = calibrate(nominal, data, method="closed-form")
    targets = {} if cal.cameras is None else dict(cal.cameras.root_T_targets)
    return Robot(cal.urdf_xml, nominal.source), targets


def _reorder(qs: NDArray[np.float64], names: Sequence[str], model: CPCModel
             ) -> NDArray[np.float64]:
    """Columns of ``qs`` (in ``names`` order) in the model's joint order."""
    return qs[:, [list(names).index(j) for j in model.topology.joint_names]]


def _position_ms(model: CPCModel, truth: CPCModel, qs: NDArray[np.float64],
                 names: Sequence[str], frames: Sequence[str]) -> NDArray[np.float64]:
    """Mean square position error of each frame over ``qs`` (``names`` order), (E,), m^2."""
    q_model, q_truth = _reorder(qs, names, model), _reorder(qs, names, truth)
    return np.array([np.mean(np.sum((model.frame_poses(q_model, f)[:, :3, 3]
                                     - truth.frame_poses(q_truth, f)[:, :3, 3]) ** 2, axis=1))
                     for f in frames])


def true_chart_coordinates(problem: LeastSquaresProblem, truth_robot: Robot,
                           root_T_targets: dict[str, ArrayLike]) -> NDArray[np.float64]:
    """The truth in the chart of a least-squares problem (from its start), shape (P,).

    CPC part: ``problem.model0.chart_coordinates`` of the truth's canonical model with
    the start's motion senses; targets: the inverse of the Cayley chart around the start
    pose. ``problem.model_at(x)`` and ``problem.unknowns_at(x)`` then reproduce the truth.

    Raises
    ------
    ValueError
        For unknowns other than targets, or a missing target.
    """
    m0 = problem.model0
    unknown = problem.unknown_blocks
    if problem.model_frame is not None or any(b.key.kind != "target" for b in unknown):
        raise ValueError("true_chart_coordinates: only the CPC chart and target poses are "
                         "supported")
    truth = cpc_from_geometry(geometry_from_robot(truth_robot, m0.topology.frames),
                              sign=m0.sign)
    x = np.zeros(problem.n_parameters)
    x[: m0.n_parameters] = m0.chart_coordinates(truth)
    for block, sl in zip(unknown, problem.slices[problem.n_robot_blocks:], strict=True):
        if block.key.name not in root_T_targets:
            raise ValueError(f"root_T_targets: missing the true pose of target "
                             f"{block.key.name!r}")
        x[sl] = block.coordinates(np.asarray(root_T_targets[block.key.name], dtype=float))
    return x


def _ratio_band(covariance: NDArray[np.float64], G: NDArray[np.float64],
                rng: np.random.Generator, draws: int = 4000) -> NDArray[np.float64]:
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


def _rms_over(values_mm: NDArray[np.float64], axis: int | tuple[int, ...]) -> Any:
    """RMS of RMS values (equal counts): sqrt of the mean of their squares."""
    return np.sqrt(np.mean(np.square(values_mm), axis=axis))


# -- the CRLB study --------------------------------------------------------------------


#: The per-trial arrays of :class:`CRLBStudy`, in the order its JSON lists them, and their
#: dtypes.
_CRLB_ARRAYS = dict.fromkeys(
    ("start_rms_mm", "refined_rms_mm", "estimated_noise_rms_mm", "crlb_rms_mm", "z",
     "z_estimated_noise", "nees", "ratio_band", "noise_estimates", "sigma_hat2", "seconds"),
    float)


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
        (:func:`predicted_position_rms` per frame), mm.
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
        values = {"start": self.start_rms_mm, "refined": self.refined_rms_mm,
                  "estimated_noise": self.estimated_noise_rms_mm, "crlb": self.crlb_rms_mm}
        if which not in values:
            raise ValueError(f"which: expected one of {sorted(values)}, got {which!r}")
        return _rms_over(values[which], axis=1)

    @property
    def ratio(self) -> NDArray[np.float64]:
        """Refined (true noise) over CRLB RMS error of each trial, (T,)."""
        return self.trial_rms_mm("refined") / self.trial_rms_mm("crlb")

    def pooled_ratio(self, which: str = "refined") -> float:
        """``sqrt(sum of mean square errors / sum of their bounds)`` over trials (1 for an
        efficient estimator)."""
        return float(np.sqrt(np.sum(self.trial_rms_mm(which) ** 2)
                             / np.sum(self.trial_rms_mm("crlb") ** 2)))

    @property
    def pooled_ratio_per_frame(self) -> NDArray[np.float64]:
        """:meth:`pooled_ratio` of each frame, (E,)."""
        return np.sqrt(np.sum(self.refined_rms_mm ** 2, axis=0)
                       / np.sum(self.crlb_rms_mm ** 2, axis=0))

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
                "coverage": {f"{k:g}": {kind: self.coverage(k, kind=kind)
                                        for kind in ("all", "model", "target")}
                             for k in NORMAL_COVERAGE},
                "coverage_estimated_noise": {f"{k:g}": self.coverage(k, estimated_noise=True)
                                             for k in NORMAL_COVERAGE},
                "true_noise": self.true_noise.tolist(),
                "noise_ratio_mean": self.noise_ratio.mean(axis=0).tolist(),
            },
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> CRLBStudy:
        """The study written by :meth:`to_dict` (the summary is recomputed)."""
        return cls(setup=ExperimentSetup.from_dict(doc["setup"]),
                   parameter_names=tuple((str(o), str(f)) for o, f in doc["parameter_names"]),
                   **arrays_from(doc, _CRLB_ARRAYS))


def _crlb_trial(nominal: Robot, setup: ExperimentSetup, t: int) -> tuple[tuple, tuple]:
    """Trial ``t`` of :func:`crlb_study` (a task: module level, picklable arguments):
    its per-trial numbers and the names of the free parameters."""
    t0 = time.perf_counter()
    exp = _simulate_experiment(nominal, setup, t)
    start, start_targets = _pipeline_start(nominal, exp.data)
    fit = refine(nominal, exp.data, start=start, targets=start_targets, noise=setup.noise)
    fit_est = refine(nominal, exp.data, start=start, targets=start_targets)
    truth = cpc_from_robot(exp.truth, setup.frames)
    qs = exp.test_qs
    start_ms = _position_ms(cpc_from_robot(start, setup.frames), truth, qs,
                            setup.joint_names, setup.frames)
    refined_ms = _position_ms(fit.model, truth, qs, setup.joint_names, setup.frames)
    estimated_ms = _position_ms(fit_est.model, truth, qs, setup.joint_names, setup.frames)
    bound = cramer_rao(exp.truth, exp.data, setup.frames, noise=setup.noise,
                       targets=exp.root_T_targets)
    G = position_jacobians(bound.model, _reorder(qs, setup.joint_names, bound.model),
                           setup.frames)
    crlb_ms = _predicted_ms(bound.model_covariance, G)
    band = _ratio_band(bound.model_covariance, G,
                       np.random.default_rng([setup.seed, _BAND_TAG, t]))
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
    log.info("crlb trial %d: refined %.3g mm, CRLB %.3g mm, %.2f s", t,
             1e3 * np.sqrt(refined_ms.mean()), 1e3 * np.sqrt(crlb_ms.mean()), seconds)
    return ((start_ms, refined_ms, estimated_ms, crlb_ms, band, z, nees, z_est,
             (fit_est.noise.position_m, fit_est.noise.rotation_rad), fit.sigma_hat2, seconds),
            trial_names)


def crlb_study(nominal: Robot, *, trials: int = 30, sigma_mm: float = 0.5,
               sigma_deg: float = 0.5, per_joint: int = 9, stage2_views: int = 30,
               n_test: int = 200, seed: int = 0, progress: Progress | None = None,
               executor: Executor | None = None) -> CRLBStudy:
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
    progress : callable, optional
        ``progress(done, total)`` after each trial.
    executor : concurrent.futures.Executor, optional
        Run the trials as its tasks (:func:`verification.studies.run_trials`); default
        serially here. The numbers do not depend on it (each trial seeds its own).

    Returns
    -------
    CRLBStudy
    """
    setup = _setup(nominal, sigma_mm=sigma_mm, sigma_deg=sigma_deg, per_joint=per_joint,
                   stage2_views=stage2_views, n_test=n_test, seed=seed)
    trials = check_count(trials, "trials", 1)
    E = len(setup.frames)
    start_ms, refined_ms, estimated_ms, crlb_ms = (np.empty((trials, E)) for _ in range(4))
    zs, zs_est, noise_est = [], [], np.empty((trials, 2))
    nees, band = np.empty(trials), np.empty((trials, 2))
    sigma_hat2, seconds = np.empty(trials), np.empty(trials)
    names: tuple[tuple[str, str], ...] | None = None
    trial_results = run_trials(_crlb_trial, [(nominal, setup, t) for t in range(trials)],
                               executor=executor, progress=progress)
    for t, (res, trial_names) in enumerate(trial_results):
        (start_ms[t], refined_ms[t], estimated_ms[t], crlb_ms[t], band[t], z, nees[t], z_est,
         noise_est[t], sigma_hat2[t], seconds[t]) = res
        zs.append(z)
        zs_est.append(z_est)
        if names is None:
            names = trial_names
        elif names != trial_names:
            raise RuntimeError("crlb_study: the free parameters differ between trials")
    result = CRLBStudy(
        setup=setup, parameter_names=names or (),
        start_rms_mm=1e3 * np.sqrt(start_ms), refined_rms_mm=1e3 * np.sqrt(refined_ms),
        estimated_noise_rms_mm=1e3 * np.sqrt(estimated_ms), crlb_rms_mm=1e3 * np.sqrt(crlb_ms),
        z=np.array(zs), z_estimated_noise=np.array(zs_est), nees=nees, ratio_band=band,
        noise_estimates=noise_est,
        sigma_hat2=sigma_hat2, seconds=seconds)
    freeze(*(getattr(result, name) for name in _CRLB_ARRAYS))
    return result


# -- the robustness study --------------------------------------------------------------

#: Default variants of the robustness study: (loss, "given" | "estimated" noise).
ROBUST_VARIANTS = (("linear", "given"), ("huber", "given"), ("cauchy", "given"),
                   ("huber", "estimated"), ("cauchy", "estimated"))


#: The per-trial arrays of :class:`RobustStudy`, in the order its JSON lists them, and
#: their dtypes.
_ROBUST_ARRAYS = {
    "clean_rms_mm": float, "start_rms_mm": float, "rms_mm": float, "n_observations": np.int64,
    "n_planted": np.int64, "flagged_planted": np.int64, "flagged_clean": np.int64,
    "noise_used": float, "seconds": float,
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
        return tuple(loss if noise == "given" else f"{loss}, σ estimated"
                     for loss, noise in self.variants)

    def variant(self, loss: str, noise: str = "given") -> int:
        """Index of a variant."""
        try:
            return self.variants.index((loss, noise))
        except ValueError:
            raise KeyError(f"no variant {(loss, noise)}; the study has {self.variants}"
                           ) from None

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
            "outlier_fraction": self.outlier_fraction, "outlier_mm": self.outlier_mm,
            "outlier_deg": self.outlier_deg,
            "variants": [list(v) for v in self.variants],
            **json_lists(self, _ROBUST_ARRAYS),
            "summary": {label: {"median_ratio_to_clean": float(np.median(ratio)),
                                "max_ratio_to_clean": float(np.max(ratio)),
                                "recall": float(rec), "false_alarm_rate": float(fa)}
                        for label, ratio, rec, fa in zip(
                            self.labels, self.ratio_to_clean.T, self.recall,
                            self.false_alarm_rate, strict=True)},
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> RobustStudy:
        """The study written by :meth:`to_dict` (the summary is recomputed)."""
        return cls(setup=ExperimentSetup.from_dict(doc["setup"]),
                   outlier_fraction=float(doc["outlier_fraction"]),
                   outlier_mm=float(doc["outlier_mm"]), outlier_deg=float(doc["outlier_deg"]),
                   variants=tuple((str(a), str(b)) for a, b in doc["variants"]),
                   **arrays_from(doc, _ROBUST_ARRAYS))


def _unit_vectors(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def plant_outliers(data: Measurements, rng: np.random.Generator, *, fraction: float,
                   distance_m: float, angle_rad: float
                   ) -> tuple[Measurements, frozenset[tuple[str, str, int]]]:
    """Corrupt a random ``fraction`` of the pose and target observations.

    Each chosen observation (one sample of one pose or target group) has its position
    moved by ``distance_m`` in a uniformly random direction (in the measurement frame)
    and its orientation turned by ``angle_rad`` about a uniformly random axis (on the
    measured frame's side).

    Returns
    -------
    corrupted : Measurements
    planted : frozenset of (kind, frame, sample)
        The corrupted observations, keyed as ``refine``'s ``downweighted``.
    """
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"fraction: expected 0 <= fraction <= 1, got {fraction}")
    groups = [("pose", g.frame, g.sample, g.meas_T_frame) for g in data.poses] + \
             [("target", g.camera, g.sample, g.camera_T_target) for g in data.targets]
    index = [(k, r) for k, (_, _, sample, _) in enumerate(groups) for r in range(len(sample))]
    n = round(fraction * len(index)) if fraction > 0.0 else 0
    n = max(n, 1) if fraction > 0.0 else 0
    chosen = rng.choice(len(index), size=n, replace=False)
    arrays = [T.copy() for _, _, _, T in groups]
    dps = distance_m * _unit_vectors(rng, n)
    dRs = matrix_from_rotation_vector(angle_rad * _unit_vectors(rng, n))
    planted = set()
    for c, dp, dR in zip(chosen, dps, dRs, strict=True):
        k, r = index[c]
        arrays[k][r, :3, 3] += dp
        arrays[k][r, :3, :3] = arrays[k][r, :3, :3] @ dR
        kind, frame, sample, _ = groups[k]
        planted.add((kind, frame, int(sample[r])))
    n_poses = len(data.poses)
    poses = tuple(replace(g, meas_T_frame=arrays[k]) for k, g in enumerate(data.poses))
    targets = tuple(replace(g, camera_T_target=arrays[n_poses + k])
                    for k, g in enumerate(data.targets))
    corrupted = replace(data, poses=poses, targets=targets,
                        source=f"{data.source} + {n} planted outliers")
    return corrupted, frozenset(planted)


def _robust_trial(nominal: Robot, setup: ExperimentSetup, t: int,
                  variants: tuple[tuple[str, str], ...], outlier_fraction: float,
                  outlier_mm: float, outlier_deg: float) -> tuple:
    """Trial ``t`` of :func:`robustness_study` (a task: module level, picklable
    arguments)."""
    t0 = time.perf_counter()
    exp = _simulate_experiment(nominal, setup, t)
    truth = cpc_from_robot(exp.truth, setup.frames)

    def held_out_ms(model: CPCModel) -> float:
        return float(_position_ms(model, truth, exp.test_qs, setup.joint_names,
                                  setup.frames).mean())

    V = len(variants)
    rms_ms, noise_used = np.empty(V), np.empty((V, 2))
    flagged_planted, flagged_clean = np.zeros(V, np.int64), np.zeros(V, np.int64)
    start, start_targets = _pipeline_start(nominal, exp.data)
    clean_ms = held_out_ms(refine(nominal, exp.data, start=start, targets=start_targets,
                                  noise=setup.noise).model)
    rng = np.random.default_rng([setup.seed, _OUTLIER_TAG, t])
    data, planted = plant_outliers(exp.data, rng, fraction=outlier_fraction,
                                   distance_m=1e-3 * outlier_mm,
                                   angle_rad=float(np.radians(outlier_deg)))
    n_obs = sum(len(g.sample) for g in (*data.poses, *data.targets))
    start, start_targets = _pipeline_start(nominal, data)
    start_ms = held_out_ms(cpc_from_robot(start, setup.frames))
    for v, (loss, noise) in enumerate(variants):
        fit = refine(nominal, data, start=start, targets=start_targets, loss=loss,
                     noise=setup.noise if noise == "given" else None)
        rms_ms[v] = held_out_ms(fit.model)
        flagged = {(kind, frame, sample) for kind, frame, sample, _ in fit.downweighted}
        flagged_planted[v] = len(flagged & planted)
        flagged_clean[v] = len(flagged - planted)
        noise_used[v] = fit.noise.position_m, fit.noise.rotation_rad
    seconds = time.perf_counter() - t0
    log.info("robust trial %d: clean %.3g mm, %s, %.2f s", t, 1e3 * np.sqrt(clean_ms),
             ", ".join(f"{loss}/{noise} {1e3 * np.sqrt(m):.3g} mm"
                       for (loss, noise), m in zip(variants, rms_ms, strict=True)), seconds)
    return (clean_ms, start_ms, rms_ms, n_obs, len(planted), flagged_planted, flagged_clean,
            noise_used, seconds)


def robustness_study(nominal: Robot, *, trials: int = 20, outlier_fraction: float = 0.05,
                     outlier_mm: float = 50.0, outlier_deg: float = 5.0,
                     variants: Sequence[tuple[str, str]] = ROBUST_VARIANTS,
                     sigma_mm: float = 0.5, sigma_deg: float = 0.5, per_joint: int = 9,
                     stage2_views: int = 30, n_test: int = 200, seed: int = 0,
                     progress: Progress | None = None,
                     executor: Executor | None = None) -> RobustStudy:
    """Refinement of data with planted gross errors, linear vs robust losses.

    Each trial takes the data of the same trial of :func:`crlb_study`, refines the clean
    data (pipeline start, linear loss, true noise: the reference), then corrupts
    ``outlier_fraction`` of the observations (:func:`plant_outliers`: ``outlier_mm``
    in a random direction and ``outlier_deg`` about a random axis), restarts the pipeline
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
    sigma_mm, sigma_deg, per_joint, stage2_views, n_test, seed, progress, executor
        As for :func:`crlb_study`.

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
    setup = _setup(nominal, sigma_mm=sigma_mm, sigma_deg=sigma_deg, per_joint=per_joint,
                   stage2_views=stage2_views, n_test=n_test, seed=seed)
    trials = check_count(trials, "trials", 1)
    variants = tuple((str(loss), str(noise)) for loss, noise in variants)
    for loss, noise in variants:
        if loss not in ("linear", "huber", "cauchy") or noise not in ("given", "estimated"):
            raise ValueError(f"variants: expected (loss, noise) with loss linear, huber or "
                             f"cauchy and noise given or estimated, got {(loss, noise)}")
    if not variants:
        raise ValueError("variants: give at least one (loss, noise)")
    if not 0.0 <= float(outlier_fraction) <= 1.0:
        raise ValueError(f"outlier_fraction: expected 0 <= fraction <= 1, got "
                         f"{outlier_fraction}")
    outlier_mm = _check_positive(outlier_mm, "outlier_mm")
    outlier_deg = float(outlier_deg)
    if not (np.isfinite(outlier_deg) and outlier_deg >= 0.0):
        raise ValueError(f"outlier_deg: expected a finite angle >= 0, got {outlier_deg}")
    V = len(variants)
    clean_ms, start_ms, seconds = np.empty(trials), np.empty(trials), np.empty(trials)
    rms_ms = np.empty((trials, V))
    n_obs, n_planted = np.empty(trials, np.int64), np.empty(trials, np.int64)
    flagged_planted, flagged_clean = np.zeros((trials, V), np.int64), np.zeros((trials, V),
                                                                                np.int64)
    noise_used = np.empty((trials, V, 2))
    trial_results = run_trials(
        _robust_trial, [(nominal, setup, t, variants, float(outlier_fraction), outlier_mm,
                         outlier_deg) for t in range(trials)],
        executor=executor, progress=progress)
    for t, res in enumerate(trial_results):
        (clean_ms[t], start_ms[t], rms_ms[t], n_obs[t], n_planted[t], flagged_planted[t],
         flagged_clean[t], noise_used[t], seconds[t]) = res
    result = RobustStudy(
        setup=setup, outlier_fraction=float(outlier_fraction), outlier_mm=outlier_mm,
        outlier_deg=outlier_deg, variants=variants, clean_rms_mm=1e3 * np.sqrt(clean_ms),
        start_rms_mm=1e3 * np.sqrt(start_ms), rms_mm=1e3 * np.sqrt(rms_ms),
        n_observations=n_obs, n_planted=n_planted, flagged_planted=flagged_planted,
        flagged_clean=flagged_clean, noise_used=noise_used, seconds=seconds)
    freeze(*(getattr(result, name) for name in _ROBUST_ARRAYS))
    return result


# -- text tables -----------------------------------------------------------------------


def format_crlb(study: CRLBStudy) -> str:
    """Markdown tables of the CRLB study: errors per frame, coverage, noise (mm, deg)."""
    s = study
    frames = s.setup.frames
    columns = (("start", s.start_rms_mm), ("refined", s.refined_rms_mm),
               ("estimated_noise", s.estimated_noise_rms_mm), ("crlb", s.crlb_rms_mm))
    lines = [
        f"Cramér-Rao bound study: {s.trials} trials; held-out RMS position error against "
        "the truth (mm), pooled over trials (sqrt of the mean square).",
        s.setup.describe() + ".",
        "",
        "| frame | closed form + hand-eye | refined (σ given) | refined (σ estimated) "
        "| CRLB | refined / CRLB |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for e, frame in enumerate(frames):
        cells = [f"{_rms_over(v[:, e], 0):.3f}" for _, v in columns]
        lines.append(f"| {frame} | " + " | ".join(cells)
                     + f" | {s.pooled_ratio_per_frame[e]:.3f} |")
    cells = [f"{_rms_over(s.trial_rms_mm(name), 0):.3f}" for name, _ in columns]
    lines.append("| **all frames** | " + " | ".join(cells) + f" | {s.pooled_ratio():.3f} |")
    ratio = s.ratio
    lines += [
        "",
        f"refined / CRLB per trial: median {np.median(ratio):.3f}, min {ratio.min():.3f}, "
        f"max {ratio.max():.3f}; {100 * s.within_band:.0f} % of the trials inside the 5-95 % "
        f"band an efficient estimator would show (90 % expected; typical band "
        f"{np.median(s.ratio_band[:, 0]):.2f}-{np.median(s.ratio_band[:, 1]):.2f}). Pooled "
        f"{s.pooled_ratio():.3f} (target <= 1.05; σ estimated: "
        f"{s.pooled_ratio('estimated_noise'):.3f}).",
        "",
        "Coverage: fraction of parameters with |estimate - truth| <= k σ (σ as refine "
        f"reports it), {s.z.shape[1]} free parameters x {s.trials} trials:",
        "",
        "| k | normal | CPC model (σ given) | target pose (σ given) | all (σ given) "
        "| all (σ estimated) |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for k, expected in NORMAL_COVERAGE.items():
        cells = [s.coverage(k, kind="model"), s.coverage(k, kind="target"), s.coverage(k),
                 s.coverage(k, estimated_noise=True)]
        lines.append(f"| {k:g} | {100 * expected:.1f} % | "
                     + " | ".join(f"{100 * c:.1f} %" for c in cells) + " |")
    z = s.z[np.isfinite(s.z)]
    true = s.true_noise
    est, ratio_n = s.noise_estimates, s.noise_ratio
    lines += [
        "",
        f"RMS of (estimate - truth) / σ: {np.sqrt(np.mean(z ** 2)):.3f} (1 expected). "
        f"NEES (x_hat - x)^T C^-1 (x_hat - x): mean {s.nees.mean():.1f} over {s.trials} "
        f"trials (chi-square: {s.n_parameters} ± {np.sqrt(2.0 * s.n_parameters / s.trials):.1f})"
        f"; reduced chi-square of the fit, σ given: mean {s.sigma_hat2.mean():.3f}.",
        "",
        "| noise (per component) | true | estimated, mean ± std | estimated / true: "
        "mean, min, max |",
        "|---|---:|---:|---:|",
        f"| position (mm) | {1e3 * true[0]:.4f} | {1e3 * est[:, 0].mean():.4f} ± "
        f"{1e3 * sample_std(est[:, 0]):.4f} | {ratio_n[:, 0].mean():.3f}, "
        f"{ratio_n[:, 0].min():.3f}, {ratio_n[:, 0].max():.3f} |",
        f"| orientation (deg) | {np.degrees(true[1]):.4f} | {np.degrees(est[:, 1].mean()):.4f}"
        f" ± {np.degrees(sample_std(est[:, 1])):.4f} | {ratio_n[:, 1].mean():.3f}, "
        f"{ratio_n[:, 1].min():.3f}, {ratio_n[:, 1].max():.3f} |",
        "",
        f"{np.sum(s.seconds):.1f} s ({np.mean(s.seconds):.2f} s per trial).",
    ]
    return "\n".join(lines)


def format_robustness(study: RobustStudy) -> str:
    """Markdown table of the robustness study: held-out errors and detection per variant."""
    s = study
    ratio = s.ratio_to_clean
    lines = [
        f"Robustness study: {s.trials} trials; {100 * s.outlier_fraction:g} % of the "
        f"observations corrupted by {s.outlier_mm:g} mm and {s.outlier_deg:g} deg "
        f"({int(s.n_planted.sum())} planted among {int(s.n_observations.sum())}). Held-out RMS "
        "position error against the truth (mm), all frames.",
        s.setup.describe() + ".",
        "",
        "| refinement | RMS error: median | max | / clean: median | max | planted "
        "down-weighted | clean down-weighted |",
        "|---|---:|---:|---:|---:|---:|---:|",
        f"| clean data, linear (reference) | {np.median(s.clean_rms_mm):.3f} | "
        f"{s.clean_rms_mm.max():.3f} | 1 | 1 | – | – |",
        f"| start (closed form + hand-eye), corrupted | {np.median(s.start_rms_mm):.3f} | "
        f"{s.start_rms_mm.max():.3f} | {np.median(s.start_rms_mm / s.clean_rms_mm):.2f} | "
        f"{np.max(s.start_rms_mm / s.clean_rms_mm):.2f} | – | – |",
    ]
    for v, label in enumerate(s.labels):
        lines.append(
            f"| {label} | {np.median(s.rms_mm[:, v]):.3f} | {s.rms_mm[:, v].max():.3f} | "
            f"{np.median(ratio[:, v]):.2f} | {ratio[:, v].max():.2f} | "
            f"{100 * s.recall[v]:.0f} % | {100 * s.false_alarm_rate[v]:.1f} % |")
    estimated = [v for v, (_, noise) in enumerate(s.variants) if noise == "estimated"]
    if estimated:
        sp = 1e3 * s.noise_used[:, estimated, 0]
        lines += ["", f"Noise estimated with outliers: position {np.median(sp):.2f} mm per "
                  f"component (median; true {s.setup.sigma_mm:g} mm)."]
    lines += ["", "Down-weighted: refine's `downweighted` (observations beyond the robust "
              "loss's threshold: the 99 % quantile of a clean residual norm).",
              "", f"{np.sum(s.seconds):.1f} s ({np.mean(s.seconds):.2f} s per trial)."]
    return "\n".join(lines)


# -- plots -----------------------------------------------------------------------------


def plot_crlb(study: CRLBStudy, path: str | Path) -> Path:
    """Write the CRLB study as a PNG: error vs bound, ratio per trial, coverage.

    Left: each trial's held-out RMS position error of each end frame against the RMS
    error its Cramér-Rao bound implies, for the refined model (true noise given) and the
    closed-form + hand-eye start, with ``y = x``; large diamonds pool the trials per
    frame. Middle: the ratio refined / CRLB of each trial (all frames) inside the band
    an efficient estimator would show, and the pooled ratio. Right: the fraction of
    parameters within 1, 2 and 3 reported standard deviations of the truth, beside a
    normal distribution's.

    Returns
    -------
    Path
        ``path``.
    """
    s = study
    fig = new_figure((16.0, 5.6))
    ax, mx, bx = fig.subplots(1, 3, width_ratios=(1.1, 1.0, 0.9))
    colors = ("tab:blue", "tab:green", "tab:red", "tab:purple", "tab:orange", "tab:brown")
    for e, frame in enumerate(s.setup.frames):
        color = colors[e % len(colors)]
        ax.scatter(s.crlb_rms_mm[:, e], s.start_rms_mm[:, e], marker="^", s=14,
                   color=color, alpha=0.3)
        ax.scatter(s.crlb_rms_mm[:, e], s.refined_rms_mm[:, e], marker="o", s=16,
                   color=color, alpha=0.75, label=frame)
        ax.scatter(_rms_over(s.crlb_rms_mm[:, e], 0), _rms_over(s.refined_rms_mm[:, e], 0),
                   marker="D", s=90, color=color, edgecolor="k", linewidth=1.2, zorder=4)
    values = np.concatenate([s.crlb_rms_mm.ravel(), s.refined_rms_mm.ravel(),
                             s.start_rms_mm.ravel()])
    line = np.array([0.8 * values.min(), 1.25 * values.max()])
    ax.plot(line, line, color="0.2", linewidth=1.2, label="y = x (efficient)")
    ax.scatter([], [], marker="o", color="0.4", label="refined, σ given (per trial)")
    ax.scatter([], [], marker="^", color="0.4", alpha=0.4,
               label="closed form + hand-eye start")
    ax.scatter([], [], marker="D", color="0.4", edgecolor="k", label="pooled over trials")
    log_axes(ax, "both")
    ax.set_xlim(*line)
    ax.set_ylim(*line)
    ax.set_aspect("equal")
    ax.set_xlabel("RMS error implied by the Cramér-Rao bound (mm)")
    ax.set_ylabel("held-out RMS position error vs truth (mm)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper left")
    ax.set_title("per trial and end frame", fontsize=10)

    t = np.arange(1, s.trials + 1)
    mx.fill_between(t, s.ratio_band[:, 0], s.ratio_band[:, 1], step="mid", color="0.85",
                    label="5-95 % for an efficient estimator")
    mx.plot(t, s.trial_rms_mm("estimated_noise") / s.trial_rms_mm("crlb"), "x",
            color="tab:orange", label="refined, σ estimated")
    mx.plot(t, s.ratio, "o", color="tab:blue", label="refined, σ given")
    mx.axhline(1.0, color="0.2", linewidth=1.0)
    mx.axhline(s.pooled_ratio(), color="tab:blue", linestyle="--", linewidth=1.2,
               label=f"pooled: {s.pooled_ratio():.3f}")
    mx.set_xlabel("trial (new true head each)")
    mx.set_ylabel("held-out RMS error / CRLB RMS error (all frames)")
    mx.grid(True, alpha=0.3)
    mx.legend(fontsize=8, loc="upper right")
    mx.set_title(f"ratio per trial; NEES mean {s.nees.mean():.1f} (χ²: {s.n_parameters})",
                 fontsize=10)

    ks = list(NORMAL_COVERAGE)
    bars = (("CPC model, σ given", [s.coverage(k, kind="model") for k in ks], "tab:blue"),
            ("target pose, σ given", [s.coverage(k, kind="target") for k in ks], "tab:green"),
            ("all, σ estimated", [s.coverage(k, estimated_noise=True) for k in ks],
             "tab:orange"))
    x = np.arange(len(ks))
    width = 0.8 / len(bars)
    for i, (label, cover, color) in enumerate(bars):
        bx.bar(x + (i - 1) * width, 100 * np.array(cover), width, color=color, label=label)
    for xi, k in zip(x, ks, strict=True):
        bx.hlines(100 * NORMAL_COVERAGE[k], xi - 0.45, xi + 0.45, color="0.1", linewidth=1.5,
                  label="normal distribution" if xi == 0 else None)
    bx.set_xticks(x, [f"±{k:g} σ" for k in ks])
    bx.set_ylim(0, 105)
    bx.set_ylabel("parameters with |estimate - truth| <= k σ (%)")
    bx.grid(True, axis="y", alpha=0.3)
    bx.legend(fontsize=8, loc="lower right")
    bx.set_title(f"coverage, σ as reported: {s.n_parameters} parameters x {s.trials} trials",
                 fontsize=10)
    fig.suptitle(
        f"Refined calibration vs its Cramér-Rao bound: {s.trials} trials, new true head each; "
        f"noise {s.setup.sigma_mm:g} mm, {s.setup.sigma_deg:g}°; {s.setup.per_joint} values "
        f"per joint + {s.setup.stage2_views} target views; {s.setup.n_test} held-out "
        "configurations", fontsize=10)
    return save_figure(fig, path)


def plot_robustness(study: RobustStudy, path: str | Path) -> Path:
    """Write the robustness study as a PNG: held-out errors per variant, and detection.

    Left: each trial's held-out RMS position error (log scale) for the corrupted start
    and every variant, beside the clean-data result. Right: the fraction of planted
    outliers and of clean observations that each variant down-weighted.

    Returns
    -------
    Path
        ``path``.
    """
    s = study
    fig = new_figure((12.0, 5.4))
    ax, bx = fig.subplots(1, 2, width_ratios=(1.4, 1.0))
    labels = ["clean data,\nlinear", "start,\ncorrupted", *[lb.replace(", ", ",\n")
                                                          for lb in s.labels]]
    columns = [s.clean_rms_mm, s.start_rms_mm, *s.rms_mm.T]
    rng = np.random.default_rng(0)  # horizontal jitter only
    for i, values in enumerate(columns):
        ax.scatter(i + rng.uniform(-0.15, 0.15, len(values)), values, s=16, alpha=0.7,
                   color="tab:green" if i == 0 else ("0.55" if i == 1 else "tab:blue"))
        ax.hlines(np.median(values), i - 0.3, i + 0.3, color="0.1", linewidth=2)
    ax.axhline(np.median(s.clean_rms_mm), color="tab:green", linestyle=":", linewidth=1)
    log_axes(ax, "y")
    ax.set_xticks(range(len(columns)), labels, fontsize=8)
    ax.set_ylabel("held-out RMS position error vs truth (mm); bar = median")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.set_title("per trial, all end frames", fontsize=10)
    x = np.arange(len(s.variants))
    planted = bx.bar(x - 0.2, 100 * s.recall, 0.4, color="tab:red", label="planted outliers")
    clean = bx.bar(x + 0.2, 100 * s.false_alarm_rate, 0.4, color="tab:gray",
                   label="clean observations")
    for bars in (planted, clean):
        bx.bar_label(bars, fmt="%.0f", fontsize=7.5)
    bx.set_xticks(x, [lb.replace(", ", ",\n") for lb in s.labels], fontsize=8)
    bx.set_ylim(0, 122)
    bx.set_yticks(np.arange(0, 101, 20))
    bx.set_ylabel("down-weighted by refine (weight < 0.5), %")
    bx.grid(True, axis="y", alpha=0.3)
    bx.legend(fontsize=8, loc="upper center", ncols=2)
    bx.set_title("detection", fontsize=10)
    fig.suptitle(
        f"Robust refinement: {100 * s.outlier_fraction:g} % of observations corrupted by "
        f"{s.outlier_mm:g} mm and {s.outlier_deg:g}° ({s.trials} trials); noise "
        f"{s.setup.sigma_mm:g} mm, {s.setup.sigma_deg:g}°", fontsize=10)
    return save_figure(fig, path)


# -- runs on the built-in head ---------------------------------------------------------


def run_crlb(out_dir: str | Path, *, urdf: str | Path | None = None, **kwargs: Any
             ) -> CRLBStudy:
    """Run :func:`crlb_study` (on the built-in IIS-head unless ``urdf``) and write
    ``crlb.png`` and ``crlb.json`` into ``out_dir``; ``kwargs`` go to the study."""
    return run_on_head(crlb_study, plot_crlb, out_dir, "crlb", urdf, kwargs)


def run_robustness(out_dir: str | Path, *, urdf: str | Path | None = None, **kwargs: Any
                   ) -> RobustStudy:
    """Run :func:`robustness_study` (on the built-in IIS-head unless ``urdf``) and write
    ``robust.png`` and ``robust.json`` into ``out_dir``; ``kwargs`` go to the study."""
    return run_on_head(robustness_study, plot_robustness, out_dir, "robust", urdf, kwargs)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m verification.crlb {crlb,robust} --out DIR [--trials N] [--seed S]``: run
    one study on the built-in head, write its PNG and JSON, print the table."""
    return choice_main(
        argv, prog="python -m verification.crlb",
        description="crlb: refined calibration vs its Cramér-Rao bound; robust: refinement "
                    "with planted outliers (linear, Huber, Cauchy losses).",
        trials_help="random trials (default: 30 for crlb, 20 for robust)",
        studies={"crlb": (run_crlb, format_crlb),
                 "robust": (run_robustness, format_robustness)})

if __name__ == "__main__":
    sys.exit(main())
