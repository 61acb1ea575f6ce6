"""k-fold cross-validation of the whole calibration pipeline, with baselines.

The honest answer to "how accurate is it really?": every sample is predicted by a model
that never saw it. Folds are drawn by sample; on each fold the pipeline is trained on the
other folds with several parameter sets and scored on the held-out one:

- ``"none"``: the nominal geometry (only the frames the URDF cannot know are fitted: the
  measurement frame, targets, markers, point offsets);
- ``"frames"``: nominal joints; base and tool (hand-eye) frames fitted;
- ``"offsets"``: frames plus joint zero offsets;
- ``"full"``: closed form, hand-eye and the joint refinement of every identifiable CPC
  parameter (kinfw's default).

Held-out errors are predictions with the trained frames (targets, markers, planes, the
root's pose in an external frame) held fixed: nothing is refitted to the test fold. Each
fold is scored in the metrics of the observed kinds
(:attr:`kinfw.observations.ObservationKind.metrics`): the RMS over the held-out
observations of each per-observation metric (a pose's position error norm in mm and
rotation angle in deg, an image point's reprojection error in px, a plane contact's
height in mm, a registered kind's own), and of each group metric over the held-out
groups (a plane's tilt, deg). Images (``pixels`` observations) are split by sample, whole.

Selection (``select``) ranks the sets by the held-out error whitened by the noise the
full-data fit estimates (or the given one): every noise component's error together, each
in units of its own noise, so a set that is better in millimetres but worse in degrees by
more than the noise can tell is not chosen. With ``exclude_flagged`` the observations
the full-data fit rejects as gross errors are left out of the held-out scores (they are
still in the training folds, where each fit rejects them itself).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from kinfw.identification import Calibration, identify
from kinfw.identification.checks import ChangeBound, InsufficientDataError, fit_plausibility
from kinfw.identification.problem import NoiseModel, Unknown, build_problem
from kinfw.measurements import Measurements, drop_duplicate_samples
from kinfw.model import BlockKey, ModelSpec, PriorScales, Robot
from kinfw.observations import Metric, NoiseComponent, NumericContext, kind_of
from kinfw.verification.evaluation._accuracy import AccuracyReport, group_errors
from kinfw.verification.evaluation._trials import executor_for_jobs, run_trials

#: Parameter sets compared by default: the nominal baseline, frames only, and full.
BASELINES = ("none", "frames", "full")
#: The set name that stands for ``kinfw calibrate``'s default on each training fold: the
#: model choice's set and prior (``kinfw crossval``'s "default" column).
AUTO = "auto"
#: Parameter sets compared by default with ``select``: the baselines and offsets.
SELECTION_SETS = ("none", "frames", "offsets", "full")


@dataclass(frozen=True, slots=True)
class FoldScore:
    """One parameter set on one fold.

    Attributes
    ----------
    fold : int
    parameters : str
    n_train, n_test : int
        Samples.
    errors : tuple of (Metric, float)
        Per metric of the held-out observations its RMS (display unit: mm, deg, px):
        over the observations for a per-observation metric, over the groups for a
        group metric (NaN when undefined).
    worst_sample : int
        The held-out sample with the largest error in the first per-observation metric,
        and that error (its display unit).
    worst : float
    condition : float
        Condition number of the trained fit (poor excitation when large).
    n_parameters, n_residuals : int
        Estimated parameters and training residuals.
    """

    fold: int
    parameters: str
    n_train: int
    n_test: int
    errors: tuple[tuple[Metric, float], ...]
    worst_sample: int
    worst: float
    condition: float
    n_parameters: int
    n_residuals: int

    def of(self, name: str) -> float:
        """The held-out RMS in the metric ``name`` (NaN when the fold has none)."""
        return next((v for m, v in self.errors if m.name == name), float("nan"))

    def to_dict(self) -> dict:
        """JSON-ready; each metric's RMS under its headline key (``position_rms_mm``),
        the worst error under ``worst_<unit>``; undefined numbers None."""
        unit = self.errors[0][0].unit if self.errors else ""
        return {
            "fold": self.fold,
            "parameters": self.parameters,
            "n_train": self.n_train,
            "n_test": self.n_test,
            **{m.headline: _num(v) for m, v in self.errors},
            "worst_sample": self.worst_sample,
            "_".join(p for p in ("worst", unit) if p): _num(self.worst),
            "condition": _num(self.condition),
            "n_parameters": self.n_parameters,
            "n_residuals": self.n_residuals,
        }


def _num(value: float | None) -> float | None:
    """Strict JSON: an undefined number (NaN, inf) is None."""
    return None if value is None or not np.isfinite(value) else float(value)


@dataclass(frozen=True, slots=True)
class CrossValidation:
    """Scores of every parameter set on every fold, and what they mean.

    Attributes
    ----------
    k, seed : int
    sets : tuple of str
    scores : tuple of FoldScore
    warnings : tuple of str
        E.g. the full calibration is worse held-out than frames only, with the likely
        cause.
    selected : str or None
        With selection, the set with the lowest mean whitened held-out error
        (:meth:`whitened`).
    noise : tuple of (NoiseComponent, float) or None
        Per noise component of the data its sigma (SI) whitening the selection: the
        given noise, else that of the full-data fit; None without selection.
    excluded : tuple of (int, str, str, str or None)
        Observations left out of the held-out scores as ``(sample, kind, frame,
        marker)``: those the full-data fit rejected (``exclude_flagged``).
    """

    k: int
    seed: int
    sets: tuple[str, ...]
    scores: tuple[FoldScore, ...]
    warnings: tuple[str, ...]
    selected: str | None
    noise: tuple[tuple[NoiseComponent, float], ...] | None = None
    excluded: tuple[tuple[int, str, str, str | None], ...] = ()

    @property
    def metrics(self) -> tuple[Metric, ...]:
        """The metrics of the folds' scores, in order of first appearance."""
        return tuple(dict.fromkeys(m for s in self.scores for m, _ in s.errors))

    def mean(self, parameters: str, name: str | None = None) -> float:
        """Mean over the folds that have it of the held-out RMS in the metric ``name``
        (default: the first of :attr:`metrics`) for one parameter set; NaN if none."""
        return _mean_of(self.scores, parameters, name)

    def whitened(self, parameters: str) -> float:
        """Mean over folds of ``sum_c (RMS_c / sigma_c)^2`` for one set: per noise
        component ``c`` of :attr:`noise` the fold's held-out RMS of its error size in SI
        (its metric's RMS over the display scale) over its sigma; NaN without ``noise``.

        An observation's squared error in a component of ``r`` rows has mean ``r
        sigma^2`` under the noise (3 + 3 for a pose predicted to the noise, 3 for a point,
        2 for an image point, 1 for a plane contact): each term counts its component in
        units of what the noise can tell, so positions, angles, pixels and a registered
        kind's errors mix on one scale. A fold with no error in a noise component's
        metric (only group metrics) scores NaN.
        """
        if self.noise is None:
            return float("nan")
        out = [
            whitened_score(s.errors, self.noise) for s in self.scores if s.parameters == parameters
        ]
        return float(np.mean(out)) if out else float("nan")

    def to_dict(self) -> dict:
        """Strict-JSON-ready: an undefined score (NaN: no such observations) is None;
        per metric of :attr:`metrics` the mean over folds (``mean_position_rms_mm``);
        the whitening noise per component in SI (``position_m``, ``rotation_rad``)."""
        return {
            "k": self.k,
            "seed": self.seed,
            "sets": list(self.sets),
            "folds": [s.to_dict() for s in self.scores],
            **{
                f"mean_{m.headline}": {p: _num(self.mean(p, m.name)) for p in self.sets}
                for m in self.metrics
            },
            "mean_whitened": (
                None if self.noise is None else {p: _num(self.whitened(p)) for p in self.sets}
            ),
            "noise": None
            if self.noise is None
            else {f"{c.name}_{c.unit}": sigma for c, sigma in self.noise},
            "excluded": [
                {"sample": s, "kind": k, "frame": f, "marker": m} for s, k, f, m in self.excluded
            ],
            "warnings": list(self.warnings),
            "selected": self.selected,
        }


