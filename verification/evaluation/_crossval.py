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

Held-out errors are predictions with the trained frames (targets, markers, the root's pose
in an external frame) held fixed: nothing is refitted to the test fold. Position errors are
per-sample error vector norms (mm); orientation errors the small-angle rotation (deg).
Images (``pixels`` observations) are split by sample, whole, and scored by their RMS
reprojection error (px) under the fold's model and the target pose fitted on the
training folds; they have no position or orientation score (NaN, null in JSON).

Selection (``select``) ranks the sets by the held-out error whitened by the noise the
full-data fit estimates (or the given one): position and orientation together, each in
units of its own noise, so a set that is better in millimetres but worse in degrees by
more than the noise can tell is not chosen. With ``exclude_flagged`` the observations
the full-data fit rejects as gross errors are left out of the held-out scores (they are
still in the training folds, where each fit rejects them itself).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from kinfw.identification import Calibration, calibrate
from kinfw.identification.problem import NoiseModel, Unknown, build_problem
from kinfw.measurements import Measurements
from kinfw.model import Robot
from kinfw.observations import POSITION, ROTATION, kind_of
from kinfw.verification.evaluation._trials import executor_for_jobs, run_trials

__all__ = [
    "BASELINES",
    "SELECTION_SETS",
    "CrossValidation",
    "FoldScore",
    "crossvalidate",
    "held_out_error_sizes",
    "held_out_errors",
]

