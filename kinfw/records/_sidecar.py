"""The calibration sidecar ``CALIBRATED.kinfw.json``: typed, with ``read``/``write``.

``kinfw calibrate`` writes it beside the calibrated URDF: what produced the URDF
(date, kinfw version, method, SHA-256 of the nominal URDF and of the data) and what is
needed to predict measurements that the URDF does not hold: the root's pose in the
measurement frame (``w_T_root``), the calibrated unknowns (target poses, markers, point
offsets, external frames), the noise and the held-out errors. ``kinfw verify`` and
``kinfw view`` read it; ``kinfw verify`` refuses one that is not the calibration of the
URDF it is given (:meth:`CalibrationSidecar.check_urdf`: the SHA-256s differ).

The file is JSON, format ``kinfw-calibration`` version 1 (``docs/conventions.md``);
dictionaries exist only at that edge (:meth:`CalibrationSidecar.from_dict`,
:meth:`CalibrationSidecar.to_dict`). SI inside; a field name says ``mm`` or ``deg`` where
a value in the file is not SI, as in the reports.

The records shared with the calibration report (:class:`DataProvenance`,
:class:`NoiseSummary`, :class:`CalibratedUnknown`, :class:`BeforeAfter`,
:class:`ModelSummary`: :mod:`kinfw.records`) and the reader :class:`DocReader`
with its :class:`CalibrationFileError` (:mod:`kinfw.records`) are importable from here
too.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from kinfw.files import json_text, write_text_atomic
from kinfw.records._doc_reader import CalibrationFileError, DocReader
from kinfw.records._records import (
    BeforeAfter,
    CalibratedUnknown,
    DataProvenance,
    GuardSummary,
    ModelSummary,
    NoiseSummary,
    RobotBlockRecord,
    read_only_array,
)

if TYPE_CHECKING:
    from kinfw.model import ModelSpec


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
    calibrated_urdf_sha256 : str or None
        SHA-256 of the calibrated URDF as written (None in files written before it was
        recorded).
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
    guard : GuardSummary or None
        The plausibility guard's bound and outcome, and whether large changes were
        allowed (None in files written before it was recorded).
    robot_blocks : tuple of RobotBlockRecord
        The calibrated model spec (``--model compliance``...): what the URDF cannot hold;
        :meth:`spec` rebuilds it. Empty for a URDF alone.
    gravity : ndarray, shape (3,), or None
        The calibration data's gravity in the root frame (m/s^2) when it was not the
        standard 9.81 along -z (None): what ``kinfw reach`` deflects a compliance under.
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
    calibrated_urdf_sha256: str | None = None
    guard: GuardSummary | None = None
    robot_blocks: tuple[RobotBlockRecord, ...] = ()
    gravity: NDArray[np.float64] | None = None

    FORMAT: ClassVar[str] = "kinfw-calibration"
    VERSION: ClassVar[int] = 1
    source: str = field(default="<memory>", compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "w_T_root", read_only_array(self.w_T_root, "w_T_root", (4, 4)))
        object.__setattr__(self, "unknowns", tuple(self.unknowns))
        object.__setattr__(self, "robot_blocks", tuple(self.robot_blocks))
        if self.gravity is not None:
            object.__setattr__(self, "gravity", read_only_array(self.gravity, "gravity", (3,)))
        object.__setattr__(
            self,
            "hand_eye_targets",
            tuple(
                (str(t), read_only_array(T, f"hand_eye_targets[{t!r}]", (4, 4)))
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

    def spec(self) -> ModelSpec:
        """The calibrated model spec (:class:`kinfw.model.ModelSpec`) of
        :attr:`robot_blocks`, to put beside the calibrated URDF
        (:meth:`kinfw.model.Robot.with_spec`).

        Raises
        ------
        CalibrationFileError
            Naming the sidecar and the block: a block name no registered block has (a
            plugin's, not installed), or values of the wrong size.
        """
        from kinfw.model import ModelSpec

        try:
            return ModelSpec.from_list(
                [{"block": r.spec, "values": r.values} for r in self.robot_blocks], self.source
            )
        except ValueError as exc:
            raise CalibrationFileError(f"robot_blocks: {exc}") from None

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

    def check_urdf(self, urdf: str | Path) -> CalibrationSidecar:
        """Return the sidecar when it belongs to the URDF file ``urdf``: the file's
        SHA-256 is the calibrated URDF's recorded in the sidecar, or the nominal's it was
        calibrated from. A sidecar written before the calibrated URDF's SHA-256 was
        recorded cannot be checked and is returned as it is.

        Raises
        ------
        CalibrationFileError
            Naming the sidecar and ``urdf``, then (on later lines) each file and its
            SHA-256: the sidecar is the calibration of another URDF.
        """
        if self.calibrated_urdf_sha256 is None:
            return self
        sha = hashlib.sha256(Path(urdf).read_bytes()).hexdigest()
        if sha in (self.calibrated_urdf_sha256, self.nominal_urdf_sha256):
            return self
        recorded = [f"  {urdf}: sha256 {sha}"]
        recorded.append(
            f"  calibrated URDF {self.calibrated_urdf} (recorded in the sidecar): "
            f"sha256 {self.calibrated_urdf_sha256}"
        )
        if self.nominal_urdf_sha256 is not None:
            recorded.append(
                f"  nominal URDF {self.nominal_urdf} (recorded in the sidecar): "
                f"sha256 {self.nominal_urdf_sha256}"
            )
        raise CalibrationFileError(
            f"{self.source}: the calibration of another URDF, not {urdf} (their SHA-256s "
            "differ); give the sidecar written with it, or none\n" + "\n".join(recorded)
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON document (``kinfw-calibration`` v1)."""
        doc = {
            "format": self.FORMAT,
            "version": self.VERSION,
            "created": self.created,
            "kinfw_version": self.kinfw_version,
            "method": self.method,
            "calibrated_urdf": self.calibrated_urdf,
            **(
                {}
                if self.calibrated_urdf_sha256 is None
                else {"calibrated_urdf_sha256": self.calibrated_urdf_sha256}
            ),
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
        }
        return (
            doc
            | ({} if self.model is None else {"model": self.model.to_dict()})
            | ({} if self.guard is None else {"guard": self.guard.to_dict()})
            | (
                {"robot_blocks": [r.to_dict() for r in self.robot_blocks]}
                if self.robot_blocks
                else {}
            )
            | ({} if self.gravity is None else {"gravity": self.gravity.tolist()})
        )

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
        guard = r.value(doc, "guard", "", optional=True)
        return cls(
            created=r.string(doc, "created", ""),
            kinfw_version=r.string(doc, "kinfw_version", ""),
            method=r.string(doc, "method", ""),
            calibrated_urdf=r.string(doc, "calibrated_urdf", ""),
            calibrated_urdf_sha256=r.string(doc, "calibrated_urdf_sha256", "", optional=True),
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
            guard=None if guard is None else GuardSummary.from_dict(guard, r, "guard"),
            robot_blocks=tuple(
                RobotBlockRecord.from_dict(b, r, f"robot_blocks[{k}]")
                for k, b in enumerate(r.items(doc, "robot_blocks", "", optional=True) or [])
            ),
            gravity=None
            if doc.get("gravity") is None
            else r.array(r.value(doc, "gravity", ""), "gravity", (3,)),
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
