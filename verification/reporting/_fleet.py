"""Calibrate a fleet: many robots' datasets with the same options, one calibrated URDF and
report per robot and a summary (``kinfw fleet``, :func:`calibrate_fleet`).

The layout (:func:`fleet_members`): each robot is one measurement file. Its nominal URDF
is the one given for the whole fleet, else the one ``*.urdf`` file beside its measurement
file (a folder per robot: ``robots/NAME/robot.urdf`` + ``robots/NAME/data.json``). Its
name is the measurement file's stem, or, when two files share a stem (``data.json`` in
each folder), its folder's name. The robots are calibrated independently, in this
process or as tasks of an executor (a process pool, a Dask scheduler's workers:
:func:`kinfw.verification.evaluation.open_executor`); the files and data travel to the
tasks pickled and every file is written here, so the workers need no shared files, and
the outputs are the same wherever the tasks ran.

Outputs in the fleet's folder: per robot ``NAME/calibrated.urdf`` with its sidecar
``NAME/calibrated.kinfw.json`` and ``NAME/report.json`` (what ``kinfw calibrate --out
NAME/calibrated.urdf --report NAME/report.json`` writes), and ``summary.json``
(:meth:`FleetResult.to_dict`). A robot whose files or data are bad, or whose calibration
fails, is a failed row with its error; the others go on.
"""

from __future__ import annotations

import dataclasses
import glob
import logging
import math
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from kinfw.files import check_output_dir, json_text, write_text_atomic
from kinfw.identification.checks import ImplausibleCalibrationError
from kinfw.measurements import Measurements, mounted_robot, read_measurements
from kinfw.model import Robot, load_robot
from kinfw.records import BeforeAfter, ErrorValue, ModelSummary, write_report
from kinfw.verification.evaluation import run_trials
from kinfw.verification.reporting._calibrate import CalibrationResult, calibrate_and_report
from kinfw.verification.reporting._report import file_sha256

#: The summary file in the fleet's folder; each robot's files are in ``NAME/``.
FLEET_SUMMARY = "summary.json"
CALIBRATED_URDF = "calibrated.urdf"
REPORT = "report.json"


# -- the robots ----------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class FleetMember:
    """One robot of a fleet.

    Attributes
    ----------
    name : str
        Its name in the summary and its folder among the outputs.
    urdf : Path
        Its nominal URDF.
    data : Path
        Its measurement file (``kinfw-measurements``).
    """

    name: str
    urdf: Path
    data: Path


def _measurement_file(folder: Path) -> Path:
    """The one measurement file (``*.json`` but a sidecar ``*.kinfw.json``) of a robot's
    folder."""
    found = sorted(
        p for p in folder.glob("*.json") if p.is_file() and not p.name.endswith(".kinfw.json")
    )
    if len(found) != 1:
        listed = ", ".join(p.name for p in found) or "none"
        raise ValueError(
            f"{folder}: expected one measurement file (*.json) in a robot's folder, found "
            f"{listed}; name the files with a pattern instead, e.g. '{folder.parent}/*/data.json'"
        )
    return found[0]


def _nominal_urdf(data: Path) -> Path:
    """The one ``*.urdf`` beside a measurement file."""
    found = sorted(p for p in data.parent.glob("*.urdf") if p.is_file())
    if len(found) != 1:
        listed = ", ".join(p.name for p in found) or "none"
        raise ValueError(
            f"{data}: expected one nominal URDF (*.urdf) beside it, found {listed}; put it "
            "there or give one URDF for the whole fleet (--urdf)"
        )
    return found[0]


def _expand(source: str | os.PathLike[str]) -> list[Path]:
    """The measurement files a source names: itself, a glob pattern's matches (sorted),
    or the one measurement file in each subfolder of a folder (sorted)."""
    text = os.fspath(source)
    if any(c in text for c in "*?["):
        # glob.glob: a pattern may be absolute, which Path.glob does not take
        matches = glob.glob(text, recursive=True)  # noqa: PTH207
        found = sorted(Path(p) for p in matches if Path(p).is_file())
        if not found:
            raise ValueError(f"{text!r}: matches no file")
        return found
    path = Path(text)
    if path.is_dir():
        folders = sorted(p for p in path.iterdir() if p.is_dir() and not p.name.startswith("."))
        if not folders:
            raise ValueError(f"{path}: a folder of robots holds one folder per robot; it has none")
        return [_measurement_file(f) for f in folders]
    if not path.is_file():
        raise ValueError(f"{path}: no such measurement file or folder")
    return [path]


