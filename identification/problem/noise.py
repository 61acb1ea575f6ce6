"""The noise model and its estimation from residuals, generic over noise components.

Each observation kind splits its residual rows into noise components
(:class:`kinfw.observations.NoiseComponent`: ``position`` 3 rows in m, ``rotation`` 3
rows in rad, or a kind's own). :class:`NoiseModel` holds one sigma per component name;
:func:`estimate_noise` rescales each from the whitened residuals (variance components).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw.observations.base import NoiseComponent

__all__ = ["NoiseModel", "estimate_noise"]

#: The component whose sigma a noise model uses for a component it does not name, by unit.
DEFAULT_COMPONENT = {"m": "position", "rad": "rotation"}


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
    """

    sigmas: tuple[tuple[str, float], ...]
    estimated: bool

    def __init__(self, position_m: float | None = None, rotation_rad: float | None = None,
                 estimated: bool = False, *, sigmas: Mapping[str, float] | None = None
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
            raise KeyError(f"noise: no sigma for component {component.name!r} (unit "
                           f"{component.unit}); give it in NoiseModel(sigmas=...)")
        return values[fallback]


def _chi2_constants(dof: int) -> tuple[float, float, float]:
    """Chi-square(dof): median, 99.9 % quantile, and the mean below that quantile / dof
    (the trimmed second moment), from scipy.stats for dof 1..6, else Wilson-Hilferty."""
    table = {
        1: (0.454936423119572, 10.827566170662733, 0.9882925078281297),
        2: (1.386294361119891, 13.815510557964274, 0.9930853300510688),
        3: (2.3659738843753377, 16.26623619623813, 0.9948712017073625),
        4: (3.3566939800333224, 18.46682695290317, 0.9958302639735415),
        5: (4.351460191095526, 20.515005652432873, 0.9964380686811932),
        6: (5.348120627447118, 22.457744484825323, 0.9968619892255411),
    }
    if dof in table:
        return table[dof]
    c = 2.0 / (9.0 * dof)
    return dof * (1.0 - c) ** 3, dof * (1.0 - c + 3.090232 * np.sqrt(c)) ** 3, 1.0


def estimate_noise(r: NDArray, groups: Sequence[Any], sigma: NoiseModel,
                   leverage: NDArray, *, robust: bool = False, first: bool = True
                   ) -> NoiseModel:
    """Rescale each noise component's sigma from the whitened residuals.

    ``groups`` are the problem's residual groups (``sample``, ``rows``, ``components``),
    in the order of the rows of ``r``; ``leverage`` is the diagonal of the hat matrix
    ``J (J^T J)^+ J^T`` (one per row): a component's residual degrees of freedom are its
    rows minus its leverages, so a component the fit follows closely (orientations,
    here) is not underestimated.

    Least squares: variance components (each component's sum of squares over its degrees
    of freedom). With a robust loss: first the median of the per-observation squared
    norms over the chi-square(rows) median, which gross outliers do not inflate; then
    (``first=False``) the second moment of the observations inside the 99.9 % quantile,
    which depends on the noise's shape only through that tail.
    """
    blocks: dict[str, list[NDArray]] = {}
    hats: dict[str, list[NDArray]] = {}
    comps: dict[str, NoiseComponent] = {}
    k = 0
    for grp in groups:
        m, rows = len(grp.sample), grp.rows
        block = r[k : k + m * rows].reshape(m, rows)
        h = leverage[k : k + m * rows].reshape(m, rows)
        c0 = 0
        for c in grp.components:
            if comps.setdefault(c.name, c).rows != c.rows:
                raise ValueError(f"noise component {c.name!r} has {c.rows} rows in one kind "
                                 f"and {comps[c.name].rows} in another")
            blocks.setdefault(c.name, []).append(block[:, c0 : c0 + c.rows])
            hats.setdefault(c.name, []).append(h[:, c0 : c0 + c.rows])
            c0 += c.rows
        k += m * rows

    def factor(name: str) -> float:
        block, hat = np.concatenate(blocks[name]), np.concatenate(hats[name])
        dof = comps[name].rows
        median, q999, trimmed = _chi2_constants(dof)
        share = max(1.0 - hat.sum() / block.size, 1e-3)
        s2 = np.sum(block**2, axis=1)
        if robust and first:
            return float(np.sqrt(np.median(s2) / (median * share)))
        if robust:
            inside = s2[s2 < q999]
            return float(np.sqrt(np.mean(inside) / (dof * trimmed * share))) \
                if len(inside) else 1.0
        return float(np.sqrt(np.sum(s2) / (block.size * share)))

    values = dict(sigma.sigmas)
    for name, c in comps.items():
        floor = 1e-15 if c.unit == "rad" else 1e-12
        values[name] = float(max(sigma.sigma(c) * factor(name), floor))
    return NoiseModel(estimated=True, sigmas=values)
