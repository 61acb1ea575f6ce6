"""Hand-eye pose-pair files (:func:`kinfw.measurements.read_pose_pairs`): CSV, JSON and
easy_handeye2 YAML read back what was written, a hand-written file of each format is
read as its numbers say (poses built with Pinocchio), and bad files are refused naming
the file, row and column."""

import json
import re

import numpy as np
import pinocchio as pin
import pytest

from kinfw.measurements import (
    POSE_PAIR_COLUMNS,
    PosePairs,
    pose_pairs_text,
    read_pose_pairs,
)
from kinfw.observations import DatasetError


def _poses(rng, n):
    return np.stack(
        [pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3)).homogeneous for _ in range(n)]
    )


@pytest.mark.parametrize("fmt", ["csv", "json", "yaml"])
@pytest.mark.parametrize("setup", [None, "eye-to-hand"])
def test_written_pairs_read_back(tmp_path, fmt, setup):
    rng = np.random.default_rng(1)
    pairs = PosePairs(_poses(rng, 5), _poses(rng, 5), "sim", setup)
    path = tmp_path / f"pairs.{fmt}"
    path.write_text(pose_pairs_text(pairs, fmt))
    back = read_pose_pairs(path)
    np.testing.assert_allclose(back.base_T_hands, pairs.base_T_hands, atol=1e-12)
    np.testing.assert_allclose(back.sensor_T_targets, pairs.sensor_T_targets, atol=1e-12)
    assert back.setup == (("eye-to-hand" if setup else "eye-in-hand") if fmt == "yaml" else None)


def _quat_xyzw(T):
    q = pin.Quaternion(T[:3, :3])
    return [float(q.x), float(q.y), float(q.z), float(q.w)]


def test_a_hand_written_csv_with_shuffled_and_extra_columns(tmp_path):
    rng = np.random.default_rng(2)
    A, B = _poses(rng, 3), _poses(rng, 3)
    cols = ["stamp", *reversed(POSE_PAIR_COLUMNS)]
    lines = ["\ufeff" + ",".join(cols)]
    for i in range(3):
        values = {"stamp": i}
        for pose, T in (("hand", A[i]), ("sensor", B[i])):
            values.update(zip([f"{pose}_{c}" for c in "xyz"], T[:3, 3], strict=True))
            q = _quat_xyzw(T)
            values.update(zip([f"{pose}_q{c}" for c in "xyzw"], q, strict=True))
        lines.append(",".join(repr(float(values[c])) for c in cols))
    path = tmp_path / "p.csv"
    path.write_text("\n".join(lines) + "\n")
    back = read_pose_pairs(path)
    np.testing.assert_allclose(back.base_T_hands, A, atol=1e-12)
    np.testing.assert_allclose(back.sensor_T_targets, B, atol=1e-12)


def test_easy_handeye2_eye_on_base_samples_hold_the_base_in_the_effector(tmp_path):
    """easy_handeye2 records, eye-on-base, the TF lookup of the base in the effector:
    the reader returns its inverse, base_T_hand."""
    rng = np.random.default_rng(3)
    A, B = _poses(rng, 3), _poses(rng, 3)

    def tf(T):
        x, y, z, w = _quat_xyzw(T)
        t = [float(v) for v in T[:3, 3]]
        return (
            f"    translation: {{x: {t[0]!r}, y: {t[1]!r}, z: {t[2]!r}}}\n"
            f"    rotation: {{x: {x!r}, y: {y!r}, z: {z!r}, w: {w!r}}}\n"
        )

    text = "parameters:\n  calibration_type: eye_on_base\n  name: ''\nsamples:\n"
    for a, b in zip(A, B, strict=True):
        text += "- robot:\n" + tf(pin.SE3(a).inverse().homogeneous) + "  tracking:\n" + tf(b)
    path = tmp_path / "demo.samples"
    path.write_text(text)
    back = read_pose_pairs(path)
    assert back.setup == "eye-to-hand"
    np.testing.assert_allclose(back.base_T_hands, A, atol=1e-12)
    np.testing.assert_allclose(back.sensor_T_targets, B, atol=1e-12)