def fleet_members(
    sources: Sequence[str | os.PathLike[str]], *, urdf: str | os.PathLike[str] | None = None
) -> tuple[FleetMember, ...]:
    """The robots of a fleet, from measurement files, glob patterns of them or folders.

    Parameters
    ----------
    sources : sequence of path or str
        Each a measurement file, a glob pattern (``"robots/*/data.json"``, expanded here,
        sorted; ``**`` recurses) or a folder holding one folder per robot (each with one
        measurement file, ``*.json``). A file named twice counts once.
    urdf : path, optional
        The nominal URDF of every robot; default the one ``*.urdf`` file beside each
        measurement file.

    Returns
    -------
    tuple of FleetMember
        In the order of ``sources``. Named by the measurement file's stem, or by its
        folder's name when two files share a stem.

    Raises
    ------
    ValueError
        A source names nothing; ``urdf`` is not a file; a robot's folder has no or
        several measurement files or URDFs; two robots have the same name (the message
        names both files).
    """
    if urdf is not None and not Path(urdf).is_file():
        raise ValueError(f"{urdf}: no such URDF file")
    files: dict[Path, Path] = {}
    for source in sources:
        for path in _expand(source):
            files.setdefault(path.resolve(), path)
    if not files:
        raise ValueError("no measurement files given")
    datas = list(files.values())
    stems = [p.stem for p in datas]
    names = stems if len(set(stems)) == len(stems) else [p.resolve().parent.name for p in datas]
    seen: dict[str, Path] = {}
    for name, path in zip(names, datas, strict=True):
        if name in seen:
            raise ValueError(
                f"two robots named {name!r}: {seen[name]} and {path} (a robot is named after "
                "its measurement file, or its folder when the files share a name)"
            )
        seen[name] = path
    return tuple(
        FleetMember(name, Path(urdf) if urdf is not None else _nominal_urdf(path), path)
        for name, path in zip(names, datas, strict=True)
    )


# -- the summary ---------------------------------------------------------------------------
def _pooled_rms(rows: Sequence[BeforeAfter]) -> tuple[tuple[ErrorValue, ErrorValue], ...]:
    """Per RMS metric of any group (a group metric's one number is left out), the RMS
    over every observation of all groups, before and after: the groups' RMS pooled by
    their counts, ``sqrt(sum n_g rms_g^2 / sum n_g)``."""
    sums: dict[str, list] = {}
    for row in rows:
        for b, a in zip(row.before, row.after, strict=True):
            if b.stat != "rms":
                continue
            entry = sums.setdefault(b.key, [b, 0.0, 0.0, 0])
            entry[1] += row.n * b.value**2
            entry[2] += row.n * a.value**2
            entry[3] += row.n
    return tuple(
        (v.with_value(math.sqrt(sb / n)), v.with_value(math.sqrt(sa / n)))
        for v, sb, sa, n in sums.values()
    )


