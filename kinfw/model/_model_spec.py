"""Model specs: the robot plus named robot blocks, and the registry of block names.

A model spec is the list of what the URDF cannot hold that a calibration estimates with
the geometry: ``--model compliance``, ``--model gear-scale:JOINT``, ``--model
coupling:JOINT=K*OTHER`` (:mod:`kinfw.model` lists the shipped blocks). Each name is a
:class:`~kinfw.model.SpecBlock` class in a registry (:func:`register_block`; a plugin adds
its own), and a calibrated spec (its blocks started at their estimates) is recorded in the
calibration's sidecar, so verify, reach, view and export re-apply it
(:meth:`ModelSpec.joint_values`, :meth:`ModelSpec.readings`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.model._blocks import SpecBlock
from kinfw.model._joint_blocks import GearScaleBlock, JointComplianceBlock, JointCouplingBlock
from kinfw.model._loads import STANDARD_GRAVITY, BlockSamples, Payloads
from kinfw.plugins import load_plugins

_REGISTRY: dict[str, type[SpecBlock]] = {}


def register_block(cls: type[SpecBlock]) -> type[SpecBlock]:
    """Add a :class:`~kinfw.model.SpecBlock` class to the registry under its
    ``block_name`` (usable as a class decorator). A ValueError when the name is taken or
    the class is not a SpecBlock."""
    if not (isinstance(cls, type) and issubclass(cls, SpecBlock)):
        raise ValueError(f"register_block: expected a SpecBlock subclass, got {cls!r}")
    name = cls.block_name
    if not name or not all(ch.isalnum() or ch in "-_" for ch in name):
        raise ValueError(
            f"register_block: {cls.__name__}.block_name {name!r}: letters, digits, - and _"
        )
    if name in _REGISTRY and _REGISTRY[name] is not cls:
        raise ValueError(
            f"register_block: the block name {name!r} is taken by {_REGISTRY[name].__name__}"
        )
    _REGISTRY[name] = cls
    return cls


def block_names() -> tuple[str, ...]:
    """The registered block names, sorted (the plugins' too: :mod:`kinfw.plugins`)."""
    load_plugins()
    return tuple(sorted(_REGISTRY))


def block_from_spec(text: str) -> SpecBlock:
    """The block of one spec text ``NAME`` or ``NAME:ARGUMENT`` (a ValueError naming the
    known names, or the block's expected form)."""
    load_plugins()
    name, _, argument = str(text).strip().partition(":")
    cls = _REGISTRY.get(name)
    if cls is None:
        raise ValueError(
            f"--model {text}: unknown block {name!r}; known blocks: {', '.join(block_names())}"
        )
    return cls.from_spec(argument)


for _cls in (JointComplianceBlock, GearScaleBlock, JointCouplingBlock):
    register_block(_cls)


@dataclass(frozen=True, slots=True)
class ModelSpec:
    """The robot blocks a calibration adds to the URDF (empty: the URDF alone).

    Attributes
    ----------
    blocks : tuple of SpecBlock
        In the spec's order; their joint hooks act by stage (the readings' maps, then the
        deflections), in this order within a stage.
    """

    blocks: tuple[SpecBlock, ...] = ()

    def __post_init__(self) -> None:
        keys = [b.key for b in self.blocks]
        for b in self.blocks:
            if not isinstance(b, SpecBlock):
                raise ValueError(f"ModelSpec: expected SpecBlock instances, got {type(b).__name__}")
            if keys.count(b.key) > 1:
                raise ValueError(f"ModelSpec: the block {b.spec} is listed twice")

    @classmethod
    def parse(cls, texts: Iterable[str]) -> ModelSpec:
        """The spec of ``--model`` texts (each ``NAME[:ARGUMENT]``)."""
        return cls(tuple(block_from_spec(t) for t in texts))

    def __bool__(self) -> bool:
        return bool(self.blocks)

    def summary(self) -> str:
        """One phrase: ``"compliance (6 entries), gear-scale:tilt"``."""
        return ", ".join(
            b.block_name + (f" ({b.size} entries)" if b.size > 1 else f":{b.argument}")
            for b in self.blocks
        )

    @property
    def texts(self) -> tuple[str, ...]:
        """The spec texts that rebuild the blocks (without their values)."""
        return tuple(b.spec for b in self.blocks)

    def ordered(self) -> tuple[SpecBlock, ...]:
        """The blocks in the order their joint hooks act."""
        return tuple(
            b for stage in ("readings", "deflection") for b in self.blocks if b.stage == stage
        )

    def bound(self, samples: BlockSamples) -> ModelSpec:
        """Every block as it applies to these samples (:meth:`~kinfw.model.RobotBlock.for_data`)."""
        return ModelSpec(tuple(b.for_data(samples) for b in self.blocks))

    def with_values(self, values: Sequence[ArrayLike]) -> ModelSpec:
        """The blocks started at ``values`` (one array per block): a calibrated spec."""
        return ModelSpec(tuple(b.with_start(v) for b, v in zip(self.blocks, values, strict=True)))

    def joint_values(
        self,
        robot: Any,
        joint_names: tuple[str, ...],
        qs: ArrayLike,
        payloads: Payloads | None = None,
        gravity: ArrayLike = STANDARD_GRAVITY,
    ) -> NDArray[np.float64]:
        """The URDF joint values (n, J) at the readings ``qs`` (n, J) of ``joint_names``:
        every block's hook at its value, for these payloads and gravity (root frame,
        m/s^2)."""
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        samples = BlockSamples(robot, tuple(joint_names), qs, payloads, gravity)
        q = qs
        for b in self.ordered():
            q = b.joint_values(q, samples)
        return q

    def readings(
        self,
        robot: Any,
        joint_names: tuple[str, ...],
        qs: ArrayLike,
        payloads: Payloads | None = None,
        gravity: ArrayLike = STANDARD_GRAVITY,
    ) -> NDArray[np.float64]:
        """The inverse of :meth:`joint_values`: the readings (joint commands) that give the
        URDF joint values ``qs`` (n, J), the deflection under these payloads compensated."""
        q = np.atleast_2d(np.asarray(qs, dtype=float))
        samples = BlockSamples(robot, tuple(joint_names), q, payloads, gravity)
        for b in reversed(self.ordered()):
            q = b.readings(q, samples.at(q))
        return q

    def to_list(self) -> list[dict[str, Any]]:
        """JSON-ready: per block its spec text, names, units and values."""
        return [
            {
                "block": b.spec,
                "names": [f"{n.owner}:{n.field}" for n in b.names],
                "units": list(b.units),
                "values": b.start.tolist(),
            }
            for b in self.blocks
        ]

    @classmethod
    def from_list(cls, entries: Sequence[dict[str, Any]], source: str = "<memory>") -> ModelSpec:
        """The spec of :meth:`to_list` (a ValueError naming ``source`` and the entry)."""
        blocks = []
        for i, entry in enumerate(entries):
            try:
                block = block_from_spec(entry["block"])
                blocks.append(block.with_start(np.asarray(entry["values"], dtype=float)))
            except (KeyError, TypeError, ValueError) as exc:
                raise ValueError(f"{source}: model[{i}]: {exc}") from None
        return cls(tuple(blocks))
