"""Reading and writing ``kinfw-measurements`` files (the format: :mod:`kinfw.measurements`).

:func:`read_measurements` / :func:`measurements_from_dict` validate a document and
convert it to SI; :func:`measurements_to_dict` / :func:`write_measurements` write a
dataset back in SI. Each observation is read and written by its kind
(:mod:`kinfw.observations`).
"""

from __future__ import annotations

import json
import logging
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinfw import progress
from kinfw.camera import CameraError, CameraIntrinsics, intrinsics_from_dict
from kinfw.files import write_text_atomic
from kinfw.measurements._dataset import Measurements
from kinfw.measurements._mounts import mounts_from_dict, mounts_to_dict
from kinfw.model import STANDARD_GRAVITY, Payloads
from kinfw.observations import DatasetError, ObservationReader, describe, kind_named, kind_of, kinds

logger = logging.getLogger("kinfw.measurements")

FORMAT = "kinfw-measurements"
SUPPORTED_VERSIONS = (1,)

_LENGTH_UNITS = ("m", "mm")
_ANGLE_UNITS = ("rad", "deg")
_JOINT_UNITS = ("m", "mm", "rad", "deg")

#: The top-level keys of a file; ``"comment"`` is free text for the people who read it
#: (ignored). Any other key is warned of, once.
TOP_KEYS = (
    "format",
    "version",
    "units",
    "joint_names",
    "joint_units",
    "measured_in",
    "gravity",
    "cameras",
    "mounts",
    "samples",
    "comment",
)
#: The keys of a sample.
SAMPLE_KEYS = ("q", "observations", "payload")
#: The keys of a sample's payload.
PAYLOAD_KEYS = ("frame", "mass_kg", "com", "inertia")
#: The keys of every observation, whatever its kind (a kind adds its ``file_keys``).
OBSERVATION_KEYS = ("kind", "frame")


# -- reading ---------------------------------------------------------------------------


def _columns_to_si(qs: NDArray[np.float64], units: Sequence[str]) -> NDArray[np.float64]:
    out = qs.copy()
    for c, unit in enumerate(units):
        if unit == "mm":
            out[:, c] = qs[:, c] / 1000.0
        elif unit == "deg":
            out[:, c] = np.deg2rad(qs[:, c])
    return out


def read_measurements(
    path: str | Path, *, cameras: Mapping[str, CameraIntrinsics] | None = None
) -> Measurements:
    """Read a ``kinfw-measurements`` JSON file (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The file.
    cameras : mapping of str to CameraIntrinsics, optional
        Camera intrinsics by camera frame that override or add to the file's
        ``"cameras"`` section (the CLI's ``--camera FRAME=FILE``).

    Returns
    -------
    Measurements
        In SI units, with ``source`` set to ``str(path)``.

    Raises
    ------
    DatasetError
        When the file cannot be read, is not valid JSON (the message gives line and
        column) or breaks a rule of the format (the message gives the key path).
    """
    path = Path(path)
    source = str(path)
    progress.stage(f"reading the measurements {source}")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DatasetError(f"{source}: measurement file not found") from None
    except UnicodeDecodeError as exc:
        raise DatasetError(
            f"{source}: not a UTF-8 text file ({exc.reason} at byte {exc.start})"
        ) from None
    except OSError as exc:
        raise DatasetError(f"{source}: cannot read measurement file ({exc.strerror})") from None
    if not text.strip():
        raise DatasetError(f"{source}: the file is empty; expected a {FORMAT} JSON document")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise DatasetError(
            f"{source}: invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"
        ) from None
    return measurements_from_dict(doc, source=source, cameras=cameras)


def _read_cameras(
    p: ObservationReader, doc: dict[str, Any], given: Mapping[str, CameraIntrinsics] | None
) -> dict[str, CameraIntrinsics]:
    """The ``"cameras"`` section (frame -> intrinsics), updated by ``given``."""
    out: dict[str, CameraIntrinsics] = {}
    if doc.get("cameras") is not None:
        section = p.obj(doc["cameras"], "cameras")
        for frame, entry in section.items():
            try:
                out[frame] = intrinsics_from_dict(entry, f"{p.source}: cameras.{frame}")
            except CameraError as exc:
                raise DatasetError(str(exc)) from None
    out.update(given or {})
    return out