@dataclass(frozen=True, slots=True)
class FleetRow:
    """One robot of a calibrated fleet: its summary, or why it failed.

    Attributes
    ----------
    name : str
    urdf, data : str
        Its nominal URDF and measurement file.
    error : str or None
        None when calibrated; else the one-line reason (a file that cannot be read, data
        the calibration refuses, an output that cannot be written; an unexpected
        error is prefixed with its type).
    warnings : tuple of str
        What its calibration warned about (kinfw's Python warnings and logged warnings,
        each once, in order), wherever it ran.
    n_samples : int or None
        Samples of its data (None when the data could not be read).
    model : ModelSummary or None
        The parameter set and prior fitted, and why (the model choice's reason).
    rms : tuple of (ErrorValue, ErrorValue)
        Per RMS metric of its data (``position`` mm, ``rotation`` deg, ``pixel`` px, ...),
        before and after calibration, in-sample, over all its observation groups
        (pooled by their counts).

    A calibrated robot's files are ``NAME/calibrated.urdf`` (+ sidecar) and
    ``NAME/report.json`` in the fleet's folder.
    """

    name: str
    urdf: str
    data: str
    error: str | None = None
    warnings: tuple[str, ...] = ()
    n_samples: int | None = None
    model: ModelSummary | None = None
    rms: tuple[tuple[ErrorValue, ErrorValue], ...] = ()

    @property
    def ok(self) -> bool:
        return self.error is None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready; the outputs' paths relative to the fleet's folder."""
        return {
            "robot": self.name,
            "status": "calibrated" if self.ok else "failed",
            "error": self.error,
            "warnings": list(self.warnings),
            "urdf": self.urdf,
            "data": self.data,
            "n_samples": self.n_samples,
            "model": None if self.model is None else self.model.to_dict(),
            "rms_in_sample": {
                key: value
                for b, a in self.rms
                for key, value in ((f"before_{b.key}", b.value), (f"after_{a.key}", a.value))
            },
            "calibrated_urdf": f"{self.name}/{CALIBRATED_URDF}" if self.ok else None,
            "report": f"{self.name}/{REPORT}" if self.ok else None,
        }


@dataclass(frozen=True, slots=True)
class FleetResult:
    """A calibrated fleet (:func:`calibrate_fleet`).

    Attributes
    ----------
    rows : tuple of FleetRow
        One per robot, in the order of the members.
    out_dir : str
        The fleet's folder.
    """

    rows: tuple[FleetRow, ...]
    out_dir: str

    FORMAT: ClassVar[str] = "kinfw-fleet-summary"
    VERSION: ClassVar[int] = 1

    @property
    def failed(self) -> tuple[FleetRow, ...]:
        return tuple(r for r in self.rows if not r.ok)

    def to_dict(self) -> dict[str, Any]:
        """What ``summary.json`` holds (format ``kinfw-fleet-summary`` v1)."""
        return {
            "format": self.FORMAT,
            "version": self.VERSION,
            "n_robots": len(self.rows),
            "n_failed": len(self.failed),
            "robots": [r.to_dict() for r in self.rows],
        }


# -- the calibration -----------------------------------------------------------------------
def _error_text(exc: Exception) -> str:
    """A user error's message (ValueError, OSError: bad files or data), else the type
    too (an unexpected error)."""
    # an error of a first line and details (the plausibility guard's): the first line,
    # the details are kinfw calibrate's on that robot
    text = " ".join((str(exc).strip().splitlines() or [""])[0].split())
    return text if isinstance(exc, ValueError | OSError) else f"{type(exc).__name__}: {text}"


class _Collected(logging.Handler):
    """Appends each logged warning's message to a list."""

    def __init__(self, out: list[str]) -> None:
        super().__init__(logging.WARNING)
        self.out = out

    def emit(self, record: logging.LogRecord) -> None:
        self.out.append(record.getMessage())


def _calibrate_one(
    nominal: Robot, data: Measurements, options: Mapping[str, Any]
) -> tuple[CalibrationResult | str, tuple[str, ...]]:
    """One robot's task: :func:`calibrate_and_report`, or the error's text (so that one
    robot's failure does not stop the others), and the warnings it gave: kinfw's
    ``UserWarning`` and the warnings logged under ``kinfw``, collected here instead of
    printed, so that they come back from any worker with the robot they belong to.

    Collecting swaps process-wide hooks (:func:`warnings.catch_warnings`, the ``kinfw``
    logger's handlers) while the task runs: one task per worker thread keeps them apart.
    """
    said: list[str] = []
    logger = logging.getLogger("kinfw")
    handler, propagate = _Collected(said), logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a library's deprecation notice is not the robot's
            warnings.simplefilter("always", UserWarning)
            warnings.showwarning = lambda message, *_, **__: said.append(str(message))
            try:
                result = calibrate_and_report(nominal, data, **options)
            except Exception as exc:  # reported in its row; the fleet goes on
                result = _error_text(exc)
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate
    return result, tuple(dict.fromkeys(" ".join(w.split()) for w in said))


