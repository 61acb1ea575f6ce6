"""The Cramér-Rao bound of a calibration experiment, and what it implies for positioning.

The Cramér-Rao lower bound (CRLB) of an experiment, :func:`cramer_rao`, is the inverse
of the Fisher information ``J^T J`` of the whitened residuals at the *true* model and
target pose; :func:`predicted_position_rms` maps it to the RMS positioning error it
implies at held-out configurations, ``sqrt(mean trace(G C G^T))`` with ``G`` the
Jacobian of an end frame's position with respect to the CPC chart
(:func:`position_jacobians`). An efficient estimator reaches it;
:func:`kinfw.verification.studies.crlb_study` checks that the refined calibration does.

References
----------
C. R. Rao (1945), H. Cramér (1946): the information inequality.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.identification import information_matrix
from kinfw.identification.problem import LeastSquaresProblem, NoiseModel, build_problem
from kinfw.measurements import Measurements
from kinfw.model import CPC_KEY, CPCModel, Robot, cpc_from_geometry, geometry_from_robot

log = logging.getLogger(__name__)


#: Probability that a normal variable lies within 1, 2 and 3 standard deviations.
NORMAL_COVERAGE = {1.0: 0.6826894921370859, 2.0: 0.9544997361036416, 3.0: 0.9973002039367398}


_RANK_TOL = 1e-12  # eigenvalues of the scaled information below this (relative) are null


# -- the bound -----------------------------------------------------------------------


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
        Every unknown of the problem, as :func:`kinfw.identification.problem.build_problem`
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
        """The block of the CPC chart, shape (``model.n_parameters``,) * 2 in the order of
        ``model.parameter_names`` (the marginal bound: the target poses are nuisance
        parameters)."""
        idx = [self.parameter_names.index(n) for n in self.model.parameter_names]
        return self.covariance[np.ix_(idx, idx)]


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


def cramer_rao(
    truth_robot: Robot,
    measurements: Measurements,
    frames: Sequence[str],
    *,
    noise: NoiseModel,
    targets: dict[str, ArrayLike],
) -> CRLB:
    """The Cramér-Rao bound of a simulated experiment.

    The least-squares problem of :func:`kinfw.identification.refine` is built around
    the *true* model (``start = truth_robot``) and the true target poses, and the bound
    is the inverse of its Fisher information ``J^T J``
    (:func:`kinfw.identification.information_matrix`; ``J`` the Jacobian of the
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
        raise ValueError(f"targets: give the true pose of every observed target; missing {missing}")
    others = [f"{k.kind} {k.name!r}" for k in unknown if k.kind != "target"]
    if others or problem.model_frame is not None:
        raise ValueError(
            "cramer_rao: the data has unknowns whose true value cannot be given "
            f"({', '.join(others) or f'external measurement frame {problem.model_frame!r}'})"
            "; the bound is supported for pose observations in the root frame and targets"
        )
    observed = problem.model0.topology.frames
    if set(frames) != set(observed) or len(frames) != len(observed):
        raise ValueError(
            f"frames: expected the observed end frames {list(observed)} (any "
            f"order), got {list(frames)}"
        )
    cov_free, rank = _pseudo_inverse(information_matrix(problem, noise))
    P = problem.n_parameters
    covariance = np.zeros((P, P))
    idx = np.flatnonzero(problem.free)
    covariance[np.ix_(idx, idx)] = cov_free
    if rank < len(idx):
        log.warning(
            "cramer_rao: the information has rank %d < %d free parameters; the "
            "bound covers the identifiable subspace only",
            rank,
            len(idx),
        )
    return CRLB(
        model=problem.model0,
        frames=frames,
        parameter_names=problem.names,
        free=problem.free.copy(),
        covariance=covariance,
        rank=rank,
        noise=noise,
    )


# -- what the bound implies for positioning --------------------------------------------


def _check_qs(model: CPCModel, qs: ArrayLike) -> NDArray[np.float64]:
    qs = np.asarray(qs, dtype=float)
    if qs.ndim != 2 or qs.shape[1] != model.n_joints or not np.isfinite(qs).all():
        raise ValueError(
            f"qs: expected finite joint values of shape (n, {model.n_joints}) "
            f"in the order {list(model.topology.joint_names)}, got shape "
            f"{qs.shape}"
        )
    return qs


def _check_frames(model: CPCModel, frames: Sequence[str]) -> tuple[str, ...]:
    if isinstance(frames, str):
        raise TypeError("frames: expected a sequence of frame names, not a string")
    frames = tuple(frames)
    unknown = [f for f in frames if f not in model.topology.frames]
    if not frames or unknown:
        raise ValueError(
            f"frames: expected end frames of the model "
            f"{list(model.topology.frames)}, got {list(frames)}"
        )
    return frames


def position_jacobians(
    model: CPCModel,
    qs: ArrayLike,
    frames: Sequence[str],
    *,
    method: str = "casadi",
    step: float = 1e-6,
) -> NDArray[np.float64]:
    """Jacobians of end-frame positions with respect to the CPC chart at ``model``.

    Parameters
    ----------
    model : CPCModel
        The chart's origin (``delta = 0``, :meth:`kinfw.model.CPCModel.perturbed`).
    qs : array_like, shape (n, J)
        Configurations, columns in ``model.topology.joint_names`` order (rad, m).
    frames : sequence of str
        End frames of ``model``.
    method : {"casadi", "finite_difference"}
        Exact derivatives of :func:`kinfw.model.cpc_fk_function`, or central
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

        from kinfw.model import cpc_fk_function

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
    if (
        model.topology != bound.model.topology
        or model.parameter_names != bound.model.parameter_names
    ):
        raise ValueError(
            "model: its CPC chart does not match the bound's (pass bound.model, "
            "the model the bound was computed around)"
        )


def predicted_position_ms(
    covariance: NDArray[np.float64], G: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Mean over configurations of ``trace(G C G^T)`` per frame, (E,), m^2."""
    return np.einsum("nekp,pq,nekq->ne", G, covariance, G).mean(axis=0)


def predicted_position_rms(
    bound: CRLB, model: CPCModel, qs: ArrayLike, frames: Sequence[str], *, method: str = "casadi"
) -> float:
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
    return float(np.sqrt(predicted_position_ms(bound.model_covariance, G).mean()))


def true_chart_coordinates(
    problem: LeastSquaresProblem, truth_robot: Robot, root_T_targets: dict[str, ArrayLike]
) -> NDArray[np.float64]:
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
        raise ValueError(
            "true_chart_coordinates: only the CPC chart and target poses are supported"
        )
    truth = cpc_from_geometry(geometry_from_robot(truth_robot, m0.topology.frames), sign=m0.sign)
    x = np.zeros(problem.n_parameters)
    x[problem.block(CPC_KEY)[1]] = m0.chart_coordinates(truth)
    for block in unknown:
        _, sl = problem.block(block.key)
        if block.key.name not in root_T_targets:
            raise ValueError(f"root_T_targets: missing the true pose of target {block.key.name!r}")
        x[sl] = block.coordinates(np.asarray(root_T_targets[block.key.name], dtype=float))
    return x