def _mean_of(scores: Sequence[FoldScore], parameters: str, name: str | None = None) -> float:
    """Mean over the folds of ``parameters`` that have a finite RMS in metric ``name``
    (default: the first metric of the first fold); NaN if none."""
    mine = [s for s in scores if s.parameters == parameters]
    if name is None:
        name = next((s.errors[0][0].name for s in mine if s.errors), "")
    values = [v for v in (s.of(name) for s in mine) if np.isfinite(v)]
    return float(np.mean(values)) if values else float("nan")


def whitened_score(
    errors: Sequence[tuple[Metric, float]], noise: Sequence[tuple[NoiseComponent, float]]
) -> float:
    """``sum_c (RMS_c / sigma_c)^2`` over the noise components ``c`` of ``noise`` (SI
    sigmas) that ``errors`` (per metric its RMS, display unit) has a finite value of; NaN
    when none (see :meth:`CrossValidation.whitened`)."""
    sigma = {c.display: v for c, v in noise}
    terms = [(v / m.scale / sigma[m]) ** 2 for m, v in errors if m in sigma and np.isfinite(v)]
    return float(sum(terms)) if terms else float("nan")  # nothing to whiten: undefined


def metric_rms(held: AccuracyReport) -> tuple[tuple[Metric, float], ...]:
    """Per metric of ``held`` the RMS of its finite values over every group (display
    unit): over the observations for a per-observation metric, over the groups for a
    group metric."""
    errors = []
    for m in held.metrics:
        found = [e for g in held.groups if (e := g.of(m.name)) is not None and e.metric == m]
        values = np.concatenate([np.ravel(e.shown()) for e in found])
        errors.append((m, _rms(values)))
    return tuple(errors)


