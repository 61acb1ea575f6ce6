"""The noise model and its estimation from residuals, generic over noise components.

Each observation kind splits its residual rows into noise components
(:class:`kinfw.observations.NoiseComponent`: ``position`` 3 rows in m, ``rotation`` 3
rows in rad, or a kind's own). :class:`NoiseModel` holds one sigma per component name;
:func:`estimate_noise` rescales each from the whitened residuals (variance components).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.observations import NoiseComponent

#: The component whose sigma a noise model uses for a component it does not name, by unit.
DEFAULT_COMPONENT = {"m": "position", "rad": "rotation", "px": "pixel"}


@dataclass(frozen=True, slots=True, init=False)
class NoiseModel:
    """Measurement noise used to whiten the residuals: one sigma per noise component.

    ``NoiseModel(position_m, rotation_rad)`` gives the two built-in components;
    ``sigmas={"distance": 1e-4}`` adds (or overrides) others. A component the model does
    not name uses the sigma of ``position`` (unit m) or ``rotation`` (unit rad).

    Attributes
    ----------
    sigmas : tuple of (str, float)
        Standard deviation of each component's rows (SI: m, or rad small-angle).
    estimated : bool
        True when estimated from the residuals rather than given.

    Notes
    -----
    The robust estimate (``loss`` huber or cauchy) assumes each component's noise model
    (:attr:`kinfw.observations.NoiseComponent.distribution`): for the built-in kinds
    that of Shih et al. (1992, Fig. 10), as :func:`kinfw.simulation.perturb_poses`
    draws it: each position component ``N(0, position_m)``; an orientation error is a
    rotation by an angle ``N(0, sqrt(3) rotation_rad)`` about a uniformly random axis,
    whose three components have deviation ``rotation_rad`` each without being Gaussian.
    Least squares' estimate assumes only the variances.
    """

    sigmas: tuple[tuple[str, float], ...]
    estimated: bool

    def __init__(
        self,
        position_m: float | None = None,
        rotation_rad: float | None = None,
        estimated: bool = False,
        *,
        sigmas: Mapping[str, float] | None = None,
    ) -> None:
        values: dict[str, float] = {}
        if position_m is not None:
            values["position"] = float(position_m)
        if rotation_rad is not None:
            values["rotation"] = float(rotation_rad)
        values.update({k: float(v) for k, v in (sigmas or {}).items()})
        object.__setattr__(self, "sigmas", tuple(values.items()))
        object.__setattr__(self, "estimated", bool(estimated))

    def of(self, name: str) -> float:
        """The sigma of a component by name (KeyError if the model does not name it)."""
        return dict(self.sigmas)[name]

    @property
    def position_m(self) -> float:
        """Standard deviation of each position component, metres."""
        return self.of("position")

    @property
    def rotation_rad(self) -> float:
        """Standard deviation of each orientation component (small-angle), radians."""
        return self.of("rotation")

    def sigma(self, component: NoiseComponent) -> float:
        """The sigma of a component's rows: its own, else its unit's default."""
        values = dict(self.sigmas)
        if component.name in values:
            return values[component.name]
        fallback = DEFAULT_COMPONENT.get(component.unit)
        if fallback is None or fallback not in values:
            raise KeyError(
                f"noise: no sigma for component {component.name!r} (unit "
                f"{component.unit}); give it in NoiseModel(sigmas=...)"
            )
        return values[fallback]


def chi2_cdf(x: float, dof: int) -> float:
    """CDF of the chi-square distribution, closed form for any positive integer ``dof``.

    ``F_1(x) = erf(sqrt(x / 2))``, ``F_2(x) = 1 - exp(-x / 2)`` and
    ``F_{k+2}(x) = F_k(x) - (x / 2)^(k / 2) exp(-x / 2) / Gamma(k / 2 + 1)``.
    """
    if dof < 1:
        raise ValueError(f"dof: expected a positive integer, got {dof}")
    if x <= 0.0:
        return 0.0
    F = math.erf(math.sqrt(x / 2.0)) if dof % 2 else 1.0 - math.exp(-x / 2.0)
    for k in range(2 - dof % 2, dof, 2):
        F -= (x / 2.0) ** (k / 2.0) * math.exp(-x / 2.0) / math.gamma(k / 2.0 + 1.0)
    return F


def quantile(cdf: Callable[[float], float], p: float) -> float:
    """Quantile of a distribution on [0, inf) from its CDF, by bisection."""
    lo, hi = 0.0, 1.0
    while cdf(hi) < p:
        hi *= 2.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < p else (lo, mid)
    return 0.5 * (lo + hi)


def norm2_cdf(components: Sequence[NoiseComponent]) -> Callable[[float], float]:
    """CDF of one observation's whitened squared residual norm under its components'
    noise models: ``chi2(g)`` for ``g`` Gaussian rows, plus ``3 chi2(1)`` for an
    ``"angle"`` component. A pose (position + orientation): ``S = X + 3 t^2``,
    ``P(S <= s) = int_0^sqrt(s/3) 2 phi(t) F_3(s - 3 t^2) dt`` (Gauss-Legendre, 64 nodes).
    More than one angle component falls back to ``chi2(rows)``.
    """
    gaussian = sum(c.rows for c in components if c.distribution == "gaussian")
    angles = sum(1 for c in components if c.distribution == "angle")
    if angles == 0:
        return lambda s: chi2_cdf(s, gaussian)
    if angles > 1:
        rows = sum(c.rows for c in components)
        return lambda s: chi2_cdf(s, rows)
    if gaussian == 0:
        return lambda s: chi2_cdf(s / 3.0, 1)
    nodes, weights = np.polynomial.legendre.leggauss(64)

    def cdf(s: float) -> float:
        if s <= 0.0:
            return 0.0
        b = math.sqrt(s / 3.0)
        t = 0.5 * b * (nodes + 1.0)
        f = np.array([chi2_cdf(s - 3.0 * ti * ti, gaussian) for ti in t])
        return float(
            0.5 * b * np.sum(weights * 2.0 * np.exp(-0.5 * t * t) / math.sqrt(2.0 * math.pi) * f)
        )

    return cdf


@dataclass(frozen=True, slots=True)
class NoiseShape:
    """Distribution of one component's whitened squared residual norm ``X`` per
    observation (``rows`` rows of unit variance): the constants of the robust estimate.

    Attributes
    ----------
    median : float
        Median of ``X``.
    cut : float
        Its 99.9 % quantile: the trimmed second moment keeps ``X < cut``.
    trimmed : float
        ``E[X | X < cut] / rows``: the trimmed second moment per row, relative to the
        untrimmed one (1).
    """

    median: float
    cut: float
    trimmed: float


@functools.cache
def _shape(rows: int, distribution: str) -> NoiseShape:
    if distribution == "angle":
        # X = 3 chi2(1): E[X | X < c] / 3 = E[Y | Y < c/3] = F_3(c/3) / F_1(c/3)
        cut = 3.0 * quantile(lambda x: chi2_cdf(x, 1), 0.999)
        return NoiseShape(
            3.0 * quantile(lambda x: chi2_cdf(x, 1), 0.5),
            cut,
            chi2_cdf(cut / 3.0, 3) / chi2_cdf(cut / 3.0, 1),
        )
    # X ~ chi2(k): E[X; X < c] = k F_{k+2}(c), so E[X | X < c] / k = F_{k+2}(c) / F_k(c)
    cut = quantile(lambda x: chi2_cdf(x, rows), 0.999)
    return NoiseShape(
        quantile(lambda x: chi2_cdf(x, rows), 0.5),
        cut,
        chi2_cdf(cut, rows + 2) / chi2_cdf(cut, rows),
    )


def noise_shape(component: NoiseComponent) -> NoiseShape:
    """The robust constants of a noise component (closed forms through chi-square CDFs).

    Positions (``"gaussian"``, 3 rows): ``X ~ chi2(3)``. Orientations (``"angle"``): a
    rotation vector ``theta u``, ``theta ~ N(0, s)``, ``u`` uniform on the sphere,
    whitened by its per-component deviation ``s / sqrt(3)``: ``X = 3 chi2(1)``, whose
    median is 1.365 against chi2(3)'s 2.366.
    """
    return _shape(component.rows, component.distribution)


def estimate_noise(
    r: NDArray,
    groups: Sequence[Any],
    sigma: NoiseModel,
    leverage: NDArray | Mapping[str, float],
    *,
    robust: bool = False,
    first: bool = True,
) -> NoiseModel:
    """Rescale each noise component's sigma from the whitened residuals.

    Parameters
    ----------
    r : ndarray, shape (R,)
        Whitened residuals (by ``sigma``) of every observation, groups in order.
    groups : sequence
        The problem's residual groups (``sample``, ``rows``, ``components``), in the
        order of the rows of ``r``.
    sigma : NoiseModel
        The whitening of ``r``.
    leverage : ndarray, shape (R,), or mapping of str to float
        Diagonal of the hat matrix ``J (J^T J)^+ J^T`` (one per row), or per noise
        component (by name) the sum of its rows' (only the sums enter:
        :func:`~kinfw.identification.problem.leverage_sums`): a component's residual
        degrees of freedom are its rows minus its leverages, so a component the fit
        follows closely (orientations, here) is not underestimated.
    robust : bool
        False: least squares' variance components. True: the robust estimate below.
    first : bool
        Robust only: the first round (median) rather than a later one (trimmed moment).

    Returns
    -------
    NoiseModel
        ``estimated=True``; one sigma per component seen, the others kept.

    Notes
    -----
    Per observation and component, ``X`` is the squared norm of the whitened rows; its
    distribution under the component's noise model is :func:`noise_shape` (positions
    ``chi2(3)``; orientations, an angle about a uniformly random axis, ``3 chi2(1)``).

    Least squares: variance components, ``sigma_new^2 = sigma^2 sum(X) / (rows n share)``,
    with ``share`` the component's mean ``1 - leverage``; consistent for any shape.

    Robust, first round: ``sigma_new^2 = sigma^2 median(X) / (share median_model)``,
    which gross outliers do not inflate. Later rounds: the trimmed second moment,
    ``sigma_new^2 = sigma^2 mean(X | X < cut) / (rows share trimmed)`` with ``cut`` the
    model's 99.9 % quantile; its fixed point is the true sigma under the model and gross
    outliers (beyond ``cut``) do not enter it. For orientations whose components are
    instead independent Gaussians the estimate is 0.6 % high after the trimmed rounds.
    """
    blocks: dict[str, list[NDArray]] = {}
    hats: dict[str, list[NDArray]] = {}
    comps: dict[str, NoiseComponent] = {}
    k = 0
    for grp in groups:
        m, rows = len(grp.sample), grp.rows
        block = r[k : k + m * rows].reshape(m, rows)
        h = None if isinstance(leverage, Mapping) else leverage[k : k + m * rows].reshape(m, rows)
        c0 = 0
        for c in grp.components:
            if comps.setdefault(c.name, c).rows != c.rows:
                raise ValueError(
                    f"noise component {c.name!r} has {c.rows} rows in one kind "
                    f"and {comps[c.name].rows} in another"
                )
            blocks.setdefault(c.name, []).append(block[:, c0 : c0 + c.rows])
            if h is not None:
                hats.setdefault(c.name, []).append(h[:, c0 : c0 + c.rows])
            c0 += c.rows
        k += m * rows

    def factor(name: str) -> float:
        block = np.concatenate(blocks[name])
        hat = leverage[name] if isinstance(leverage, Mapping) else np.concatenate(hats[name]).sum()
        shape = noise_shape(comps[name])
        share = max(1.0 - hat / block.size, 1e-3)
        s2 = np.sum(block**2, axis=1)
        if robust and first:
            return float(np.sqrt(np.median(s2) / (shape.median * share)))
        if robust:
            inside = s2[s2 < shape.cut]
            return (
                float(np.sqrt(np.mean(inside) / (comps[name].rows * shape.trimmed * share)))
                if len(inside)
                else 1.0
            )
        return float(np.sqrt(np.sum(s2) / (block.size * share)))

    values = dict(sigma.sigmas)
    for name, c in comps.items():
        # noise-free data: ~100 times the rounding of a prediction (1e-13 m of a metre-
        # sized robot, 1e-16 rad, 1e-13-1e-11 px), so that rounding whitens to ~0.01 and
        # cannot tell directions apart that the data leave undetermined
        floor = {"rad": 1e-14, "px": 1e-9}.get(c.unit, 1e-11)
        values[name] = float(max(sigma.sigma(c) * factor(name), floor))
    return NoiseModel(estimated=True, sigmas=values)
