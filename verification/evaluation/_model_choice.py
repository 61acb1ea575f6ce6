"""Model choice by default: the parameter set and prior that predict held-out data best.

``kinfw calibrate`` (``--params auto``, the default) asks :func:`choose_parameters`
which model to fit. When the data is plentiful -- at least :data:`ROWS_PER_PARAMETER`
residual rows per free parameter of the full set, a view (an image) counting at most
:data:`VIEW_ROWS` -- every parameter can be estimated and ``"full"`` is chosen without
cross-validation (fast: ``kinfw demo``'s 85 samples give about 20 rows per parameter);
if those data then refuse ``"full"`` (500 contacts of one plane: the fit drifts along
what they do not determine), ``kinfw calibrate`` warns and scores the candidates after
all (``cross_validate=True``). Otherwise each candidate is fitted once on all the data
and scored by leave-one-sample-out cross-validation in closed form, linearised at its
fit (:func:`kinfw.verification.evaluation.leave_one_out`: every sample predicted by the
fit without it, one Gauss-Newton step away, no refit and no random partition); the
candidate with the lowest whitened held-out error wins (each observed kind's error in
its own metric, every noise component in units of its noise, so poses, points, image
points, plane contacts and registered kinds mix:
:func:`whitened_score`):

- ``"frames"``: nominal joints, base and tool frames fitted;
- ``"offsets"``: frames plus joint zero offsets;
- ``"full"``: every identifiable CPC parameter;
- ``"full"`` with a Gaussian prior on the deviations from the nominal, one sigma per
  parameter group (:class:`kinfw.model.PriorScales`: zero offsets, axes, positions, the
  tools, freed intrinsics, model spec blocks), chosen continuously by the linearised
  leave-one-out of the fit itself (``identify(choose_prior=True)``,
  :func:`kinfw.identification.problem.choose_prior`): a length and an angle sigma
  shared by the joints' groups first, then one per group when that predicts better by
  more than its standard error.

Until issue 23 the candidates were scored by refitting 5-fold cross-validation (55
calibrations for 11 candidates, 13.7 s on 35 TIAGo samples); its choice moved with the
partition on the smallest sets (18-sample folds). Until issue 37 the prior was one length
and one angle sigma from a grid of 8 (11 fits); the group sigmas cost one fit and its
warm refits, 4 candidates in all, and the chosen fit is the calibration
(:attr:`ModelChoice.fit`).

The observations the robust full-data fit rejects as gross errors are left out of every
score (each candidate's fit rejects its own; those it did not train on are predicted by
its full fit): one 68 mm sample moves an RMS more than the candidates differ.

Ties (within 1 %) go to the simpler model, in the order above. Identification does not
import this module; the CLI wires them.

**What the URDF cannot hold.** When the robot has no model spec of its own and its links
carry inertias that gravity loads in these data, the chosen set is fitted again with a
joint compliance (:class:`kinfw.model.JointComplianceBlock`, ``--model compliance``) and
both are scored by the same leave-one-out (every sample predicted by the fit without it,
whitened by the rigid fit's noise): the compliance is kept only when it predicts held-out
samples more than 1 % better (:data:`MODEL_GAIN`), so rigid data keep the rigid model and
its held-out error (:func:`choose_model_spec`).
"""

from __future__ import annotations

import contextlib
import logging
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from kinfw import progress
from kinfw.identification import Calibration, identify
from kinfw.identification.problem import NoiseModel, build_problem
from kinfw.measurements import Measurements, observed_joints
from kinfw.model import (
    BlockSamples,
    JointComplianceBlock,
    ModelSpec,
    PriorScales,
    Robot,
    RobotModelError,
)
from kinfw.observations import DatasetError, Metric
from kinfw.verification.evaluation._crossval import (
    metric_rms,
    rejected_keys,
    whitened_score,
    whitening_noise,
    without_observations,
)
from kinfw.verification.evaluation._loo import leave_one_out

