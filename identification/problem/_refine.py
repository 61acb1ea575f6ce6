"""Joint nonlinear least squares over every unknown at once (CasADi + Levenberg-Marquardt).

One problem holds the identifiable CPC parameters of the whole tree (the chart of
:meth:`kinfw.model.CPCModel.perturbed`), each target's pose, the pose of the root in every
external measurement frame, every marker's pose and every unknown point offset, and uses
every ``pose``, ``target`` and ``point`` observation together. It is the nonlinear
identification the paper sets aside (Shih et al. eq. 23), started from the closed form
and the hand-eye solution (or from the nominal URDF).

Residuals are whitened by the measurement noise: ``(measured - predicted) / sigma_p`` for
positions and ``0.5 vee(R_pred^T R_meas - R_meas^T R_pred) / sigma_r`` for orientations
(the sine of the error angle about its axis: smooth at zero error, unlike a log), and
each further observation kind's rows by the sigma of its own noise component. With
``sigma`` not given they are estimated from the residuals (variance components: each
component's sum of squares over its share of the degrees of freedom, iterated).

The problem is assembled by :mod:`kinfw.identification.problem` from parameter blocks
(:mod:`kinfw.model`) and the observation kinds of the registry
(:mod:`kinfw.observations`): CasADi builds each observation group's residual and its
exact Jacobian from the CPC model (:func:`kinfw.model.cpc_fk_function`) and maps
them over the samples; the solver is Levenberg-Marquardt on those functions (numpy,
:mod:`kinfw.identification.problem`), with an optional Huber or Cauchy loss by
iteratively reweighted least squares; the noise is estimated per noise component
(:mod:`kinfw.identification.problem`); covariance and identifiability come from
:mod:`kinfw.identification.problem`. Directions of the parameter space the data
does not determine are left at the start (minimum-norm steps) and reported. This module
orchestrates them.

Gauge (:mod:`kinfw.identification.problem`). The CPC chart is minimal for poses of end
frames in the measurement frame. Two more redundancies are fixed: when every observation
is in one external frame (``measured_in``), the model is expressed in that frame (the
root's pose in it comes from the export's registration, not from a separate unknown);
and an end frame observed only through markers or points of unknown offset keeps its
nominal tool transform (the markers carry the freedom).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from kinfw import progress
from kinfw.identification.problem._build import build_problem
from kinfw.identification.problem._diagnostics import (
    GroupResiduals,
    Identifiability,
    RejectedObservation,
    covariance_and_identifiability,
    group_residuals,
    rejected_observations,
)
from kinfw.identification.problem._noise import NoiseModel, estimate_noise, norm2_cdf
from kinfw.identification.problem._prior_choice import choose_prior
from kinfw.identification.problem._problem import LeastSquaresProblem, NormalEquations, Unknown
from kinfw.identification.problem._refine_result import RefineResult
from kinfw.identification.problem._solver import (
    LOSS_SCALE,
    LOSSES,
    levenberg_marquardt,
    leverage_sums,
    leverages,
    negligible_columns,
    observation_norms,
    row_weights,
    tall_r,
    thresholds,
)
from kinfw.measurements import (
    Measurements,
    check_measurements,
    fixed_in_experiment,
    robot_measurement_frames,
)
from kinfw.model import BaseBlock, PriorScales, Robot, RobotBlock, check_robot
from kinfw.observations import DatasetError, kind_named, kind_of

log = logging.getLogger(__name__)

#: Default rejection quantile of :func:`refine`, as a standard-normal ``z``: Phi(3.09) =
#: 0.999, so 0.1 % of clean observations are rejected.
REJECT_Z = 3.09
#: Default largest fraction of the observations :func:`refine` rejects.
MAX_REJECT_FRACTION = 0.05


def information_matrix(problem: LeastSquaresProblem, noise: NoiseModel) -> NDArray[np.float64]:
    """Fisher information ``J^T J`` of the whitened residuals at the problem's start.

    Built around the *true* model and frames, its inverse is the Cramer-Rao bound on the
    covariance of any unbiased estimate of the chart coordinates (free entries only).
    """
    _, J = problem.evaluate(np.zeros(problem.n_parameters), noise, True)
    Jf = J[:, problem.free]
    return Jf.T @ Jf


def refine(
    robot: Robot,
    measurements: Measurements,
    *,
    start: Robot | None = None,
    targets: dict[str, NDArray] | None = None,
    noise: NoiseModel | None = None,
    loss: str = "linear",
    loss_scale: float = LOSS_SCALE,
    max_iterations: int = 100,
    noise_rounds: int = 5,
    parameters: str | tuple[str, ...] = "full",
    prior: PriorScales | tuple[float, float] | None = None,
    choose_prior: bool = False,
    known: tuple[Unknown, ...] = (),
    refine_intrinsics: bool | tuple[str, ...] = (),
    extra_blocks: tuple[RobotBlock, ...] = (),
    reject: float | None = REJECT_Z,
    max_reject_fraction: float = MAX_REJECT_FRACTION,
    max_reject_rounds: int = 5,
) -> RefineResult:
    """Refine every unknown jointly by whitened nonlinear least squares.

    Parameters
    ----------
    robot : Robot
        The nominal URDF: topology, joint types, and the tool transforms kept for frames
        observed only through markers.
    measurements : Measurements
        ``pose``, ``target`` and ``point`` observations (any mix).
    start : Robot, optional
        Start geometry (e.g. the closed-form + hand-eye URDF); default ``robot``.
    targets : dict of str to ndarray (4, 4), optional
        Start poses ``root_T_target`` (e.g. from the hand-eye step); default estimated.
    noise : NoiseModel, optional
        Measurement noise; default estimated from the residuals (starting from 1 mm and
        0.5 deg).
    loss : {"linear", "huber", "cauchy"}
        Robust loss on each observation's whitened residual norm.
    loss_scale : float
        Where the robust loss departs from least squares, as a standard-normal quantile
        ``z``: an observation's whitened residual norm is compared with the same quantile
        of its clean distribution under the noise model of :class:`NoiseModel` (exact:
        ``chi2(3) + 3 chi2(1)`` for poses and targets, ``chi2(3)`` for points), so 2.33
        flags 1 % of clean observations.
    max_iterations : int
        Levenberg-Marquardt iterations per noise round.
    noise_rounds : int
        At most this many re-estimations of the noise when it is not given: fewer once a
        converged round leaves every sigma within :data:`NOISE_SETTLED` of itself.
    parameters : {"full", "offsets", "frames", "none"} or tuple of joint names
        What to estimate besides the targets, external frames, markers and offsets:
        ``"full"`` every identifiable CPC parameter; ``"offsets"`` joint zero offsets,
        the base frame and the end frames' tool transforms; ``"frames"`` the base and tool
        frames only (nominal joints); ``"none"`` nothing of the robot (the nominal
        baseline); a mask: ``"frames"`` plus the CPC parameters named by joint (all of
        its parameters) or ``"joint:field"`` (``b_tilt_1``, ``b_tilt_2``, ``l_x``,
        ``l_y``).
    prior : PriorScales or (sigma_m, sigma_rad), optional
        Gaussian prior on the robot parameters' deviations from the nominal URDF (from
        the start when the model lives in an external frame), for small datasets, one
        sigma per parameter group (:class:`kinfw.identification.PriorScales`: zero
        offsets, axes, positions, base, tools, intrinsics, model spec blocks); a pair is
        :meth:`~kinfw.identification.PriorScales.uniform`: the joints' (the CPC chart's
        axis tilts and line offsets, zero offsets) and the base, the end frames' tools (a
        camera's mount) free, as ``"frames"`` fits them. With ``"full"``, the joint zero
        offsets are estimated too, under the prior (a zero offset is one angle where the
        CPC chart would spread it over every axis below the joint:
        :func:`kinfw.identification.problem.robot_blocks`).
    choose_prior : bool
        Choose the prior's group sigmas from these data: after the fit under ``prior``
        (default :data:`CHOICE_START`), the sigmas that minimise the linearised
        leave-one-sample-out error (:func:`kinfw.identification.problem.choose_prior`),
        the fit again under them, warm, until they settle (at most
        :data:`PRIOR_ROUNDS` choices). :attr:`RefineResult.prior` holds them.
    known : tuple of Unknown
        Start values of extra unknowns (targets, frames, markers, offsets) instead of
        estimating them from these data.
    refine_intrinsics : bool or tuple of str
        Cameras (frames) of ``pixels`` observations whose 9 intrinsics (fx, fy, cx, cy,
        k1, k2, p1, p2, k3) are estimated too, started from the data's; True: every
        camera; default none (the intrinsics are known). What the images cannot
        determine (k3 with the board always near the image centre) is reported as
        unidentifiable and left at its start.
    extra_blocks : tuple of RobotBlock
        Parameters of the robot model besides the CPC chart, base and joint zero offsets
        (a joint's gear scale: :class:`kinfw.model.RobotBlock`, with its hooks into the
        forward kinematics), free as their ``free_for(parameters)`` says; reported by
        name and unit with the others.
    reject : float or None
        With a robust loss: the rejection quantile, as a standard-normal ``z`` (default
        3.09, the 99.9 % quantile); observations whose whitened residual norm is beyond
        that quantile of its clean distribution are excluded and the problem refitted
        without them (see Notes). None keeps every observation (down-weighted only).
        Ignored for ``loss="linear"``.
    max_reject_fraction : float
        At most this fraction of the observations is rejected (the worst; at least one
        when the fraction is positive: a small dataset may hold one gross error); when more lie
        beyond the threshold, :attr:`RefineResult.rejection_note` says so.
    max_reject_rounds : int
        Refits after rejection, at most.

    Returns
    -------
    RefineResult

    Raises
    ------
    DatasetError
        When the data does not fit the robot or leaves an external frame unplaceable.
    TypeError
        ``robot`` or ``measurements`` is not a Robot / Measurements (a path: load it
        first), naming the argument.

    Notes
    -----
    Gross errors are rejected explicitly rather than by a redescending loss: a
    redescending loss (Cauchy, Tukey) has local minima, its result depends on the start,
    and an observation's influence never quite reaches zero (nor does the report say
    which were dropped); explicit rejection refits exactly the problem without them, so
    the result equals the fit of the data with those observations deleted.

    The test, per observation: the norm ``s`` of its whitened residual, at the robust
    fit (Huber or Cauchy by IRLS, whose noise estimate is robust: a median, then a
    moment trimmed at the 99.9 % quantile, :func:`kinfw.identification.problem.estimate_noise`,
    which gross errors do not inflate), against the ``Phi(reject)`` quantile of the
    clean norm under the noise model of the kind's noise components (exact CDFs of
    :func:`kinfw.identification.problem.norm2_cdf`: ``chi2(3)`` for a point,
    ``chi2(3) + 3 chi2(1)`` for a pose or target). A clean observation is therefore
    rejected with probability ``1 - Phi(reject)`` (0.1 % by default; a little less, as
    fitted residuals are smaller than the noise by the leverage), a 70 mm error on
    0.5 mm noise (a whitened norm of 140 against a threshold near 4.0) surely.

    Rounds: fit, reject the observations beyond the threshold, refit without them
    (from the same starts, noise re-estimated), and again until no new observation is
    beyond the threshold or ``max_reject_rounds`` refits; a rejected observation is not
    readmitted. More than ``max_reject_fraction`` of the observations (at least one)
    beyond the threshold is not what a few gross errors look like (under the noise
    model, 0.1 % is expected): only the worst that fraction allows are rejected and
    ``rejection_note`` says the data may be inconsistent with the model. A rejection
    that leaves the problem undetermined (:class:`DatasetError` on the refit) is undone
    and noted.
    """
    robot = check_robot(robot, "robot")
    measurements = check_measurements(measurements, "measurements")
    _check_loss_options(loss, reject, max_reject_fraction)
    t0 = time.perf_counter()

    def fit(data: Measurements, warm: _Fitted | None = None) -> _Fitted:
        return _fit(
            robot,
            data,
            warm=warm,
            start=start,
            targets=targets,
            noise=noise,
            loss=loss,
            loss_scale=loss_scale,
            max_iterations=max_iterations,
            noise_rounds=noise_rounds,
            parameters=parameters,
            prior=prior,
            choose_prior=choose_prior,
            known=known,
            refine_intrinsics=refine_intrinsics,
            extra_blocks=extra_blocks,
        )

    fitted = fit(measurements)
    if loss == "linear" or reject is None:
        return _rated(fitted, loss)
    fitted, rounds, rejected, note = _reject_gross_errors(
        fit,
        measurements,
        fitted,
        reject=reject,
        max_reject_fraction=max_reject_fraction,
        max_reject_rounds=max_reject_rounds,
    )
    result = _rated(fitted, loss)
    rejected = _clean_tail(
        _rejected_at_final(rounds, rejected, fitted.problem, result),
        sum(len(g.sample) for g in fitted.problem.groups) + len(rejected),
        reject,
    )
    _log_rejection(rejected, note)
    return replace(
        result,
        rejected=tuple(rejected),
        rejection_note=note,
        seconds=time.perf_counter() - t0,
    )


def _check_loss_options(loss: str, reject: float | None, max_reject_fraction: float) -> None:
    """Refuse a loss, rejection quantile or rejection fraction :func:`refine` cannot use."""
    if loss not in LOSSES:
        raise ValueError(f"loss: expected one of {LOSSES}, got {loss!r}")
    if reject is not None and not reject > 0.0:
        raise ValueError(f"reject: expected a positive z (e.g. 3.09) or None, got {reject!r}")
    if not 0.0 <= max_reject_fraction < 1.0:
        raise ValueError(
            f"max_reject_fraction: expected 0 <= fraction < 1, got {max_reject_fraction!r}"
        )


#: One rejection round of :func:`refine`: the problem fitted, its thresholds and the mask
#: of the observations it rejected.
_Round = tuple[LeastSquaresProblem, NDArray, NDArray]


def _reject_gross_errors(
    fit: Callable[[Measurements, _Fitted], _Fitted],
    measurements: Measurements,
    fitted: _Fitted,
    *,
    reject: float,
    max_reject_fraction: float,
    max_reject_rounds: int,
) -> tuple[_Fitted, list[_Round], list[RejectedObservation], str | None]:
    """The rejection rounds of :func:`refine` (see its Notes), from the robust fit
    ``fitted``: the last fit, the rounds that rejected, the rejected observations (at
    the fits that rejected them) and the rejection note. Each refit starts from the fit
    before it (``fit(data, warm)``)."""
    n_obs = sum(len(g.sample) for g in fitted.problem.groups)
    # one gross error is what any dataset may hold, however small (a training fold of 16)
    allowed = max(int(np.floor(max_reject_fraction * n_obs)), int(max_reject_fraction > 0))
    rejected: list[RejectedObservation] = []
    rounds: list[_Round] = []
    note = None
    data = measurements
    for _ in range(max_reject_rounds):
        problem, r = fitted.problem, fitted.r
        groups = list(problem.groups)
        m = sum(len(g.sample) for g in groups)
        k = thresholds(problem.obs_components, reject)[:m]
        norms = observation_norms(r, problem.obs_sizes)[:m]
        beyond = norms > k
        if not beyond.any():
            break
        room = allowed - len(rejected)
        if beyond.sum() > room:
            note = _too_many_note(
                int(beyond.sum()) + len(rejected), n_obs, allowed, reject, max_reject_fraction
            )
            order = np.argsort(-(norms / k), kind="stable")
            keep_worst = np.zeros(m, bool)
            keep_worst[order[: max(room, 0)]] = True
            beyond &= keep_worst
            if not beyond.any():
                break
        new = rejected_observations(groups, r, fitted.solution.noise, norms, k, beyond)
        rounds.append((problem, k, beyond))
        reduced = _without(data, groups, beyond)
        progress.stage(f"refine: refit without {len(rejected) + len(new)} gross errors")
        try:
            refit = fit(reduced, fitted)
        except DatasetError as exc:
            note = (
                f"{len(new)} observations beyond the rejection threshold were kept: "
                f"without them {exc}"
            )
            break
        rejected += new
        data, fitted = reduced, refit
        if note is not None:
            break
    return fitted, rounds, rejected, note


def _too_many_note(
    n_beyond: int, n_obs: int, allowed: int, reject: float, max_reject_fraction: float
) -> str:
    """The rejection note when ``n_beyond`` of ``n_obs`` observations lie beyond the
    threshold, more than the ``allowed`` rejections."""
    return (
        f"{n_beyond} of {n_obs} observations lie beyond the "
        f"{100 * _phi(reject):.4g} % quantile of the clean residual (expected "
        f"{100 * (1 - _phi(reject)):.2g} %); only the worst {allowed} "
        f"(at most {100 * max_reject_fraction:.3g} %, at least one) are rejected: the "
        "data may be inconsistent with the model (a missing parameter, a wrong frame "
        "or noise model) rather than hold a few gross errors"
    )


def _rejected_at_final(
    rounds: list[_Round],
    rejected: list[RejectedObservation],
    problem: LeastSquaresProblem,
    result: RefineResult,
) -> list[RejectedObservation]:
    """The rejected observations, worst first, with their residuals against the final
    fit (``result`` of ``problem``) when the problems they were in have its layout (the
    same blocks: the functions take the model and the starts as inputs); else those at
    the fit that rejected them."""
    final = []
    for p_round, k, mask in rounds:
        r_final = _residuals_with(p_round, problem, result.estimate, result.noise)
        if r_final is None:
            final = rejected
            break
        norms = observation_norms(r_final, [(len(g.sample), g.rows) for g in p_round.groups])
        final += rejected_observations(p_round.groups, r_final, result.noise, norms, k, mask)
    out = list(final)
    out.sort(key=lambda o: -o.excess)
    return out


#: A rejected observation is the tail of clean data (:func:`_clean_tail`) while this many
#: clean sets of the data's size in 1,000 reach that far (the largest of ``n`` clean
#: observations is beyond it with this probability), and while the observations so far
#: out are no more than this quantile of their expected count allows.
CLEAN_TAIL_P = 1e-3


def _clean_tail(
    rejected: list[RejectedObservation], n_obs: int, reject: float
) -> list[RejectedObservation]:
    """``rejected`` with :attr:`RejectedObservation.clean_tail` set where clean data
    reach: ``n_obs`` clean observations put ``n_obs (1 - Phi(reject))`` beyond the
    threshold on average (0.12 of 120), so one 1.1 times beyond it is no gross error,
    while one 30 times beyond it (a 67 mm error on 0.5 mm noise) is. The mildest first,
    an observation is the tail while ``n_obs P(clean norm > its norm)`` is at least
    :data:`CLEAN_TAIL_P` and the count so far within the Poisson quantile
    ``1 - CLEAN_TAIL_P`` of the expected count."""
    expected = n_obs * (1.0 - _phi(reject))
    allowed, tail = 0, math.exp(-expected)  # P(N <= allowed) for N ~ Poisson(expected)
    term = tail
    while 1.0 - tail > CLEAN_TAIL_P:
        allowed += 1
        term *= expected / allowed
        tail += term
    out, count = {}, 0
    for i in sorted(range(len(rejected)), key=lambda i: rejected[i].excess):
        o = rejected[i]
        beyond = 1.0 - norm2_cdf(kind_named(o.kind).components)(o.whitened_norm**2)
        clean = count < allowed and n_obs * beyond >= CLEAN_TAIL_P
        count += clean
        out[i] = replace(o, clean_tail=clean)
    return [out[i] for i in range(len(rejected))]


def _log_rejection(rejected: list[RejectedObservation], note: str | None) -> None:
    """Log the rejected observations (info) and the rejection note (warning)."""
    gross = [o for o in rejected if not o.clean_tail]
    if len(gross) < len(rejected):
        log.info(
            "refine: %d observations beyond the 99.9 %% quantile (expected on clean data), "
            "left out",
            len(rejected) - len(gross),
        )
    if gross:
        log.info(
            "refine: %d observations rejected as gross errors (worst: %s %s sample %d, "
            "%.3g times the threshold)",
            len(gross),
            gross[0].kind,
            gross[0].frame,
            gross[0].sample,
            gross[0].excess,
        )
    if note is not None:
        log.warning("refine: %s", note)


def _phi(z: float) -> float:
    """The standard normal CDF."""
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


def _residuals_with(
    problem: LeastSquaresProblem, other: LeastSquaresProblem, x: NDArray, noise: NoiseModel
) -> NDArray | None:
    """The whitened residuals of ``problem``'s observations under ``other``'s model,
    starts and estimate ``x`` (groups only, no prior rows); None when the two problems'
    blocks differ (e.g. a group left empty by the rejection took its marker along)."""
    layout = [(b.key, b.size) for b in problem.blocks]
    if layout != [(b.key, b.size) for b in other.blocks] or not other.groups:
        return None
    const = other.groups[0].const
    if len(const) != len(problem.groups[0].const):
        return None
    out = []
    for g in problem.groups:
        r, _ = replace(g, const=const).evaluate(x, False)
        out.append(r / np.tile(g.row_sigma(noise), len(g.sample)))
    return np.concatenate(out)


def _without(data: Measurements, groups: list, drop: NDArray[np.bool_]) -> Measurements:
    """``data`` without the observations marked in ``drop`` (per observation of the
    problem's ``groups``, in order); samples keep their indices, empty groups go."""
    kept, o = [], 0
    for grp in groups:
        m = len(grp.sample)
        rows = np.flatnonzero(~drop[o : o + m])
        if len(rows):
            g = grp.group
            kept.append(kind_of(g).take(g, rows, g.sample[rows]))
        o += m
    return data.with_groups(kept)


def _fit(
    robot: Robot,
    measurements: Measurements,
    *,
    warm: _Fitted | None,
    start: Robot | None,
    targets: dict[str, NDArray] | None,
    noise: NoiseModel | None,
    loss: str,
    loss_scale: float,
    max_iterations: int,
    noise_rounds: int,
    parameters: str | tuple[str, ...],
    prior: PriorScales | tuple[float, float] | None,
    choose_prior: bool,
    known: tuple[Unknown, ...],
    refine_intrinsics: bool | tuple[str, ...],
    extra_blocks: tuple[RobotBlock, ...],
) -> _Fitted:
    """One robust fit of every observation of ``measurements`` (see :func:`refine`),
    before its quality (:func:`_rated`). With ``warm``, a fit of
    the same problem on more data (a rejection refit), its estimate is where the solver
    starts, and its noise estimate too when it had settled (the chart and the start the
    undetermined directions stay at remain a cold fit's; so do the noise rounds unless
    settled: the same estimate, in fewer iterations). ``choose_prior``: the prior's
    scales chosen from the data (:func:`_with_chosen_prior`), from the warm fit's."""
    t0 = time.perf_counter()
    progress.stage(f"refine: start values ({measurements.n_samples} samples)")
    prior = PriorScales.of(prior)
    if choose_prior:
        prior = warm.prior if warm is not None and warm.prior is not None else prior
        prior = CHOICE_START if prior is None else prior
    problem = build_problem(
        robot,
        measurements,
        start=start,
        targets=targets,
        parameters=parameters,
        prior=prior,
        known=known,
        refine_intrinsics=refine_intrinsics,
        extra_blocks=extra_blocks,
    )
    problem = _fixed_in_experiment_kept(problem, robot, measurements)
    given = noise is not None
    if given:
        _check_noise_covers(noise, problem, measurements.source)
    sigma = (
        noise if given else NoiseModel(1e-3, np.radians(0.5), estimated=True, sigmas={"pixel": 1.0})
    )
    k = thresholds(problem.obs_components, loss_scale)
    x0, settled = None, False
    if (
        warm is not None
        and warm.problem.names == problem.names
        and np.array_equal(warm.problem.free, problem.free)
    ):
        x0 = warm.solution.x
        if warm.solution.settled and not given:  # the same fixed point, from next to it
            sigma, settled = warm.solution.noise, True
    solution = _solve(
        problem,
        sigma,
        x0=x0,
        settled=settled,
        given=given,
        loss=loss,
        k=k,
        max_iterations=max_iterations,
        noise_rounds=noise_rounds,
    )
    if choose_prior:
        problem, solution, prior = _with_chosen_prior(
            problem,
            solution,
            prior,
            given=given,
            loss=loss,
            loss_scale=loss_scale,
            max_iterations=max_iterations,
            noise_rounds=noise_rounds,
        )
        k = thresholds(problem.obs_components, loss_scale)
    r = problem.evaluate_free(solution.x, solution.noise, False)[0]
    return _Fitted(problem, measurements, solution, given, k, r, time.perf_counter() - t0, prior)


#: The prior a fit that chooses its scales starts from (``refine(choose_prior=True)``):
#: 1 mm and 5 mrad (an angle as loose as a length over 0.2 m) on the joints' geometry and
#: the base, tools free; the search spans far beyond it either way
#: (:data:`kinfw.identification.problem.SEARCH_SPAN`).
CHOICE_START = PriorScales.uniform(1e-3, 5e-3)

#: Size (chart coordinates, m and rad) of an estimate's part along undetermined
#: directions above which a refinement is refused (``kinfw.identification.identify``): 10 mm
#: or 10 mrad. Forced ``full`` on one plane's contacts drifts by metres when it does not
#: converge (the root's joint by 1.6 m on 40 contacts), by 0.54 on 90 (the root's joint
#: by 0.50 m) and 0.3 on 48 (all accepted while this was 1.0). A converged fit returns
#: to the nominal along those directions to rounding (noise-free data included, since
#: the noise floors and :data:`ROUNDING_SLACK`); one that
#: cannot is refused as well. The model choice's candidates fit through
#: ``identify``: such a candidate fails and another is chosen; a prior chosen from the
#: data is tightened until its fit returns (:func:`_with_chosen_prior`).
UNDETERMINED_LEFT = 1e-2

#: Halvings of every sigma of a chosen prior, at most, while its fit cannot return along
#: what the data do not determine (a loose group lets a curved valley drift: images of a
#: board leave the robot's pose relative to it free).
PRIOR_TIGHTENINGS = 6

#: Choices of the prior's scales, each followed by a warm refit, at most; fewer once a
#: choice leaves every sigma within :data:`PRIOR_SETTLED` (relative) of the one before.
PRIOR_ROUNDS = 3
PRIOR_SETTLED = 0.05


def _with_chosen_prior(
    problem: LeastSquaresProblem,
    solution: _Solution,
    prior: PriorScales,
    *,
    given: bool,
    loss: str,
    loss_scale: float,
    max_iterations: int,
    noise_rounds: int,
) -> tuple[LeastSquaresProblem, _Solution, PriorScales]:
    """The prior's scales chosen at the fit ``solution`` (:func:`choose_prior`), the
    problem refitted under them from it (:func:`_returning_fit`), until they settle: the
    last problem, its fit and the scales."""

    def refit(trial: LeastSquaresProblem, start: _Solution) -> _Solution:
        return _solve(
            trial,
            start.noise,
            x0=start.x,
            settled=start.settled and not given,
            given=given,
            loss=loss,
            k=thresholds(trial.obs_components, loss_scale),
            max_iterations=max_iterations,
            noise_rounds=noise_rounds,
        )

    for _ in range(PRIOR_ROUNDS):
        k = thresholds(problem.obs_components, loss_scale)
        chosen, _ = choose_prior(problem, solution.x, solution.noise, loss, k, prior)
        settled = _same_scales(chosen, prior)
        prior = chosen
        if settled:
            break
        problem, solution, prior = _returning_fit(problem, solution, chosen, refit)
    return problem, solution, prior


def _returning_fit(
    problem: LeastSquaresProblem,
    solution: _Solution,
    prior: PriorScales,
    refit: Callable[[LeastSquaresProblem, _Solution], _Solution],
) -> tuple[LeastSquaresProblem, _Solution, PriorScales]:
    """``refit`` under ``prior`` warm from ``solution``, every sigma halved (at most
    :data:`PRIOR_TIGHTENINGS` times) while the fit leaves more than
    :data:`UNDETERMINED_LEFT` along what the data do not determine."""
    for tightening in range(PRIOR_TIGHTENINGS + 1):
        if tightening:
            prior = prior.with_sigmas(
                {(s.group, s.unit): s.sigma / 2 for s in prior.scales}, prior.how
            )
        trial = problem.with_prior(prior)
        fitted = refit(trial, solution)
        if fitted.undetermined <= UNDETERMINED_LEFT:
            break
    return trial, fitted, prior


def _same_scales(a: PriorScales, b: PriorScales) -> bool:
    """Whether ``a`` and ``b`` have the same groups, each sigma within
    :data:`PRIOR_SETTLED` of the other's."""
    keys = {(s.group, s.unit) for s in a.scales}
    if keys != {(s.group, s.unit) for s in b.scales}:
        return False
    return all(abs(np.log(a.sigma(*key) / b.sigma(*key))) < PRIOR_SETTLED for key in keys)


@dataclass(frozen=True, slots=True)
class _Fitted:
    """A fit of :func:`_fit` before its quality: the problem and the data it fitted, the
    solution, whether the noise was given, the robust thresholds ``k`` (per
    observation), the whitened residuals ``r`` at the estimate and the seconds taken."""

    problem: LeastSquaresProblem
    data: Measurements
    solution: _Solution
    given: bool
    k: NDArray[np.float64]
    r: NDArray[np.float64]
    seconds: float
    prior: PriorScales | None = None


def _rated(fitted: _Fitted, loss: str) -> RefineResult:
    """The result of a fit, with its residuals, covariance and identifiability
    (:func:`_quality_at`): only for the fit :func:`refine` returns (a rejection refit
    replaces the fits before it)."""
    t0 = time.perf_counter()
    problem, solution = fitted.problem, fitted.solution
    x, sigma = solution.x, solution.noise
    quality = _quality_at(
        problem, x, sigma, given=fitted.given, loss=loss, k=fitted.k, data=fitted.data
    )
    result = RefineResult(
        model=problem.model_at(x),
        model_frame=problem.model_frame,
        unknowns=problem.unknowns_at(x),
        parameter_names=problem.names,
        parameter_units=problem.units,
        free=problem.free.copy(),
        estimate=x,
        covariance=quality.covariance,
        noise=sigma,
        sigma_hat2=quality.sigma_hat2,
        residuals=quality.residuals,
        downweighted=quality.downweighted,
        identifiability=quality.identifiability,
        iterations=solution.iterations,
        converged=solution.converged,
        undetermined=solution.undetermined,
        noise_settled=solution.settled,
        residual_noise=solution.said,
        w_T_base=problem.base_motion_at(x),
        spec=problem.spec_at(x),
        prior=fitted.prior,
        cost=quality.cost,
        seconds=fitted.seconds + time.perf_counter() - t0,
    )
    log.info(
        "refine: %d free parameters (%d before gauge fixing and the parameter set), "
        "%d residuals, %d iterations, sigma_hat^2 %.3g, %.3f s",
        quality.identifiability.n_parameters,
        problem.n_parameters,
        len(quality.r),
        solution.iterations,
        quality.sigma_hat2,
        result.seconds,
    )
    return result


def _check_noise_covers(noise: NoiseModel, problem: LeastSquaresProblem, source: str) -> None:
    """Refuse a user's noise model that misses a noise component of the problem's data."""
    for c in {c for g in problem.groups for c in g.components}:
        try:
            noise.sigma(c)
        except KeyError as exc:
            hint = "; on the command line --sigma-px" if c.unit == "px" else ""
            raise ValueError(f"{source}: {exc.args[0]}{hint}") from None


@dataclass(frozen=True, slots=True)
class _Solution:
    """The estimate ``x`` of the chart coordinates, the noise model it ends with, the
    Levenberg-Marquardt iterations (summed over the noise rounds) and convergence, and
    the part along undetermined directions left (:func:`_nearest_to_start`), whether
    the noise estimate settled (:func:`_noise_settled`; True when given) and, with a given
    noise, what the residuals say it is (:func:`_residual_noise`)."""

    x: NDArray[np.float64]
    noise: NoiseModel
    iterations: int
    converged: bool
    undetermined: float = 0.0
    settled: bool = True
    said: NoiseModel | None = None


def _solve(
    problem: LeastSquaresProblem,
    sigma: NoiseModel,
    *,
    x0: NDArray | None,
    settled: bool,
    given: bool,
    loss: str,
    k: NDArray,
    max_iterations: int,
    noise_rounds: int,
) -> _Solution:
    """Levenberg-Marquardt from the start (or from ``x0`` (P,): the same minimum, fewer
    iterations), the noise re-estimated after each of the ``noise_rounds`` rounds unless
    ``given`` (then one round under ``sigma``). ``settled``: ``sigma`` is a noise estimate
    at its fixed point (from a fit of the same problem), so the first round is a later
    one."""
    free, obs_sizes = problem.free, problem.obs_sizes

    def full(x_free: NDArray) -> NDArray:  # the fixed entries stay at the start
        x = np.zeros(problem.n_parameters)
        x[free] = x_free
        return x

    x_free = np.zeros(int(free.sum()))
    n_rows = sum(m * rows for m, rows in obs_sizes)
    # what the data do not see at the start stays there for every round: once the other
    # parameters have moved, a structurally redundant one (a joint's axis tilt when the
    # only observed point lies on that axis) gets a small column again and would drift
    # along its redundancy; the diagnostics still report it (with the full free mask)
    G0 = problem.normal_equations(full(x_free), sigma, np.ones(n_rows)).G
    moving = ~negligible_columns(np.zeros((0, len(G0))), np.sqrt(np.diag(G0)))
    if x0 is not None:
        x_free[moving] = x0[free][moving]
    iterations, converged = 0, False
    for round_ in range(1 if given else noise_rounds):
        if not given:
            progress.stage(f"refine: noise estimate, round {round_ + 1}/{noise_rounds}")
        x_free, its, converged = levenberg_marquardt(
            lambda v, jac, s=sigma: problem.evaluate_free(full(v), s, jac),
            x_free,
            moving,
            obs_sizes,
            loss,
            k,
            max_iterations,
            lambda v, w, s=sigma: _gram(problem.normal_equations(full(v), s, w)),
        )
        iterations += its
        if given:
            break
        before = sigma
        sigma = _residual_noise(
            problem, full(x_free), sigma, moving, loss, k, first=round_ == 0 and not settled
        )
        settled = converged and _noise_settled(before, sigma)
        if settled:
            break  # the next round would solve the same problem again
    r, _ = problem.evaluate_free(full(x_free), sigma, False)
    w = np.sqrt(row_weights(r, obs_sizes, loss, k))
    # the data's rows alone: a prior's rows make every direction look determined
    data_rows = n_rows - len(problem.prior_rows)
    data_w = np.where(np.arange(n_rows) < data_rows, w, 0.0)
    G = problem.normal_equations(full(x_free), sigma, data_w).G[np.ix_(moving, moving)]
    left = 0.0
    if not _every_direction_determined(G):
        robot = _robot_entries(problem)
        x_free[moving], left = _nearest_to_start(
            lambda v, jac: problem.evaluate_free(full(v), sigma, jac),
            x_free,
            moving,
            robot[free][moving],
            lambda r: np.sqrt(row_weights(r, obs_sizes, loss, k)),
            data_rows,
        )
    said = _residual_noise(problem, full(x_free), sigma, moving, loss, k) if given else None
    return _Solution(full(x_free), sigma, iterations, converged, left, settled or given, said)


def _residual_noise(
    problem: LeastSquaresProblem,
    x: NDArray,
    sigma: NoiseModel,
    moving: NDArray[np.bool_],
    loss: str,
    k: NDArray,
    *,
    first: bool = True,
) -> NoiseModel:
    """The noise the residuals of ``problem`` at ``x`` (P,) say, whitened by ``sigma``
    (:func:`kinfw.identification.problem.estimate_noise`, with the leverages of the
    ``moving`` free parameters; robust unless ``loss`` is linear, and then by default its
    median round, whatever ``sigma`` is)."""
    r, _ = problem.evaluate_free(x, sigma, False)
    w = np.sqrt(row_weights(r, problem.obs_sizes, loss, k))
    hat = None
    if moving.all():  # else a column is negligible: leverage_sums would refuse
        normal = problem.normal_equations(x, sigma, w, by_component=True)
        hat = leverage_sums(normal.G, normal.by_component)
    if hat is None:  # rank deficient or ill conditioned: the rows' own leverages
        hat = leverages(problem.evaluate_free(x, sigma, True)[1], w)
    return estimate_noise(r, problem.groups, sigma, hat, robust=loss != "linear", first=first)


def _every_direction_determined(G: NDArray) -> bool:
    """Whether the normal matrix ``G`` (p, p) (``J^T J`` of the whitened, robust-weighted
    Jacobian) proves that the data determine every direction by the rank rule of
    :func:`_nearest_to_start` (:data:`UNDETERMINED_TOL`), without forming the Jacobian.

    With unit-norm columns (a diagonal scaling, which also removes the distance's), the
    eigenvalues of ``G`` are the squared singular values of the Jacobian, computed to
    within about 2e-16 of the largest: a smallest eigenvalue above :data:`SCREEN_TOL`
    (1e-12) of the largest puts the smallest relative singular value above ~1e-6, far
    above the rule's 1e-8. False does not mean a direction is undetermined, only that
    the Jacobian must tell (:func:`_nearest_to_start`).
    """
    d = np.sqrt(np.diag(G))
    if not len(d) or not (d > 0.0).all() or not np.isfinite(G).all():
        return not len(d)
    eig = np.linalg.eigvalsh(G / np.outer(d, d))
    return bool(eig[0] > SCREEN_TOL * eig[-1])


#: Smallest eigenvalue, relative to the largest, of the column-scaled normal matrix above
#: which :func:`_every_direction_determined` holds (a relative singular value above 1e-6).
SCREEN_TOL = 1e-12


#: Largest relative change of every noise component's sigma between two rounds below which
#: :func:`_solve` stops re-estimating the noise (after a converged round): another round
#: would reweigh the components by about twice this fraction, which moves the estimate by
#: a small fraction of its standard errors.
NOISE_SETTLED = 1e-4


def _noise_settled(before: NoiseModel, after: NoiseModel) -> bool:
    """Whether no noise component's sigma changed by more than :data:`NOISE_SETTLED` of
    itself from ``before`` to ``after``."""
    old = dict(before.sigmas)
    return all(abs(v - old.get(c, np.inf)) <= NOISE_SETTLED * v for c, v in after.sigmas)


def _fixed_in_experiment_kept(
    problem: LeastSquaresProblem, robot: Robot, measurements: Measurements
) -> LeastSquaresProblem:
    """``problem`` with the robot's parameters that these data cannot see at their start:
    those of the joints fixed in this experiment
    (:func:`kinfw.measurements.fixed_in_experiment`: a still leg between the root and a
    foot a plane is fixed to) and of the frames they alone carry (the foot's mounting)."""
    fixed = set(fixed_in_experiment(measurements, robot))
    if not fixed:
        return problem
    for frame in robot_measurement_frames(measurements, robot):
        movable = [j.name for j in robot.path_joints(frame) if j.type != "fixed"]
        if movable and movable[-1] in fixed:
            fixed.add(frame)
    blocks = tuple(
        b.with_free(b.free & ~np.isin([n.owner for n in b.names], sorted(fixed)))
        if isinstance(b, RobotBlock)
        else b
        for b in problem.blocks
    )
    return replace(problem, blocks=blocks)


def _robot_entries(problem: LeastSquaresProblem) -> NDArray[np.bool_]:
    """Which entries of ``x`` (P,) are the robot's (its blocks), not the unknowns'."""
    return np.concatenate([np.full(b.size, isinstance(b, RobotBlock)) for b in problem.blocks])


#: Relative singular value (of the column-scaled Jacobian) below which a direction of the
#: parameter space is not determined by the data: the identifiability report's rank rule.
UNDETERMINED_TOL = 1e-8
#: Weight of an unknown block's coordinate (a plane, a marker) against a robot parameter's
#: in the distance :func:`_nearest_to_start` minimises: the robot's parameters stay at the
#: start first; an undetermined direction of the unknowns alone still stays at theirs.
UNKNOWN_WEIGHT = 1e-3

#: Whitened cost per residual row that :func:`_nearest_to_start` may add besides 1e-6 of
#: the cost at its start: on noise-free data the residuals are rounding (the noise
#: estimate at its floor, :func:`kinfw.identification.problem.estimate_noise`), and a move
#: along undetermined directions changes them by rounding, at most ~1e-4 whitened per
#: row at the floors; on real data (a cost of about one per row) it is 1e-6 of the cost
#: again.
ROUNDING_SLACK = 1e-6


def _nearest_to_start(
    evaluate: Callable[[NDArray, bool], tuple[NDArray, NDArray | None]],
    x_free: NDArray,
    moving: NDArray[np.bool_],
    robot: NDArray[np.bool_],
    weights: Callable[[NDArray], NDArray],
    data_rows: int,
    rounds: int = 200,
) -> tuple[NDArray[np.float64], float]:
    """The estimate moved along what the data do not determine to the start: shape
    ``(moving.sum(),)``, the ``moving`` entries of ``x_free``; and the norm of its part
    along those directions that could not be removed (0 when none is left; in the
    distance's coordinates).

    Plane contacts leave the rigid motion of the robot with its planes and a common scale
    free, a joint that never moves its axis, and so on: the cost is the same along those
    directions, so the solver's end point along them is an accident of its path (the
    steps are minimum-norm only to first order). This returns the point of the minimum's
    valley nearest to the start: the null space of the data's whitened, robust-weighted
    Jacobian (rank rule :data:`UNDETERMINED_TOL` on unit-norm columns, as the
    identifiability report), the estimate's part along it removed, then Gauss-Newton
    steps back to the minimum within the determined directions (a shorter move, halved
    until the cost stays at the minimum, when the directions are curved over a long
    way); repeated until the removed part is rounding. A prior's rows are left out of
    the null space: they determine every direction they restrain, so with them in, a
    rigid motion of the robot with its plane would look determined and stay wherever
    the prior's trade-off with the data put it (the default's estimate on standing
    TALOS contacts kept 0.69 mm along it). The steps back to the minimum keep them, and
    the cost at the minimum may then exceed the data's before the move by at most the
    prior's after it (the bound of a linear problem: the move changes the data's cost
    by rounding, and the steps lower the sum). The distance is Euclidean in the chart
    coordinates (m, rad) of the robot's parameters, with the unknown blocks' weighted by
    :data:`UNKNOWN_WEIGHT`: an exported URDF then differs from its start only along
    directions the data determine.

    Parameters
    ----------
    evaluate : callable
        ``(x_free, with_jacobian) -> (r, J)``: whitened residuals (N,) and their
        Jacobian (N, n_free), or None without ``with_jacobian``.
    x_free : ndarray, shape (n_free,)
        The solver's estimate (chart coordinates from the start).
    moving : ndarray of bool, shape (n_free,)
        The entries the solver moved (the others stay at the start).
    robot : ndarray of bool, shape (moving.sum(),)
        Which moving entries are the robot's.
    weights : callable
        ``r -> w`` (N,): the robust loss's row weights' square roots at ``r``.
    data_rows : int
        The first ``data_rows`` rows are the data's, the rest a prior's.
    rounds : int
        At most this many projections.
    """
    scale = np.where(robot, 1.0, UNKNOWN_WEIGHT)  # y = scale * x: Euclidean in y
    x = x_free.copy()

    def whitened(v: NDArray) -> tuple[NDArray, NDArray]:
        r, J = evaluate(v, True)
        w = weights(r)
        return r * w, J[:, moving] * w[:, None] / scale

    def svd(
        Jy: NDArray, with_u: bool
    ) -> tuple[NDArray | None, NDArray, NDArray, NDArray, NDArray[np.bool_]]:
        """``(U, s, Vt, c, kept)`` of ``Jy / c`` (unit-norm columns), ``Vt`` square (the
        null space's directions too); without ``with_u`` from the ``R`` of its blocked
        QR (:func:`tall_r`: the same ``s`` and ``Vt``, no array of ``Jy``'s size) and
        ``U`` None."""
        c = np.linalg.norm(Jy, axis=0)
        c = np.where(c > 0.0, c, 1.0)
        if with_u:  # U only as wide as Jy: a full U of a tall Jy would be rows x rows
            U, s, Vt = np.linalg.svd(Jy / c, full_matrices=len(Jy) < Jy.shape[1])
        else:
            U, (_, s, Vt) = None, np.linalg.svd(tall_r(Jy, 1.0 / c), full_matrices=True)
        s = np.concatenate([s, np.zeros(len(Vt) - len(s))])
        kept = s > UNDETERMINED_TOL * s[0] if s.size and s[0] > 0 else np.zeros(len(s), bool)
        return U, s, Vt, c, kept

    def costs(v: NDArray) -> tuple[float, float]:
        """The data's cost and the prior's at ``v``."""
        r = evaluate(v, False)[0]
        r = r * weights(r)
        if not np.isfinite(r).all():
            return np.inf, np.inf
        return float(r[:data_rows] @ r[:data_rows]), float(r[data_rows:] @ r[data_rows:])

    def back_to_minimum(v: NDArray, Q: NDArray) -> NDArray:
        """Gauss-Newton steps within the determined directions (orthogonal to ``Q``)."""
        v = v.copy()
        for _ in range(3):
            r, Jy = whitened(v)
            if not (np.isfinite(r).all() and np.isfinite(Jy).all()):
                break
            U, s, Vt, c, kept = svd(Jy, True)
            n = int(kept.sum())
            step = -(Vt[:n].T @ ((U[:, :n].T @ r) / s[:n])) / c
            step -= Q @ (Q.T @ step)
            v[moving] += step / scale
        return v

    before = costs(x)[0]
    # rounding: a whitened row at the noise floor (noise-free data) is not exact
    slack = before * 1e-6 + ROUNDING_SLACK * data_rows
    fraction, left = 1.0, 0.0
    for _ in range(rounds):
        Jy = whitened(x)[1][:data_rows]
        if not np.isfinite(Jy).all():
            break
        _, _, Vt, c, kept = svd(Jy, False)
        if kept.all():
            break
        Q = np.linalg.qr(Vt[~kept].T / c[:, None])[0]  # the null space, in y
        y = scale * x[moving]
        along = Q @ (Q.T @ y)
        left = float(np.linalg.norm(along))
        if left <= 1e-12 * max(1.0, np.linalg.norm(y)):
            left = 0.0
            break
        # a long way along curved directions: shorter moves, each back to the minimum
        while fraction >= 1e-3:
            trial = x.copy()
            trial[moving] -= fraction * along / scale
            # the move leaves the data's cost; back at the minimum, the cost is at most
            # the data's before the move plus the prior's after it (linear bound)
            prior = costs(trial)[1]
            trial = back_to_minimum(trial, Q)
            data, prior_after = costs(trial)
            if data + prior_after <= before + prior + slack:
                x = trial
                if prior > 0.0:  # the next move is bounded from here (the data's cost rose)
                    before = max(before, data)
                fraction = min(1.0, 2.0 * fraction)
                break
            fraction /= 2.0
        else:
            log.info(
                "refine: the estimate could not be moved further along the %d "
                "undetermined directions without raising the cost (%.3g of its part "
                "along them left)",
                int((~kept).sum()),
                float(np.linalg.norm(along)),
            )
            break
    return x[moving], left


def _gram(normal: NormalEquations) -> tuple[NDArray, NDArray]:
    """``(A^T A, A^T b)`` of the normal equations, what the solver takes."""
    return normal.G, normal.g


@dataclass(frozen=True, slots=True)
class _Quality:
    """The fit's quality at its estimate: whitened residuals ``r`` (and per group, with
    the observations the robust loss down-weighted), reduced chi-square, cost, covariance
    and identifiability."""

    r: NDArray[np.float64]
    residuals: tuple[GroupResiduals, ...]
    downweighted: tuple[tuple[str, str, int, float], ...]
    sigma_hat2: float
    cost: float
    covariance: NDArray[np.float64]
    identifiability: Identifiability


def _quality_at(
    problem: LeastSquaresProblem,
    x: NDArray,
    sigma: NoiseModel,
    *,
    given: bool,
    loss: str,
    k: NDArray,
    data: Measurements,
) -> _Quality:
    """Residuals, covariance and identifiability of ``problem`` at ``x`` under ``sigma``
    (a ``given`` noise model is trusted; an estimated one is rescaled by the fit); with
    the robust ``loss``, observations beyond ``k`` are flagged."""
    free = problem.free
    r, Jw = problem.evaluate_free(x, sigma, True)
    w_rows = row_weights(r, problem.obs_sizes, loss, k)
    rw = r * np.sqrt(w_rows)
    Jw *= np.sqrt(w_rows)[:, None]  # the free columns, robust-weighted (a fresh array)
    dof = max(len(r) - int(free.sum()), 1)
    sigma_hat2 = float(rw @ rw / dof)
    s_base = next(
        s for b, s in zip(problem.blocks, problem.slices, strict=True) if isinstance(b, BaseBlock)
    )
    covariance, ident = covariance_and_identifiability(
        Jw,
        free,
        list(problem.names),
        1.0 if given else sigma_hat2,
        data,
        problem.model0,
        # every column's Jacobian only for a rank-deficient fit (its null directions)
        base_columns=lambda: (
            problem.evaluate(x, sigma, True)[1][:, s_base] * np.sqrt(w_rows)[:, None]
        ),
        robot=_robot_entries(problem),
    )
    # blocks that know when a full-rank estimate is still not determined (intrinsics)
    poor = tuple(
        item
        for b, s in zip(problem.blocks, problem.slices, strict=True)
        if b.free.any()
        for item in b.undetermined(x[s], covariance[s, s])
    )
    if poor:
        ident = replace(ident, unidentifiable=(*ident.unidentifiable, *poor))
    flagged = (
        observation_norms(r, problem.obs_sizes) > k if loss != "linear" else np.zeros(len(k), bool)
    )
    residuals, downweighted = group_residuals(list(problem.groups), r, w_rows, sigma, flagged)
    return _Quality(r, residuals, downweighted, sigma_hat2, 0.5 * float(rw @ rw), covariance, ident)
