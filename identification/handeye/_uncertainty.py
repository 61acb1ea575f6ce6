"""The uncertainty of a hand-eye transform and the verdict on it (issue 13: never a bare
answer): per-axis and worst-direction 1-sigma from a covariance, and a :class:`Verdict`
(determined, poorly determined, undetermined) against thresholds that do not depend on
the length unit, with a message that says why ("poorly determined (sigma ...)"). Code
reads the enum; the message is for people. The covariances come from
:mod:`kinfw.identification.handeye`.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import skew

#: Verdict thresholds (1-sigma, worst direction): rotation in degrees, translation as a
#: fraction of the RMS camera-target distance (so it does not depend on the unit).
POOR_ROTATION_DEG = 1.0
UNDETERMINED_ROTATION_DEG = 10.0
POOR_TRANSLATION_FRACTION = 0.02
UNDETERMINED_TRANSLATION_FRACTION = 0.2


class Verdict(enum.Enum):
    """How well the data determine a hand-eye transform, from its worst 1-sigma.

    The members are in order of severity; the value is the verdict's wording in
    messages. ``DETERMINED``: rotation within ``POOR_ROTATION_DEG`` and translation
    within ``POOR_TRANSLATION_FRACTION`` of the scene's length; ``POORLY_DETERMINED``:
    beyond those, within ``UNDETERMINED_ROTATION_DEG`` and
    ``UNDETERMINED_TRANSLATION_FRACTION``; ``UNDETERMINED``: beyond those, or a
    covariance that is not finite.
    """

    DETERMINED = "determined"
    POORLY_DETERMINED = "poorly determined"
    UNDETERMINED = "undetermined"

    @property
    def severity(self) -> int:
        """0 for ``DETERMINED``, 1 for ``POORLY_DETERMINED``, 2 for ``UNDETERMINED``."""
        return _SEVERITY[self]


_SEVERITY = {verdict: rank for rank, verdict in enumerate(Verdict)}


@dataclass(frozen=True, slots=True)
class Uncertainty:
    """1-sigma uncertainty of one rigid transform and the verdict on it.

    Attributes
    ----------
    sigma_rotation_deg : ndarray, shape (3,)
        Per axis of the transform's child frame (right perturbation), degrees.
    sigma_translation : ndarray, shape (3,)
        Per axis of the parent frame, input length unit.
    worst_rotation_deg, worst_translation : float
        Along the worst direction (square root of the largest eigenvalue).
    worst_rotation_axis, worst_translation_axis : ndarray, shape (3,)
        Those directions (unit vectors, child and parent frame).
    verdict : Verdict
        The verdict on the worst 1-sigma.
    reason : str
        What makes it so, for people: empty when determined, ``"sigma ... deg, ..."``
        when poorly determined, the undetermined direction and its sigma otherwise.
    """

    sigma_rotation_deg: NDArray[np.float64]
    sigma_translation: NDArray[np.float64]
    worst_rotation_deg: float
    worst_translation: float
    worst_rotation_axis: NDArray[np.float64]
    worst_translation_axis: NDArray[np.float64]
    verdict: Verdict
    reason: str

    @property
    def message(self) -> str:
        """The verdict in words: ``"determined"``, ``"poorly determined (sigma ... deg,
        ...)"`` or ``"undetermined (<worst direction>: sigma ...)"``."""
        return _message(self.verdict, self.reason)


def _message(verdict: Verdict, reason: str) -> str:
    return f"{verdict.value} ({reason})" if reason else verdict.value


def combined_verdict(named: Sequence[tuple[str, Uncertainty]]) -> tuple[Verdict, str]:
    """One verdict for several transforms: the worst one's (the first of equals) and its
    message naming the transform, e.g. ``"poorly determined (camera_T_hand: sigma ...)"``;
    ``"determined"`` when all are.

    Parameters
    ----------
    named : sequence of (str, Uncertainty)
        Each transform's name (e.g. ``"camera_T_hand"``) and uncertainty; not empty.
    """
    worst_name, worst = max(named, key=lambda item: item[1].verdict.severity)
    if worst.verdict is Verdict.DETERMINED:
        return worst.verdict, worst.verdict.value
    return worst.verdict, _message(worst.verdict, f"{worst_name}: {worst.reason}")