#: How much better (a fraction of the rigid model's whitened held-out error) a model spec
#: candidate (a joint compliance) must predict to be chosen over the rigid model. The
#: margin alone is not what keeps real data safe: on TIAGo's 401 eye-hand poses
#: (tests/data/tiago_figaroh) the leave-one-out scored a compliance 9 % better (8.32 vs
#: 9.19 mm) whose 5-fold held-out error was 0.9 % worse (12.45 vs 12.34 mm), and neither
#: a 10 % margin nor a 5-fold refit confirming the choice avoided it; the compliance it
#: fitted is not a joint's (:func:`physical_compliance`), which does.
MODEL_GAIN = 0.01

#: Residual rows per free parameter of the full set from which "full" is chosen without
#: cross-validation (a least-squares rule of thumb: ten observations per unknown keep the
#: parameter scatter well below the model's bias for a well-excited robot).
ROWS_PER_PARAMETER = 10.0

#: Rows one view (a group's observations of one sample) counts for at most in
#: :func:`rows_per_parameter`: the 6 numbers of a rigid pose.
VIEW_ROWS = 6


@dataclass(frozen=True, slots=True)
class Candidate:
    """One model scored by leave-one-out cross-validation (closed form).

    Attributes
    ----------
    parameters : str
        ``"frames"``, ``"offsets"`` or ``"full"``.
    prior : PriorScales or None
        The Gaussian prior on deviations from the nominal, by group (chosen from the
        data: :attr:`PriorScales.how` ``"leave-one-out"``).
    whitened : float
        The whitened held-out error (about 6 for poses predicted to the noise, 3 for
        points, 1 for plane contacts; lower is better):
        :func:`whitened_score` of :attr:`errors`.
    errors : tuple of (Metric, float)
        Per metric of the data its held-out RMS over every sample (display unit).
    failed : str or None
        Why the candidate could not be scored (the data too small for its parameters or
        its cameras, on all the data or without one sample); its scores are then NaN
        and it is not chosen.
    model : tuple of str
        The robot blocks fitted besides the URDF (``("compliance",)``); empty for the
        URDF alone.
    """

    parameters: str
    prior: PriorScales | None
    whitened: float
    errors: tuple[tuple[Metric, float], ...] = ()
    failed: str | None = None
    model: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        """E.g. ``"full"``, ``"full, prior 3 mm / 1.72 deg"``, ``"full, prior offsets
        0.5 deg, axes 0.05 deg, positions 1 mm"`` or ``"full + compliance"``."""
        spec = "".join(f" + {m}" for m in self.model)
        if self.prior is None:
            return self.parameters + spec
        return f"{self.parameters}, {self.prior.label}{spec}"