def _read_units(p: ObservationReader, doc: dict[str, Any]) -> tuple[str, str]:
    """Check ``format`` and ``version``; return the document's (length, angle) units."""
    fmt = p.get(doc, "format", "", f"{FORMAT!r}")
    if fmt != FORMAT:
        raise p.error("format", f"expected {FORMAT!r}, got {describe(fmt)}")
    version = p.get(doc, "version", "", "1")
    if isinstance(version, bool) or version not in SUPPORTED_VERSIONS:
        supported = ", ".join(map(str, SUPPORTED_VERSIONS))
        raise p.error(
            "version",
            f"unsupported version {describe(version)}; this reader supports version {supported}",
        )
    units = p.obj(
        p.get(doc, "units", "", '{"length": "m" or "mm", "angle": "rad" or "deg"}'), "units"
    )
    length_unit = p.choice(
        p.get(units, "length", "units", '"m" or "mm"'), "units.length", _LENGTH_UNITS
    )
    angle_unit = p.choice(
        p.get(units, "angle", "units", '"rad" or "deg"'), "units.angle", _ANGLE_UNITS
    )
    return length_unit, angle_unit


def _read_joints(
    p: ObservationReader, doc: dict[str, Any], angle_unit: str
) -> tuple[tuple[str, ...], Sequence[str]]:
    """Return the distinct ``joint_names`` and each joint's unit (default: the angle unit)."""
    raw_names = p.list_of(
        p.get(doc, "joint_names", "", "a list of joint names"), "joint_names", "joint names"
    )
    joint_names = tuple(p.string(x, f"joint_names[{c}]") for c, x in enumerate(raw_names))
    seen: dict[str, int] = {}
    for c, name in enumerate(joint_names):
        if name in seen:
            raise p.error(
                f"joint_names[{c}]",
                f"joint {name!r} is already joint_names[{seen[name]}]; names must be distinct",
            )
        seen[name] = c
    k = len(joint_names)
    joint_units: Sequence[str] = (angle_unit,) * k
    if doc.get("joint_units") is not None:
        raw_units = doc["joint_units"]
        if not isinstance(raw_units, list) or len(raw_units) != k:
            got = f"{len(raw_units)}" if isinstance(raw_units, list) else describe(raw_units)
            raise p.error(
                "joint_units",
                f"expected a list of {k} units (one per joint_names entry), got {got}",
            )
        joint_units = [
            p.choice(u, f"joint_units[{c}]", _JOINT_UNITS) for c, u in enumerate(raw_units)
        ]
    return joint_names, joint_units


class _UnknownKeys:
    """The keys a file holds that the reader does not know, by place (the top level,
    samples, payloads, an observation kind): one warning per key and place, with the
    first place it is at and how many have it. A key whose value is null is absent."""

    def __init__(self) -> None:
        #: (kind or place, key) -> [first at, count, known keys, kind, place]
        self.found: dict[tuple[str, str], list[Any]] = {}

    def note(
        self,
        objects: Sequence[dict[str, Any]],
        at: Callable[[int], str],
        known: Sequence[str],
        place: str,
        kind: str | None = None,
    ) -> None:
        """Note the unknown keys of ``objects`` (JSON objects, ``at(k)`` where the k-th
        is, of ``place``: ``"samples"``; observations of ``kind``)."""
        allowed = frozenset(known)
        if set().union(*objects) <= allowed:  # the usual case, at once
            return
        for k in [k for k, obj in enumerate(objects) if not obj.keys() <= allowed]:
            for key, value in objects[k].items():
                if key not in allowed and value is not None:
                    entry = self.found.setdefault(
                        (kind or place, key), [at(k), 0, tuple(known), kind, place]
                    )
                    entry[1] += 1

    def warn(self, source: str) -> None:
        """One :class:`UserWarning` per unknown key and place."""
        for (_, key), (at, count, known, kind, place) in self.found.items():
            many = f", in {count} {place}" if count > 1 else ""
            on = "" if kind is None else f" on a {kind!r} observation"
            where = f"{at}: unknown key {key!r}" if at else f"unknown top-level key {key!r}"
            warnings.warn(
                f"{source}: {where}{on} (ignored{many}); known keys: {', '.join(known)}",
                UserWarning,
                stacklevel=3,
            )