def whitening_noise(
    noise: NoiseModel, data: Measurements
) -> tuple[tuple[NoiseComponent, float], ...]:
    """Per noise component of ``data``'s kinds (each name once) its sigma in ``noise``
    (SI, :meth:`kinfw.identification.problem.NoiseModel.sigma`)."""
    components = {c.name: c for g in data.all_groups() for c in kind_of(g).components}.values()
    return tuple((c, float(noise.sigma(c))) for c in components)


def fitted_unknowns(result: Calibration) -> tuple[Unknown, ...]:
    """The frames a calibration fitted that its URDF cannot hold (targets, markers,
    planes), with the root's pose in the external measurement frame when there is one:
    what :func:`held_out_errors` holds fixed."""
    unknowns = result.refined.unknowns
    if result.refined.model_frame is not None:
        unknowns = (*unknowns, Unknown("frame", result.refined.model_frame, result.w_T_root))
    return unknowns


def rejected_keys(result: Calibration) -> tuple[tuple[int, str, str, str | None], ...]:
    """The observations a calibration rejected as gross errors, ``(sample, kind, frame,
    marker)``, sorted."""
    return tuple(
        sorted(
            {(o.sample, o.kind, o.frame, o.marker) for o in result.refined.rejected},
            key=lambda e: (e[0], e[1], e[2], e[3] or ""),
        )
    )


def held_out_errors(
    nominal: Robot,
    model_urdf: str,
    unknowns: tuple[Unknown, ...],
    test: Measurements,
    spec: ModelSpec | None = None,
) -> AccuracyReport:
    """The errors of a calibrated URDF, its model spec (``spec``: compliance...; default
    ``nominal``'s) and its frames (``unknowns``: targets, markers, planes, the root's
    pose in an external frame; nothing refitted) on ``test``, per observation group in
    the metrics of its kind (:class:`AccuracyReport`)."""
    model = Robot(model_urdf, "<trained>")
    nominal = nominal if spec is None else nominal.with_spec(spec)
    problem = build_problem(nominal, test, start=model, known=unknowns)
    context = NumericContext.from_robot(
        model, test.qs, test.joint_names, {BlockKey(u.kind, u.name): u.value for u in unknowns}
    )
    rows = problem.raw_residuals(np.zeros(problem.n_parameters), with_jacobian=False)
    return AccuracyReport(
        tuple(group_errors(g, r, context) for g, (r, _) in zip(problem.groups, rows, strict=True)),
        (),
    )


def _reference_fit(
    nominal: Robot,
    data: Measurements,
    *,
    noise: NoiseModel | None,
    loss: str,
    prior: PriorScales | tuple[float, float] | None,
) -> Calibration:
    """The fit of all the data whose noise whitens the selection and whose rejections are
    flagged: ``"full"``, else, on data too little for it (refused: e.g. one plane's
    contacts, along whose undetermined directions a forced full fit drifts), the next
    most flexible set that fits (``"offsets"``, ``"frames"``); full's refusal when none
    does."""
    refusal = None
    for parameters in ("full", "offsets", "frames"):
        try:
            return identify(
                nominal, data, parameters=parameters, noise=noise, loss=loss, prior=prior
            )
        except InsufficientDataError as exc:
            refusal = refusal or exc
    raise refusal