def _csv(tmp_path, rows):
    path = tmp_path / "bad.csv"
    path.write_text(",".join(POSE_PAIR_COLUMNS) + "\n" + "\n".join(rows) + "\n")
    return path


GOOD = "0,0,0,0,0,0,1,0,0,1,0,0,0,1"


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        (
            [GOOD, "0,0,0,0,0,0,1,x,0,1,0,0,0,1", GOOD],
            r"bad.csv: row 3, column 'sensor_x': 'x'",
        ),
        ([GOOD, GOOD, "0,0,0,0,0,0,2" + GOOD[13:]], r"row 4, hand_q\*: .* has norm 2"),
        ([GOOD, GOOD], r"2 pose pair\(s\); .* at least 3"),
    ],
)
def test_bad_csv_rows_are_named(tmp_path, rows, message):
    with pytest.raises(DatasetError, match=message):
        read_pose_pairs(_csv(tmp_path, rows))


def test_missing_columns_unknown_suffix_and_non_rigid_json_are_refused(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("hand_x,hand_y\n1,2\n")
    with pytest.raises(DatasetError, match=r"lacks column.*hand_z"):
        read_pose_pairs(path)
    with pytest.raises(DatasetError, match=r"unknown pose-pair format '\.txt'"):
        read_pose_pairs(tmp_path / "p.txt")
    bad = np.eye(4)
    bad[0, 0] = 2.0
    path = tmp_path / "p.json"
    path.write_text(
        json.dumps(
            [[np.eye(4).tolist(), np.eye(4).tolist()]] * 2 + [[np.eye(4).tolist(), bad.tolist()]]
        )
    )
    with pytest.raises(DatasetError, match="pair 2, sensor_T_target: not a rigid transform"):
        read_pose_pairs(path)


def _spreadsheet(text: str) -> str:
    """The CSV as a European spreadsheet saves it: byte-order mark, ';', decimal commas."""
    return "\ufeff" + re.sub(r"(\d)\.(\d)", r"\1,\2", text.replace(",", ";"))


def test_spreadsheet_csvs_are_read_as_import_csv_reads_them(tmp_path):
    """``;`` separators and decimal commas (refused: 'header lacks column(s)'), for the
    pose pairs and for pose-chain's hand poses alike."""
    from kinfw.measurements import read_hand_poses

    rng = np.random.default_rng(4)
    pairs = PosePairs(_poses(rng, 5), _poses(rng, 5), "sim", None)
    path = tmp_path / "pairs.csv"
    path.write_text(_spreadsheet(pose_pairs_text(pairs, "csv")), encoding="utf-8")
    assert ";" in path.read_text() and "0," in path.read_text()
    back = read_pose_pairs(path)
    np.testing.assert_allclose(back.base_T_hands, pairs.base_T_hands, atol=1e-12)
    np.testing.assert_allclose(back.sensor_T_targets, pairs.sensor_T_targets, atol=1e-12)
    hands = tmp_path / "hands.csv"
    lines = ["image,x,y,z,qx,qy,qz,qw"]
    for k, T in enumerate(pairs.base_T_hands):
        q = _quat_xyzw(T)
        lines.append(f"img_{k}.png," + ",".join(repr(float(v)) for v in (*T[:3, 3], *q)))
    hands.write_text(_spreadsheet("\n".join(lines) + "\n"), encoding="utf-8")
    poses = read_hand_poses(hands)
    np.testing.assert_allclose(poses.base_T_hands, pairs.base_T_hands, atol=1e-12)
    assert poses.images == tuple(f"img_{k}.png" for k in range(5))
    mixed = tmp_path / "mixed.csv"
    mixed.write_text(path.read_text().replace(",", ".", 3))
    with pytest.raises(DatasetError, match=r"both decimal commas and decimal points"):
        read_pose_pairs(mixed)
