"""Read a FIGAROH-style calibration CSV into :class:`kinfw.measurements.Measurements`.

FIGAROH (https://github.com/thanhndv212/figaroh, Apache-2.0) reads its geometric
calibration data from one CSV per session, with pandas
(``figaroh.calibration.data_loader.load_data`` and
``figaroh.data.observations.PoseObservations.from_csv`` in the 1.0.2 sdist): one row
per sample, a header row, and

- for marker ``i`` (1-based) the measured degrees of freedom among the columns
  ``xi, yi, zi, phixi, phiyi, phizi``: positions in metres, orientations in radians;
- one column per active joint, named by the URDF joint (``torso_lift_joint``,
  ``arm_1_joint``, ...), values in the joint's SI unit (rad, or m for a prismatic joint):
  FIGAROH copies them into Pinocchio's configuration vector unchanged.

FIGAROH predicts the orientation columns with ``pin.rpy.matrixToRpy`` of the marker's
rotation (``figaroh/calibration/calibration_tools.py``, the forward kinematics of the
calibration), so ``phix, phiy, phiz`` are roll, pitch, yaw about fixed axes:
``meas_R_marker = Rz(phiz) @ Ry(phiy) @ Rx(phix)``.

A marker with ``x, y, z`` only becomes a ``point`` observation of a marker of unknown
offset on ``frame``; with all six columns, a ``pose`` observation of a rigid marker of
unknown pose on ``frame``. Both are in ``measured_in`` (default: the URDF root link).
Column names are stripped of spaces (some sessions pad them: ``"x1 "``). Spreadsheet
dialects are read: a UTF-8 byte-order mark, ``;`` or tab separators, and with them
decimal commas (``0,25``); a file mixing decimal commas and points is refused. Unnamed columns
(``""`` or pandas' ``"Unnamed: N"``: a row index written by ``DataFrame.to_csv``, the empty
column after a trailing comma) are ignored, as FIGAROH ignores every column it does not
ask for; any other column must be a marker or a joint of the robot.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import quat_xyzw_from_matrix
from kinfw.measurements._csv import CsvTable, csv_table
from kinfw.measurements._dataset import Measurements
from kinfw.measurements._file import measurements_from_dict
from kinfw.measurements._mounts import Mount
from kinfw.observations import DatasetError

if TYPE_CHECKING:
    from kinfw.model import Robot

#: Columns FIGAROH reads that are not joints or markers (kept out of the joint list).
IGNORED_COLUMNS = ("session_id",)

_PANDAS_UNNAMED = re.compile(r"^Unnamed: [0-9]+$")
_MARKER_COLUMN = re.compile(r"^(x|y|z|phix|phiy|phiz)([1-9][0-9]*)$")
_POSITION = ("x", "y", "z")
_ORIENTATION = ("phix", "phiy", "phiz")
_LENGTH_SCALE = {"m": 1.0, "mm": 1e-3}
_ANGLE_SCALE = {"rad": 1.0, "deg": np.pi / 180.0}


def matrix_from_figaroh_rpy(rpy: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrices from FIGAROH's ``phix, phiy, phiz`` (Pinocchio's ``rpyToMatrix``).

    Parameters
    ----------
    rpy : array_like, shape (..., 3)
        Roll, pitch, yaw in radians: rotations about the fixed x, y, z axes.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
    """
    a = np.asarray(rpy, dtype=float)
    cr, sr = np.cos(a[..., 0]), np.sin(a[..., 0])
    cp, sp = np.cos(a[..., 1]), np.sin(a[..., 1])
    cy, sy = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack(
        [
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
            np.stack([-sp, cp * sr, cp * cr], -1),
        ],
        axis=-2,
    )


def _unnamed(name: str) -> bool:
    """A column pandas would call ``Unnamed: N``: an index written by ``to_csv`` or the
    empty column after a trailing comma. Ignored, as FIGAROH ignores it."""
    return name == "" or _PANDAS_UNNAMED.match(name) is not None