@dataclass(frozen=True, slots=True)
class ModelChoice:
    """The chosen parameter set and prior, and why.

    Attributes
    ----------
    parameters : str
        Set to calibrate with.
    prior : PriorScales or None
        The prior to calibrate with, by group.
    reason : str
        One line.
    candidates : tuple of Candidate
        Scores of every candidate, in the order tried; empty when cross-validation was
        skipped.
    rows_per_parameter : float
        Residual rows per free parameter of the full set on all the data.
    k : int
        Folds: the samples (leave-one-out); 0 when cross-validation was skipped.
    excluded : tuple of (sample, kind, frame, marker)
        Observations left out of every held-out score: those the full-data fit rejected
        as gross errors.
    fit : Calibration or None
        The chosen candidate's calibration on all the data (what
        ``calibrate(nominal, data, parameters=..., prior=..., noise=..., loss=...)``
        returns); None when cross-validation was skipped. Not serialised.
    spec : ModelSpec
        The robot blocks chosen besides the URDF (a joint compliance: :func:`choose_model_spec`),
        unfitted; :attr:`fit` holds their estimates. Empty: the URDF alone.
    """

    parameters: str
    prior: PriorScales | None
    reason: str
    candidates: tuple[Candidate, ...]
    rows_per_parameter: float
    k: int
    excluded: tuple[tuple[int, str, str, str | None], ...] = ()
    fit: Calibration | None = field(default=None, compare=False, repr=False)
    spec: ModelSpec = field(default_factory=ModelSpec)

    @property
    def label(self) -> str:
        model = tuple(b.block_name for b in self.spec.blocks)
        return Candidate(self.parameters, self.prior, np.nan, model=model).label

    def to_dict(self) -> dict:
        return {
            "parameters": self.parameters,
            "prior": None
            if self.prior is None
            else {"scales": self.prior.to_list(), "how": self.prior.how},
            "reason": self.reason,
            "model": list(self.spec.texts),
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
    """Residual rows of ``data`` per free parameter of the full set (inf without any),
    a view counting at most :data:`VIEW_ROWS`.

    A group's observations of one sample are one view of one rigid thing (an image of a
    board: 2 rows per corner): they fix at most its pose, 6 numbers of geometry, however
    many points it shows; more points only average the noise. Counted row by row, 15
    images of a 10x10 circle grid gave 59 rows per parameter of a 6-axis chain and
    ``"full"`` without cross-validation, 11.9 px held out against 3.7 px for the
    leave-one-out's choice (industrial_calibration's wrist camera, docs/measurements.md).
    Poses (6 rows), points (3) and contacts (1) are one observation per sample and group,
    counted as before."""
    with warnings.catch_warnings():  # the data's warnings come once, from the calibration
        warnings.simplefilter("ignore")
        problem = build_problem(nominal, data, parameters="full")
    rows = sum(
        np.minimum(np.bincount(g.sample) * g.rows, max(g.rows, VIEW_ROWS)).sum()
        for g in problem.groups
    )
    return float(rows) / problem.n_parameters if problem.n_parameters else float("inf")


def choose_parameters(
    nominal: Robot,
    data: Measurements,
    *,
    noise: NoiseModel | None = None,
    loss: str = "huber",
    prior: PriorScales | tuple[float, float] | None = None,
    cross_validate: bool = False,
    model_spec: bool = True,
) -> ModelChoice:
    """Choose the parameter set and prior that predict held-out data best, then
    whether a joint compliance predicts better still (:func:`choose_model_spec`).

    Parameters
    ----------
    nominal : Robot
    data : Measurements
    noise, loss
        As for :func:`kinfw.identification.identify` (``noise`` also whitens the
        scores; default: the noise the full-data fit estimates).
    prior : PriorScales or (sigma_m, sigma_rad), optional
        A prior given by the user: every set is scored with it and no prior scale is
        chosen.
    cross_validate : bool
        Score the candidates even on data with :data:`ROWS_PER_PARAMETER` rows per
        parameter or more, where ``"full"`` is otherwise chosen unscored: for data that
        refuse ``"full"`` alone (a fit that drifts along what they do not determine, as
        500 contacts of one plane can).
    model_spec : bool
        Also weigh a joint compliance (:func:`choose_model_spec`); False: the parameter
        set and prior alone (the URDF alone, as before the model spec).

    Returns
    -------
    ModelChoice
        ``"frames"``, unscored, when every joint on a measured path is one of the
        URDF's exact joints (:attr:`kinfw.model.Robot.exact_joints`: a pose chain's).

    Raises
    ------
    ValueError
        Fewer than 3 samples on small data (nothing to cross-validate), or no candidate
        can be fitted on all the data (the calibration's own error).
    """
    choice = _choose_set(
        nominal,
        data,
        noise=noise,
        loss=loss,
        prior=PriorScales.of(prior),
        cross_validate=cross_validate,
    )
    if not model_spec:
        return choice
    return choose_model_spec(nominal, data, choice, noise=noise, loss=loss)


def _choose_set(
    nominal: Robot,
    data: Measurements,
    *,
    noise: NoiseModel | None,
    loss: str,
    prior: PriorScales | None,
    cross_validate: bool,
) -> ModelChoice:
    """The parameter set and prior of :func:`choose_parameters` (without the model
    spec's candidates)."""
    ratio = rows_per_parameter(nominal, data)
    measured = observed_joints(data, nominal)
    if nominal.exact_joints and set(measured) <= set(nominal.exact_joints):
        return ModelChoice(
            "frames",
            prior,
            "every joint on a measured path is exact (the URDF's <kinfw exact>, as kinfw "
            "pose-chain writes it): only the frames are estimated",
            (),
            ratio,
            0,
        )
    if ratio >= ROWS_PER_PARAMETER and not cross_validate:
        return ModelChoice(
            "full",
            prior,
            f"{ratio:.1f} residual rows per free parameter: enough to estimate every parameter",
            (),
            ratio,
            0,
        )
    if data.n_samples < 3:
        raise ValueError(
            f"choosing the parameters needs at least 3 samples for cross-validation, got "
            f"{data.n_samples}; give --params"
        )
    runs = _runs(prior)
    fits = [
        _fit(nominal, data, parameters, p, noise=noise, loss=loss, choose_prior=choose)
        for parameters, p, choose in progress.steps(runs, "model choice", unit="candidates")
    ]
    reference = _reference(fits)
    sigma = whitening_noise(reference.refined.noise if noise is None else noise, data)
    excluded = rejected_keys(reference)
    scored = without_observations(data, {(k, f, m, s) for s, k, f, m in excluded})
    scoring = progress.steps(
        list(zip(runs, fits, strict=True)), "model choice: leave-one-out scores", unit="candidates"
    )
    candidates = [
        _score(nominal, scored, parameters, _fitted_prior(fit, p), fit, loss=loss, sigma=sigma)
        for (parameters, p, _), fit in scoring
    ]
    _check_any_fitted(candidates, data.source)
    scores = [c.whitened for c in candidates if np.isfinite(c.whitened)]
    if not scores:  # no noise component with a held-out error to whiten
        return ModelChoice(
            "full",
            prior,
            "leave-one-out cross-validation could not score these observations (no "
            "held-out error in a metric of the noise): the full set, as before",
            tuple(candidates),
            ratio,
            data.n_samples,
            fit=reference,
        )
    chosen, why = _simplest_best(candidates, min(scores))
    if excluded:
        samples = ", ".join(str(e[0]) for e in excluded)
        why += f"; {len(excluded)} rejected observation(s) not scored (sample(s) {samples})"
    return ModelChoice(
        chosen.parameters,
        chosen.prior,
        f"leave-one-out cross-validation (closed form), {ratio:.1f} residual rows per free "
        f"parameter of the full set ({_enough(ratio)}): {why}",
        tuple(candidates),
        ratio,
        data.n_samples,
        excluded,
        fit=fits[candidates.index(chosen)],
    )


def compliance_candidate(nominal: Robot, data: Measurements) -> JointComplianceBlock | None:
    """The joint compliance the model choice tries on ``data`` (of the measured joints
    but the URDF's exact ones, a pose chain's): None when the robot has a model spec of
    its own (given, or a calibration's), when a link on the measured paths lacks
    inertias, or when gravity loads none of those joints in these data."""
    names = tuple(observed_joints(data, nominal))
    compliant = [j for j in names if j not in nominal.exact_joints]
    if nominal.spec or not compliant:
        return None
    samples = BlockSamples(nominal, names, data.q_of(names), data.sample_payloads(), data.gravity)
    try:
        block = JointComplianceBlock.from_spec(",".join(compliant)).for_data(samples)
    except RobotModelError:
        return None
    return block if block.free.any() else None


def choose_model_spec(
    nominal: Robot,
    data: Measurements,
    choice: ModelChoice,
    *,
    noise: NoiseModel | None = None,
    loss: str = "huber",
) -> ModelChoice:
    """``choice`` with a joint compliance added when it predicts held-out samples more
    than :data:`MODEL_GAIN` better than the rigid model (the module docstring).

    The rigid fit is the choice's own, or (an unscored choice) fitted here and kept as
    the calibration, its warnings issued when it stays. Only ``"full"`` (with or without
    a prior) is weighed: a smaller set's residuals hold the geometry it leaves out, which
    a compliance would partly absorb. A score test at the rigid fit gates the
    rest (:func:`compliance_gain`: what a compliance would take off the whitened cost,
    in-sample, against its chi-square spread under no compliance); only then is the
    compliant model fitted and both scored by the closed-form leave-one-out on the data
    without the rigid fit's rejections, whitened by its noise. Unchanged when no
    compliance is a candidate (:func:`compliance_candidate`) or a fit fails.
    """
    block = compliance_candidate(nominal, data)
    if block is None or choice.parameters != "full":  # frames, offsets: misfit by design
        return choice
    rigid, caught = choice.fit, []
    if rigid is None:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UserWarning)
            try:
                rigid = identify(
                    nominal,
                    data,
                    parameters=choice.parameters,
                    prior=choice.prior,
                    noise=noise,
                    loss=loss,
                )
            except ValueError:  # the caller's refusal or fallback, as without compliance
                return choice
        choice = replace(choice, fit=rigid)
    gain, _, dof = compliance_gain(
        nominal, data, block, rigid, (choice.parameters, choice.prior), noise
    )
    kept = choice
    if gain > _significant(dof):
        progress.stage("model choice: joint compliance under gravity")
        kept = _with_compliance(nominal, data, choice, block, noise=noise, loss=loss)
    if not kept.spec:
        for w in caught:  # the rigid calibration's own warnings, once
            warnings.warn(w.message, w.category, stacklevel=2)
    return kept