def _note_unknown_keys(
    doc: dict[str, Any], samples: list[Any], read_keys: Mapping[str, set[str]]
) -> _UnknownKeys:
    """The unknown keys of a document that was read (``read_keys``: the keys
    :meth:`~kinfw.observations.ObservationKind.parse` read, by kind, for the kinds that
    do not list their :attr:`~kinfw.observations.ObservationKind.file_keys`)."""
    unknown = _UnknownKeys()
    unknown.note([doc], lambda _: "", TOP_KEYS, "top level")
    unknown.note(samples, "samples[{}]".format, SAMPLE_KEYS, "samples")
    with_payload = [i for i, s in enumerate(samples) if s.get("payload") is not None]
    unknown.note(
        [samples[i]["payload"] for i in with_payload],
        lambda k: f"samples[{with_payload[k]}].payload",
        PAYLOAD_KEYS,
        "payloads",
    )
    known: dict[str, tuple[str, ...]] = {}
    for kind in kinds():
        own = kind.file_keys
        if own is None:
            own = tuple(sorted(read_keys.get(kind.name, set()) - set(OBSERVATION_KEYS)))
        known[kind.name] = (*OBSERVATION_KEYS, *own)
    allowed = {name: frozenset(keys) for name, keys in known.items()}
    flat = list(chain.from_iterable(s["observations"] for s in samples))
    used = set().union(*flat)
    if all(used <= allowed[name] for name in {o["kind"] for o in flat}):
        return unknown  # the usual case, at once
    found: dict[str, list[tuple[dict[str, Any], str]]] = {}
    for i, s in enumerate(samples):
        for j, o in enumerate(s["observations"]):
            if not o.keys() <= allowed[o["kind"]]:
                found.setdefault(o["kind"], []).append((o, f"samples[{i}].observations[{j}]"))
    for name, entries in found.items():
        unknown.note(
            [o for o, _ in entries], lambda k, e=entries: e[k][1], known[name], "observations", name
        )
    return unknown


class _KeysRead(dict):  # type: ignore[type-arg]
    """An observation's dict that records the keys read from it (``get``, ``[]``,
    ``in``): the keys a kind knows when it does not list them."""

    def __init__(self, obs: dict[str, Any]) -> None:
        super().__init__(obs)
        self.read: set[str] = set()

    def get(self, key: str, default: Any = None) -> Any:
        self.read.add(key)
        return super().get(key, default)

    def __getitem__(self, key: str) -> Any:
        self.read.add(key)
        return super().__getitem__(key)

    def __contains__(self, key: object) -> bool:
        self.read.add(str(key))
        return super().__contains__(key)


@dataclass(slots=True)
class _PayloadColumns:
    """Every sample's payload as read, in SI: its frame's name (None: no payload), mass
    (kg), centre of mass (m) and inertia ``[ixx, ixy, ixz, iyy, iyz, izz]`` (kg m^2)."""

    frames: list[str | None]
    mass_kg: NDArray[np.float64]
    com_m: NDArray[np.float64]
    inertia6: NDArray[np.float64]

    @classmethod
    def empty(cls, n: int) -> _PayloadColumns:
        return cls([None] * n, np.zeros(n), np.zeros((n, 3)), np.zeros((n, 6)))

    def payloads(self, p: ObservationReader) -> Payloads | None:
        """The :class:`~kinfw.model.Payloads` of the samples; None when none has one. An
        inertia with a negative principal moment is a DatasetError naming its sample."""
        names = [f for f in self.frames if f is not None]
        if not names:
            return None
        bad = np.flatnonzero(_inertia_problem(self.inertia6))
        if len(bad):
            raise p.error(
                f"samples[{bad[0]}].payload.inertia",
                f"{self.inertia6[bad[0]].tolist()} is no rotational inertia (a negative "
                "principal moment); expected [ixx, ixy, ixz, iyy, iyz, izz] in kg m^2 about "
                "the centre of mass",
            )
        frames = tuple(dict.fromkeys(names))
        index = {f: k for k, f in enumerate(frames)}
        frame_index = np.array([-1 if f is None else index[f] for f in self.frames], np.intp)
        return Payloads(
            frames,
            frame_index,
            self.mass_kg,
            self.com_m,
            self.inertia6[:, _INERTIA_FROM_SIX].reshape(-1, 3, 3),
        )


#: ``[ixx, ixy, ixz, iyy, iyz, izz]`` (URDF order) -> the 3 x 3 matrix, row-major.
_INERTIA_FROM_SIX = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])


