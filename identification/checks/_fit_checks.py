"""After the fit: is what is left noise, or a model the data contradicts?

A least-squares fit removes from the residuals everything the model can express (they
are orthogonal to the Jacobian's columns), so what is left should be noise: unrelated to
the joint values and of the size the noise model says. Two checks say when it is not,
and name the likely cause:

- **Structure against the joint values** (:func:`residual_structure`): per observation
  group and noise component, the residual rows are regressed on the robot's motion: a
  constant, the joint values of the joints that move in the data (``cos q``, ``sin q``
  of a revolute joint, ``q`` of a prismatic one) and the observed frame's fitted
  orientation. Pure noise explains ``~ k / m`` of the sum of squares (``k`` regressors,
  ``m`` observations; uncentred, so a constant bias counts; :func:`_chance`); a
  component beyond :data:`STRUCTURE_R2` and that level plus five standard deviations
  follows the motion in a way the model cannot: typically a measured point or frame
  that is not where the URDF frame is (a frame on a revolute joint's axis asked to carry
  an offset — kinfw keeps such a frame on the axis — or a marker given as the frame
  itself: both follow the frame's orientation), or a parameter kept fixed
  (``--params``: follows a joint). What alone explains most is named. A component
  whose residuals are rounding (RMS below :data:`ROUNDING_RMS`: noise-free data) has
  nothing to report.
- **Residual size** (:func:`fit_warnings`): with a stated noise, per noise component,
  the stated sigma against the one its residuals say
  (:attr:`RefineResult.residual_noise`), too large (``--sigma-mm 500`` typed for 0.5) or
  too small (the residuals larger than the stated noise: :func:`stated_noise`) beyond
  chance (:func:`stated_noise_limit`); with an estimated noise, a position sigma above
  :data:`PLAUSIBLE_NOISE_M` (or an orientation sigma above :data:`PLAUSIBLE_NOISE_RAD`)
  is larger than any tracker or camera measures, so the "noise" is a model error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from kinfw.measurements import Measurements

if TYPE_CHECKING:
    from kinfw.identification import RefineResult


#: Fraction of a group's residual variance the joint values must explain to be reported.
STRUCTURE_R2 = 0.5
#: Estimated noise above which it is a model error, not a measurement system's noise.
PLAUSIBLE_NOISE_M = 5e-3
PLAUSIBLE_NOISE_RAD = math.radians(1.0)
#: Residual RMS below which a component is rounding, not a measurement (in its unit: m,
#: rad, px): noise-free data fit to ~1e-16 m, and rounding errors follow the joint
#: values as much as anything, so their structure is not reported.
ROUNDING_RMS = 1e-9


@dataclass(frozen=True, slots=True)
class ResidualStructure:
    """Residuals of one observation group that follow the joint values.

    Attributes
    ----------
    kind, frame : str
    marker : str or None
    n : int
        Observations in the group.
    component : str
        The noise component whose residuals are structured (e.g. ``"position"``).
    explained : float
        Fraction of the whitened residual variance explained by all moving joints.
    chance : float
        The fraction pure noise would leave, ``k / m``.
    explainer : str
        What alone explains most: a joint's name, or "the orientation of 'frame'".
    explainer_explained : float
        Its fraction alone.
    rms_m : float
        RMS position residual norm of the group, metres (NaN without positions).
    last_joint : str or None
        The last movable joint on the frame's path (None for a frame on the root).
    """

    kind: str
    frame: str
    marker: str | None
    n: int
    component: str
    explained: float
    chance: float
    explainer: str
    explainer_explained: float
    rms_m: float
    last_joint: str | None

    def message(self) -> str:
        """One line naming the group, what explains its residuals and the likely cause."""
        what = f"{self.kind} {self.frame!r}" + (f" [{self.marker}]" if self.marker else "")
        size = "" if math.isnan(self.rms_m) else f" (position RMS {1e3 * self.rms_m:.3g} mm)"
        cause = (
            self._offset_cause()
            if self.explainer.startswith("the orientation")
            else f"a parameter of or near joint {self.explainer!r} is missing or fixed "
            "(--params), or the joint's readings are off (scale, backlash)"
        )
        return (
            f"the {self.component} residuals of {what}{size} follow the robot's motion: "
            f"{100 * self.explained:.0f} % of their sum of squares is explained by the joint "
            f"values and the frame's orientation ({100 * self.chance:.0f} % expected from "
            f"noise), {100 * self.explainer_explained:.0f} % by {self.explainer} alone. "
            f"Likely cause: {cause}"
        )

    def _offset_cause(self) -> str:
        """The cause when the frame's orientation explains the residuals: an offset in
        the frame the model cannot carry (a declared marker's offset is fitted, so then
        the marker is not rigid on the frame)."""
        if self.marker is not None:
            return (
                f"marker {self.marker!r} is declared and its offset on {self.frame!r} is "
                "fitted, so an offset does not explain this: a parameter of the joints "
                "before the frame is missing or fixed (--params), or the marker is not "
                f"rigid on {self.frame!r} (on another link, or it moved during the recording)"
            )
        return (
            f"the measured point or frame is probably not where {self.frame!r} is: a "
            "constant offset in that frame that the model cannot carry"
            + (
                f" ({self.frame!r} hangs on joint {self.last_joint!r}: if it is that "
                "joint's child link, kinfw keeps it on the axis; measure a frame off the "
                "axis, or declare a marker)"
                if self.last_joint
                else ""
            )
        )


def _features(q: NDArray, revolute: NDArray) -> list[NDArray]:
    """Per joint, its regression features over the samples: (cos q, sin q) or (q,)."""
    return [
        np.stack([np.cos(q[:, j]), np.sin(q[:, j])], axis=1) if revolute[j] else q[:, j : j + 1]
        for j in range(q.shape[1])
    ]


def _explained(X: NDArray, Y: NDArray) -> float:
    """Fraction of the sum of squares of Y explained by a least-squares fit of every
    column on X (not centred: a constant bias the model cannot absorb counts; X holds the
    constant column)."""
    total = float(np.sum(Y**2))
    if total <= 0.0:
        return 0.0
    B, *_ = np.linalg.lstsq(X, Y, rcond=None)
    return 1.0 - float(np.sum((Y - X @ B) ** 2)) / total


def _chance(k: int, m: int, rows: int) -> tuple[float, float]:
    """What pure noise explains, and the threshold: with ``k`` regressors, ``m``
    observations and ``rows`` Gaussian rows each, the explained fraction is
    ``Beta(k rows / 2, (m - k) rows / 2)``: mean ``k / m``, variance
    ``(k / m)(1 - k / m) / (m rows / 2 + 1)``. Reported beyond :data:`STRUCTURE_R2` and
    the mean plus 5 standard deviations."""
    mean = k / m
    sd = math.sqrt(mean * (1.0 - mean) / (m * rows / 2.0 + 1.0))
    return mean, max(STRUCTURE_R2, mean + 5.0 * sd)


def residual_structure(
    result: RefineResult, measurements: Measurements
) -> tuple[ResidualStructure, ...]:
    """The observation groups whose residuals follow the joint values (module docstring).

    The regressors of a group are a constant, each moving joint's features, and the nine
    entries of the observed frame's fitted orientation ``w_R_frame(q)``: a constant offset
    in the frame's own coordinates (a point the model keeps elsewhere) shows in the
    measurement frame as ``w_R_frame(q) o``, linear in those entries.

    Parameters
    ----------
    result : RefineResult
        A refinement of ``measurements``.
    measurements : Measurements
        The data it was fitted to.

    Returns
    -------
    tuple of ResidualStructure
        The groups beyond both thresholds, the most explained first.
    """
    topology = result.model.topology
    q_all = measurements.q_of(topology.joint_names)
    moving = np.flatnonzero(np.ptp(q_all, axis=0) > 1e-9) if len(q_all) else np.zeros(0, int)
    revolute = np.asarray(topology.revolute)[moving]
    try:  # a fit driven far from the data can leave an axis at the chart's singularity
        w_T = result.model.frame_poses(q_all) if len(q_all) else None
    except ValueError:
        w_T = None
    found = []
    for group in result.residuals:
        q = q_all[group.sample][:, moving]
        m = len(group.sample)
        explainers = dict(
            zip((topology.joint_names[j] for j in moving), _features(q, revolute), strict=True)
        )
        if w_T is not None and group.frame in topology.frames:
            e = topology.frames.index(group.frame)
            explainers[f"the orientation of {group.frame!r}"] = w_T[
                group.sample, e, :3, :3
            ].reshape(m, 9)
        if not explainers:
            continue
        ones = np.ones((m, 1))
        X = np.concatenate([ones, *explainers.values()], axis=1)
        k = int(np.linalg.matrix_rank(X))
        if m < 3 * k:
            continue
        # per noise component (its rows share a unit): the most structured one
        scores = []
        for name, Y in group.components:
            if np.sqrt(np.mean(Y**2)) < ROUNDING_RMS:
                continue
            explained = _explained(X, Y)
            chance, limit = _chance(k, m, Y.shape[1])
            if explained >= limit:
                scores.append((explained - limit, name, Y, explained, chance))
        if not scores:
            continue
        _, component, Y, explained, chance = max(scores, key=lambda t: t[0])
        alone = {
            name: _explained(np.concatenate([ones, f], axis=1), Y) for name, f in explainers.items()
        }
        best = max(alone, key=alone.get)
        position = group.position_m
        rms = (
            float(np.sqrt(np.mean(np.sum(position**2, axis=1))))
            if position is not None
            else float("nan")
        )
        last = (
            topology.frame_parent[topology.frames.index(group.frame)]
            if group.frame in topology.frames
            else -1
        )
        found.append(
            ResidualStructure(
                group.kind,
                group.frame,
                group.marker,
                m,
                component,
                explained,
                chance,
                best,
                alone[best],
                rms,
                topology.joint_names[last] if last >= 0 else None,
            )
        )
    return tuple(sorted(found, key=lambda s: -s.explained))


def fit_warnings(result: RefineResult, measurements: Measurements) -> tuple[str, ...]:
    """Warnings about a fit that the data contradicts (module docstring), one line each."""
    out = [s.message() for s in residual_structure(result, measurements)]
    out += stated_noise(result, measurements)
    implausible = implausible_noise(result, measurements)
    if implausible:
        out.append(implausible)
    return tuple(out)


def implausible_noise(result: RefineResult, measurements: Measurements) -> str | None:
    """One line when the fit's estimated noise is larger than a tracker, probe or camera
    measures: a length component (a position, a contact's distance) above
    :data:`PLAUSIBLE_NOISE_M` or an angle above :data:`PLAUSIBLE_NOISE_RAD`; the
    "noise" is then a model error (a restricted parameter set included) or wrong data. It
    names the movable joints the observations depend on that ``measurements`` does not
    list (held at zero: a dropped column reads as noise). None otherwise."""
    from kinfw.observations import kind_of

    noise = result.noise
    if not noise.estimated:
        return None
    units = {c.name: c.unit for g in measurements.all_groups() for c in kind_of(g).components}
    limits = {"m": (PLAUSIBLE_NOISE_M, 1e3, "mm"), "rad": (PLAUSIBLE_NOISE_RAD, None, "deg")}
    large = []
    for name, sigma in noise.sigmas:
        limit = limits.get(units.get(name, ""))
        if limit is not None and sigma > limit[0]:
            shown = sigma * limit[1] if limit[1] else math.degrees(sigma)
            large.append(f"{name} {shown:.3g} {limit[2]}")
    if not large:
        return None
    names = result.model.topology.joint_names
    held = [n for n in names if n not in measurements.joint_names]
    why = (
        f"; the joints {held} move these frames but are not in the data's joint_names, "
        "so they are held at zero: if they moved, add their values"
        if held
        else ""
    )
    return (
        f"the estimated noise ({', '.join(large)} per component) is larger than a tracker, "
        "probe or camera measures: the residuals are probably a model error (a wrong "
        f"frame, marker or URDF, or a parameter set too small) or wrong data, not noise{why}"
    )


#: The stated noise is named off by its residuals' only beyond this factor, however many
#: residuals: trackers and probes are rarely specified closer, and the residuals of a
#: restricted model (a prior, fewer parameters) hold some of its model error.
STATED_NOISE_FACTOR = 1.5
#: Standard deviations of the residuals' variance estimate beyond which the stated
#: noise is named off (the median round of the robust estimate is less efficient than a
#: sum of squares: generous).
STATED_NOISE_Z = 5.0

_SHOWN = {"m": (1e3, "mm"), "rad": (180.0 / math.pi, "deg"), "px": (1.0, "px")}


def stated_noise_limit(rows: int) -> float:
    """The factor beyond which a stated sigma is off the one ``rows`` residual rows say:
    :data:`STATED_NOISE_FACTOR`, or :data:`STATED_NOISE_Z` standard deviations of the
    variance estimate of ``rows`` Gaussian rows (``sqrt(2 / rows)`` relative) where that
    is wider (4.6 at 3 rows, 1.71 at 100)."""
    return max(STATED_NOISE_FACTOR, 1.0 + STATED_NOISE_Z * math.sqrt(2.0 / max(rows, 1)))


def stated_noise(result: RefineResult, measurements: Measurements) -> tuple[str, ...]:
    """One line per noise component whose stated sigma is off the one its residuals say
    (:attr:`RefineResult.residual_noise`) by more than :func:`stated_noise_limit` of its
    rows, either way: too large hides real errors behind the prior and the robust loss
    (``--sigma-mm 500`` typed for 0.5 calibrated 3-5 times worse), too small rejects clean
    observations. Empty when the noise was estimated, or every stated sigma fits.

    Parameters
    ----------
    result : RefineResult
        A refinement with a stated noise (``noise`` given).
    measurements : Measurements
        The data it was fitted to (the noise components' units).
    """
    from kinfw.observations import kind_of

    said = result.residual_noise
    if said is None:
        return ()
    rows: dict[str, int] = {}
    for group in result.residuals:
        for name, block in group.components:
            rows[name] = rows.get(name, 0) + block.size
    units = {c.name: c.unit for g in measurements.all_groups() for c in kind_of(g).components}
    out = []
    for name, n in rows.items():
        stated, found = result.noise.of(name), said.of(name)
        ratio = found / stated
        limit = stated_noise_limit(n)
        if 1.0 / limit <= ratio <= limit:
            continue
        scale, unit = _SHOWN.get(units.get(name, ""), (1.0, units.get(name, "")))
        hint = (
            "The stated noise is too large (a value in another unit?): it hides real "
            "errors behind the prior and the robust loss."
            if ratio < 1.0
            else "The stated noise is too small, or the model misses something: clean "
            "observations are down-weighted and rejected."
        )
        out.append(
            f"the {name} residuals say a noise of {found * scale:.3g} {unit}, {ratio:.3g} "
            f"times the stated noise ({stated * scale:.3g} {unit}, {n} rows)\n{hint}"
        )
    return tuple(out)