def compliance_gain(
    nominal: Robot,
    data: Measurements,
    block: JointComplianceBlock,
    rigid: Calibration,
    model: tuple[str, PriorScales | None],
    noise: NoiseModel | None,
) -> tuple[float, float, int]:
    """The score test of a joint compliance at the rigid fit ``rigid`` of ``model``
    (its parameter set and prior): ``(gain, cost, dof)``, how much more one Gauss-Newton
    step over every free parameter and ``block``'s compliances would lower the whitened
    cost than one over the rigid parameters alone (in-sample, linear loss, without the
    observations the fit rejected), that cost, and the compliances' count. Under no
    compliance the gain is about chi-square with ``dof`` degrees of freedom (the rigid
    parameters' gradient is zero at their fit)."""
    refined = rigid.refined
    kept = without_observations(data, {(k, f, m, s) for s, k, f, m in rejected_keys(rigid)})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        problem = build_problem(
            nominal.with_spec(ModelSpec((block,))),
            kept,
            start=Robot(rigid.urdf_xml, "<rigid>"),
            known=refined.unknowns,
            parameters=model[0],
            prior=model[1],
        )
    r, J = problem.evaluate_free(
        np.zeros(problem.n_parameters), refined.noise if noise is None else noise
    )
    # the compliances' own share: the step over every free column against the step over
    # the rigid ones (the fit's robust loss leaves the rigid columns a least-squares step)
    _, s = problem.block(block.key)
    rigid_cols = ~np.isin(np.flatnonzero(problem.free), np.arange(problem.n_parameters)[s])

    def left(A: NDArray) -> float:
        step, *_ = np.linalg.lstsq(A, -r, rcond=None)
        return float(np.sum((r + A @ step) ** 2))

    return left(J[:, rigid_cols]) - left(J), float(r @ r), int(block.free.sum())


