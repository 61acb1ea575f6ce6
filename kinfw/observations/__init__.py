"""The registry of observation kinds.

Every kind of observation (``pose``, ``target``, ``point``, ``plane``, ``pixels``, and any
kind registered by an application or a test) is one
:class:`~kinfw.observations.base.ObservationKind`. The measurement files, the estimation
problem and verification look kinds up here and loop over :func:`kinds`; none of them
branches on a kind's name.

Adding a kind: write its group dataclass and its :class:`ObservationKind` subclass
(see ``docs/architecture.md`` for a worked example), then ``register_kind(MyKind())``.
"""

from __future__ import annotations

from typing import Any

from kinfw.observations.base import (
    NoiseComponent,
    ObservationKind,
    StartContext,
    SymbolicContext,
    UnknownRequest,
)
from kinfw.observations.pixels import PixelKind, PixelObservations
from kinfw.observations.plane import PlaneContacts, PlaneKind
from kinfw.observations.point import PointKind, PointObservations
from kinfw.observations.pose import PoseKind, PoseObservations
from kinfw.observations.reader import DatasetError, ObservationReader
from kinfw.observations.target import TargetKind, TargetObservations

__all__ = [
    "DatasetError",
    "NoiseComponent",
    "ObservationKind",
    "ObservationReader",
    "PixelObservations",
    "PlaneContacts",
    "PointObservations",
    "PoseObservations",
    "StartContext",
    "SymbolicContext",
    "TargetObservations",
    "UnknownRequest",
    "kind_of",
    "kinds",
    "register_kind",
    "unregister_kind",
]

_REGISTRY: dict[str, ObservationKind] = {}


def register_kind(kind: ObservationKind) -> ObservationKind:
    """Add an observation kind (its ``name`` must be new); returns it.

    Raises
    ------
    ValueError
        When a kind of that name or group type is already registered.
    """
    if kind.name in _REGISTRY:
        raise ValueError(f"register_kind: a kind named {kind.name!r} is already registered")
    if any(k.group_type is kind.group_type for k in _REGISTRY.values()):
        raise ValueError(
            f"register_kind: {kind.group_type.__name__} already belongs to a registered kind"
        )
    _REGISTRY[kind.name] = kind
    return kind


def unregister_kind(name: str) -> None:
    """Remove a kind added by :func:`register_kind` (the built-in kinds stay)."""
    if name in _BUILT_IN:
        raise ValueError(f"unregister_kind: {name!r} is a built-in kind")
    _REGISTRY.pop(name, None)


def kinds() -> tuple[ObservationKind, ...]:
    """Every registered kind, built-ins first (``pose``, ``target``, ``point``, ``plane``,
    ``pixels``)."""
    return tuple(_REGISTRY.values())


def kind_named(name: str) -> ObservationKind:
    """The kind of a file's ``"kind"`` (KeyError if not registered)."""
    return _REGISTRY[name]


def kind_of(group: Any) -> ObservationKind:
    """The kind of an observation group (by its ``kind`` class attribute)."""
    try:
        kind = _REGISTRY[group.kind]
    except (AttributeError, KeyError):
        raise TypeError(
            f"{type(group).__name__} is not the group of a registered observation kind"
        ) from None
    if not isinstance(group, kind.group_type):
        raise TypeError(
            f"{type(group).__name__}: expected {kind.group_type.__name__} for kind {kind.name!r}"
        )
    return kind


for _kind in (PoseKind(), TargetKind(), PointKind(), PlaneKind(), PixelKind()):
    register_kind(_kind)
_BUILT_IN = frozenset(_REGISTRY)
