"""The calibration sidecar ``CALIBRATED.kinfw.json``: typed, with ``read``/``write``.

``kinfw calibrate`` writes it beside the calibrated URDF: what produced the URDF
(date, kinfw version, method, SHA-256 of the nominal URDF and of the data) and what is
needed to predict measurements that the URDF does not hold: the root's pose in the
measurement frame (``w_T_root``), the calibrated unknowns (target poses, markers, point
offsets, external frames), the noise and the held-out errors. ``kinfw verify`` and
``kinfw view`` read it.

The file is JSON, format ``kinfw-calibration`` version 1 (``docs/conventions.md``);
dictionaries exist only at that edge (:meth:`CalibrationSidecar.from_dict`,
:meth:`CalibrationSidecar.to_dict`). SI inside; a field name says ``mm`` or ``deg`` where
a value in the file is not SI, as in the reports.

The pieces shared with the calibration report (:mod:`kinfw.calibration_report`) live here
too: :class:`DataProvenance`, :class:`NoiseSummary`, :class:`CalibratedUnknown`,
:class:`BeforeAfter`, and the reader :class:`DocReader` whose errors name the file and
the key path (``targets[0].root_T_target``), like :class:`kinfw.measurements.DatasetError`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.files import json_text, write_text_atomic

__all__ = [
    "BeforeAfter",
    "CalibratedUnknown",
    "CalibrationFileError",
    "CalibrationSidecar",
    "DataProvenance",
    "DocReader",
    "ModelSummary",
    "NoiseSummary",
    "read_sidecar",
    "write_sidecar",
]


class CalibrationFileError(ValueError):
    """A calibration sidecar or report that cannot be read.

    The message names the file, the key path (``unknowns[2].value``) and what was
    expected.
    """


def _short(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, str) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


@dataclass(frozen=True, slots=True)
class DocReader:
    """Typed access to a parsed JSON document; every error names ``source`` and the key.

    ``at`` is the key path of the object being read (``""`` for the top level).
    """

    source: str

    def fail(self, at: str, expected: str, got: Any = ...) -> CalibrationFileError:
        where = at or "top level"
        tail = "" if got is ... else f", got {_short(got)}"
        return CalibrationFileError(f"{self.source}: {where}: expected {expected}{tail}")

    @staticmethod
    def path(at: str, key: str | int) -> str:
        if isinstance(key, int):
            return f"{at}[{key}]"
        return f"{at}.{key}" if at else key

    def obj(self, value: Any, at: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(at, "an object", value)
        return value

    def value(self, doc: dict[str, Any], key: str, at: str, *, optional: bool = False) -> Any:
        if key not in doc:
            if optional:
                return None
            raise self.fail(self.path(at, key), "a value (the key is missing)")
        return doc[key]

    def string(
        self, doc: dict[str, Any], key: str, at: str, *, optional: bool = False
    ) -> str | None:
        v = self.value(doc, key, at, optional=optional)
        if v is None and optional:
            return None
        if not isinstance(v, str):
            raise self.fail(self.path(at, key), "a string" + (" or null" if optional else ""), v)
        return v

    def number(
        self, doc: dict[str, Any], key: str, at: str, *, optional: bool = False
    ) -> float | None:
        """A number; null is NaN (the reports write an undefined number, a point's
        rotation, as null), or None with ``optional``."""
        v = self.value(doc, key, at, optional=optional)
        if v is None:
            return None if optional else math.nan
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.fail(self.path(at, key), "a number" + (" or null" if optional else ""), v)
        return float(v)

    def integer(self, doc: dict[str, Any], key: str, at: str) -> int:
        v = self.value(doc, key, at)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(self.path(at, key), "an integer", v)
        return v

    def boolean(self, doc: dict[str, Any], key: str, at: str) -> bool:
        v = self.value(doc, key, at)
        if not isinstance(v, bool):
            raise self.fail(self.path(at, key), "true or false", v)
        return v

    def items(
        self, doc: dict[str, Any], key: str, at: str, *, optional: bool = False
    ) -> list[Any] | None:
        v = self.value(doc, key, at, optional=optional)
        if v is None and optional:
            return None
        if not isinstance(v, list):
            raise self.fail(self.path(at, key), "a list" + (" or null" if optional else ""), v)
        return v

    def array(
        self, value: Any, at: str, shape: tuple[int, ...] | None = None, *, allow_null: bool = False
    ) -> NDArray[np.float64]:
        """Nested lists of numbers as a float array (``shape`` checked when given);
        with ``allow_null`` a null entry is NaN."""
        what = f"an array of shape {shape}" if shape else "an array of numbers"
        try:
            if allow_null:
                value = _nulls_to_nan(value)
            a = np.array(value, dtype=float)
        except (TypeError, ValueError):
            raise self.fail(at, what, value) from None
        if isinstance(value, bool | str | dict) or (shape is not None and a.shape != shape):
            raise self.fail(at, what, value)
        if not allow_null and not np.all(np.isfinite(a)):
            raise self.fail(at, what + " (finite)", value)
        return a

    def strings(self, doc: dict[str, Any], key: str, at: str) -> tuple[str, ...]:
        v = self.items(doc, key, at)
        if not all(isinstance(s, str) for s in v):
            raise self.fail(self.path(at, key), "a list of strings", v)
        return tuple(v)

    def header(self, doc: Any, fmt: str, version: int) -> dict[str, Any]:
        doc = self.obj(doc, "")
        if doc.get("format") != fmt:
            raise self.fail("format", f"{fmt!r} (is this a {fmt} file?)", doc.get("format"))
        if doc.get("version") != version:
            raise self.fail(
                "version",
                f"{version} (this kinfw reads {fmt} version {version})",
                doc.get("version"),
            )
        return doc


def _nulls_to_nan(value: Any) -> Any:
    if value is None:
        return math.nan
    if isinstance(value, list):
        return [_nulls_to_nan(v) for v in value]
    return value


def _array(
    value: ArrayLike, name: str, shape: tuple[int, ...] | None = None
) -> NDArray[np.float64]:
    a = np.array(value, dtype=float)
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    a.flags.writeable = False
    return a


# -- pieces shared with the report ------------------------------------------------------
@dataclass(frozen=True, slots=True)
class DataProvenance:
    """The calibration data: where it came from, its size and the file's SHA-256."""

    source: str
    n_samples: int
    sha256: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "n_samples": self.n_samples, "sha256": self.sha256}

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> DataProvenance:
        doc = reader.obj(doc, at)
        return cls(
            reader.string(doc, "source", at),
            reader.integer(doc, "n_samples", at),
            reader.string(doc, "sha256", at, optional=True),
        )