#: Parameter sets compared by default: the nominal baseline, frames only, and full.
BASELINES = ("none", "frames", "full")
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
    position_rms_mm, rotation_rms_deg : float
        Held-out RMS (rotation NaN when only points are observed).
    worst_sample : int
        The held-out sample with the largest position error, and that error (mm).
    worst_mm : float
    condition : float
        Condition number of the trained fit (poor excitation when large).
    n_parameters, n_residuals : int
        Estimated parameters and training residuals.
    pixel_rms_px : float
        Held-out RMS reprojection error of the test images' points, px (the norm of each
        point's (u, v) error); NaN without ``pixels`` observations. Position and rotation
        scores are over the other kinds only (NaN when there are none).
    """

    fold: int
    parameters: str
    n_train: int
    n_test: int
    position_rms_mm: float
    rotation_rms_deg: float
    worst_sample: int
    worst_mm: float
    condition: float
    n_parameters: int
    n_residuals: int
    pixel_rms_px: float = float("nan")


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
    noise : tuple of (float, float) or None
        ``(position_m, rotation_rad)`` per component whitening the selection: the given
        noise, else that of the full-data fit; None without selection.
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
    noise: tuple[float, float] | None = None
    excluded: tuple[tuple[int, str, str, str | None], ...] = ()
    pixel_sigma_px: float | None = None

    @property
    def has_pixels(self) -> bool:
        """Whether any held-out fold has images (a pixel score)."""
        return any(not np.isnan(s.pixel_rms_px) for s in self.scores)

    def mean(self, parameters: str, field: str = "position_rms_mm") -> float:
        """Mean over folds of a score field for one parameter set."""
        return float(
            np.mean([getattr(s, field) for s in self.scores if s.parameters == parameters])
        )

    def whitened(self, parameters: str) -> float:
        """Mean over folds of ``(position RMS / sigma_p)^2 + (rotation RMS /
        sigma_r)^2`` for one set, with :attr:`noise`'s sigmas (per component, so a clean
        prediction scores about 3 + 3 for poses, 3 for points); NaN without ``noise``.

        An observation's squared position error has mean ``3 sigma_p^2`` under the
        noise and its squared rotation angle ``3 sigma_r^2``: each term counts its
        component in units of what the noise can tell, position and orientation on one
        scale.
        """
        if self.noise is None:
            return float("nan")
        sp, sr = self.noise
        out = []
        for s in self.scores:
            if s.parameters != parameters:
                continue
            rot = 0.0 if np.isnan(s.rotation_rms_deg) else np.radians(s.rotation_rms_deg) / sr
            pos = 0.0 if np.isnan(s.position_rms_mm) else 1e-3 * s.position_rms_mm / sp
            px = 0.0
            if not np.isnan(s.pixel_rms_px) and self.pixel_sigma_px:
                px = s.pixel_rms_px / self.pixel_sigma_px  # (u, v): 2 components
            out.append(pos**2 + rot**2 + px**2)
        return float(np.mean(out))

    def to_dict(self) -> dict:
        """Strict-JSON-ready: an undefined score (NaN: no such observations) is None."""

        def num(value):
            return None if value is None or not np.isfinite(value) else value

        return {
            "k": self.k,
            "seed": self.seed,
            "sets": list(self.sets),
            "folds": [
                {
                    f: num(getattr(s, f)) if f not in ("fold", "parameters") else getattr(s, f)
                    for f in FoldScore.__slots__
                }
                for s in self.scores
            ],
            "mean_position_rms_mm": {p: num(self.mean(p)) for p in self.sets},
            "mean_rotation_rms_deg": {p: num(self.mean(p, "rotation_rms_deg")) for p in self.sets},
            "mean_pixel_rms_px": {p: num(self.mean(p, "pixel_rms_px")) for p in self.sets},
            "mean_whitened": (
                None if self.noise is None else {p: num(self.whitened(p)) for p in self.sets}
            ),
            "noise": None
            if self.noise is None
            else {"position_m": self.noise[0], "rotation_rad": self.noise[1]},
            "excluded": [
                {"sample": s, "kind": k, "frame": f, "marker": m} for s, k, f, m in self.excluded
            ],
            "warnings": list(self.warnings),
            "selected": self.selected,
        }


def held_out_errors(
    nominal: Robot, model_urdf: str, unknowns: tuple[Unknown, ...], test: Measurements
) -> tuple[NDArray, NDArray, NDArray]:
    """Per-observation held-out position errors (m), rotation errors (rad, NaN for
    points) and sample indices of ``test``, predicted by a calibrated URDF and its frames.
    """
    sizes, samples = held_out_error_sizes(nominal, model_urdf, unknowns, test)
    return sizes["position"], sizes["rotation"], samples


def held_out_error_sizes(
    nominal: Robot, model_urdf: str, unknowns: tuple[Unknown, ...], test: Measurements
) -> tuple[dict[str, NDArray], NDArray]:
    """Per observation row of ``test`` (a pose, a point, an image's corner) the size of
    its held-out error per noise component, predicted by a calibrated URDF and its
    frames: ``{"position": m, "rotation": rad, "pixel": px, ...}``, each (n,), NaN where
    the row has no such component; and the rows' sample indices (n,)."""
    problem = build_problem(nominal, test, start=Robot(model_urdf, "<trained>"), known=unknowns)
    names = dict.fromkeys(
        [POSITION.name, ROTATION.name, *(c.name for g in problem.groups for c in g.components)]
    )
    sizes: dict[str, list[NDArray]] = {name: [] for name in names}
    samples = []
    for g, (r, _) in zip(
        problem.groups,
        problem.raw_residuals(np.zeros(problem.n_parameters), with_jacobian=False),
        strict=True,
    ):
        size = {name: np.full(len(g.sample), np.nan) for name in names}
        r = r / g.kind.row_weights(g.group)[:, None]  # the errors, not their fit weights
        c0 = 0
        for c in g.components:  # error sizes per noise component (m, rad, px)
            size[c.name] = c.magnitude(r[:, c0 : c0 + c.rows])
            c0 += c.rows
        for name in names:
            sizes[name].append(size[name])
        samples.append(g.sample)
    return {k: np.concatenate(v) for k, v in sizes.items()}, np.concatenate(samples)


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
) -> FoldScore:
    """Train with one parameter set, score on the held-out fold (``test_ids``: the
    original indices of the test samples). One task of :func:`crossvalidate`: module
    level, picklable arguments."""
    with warnings.catch_warnings():
        # the data's warnings (limits, fit checks) belong to the full data, said once by
        # the caller; every fold would repeat them with its own numbers
        warnings.simplefilter("ignore", UserWarning)
        result = calibrate(
            nominal, train, parameters=parameters, noise=noise, loss=loss, prior=prior
        )
    unknowns = result.refined.unknowns
    if result.refined.model_frame is not None:  # the root's pose in the external frame
        unknowns = (*unknowns, Unknown("frame", result.refined.model_frame, result.w_T_root))
    sizes, samples = held_out_error_sizes(nominal, result.urdf_xml, unknowns, test)
    pos, rot = sizes["position"], sizes["rotation"]
    pixel = sizes.get("pixel", np.full(len(samples), np.nan))
    # the worst held-out sample by position, else (images only) by pixel error
    worst_of = pos if np.isfinite(pos).any() else pixel
    worst = int(np.nanargmax(worst_of)) if np.isfinite(worst_of).any() else 0
    ident = result.refined.identifiability
    return FoldScore(
        fold=fold,
        parameters=parameters,
        n_train=train.n_samples,
        n_test=test.n_samples,
        position_rms_mm=1e3 * _rms(pos),
        rotation_rms_deg=float(np.degrees(_rms(rot))),
        worst_sample=int(test_ids[samples[worst]]),
        worst_mm=1e3 * float(pos[worst]),
        condition=ident.condition,
        n_parameters=ident.n_parameters,
        n_residuals=sum(len(g.sample) * g.rows for g in result.refined.residuals),
        pixel_rms_px=_rms(pixel),
    )