def _read_table(path: Path) -> tuple[list[str], list[tuple[int, list[str]]], CsvTable]:
    """Header (stripped), the data rows with their line numbers (blank lines skipped),
    and the split text (its dialect: decimal commas). A UTF-8 byte-order mark is skipped; the
    separator is ``,``, ``;`` or a tab (:func:`kinfw.measurements.csv_table`)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{path}: not a UTF-8 text CSV file ({exc.reason})") from None
    table = csv_table(text, str(path))
    if not table.rows:
        raise DatasetError(f"{path}: empty file; expected a header row of column names")
    delimiter = table.delimiter
    header = [cell.strip() for cell in table.rows[0][1]]
    data = table.rows[1:]
    if not data:
        raise DatasetError(f"{path}: no data rows after the header")
    for i, name in enumerate(header):
        if not _unnamed(name) and header.index(name) != i:
            raise DatasetError(f"{path}: header: column {name!r} appears twice")
    out = []
    for line, row in data:
        cells = [c.strip() for c in row]
        while len(cells) > len(header) and cells[-1] == "":
            cells.pop()
        if len(cells) < len(header) and all(_unnamed(h) for h in header[len(cells) :]):
            cells += [""] * (len(header) - len(cells))
        if len(cells) != len(header):
            raise DatasetError(
                f"{path}: line {line}: {len(cells)} values separated by {delimiter!r}, "
                f"expected {len(header)} (one per header column; the separator is the one "
                "the header line holds most of: ',', ';' or a tab)"
            )
        out.append((line, cells))
    return header, out, table


def _numbers(
    path: Path, header: list[str], rows: list[tuple[int, list[str]]], dialect: CsvTable
) -> NDArray[np.float64]:
    """The table as floats (``0,25`` read as 0.25 in a decimal-comma file); names the
    row, line and column of the first bad cell."""
    table = np.full((len(rows), len(header)), np.nan)
    named = [c for c, name in enumerate(header) if not _unnamed(name)]
    for r, (line, cells) in enumerate(rows):
        for c in named:
            cell = cells[c]
            try:
                table[r, c] = dialect.number(cell)
            except ValueError:
                raise DatasetError(
                    f"{path}: row {r} (line {line}), column {header[c]!r}: expected a "
                    f"number, got {cell!r}"
                ) from None
    bad = np.zeros(table.shape, dtype=bool)
    bad[:, named] = ~np.isfinite(table[:, named])
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise DatasetError(
            f"{path}: row {r} (line {rows[r][0]}), column {header[c]!r}: {table[r, c]} is not a "
            f"finite number ({int(bad.any(axis=1).sum())} row(s) affected; e.g. an occluded "
            "marker): delete those rows"
        )
    return table


def _markers(path: Path, header: list[str]) -> dict[int, dict[str, int]]:
    """Marker number -> {dof: column index}; each marker has x, y, z and all or no phi."""
    markers: dict[int, dict[str, int]] = {}
    for c, name in enumerate(header):
        match = _MARKER_COLUMN.match(name)
        if match:
            markers.setdefault(int(match.group(2)), {})[match.group(1)] = c
    for i, dofs in sorted(markers.items()):
        missing = [f"{d}{i}" for d in _POSITION if d not in dofs]
        has_phi = [d for d in _ORIENTATION if d in dofs]
        if has_phi and len(has_phi) != 3:
            missing += [f"{d}{i}" for d in _ORIENTATION if d not in dofs]
        if missing:
            raise DatasetError(
                f"{path}: header: marker {i} lacks column(s) {missing}; expected x{i}, y{i}, "
                f"z{i} and optionally all of phix{i}, phiy{i}, phiz{i}"
            )
    if not markers:
        raise DatasetError(
            f"{path}: header: no marker columns; expected x1, y1, z1 (and optionally "
            f"phix1, phiy1, phiz1), got {header}"
        )
    return markers


def measurements_from_figaroh_csv(
    path: str | Path,
    *,
    robot: Robot,
    frame: str,
    measured_in: str | None = None,
    marker: str = "marker",
    length_unit: str = "m",
    angle_unit: str = "rad",
    target: str | None = None,
    camera_frame: str | None = None,
) -> Measurements:
    """Read a FIGAROH calibration CSV (see the module docstring for its columns).

    Parameters
    ----------
    path : str or Path
        The CSV file.
    robot : Robot
        The URDF robot: every non-marker column must be one of its movable joints
        (``robot.joint_names``); its joint types say which columns are lengths.
    frame : str
        URDF link or joint the markers are rigidly attached to (any frame fixed to the
        link of the last joint that moves them; their offsets are estimated).
    measured_in : str, optional
        Name of the measurement frame (a frame not in the URDF, whose pose is then
        estimated); None: the URDF root link.
    marker : str
        Prefix of the marker names: marker ``i`` of the file is ``f"{marker}{i}"``.
    length_unit : {"m", "mm"}
        Unit of ``x, y, z`` and of prismatic joint values (FIGAROH: ``"m"``).
    angle_unit : {"rad", "deg"}
        Unit of ``phix, phiy, phiz`` and of revolute joint values (FIGAROH: ``"rad"``).
    target : str, optional
        Read each 6D marker as the pose ``camera_T_target`` of a fixed target seen by a
        camera on ``frame`` (a camera on a flange seeing a board): ``target``
        observations, the target's pose and the camera's mount on ``frame`` estimated.
        Target ``i`` is named ``target`` (one marker) or ``f"{target}{i}"``. Excludes
        ``measured_in`` (the camera is the measurement frame); every marker needs its
        ``phi`` columns; needs ``camera_frame``.
    camera_frame : str, optional
        With ``target``: the camera's own URDF link, on a fixed joint that hangs (through
        fixed joints only) from ``frame``; its joint origin, the camera's mount, is what
        the calibration estimates and writes. Required, so that no existing frame
        (``tool0``) is redefined as the camera. A name the URDF lacks is mounted on
        ``frame``'s link (the dataset's ``mounts``: :func:`mounted_robot` adds it as a
        link on a fixed joint, identity start).

    Returns
    -------
    Measurements
        One sample per data row, in file order; joint values in SI, columns in the
        file's order; per marker a ``point`` group (``x, y, z`` only) or a ``pose``
        group (with ``phix, phiy, phiz``), ``marker`` named, offsets unknown; with
        ``target``, a ``target`` group per marker, and ``mounts`` holding the camera
        frame when the URDF lacks it.

    Raises
    ------
    DatasetError
        Naming the file, the row (0-based, and its line) and the column: a missing or
        duplicated column, a column that is neither a marker nor a joint of the robot, a
        cell that is not a finite number, a row of the wrong length.
    ValueError
        An unknown unit.
    """
    path = Path(path)
    if length_unit not in _LENGTH_SCALE:
        raise ValueError(f"length_unit: expected one of {list(_LENGTH_SCALE)}, got {length_unit!r}")
    if angle_unit not in _ANGLE_SCALE:
        raise ValueError(f"angle_unit: expected one of {list(_ANGLE_SCALE)}, got {angle_unit!r}")
    mounts: dict[str, Mount] = {}
    header, rows, dialect = _read_table(path)
    markers = _markers(path, header)
    if target is not None:
        _check_target_markers(path, markers, measured_in)
        link = camera_link(path, robot, frame, camera_frame)
        mounts = {camera_frame: link} if isinstance(link, Mount) else {}
        frame = camera_frame
    joint_columns = _joint_columns(path, header, markers, robot)
    table = _numbers(path, header, rows, dialect)
    length, angle = _LENGTH_SCALE[length_unit], _ANGLE_SCALE[angle_unit]
    joint_names = [header[c] for c in joint_columns]
    scales = np.array(
        [length if robot.joint(n).type == "prismatic" else angle for n in joint_names]
    )
    qs = table[:, joint_columns] * scales
    per_marker = [
        _marker_observations(
            table, i, dofs, len(markers), frame, marker, measured_in, target, length, angle
        )
        for i, dofs in sorted(markers.items())
    ]
    doc = {
        "format": "kinfw-measurements",
        "version": 1,
        "units": {"length": "m", "angle": "rad"},
        "joint_names": joint_names,
        "samples": [
            {"q": q, "observations": [obs[s] for obs in per_marker]}
            for s, q in enumerate(qs.tolist())
        ],
    }
    return measurements_from_dict(doc, source=str(path)).with_mounts(mounts)


def camera_link(path: Path, robot: Robot, frame: str, camera_frame: str | None) -> str | Mount:
    """The camera's own link for ``target`` observations (see
    :func:`measurements_from_figaroh_csv`), checked: its name when the URDF has it, else
    the :class:`Mount` that adds it on ``frame``'s link; a refusal says what to give."""
    if camera_frame is None:
        raise DatasetError(
            f"{path}: target poses are measured in the camera, whose pose on {frame!r} is "
            f"unknown: reading them as seen by {frame!r} would make calibrate redefine "
            f"{frame!r} as the camera. Name the camera's own frame with --camera-frame NAME "
            f"(camera_frame=): a link of the URDF fixed to {frame!r}, or a new name, which "
            f"the file then mounts on {frame!r} (calibrate adds it as a link on a fixed joint)"
        )
    if not robot.has_frame(camera_frame):
        link = frame if frame in robot.link_names else robot.joint(frame).child
        return Mount(link)
    if camera_frame == frame or robot.movable_path(camera_frame) != robot.movable_path(frame):
        raise DatasetError(
            f"{path}: camera frame {camera_frame!r} must be its own link fixed to {frame!r} "
            f"(no joint that moves between them, and not {frame!r} itself)"
        )
    return camera_frame


