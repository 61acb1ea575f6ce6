"""The registry of observation kinds.

Every kind of observation (``pose``, ``target``, ``point``, ``plane``, ``sphere``,
``divot``, ``pixels``, and any
kind registered by an application or a test) is one
:class:`~kinfw.observations.ObservationKind`. The measurement files, the estimation
problem and verification look kinds up here and loop over :func:`kinds`; none of them
branches on a kind's name.

Adding a kind: write its group dataclass and its :class:`ObservationKind` subclass
(see ``docs/architecture.md`` for a worked example), then ``register_kind(MyKind())``:
in your program, or in a plugin module that another installed package names in the
entry-point group ``kinfw.plugins`` (:mod:`kinfw.plugins`), which the look-ups here
(:func:`kinds`, ``kind_named``, :func:`kind_of`) load before their first answer.
Its :attr:`~ObservationKind.file_keys` lists the keys its file observations may hold
(unset: the keys its ``parse`` reads); the reader warns of any other.
"""

from __future__ import annotations

from typing import (
    Any,
)

from kinfw.observations._base import (
    POSITION,
    ROTATION,
    Metric,
    MetricErrors,
    NoiseComponent,
    ObservationKind,
    UnknownRequest,
    component_errors,
    data_array,
    evenly_spaced,
    frozen_array,
    sample_array,
)
from kinfw.observations._contexts import (
    StartContext,
    SymbolicContext,
    inverse_casadi,
)
from kinfw.observations._divot import (
    PLACEMENT,
    DivotContacts,
    DivotKind,
    divot_key,
    pivot_calibration,
)
from kinfw.observations._intrinsics_block import (
    IntrinsicsBlock,
)
from kinfw.observations._numeric import (
    Drawing,
    MissingValue,
    NumericContext,
    gaussian_rows,
    node_name,
    perturb_transforms,
    predicted_or_missing,
    random_small_rotations,
    random_unit_vectors,
    transforms_from_pose_rows,
)
from kinfw.observations._pixels import (
    PIXEL,
    PixelKind,
    PixelObservations,
    pixel_weights,
)
from kinfw.observations._plane import (
    DISTANCE,
    TILT,
    PlaneBlock,
    PlaneContacts,
    PlaneKind,
    fit_plane,
    lifted_probe_offset,
    plane_key,
)
from kinfw.observations._pnp import (
    pnp_camera_T_targets,
    target_observations_from_pixels,
)
from kinfw.observations._point import (
    PointKind,
    PointObservations,
    offset_key,
)
from kinfw.observations._pose import (
    QUAT_NORM_TOL,
    QUAT_ROUNDED_TOL,
    PoseKind,
    PoseObservations,
    read_quaternion,
)
from kinfw.observations._reader import (
    DatasetError,
    ObservationReader,
    describe,
)
from kinfw.observations._rigid import (
    RigidTransformKind,
)
from kinfw.observations._sphere import (
    SphereBlock,
    SphereContacts,
    SphereKind,
    fit_sphere,
    lifted_sphere_probe,
    sphere_key,
)
from kinfw.observations._target import TargetKind, TargetObservations
from kinfw.plugins import load_plugins

__all__ = [
    "DISTANCE",
    "PIXEL",
    "PLACEMENT",
    "POSITION",
    "QUAT_NORM_TOL",
    "QUAT_ROUNDED_TOL",
    "ROTATION",
    "TILT",
    "DatasetError",
    "DivotContacts",
    "Drawing",
    "IntrinsicsBlock",
    "Metric",
    "MetricErrors",
    "MissingValue",
    "NoiseComponent",
    "NumericContext",
    "ObservationKind",
    "ObservationReader",
    "PixelObservations",
    "PlaneBlock",
    "PlaneContacts",
    "PointObservations",
    "PoseObservations",
    "RigidTransformKind",
    "SphereBlock",
    "SphereContacts",
    "StartContext",
    "SymbolicContext",
    "TargetObservations",
    "UnknownRequest",
    "component_errors",
    "data_array",
    "describe",
    "divot_key",
    "evenly_spaced",
    "fit_plane",
    "fit_sphere",
    "frozen_array",
    "gaussian_rows",
    "inverse_casadi",
    "kind_of",
    "kinds",
    "lifted_probe_offset",
    "lifted_sphere_probe",
    "node_name",
    "offset_key",
    "perturb_transforms",
    "pivot_calibration",
    "pixel_weights",
    "plane_key",
    "pnp_camera_T_targets",
    "predicted_or_missing",
    "random_small_rotations",
    "random_unit_vectors",
    "read_quaternion",
    "register_kind",
    "sample_array",
    "sphere_key",
    "target_observations_from_pixels",
    "transforms_from_pose_rows",
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
    ``sphere``, ``divot``, ``pixels``), then those of the plugins
    (:func:`kinfw.plugins.load_plugins`) and of the program."""
    load_plugins()
    return tuple(_REGISTRY.values())


def kind_named(name: str) -> ObservationKind:
    """The kind of a file's ``"kind"``, a plugin's too (KeyError if not registered)."""
    load_plugins()
    return _REGISTRY[name]


def kind_of(group: Any) -> ObservationKind:
    """The kind of an observation group (by its ``kind`` class attribute)."""
    load_plugins()
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


for _kind in (
    PoseKind(),
    TargetKind(),
    PointKind(),
    PlaneKind(),
    SphereKind(),
    DivotKind(),
    PixelKind(),
):
    register_kind(_kind)
_BUILT_IN = frozenset(_REGISTRY)