def _warnings(cv_scores: list[FoldScore], sets: tuple[str, ...], loss: str) -> list[str]:
    def mean(p, f="position_rms_mm"):
        return float(np.mean([getattr(s, f) for s in cv_scores if s.parameters == p]))

    out = []
    if "full" in sets and "frames" in sets and mean("full") > mean("frames"):
        full = [s for s in cv_scores if s.parameters == "full"]
        causes = []
        ratio = np.mean([s.n_residuals / max(s.n_parameters, 1) for s in full])
        if ratio < 10:
            causes.append(
                f"too many parameters for the data ({ratio:.1f} training residuals per parameter)"
            )
        worst = max(full, key=lambda s: s.worst_mm)
        if worst.worst_mm > 5 * np.median([s.position_rms_mm for s in full]):
            advice = (
                "try --loss huber"
                if loss == "linear"
                else f"the {loss} loss already rejects gross errors in training; "
                "--exclude-flagged leaves those out of the scores"
            )
            causes.append(
                f"an outlier (sample {worst.worst_sample}: {worst.worst_mm:.1f} mm "
                f"held out; {advice})"
            )
        cond = max(s.condition for s in full)
        if cond > 1e4:
            causes.append(
                f"poor excitation (condition number {cond:.3g}: move the joints "
                "through more of their ranges)"
            )
        out.append(
            f"the full calibration is worse held-out than frames only ({mean('full'):.3f} mm "
            f"vs {mean('frames'):.3f} mm); likely cause: "
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
    prior: tuple[float, float] | None = None,
    progress: Callable[[int, int], None] | None = None,
    executor: Executor | None = None,
    jobs: int = 1,
    exclude_flagged: bool = False,
    reference: Calibration | None = None,
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
        Parameter sets (see :func:`kinfw.identification.refine`); default
        :data:`BASELINES`, with ``select`` :data:`SELECTION_SETS` (``kinfw crossval
        [--select]``).
    select : bool
        Pick the set with the lowest mean whitened held-out error
        (:meth:`CrossValidation.whitened`: position and orientation together, in units
        of the given noise, else that of the full-data fit).
    noise, loss, prior
        As for :func:`kinfw.identification.calibrate`.
    progress : callable(done, total), optional
    executor : concurrent.futures.Executor, optional
        Run the fits (folds x sets) as tasks of this executor (a process pool, Dask's or
        Ray's); default serially in this process. The scores are the same either way.
    jobs : int
        Without an ``executor``: run the fits in a pool of ``jobs`` worker processes,
        shut down at the end (1, the default: in this process).
    exclude_flagged : bool
        Leave the observations the full-data fit (``"full"``, this ``loss``) rejects as
        gross errors out of the held-out scores (:attr:`CrossValidation.excluded`);
        nothing is rejected with ``loss="linear"``.
    reference : Calibration, optional
        That full-data fit, when the caller has it already (the model choice scores
        several priors against the same flags and noise).
    """
    if not 2 <= k <= data.n_samples:
        raise ValueError(f"k: expected 2 <= k <= {data.n_samples} samples, got {k}")
    if sets is None:
        sets = SELECTION_SETS if select else BASELINES
    if reference is None and (exclude_flagged or (select and noise is None)):
        # the full-data fit: its noise whitens the selection, its rejections are flagged
        reference = calibrate(nominal, data, parameters="full", noise=noise, loss=loss, prior=prior)
    excluded: tuple[tuple[int, str, str, str | None], ...] = ()
    scored = data
    if exclude_flagged and reference is not None:
        rejected = reference.refined.rejected
        excluded = tuple(
            sorted(
                ((o.sample, o.kind, o.frame, o.marker) for o in rejected),
                key=lambda e: (e[0], e[1], e[2], e[3] or ""),
            )
        )
        drop = {(o.kind, o.frame, o.marker, o.sample) for o in rejected}
        scored = _without_observations(data, drop)
    tasks = [
        (nominal, train, test, test_ids, parameters, f, noise, loss, prior)
        for f, (train, test, test_ids) in enumerate(_folds(data, scored, k, seed))
        for parameters in sets
    ]
    pool = executor_for_jobs(jobs) if executor is None else None
    try:
        scores = run_trials(_score, tasks, executor=executor or pool, progress=progress)
    finally:
        if pool is not None:
            pool.shutdown()
    selected, sigma, sigma_px = None, None, None
    if select:
        used = noise if noise is not None else reference.refined.noise
        sigma = (float(used.position_m), float(used.rotation_rad))
        sigma_px = dict(used.sigmas).get("pixel")
    cv = CrossValidation(
        k,
        seed,
        tuple(sets),
        tuple(scores),
        tuple(_warnings(scores, sets, loss)),
        None,
        sigma,
        excluded,
        sigma_px,
    )
    if select:
        selected = min(sets, key=cv.whitened)
    return replace(cv, selected=selected)


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


def _without_observations(
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