def _check_target_markers(
    path: Path, markers: dict[int, dict[str, int]], measured_in: str | None
) -> None:
    """Raise unless markers can be read as targets: no ``measured_in``, every ``phi`` column."""
    if measured_in is not None:
        raise ValueError(
            "target and measured_in exclude each other: a target's pose is measured in "
            "the camera on the frame"
        )
    for i, dofs in sorted(markers.items()):
        if "phix" not in dofs:
            raise DatasetError(
                f"{path}: header: marker {i} has no phix{i}, phiy{i}, phiz{i} columns: a "
                "target seen by a camera needs its orientation (6D poses)"
            )


def _joint_columns(
    path: Path, header: list[str], markers: dict[int, dict[str, int]], robot: Robot
) -> list[int]:
    """Indices of the joint columns (neither marker, ignored nor unnamed), in file order.

    Raises unless each names a movable joint of ``robot`` and there is at least one.
    """
    marker_columns = {c for dofs in markers.values() for c in dofs.values()}
    joint_columns = [
        c
        for c, name in enumerate(header)
        if c not in marker_columns and name not in IGNORED_COLUMNS and not _unnamed(name)
    ]
    movable = set(robot.joint_names)
    for c in joint_columns:
        if header[c] not in movable:
            raise DatasetError(
                f"{path}: header: column {header[c]!r} is neither a marker column (x1, y1, "
                f"z1, phix1, ...) nor a movable joint of {robot.source}; its movable joints "
                f"are {list(robot.joint_names)}"
            )
    if not joint_columns:
        raise DatasetError(f"{path}: header: no joint columns (named by URDF joint)")
    return joint_columns