def uncertainty(
    covariance: NDArray, length: float, *, unit: str = "", frame: str = "the child frame"
) -> Uncertainty:
    """Per-axis and worst 1-sigma of a transform and the conditioning verdict.

    Parameters
    ----------
    covariance : ndarray, shape (6, 6)
        Of ``(dphi, dt)``: rotation right-perturbed (radians), translation (length).
    length : float
        The scene's length scale (RMS camera-target distance), for the translation
        thresholds ``POOR_TRANSLATION_FRACTION`` and ``UNDETERMINED_TRANSLATION_FRACTION``.
    unit : str
        Name of the length unit for the verdict (e.g. ``"m"``); empty: "input unit".
    frame : str
        Name of the rotation's frame, for the verdict.
    """
    C_r, C_t = covariance[:3, :3], covariance[3:, 3:]
    ev_r, V_r = np.linalg.eigh(0.5 * (C_r + C_r.T))
    ev_t, V_t = np.linalg.eigh(0.5 * (C_t + C_t.T))
    worst_r = float(np.degrees(np.sqrt(max(ev_r[-1], 0.0))))
    worst_t = float(np.sqrt(max(ev_t[-1], 0.0)))
    axis_r, axis_t = V_r[:, -1], V_t[:, -1]
    axis_r = axis_r * np.sign(axis_r[np.argmax(np.abs(axis_r))])
    axis_t = axis_t * np.sign(axis_t[np.argmax(np.abs(axis_t))])
    if unit == "m":
        t_text = f"{1000.0 * worst_t:.3g} mm"
    else:
        t_text = f"{worst_t:.3g} {unit or 'input length units'}"
    finite = np.all(np.isfinite(covariance))
    if not finite or worst_r > UNDETERMINED_ROTATION_DEG:
        verdict = Verdict.UNDETERMINED
        reason = (
            f"rotation about {np.round(axis_r, 3).tolist()} in {frame}: sigma {worst_r:.3g} deg"
        )
    elif worst_t > UNDETERMINED_TRANSLATION_FRACTION * length:
        verdict = Verdict.UNDETERMINED
        reason = f"translation along {np.round(axis_t, 3).tolist()}: sigma {t_text}"
    elif worst_r > POOR_ROTATION_DEG or worst_t > POOR_TRANSLATION_FRACTION * length:
        verdict = Verdict.POORLY_DETERMINED
        reason = f"sigma {worst_r:.3g} deg, {t_text}"
    else:
        verdict, reason = Verdict.DETERMINED, ""
    return Uncertainty(
        sigma_rotation_deg=np.degrees(np.sqrt(np.maximum(np.diag(C_r), 0.0))),
        sigma_translation=np.sqrt(np.maximum(np.diag(C_t), 0.0)),
        worst_rotation_deg=worst_r,
        worst_translation=worst_t,
        worst_rotation_axis=axis_r,
        worst_translation_axis=axis_t,
        verdict=verdict,
        reason=reason,
    )


def inverse_covariance_map(P: NDArray) -> NDArray:
    """Linear map (6, 6) from ``(dphi_P, dt_P)`` to the same coordinates of ``P^-1``.

    ``P^-1 = (R_P^T, -R_P^T t_P)``: ``dphi -> -R_P dphi``,
    ``dt -> [t_X]_x dphi - R_P^T dt`` with ``t_X = -R_P^T t_P``.
    """
    R_P, t_P = P[:3, :3], P[:3, 3]
    t_X = -R_P.T @ t_P
    G = np.zeros((6, 6))
    G[:3, :3] = -R_P
    G[3:, :3] = skew(t_X)
    G[3:, 3:] = -R_P.T
    return G