def _rms(values: NDArray) -> float:
    """RMS of the finite values; NaN when there are none."""
    finite = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(finite**2))) if len(finite) else float("nan")


def _score(
    nominal: Robot,
    train: Measurements,
    test: Measurements,
    test_ids: NDArray,
    parameters: str,
    fold: int,
    noise,
    loss,
    prior,
    bound: ChangeBound | None = None,
) -> FoldScore | str:
    """Train with one parameter set, score on the held-out fold (``test_ids``: the
    original indices of the test samples); the refusal's message when the training fold
    is too little for the set. One task of :func:`crossvalidate`: module level,
    picklable arguments."""
    with warnings.catch_warnings():
        # the data's warnings (limits, fit checks) belong to the full data, said once by
        # the caller; every fold would repeat them with its own numbers
        warnings.simplefilter("ignore", UserWarning)
        try:
            if parameters == AUTO:
                result, chosen = _chosen_fit(nominal, train, noise, loss)
                refused = _implausible(nominal, result, train, chosen, bound)
                if refused:  # kinfw calibrate would not write it
                    return refused
            else:
                result = identify(
                    nominal, train, parameters=parameters, noise=noise, loss=loss, prior=prior
                )
        except InsufficientDataError as exc:  # this set on this fold: said by the caller
            return str(exc)
        except ValueError as exc:  # the model choice on a fold too small to choose
            if parameters != AUTO:
                raise
            return str(exc)
    held = held_out_errors(nominal, result.urdf_xml, fitted_unknowns(result), test, result.spec)
    # the worst held-out sample in the first per-observation metric
    first = next((m for m in held.metrics if m.per_observation), None)
    worst_sample, worst = 0, float("nan")
    if first is not None:
        sizes, samples = held.values(first.name)
        if np.isfinite(sizes).any():
            k = int(np.nanargmax(sizes))
            worst_sample, worst = int(test_ids[samples[k]]), first.scale * float(sizes[k])
    ident = result.refined.identifiability
    return FoldScore(
        fold=fold,
        parameters=parameters,
        n_train=train.n_samples,
        n_test=test.n_samples,
        errors=metric_rms(held),
        worst_sample=worst_sample,
        worst=worst,
        condition=ident.condition,
        n_parameters=ident.n_parameters,
        n_residuals=sum(len(g.sample) * g.rows for g in result.refined.residuals),
    )


def _implausible(
    nominal: Robot,
    result: Calibration,
    train: Measurements,
    prior: PriorScales | tuple[float, float] | None,
    bound: ChangeBound | None,
) -> str | None:
    """The plausibility guard's refusal of the default's fit on a training fold, as
    ``kinfw calibrate`` would refuse to write it
    (:func:`kinfw.identification.checks.fit_plausibility`); None when plausible."""
    calibrated = Robot(result.urdf_xml, "<calibrated>", spec=result.spec)
    verdict = fit_plausibility(nominal, calibrated, train, prior, bound=bound)
    if verdict.plausible:
        return None
    return (
        f"implausible calibration: {verdict.beyond[0].text()}, beyond the bound "
        f"{verdict.bound_text()} (kinfw calibrate would not write it)"
    )


def _chosen_fit(
    nominal: Robot, train: Measurements, noise, loss
) -> tuple[Calibration, tuple[float, float] | None]:
    """What ``kinfw calibrate``'s default fits on ``train``, and with which prior: the
    model choice's set and prior (:func:`kinfw.verification.evaluation.choose_parameters`),
    scored after all when the training data would take ``"full"`` unscored but refuse it
    (one plane's contacts)."""
    from kinfw.verification.evaluation._model_choice import choose_parameters

    choice = choose_parameters(nominal, train, noise=noise, loss=loss)
    if choice.fit is not None:
        return choice.fit, choice.prior
    try:
        fit = identify(
            nominal, train, parameters=choice.parameters, prior=choice.prior, noise=noise, loss=loss
        )
        return fit, choice.prior
    except InsufficientDataError:
        if choice.k > 0:
            raise
    choice = choose_parameters(nominal, train, noise=noise, loss=loss, cross_validate=True)
    fit = choice.fit or identify(
        nominal, train, parameters=choice.parameters, prior=choice.prior, noise=noise, loss=loss
    )
    return fit, choice.prior


