"""Gaussian priors by parameter group: :class:`PriorScales`, one sigma per group and unit.

A calibration's deviations from the nominal URDF are not all alike: an encoder zero is
often off by a degree where a machined length is right to a tenth of a millimetre, and a
camera mount in a URDF is often a guess. One length and one angle sigma for every
deviation (kinfw until issue 37, FIGAROH's ``map`` default) shrinks them all alike;
FIGAROH's best automatic setting (``map_cv`` with ``cv_per_group``) chooses a scale per
group. The groups (:data:`PRIOR_GROUPS`, :func:`prior_groups`):

- ``"offsets"``: the joint zero offsets (rad; m for a prismatic joint);
- ``"axes"``: the CPC chart's axis tilts ``b_tilt_1/2`` (rad), a joint axis' direction
  (Zhuang et al. 1992, eq. 5: the axis' ``b_x, b_y``);
- ``"positions"``: the CPC chart's line offsets ``l_x/l_y`` (m), a joint axis' position;
- ``"base"``: the base frame before the chain (rad, m), free in ``"frames"`` and
  ``"offsets"``;
- ``"tools"``: the end frames' tools (rad, m): the mounts of cameras and marker bodies, the
  flange's tool frame (no prior by default: a URDF's mount is often a rough guess);
- ``"intrinsics"``: freed camera intrinsics (fx, fy, cx, cy px; distortion unitless),
  centred on the camera file's;
- a model spec block's name (``"compliance"``, ``"gear-scale"``...): its values in their
  unit, centred on the rigid URDF model (zero).

Unknowns the URDF holds no value for (an external measurement frame, a target, a marker
offset or a plane found from the data) have no prior: there is no nominal to centre one
on, and a prior centred on the data's own start estimate is not prior knowledge.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from kinfw.model._blocks import (
    BaseBlock,
    Block,
    CPCBlock,
    RobotBlock,
    SpecBlock,
    ZeroOffsetBlock,
)

#: The groups of the robot's own geometry, in the order reports list them (model spec
#: blocks follow under their own names).
PRIOR_GROUPS = ("offsets", "axes", "positions", "base", "tools", "intrinsics")

#: Groups of the joints' geometry: :meth:`PriorScales.sigma_m` / ``sigma_rad`` (the
#: plausibility bound of a change) are their loosest sigmas.
JOINT_GROUPS = ("offsets", "axes", "positions")

#: Display unit and factor per SI unit (sigmas are kept in SI units).
_DISPLAY = {"m": ("mm", 1e3), "rad": ("deg", math.degrees(1.0))}


@dataclass(frozen=True, slots=True)
class PriorScale:
    """One group's prior sigma.

    Attributes
    ----------
    group : str
        One of :data:`PRIOR_GROUPS` or a model spec block's name.
    unit : str
        The SI unit of the entries it applies to (``"m"``, ``"rad"``, ``"px"``...).
    sigma : float
        Standard deviation of a deviation from the nominal, in ``unit``; > 0.
    """

    group: str
    unit: str
    sigma: float

    def __post_init__(self) -> None:
        if not (
            isinstance(self.sigma, (int, float)) and self.sigma > 0 and math.isfinite(self.sigma)
        ):
            raise ValueError(
                f"prior {self.group} ({self.unit}): expected a positive finite sigma, "
                f"got {self.sigma!r}"
            )

    @property
    def text(self) -> str:
        """E.g. ``"offsets 0.5 deg"``, ``"positions 0.3 mm"``, ``"intrinsics 2 px"``."""
        unit, factor = _DISPLAY.get(self.unit, (self.unit, 1.0))
        return f"{self.group} {factor * self.sigma:.3g} {unit}"

    @property
    def option(self) -> str:
        """The text of ``--prior`` that gives it (:meth:`parse`): ``"offsets=0.5deg"``."""
        unit, factor = _DISPLAY.get(self.unit, (self.unit, 1.0))
        return f"{self.group}={factor * self.sigma:.4g}{unit}"

    @classmethod
    def parse(cls, text: str) -> PriorScale:
        """``GROUP=VALUE UNIT`` (``"offsets=0.5deg"``, ``"positions=0.2mm"``,
        ``"intrinsics=2px"``, ``"compliance=1e-4rad/Nm"``): lengths in mm or m, angles in
        deg or rad, other units as the block states them. A ValueError saying the form
        otherwise."""
        group, sep, value = text.partition("=")
        match = re.fullmatch(r"\s*([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)\s*(\S.*?)?\s*", value)
        try:
            sigma, unit = float(match[1]), (match[2] or "")
        except (TypeError, ValueError):
            sigma, unit = math.nan, ""
        if not sep or not group.strip() or not unit or not math.isfinite(sigma):
            raise ValueError(
                "prior: expected GROUP=VALUE UNIT, e.g. offsets=0.5deg, positions=0.2mm "
                f"(groups: {', '.join(PRIOR_GROUPS)} or a model block's name), got {text!r}"
            )
        si = {"mm": ("m", 1e-3), "m": ("m", 1.0), "deg": ("rad", math.radians(1.0))}
        si_unit, factor = si.get(unit, (unit, 1.0))
        return cls(group.strip(), si_unit, sigma * factor)


@dataclass(frozen=True, slots=True)
class PriorScales:
    """A Gaussian prior on the robot's deviations from the nominal, one sigma per group
    and unit (the module docstring); a group absent has no prior.

    Attributes
    ----------
    scales : tuple of PriorScale
        At most one per ``(group, unit)``.
    how : str
        How the sigmas were set: ``"given"``, or by the data (``"leave-one-out"``).
    """

    scales: tuple[PriorScale, ...] = ()
    how: str = "given"

    def __post_init__(self) -> None:
        keys = [(s.group, s.unit) for s in self.scales]
        if len(set(keys)) != len(keys):
            raise ValueError(f"prior: a group and unit given twice in {keys}")

    @classmethod
    def uniform(cls, sigma_m: float, sigma_rad: float) -> PriorScales:
        """One length and one angle sigma for the joints' geometry and the base (zero
        offsets, axes, positions, base): the prior of ``--prior-mm`` / ``--prior-deg``;
        the tools stay free."""
        return cls(
            tuple(
                PriorScale(g, u, s)
                for g in ("offsets", "axes", "positions", "base")
                for u, s in (("m", sigma_m), ("rad", sigma_rad))
                if (g, u) not in (("axes", "m"), ("positions", "rad"))
            )
        )

    @staticmethod
    def of(prior: PriorScales | tuple[float, float] | None) -> PriorScales | None:
        """``prior`` as PriorScales: a pair ``(sigma_m, sigma_rad)`` is
        :meth:`uniform`; None stays None."""
        if prior is None or isinstance(prior, PriorScales):
            return prior
        try:
            sigma_m, sigma_rad = (float(v) for v in prior)
        except (TypeError, ValueError):
            raise TypeError(
                f"prior: expected PriorScales or (sigma_m, sigma_rad), got {prior!r}"
            ) from None
        return PriorScales.uniform(sigma_m, sigma_rad)

    def sigma(self, group: str | None, unit: str) -> float:
        """The sigma of ``group`` in ``unit`` (inf: no prior)."""
        for s in self.scales:
            if (s.group, s.unit) == (group, unit):
                return s.sigma
        return math.inf

    def with_sigmas(self, sigmas: dict[tuple[str, str], float], how: str) -> PriorScales:
        """These scales with ``sigmas`` by ``(group, unit)`` set (inf: removed)."""
        kept = [s for s in self.scales if (s.group, s.unit) not in sigmas]
        new = [PriorScale(g, u, float(v)) for (g, u), v in sigmas.items() if math.isfinite(v)]
        return replace(self, scales=tuple(sorted((*kept, *new), key=_order)), how=how)

    @property
    def sigma_m(self) -> float:
        """The loosest length sigma of the joints' geometry (:data:`JOINT_GROUPS`), m;
        0 without one."""
        return self._loosest("m")

    @property
    def sigma_rad(self) -> float:
        """The loosest angle sigma of the joints' geometry, rad; 0 without one."""
        return self._loosest("rad")

    def _loosest(self, unit: str) -> float:
        return max(
            (s.sigma for s in self.scales if s.unit == unit and s.group in JOINT_GROUPS),
            default=0.0,
        )

    @property
    def is_uniform(self) -> bool:
        """Whether this is :meth:`uniform` of its loosest sigmas (``--prior-mm``/``-deg``)."""
        m, rad = self.sigma_m, self.sigma_rad
        return m > 0 and rad > 0 and set(self.scales) == set(PriorScales.uniform(m, rad).scales)

    @property
    def label(self) -> str:
        """``"prior 1 mm / 0.115 deg"`` for a uniform prior, else the groups
        (``"prior offsets 0.5 deg, axes 0.01 deg, positions 0.2 mm"``)."""
        if self.is_uniform:
            return f"prior {1e3 * self.sigma_m:.3g} mm / {math.degrees(self.sigma_rad):.3g} deg"
        return "prior " + ", ".join(s.text for s in self.scales)

    @property
    def options(self) -> str:
        """The command-line options that give this prior (``--prior-mm 1 --prior-deg
        0.1`` for a uniform one, else ``--prior GROUP=VALUE`` per group)."""
        m, rad = self.sigma_m, self.sigma_rad
        if self.is_uniform:
            return f"--prior-mm {1e3 * m:.4g} --prior-deg {math.degrees(rad):.4g}"
        return " ".join(f"--prior {s.option}" for s in self.scales)

    def to_list(self) -> list[dict]:
        """``[{"group", "unit", "sigma"}]`` in SI units (a sidecar's)."""
        return [{"group": s.group, "unit": s.unit, "sigma": s.sigma} for s in self.scales]

    @classmethod
    def from_list(cls, entries: list[dict], how: str = "given") -> PriorScales:
        """Inverse of :meth:`to_list`."""
        return cls(
            tuple(PriorScale(str(e["group"]), str(e["unit"]), float(e["sigma"])) for e in entries),
            how,
        )