@dataclass(frozen=True, slots=True)
class ModelSummary:
    """The model the refinement fitted: its parameter set and prior, and why.

    Attributes
    ----------
    parameters : tuple of str
        ``("full",)``, ``("offsets",)``, ``("frames",)``, ``("none",)`` or joint names.
    prior_m, prior_rad : float or None
        Sigmas of the Gaussian prior on the deviations from the nominal (m; rad), None
        without a prior.
    reason : str
        ``"given"`` (by the caller, ``--params`` / ``--prior-*``) or the model choice's
        one-line reason (:class:`verification.model_choice.ModelChoice`).
    """

    parameters: tuple[str, ...]
    prior_m: float | None
    prior_rad: float | None
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameters": list(self.parameters),
            "prior_mm": None if self.prior_m is None else 1e3 * self.prior_m,
            "prior_deg": None if self.prior_rad is None else math.degrees(self.prior_rad),
            "reason": self.reason,
        }

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> ModelSummary:
        doc = reader.obj(doc, at)
        mm = reader.number(doc, "prior_mm", at, optional=True)
        deg = reader.number(doc, "prior_deg", at, optional=True)
        if (mm is None) != (deg is None):
            raise reader.fail(reader.path(at, "prior_mm"), "prior_mm and prior_deg both or neither")
        return cls(
            reader.strings(doc, "parameters", at),
            None if mm is None else 1e-3 * mm,
            None if deg is None else math.radians(deg),
            reader.string(doc, "reason", at),
        )