def _warnings(cv_scores: list[FoldScore], sets: tuple[str, ...], loss: str) -> list[str]:
    """Why the full calibration predicts worse than frames only, in the first metric."""

    def mean(p):
        return _mean_of(cv_scores, p)

    out = []
    if "full" in sets and "frames" in sets and mean("full") > mean("frames"):
        full = [s for s in cv_scores if s.parameters == "full"]
        unit = next((s.errors[0][0].unit for s in full if s.errors), "")
        causes = []
        ratio = np.mean([s.n_residuals / max(s.n_parameters, 1) for s in full])
        if ratio < 10:
            causes.append(
                f"too many parameters for the data ({ratio:.1f} training residuals per parameter)"
            )
        worst = max(full, key=lambda s: s.worst if np.isfinite(s.worst) else -np.inf)
        if worst.worst > 5 * np.median([s.errors[0][1] for s in full if s.errors]):
            advice = (
                "try --loss huber"
                if loss == "linear"
                else f"the {loss} loss already rejects gross errors in training; "
                "--exclude-flagged leaves those out of the scores"
            )
            causes.append(
                f"an outlier (sample {worst.worst_sample}: {worst.worst:.1f} {unit} "
                f"held out; {advice})"
            )
        cond = max(s.condition for s in full)
        if cond > 1e4:
            causes.append(
                f"poor excitation (condition number {cond:.3g}: move the joints "
                "through more of their ranges)"
            )
        out.append(
            f"the full calibration is worse held-out than frames only ({mean('full'):.3f} "
            f"{unit} vs {mean('frames'):.3f} {unit}); likely cause: "
            + ("; ".join(causes) if causes else "too many parameters for the data")
        )
    return out


def crossvalidate(
    nominal: Robot,
    data: Measurements,
    *,
    k: int = 5,
    seed: int = 0,
    sets: tuple[str, ...] | None = None,
    select: bool = False,
    noise: NoiseModel | None = None,
    loss: str = "huber",
    prior: PriorScales | tuple[float, float] | None = None,
    executor: Executor | None = None,
    jobs: int = 1,
    exclude_flagged: bool = False,
    reference: Calibration | None = None,
    keep_duplicates: bool = False,
    change_bound: ChangeBound | None = None,
) -> CrossValidation:
    """k-fold cross-validation of the pipeline for each parameter set in ``sets``.

    Parameters
    ----------
    nominal : Robot
    data : Measurements
    k : int
        Folds (2 <= k <= samples); folds are a random partition of the samples (seeded).
    seed : int
    sets : tuple of str, optional
        Parameter sets (see :func:`kinfw.identification.refine`), or :data:`AUTO`
        (``"auto"``: ``kinfw calibrate``'s default, the model choice on each training
        fold; ``prior`` does not apply to it; a fold's fit beyond the plausibility guard's
        bound, which ``kinfw calibrate`` would not write, leaves the set unscored with a
        warning that says so); default :data:`BASELINES` and
        :data:`AUTO`, with ``select`` :data:`SELECTION_SETS` (``kinfw crossval
        [--select]``).
    select : bool
        Pick the set with the lowest mean whitened held-out error
        (:meth:`CrossValidation.whitened`: every noise component's error together, in
        units of the given noise, else that of the full-data fit).
    noise, loss, prior
        As for :func:`kinfw.identification.identify`.
    executor : concurrent.futures.Executor, optional
        Run the fits (folds x sets) as tasks of this executor (a process pool, Dask's or
        Ray's); default serially in this process. The scores are the same either way.
        The fits are a :func:`kinfw.progress.task`, a step as each finishes.
    jobs : int
        Without an ``executor``: run the fits in a pool of ``jobs`` worker processes,
        shut down at the end (1, the default: in this process).
    exclude_flagged : bool
        Leave the observations the full-data fit (``"full"``, this ``loss``; on data too
        little for full the most flexible set that fits: :func:`_reference_fit`) rejects as
        gross errors out of the held-out scores (:attr:`CrossValidation.excluded`);
        nothing is rejected with ``loss="linear"``.
    reference : Calibration, optional
        That full-data fit, when the caller has it already (the model choice scores
        several priors against the same flags and noise).
    keep_duplicates : bool
        Keep the samples that repeat an earlier one (``--keep-duplicates``). By default
        they are dropped first, with one ``UserWarning`` naming them
        (:func:`kinfw.measurements.drop_duplicate_samples`): a copy in a test fold of a
        training sample would be scored in-sample.
    change_bound : ChangeBound, optional
        The plausibility guard's rule for the default's fits (``--max-change-mm``,
        ``--max-change-deg``; default :class:`kinfw.identification.checks.ChangeBound`).
    """
    if not keep_duplicates:
        data = drop_duplicate_samples(data, stacklevel=3)
    if not 2 <= k <= data.n_samples:
        raise ValueError(f"k: expected 2 <= k <= {data.n_samples} samples, got {k}")
    if sets is None:
        sets = SELECTION_SETS if select else (*BASELINES, AUTO)
    if reference is None and (exclude_flagged or (select and noise is None)):
        # the full-data fit: its noise whitens the selection, its rejections are flagged
        reference = _reference_fit(nominal, data, noise=noise, loss=loss, prior=prior)
    excluded: tuple[tuple[int, str, str, str | None], ...] = ()
    scored = data
    if exclude_flagged and reference is not None:
        excluded = rejected_keys(reference)
        scored = without_observations(data, {(k, f, m, s) for s, k, f, m in excluded})
    tasks = [
        (nominal, train, test, test_ids, parameters, f, noise, loss, prior, change_bound)
        for f, (train, test, test_ids) in enumerate(_folds(data, scored, k, seed))
        for parameters in sets
    ]
    pool = executor_for_jobs(jobs) if executor is None else None
    try:
        scores = run_trials(_score, tasks, executor=executor or pool, name="cross-validation fits")
    finally:
        if pool is not None:
            pool.shutdown()
    scores, sets, refused = _without_refused(scores, tasks, tuple(sets))
    selected, sigma = None, None
    if select:
        sigma = whitening_noise(noise if noise is not None else reference.refined.noise, data)
    cv = CrossValidation(
        k,
        seed,
        sets,
        tuple(scores),
        (*refused, *_warnings(scores, sets, loss)),
        None,
        sigma,
        excluded,
    )
    if select:
        selected = min(sets, key=cv.whitened)
    return replace(cv, selected=selected)


