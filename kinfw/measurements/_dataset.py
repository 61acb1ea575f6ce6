"""The calibration dataset: :class:`Measurements`, its groups, subsets and merges.

The file format it is read from and written to is described in
:mod:`kinfw.measurements` (reader and writer in :mod:`kinfw.measurements._file`); the
checks against a robot are in :mod:`kinfw.measurements`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from os import PathLike
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.measurements._mounts import Mount
from kinfw.model import STANDARD_GRAVITY, Payloads
from kinfw.observations import (
    DatasetError,
    PointObservations,
    PoseObservations,
    TargetObservations,
    frozen_array,
    kind_named,
    kind_of,
    kinds,
)


class FrozenMapping(Mapping[str, Any]):
    """A read-only mapping (a copy of the given one) that pickles, unlike
    ``types.MappingProxyType`` (datasets go to worker processes)."""

    __slots__ = ("_items",)

    def __init__(self, items: Mapping[str, Any] | None = None) -> None:
        self._items = dict(items or {})

    def __getitem__(self, key: str) -> Any:
        return self._items[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        return f"FrozenMapping({self._items!r})"

    def __getstate__(self) -> dict[str, Any]:
        return self._items

    def __setstate__(self, state: dict[str, Any]) -> None:
        self._items = dict(state)


@dataclass(frozen=True, slots=True, eq=False)
class Measurements:
    """A calibration dataset: joint values per sample and the observations made.

    Arrays are read-only; methods return new datasets. Observation groups are held per
    kind (:mod:`kinfw.observations`): :meth:`groups` gives those of one kind,
    :meth:`all_groups` every group. The built-in kinds keep their own fields
    (``poses``, ``targets``, ``points``: the closed form and the camera steps read poses
    and targets only); groups of any other registered kind are in ``others``.

    Attributes
    ----------
    joint_names : tuple of str
        Joints whose values are recorded (columns of ``qs``); others are held at zero.
    qs : ndarray, shape (n, k)
        Joint values of each sample in SI (rad for revolute, m for prismatic joints),
        columns in ``joint_names`` order.
    poses : tuple of PoseObservations
        ``pose`` observation groups, first-seen order.
    targets : tuple of TargetObservations
        ``target`` observation groups, first-seen order.
    points : tuple of PointObservations
        ``point`` observation groups, first-seen order.
    source : str
        File path (or ``"<memory>"``) used in messages.
    others : tuple
        Groups of registered kinds other than the three built-in ones, first-seen order.
    cameras : mapping of str to CameraIntrinsics
        Camera intrinsics by camera frame (the file's ``"cameras"`` section; frames that
        no observation uses are kept), read-only.
    mounts : mapping of str to Mount
        Frames the data name that the URDF may lack, each on a URDF link (the file's
        ``"mounts"`` section; :func:`kinfw.measurements.mounted_robot` adds them), read-only.
    payloads : Payloads or None
        What each sample's robot carries (the file's per-sample ``"payload"``): one entry
        per sample; None when no sample carries one (:meth:`sample_payloads` gives a
        :class:`~kinfw.model.Payloads` either way).
    gravity : ndarray, shape (3,)
        Gravity in the URDF root frame, m/s^2 (the file's ``"gravity"``; default
        :data:`~kinfw.model.STANDARD_GRAVITY`, 9.81 along the root's -z), read-only.
    """

    joint_names: tuple[str, ...]
    qs: NDArray[np.float64]
    poses: tuple[PoseObservations, ...] = ()
    targets: tuple[TargetObservations, ...] = ()
    points: tuple[PointObservations, ...] = ()
    source: str = "<memory>"
    others: tuple[Any, ...] = ()
    cameras: Mapping[str, Any] = field(default_factory=dict)
    mounts: Mapping[str, Mount] = field(default_factory=dict)
    payloads: Payloads | None = None
    gravity: NDArray[np.float64] = field(default=STANDARD_GRAVITY)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        src = self.source
        object.__setattr__(self, "gravity", _checked_gravity(self.gravity, src))
        object.__setattr__(self, "cameras", FrozenMapping(self.cameras))
        object.__setattr__(self, "mounts", FrozenMapping(self.mounts))
        for name, mount in self.mounts.items():
            if not isinstance(mount, Mount):
                raise DatasetError(
                    f"{src}: mounts[{name!r}]: expected Mount, got {type(mount).__name__}"
                )
        names = tuple(self.joint_names)
        if isinstance(self.joint_names, str) or not all(isinstance(n, str) for n in names):
            raise DatasetError(f"{src}: joint_names: expected a sequence of strings")
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            raise DatasetError(f"{src}: joint_names: joint {dup!r} is listed twice")
        qs = np.asarray(self.qs, dtype=float)
        if qs.ndim != 2 or qs.shape[1] != len(names):
            raise DatasetError(
                f"{src}: qs: expected shape (n, {len(names)}) (one column per joint name), "
                f"got {qs.shape}"
            )
        if not np.isfinite(qs).all():
            raise DatasetError(f"{src}: qs: all joint values must be finite")
        object.__setattr__(self, "joint_names", names)
        object.__setattr__(self, "qs", frozen_array(qs, np.float64))
        n = qs.shape[0]
        for attr, cls in (
            ("poses", PoseObservations),
            ("targets", TargetObservations),
            ("points", PointObservations),
            ("others", None),
        ):
            groups = tuple(getattr(self, attr))
            for g in groups:
                if cls is not None and not isinstance(g, cls):
                    raise DatasetError(
                        f"{src}: {attr}: expected {cls.__name__}, got {type(g).__name__}"
                    )
                if cls is None:
                    try:
                        kind = kind_of(g)
                    except TypeError as exc:
                        raise DatasetError(f"{src}: others: {exc}") from None
                    if kind.measurements_field is not None:
                        raise DatasetError(
                            f"{src}: others: {kind.name!r} groups belong in "
                            f"{kind.measurements_field}"
                        )
                if len(g.sample) and g.sample.max() >= n:
                    raise DatasetError(
                        f"{src}: {attr}: {g!r} refers to sample {int(g.sample.max())}, "
                        f"but there are {n} samples"
                    )
            object.__setattr__(self, attr, groups)
        if self.payloads is not None:
            if not isinstance(self.payloads, Payloads):
                raise DatasetError(
                    f"{src}: payloads: expected Payloads or None, got "
                    f"{type(self.payloads).__name__}"
                )
            if len(self.payloads) != n:
                raise DatasetError(
                    f"{src}: payloads: expected one entry per sample ({n}), "
                    f"got {len(self.payloads)}"
                )
        _check_one_frame_per_target(self)

    def __repr__(self) -> str:
        others = f", others={list(self.others)}" if self.others else ""
        return (
            f"Measurements(source={self.source!r}, n_samples={self.n_samples}, "
            f"joint_names={list(self.joint_names)}, poses={list(self.poses)}, "
            f"targets={list(self.targets)}, points={list(self.points)}{others})"
        )

    def sample_payloads(self) -> Payloads:
        """The payload of every sample (:attr:`payloads`, or
        :meth:`Payloads.none <kinfw.model.Payloads.none>` when no sample carries one)."""
        return Payloads.none(self.n_samples) if self.payloads is None else self.payloads

    def groups(self, kind: str) -> tuple[Any, ...]:
        """The observation groups of one kind (by its file name, e.g. ``"pose"``)."""
        field = kind_named(kind).measurements_field
        if field is not None:
            return getattr(self, field)
        return tuple(g for g in self.others if g.kind == kind)

    def all_groups(self) -> Iterator[Any]:
        """Every observation group, kind by kind in registry order."""
        for kind in kinds():
            yield from self.groups(kind.name)

    def with_cameras(self, cameras: Mapping[str, Any]) -> Measurements:
        """The dataset with camera intrinsics added or replaced (by camera frame), in
        :attr:`cameras` and in the groups that use them."""
        merged = {**self.cameras, **cameras}
        groups = [kind_of(g).with_cameras(g, merged) for g in self.all_groups()]
        return self.with_groups(groups, cameras=merged)

    def with_mounts(self, mounts: Mapping[str, Mount]) -> Measurements:
        """The dataset with more mounted frames (:attr:`mounts`); a frame already
        mounted differently is a DatasetError naming it."""
        return replace(self, mounts=_merged_mounts((self.mounts, mounts), self.source))

    def with_groups(self, groups: Sequence[Any], **changes: Any) -> Measurements:
        """The dataset with other observation groups (of any registered kinds), and
        other ``changes`` of its fields (e.g. ``qs``, with ``payloads`` when it has them)."""
        by_field: dict[str, list[Any]] = {"poses": [], "targets": [], "points": [], "others": []}
        for g in groups:
            by_field[kind_of(g).measurements_field or "others"].append(g)
        return replace(self, **{k: tuple(v) for k, v in by_field.items()}, **changes)

    def with_quaternions_reordered(self) -> Measurements | None:
        """The dataset as if every measured orientation's quaternion had been stored in
        the other order: each rotation's ``(x, y, z, w)`` read as ``(w, x, y, z)``
        (poses and target poses; the positions kept). None without measured
        orientations. The diagnosis of quaternions written scalar first where kinfw reads
        them scalar last (``quat_xyzw``)."""
        from kinfw.geometry import quat_xyzw_from_matrix, transform_from_xyz_quat_xyzw

        def reordered(T: NDArray) -> NDArray:
            q = quat_xyzw_from_matrix(T[:, :3, :3])  # the stored one, up to its sign
            return transform_from_xyz_quat_xyzw(T[:, :3, 3], q[:, [1, 2, 3, 0]])

        if not (self.poses or self.targets):
            return None
        poses = [replace(g, meas_T_frame=reordered(g.meas_T_frame)) for g in self.poses]
        targets = [replace(g, camera_T_target=reordered(g.camera_T_target)) for g in self.targets]
        return replace(self, poses=tuple(poses), targets=tuple(targets))

    def _groups(self) -> Iterator[Any]:
        return self.all_groups()

    @property
    def n_samples(self) -> int:
        """Number of samples ``n`` (rows of :attr:`qs`)."""
        return int(self.qs.shape[0])

    @property
    def observed_frames(self) -> tuple[str, ...]:
        """Every URDF frame named by an observation (``frame`` or ``camera``), no duplicates.

        Ordered by first use: by the first sample that observes the frame, then poses
        before targets before points, then group order. ``measured_in`` frames and marker
        and target names are not included.
        """
        return tuple(first_uses(self))

    def subset(self, samples: ArrayLike) -> Measurements:
        """The dataset restricted to some samples, renumbered in the order given.

        Parameters
        ----------
        samples : array_like of int, shape (p,), or of bool, shape (n,)
            Sample indices to keep (new sample ``i`` is old sample ``samples[i]``; an
            index may repeat, e.g. for a bootstrap), or a boolean mask over the samples.

        Returns
        -------
        Measurements
            ``qs`` of shape ``(p, k)`` and the kept samples' :attr:`payloads`; every group
            keeps the observations of the kept samples, with renumbered indices sorted
            ascending; groups left empty are dropped.
        """
        sel = np.asarray(samples)
        n = self.n_samples
        if sel.dtype == bool:
            if sel.shape != (n,):
                raise ValueError(
                    f"{self.source}: subset: a boolean mask needs shape ({n},), got {sel.shape}"
                )
            sel = np.flatnonzero(sel)
        if sel.size == 0:
            sel = sel.astype(np.int64)
        if sel.ndim != 1 or not np.issubdtype(sel.dtype, np.integer):
            raise ValueError(
                f"{self.source}: subset: expected a 1-D array of sample indices, "
                f"got shape {sel.shape}, dtype {sel.dtype}"
            )
        if sel.size and (sel.min() < 0 or sel.max() >= n):
            bad = int(sel[(sel < 0) | (sel >= n)][0])
            raise IndexError(
                f"{self.source}: subset: sample index {bad} is out of range for {n} samples"
            )
        order = np.argsort(sel, kind="stable")
        sorted_sel = sel[order]

        def select(group: Any) -> Any:
            # Each row of the group appears once per occurrence of its sample in `sel`.
            left = np.searchsorted(sorted_sel, group.sample, side="left")
            counts = np.searchsorted(sorted_sel, group.sample, side="right") - left
            if not counts.any():
                return None
            rows = np.repeat(np.arange(len(group.sample)), counts)
            starts = np.repeat(np.cumsum(counts) - counts, counts)
            new = order[np.repeat(left, counts) + np.arange(len(rows)) - starts]
            by_sample = np.lexsort((rows, new))
            return kind_of(group).take(group, rows[by_sample], new[by_sample].astype(np.int64))

        kept = [g for g in map(select, self.all_groups()) if g is not None]
        payloads = None if self.payloads is None else self.payloads.subset(sel)
        return self.with_groups(kept, qs=self.qs[sel], payloads=payloads)

    def q_of(self, joint_names: Sequence[str]) -> NDArray[np.float64]:
        """Joint values with columns in another order.

        Parameters
        ----------
        joint_names : sequence of str
            Wanted column order (e.g. a model's joints).

        Returns
        -------
        ndarray, shape (n, len(joint_names))
            SI joint values; a joint not in :attr:`joint_names` is held at zero.
        """
        if isinstance(joint_names, str):
            raise TypeError("q_of: joint_names must be a sequence of names, not a string")
        column = {name: c for c, name in enumerate(self.joint_names)}
        out = np.zeros((self.n_samples, len(joint_names)))
        for c, name in enumerate(joint_names):
            if name in column:
                out[:, c] = self.qs[:, column[name]]
        return out


def _check_one_frame_per_target(m: Measurements) -> None:
    """Raise unless every target name is on one frame (or fixed in the world) in every
    group that names it, naming two groups that disagree and their first samples."""
    homes: dict[str, Any] = {}
    for g in m.all_groups():
        if not hasattr(g, "target_frame"):
            continue
        seen = homes.setdefault(g.target, g)
        if seen.target_frame != g.target_frame:

            def placed(group: Any) -> str:
                where = group.target_frame
                on = "fixed in the world" if where is None else f"on {where!r}"
                return f"{on} in {group!r} (first sample {int(group.sample.min())})"

            raise DatasetError(
                f"{m.source}: target {g.target!r} is {placed(seen)} but {placed(g)}; a "
                "target is rigidly attached to one frame (give each board its own name)"
            )


def first_uses(measurements: Measurements) -> dict[str, tuple[int, str]]:
    """Observed frame -> (first sample index, kind), ordered by first use."""
    entries = []
    for rank, g in enumerate(measurements._groups()):
        first = int(g.sample.min()) if len(g.sample) else measurements.n_samples
        entries += [(first, rank, frame, g.kind) for frame in kind_of(g).frames(g)]
    out: dict[str, tuple[int, str]] = {}
    for first, _, frame, kind in sorted(entries):
        out.setdefault(frame, (first, kind))
    return out


def merge_same_key(groups: Iterable[Any]) -> tuple[Any, ...]:
    """Merge groups with equal keys (kind, frame, marker...), rows sorted by sample."""
    by_key: dict[tuple[Any, ...], list[Any]] = {}
    for g in groups:
        by_key.setdefault(kind_of(g).key(g), []).append(g)
    return tuple(
        parts[0] if len(parts) == 1 else kind_of(parts[0]).concatenate(parts)
        for parts in by_key.values()
    )


def check_measurements(data: object, name: str) -> Measurements:
    """``data`` itself when it is a :class:`Measurements`; else a TypeError naming the
    argument ``name`` (a path: read it with
    :func:`kinfw.measurements.read_measurements`)."""
    if isinstance(data, Measurements):
        return data
    hint = " (read it with kinfw.read_measurements)" if isinstance(data, str | PathLike) else ""
    raise TypeError(f"{name}: expected Measurements, got {type(data).__name__} {data!r:.60}{hint}")


def concatenate_measurements(*parts: Measurements) -> Measurements:
    """One dataset holding the samples of ``parts`` in order.

    The joint names are united (first-seen order); a joint that a part does not list is
    held at zero in its samples. Groups that observe the same thing (same frame, kind,
    marker, offset and measurement frame) are merged. The payloads follow their samples
    (None when no part has any); the parts must share one gravity. The source is the
    parts' sources joined by ``" + "``.
    """
    if not parts:
        raise ValueError("concatenate_measurements: give at least one dataset")
    for p in parts[1:]:
        if not np.array_equal(p.gravity, parts[0].gravity):
            raise DatasetError(
                f"{p.source}: gravity {p.gravity.tolist()} m/s^2 differs from "
                f"{parts[0].source}'s {parts[0].gravity.tolist()}; concatenate data of one "
                "gravity (one root frame)"
            )
    payloads = None
    if any(p.payloads is not None for p in parts):
        payloads = parts[0].sample_payloads()
        for p in parts[1:]:
            payloads = payloads.concatenate(p.sample_payloads())
    names = tuple(dict.fromkeys(n for p in parts for n in p.joint_names))
    offsets = np.cumsum([0, *(p.n_samples for p in parts[:-1])])

    groups = merge_same_key(
        replace(g, sample=g.sample + off)
        for p, off in zip(parts, offsets, strict=True)
        for g in p.all_groups()
    )
    return Measurements(names, np.zeros((0, len(names)))).with_groups(
        groups,
        qs=np.concatenate([p.q_of(names) for p in parts]),
        source=" + ".join(dict.fromkeys(p.source for p in parts)),
        cameras={k: v for p in parts for k, v in p.cameras.items()},
        mounts=_merged_mounts([p.mounts for p in parts], " + ".join(p.source for p in parts)),
        payloads=payloads,
        gravity=parts[0].gravity,
    )


#: The norms of gravity a dataset may give (m/s^2): a typo (9810, 0.981 or 0) is refused.
GRAVITY_NORM_RANGE = (0.1, 100.0)


def _checked_gravity(value: Any, source: str) -> NDArray[np.float64]:
    """Gravity as a read-only (3,) array; a DatasetError naming ``gravity`` unless it is
    three finite numbers of norm within :data:`GRAVITY_NORM_RANGE` (m/s^2)."""
    try:
        g = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise DatasetError(
            f"{source}: gravity: expected 3 numbers [gx, gy, gz] (m/s^2), got {value!r:.60}"
        ) from None
    if g.shape != (3,) or not np.isfinite(g).all():
        raise DatasetError(
            f"{source}: gravity: expected 3 finite numbers [gx, gy, gz] (m/s^2), got "
            f"{g.tolist() if g.size <= 6 else f'shape {g.shape}'}"
        )
    low, high = GRAVITY_NORM_RANGE
    norm = float(np.linalg.norm(g))
    if not low <= norm <= high:
        raise DatasetError(
            f"{source}: gravity: its norm is {norm:.6g} m/s^2, expected {low:g} to {high:g} "
            "(m/s^2 in the root frame, e.g. [0, 0, -9.81])"
        )
    return frozen_array(g, np.float64)


def _merged_mounts(parts: Iterable[Mapping[str, Mount]], source: str) -> dict[str, Mount]:
    """The union of mount sections; one frame mounted two ways is a DatasetError."""
    out: dict[str, Mount] = {}
    for mounts in parts:
        for name, mount in mounts.items():
            seen = out.setdefault(name, mount)
            if not seen.same_as(mount):
                raise DatasetError(
                    f"{source}: mounts: frame {name!r} is mounted on {seen.parent!r} in one "
                    f"part and on {mount.parent!r} (or at another start pose) in another"
                )
    return out