def _significant(dof: int) -> float:
    """A score-test gain far beyond chance: six standard deviations above the mean of
    chi-square with ``dof`` degrees of freedom."""
    return dof + 6.0 * np.sqrt(2.0 * dof)


def missing_compliance(
    nominal: Robot,
    data: Measurements,
    fit: Calibration,
    model: tuple[str, PriorScales | None],
    noise: NoiseModel | None = None,
) -> str | None:
    """Why a rigid calibration's residuals point at a missing joint compliance, or None:
    the score test (:func:`compliance_gain`) far beyond chance and a compliance would
    take more than a tenth off the whitened cost. For a calibration whose model was
    given (``--params``), which the model choice did not weigh."""
    block = compliance_candidate(nominal, data)
    if block is None or fit.refined is None:
        return None
    gain, cost, dof = compliance_gain(nominal, data, block, fit, model, noise)
    if gain <= _significant(dof) or gain <= 0.1 * cost:
        return None
    joints = ", ".join(j for j, f in zip(block.joints, block.free, strict=True) if f)
    return (
        f"residuals follow the gravity torque on {joints}: a joint compliance would take "
        f"{100 * gain / cost:.0f} % off the whitened cost (chi-square {gain:.3g}, {dof} "
        "parameters); add --model compliance"
    )


#: Standard deviations beyond zero an estimated compliance must lie to count as one
#: (:func:`physical_compliance`).
COMPLIANCE_Z = 3.0


