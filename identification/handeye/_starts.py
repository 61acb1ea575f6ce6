"""Closed-form starts for hand-eye ``A X = X B`` and robot-world ``A = X B Y``: the one
registry of the methods by name (:data:`START_METHODS`), every one that succeeds on given
poses, and their ranking.

The methods are pure functions of the absolute poses, in the conventions of the solvers
(:func:`~kinfw.identification.handeye.solve_axxb` and
:func:`~kinfw.identification.handeye.solve_axyb`; the frames of
:mod:`kinfw.identification.handeye`), in the papers' letters:

``problem="axxb"``
    ``A X = X B`` (eye-in-hand): ``A[i] = base_T_hand``, ``B[i] = camera_T_target``,
    ``X = hand_T_camera``, ``Y = base_T_target``; Park & Martin (1994), Andreff, Horaud
    & Espiau (2001), Daniilidis (1999).
``problem="axyb"``
    ``A = X B Y`` (robot-world and hand-eye): ``A[i] = camera_T_target``,
    ``B[i] = hand_T_base``, ``X = camera_T_hand``, ``Y = base_T_target``; Shah (2013),
    Li, Wang & Wu (2010).

Every method returns ``(X, Y)`` as ``(4, 4)`` arrays in the input length unit, exactly
equivariant to that unit, or raises :class:`~kinfw.identification.handeye.StartError`
(a ``ValueError``) when its system cannot determine the answer. Here:
:data:`START_METHODS` (:class:`StartMethod` by name), :func:`candidate_starts` (every
method of a problem that succeeds, after one input check) and :func:`rank_starts`
(candidates scored by their absolute-pose residuals).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import check_transform, rotation_angle
from kinfw.identification.handeye._checks import StartError, check_start_poses
from kinfw.identification.handeye._starts_axxb import (
    andreff_axxb,
    andreff_prepared,
    daniilidis_axxb,
    daniilidis_prepared,
    park_axxb,
    park_prepared,
    prepare_axxb,
)
from kinfw.identification.handeye._starts_axyb import li_axyb, li_checked, shah_axyb, shah_checked
from kinfw.plugins import load_plugins

log = logging.getLogger(__name__)

Pose = NDArray[np.float64]

#: The problems and how :func:`candidate_starts` checks their poses once for all methods:
#: ``A X = X B``'s cores take the checked poses and their relative motions, ``A = X B
#: Y``'s the checked poses.
_PREPARE: Mapping[str, Callable[[ArrayLike, ArrayLike, str], tuple[Pose, ...]]] = {
    "axxb": prepare_axxb,
    "axyb": check_start_poses,
}


@dataclass(frozen=True, slots=True)
class StartMethod:
    """One closed-form start.

    Attributes
    ----------
    problem : {"axxb", "axyb"}
        ``"axxb"``: ``A X = X B``; ``"axyb"``: ``A = X B Y`` (module docstring).
    solve : callable
        ``solve(A, B) -> (X, Y)``: the public function (e.g.
        :func:`~kinfw.identification.handeye.park_axxb`), which checks its input.
    solve_prepared : callable or None
        The same on the problem's prepared input
        (:func:`~kinfw.identification.handeye._starts_axxb.prepare_axxb` for ``"axxb"``,
        :func:`~kinfw.identification.handeye._checks.check_start_poses` for ``"axyb"``): what
        :func:`candidate_starts` calls after one check for all methods. None (a start
        added with :func:`register_start` may leave it out): ``solve`` is called on the
        checked poses.
    """

    problem: str
    solve: Callable[[ArrayLike, ArrayLike], tuple[Pose, Pose]]
    solve_prepared: Callable[..., tuple[Pose, Pose]] | None = None


_METHODS: dict[str, StartMethod] = {
    "park": StartMethod("axxb", park_axxb, park_prepared),
    "andreff": StartMethod("axxb", andreff_axxb, andreff_prepared),
    "daniilidis": StartMethod("axxb", daniilidis_axxb, daniilidis_prepared),
    "shah": StartMethod("axyb", shah_axyb, shah_checked),
    "li": StartMethod("axyb", li_axyb, li_checked),
}
_BUILT_IN = frozenset(_METHODS)

#: Every closed-form start by name, in the order :func:`candidate_starts` tries them (a
#: read-only view: add one with :func:`register_start`). The starts of installed plugins
#: (:mod:`kinfw.plugins`) are here once :func:`candidate_starts` or
#: :func:`kinfw.plugins.load_plugins` has run.
START_METHODS: Mapping[str, StartMethod] = MappingProxyType(_METHODS)


def register_start(name: str, method: StartMethod) -> StartMethod:
    """Add a closed-form start under a new ``name``; returns it.

    The solvers then fit from it too whenever they try the closed forms (a first fit
    that is not clean: :func:`~kinfw.identification.handeye.solve_axxb`),
    :func:`candidate_starts` lists it after the built-ins, and ``kinfw handeye --method
    NAME`` fits it beside OpenCV's closed forms
    (:func:`~kinfw.identification.handeye.fit_method`). A ``method`` without
    ``solve_prepared`` is called as ``method.solve(A, B)`` on the checked poses. A plugin
    module registers its starts so when it is imported (:mod:`kinfw.plugins`).

    Raises
    ------
    ValueError
        When ``name`` is taken or ``method.problem`` is not ``"axxb"`` or ``"axyb"``.
    """
    if name in _METHODS:
        raise ValueError(f"register_start: a start named {name!r} is already registered")
    _check_problem(method.problem)
    _METHODS[name] = method
    return method


def unregister_start(name: str) -> None:
    """Remove a start added by :func:`register_start` (the built-ins stay)."""
    if name in _BUILT_IN:
        raise ValueError(f"unregister_start: {name!r} is a built-in start")
    _METHODS.pop(name, None)


def candidate_starts(
    A: ArrayLike, B: ArrayLike, *, problem: str = "axxb"
) -> dict[str, tuple[Pose, Pose]]:
    """Every closed form of ``problem`` that succeeds on these poses, by name.

    ``A``, ``B`` (n, 4, 4) as the closed forms of ``problem`` take them (module
    docstring). A method that raises :class:`StartError` is left out (logged at debug
    level); when all fail, the first method's error is raised. The plugins' starts are
    loaded first (:func:`kinfw.plugins.load_plugins`).
    """
    load_plugins()
    prepared = _PREPARE[_check_problem(problem)](A, B, "candidate_starts")
    out: dict[str, tuple[Pose, Pose]] = {}
    first: StartError | None = None
    for name, method in START_METHODS.items():
        if method.problem != problem:
            continue
        try:
            if method.solve_prepared is None:
                out[name] = method.solve(*prepared[:2])
            else:
                out[name] = method.solve_prepared(*prepared)
        except StartError as err:
            log.debug("candidate_starts: %s failed: %s", name, err)
            first = first or err
    if not out and first is not None:
        raise first
    return out


def _check_problem(problem: str) -> str:
    if problem not in _PREPARE:
        raise ValueError(f"problem: expected 'axxb' or 'axyb', got {problem!r}")
    return problem


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
    _check_problem(problem)
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
