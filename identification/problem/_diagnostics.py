"""What the fit tells: covariance, identifiability, per-group residuals.

Generic over parameter blocks and observation kinds: the covariance comes from the
whitened Jacobian, residuals are split by each kind's noise components.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.identification.problem._solver import column_norms, negligible_columns, tall_r
from kinfw.measurements import Measurements
from kinfw.model import CPCModel

_ROTATION_FIELDS = ("rot_x", "rot_y", "rot_z")


@dataclass(frozen=True, slots=True)
class Identifiability:
    """What the data determines, from the SVD of the whitened, column-scaled Jacobian.

    Attributes
    ----------
    rank, n_parameters : int
        Identifiable directions, and free parameters (both 0 with ``parameters="none"``
        and nothing else to estimate).
    condition : float
        Largest over smallest singular value among the identifiable directions; inf when
        no direction is identifiable, nan (undefined) when there is no free parameter.
    observability_o1 : float
        Borm & Menq's O1: geometric mean of the singular values over sqrt(rows); 0 when
        a direction is not identifiable, nan (undefined) when there is no free parameter.
    unidentifiable : tuple of (tuple of (owner, field), str)
        Per null direction, the parameters involved and why they are not determined.
    correlations : tuple of (str, str, float)
        Parameter pairs with |rho| > 0.9.
    """

    rank: int
    n_parameters: int
    condition: float
    observability_o1: float
    unidentifiable: tuple[tuple[tuple[tuple[str, str], ...], str], ...]
    correlations: tuple[tuple[str, str, float], ...]


@dataclass(frozen=True, slots=True)
class GroupResiduals:
    """Residuals of one observation group after the fit (measured minus predicted).

    Attributes
    ----------
    kind, frame : str
    marker : str or None
    sample : ndarray of int, shape (m,)
    components : tuple of (str, ndarray (m, rows))
        Per noise component of the kind, its residual rows in SI (m; rad as
        ``sin(angle) u`` for orientations).
    weight : ndarray, shape (m,)
        Robust-loss weight of each observation (1 = full weight).
    downweighted : ndarray of bool, shape (m,)
        Observations beyond the robust loss's threshold (all False for least squares).
    labels : tuple of str, or None
        Per observation, where it is in its sample when a sample has many (an image's
        corners: ``"image LABEL corner ID"``); None for the other kinds.
    """

    kind: str
    frame: str
    marker: str | None
    sample: NDArray[np.int64]
    components: tuple[tuple[str, NDArray[np.float64]], ...]
    weight: NDArray[np.float64]
    downweighted: NDArray[np.bool_]
    labels: tuple[str, ...] | None = None

    def component(self, name: str) -> NDArray[np.float64] | None:
        """The rows of one component, None if the kind has no such component."""
        return dict(self.components).get(name)

    @property
    def position_m(self) -> NDArray[np.float64] | None:
        """Position rows (m, 3), metres (None for a kind without positions)."""
        return self.component("position")

    @property
    def rotation_rad(self) -> NDArray[np.float64] | None:
        """Small-angle orientation error (m, 3), None for a kind without orientation."""
        return self.component("rotation")

    @property
    def rows(self) -> int:
        """Residual rows per observation."""
        return sum(v.shape[1] for _, v in self.components)


@dataclass(frozen=True, slots=True)
class RejectedObservation:
    """An observation excluded from the fit as a gross error (beyond the rejection
    threshold of :func:`kinfw.identification.refine`).

    Attributes
    ----------
    kind, frame : str
        Observation kind and frame (the camera for ``target`` observations).
    marker : str or None
    sample : int
        Index into the data's samples (from 0).
    residuals : tuple of (str, str, float)
        Per noise component of the kind: its name, its unit (``"m"``, ``"rad"``) and the
        size of the residual (measured minus predicted) in that unit: the norm of the
        component's rows, an angle for orientations
        (:meth:`kinfw.observations.NoiseComponent.magnitude`), against the fit it
        is reported with (:attr:`kinfw.identification.RefineResult.rejected`).
    whitened_norm : float
        Norm of its whitened residual (by that fit's noise).
    threshold : float
        The rejection threshold of that norm (the clean residual norm's quantile).
    where : str or None
        Where in the sample, when a sample has many observations of the group: an
        image point's ``"image LABEL corner ID"``; None otherwise.
    clean_tail : bool
        Whether clean data reach this far: beyond the threshold, as 0.1 % of clean
        observations are, but not beyond what that many clean observations reach, and
        among no more of them than their expected count allows (set by
        :func:`kinfw.identification.refine`); False: a gross error.
    """

    kind: str
    frame: str
    marker: str | None
    sample: int
    residuals: tuple[tuple[str, str, float], ...]
    whitened_norm: float
    threshold: float
    where: str | None = None
    clean_tail: bool = False

    @property
    def excess(self) -> float:
        """How far beyond the threshold (``whitened_norm / threshold``); worst first."""
        return self.whitened_norm / self.threshold

    def residual(self, component: str) -> float | None:
        """The residual size of one component (SI), None if the kind has no such one."""
        return next((v for n, _, v in self.residuals if n == component), None)


def observation_labels(grp: Any) -> list[str] | None:
    """Per observation of a residual group, where it is in its sample when a sample has
    many (an image's corners: ``"image LABEL corner ID"``); None for the other kinds."""
    data = getattr(grp, "group", None)
    image, point_id = getattr(data, "image", None), getattr(data, "point_id", None)
    if image is None or point_id is None:
        return None
    return [
        f"image {str(im) or f'of sample {int(s)}'} corner {int(pid)}"
        for im, pid, s in zip(image, point_id, data.sample, strict=True)
    ]


def rejected_observations(
    groups: Sequence[Any],
    r: NDArray,
    noise: Any,
    norms: NDArray,
    threshold: NDArray,
    rejected: NDArray,
) -> tuple[RejectedObservation, ...]:
    """The observations marked in ``rejected`` (per observation, groups in order) as
    :class:`RejectedObservation`, from the whitened residuals ``r`` (group rows first)
    whitened by ``noise``, their ``norms`` and ``threshold`` (per observation)."""
    out, k, o = [], 0, 0
    for grp in groups:
        m, rows = len(grp.sample), grp.rows
        block = r[k : k + m * rows].reshape(m, rows)
        block = block / grp.kind.row_weights(grp.group)[:, None]  # errors, not fit weights
        labels = observation_labels(grp)
        for i in np.flatnonzero(rejected[o : o + m]):
            sizes, c0 = [], 0
            for c in grp.components:
                rows_si = block[i : i + 1, c0 : c0 + c.rows] * noise.sigma(c)
                sizes.append((c.name, c.unit, float(c.magnitude(rows_si)[0])))
                c0 += c.rows
            out.append(
                RejectedObservation(
                    grp.kind.name,
                    grp.frame,
                    grp.marker,
                    int(grp.sample[i]),
                    tuple(sizes),
                    float(norms[o + i]),
                    float(threshold[o + i]),
                    None if labels is None else labels[i],
                )
            )
        k += m * rows
        o += m
    return tuple(out)


#: Why a null direction is not determined when it moves the whole robot rigidly (what
#: the base block would) and the unknowns with it.
WORLD_MOTION = (
    "on these data the robot's part of this direction acts as a rigid motion of the "
    "whole robot (its base), which the unknowns (planes, targets, frames) absorb: "
    "nothing in the data is fixed to the root; the estimate stays at the start (the "
    "nominal URDF) along it"
)


def covariance_and_identifiability(
    Jw: NDArray,
    free: NDArray,
    names: Sequence[tuple[str, str]],
    sigma_hat2: float,
    measurements: Measurements,
    model: CPCModel,
    base_columns: NDArray | Callable[[], NDArray] | None = None,
    robot: NDArray | None = None,
) -> tuple[NDArray, Identifiability]:
    """``sigma_hat2 (J^T J)^+`` on the identifiable subspace, and what the data determines.

    ``Jw`` is the whitened (and robust-weighted) Jacobian (N, P), or only its ``free``
    columns (N, n_free); ``names`` the parameters' ``(owner, field)``; ``model`` gives
    the joints (to explain null directions by joints that never move); ``base_columns``
    (N, 6), the same Jacobian's columns of a rigid motion of the whole robot (the base
    block's, free or not; or a callable returning them, called only when the Jacobian
    is rank deficient), and ``robot`` (P,), which parameters are the robot's: the null
    directions that are such a motion with the unknowns following it come first and are
    named so (:data:`WORLD_MOTION`).

    Notes
    -----
    The singular values and right singular vectors are those of the column-scaled free
    Jacobian ``Js`` (:func:`~kinfw.identification.problem.scaled_columns`), taken from
    the ``R`` of its QR by blocks of rows (:func:`~kinfw.identification.problem.tall_r`:
    ``Js = Q R``, so ``R`` has them too): linear in the rows, with no temporary of the
    Jacobian's size; the rank is the number of singular values above 1e-8 of the
    largest.
    """
    P = len(names)
    Jf = Jw if Jw.shape[1] == int(free.sum()) else Jw[:, free]
    c = column_norms(Jf)
    tiny = negligible_columns(Jf, c)
    c = np.where(tiny, 1.0, c)
    _, s, Vt = np.linalg.svd(tall_r(Jf, np.where(tiny, 0.0, 1.0 / c)), full_matrices=False)
    if len(s) < Jf.shape[1]:  # fewer rows than parameters: the rest is null too
        Q, _ = np.linalg.qr(Vt.T, mode="complete")
        Vt = np.vstack([Vt, Q[:, len(s) :].T])
        s = np.concatenate([s, np.zeros(Jf.shape[1] - len(s))])
    rank = int(np.sum(s > s[0] * 1e-8)) if len(s) and s[0] > 0 else 0
    V = Vt[:rank].T
    cov_free = (V / s[:rank] ** 2) @ V.T / np.outer(c, c) * sigma_hat2
    covariance = np.zeros((P, P))
    idx = np.flatnonzero(free)
    covariance[np.ix_(idx, idx)] = cov_free
    free_names = [tuple(names[k]) for k in idx]
    n_world = 0
    if base_columns is not None and robot is not None and rank < len(s):
        base = base_columns() if callable(base_columns) else base_columns
        Vt, n_world = _world_motions_first(Jf, Vt, c, rank, base, robot[free])
    q_range = (
        np.ptp(measurements.q_of(model.topology.joint_names), axis=0)
        if measurements.n_samples
        else np.zeros(model.n_joints)
    )
    still = {n for n, rng in zip(model.topology.joint_names, q_range, strict=True) if rng < 1e-9}
    unidentifiable = []
    for i, v in enumerate(Vt[rank:]):
        involved = tuple(free_names[k] for k in np.flatnonzero(np.abs(v) > 0.2 * np.abs(v).max()))
        owners = {o for o, _ in involved}
        if i < n_world:
            why = WORLD_MOTION
        elif owners & still:
            why = (
                f"joint(s) {sorted(owners & still)} never move in the data, so their "
                "axes are not observed"
            )
        elif all(f in _ROTATION_FIELDS for _, f in involved):
            why = "only positions of these frames are observed; their orientation is free"
        else:
            why = (
                "these parameters change every prediction in the same way; the data "
                "cannot tell them apart (add motion of the joints involved)"
            )
        unidentifiable.append((involved, why))
    d = np.sqrt(np.clip(np.diag(cov_free), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = cov_free / np.outer(d, d)
    pairs = [
        (abs(rho[a, b]), a, b)
        for a in range(len(d))
        for b in range(a + 1, len(d))
        if d[a] > 0 and d[b] > 0 and abs(rho[a, b]) > 0.9
    ]
    pairs.sort(reverse=True)
    correlations = tuple(
        (":".join(free_names[a]), ":".join(free_names[b]), float(rho[a, b]))
        for _, a, b in pairs[:20]
    )
    # no free parameter: nothing to condition or observe, both undefined (nan)
    if not len(s):
        o1 = condition = float("nan")
    else:
        o1 = float(np.exp(np.mean(np.log(s))) / np.sqrt(Jf.shape[0])) if rank == len(s) else 0.0
        condition = float(s[0] / s[rank - 1]) if rank else float("inf")
    return covariance, Identifiability(
        rank=rank,
        n_parameters=len(free_names),
        condition=condition,
        observability_o1=o1,
        unidentifiable=tuple(unidentifiable),
        correlations=correlations,
    )


def _world_motions_first(
    Jf: NDArray, Vt: NDArray, c: NDArray, rank: int, base_columns: NDArray, robot: NDArray
) -> tuple[NDArray, int]:
    """``Vt`` (rows: right singular vectors of the column-scaled ``Jf``, shape (n, n))
    with its null rows (from ``rank``) rotated so that the rigid motions of the whole
    robot come first, and how many they are.

    A null vector ``v`` (``v / c`` unscaled) is such a motion when the change of the
    robot's parameters (``robot``: mask of the free columns) alone changes the residuals,
    and as a rigid motion of the robot does: ``Jf_robot (v / c)_robot`` nonzero and in
    the span of ``base_columns`` (N, 6), the unknowns absorbing it (``Jf v = 0``). The
    combinations with that property: the null space of the robot parts' residual
    changes projected off the base's span, less the combinations whose robot part
    changes nothing (a redundancy of the robot's own parameters, e.g. a tool turned
    about its probe); relative rank rule 1e-6. It is a statement about these data: a
    common scale whose robot part shifts every contact alike (a plane's offset takes
    it) reads the same; a world motion that the chart follows only with a probe's
    offset re-expressed is not found and keeps the generic explanation.
    """
    null = Vt[rank:]
    M = Jf[:, robot] @ (null / c)[:, robot].T  # (N, m): each null vector's robot part
    Ub, sb, _ = np.linalg.svd(base_columns, full_matrices=False)
    Qb = Ub[:, sb > 1e-9 * sb[0]] if sb.size and sb[0] > 0 else Ub[:, :0]
    scale = max(float(np.linalg.norm(M)), 1e-300)

    def split(A: NDArray) -> tuple[NDArray, NDArray]:
        """Orthonormal rows spanning ``A``'s null space (rule 1e-6 of ``scale``) and
        the rest. Only the right singular vectors are needed: the full left ones of a
        tall ``A`` (N residual rows) would cost N^2 memory and time (9.7 s for 18,000)."""
        _, sa, Wt = np.linalg.svd(A, full_matrices=A.shape[0] < A.shape[1])
        sa = np.concatenate([sa, np.zeros(len(Wt) - len(sa))])
        small = sa <= 1e-6 * scale
        return Wt[small], Wt[~small]

    in_span, rest = split(M - Qb @ (Qb.T @ M))  # (k, m), (m - k, m)
    idle, moving = split(M @ in_span.T)  # within in_span: no effect, base-like effect
    world = moving @ in_span
    if not len(world):
        return Vt, 0
    others = np.vstack([idle @ in_span, rest])
    return np.vstack([Vt[:rank], world @ null, others @ null]), len(world)


def group_residuals(
    groups: Sequence[Any], r: NDArray, w_rows: NDArray, noise: Any, flagged: NDArray
) -> tuple[tuple[GroupResiduals, ...], tuple]:
    """Per-group residuals in SI (measured minus predicted: the kinds' row weights
    divided out), and the observations beyond the robust threshold.

    ``groups`` are the problem's residual groups, ``r`` the whitened residuals (group
    rows first), ``w_rows`` the robust weight of each row, ``flagged`` per observation.
    """
    out, down, k, o = [], [], 0, 0
    for grp in groups:
        m, rows = len(grp.sample), grp.rows
        block = r[k : k + m * rows].reshape(m, rows)
        block = block / grp.kind.row_weights(grp.group)[:, None]  # errors, not fit weights
        weight = w_rows[k : k + m * rows : rows]
        comps, c0 = [], 0
        for c in grp.components:
            comps.append((c.name, block[:, c0 : c0 + c.rows] * noise.sigma(c)))
            c0 += c.rows
        out.append(
            GroupResiduals(
                grp.kind.name,
                grp.frame,
                grp.marker,
                grp.sample,
                tuple(comps),
                weight,
                flagged[o : o + m].copy(),
                None if (labels := observation_labels(grp)) is None else tuple(labels),
            )
        )
        down += [
            (grp.kind.name, grp.frame, int(sm), float(wt))
            for sm, wt, bad in zip(grp.sample, weight, flagged[o : o + m], strict=True)
            if bad
        ]
        k += m * rows
        o += m
    return tuple(out), tuple(down)