def physical_compliance(refined) -> bool:
    """Whether a refinement's compliances look like a joint's: at least one above
    :data:`COMPLIANCE_Z` standard deviations, none below minus that (a joint does not
    stiffen against gravity). A compliance fitted to a misfit of something else (wrong
    camera intrinsics: the IIS-head's vergence at -0.019 +- 0.016 rad/Nm) is neither, and
    is not offered to the model choice."""
    z = [
        value / std
        for (_, field_), value, std in zip(
            refined.parameter_names, refined.estimate, refined.std, strict=True
        )
        if field_ == "compliance" and std > 0
    ]
    return bool(z) and max(z) > COMPLIANCE_Z and min(z) > -COMPLIANCE_Z


def _with_compliance(
    nominal: Robot,
    data: Measurements,
    choice: ModelChoice,
    block: JointComplianceBlock,
    *,
    noise: NoiseModel | None,
    loss: str,
) -> ModelChoice:
    """``choice`` (its fit the rigid one) with the compliant model fitted and both
    scored by leave-one-out; the compliance kept when it predicts better by
    :data:`MODEL_GAIN`."""
    rigid = choice.fit
    compliant = _fit(
        nominal.with_spec(ModelSpec((block,))),
        data,
        choice.parameters,
        choice.prior,
        noise=noise,
        loss=loss,
    )
    if isinstance(compliant, ValueError) or not physical_compliance(compliant.refined):
        return choice
    sigma = whitening_noise(rigid.refined.noise if noise is None else noise, data)
    excluded = rejected_keys(rigid)
    scored = without_observations(data, {(k, f, m, s) for s, k, f, m in excluded})
    label = (choice.parameters, choice.prior)
    scores = [
        _score(robot, scored, *label, fit, loss=loss, sigma=sigma)
        for robot, fit in ((nominal, rigid), (nominal.with_spec(compliant.spec), compliant))
    ]
    scores[1] = replace(scores[1], model=("compliance",))
    candidates = [c for c in choice.candidates if (c.parameters, c.prior, c.model) != (*label, ())]
    candidates += scores
    rigid_score, compliant_score = scores[0].whitened, scores[1].whitened
    better = np.isfinite(compliant_score) and compliant_score < (1 - MODEL_GAIN) * rigid_score
    if not better:
        return replace(choice, candidates=tuple(candidates), k=choice.k or data.n_samples)
    why = (
        f"; a joint compliance under gravity predicts held-out samples better: "
        f"{compliant_score:.3g} whitened vs {rigid_score:.3g} rigid (--model compliance)"
    )
    return replace(
        choice,
        reason=choice.reason + why,
        candidates=tuple(candidates),
        k=choice.k or data.n_samples,
        fit=compliant,
        spec=ModelSpec((block,)),
    )


def _enough(ratio: float) -> str:
    """Why rows ``ratio`` per parameter were scored: too few, or full alone refused."""
    if ratio < ROWS_PER_PARAMETER:
        return f"< {ROWS_PER_PARAMETER:g}"
    return "enough, but full alone was refused"


def _fit(
    nominal: Robot,
    data: Measurements,
    parameters: str,
    prior: PriorScales | None,
    *,
    noise: NoiseModel | None,
    loss: str,
    choose_prior: bool = False,
) -> Calibration | ValueError:
    """One candidate's calibration on all the data (its prior's group sigmas chosen from
    them with ``choose_prior``), or the error that refused it (too little data for its
    parameters, or to place a camera)."""
    label = "full, prior by group" if choose_prior else Candidate(parameters, prior, np.nan).label
    # the data's warnings come once, from the calibration; what is logged names the candidate
    with warnings.catch_warnings(), _candidate_named(label):
        warnings.simplefilter("ignore", UserWarning)
        try:
            return identify(
                nominal,
                data,
                parameters=parameters,
                noise=noise,
                loss=loss,
                prior=prior,
                choose_prior=choose_prior,
            )
        except ValueError as exc:
            return exc


def _fitted_prior(fit: Calibration | ValueError, prior: PriorScales | None) -> PriorScales | None:
    """The prior a candidate was fitted under: its fit's (chosen from the data), else
    ``prior`` (a refused fit)."""
    return prior if isinstance(fit, ValueError) else fit.prior