def _order(s: PriorScale) -> tuple[int, str, str]:
    """Report order: :data:`PRIOR_GROUPS`, then the model spec blocks by name."""
    rank = PRIOR_GROUPS.index(s.group) if s.group in PRIOR_GROUPS else len(PRIOR_GROUPS)
    return rank, s.group, s.unit


def _block_prior_groups(block: Block, joint_entries: int) -> tuple[str | None, ...]:
    """The prior group of each entry of ``block`` (None: no prior): the module
    docstring's. ``joint_entries`` is the CPC chart's count of joint entries, before its
    end frames' tools."""
    if isinstance(block, CPCBlock):
        return tuple(
            "tools" if i >= joint_entries else ("axes" if f.startswith("b_tilt") else "positions")
            for i, f in enumerate(block.fields)
        )
    if isinstance(block, ZeroOffsetBlock):
        return ("offsets",) * block.size
    if isinstance(block, BaseBlock):
        return ("base",) * block.size
    if isinstance(block, SpecBlock):
        return (block.block_name,) * block.size
    if isinstance(block, RobotBlock):  # an application's block (a test's gear scale)
        return (block.key.kind,) * block.size
    if block.key.kind == "intrinsics":
        return ("intrinsics",) * block.size
    return (None,) * block.size


def prior_groups(
    blocks: tuple[Block, ...], joint_entries: int
) -> tuple[tuple[str | None, str], ...]:
    """``(group, unit)`` of every parameter of ``blocks`` in order (:func:`_block_prior_groups`)."""
    return tuple(
        (g, u)
        for b in blocks
        for g, u in zip(_block_prior_groups(b, joint_entries), b.units, strict=True)
    )


def prior_sigmas(
    groups: tuple[tuple[str | None, str], ...], prior: PriorScales | None
) -> NDArray[np.float64]:
    """Per parameter (P,) the sigma of ``prior`` for its ``(group, unit)`` (inf: none)."""
    if prior is None:
        return np.full(len(groups), np.inf)
    return np.array([prior.sigma(g, u) for g, u in groups], dtype=float)


def spec_prior_mean(blocks: tuple[Block, ...], size: int) -> NDArray[np.float64]:
    """The prior mean (P,) of the model spec blocks' entries: the rigid model, ``-start``
    in their chart (``value = start + d``); zero elsewhere."""
    mean = np.zeros(size)
    k = 0
    for b in blocks:
        if isinstance(b, SpecBlock):
            mean[k : k + b.size] = -np.asarray(b.start)
        k += b.size
    return mean
