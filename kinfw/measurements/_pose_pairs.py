"""Hand-eye pose pairs (``kinfw handeye``): read and write them as CSV, JSON or
easy_handeye2's saved samples (YAML).

A pose pair is what a hand-eye calibration records at each robot pose: the hand's pose
in the robot's base, ``base_T_hand`` (forward kinematics, the robot's TF), and the
target's pose in the sensor, ``sensor_T_target`` (a camera's extrinsics, a tracker's
marker). Every reader returns :class:`PosePairs` with these two names, whatever the
setup (eye-in-hand: the sensor on the hand, the target fixed; eye-to-hand: the sensor
fixed, the target on the hand).

Formats (chosen by the file's suffix)
-------------------------------------
``.csv``
    A header row with the 14 columns of :data:`POSE_PAIR_COLUMNS` (in any order, other
    columns ignored) and one row per pair: positions, and unit quaternions stored scalar
    last ``(qx, qy, qz, qw)``, of ``base_T_hand`` (``hand_*``) and ``sensor_T_target``
    (``sensor_*``), in one length unit (metres unless told otherwise). Spreadsheet
    dialects are read as ``import-csv`` reads them (:func:`kinfw.measurements.csv_table`:
    a byte-order mark, ``;`` or tab separators, decimal commas).
``.json``
    A list of pairs ``[base_T_hand, sensor_T_target]``, each a 4x4 row-major matrix
    (a list of 4 rows of 4 numbers); rotations are projected onto the nearest rotation
    (:data:`RIGID_TOL`).
``.yaml``, ``.yml``, ``.samples``
    easy_handeye2's saved samples: ``samples:`` a list of ``{robot: {translation:
    {x, y, z}, rotation: {x, y, z, w}}, tracking: {...}}`` with ``parameters:
    calibration_type`` (``eye_in_hand`` or ``eye_on_base``). ``robot`` is easy_handeye2's
    TF lookup of the effector in the base (eye-in-hand) or of the base in the effector
    (eye-on-base: it inverts it itself), ``tracking`` the marker in the tracking base;
    the reader returns ``base_T_hand`` either way.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from kinfw.geometry import (
    inverse_transform,
    project_to_rotation,
    transform_from_xyz_quat_xyzw,
    xyz_quat_xyzw_from_transform,
)
from kinfw.measurements._checks import duplicates_warning, equal_row_pairs, first_copies
from kinfw.measurements._csv import csv_table
from kinfw.observations import QUAT_NORM_TOL, QUAT_ROUNDED_TOL, DatasetError

#: The CSV columns, in the order the writer writes them: ``base_T_hand`` then
#: ``sensor_T_target``, each position (length unit) then quaternion scalar last.
POSE_PAIR_COLUMNS = tuple(
    f"{pose}_{part}"
    for pose in ("hand", "sensor")
    for part in ("x", "y", "z", "qx", "qy", "qz", "qw")
)
#: The columns of :func:`read_hand_poses`: ``base_T_hand`` alone.
HAND_POSE_COLUMNS = POSE_PAIR_COLUMNS[:7]
#: The same without the ``hand_`` prefix, which :func:`read_hand_poses` also reads.
PLAIN_POSE_COLUMNS = tuple(c.removeprefix("hand_") for c in HAND_POSE_COLUMNS)
#: Fewer pairs than this cannot determine a hand-eye transform (two relative motions
#: about different axes need three poses).
MIN_POSE_PAIRS = 3
#: Largest deviation from orthonormal (``max |R^T R - I|``) accepted in a JSON matrix;
#: accepted rotations are projected onto the nearest rotation (real files are printed to
#: 6-7 digits: Tabb's robot poses are off by 1e-6).
RIGID_TOL = 1e-4
#: easy_handeye2's ``calibration_type`` values, as :class:`PosePairs.setup` names them.
EASY_HANDEYE_SETUPS = {"eye_in_hand": "eye-in-hand", "eye_on_base": "eye-to-hand"}
SUFFIXES = {".csv": "csv", ".json": "json", ".yaml": "yaml", ".yml": "yaml", ".samples": "yaml"}


@dataclass(frozen=True, slots=True)
class PosePairs:
    """The poses a hand-eye calibration records, one pair per robot pose.

    Attributes
    ----------
    base_T_hands : ndarray, shape (n, 4, 4)
        Pose of the hand (end effector, flange) in the robot's base, file length unit.
    sensor_T_targets : ndarray, shape (n, 4, 4)
        Pose of the target (board, marker) in the sensor (camera, tracker), same unit.
    source : str
        Where the pairs came from (the file's path), for messages.
    setup : str or None
        ``"eye-in-hand"`` or ``"eye-to-hand"`` when the file says (easy_handeye2's
        ``calibration_type``), else None.
    """

    base_T_hands: NDArray[np.float64]
    sensor_T_targets: NDArray[np.float64]
    source: str
    setup: str | None = None

    def __len__(self) -> int:
        return len(self.base_T_hands)

    def scaled(self, metres_per_unit: float) -> PosePairs:
        """The same pairs with every translation multiplied by ``metres_per_unit``."""
        a, b = self.base_T_hands.copy(), self.sensor_T_targets.copy()
        a[:, :3, 3] *= metres_per_unit
        b[:, :3, 3] *= metres_per_unit
        return PosePairs(a, b, self.source, self.setup)


def duplicate_pairs(pairs: PosePairs) -> NDArray[np.int64]:
    """The pose pairs that repeat an earlier one: both poses equal entry by entry within
    :data:`~kinfw.measurements.DUPLICATE_RTOL` relative (at least 1 length unit).

    Returns
    -------
    ndarray of int, shape (d, 2)
        Rows ``[pair, earlier]``: each duplicate pair's index and the first pair it
        repeats, sorted by the duplicate."""
    rows = np.concatenate(
        [
            pairs.base_T_hands.reshape(len(pairs), -1),
            pairs.sensor_T_targets.reshape(len(pairs), -1),
        ],
        axis=1,
    )
    return first_copies(*equal_row_pairs(rows))


def drop_duplicate_pairs(pairs: PosePairs, *, stacklevel: int = 2) -> PosePairs:
    """``pairs`` without the pairs that repeat an earlier one (:func:`duplicate_pairs`),
    with one ``UserWarning`` naming them (a few shown, the rest counted); unchanged, and
    silent, when there are none. A pair recorded twice would count twice in the fit and
    shrink every sigma by 1/sqrt(2)."""
    duplicates = duplicate_pairs(pairs)
    if not len(duplicates):
        return pairs
    warnings.warn(
        duplicates_warning(pairs.source, duplicates, len(pairs), "pose pairs"),
        UserWarning,
        stacklevel=stacklevel,
    )
    keep = np.ones(len(pairs), dtype=bool)
    keep[duplicates[:, 0]] = False
    return PosePairs(
        pairs.base_T_hands[keep], pairs.sensor_T_targets[keep], pairs.source, pairs.setup
    )


def _pose(xyz, quat_xyzw, where: str, names: str = "qx, qy, qz, qw") -> NDArray[np.float64]:
    """``a_T_b`` of a position and a scalar-last quaternion, refusing a non-unit one;
    ``names`` are the quaternion's columns or keys, for the message."""
    try:
        xyz, q = np.asarray(xyz, dtype=float), np.asarray(quat_xyzw, dtype=float)
    except (TypeError, ValueError):
        raise DatasetError(f"{where}: a value is not a number") from None
    if not (np.isfinite(xyz).all() and np.isfinite(q).all()):
        raise DatasetError(f"{where}: a value is not a finite number")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUAT_NORM_TOL:
        raise DatasetError(
            f"{where}: quaternion ({names}) = {q.tolist()} has norm {norm:.6g}, "
            f"not 1 (within {QUAT_NORM_TOL:g}): quaternions are unit, stored scalar last"
        )
    return transform_from_xyz_quat_xyzw(xyz, q)


def _csv_rows(
    path: Path,
    text: str,
    columns: tuple[str, ...],
    what: str,
    *,
    word: str = "row",
    key: str | None = None,
) -> tuple[list[str], list[tuple[int, list[str], list[float]]]]:
    """The CSV's header and, per non-empty row, its line number, cells and the numbers of
    ``columns`` (any order in the file, other columns kept in the cells); ``what`` says
    what the columns are, for the error naming a missing one. Errors name a row's file
    line as ``word`` N and, when the header has the column ``key``, the row's cell of
    it (an image's name)."""
    table = csv_table(text, str(path))
    rows = table.rows
    if not rows:
        raise DatasetError(f"{path}: empty; expected a header with {', '.join(columns)}")
    header = [c.strip() for c in rows[0][1]]
    missing = [c for c in columns if c not in header]
    if missing:
        raise DatasetError(
            f"{path}: header lacks column(s) {', '.join(missing)} (the columns are "
            f"{', '.join(columns)}: {what}, position then quaternion scalar last)"
        )
    index = [header.index(c) for c in columns]
    named = header.index(key) if key in header else None
    out = []
    for line, row in rows[1:]:
        values = []
        for c, k in zip(columns, index, strict=True):
            cell = row[k].strip() if k < len(row) else ""
            try:
                values.append(table.number(cell))
            except ValueError:
                at = _row_label(path, line, row, word, key, named)
                raise DatasetError(f"{at}, column {c!r}: {cell!r} is not a number") from None
        out.append((line, row, values))
    return header, out


def _row_label(
    path: Path, line: int, row: list[str], word: str, key: str | None, index: int | None
) -> str:
    """``PATH: line N`` (``word`` N), with ``(image 'a.png')`` when the row's cell of
    column ``key`` (at ``index``) is not empty."""
    name = row[index].strip() if index is not None and index < len(row) else ""
    return f"{path}: {word} {line}" + (f" ({key} {name!r})" if name else "")


def _read_csv(path: Path, text: str) -> PosePairs:
    what = "base_T_hand and sensor_T_target"
    _, rows = _csv_rows(path, text, POSE_PAIR_COLUMNS, what)
    hands, sensors = [], []
    for line, _, values in rows:
        hands.append(_pose(values[0:3], values[3:7], f"{path}: row {line}, hand_q*"))
        sensors.append(_pose(values[7:10], values[10:14], f"{path}: row {line}, sensor_q*"))
    return _pairs(hands, sensors, str(path), None)


@dataclass(frozen=True, slots=True)
class HandPoses:
    """The hand's logged poses, one per image (``kinfw pose-chain``).

    Attributes
    ----------
    base_T_hands : ndarray, shape (n, 4, 4)
        Pose of the hand in the robot's base, the file's length unit.
    images : tuple of str, or None
        The ``image`` column (each row's image file), when the file has one.
    source : str
        The file's path, for messages.
    """

    base_T_hands: NDArray[np.float64]
    images: tuple[str, ...] | None
    source: str


def read_hand_poses(path: str | Path) -> HandPoses:
    """Read the hand's poses from a CSV: the ``hand_*`` columns of
    :data:`POSE_PAIR_COLUMNS` (``base_T_hand``: position, quaternion scalar last), or the
    same without the prefix (:data:`PLAIN_POSE_COLUMNS`: ``x, y, z, qx, qy, qz, qw``),
    and, optionally, an ``image`` column naming each row's image.

    Quaternions whose norm is within :data:`~kinfw.observations.QUAT_NORM_TOL` of 1 are
    renormalised; when some are off by more than
    :data:`~kinfw.observations.QUAT_ROUNDED_TOL` (written with a few decimals), one
    ``UserWarning`` names the file, how many rows and the largest ``| |q| - 1 |``.

    Parameters
    ----------
    path : str or Path
        The CSV file.

    Returns
    -------
    HandPoses
        The poses in the file's length unit, and the ``image`` column if any.

    Raises
    ------
    DatasetError
        A missing or unreadable file, a header with neither set of columns (the message
        shows the header and both sets), a cell that is not a number, a quaternion that
        is not unit (each naming the file line, the columns and the row's image when
        there is an ``image`` column), an empty image name, or fewer than
        :data:`MIN_POSE_PAIRS` rows.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise DatasetError(f"{path}: cannot read ({err.strerror or err})") from None
    columns = _hand_pose_columns(path, text)
    header, rows = _csv_rows(path, text, columns, "base_T_hand", word="line", key="image")
    k = header.index("image") if "image" in header else None
    images = None
    if k is not None:
        images = tuple(row[k].strip() if k < len(row) else "" for _, row, _ in rows)
        empty = [line for (line, _, _), name in zip(rows, images, strict=True) if not name]
        if empty:
            raise DatasetError(f"{path}: line {empty[0]}: the 'image' cell is empty")
    names = ", ".join(columns[3:])
    poses = [
        _pose(v[0:3], v[3:7], _row_label(path, line, row, "line", "image", k), names)
        for line, row, v in rows
    ]
    if len(poses) < MIN_POSE_PAIRS:
        raise DatasetError(
            f"{path}: {len(poses)} hand pose(s); at least {MIN_POSE_PAIRS} are needed"
        )
    off = np.abs(np.linalg.norm([v[3:7] for _, _, v in rows], axis=1) - 1.0)
    rounded = off[off > QUAT_ROUNDED_TOL]
    if len(rounded):
        warnings.warn(
            f"{path}: {len(rounded)} of {len(rows)} rows have quaternions ({names}) whose "
            f"norms differ from 1 by up to {rounded.max():.2g} (rounded?); renormalised",
            UserWarning,
            stacklevel=2,
        )
    return HandPoses(np.stack(poses), images, str(path))


def _hand_pose_columns(path: Path, text: str) -> tuple[str, ...]:
    """The pose columns the CSV's header holds: :data:`HAND_POSE_COLUMNS`, else
    :data:`PLAIN_POSE_COLUMNS`; an error showing the header and both sets when it holds
    neither."""
    rows = csv_table(text, str(path)).rows
    header = [c.strip() for c in rows[0][1]] if rows else []
    for columns in (HAND_POSE_COLUMNS, PLAIN_POSE_COLUMNS):
        if set(header) >= set(columns):
            return columns
    closest = min((HAND_POSE_COLUMNS, PLAIN_POSE_COLUMNS), key=lambda c: len(set(c) - set(header)))
    missing = [c for c in closest if c not in header]
    found = f"line 1: the header is [{', '.join(header)}]" if header else "empty"
    raise DatasetError(
        f"{path}: {found}; expected the columns {', '.join(HAND_POSE_COLUMNS)}, or "
        f"{', '.join(PLAIN_POSE_COLUMNS)} (base_T_hand: position, then quaternion scalar "
        f"last; optionally 'image' naming each row's image)"
        + (f"; {', '.join(missing)} missing" if header else "")
    )


def _matrix(value, where: str) -> NDArray[np.float64]:
    T = np.asarray(value, dtype=float)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise DatasetError(f"{where}: expected a 4x4 matrix of finite numbers")
    R = T[:3, :3]
    error = np.abs(R.T @ R - np.eye(3)).max()
    if error > RIGID_TOL or np.linalg.det(R) < 0 or np.abs(T[3] - [0, 0, 0, 1]).max() > 0:
        raise DatasetError(
            f"{where}: not a rigid transform (rotation off orthonormal by {error:.3g}, "
            "or a reflection, or a last row other than 0 0 0 1)"
        )
    T = T.copy()
    T[:3, :3] = project_to_rotation(R)
    return T


def _read_json(path: Path, text: str) -> PosePairs:
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise DatasetError(f"{path}: not JSON ({err})") from None
    if isinstance(data, dict) and data.get("format") == "kinfw-measurements":
        raise DatasetError(
            f"{path}: a kinfw measurement file, not pose pairs: give the robot's URDF "
            "(kinfw handeye --urdf) to compute the hand's poses from its joint values"
        )
    if not isinstance(data, list) or not all(isinstance(p, list) and len(p) == 2 for p in data):
        raise DatasetError(f"{path}: expected a list of [base_T_hand, sensor_T_target] pairs")
    hands = [_matrix(p[0], f"{path}: pair {i}, base_T_hand") for i, p in enumerate(data)]
    sensors = [_matrix(p[1], f"{path}: pair {i}, sensor_T_target") for i, p in enumerate(data)]
    return _pairs(hands, sensors, str(path), None)


def _tf(value, where: str) -> NDArray[np.float64]:
    try:
        t, r = value["translation"], value["rotation"]
        return _pose([t[k] for k in "xyz"], [r[k] for k in "xyzw"], where)
    except (KeyError, TypeError):
        raise DatasetError(
            f"{where}: expected translation: {{x, y, z}} and rotation: {{x, y, z, w}}"
        ) from None


def _read_yaml(path: Path, text: str) -> PosePairs:
    import yaml

    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise DatasetError(f"{path}: not YAML ({' '.join(str(err).split())})") from None
    if not isinstance(data, dict) or not isinstance(data.get("samples"), list):
        raise DatasetError(f"{path}: expected easy_handeye2's samples (a 'samples:' list)")
    kind = (data.get("parameters") or {}).get("calibration_type") or None
    if kind is not None and kind not in EASY_HANDEYE_SETUPS:
        raise DatasetError(
            f"{path}: parameters.calibration_type {kind!r} is not one of "
            f"{', '.join(EASY_HANDEYE_SETUPS)}"
        )
    setup = EASY_HANDEYE_SETUPS.get(kind)
    hands, sensors = [], []
    for i, sample in enumerate(data["samples"]):
        if not isinstance(sample, dict) or not {"robot", "tracking"} <= sample.keys():
            raise DatasetError(f"{path}: sample {i}: expected 'robot' and 'tracking'")
        robot = _tf(sample["robot"], f"{path}: sample {i}, robot")
        # eye_on_base: easy_handeye2 records the base in the effector (hand_T_base)
        hands.append(inverse_transform(robot) if kind == "eye_on_base" else robot)
        sensors.append(_tf(sample["tracking"], f"{path}: sample {i}, tracking"))
    return _pairs(hands, sensors, str(path), setup)


def _pairs(hands, sensors, source: str, setup: str | None) -> PosePairs:
    if len(hands) < MIN_POSE_PAIRS:
        raise DatasetError(
            f"{source}: {len(hands)} pose pair(s); a hand-eye calibration needs at least "
            f"{MIN_POSE_PAIRS} (two motions about different axes), 10 or more in practice"
        )
    return PosePairs(np.stack(hands), np.stack(sensors), source, setup)


def target_views(measurements) -> tuple:
    """The ``target`` groups of ``measurements``, and each ``pixels`` group as the target
    poses of its images from PnP (:func:`kinfw.observations.target_observations_from_pixels`;
    images PnP cannot solve are left out): a tuple of
    :class:`kinfw.observations.TargetObservations`."""
    from kinfw.observations import target_observations_from_pixels

    return (
        *measurements.targets,
        *(target_observations_from_pixels(g) for g in measurements.groups("pixels")),
    )


def pose_pairs_from_measurements(
    measurements, robot, *, hand_frame: str, camera: str | None = None
) -> PosePairs:
    """Pose pairs of a kinfw measurement file's ``target`` or ``pixels`` observations (the
    images of ``kinfw detect``, each turned into the target's pose by PnP,
    :func:`target_views`): at each observation the hand's pose by the robot's forward
    kinematics and the target's pose in the camera (eye-in-hand; metres).

    Parameters
    ----------
    measurements : kinfw.measurements.Measurements
        With ``target`` or ``pixels`` observations.
    robot : kinfw.model.Robot
        The model whose forward kinematics give ``base_T_hand`` (its root link is the
        base).
    hand_frame : str
        The URDF link the camera is mounted on.
    camera : str, optional
        The camera frame whose observations to use; needed when several cameras observe.

    Raises
    ------
    DatasetError
        No target or pixels observations, several cameras and none chosen (the message
        lists them), or fewer than :data:`MIN_POSE_PAIRS` observations.
    """
    views = target_views(measurements)
    groups = [g for g in views if camera is None or g.camera == camera]
    cameras = sorted({g.camera for g in views})
    if not groups:
        raise DatasetError(
            f"{measurements.source}: no target or pixels observations"
            + (f" by camera {camera!r} (cameras: {', '.join(cameras)})" if cameras else "")
        )
    if len({g.camera for g in groups}) > 1 or len(groups) > 1:
        raise DatasetError(
            f"{measurements.source}: targets seen by {', '.join(cameras)} or several targets: "
            "choose one camera (--camera-frame) and one target per file"
        )
    g = groups[0]
    qs = measurements.qs[g.sample]
    base_T_hands = robot.frame_poses(qs, hand_frame, measurements.joint_names)
    return _pairs(list(base_T_hands), list(g.camera_T_target), measurements.source, "eye-in-hand")


def read_pose_pairs(path: str | Path) -> PosePairs:
    """Read hand-eye pose pairs from a CSV, JSON or easy_handeye2 YAML file.

    Parameters
    ----------
    path : str or Path
        The file; its suffix picks the format (``.csv``, ``.json``, ``.yaml`` / ``.yml``
        / ``.samples``; the module's docstring describes each).

    Returns
    -------
    PosePairs
        ``base_T_hands`` and ``sensor_T_targets``, (n, 4, 4), in the file's length unit.

    Raises
    ------
    DatasetError
        An unknown suffix, a missing or unreadable file, a missing CSV column, a cell that
        is not a number (file, row and column), a quaternion that is not unit (file, row),
        a matrix that is not a rigid transform (pair index), or fewer than
        :data:`MIN_POSE_PAIRS` pairs.
    """
    path = Path(path)
    fmt = SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise DatasetError(
            f"{path}: unknown pose-pair format {path.suffix!r} (use {', '.join(SUFFIXES)})"
        )
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise DatasetError(f"{path}: cannot read ({err.strerror or err})") from None
    return {"csv": _read_csv, "json": _read_json, "yaml": _read_yaml}[fmt](path, text)


def pose_pairs_text(pairs: PosePairs, fmt: str) -> str:
    """``pairs`` as the text of a ``"csv"``, ``"json"`` or ``"yaml"`` (easy_handeye2
    samples) file that :func:`read_pose_pairs` reads back; numbers by ``repr`` (exact)."""
    if fmt == "json":
        pairs_list = zip(pairs.base_T_hands, pairs.sensor_T_targets, strict=True)
        return json.dumps([[a.tolist(), b.tolist()] for a, b in pairs_list])
    xyz_a, q_a = xyz_quat_xyzw_from_transform(pairs.base_T_hands)
    xyz_b, q_b = xyz_quat_xyzw_from_transform(pairs.sensor_T_targets)
    if fmt == "csv":
        lines = [",".join(POSE_PAIR_COLUMNS)]
        for row in np.hstack([xyz_a, q_a, xyz_b, q_b]):
            lines.append(",".join(repr(float(v)) for v in row))
        return "\n".join(lines) + "\n"
    if fmt == "yaml":
        import yaml

        def tf(xyz, q):
            return {
                "translation": dict(zip("xyz", map(float, xyz), strict=True)),
                "rotation": dict(zip("xyzw", map(float, q), strict=True)),
            }

        samples = [
            {"robot": tf(xyz_a[i], q_a[i]), "tracking": tf(xyz_b[i], q_b[i])}
            for i in range(len(pairs))
        ]
        kind = {"eye-to-hand": "eye_on_base"}.get(pairs.setup or "", "eye_in_hand")
        if kind == "eye_on_base":  # easy_handeye2 records hand_T_base then
            xyz_i, q_i = xyz_quat_xyzw_from_transform(inverse_transform(pairs.base_T_hands))
            for i, s in enumerate(samples):
                s["robot"] = tf(xyz_i[i], q_i[i])
        return yaml.safe_dump(
            {"parameters": {"calibration_type": kind}, "samples": samples}, sort_keys=False
        )
    raise ValueError(f"pose_pairs_text: unknown format {fmt!r} (csv, json, yaml)")