@contextlib.contextmanager
def _candidate_named(label: str) -> Iterator[None]:
    """Within, what kinfw's loggers say at WARNING or above begins with the candidate
    ``label`` (``"model choice, candidate frames: refine: 45 of 80 observations lie
    beyond ..."``): a restricted candidate's residuals are expected to be poor, and
    unnamed they read as the calibration's."""
    prefix = f"model choice, candidate {label}: ".replace("%", "%%")

    def name(record: logging.LogRecord) -> bool:
        if record.levelno >= logging.WARNING:
            record.msg = prefix + str(record.msg)
        return True

    loggers = [
        logger
        for key, logger in logging.root.manager.loggerDict.items()
        if (key == "kinfw" or key.startswith("kinfw.")) and isinstance(logger, logging.Logger)
    ]
    for logger in loggers:
        logger.addFilter(name)
    try:
        yield
    finally:
        for logger in loggers:
            logger.removeFilter(name)


def _reference(fits: list[Calibration | ValueError]) -> Calibration:
    """The fit whose noise whitens every score and whose rejections are left out of
    them: full with the user's prior (the third of :func:`_runs`), else, when the data
    cannot determine it, the most flexible candidate fitted (full under the weakest
    prior ... frames); the first refusal when none is."""
    order = [2, *range(len(fits) - 1, 2, -1), 1, 0]
    fitted = [fits[i] for i in order if not isinstance(fits[i], ValueError)]
    if not fitted:
        raise fits[0]
    return fitted[0]


def _check_any_fitted(candidates: list[Candidate], source: str) -> None:
    """Refuse data on which no candidate can be scored."""
    failed = [c for c in candidates if c.failed is not None]
    if len(failed) == len(candidates):
        raise DatasetError(
            f"{source}: too few samples to choose the parameters by leave-one-out "
            f"cross-validation: no candidate can be fitted without one sample "
            f"({failed[0].label}: {failed[0].failed}); give --params (e.g. frames)"
        )


def _runs(prior: PriorScales | None) -> list[tuple[str, PriorScales | None, bool]]:
    """The candidates ``(parameters, prior, choose_prior)`` in the order tried: frames,
    offsets, full (with the user's ``prior``), then, without one, full under the prior by
    group chosen from the data."""
    runs = [(p, prior, False) for p in ("frames", "offsets", "full")]
    if prior is None:
        runs.append(("full", None, True))
    return runs


def _score(
    nominal: Robot,
    scored: Measurements,
    parameters: str,
    prior: PriorScales | None,
    fit: Calibration | ValueError,
    *,
    loss: str,
    sigma: tuple,
) -> Candidate:
    """One candidate scored by closed-form leave-one-out on ``scored`` (the data without
    the reference's rejections), whitened by ``sigma``."""
    if isinstance(fit, ValueError):
        return Candidate(parameters, prior, np.nan, failed=str(fit))
    own = {(k, f, m, s) for s, k, f, m in rejected_keys(fit)}
    loo = leave_one_out(
        nominal, scored, fit, parameters=parameters, prior=prior, loss=loss, trained_without=own
    )
    if loo.undetermined:
        samples = ", ".join(str(s) for s in loo.undetermined[:5])
        more = "..." if len(loo.undetermined) > 5 else ""
        return Candidate(
            parameters,
            prior,
            np.nan,
            failed=f"too little data: without sample {samples}{more} some of its "
            "parameters are undetermined",
        )
    errors = metric_rms(loo.held)
    return Candidate(parameters, prior, whitened_score(errors, sigma), errors)


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
            "fitted on these data, or without one sample (too few residuals for its "
            "parameters, or a fit that drifts along what the data do not determine)"
        )
    else:
        (metric, mine), (_, theirs) = chosen.errors[0], full.errors[0]
        why = (
            f"lowest held-out error: {chosen.whitened:.3g} whitened vs {full.whitened:.3g} "
            f"for full alone ({metric.name} {mine:.3g} vs {theirs:.3g} {metric.unit})"
        )
    return chosen, why
