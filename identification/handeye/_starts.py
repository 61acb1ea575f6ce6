"""Closed-form starts for hand-eye ``A X = X B`` and robot-world ``A = X B Y``: the
methods by name, every one that succeeds on given poses, and their ranking.

The methods are pure functions of the absolute poses, in the conventions of the solvers
(:func:`~kinfw.identification.handeye.solve_axxb` and
:func:`~kinfw.identification.handeye.solve_axyb`):

:mod:`kinfw.identification.handeye`
    ``A X = X B`` (eye-in-hand): ``A[i] = base_T_hand``, ``B[i] = eye_T_target``,
    ``X = hand_T_eye``, ``Y = base_T_target``; Park & Martin (1994), Andreff, Horaud &
    Espiau (2001), Daniilidis (1999).
:mod:`kinfw.identification.handeye`
    ``A = X B Y`` (robot-world and hand-eye): ``A[i] = camera_T_target``,
    ``B[i] = hand_T_root``, ``X = camera_T_hand``, ``Y = root_T_target``; Shah (2013),
    Li, Wang & Wu (2010).

Every method returns ``(X, Y)`` as ``(4, 4)`` arrays in the input length unit, exactly
equivariant to that unit, or raises :class:`~kinfw.identification.handeye.StartError`
(a ``ValueError``) when its system cannot determine the answer. Here:
``AXXB_STARTS`` and ``AXYB_STARTS`` (the methods by name), :func:`candidate_starts`
(every method that succeeds, after one input check) and :func:`rank_starts` (candidates
scored by their absolute-pose residuals).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import check_transform, rotation_angle
from kinfw.identification.handeye._checks import StartError, check_start_poses
from kinfw.identification.handeye._starts_axxb import (
    AXXB_FROM_MOTIONS,
    andreff_axxb,
    daniilidis_axxb,
    park_axxb,
    prepare_axxb,
)
from kinfw.identification.handeye._starts_axyb import AXYB_FROM_CHECKED, li_axyb, shah_axyb

__all__ = ["AXXB_STARTS", "AXYB_STARTS", "RankedStart", "candidate_starts", "rank_starts"]

log = logging.getLogger(__name__)

Pose = NDArray[np.float64]


#: The closed forms by name, for ``A X = X B`` and ``A = X B Y``.
AXXB_STARTS: Mapping[str, Callable[[ArrayLike, ArrayLike], tuple[Pose, Pose]]] = {
    "park": park_axxb,
    "andreff": andreff_axxb,
    "daniilidis": daniilidis_axxb,
}
AXYB_STARTS: Mapping[str, Callable[[ArrayLike, ArrayLike], tuple[Pose, Pose]]] = {
    "shah": shah_axyb,
    "li": li_axyb,
}


def candidate_starts(
    A: ArrayLike, B: ArrayLike, *, problem: str = "axxb"
) -> dict[str, tuple[Pose, Pose]]:
    """Every closed form of ``problem`` that succeeds on these poses, by name.

    A method that raises :class:`StartError` is left out (logged at debug level); when
    all fail, the first method's error is raised.
    """
    cores: Mapping[str, Callable[..., tuple[Pose, Pose]]]
    if _methods(problem) is AXXB_STARTS:
        prepared = prepare_axxb(A, B, "candidate_starts")
        cores = AXXB_FROM_MOTIONS
    else:
        prepared = check_start_poses(A, B, "candidate_starts")
        cores = AXYB_FROM_CHECKED
    out: dict[str, tuple[Pose, Pose]] = {}
    first: StartError | None = None
    for name, solve in cores.items():
        try:
            out[name] = solve(*prepared)
        except StartError as err:
            log.debug("candidate_starts: %s failed: %s", name, err)
            first = first or err
    if not out and first is not None:
        raise first
    return out


def _methods(problem: str) -> Mapping[str, Callable[[ArrayLike, ArrayLike], tuple[Pose, Pose]]]:
    if problem == "axxb":
        return AXXB_STARTS
    if problem == "axyb":
        return AXYB_STARTS
    raise ValueError(f"problem: expected 'axxb' or 'axyb', got {problem!r}")


@dataclass(frozen=True, slots=True)
class RankedStart:
    """One candidate start and its absolute-pose residual.

    Attributes
    ----------
    name : str
        The candidate's key in the mapping given to :func:`rank_starts`.
    X, Y : ndarray, shape (4, 4)
        The candidate, in the input length unit.
    rms_rotation_rad : float
        RMS over the poses of the rotation residual angle, radians (``A X = X B``: of
        ``Y^-1 A[i] X B[i]``; ``A = X B Y``: of ``A[i]^-1 X B[i] Y``).
    rms_translation : float
        RMS over the poses of the translation residual, input length unit
        (``|t(A[i] X B[i]) - t(Y)|`` in the base frame; ``|t(X B[i] Y) - t(A[i])|`` in the
        camera frame).
    score : float
        ``rms_rotation_rad / median + rms_translation / median``, medians over the
        candidates: unit-free, lower is better.
    """

    name: str
    X: Pose
    Y: Pose
    rms_rotation_rad: float
    rms_translation: float
    score: float


def rank_starts(
    A: ArrayLike,
    B: ArrayLike,
    starts: Mapping[str, tuple[ArrayLike, ArrayLike]],
    *,
    problem: str = "axxb",
) -> tuple[RankedStart, ...]:
    """Order candidate ``(X, Y)`` by their absolute-pose residuals, best first.

    Parameters
    ----------
    A, B : array_like, shape (n, 4, 4)
        The poses, as given to the closed forms of ``problem``.
    starts : mapping of str to (X, Y)
        Candidates, e.g. from :func:`candidate_starts`; ``X`` and ``Y`` of shape (4, 4).
    problem : {"axxb", "axyb"}, keyword-only
        ``"axxb"``: ``A[i] @ X @ B[i] = Y``; ``"axyb"``: ``A[i] = X @ B[i] @ Y``.

    Returns
    -------
    tuple of RankedStart
        Sorted by :attr:`RankedStart.score` (ties keep the mapping's order).

    Notes
    -----
    The rotation RMS (radians) and translation RMS (length) of each candidate are each
    divided by their median over the candidates and added, so neither the length unit
    nor a choice of weight between radians and lengths decides the order. A median of
    zero (all exact) is replaced by the smallest positive value, or 1.
    """
    _methods(problem)
    names = list(starts)
    if not names:
        raise ValueError("rank_starts: starts is empty: give at least one candidate (X, Y)")
    T_A, T_B = check_start_poses(A, B, "rank_starts")
    Xs = check_transform(np.stack([np.asarray(starts[k][0], float) for k in names]), name="X")
    Ys = check_transform(np.stack([np.asarray(starts[k][1], float) for k in names]), name="Y")
    if problem == "axxb":
        predicted = T_A[None] @ Xs[:, None] @ T_B[None]  # (c, n, 4, 4)
        reference = np.broadcast_to(Ys[:, None], predicted.shape)
    else:
        predicted = Xs[:, None] @ T_B[None] @ Ys[:, None]
        reference = np.broadcast_to(T_A[None], predicted.shape)
    rot = rotation_angle(np.swapaxes(reference[..., :3, :3], -1, -2) @ predicted[..., :3, :3])
    trans = np.linalg.norm(predicted[..., :3, 3] - reference[..., :3, 3], axis=-1)
    rms_rot = np.sqrt(np.mean(rot**2, axis=1))
    rms_trans = np.sqrt(np.mean(trans**2, axis=1))
    score = rms_rot / _positive_median(rms_rot) + rms_trans / _positive_median(rms_trans)
    order = np.argsort(score, kind="stable")
    return tuple(
        RankedStart(
            name=names[k],
            X=Xs[k],
            Y=Ys[k],
            rms_rotation_rad=float(rms_rot[k]),
            rms_translation=float(rms_trans[k]),
            score=float(score[k]),
        )
        for k in order
    )


def _positive_median(values: NDArray[np.float64]) -> float:
    med = float(np.median(values))
    if med > 0.0:
        return med
    positive = values[values > 0.0]
    return float(positive.min()) if len(positive) else 1.0