def _marker_observations(
    table: NDArray[np.float64],
    i: int,
    dofs: dict[str, int],
    n_markers: int,
    frame: str,
    marker: str,
    measured_in: str | None,
    target: str | None,
    length: float,
    angle: float,
) -> list[dict[str, Any]]:
    """The observations of marker ``i`` (columns ``dofs``), one per row, in SI.

    A ``point`` (``x, y, z`` only), a ``pose`` (with ``phix, phiy, phiz``), or with
    ``target`` a ``target`` observation; ``length`` and ``angle`` scale the file's
    units to m and rad.
    """
    xyz = table[:, [dofs[d] for d in _POSITION]] * length
    common: dict[str, Any] = {"frame": frame, "marker": f"{marker}{i}"}
    if target is not None:
        name = target if n_markers == 1 else f"{target}{i}"
        common = {"frame": frame, "target": name}
    if measured_in is not None:
        common["measured_in"] = measured_in
    if "phix" not in dofs:
        return [{**common, "kind": "point", "xyz": p} for p in xyz.tolist()]
    rpy = table[:, [dofs[d] for d in _ORIENTATION]] * angle
    quats = quat_xyzw_from_matrix(matrix_from_figaroh_rpy(rpy))
    kind = "pose" if target is None else "target"
    return [
        {**common, "kind": kind, "xyz": p, "quat_xyzw": q}
        for p, q in zip(xyz.tolist(), quats.tolist(), strict=True)
    ]