@dataclass(frozen=True, slots=True)
class NoiseSummary:
    """The noise that whitened the residuals: one sigma per noise component.

    Attributes
    ----------
    sigmas : tuple of (str, float)
        ``(component, sigma)`` in SI (m, or rad per small-angle orientation component),
        as :class:`identification.problem.NoiseModel`.
    estimated : bool
        True when estimated from the residuals rather than given.
    """

    sigmas: tuple[tuple[str, float], ...]
    estimated: bool

    NOTE: ClassVar[str] = (
        "weights: 1/sigma^2 per position component (mm) and per small-angle orientation "
        "component (an angle sigma of s about a random axis is s/sqrt(3) per component)"
    )

    def of(self, name: str) -> float | None:
        """The sigma of a component (SI), None when the calibration has no such rows."""
        return dict(self.sigmas).get(name)

    @property
    def position_sigma_mm(self) -> float | None:
        sigma = self.of("position")
        return None if sigma is None else 1e3 * sigma

    @property
    def rotation_sigma_deg_per_component(self) -> float | None:
        sigma = self.of("rotation")
        return None if sigma is None else float(np.degrees(sigma))

    def to_dict(self) -> dict[str, Any]:
        return {
            "position_sigma_mm": self.position_sigma_mm,
            "rotation_sigma_deg_per_component": self.rotation_sigma_deg_per_component,
            "estimated": self.estimated,
            "sigma_per_component": dict(self.sigmas),
            "note": self.NOTE,
        }

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> NoiseSummary:
        doc = reader.obj(doc, at)
        estimated = reader.boolean(doc, "estimated", at)
        per = reader.value(doc, "sigma_per_component", at, optional=True)
        if per is not None:
            per_at = reader.path(at, "sigma_per_component")
            per = reader.obj(per, per_at)
            return cls(tuple((k, reader.number(per, k, per_at)) for k in per), estimated)
        # older files: the two built-in components only, in mm and deg
        mm = reader.number(doc, "position_sigma_mm", at)
        deg = reader.number(doc, "rotation_sigma_deg_per_component", at)
        return cls((("position", 1e-3 * mm), ("rotation", math.radians(deg))), estimated)


@dataclass(frozen=True, slots=True, eq=False)
class CalibratedUnknown:
    """A rigid frame or point the calibration estimated besides the kinematics.

    Attributes
    ----------
    kind : str
        Parameter block kind: ``"target"`` (value ``root_T_target``), ``"frame"``
        (``meas_T_root`` of an external measurement frame), ``"marker"``
        (``frame_T_marker``), ``"offset"`` (``frame_p_point``, name ``frame:marker``),
        or a new observation kind's own.
    name : str
    value : ndarray, shape (4, 4) or (3,)
        The estimate, metres.
    """

    kind: str
    name: str
    value: NDArray[np.float64]

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", _array(self.value, f"unknown {self.kind}:{self.name}"))

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "name": self.name, "value": self.value.tolist()}

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> CalibratedUnknown:
        doc = reader.obj(doc, at)
        return cls(
            reader.string(doc, "kind", at),
            reader.string(doc, "name", at),
            reader.array(reader.value(doc, "value", at), reader.path(at, "value")),
        )


@dataclass(frozen=True, slots=True)
class BeforeAfter:
    """One observation group's RMS errors before and after calibration (NaN rotation for
    groups without orientation)."""

    group: str
    n: int
    before_position_rms_mm: float
    after_position_rms_mm: float
    before_rotation_rms_deg: float
    after_rotation_rms_deg: float

    _KEYS: ClassVar[tuple[str, ...]] = (
        "before_position_rms_mm",
        "after_position_rms_mm",
        "before_rotation_rms_deg",
        "after_rotation_rms_deg",
    )

    def to_dict(self) -> dict[str, Any]:
        return {"group": self.group, "n": self.n, **{k: getattr(self, k) for k in self._KEYS}}

    @classmethod
    def from_dict(cls, doc: Any, reader: DocReader, at: str) -> BeforeAfter:
        doc = reader.obj(doc, at)
        return cls(
            reader.string(doc, "group", at),
            reader.integer(doc, "n", at),
            *(reader.number(doc, k, at) for k in cls._KEYS),
        )

    @classmethod
    def rows_from(cls, docs: Any, reader: DocReader, at: str) -> tuple[BeforeAfter, ...]:
        if not isinstance(docs, list):
            raise reader.fail(at, "a list", docs)
        return tuple(cls.from_dict(d, reader, f"{at}[{k}]") for k, d in enumerate(docs))