def _write(member: FleetMember, result: CalibrationResult, folder: Path) -> None:
    """The robot's calibrated URDF, sidecar and report in ``folder``."""
    # the data file's SHA-256 is taken here, where the file is (a worker may not see it)
    provenance = dataclasses.replace(result.report.data, sha256=file_sha256(member.data))
    result = dataclasses.replace(result, report=dataclasses.replace(result.report, data=provenance))
    if result.refusal is not None:  # the plausibility guard: refused, its folder not made
        raise ImplausibleCalibrationError(result.refusal)
    folder.mkdir(parents=True, exist_ok=True)
    report = result.write(folder / CALIBRATED_URDF)
    write_report(folder / REPORT, report)


def calibrate_fleet(
    members: Sequence[FleetMember],
    out_dir: str | os.PathLike[str],
    *,
    read: Callable[[Path], Measurements] = read_measurements,
    executor: Executor | None = None,
    **options: Any,
) -> FleetResult:
    """Calibrate every robot of a fleet as ``kinfw calibrate`` does, with the same
    options, and write each one's calibrated URDF, sidecar and report and the summary.

    Parameters
    ----------
    members : sequence of FleetMember
        The robots (:func:`fleet_members`).
    out_dir : path
        The fleet's folder: ``NAME/calibrated.urdf`` (+ ``NAME/calibrated.kinfw.json``)
        and ``NAME/report.json`` per calibrated robot, and ``summary.json``.
    read : callable(Path) -> Measurements
        Reads a measurement file (default :func:`kinfw.measurements.read_measurements`;
        with camera intrinsics that override the files' ``"cameras"``:
        ``functools.partial(read_measurements, cameras=...)``).
    executor : concurrent.futures.Executor, optional
        Calibrate the robots as its tasks (a process pool, a Dask scheduler's:
        :func:`kinfw.verification.evaluation.open_executor`); default one after the
        other in this process. The files written are the same either way.
    **options
        Keyword arguments of :func:`calibrate_and_report` for every robot
        (``parameters``, ``method``, ``noise``, ``loss``, ``prior``,
        ``refine_intrinsics``).

    Returns
    -------
    FleetResult
        A row per robot: its summary, or the error that stopped it (a file that cannot be
        read, data the calibration refuses, an output that cannot be written).

    Raises
    ------
    kinfw.files.OutputPathError
        ``out_dir`` cannot be a writable folder (checked before any work).
    """
    out = check_output_dir(out_dir, files=(FLEET_SUMMARY,))
    loaded: dict[int, tuple[Robot, Measurements]] = {}
    failed: dict[int, FleetRow] = {}
    robots: dict[Path, Robot] = {}  # a shared nominal URDF is read once
    for i, m in enumerate(members):
        try:
            if m.urdf not in robots:
                robots[m.urdf] = load_robot(m.urdf)
            data = read(m.data)
            # frames the URDF lacks, mounted as the file (or --mount) says: as calibrate
            loaded[i] = mounted_robot(robots[m.urdf], data.mounts, data.source), data
        except (ValueError, OSError) as exc:
            failed[i] = FleetRow(m.name, str(m.urdf), str(m.data), _error_text(exc))
    order = sorted(loaded)
    results = run_trials(
        _calibrate_one,
        [(*loaded[i], options) for i in order],
        executor=executor,
        name="robots",
    )
    rows = dict(failed)
    for i, (result, said) in zip(order, results, strict=True):
        m = members[i]
        row = FleetRow(
            m.name, str(m.urdf), str(m.data), warnings=said, n_samples=loaded[i][1].n_samples
        )
        if isinstance(result, str):
            rows[i] = dataclasses.replace(row, error=result)
            continue
        try:
            _write(m, result, out / m.name)
        except (ValueError, OSError) as exc:
            rows[i] = dataclasses.replace(row, error=_error_text(exc))
            continue
        rows[i] = dataclasses.replace(
            row,
            model=result.model,
            rms=_pooled_rms(result.report.errors_in_sample),
        )
    fleet = FleetResult(tuple(rows[i] for i in range(len(members))), str(out))
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / FLEET_SUMMARY, json_text(fleet.to_dict()) + "\n")
    return fleet