def _inertia_problem(six: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Per row of ``six`` (m, 6), whether it is no rotational inertia (a negative
    principal moment, beyond rounding)."""
    matrices = six[:, _INERTIA_FROM_SIX].reshape(-1, 3, 3)
    scale = np.maximum(np.abs(six).max(axis=1, initial=0.0), 1e-300)
    return np.linalg.eigvalsh(matrices).min(axis=1) < -1e-9 * scale


def _read_payload(
    p: ObservationReader, reader: ObservationReader, raw: Any, at: str
) -> tuple[str, float, list[float], list[float]]:
    """One sample's ``"payload"`` (at ``at``): frame, mass (kg), centre of mass (m, from
    the file's length unit) and inertia (6 numbers, kg m^2)."""
    payload = p.obj(raw, at)
    frame = p.string(p.get(payload, "frame", at, "the name of a URDF link or frame"), f"{at}.frame")
    expected = "a number >= 0 (kg)"
    mass = p.number(payload, "mass_kg", at, expected)
    if mass < 0:
        raise p.error(f"{at}.mass_kg", f"expected {expected}, got {describe(payload['mass_kg'])}")
    com = [0.0, 0.0, 0.0]
    if payload.get("com") is not None:
        com = reader.lengths(p.numbers(payload["com"], 3, f"{at}.com", f"[x, y, z] in {frame!r}"))
    inertia = [0.0] * 6
    if payload.get("inertia") is not None:
        inertia = p.numbers(
            payload["inertia"], 6, f"{at}.inertia", "[ixx, ixy, ixz, iyy, iyz, izz] in kg m^2"
        )
    return frame, mass, com, inertia


def _payloads_in_bulk(reader: ObservationReader, raws: list[Any]) -> _PayloadColumns | None:
    """:func:`_read_payload` of every sample at once (``raws`` each sample's
    ``"payload"`` or None); None when any fails a check (then read one at a time)."""
    out = _PayloadColumns.empty(len(raws))
    rows = [i for i, r in enumerate(raws) if r is not None]
    if not rows:
        return out
    items = [raws[i] for i in rows]
    if set(map(type, items)) != {dict}:
        return None
    frames = [d.get("frame") for d in items]
    if set(map(type, frames)) != {str} or "" in frames:
        return None
    masses = [d.get("mass_kg") for d in items]
    read_masses = reader.numbers_many([masses], len(masses))  # one row: checked at once
    if read_masses is None or (read_masses < 0).any():
        return None
    mass = read_masses[0]
    com = _optional_rows(reader, [d.get("com") for d in items], 3)
    inertia = _optional_rows(reader, [d.get("inertia") for d in items], 6)
    if com is None or inertia is None:
        return None
    if len(rows) == len(raws):
        out.frames[:] = frames
        rows = slice(None)
    else:
        for i, frame in zip(rows, frames, strict=True):
            out.frames[i] = frame
    out.mass_kg[rows] = mass
    out.com_m[rows] = com / 1000.0 if reader.length_unit == "mm" else com
    out.inertia6[rows] = inertia
    return out


def _optional_rows(
    reader: ObservationReader, values: list[Any], width: int
) -> NDArray[np.float64] | None:
    """The rows (m, width) of ``values``, each a list of ``width`` numbers or None
    (zeros), read at once; None when one is not such a list."""
    out = np.zeros((len(values), width))
    given = [k for k, v in enumerate(values) if v is not None]
    if given:
        read = reader.numbers_many(
            values if len(given) == len(values) else [values[k] for k in given], width
        )
        if read is None:
            return None
        out[given] = read
    return out


@dataclass(frozen=True, slots=True)
class _ParsedObservations:
    """The observations read so far, flat (one entry each); grouped once at the end."""

    q_rows: list[list[float]] = field(default_factory=list)
    obs_group: list[int] = field(default_factory=list)
    obs_sample: list[int] = field(default_factory=list)
    rows: list[Any] = field(default_factory=list)
    group_of_key: dict[tuple[Any, ...], int] = field(default_factory=dict)
    marker_home: dict[str, tuple[str, str]] = field(default_factory=dict)  # marker -> (frame, at)
    target_home: dict[str, tuple[str | None, str]] = field(default_factory=dict)  # -> (frame, at)
    #: the keys parse read, by kind (for the kinds without file_keys)
    read_keys: dict[str, set[str]] = field(default_factory=dict)
    payloads: list[_PayloadColumns] = field(default_factory=list)  # one, once read


def _read_samples(
    p: ObservationReader, reader: ObservationReader, samples: list[Any], k: int
) -> _ParsedObservations:
    """Read every sample's ``q`` (``k`` values, file units), its payload and its
    observations: in bulk (:func:`_read_samples_in_bulk`, :func:`_payloads_in_bulk`)
    when the file allows, else one at a time."""
    names = tuple(kind.name for kind in kinds())
    expected_kind = (
        ", ".join(repr(n) for n in names[:-1]) + f" or {names[-1]!r}"
        if len(names) > 1
        else repr(names[0])
    )
    bulk = ObservationReader(reader.source, reader.length_unit, reader.default_measured_in)
    bulk.cameras = reader.cameras
    parsed = _read_samples_in_bulk(p, bulk, samples, k, names, expected_kind)
    payloads = None
    if parsed is not None:  # every sample is an object
        payloads = _payloads_in_bulk(bulk, [s.get("payload") for s in samples])
    if parsed is not None and payloads is not None:
        parsed.payloads.append(payloads)
        reader.quaternions += bulk.quaternions
        reader.rounded.extend(bulk.rounded)
        return parsed
    return _read_samples_one_by_one(p, reader, samples, k, names, expected_kind)


def _read_samples_in_bulk(
    p: ObservationReader,
    reader: ObservationReader,
    samples: list[Any],
    k: int,
    names: tuple[str, ...],
    expected_kind: str,
) -> _ParsedObservations | None:
    """:func:`_read_samples_one_by_one`'s result, read in bulk: every ``q`` at once, and
    the observations by their signature (every key but the kinds'
    :attr:`~kinfw.observations.ObservationKind.bulk_keys`, with its value): the first of
    each parsed one at a time, all of them by the kind's
    :meth:`~kinfw.observations.ObservationKind.parse_many`. None when a kind reads one
    at a time, a signature holds other than strings and null, or anything fails a check
    (then the one-by-one reader names the first culprit in file order)."""
    if set(map(type, samples)) != {dict}:
        return None
    qs = p.numbers_many([s.get("q") for s in samples], k)
    lists = [s.get("observations") for s in samples]
    if qs is None or set(map(type, lists)) != {list} or not all(lists):
        return None
    flat = list(chain.from_iterable(lists))
    if set(map(type, flat)) != {dict}:
        return None
    skip = frozenset(chain.from_iterable(kind.bulk_keys for kind in kinds()))
    kept_keys: dict[tuple[str, ...], tuple[str, ...]] = {}
    signature_id: dict[tuple[Any, ...], int] = {}
    first: list[int] = []
    id_list = []
    for o, obs in enumerate(flat):
        keys = tuple(obs)
        kept = kept_keys.get(keys)
        if kept is None:
            kept = kept_keys[keys] = tuple(key for key in keys if key not in skip)
        signature = (keys, *map(obs.__getitem__, kept))
        try:
            sid = signature_id.setdefault(signature, len(signature_id))
        except TypeError:  # a list or object where a string belongs
            return None
        if sid == len(first):
            # only strings and null: a value equal to a string is that string
            if not all(v is None or type(v) is str for v in signature[1:]):
                return None
            first.append(o)
        id_list.append(sid)
    ids = np.array(id_list, dtype=np.intp)
    sample_of = np.repeat(np.arange(len(samples)), list(map(len, lists)))
    parsed = _ParsedObservations(q_rows=qs.tolist(), obs_sample=sample_of.tolist())
    # the first of each signature read (and noted) on its own, as one by one would
    single = ObservationReader(reader.source, reader.length_unit, reader.default_measured_in)
    single.cameras = reader.cameras
    scratch = _ParsedObservations()
    group_of_signature = np.empty(len(first), dtype=np.intp)
    rows: list[Any] = [None] * len(flat)
    by_signature = np.split(np.argsort(ids, kind="stable"), np.cumsum(np.bincount(ids))[:-1])
    try:
        for sid, (o, members) in enumerate(zip(first, by_signature, strict=True)):
            i = int(sample_of[o])  # in file order: groups numbered as one by one
            at = f"samples[{i}].observations[{o - int(np.searchsorted(sample_of, i))}]"
            _read_observation(p, single, flat[o], at, i, names, expected_kind, scratch)
            kind = kind_named(flat[o]["kind"])
            many = kind.parse_many(reader, [flat[m] for m in members])
            if many is None:
                return None
            for m, row in zip(members.tolist(), many.tolist(), strict=True):
                rows[m] = row
            group_of_signature[sid] = scratch.obs_group[-1]
    except DatasetError:
        return None
    parsed.obs_group.extend(group_of_signature[ids].tolist())
    parsed.rows.extend(rows)
    parsed.group_of_key.update(scratch.group_of_key)
    parsed.marker_home.update(scratch.marker_home)
    parsed.read_keys.update(scratch.read_keys)
    return parsed


def _read_samples_one_by_one(
    p: ObservationReader,
    reader: ObservationReader,
    samples: list[Any],
    k: int,
    names: tuple[str, ...],
    expected_kind: str,
) -> _ParsedObservations:
    """Read every sample's ``q``, its payload and its observations, one at a time."""
    payloads = _PayloadColumns.empty(len(samples))
    parsed = _ParsedObservations(payloads=[payloads])
    for i, raw_sample in enumerate(samples):
        at = f"samples[{i}]"
        sample = p.obj(raw_sample, at)
        parsed.q_rows.append(
            p.numbers(
                p.get(sample, "q", at, f"a list of {k} joint values"),
                k,
                f"{at}.q",
                "one per joint_names entry",
            )
        )
        if sample.get("payload") is not None:
            frame, mass, com, inertia = _read_payload(p, reader, sample["payload"], f"{at}.payload")
            payloads.frames[i] = frame
            payloads.mass_kg[i] = mass
            payloads.com_m[i] = com
            payloads.inertia6[i] = inertia
        observations = p.list_of(
            p.get(sample, "observations", at, "a non-empty list of observations"),
            f"{at}.observations",
            "observations",
        )
        for j, raw_obs in enumerate(observations):
            _read_observation(
                p, reader, raw_obs, f"{at}.observations[{j}]", i, names, expected_kind, parsed
            )
    return parsed


def _read_observation(
    p: ObservationReader,
    reader: ObservationReader,
    raw_obs: Any,
    at_obs: str,
    i: int,
    names: tuple[str, ...],
    expected_kind: str,
    parsed: _ParsedObservations,
) -> None:
    """Read one observation of sample ``i`` (at ``at_obs``) by its kind into ``parsed``."""
    obs = p.obj(raw_obs, at_obs)
    frame = p.string(p.get(obs, "frame", at_obs, "the name of a URDF frame"), f"{at_obs}.frame")
    kind = kind_named(p.choice(p.get(obs, "kind", at_obs, expected_kind), f"{at_obs}.kind", names))
    if kind.file_keys is None:  # the keys it knows are those it reads
        recorded = _KeysRead(obs)
        key, row = kind.parse(reader, recorded, at_obs, frame)
        parsed.read_keys.setdefault(kind.name, set()).update(recorded.read)
    else:
        key, row = kind.parse(reader, obs, at_obs, frame)
    for what, attached, homes in (
        ("marker", kind.marker(key), parsed.marker_home),
        ("target", kind.target_of(key), parsed.target_home),
    ):
        if attached is not None:
            _check_one_frame(p, homes, what, attached, at_obs)
    parsed.obs_group.append(
        parsed.group_of_key.setdefault((kind.name, key), len(parsed.group_of_key))
    )
    parsed.obs_sample.append(i)
    parsed.rows.append(row)


def _check_one_frame(
    p: ObservationReader,
    homes: dict[str, tuple[str | None, str]],
    what: str,
    attached: tuple[str, str | None],
    at_obs: str,
) -> None:
    """Raise unless the marker or target ``attached = (name, frame)`` is on the frame it
    was first seen on (frame None: a target fixed in the world), naming both places."""

    def placed(frame: str | None) -> str:
        return "fixed in the world" if frame is None else f"on frame {frame!r}"

    name, frame = attached
    home = homes.setdefault(name, (frame, at_obs))
    if home[0] != frame:
        key = "marker" if what == "marker" else "target_frame"
        raise p.error(
            f"{at_obs}.{key}",
            f"{what} {name!r} is {placed(frame)} here but {placed(home[0])} in {home[1]}; a "
            f"{what} is rigidly attached to one frame (give each its own {what} name)",
        )


def _groups(parsed: _ParsedObservations) -> list[Any]:
    """Build one observation group per (kind, key), its rows in file order."""
    group_ids = np.array(parsed.obs_group)
    rows_of_group = np.split(
        np.argsort(group_ids, kind="stable"), np.cumsum(np.bincount(group_ids))[:-1]
    )
    sample_ids = np.array(parsed.obs_sample, dtype=np.int64)
    groups = []
    for (kind_name, key), members in zip(parsed.group_of_key, rows_of_group, strict=True):
        rows = [parsed.rows[r] for r in members]
        groups.append(kind_named(kind_name).group_from_parsed(key, sample_ids[members], rows))
    return groups


def measurements_from_dict(
    doc: dict[str, Any],
    source: str = "<memory>",
    *,
    cameras: Mapping[str, CameraIntrinsics] | None = None,
) -> Measurements:
    """Validate a parsed ``kinfw-measurements`` document and convert it to SI.

    Parameters
    ----------
    doc : dict
        The JSON document (as from ``json.load``).
    source : str, optional
        Name of the file, for messages.
    cameras : mapping of str to CameraIntrinsics, optional
        Intrinsics that override or add to the document's ``"cameras"`` section.

    Returns
    -------
    Measurements

    Raises
    ------
    DatasetError
        Naming ``source``, the key path and what was expected.
    """
    p = ObservationReader(source)
    if not isinstance(doc, dict):
        raise p.error("", f"expected a JSON object at the top level, got {describe(doc)}")
    length_unit, angle_unit = _read_units(p, doc)
    joint_names, joint_units = _read_joints(p, doc, angle_unit)
    k = len(joint_names)
    default_measured_in = None
    if doc.get("measured_in") is not None:
        default_measured_in = p.string(doc["measured_in"], "measured_in")

    gravity = STANDARD_GRAVITY
    if doc.get("gravity") is not None:
        gravity = p.numbers(doc["gravity"], 3, "gravity", "[gx, gy, gz] m/s^2 in the root frame")

    samples = p.list_of(p.get(doc, "samples", "", "a list of samples"), "samples", "samples")
    reader = ObservationReader(source, length_unit, default_measured_in)
    reader.cameras = _read_cameras(p, doc, cameras)
    parsed = _read_samples(p, reader, samples, k)

    q_rows = parsed.q_rows
    qs = _columns_to_si(np.array(q_rows, dtype=float).reshape(len(q_rows), k), joint_units)
    if reader.rounded:
        warnings.warn(
            f"{source}: {len(reader.rounded)} of {reader.quaternions} quaternions had norms "
            f"off by up to {max(reader.rounded):.2g} (rounded?); renormalised",
            UserWarning,
            stacklevel=2,
        )
    groups = _groups(parsed)
    mounts = mounts_from_dict(reader, doc["mounts"]) if doc.get("mounts") is not None else {}
    out = Measurements(
        joint_names,
        qs,
        source=source,
        cameras=reader.cameras,
        mounts=mounts,
        payloads=parsed.payloads[0].payloads(p),
        gravity=gravity,
    ).with_groups(groups)
    _note_unknown_keys(doc, samples, parsed.read_keys).warn(source)
    logger.debug(
        "%s: %d samples, %d observations in %d groups",
        source,
        out.n_samples,
        len(parsed.obs_group),
        len(parsed.group_of_key),
    )
    return out


# -- writing ---------------------------------------------------------------------------


def measurements_to_dict(measurements: Measurements) -> dict[str, Any]:
    """A ``kinfw-measurements`` version 1 document of a dataset, in SI units.

    Observations of a sample are listed group by group (poses, targets, points). When
    every pose and point group has the same non-root ``measured_in`` it is written once
    at the top level. A sample's ``"payload"`` is written when it has one, the
    ``"gravity"`` when it is not :data:`~kinfw.model.STANDARD_GRAVITY`.

    Parameters
    ----------
    measurements : Measurements

    Returns
    -------
    dict
        JSON-ready (plain lists, floats and strings).

    Raises
    ------
    DatasetError
        If the dataset has no samples or a sample has no observations (the file
        could not be read back).
    """
    m = measurements
    if m.n_samples == 0:
        raise DatasetError(f"{m.source}: cannot write a dataset with no samples")
    per_sample: list[list[dict[str, Any]]] = [[] for _ in range(m.n_samples)]
    frames_in = {kind_of(g).measured_in(g) for g in m.all_groups() if kind_of(g).has_measured_in}
    top_measured_in = next(iter(frames_in)) if len(frames_in) == 1 else None
    cameras = dict(m.cameras)
    for g in m.all_groups():
        for s, obs in kind_of(g).sample_dicts(g, top_measured_in):
            per_sample[s].append(obs)
        cameras.update(kind_of(g).cameras(g))

    empty = [i for i, obs in enumerate(per_sample) if not obs]
    if empty:
        raise DatasetError(
            f"{m.source}: samples[{empty[0]}]: has no observations; every "
            "sample of a file needs at least one (use subset() to drop it)"
        )
    doc: dict[str, Any] = {
        "format": FORMAT,
        "version": SUPPORTED_VERSIONS[-1],
        "units": {"length": "m", "angle": "rad"},
        "joint_names": list(m.joint_names),
    }
    if top_measured_in is not None:
        doc["measured_in"] = top_measured_in
    if not np.array_equal(m.gravity, STANDARD_GRAVITY):
        doc["gravity"] = m.gravity.tolist()
    if cameras:
        doc["cameras"] = {frame: c.to_dict() for frame, c in cameras.items()}
    if m.mounts:
        doc["mounts"] = mounts_to_dict(m.mounts)
    payloads = _payload_dicts(m)
    doc["samples"] = [
        {"q": q, **({} if payload is None else {"payload": payload}), "observations": obs}
        for q, payload, obs in zip(m.qs.tolist(), payloads, per_sample, strict=True)
    ]
    return doc


def _payload_dicts(m: Measurements) -> list[dict[str, Any] | None]:
    """Each sample's ``"payload"`` (SI; ``com`` and ``inertia`` left out where zero), or
    None for a sample without one."""
    if m.payloads is None:
        return [None] * m.n_samples
    p = m.payloads
    inertia = p.inertia_kg_m2.reshape(-1, 9)[:, [0, 1, 2, 4, 5, 8]]
    out: list[dict[str, Any] | None] = []
    for f, mass, com, six in zip(
        p.frame_index.tolist(), p.mass_kg.tolist(), p.com_m.tolist(), inertia.tolist(), strict=True
    ):
        if f < 0:
            out.append(None)
            continue
        payload: dict[str, Any] = {"frame": p.frames[f], "mass_kg": mass}
        if any(com):
            payload["com"] = com
        if any(six):
            payload["inertia"] = six
        out.append(payload)
    return out


def _dumps(doc: dict[str, Any]) -> str:
    """JSON text with one sample's ``q`` and one observation per line."""

    def dump(value: Any) -> str:
        return json.dumps(value, allow_nan=False, ensure_ascii=False)

    lines = [f"  {dump(key)}: {dump(value)}" for key, value in doc.items() if key != "samples"]
    samples = []
    for sample in doc["samples"]:
        extra = "".join(
            f", {dump(key)}: {dump(value)}"
            for key, value in sample.items()
            if key not in ("q", "observations")
        )
        observations = ",\n".join(f"      {dump(obs)}" for obs in sample["observations"])
        samples.append(
            f'    {{"q": {dump(sample["q"])}{extra}, "observations": [\n{observations}\n    ]}}'
        )
    lines.append('  "samples": [\n' + ",\n".join(samples) + "\n  ]")
    return "{\n" + ",\n".join(lines) + "\n}\n"


def write_measurements(path: str | Path, measurements: Measurements) -> None:
    """Write a dataset as a ``kinfw-measurements`` version 1 file in SI units.

    Floats are written with ``repr``, so :func:`read_measurements` gives back ``qs``,
    positions and offsets exactly and transforms to rounding (~1e-16). The file is
    written to a temporary file beside it and then renamed
    (:func:`kinfw.files.write_text_atomic`), so a failed write leaves no half file and
    the previous file, if any, intact.

    Parameters
    ----------
    path : str or Path
        Destination file.
    measurements : Measurements
        The dataset (see :func:`measurements_to_dict` for what cannot be written).
    """
    path = Path(path)
    write_text_atomic(path, _dumps(measurements_to_dict(measurements)))
    logger.debug("wrote %d samples to %s", measurements.n_samples, path)