# -- the sidecar ------------------------------------------------------------------------
@dataclass(frozen=True, slots=True, eq=False)
class CalibrationSidecar:
    """Provenance and the calibrated unknowns of a calibrated URDF (its ``.kinfw.json``).

    Attributes
    ----------
    created : str
        ISO 8601 date and time (UTC) of the calibration.
    kinfw_version : str
    method : str
        ``"refine"`` or ``"closed-form"``.
    calibrated_urdf : str
        File name of the calibrated URDF (beside the sidecar).
    nominal_urdf, nominal_urdf_sha256 : str or None
        Path and SHA-256 of the nominal URDF (None for a built-in or in-memory one).
    data : DataProvenance
    w_T_root : ndarray, shape (4, 4)
        Pose of the URDF root in the measurement frame, metres (identity when the root is
        the measurement frame).
    measurement_frame : str or None
        The external measurement frame the model was expressed in, None for the root.
    noise : NoiseSummary or None
        None without the joint refinement.
    unknowns : tuple of CalibratedUnknown
        Refined target poses, markers, point offsets, external frames.
    hand_eye_targets : tuple of (str, ndarray (4, 4))
        ``(target, root_T_target)`` of the hand-eye step (before the refinement).
    errors_held_out : tuple of BeforeAfter or None
        Errors on held-out data, when the calibration had some.
    model : ModelSummary or None
        The refinement's parameter set and prior, and why (None without the refinement,
        and in files written before it was recorded).
    """

    created: str
    kinfw_version: str
    method: str
    calibrated_urdf: str
    nominal_urdf: str | None
    nominal_urdf_sha256: str | None
    data: DataProvenance
    w_T_root: NDArray[np.float64]
    measurement_frame: str | None = None
    noise: NoiseSummary | None = None
    unknowns: tuple[CalibratedUnknown, ...] = ()
    hand_eye_targets: tuple[tuple[str, NDArray[np.float64]], ...] = ()
    errors_held_out: tuple[BeforeAfter, ...] | None = None
    model: ModelSummary | None = None

    FORMAT: ClassVar[str] = "kinfw-calibration"
    VERSION: ClassVar[int] = 1
    source: str = field(default="<memory>", compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "w_T_root", _array(self.w_T_root, "w_T_root", (4, 4)))
        object.__setattr__(self, "unknowns", tuple(self.unknowns))
        object.__setattr__(
            self,
            "hand_eye_targets",
            tuple(
                (str(t), _array(T, f"hand_eye_targets[{t!r}]", (4, 4)))
                for t, T in self.hand_eye_targets
            ),
        )
        if self.errors_held_out is not None:
            object.__setattr__(self, "errors_held_out", tuple(self.errors_held_out))

    def known_frames(self) -> dict[tuple[str, str], NDArray[np.float64]]:
        """The unknowns this calibration provides, keyed ``(kind, name)``:
        ``("frame", name)``: ``meas_T_root``; ``("target", name)``: ``root_T_target``
        (the refined one when there is one, else the hand-eye one); ``("marker",
        name)``: ``frame_T_marker``; ``("offset", "frame:marker")``: ``frame_p_point``;
        and any other kind's unknowns."""
        known: dict[tuple[str, str], NDArray[np.float64]] = {
            ("target", t): T for t, T in self.hand_eye_targets
        }
        known.update({(u.kind, u.name): u.value for u in self.unknowns})
        if self.measurement_frame:
            known[("frame", self.measurement_frame)] = self.w_T_root
        return known

    @property
    def root_T_targets(self) -> tuple[tuple[str, NDArray[np.float64]], ...]:
        """``(target, root_T_target)`` of every target, as calibrated (refined when
        refined, else from the hand-eye step), in the order of first appearance."""
        known = self.known_frames()
        names = dict.fromkeys(
            [t for t, _ in self.hand_eye_targets]
            + [u.name for u in self.unknowns if u.kind == "target"]
        )
        return tuple((t, known[("target", t)]) for t in names)

    def to_dict(self) -> dict[str, Any]:
        """The JSON document (``kinfw-calibration`` v1)."""
        return {
            "format": self.FORMAT,
            "version": self.VERSION,
            "created": self.created,
            "kinfw_version": self.kinfw_version,
            "method": self.method,
            "calibrated_urdf": self.calibrated_urdf,
            "nominal_urdf": {"path": self.nominal_urdf, "sha256": self.nominal_urdf_sha256},
            "data": self.data.to_dict(),
            "w_T_root": self.w_T_root.tolist(),
            "measurement_frame": self.measurement_frame,
            "noise": None if self.noise is None else self.noise.to_dict(),
            "unknowns": [u.to_dict() for u in self.unknowns],
            "targets": [
                {"target": t, "root_T_target": T.tolist()} for t, T in self.hand_eye_targets
            ],
            "errors_held_out": None
            if self.errors_held_out is None
            else [row.to_dict() for row in self.errors_held_out],
        } | ({} if self.model is None else {"model": self.model.to_dict()})

    @classmethod
    def from_dict(cls, doc: Any, source: str = "<memory>") -> CalibrationSidecar:
        """Read a parsed ``kinfw-calibration`` v1 document.

        Raises
        ------
        CalibrationFileError
            Naming ``source``, the key and what was expected.
        """
        r = DocReader(source)
        doc = r.header(doc, cls.FORMAT, cls.VERSION)
        nominal = r.obj(r.value(doc, "nominal_urdf", ""), "nominal_urdf")
        noise = r.value(doc, "noise", "", optional=True)
        targets = []
        for k, t in enumerate(r.items(doc, "targets", "", optional=True) or []):
            at = f"targets[{k}]"
            t = r.obj(t, at)
            targets.append(
                (
                    r.string(t, "target", at),
                    r.array(r.value(t, "root_T_target", at), f"{at}.root_T_target", (4, 4)),
                )
            )
        held_out = r.value(doc, "errors_held_out", "", optional=True)
        model = r.value(doc, "model", "", optional=True)
        return cls(
            created=r.string(doc, "created", ""),
            kinfw_version=r.string(doc, "kinfw_version", ""),
            method=r.string(doc, "method", ""),
            calibrated_urdf=r.string(doc, "calibrated_urdf", ""),
            nominal_urdf=r.string(nominal, "path", "nominal_urdf", optional=True),
            nominal_urdf_sha256=r.string(nominal, "sha256", "nominal_urdf", optional=True),
            data=DataProvenance.from_dict(r.value(doc, "data", ""), r, "data"),
            w_T_root=r.array(r.value(doc, "w_T_root", ""), "w_T_root", (4, 4)),
            measurement_frame=r.string(doc, "measurement_frame", "", optional=True),
            noise=None if noise is None else NoiseSummary.from_dict(noise, r, "noise"),
            unknowns=tuple(
                CalibratedUnknown.from_dict(u, r, f"unknowns[{k}]")
                for k, u in enumerate(r.items(doc, "unknowns", "", optional=True) or [])
            ),
            hand_eye_targets=tuple(targets),
            errors_held_out=None
            if held_out is None
            else BeforeAfter.rows_from(held_out, r, "errors_held_out"),
            model=None if model is None else ModelSummary.from_dict(model, r, "model"),
            source=source,
        )


def read_sidecar(path: str | Path) -> CalibrationSidecar:
    """Read a calibration sidecar (``*.kinfw.json``).

    Raises
    ------
    CalibrationFileError
        If the file is not JSON or not a ``kinfw-calibration`` v1 document (the message
        names the file and the key).
    OSError
        If the file cannot be read.
    """
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CalibrationFileError(
            f"{path}: not JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None
    return CalibrationSidecar.from_dict(doc, str(path))


def write_sidecar(path: str | Path, sidecar: CalibrationSidecar) -> Path:
    """Write ``sidecar`` as JSON (indented, atomically: :func:`kinfw.files.write_text_atomic`)."""
    return write_text_atomic(path, json_text(sidecar.to_dict()) + "\n")
