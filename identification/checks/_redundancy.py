"""Enough data for the refinement? Residual rows against free parameters.

A least-squares fit with as many residual rows as free parameters reproduces the data
exactly whatever the noise: zero residuals, an estimated noise of nothing, and an
estimate that is noise. :func:`check_redundancy` refuses such a problem before it is
solved.

Rule. With ``N`` residual rows (per observation, the rows of its kind's noise components:
3 per position, 3 per orientation; 1 per prior term) and
``P`` free parameters after gauge fixing (:attr:`LeastSquaresProblem.free`):

- noise given (``--sigma-mm/--sigma-deg``): ``N >= P``;
- noise estimated: ``N >= P + MIN_DOF_PER_KIND * K`` with ``K`` the noise components
  estimated (positions, orientations when poses or targets are observed, a new kind's
  own): each
  sigma is then estimated from at least :data:`MIN_DOF_PER_KIND` = 10 degrees of freedom
  (a relative precision of about ``sqrt(2 / 10) = 45 %`` at the limit).

A prior (``prior=``) adds one row per robot parameter, so the data then has to determine
the other unknowns and the noise only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from kinfw.identification.problem import LeastSquaresProblem
from kinfw.model import BaseBlock, Block, RobotBlock
from kinfw.observations import DatasetError

#: Residual degrees of freedom required per estimated noise component.
MIN_DOF_PER_KIND = 10


class InsufficientDataError(DatasetError):
    """Too few residuals to determine the free parameters (and the noise) with redundancy."""


@dataclass(frozen=True, slots=True)
class Redundancy:
    """Residual rows against free parameters of one refinement problem.

    Attributes
    ----------
    rows : tuple of (str, int)
        Residual rows per kind: ``"position"``, ``"orientation"``, ``"prior"``.
    n_rows : int
        Their sum.
    n_parameters : int
        Free parameters after gauge fixing.
    by_owner : tuple of (str, int)
        Free parameters per owner, readable (``"camera 'left_camera' mount"``, 6).
    needed : int
        Rows needed (:func:`check_redundancy`'s rule).
    n_samples : int
        Samples of the dataset.
    samples_needed : int
        Samples needed at the dataset's rows per sample.
    """

    rows: tuple[tuple[str, int], ...]
    n_rows: int
    n_parameters: int
    by_owner: tuple[tuple[str, int], ...]
    needed: int
    n_samples: int
    samples_needed: int

    @property
    def sufficient(self) -> bool:
        """True when the rows reach :attr:`needed`."""
        return self.n_rows >= self.needed


_UNKNOWN_LABELS = {
    "target": "target {!r} pose",
    "frame": "measurement frame {!r} pose",
    "marker": "marker {!r} pose",
    "offset": "point {!r} offset",
}


def _owner_label(block: Block, owner: str, cameras: set[str], frames: tuple[str, ...]) -> str:
    key = block.key
    if isinstance(block, BaseBlock):
        return "base frame"
    if not isinstance(block, RobotBlock):  # an unknown of an observation kind
        return _UNKNOWN_LABELS.get(key.kind, key.kind + " {!r}").format(key.name)
    if owner in cameras:
        return f"camera {owner!r} mount"
    if owner in frames:
        return f"frame {owner!r} tool"
    return f"joint {owner!r}"


def redundancy(
    problem: LeastSquaresProblem,
    *,
    noise_given: bool,
    n_samples: int,
    cameras: set[str] | frozenset[str] = frozenset(),
) -> Redundancy:
    """Count residual rows and free parameters of ``problem``.

    Parameters
    ----------
    problem : LeastSquaresProblem
        From :func:`kinfw.identification.problem.build_problem`.
    noise_given : bool
        True when the noise model is given rather than estimated.
    n_samples : int
        Samples of the dataset (for :attr:`Redundancy.samples_needed`).
    cameras : set of str
        Camera frames (``target`` observations), for readable owner names.

    Returns
    -------
    Redundancy
    """
    per_component: dict[str, int] = {}  # residual rows per noise component
    for g in problem.groups:
        for c in g.components:
            label = "orientation" if c.name == "rotation" else c.name
            per_component[label] = per_component.get(label, 0) + c.rows * len(g.sample)
    prior = len(problem.prior_rows)
    rows = tuple((k, n) for k, n in (*per_component.items(), ("prior", prior)) if n)
    data_rows = sum(per_component.values())
    n_rows = data_rows + prior
    P = int(problem.free.sum())
    kinds = sum(1 for n in per_component.values() if n > 0)
    needed = P + (0 if noise_given else MIN_DOF_PER_KIND * kinds)
    frames = problem.model0.topology.frames
    by_owner: dict[str, int] = {}
    for block in problem.blocks:
        for (owner, _), free in zip(block.names, block.free, strict=True):
            if free:
                label = _owner_label(block, owner, set(cameras), frames)
                by_owner[label] = by_owner.get(label, 0) + 1
    per_sample = data_rows / n_samples if n_samples else 0.0
    samples_needed = math.ceil((needed - prior) / per_sample) if per_sample else 0
    return Redundancy(
        rows, n_rows, P, tuple(by_owner.items()), needed, n_samples, max(samples_needed, 0)
    )


def check_redundancy(
    problem: LeastSquaresProblem,
    *,
    noise_given: bool,
    n_samples: int,
    source: str,
    cameras: set[str] | frozenset[str] = frozenset(),
    smaller: tuple[str, LeastSquaresProblem] | None = None,
) -> Redundancy:
    """Refuse a refinement whose residuals cannot determine its parameters with redundancy.

    Parameters
    ----------
    problem : LeastSquaresProblem
    noise_given : bool
    n_samples : int
    source : str
        Dataset name, for the message.
    cameras : set of str
        Camera frames, for readable owner names.
    smaller : (str, LeastSquaresProblem), optional
        A smaller parameter set (its name, e.g. ``"frames"``, and its problem) to
        suggest when it would be determined.

    Returns
    -------
    Redundancy

    Raises
    ------
    InsufficientDataError
        With the rows per kind, the free parameters grouped by owner, the rows and
        samples needed, and the smaller parameter set when it would do.
    """
    r = redundancy(problem, noise_given=noise_given, n_samples=n_samples, cameras=cameras)
    if r.sufficient:
        return r
    rows = ", ".join(f"{n} {k}" for k, n in r.rows)
    owners = ", ".join(f"{label} ({n})" for label, n in r.by_owner)
    why = (
        "noise given: as many rows as parameters"
        if noise_given
        else f"noise estimated: the parameters plus {MIN_DOF_PER_KIND} per estimated noise "
        "component"
    )
    message = (
        f"{source}: too little data to refine: {r.n_rows} residual rows ({rows}) "
        f"for {r.n_parameters} free parameters ({owners}); {r.needed} rows are needed "
        f"({why}), at least {r.samples_needed} samples like these instead of "
        f"{r.n_samples}"
    )
    if smaller is not None:
        name, small = smaller
        s = redundancy(small, noise_given=noise_given, n_samples=n_samples, cameras=cameras)
        if s.sufficient:
            message += (
                f"; or refine fewer parameters: --params {name} "
                f"({s.n_parameters} parameters) is determined by these data"
            )
    raise InsufficientDataError(message)