def _without_refused(
    scores: Sequence[FoldScore | str], tasks: Sequence[tuple], sets: tuple[str, ...]
) -> tuple[list[FoldScore], tuple[str, ...], list[str]]:
    """The fold scores and sets without the sets some fold's training data refused
    (:func:`_score` gave its message: e.g. ``full`` on one plane's contacts, which
    drifts along what they do not determine), and a warning per such set naming the
    first refusal; every set refused raises that refusal."""
    refusals: dict[str, tuple[int, str]] = {}
    for task, score in zip(tasks, scores, strict=True):
        if isinstance(score, str):
            refusals.setdefault(task[4], (task[5], score))
    kept = tuple(p for p in sets if p not in refusals)
    if not kept:
        raise InsufficientDataError(next(iter(refusals.values()))[1])
    said = [
        f"--params {p} not scored: refused on the training samples of fold {fold}: {why}"
        for p, (fold, why) in refusals.items()
    ]
    return [s for s in scores if not isinstance(s, str) and s.parameters in kept], kept, said


def _folds(
    data: Measurements, scored: Measurements, k: int, seed: int
) -> list[tuple[Measurements, Measurements, NDArray[np.int64]]]:
    """``(train, test, test sample indices)`` of each of the ``k`` folds: a seeded random
    partition of the samples; ``train`` from ``data``, ``test`` from ``scored``."""
    order = np.random.default_rng(seed).permutation(data.n_samples)
    folds = []
    for test_idx in np.array_split(order, k):
        test_ids = np.sort(test_idx)
        train = data.subset(np.sort(np.setdiff1d(order, test_idx)))
        folds.append((train, scored.subset(test_ids), test_ids))
    return folds


def without_observations(
    data: Measurements, drop: set[tuple[str, str, str | None, int]]
) -> Measurements:
    """``data`` without the observations keyed ``(kind, frame, marker, sample)`` in
    ``drop`` (samples keep their indices; groups left empty go)."""
    kept = []
    for g in data.all_groups():
        kind = kind_of(g)
        key = (kind.name, kind.frames(g)[0], getattr(g, "marker", None))
        rows = np.flatnonzero([(*key, int(s)) not in drop for s in g.sample])
        if len(rows):
            kept.append(kind.take(g, rows, g.sample[rows]))
    return data.with_groups(kept)
