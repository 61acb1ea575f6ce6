"""``kinfw pose-chain`` as a new user meets it: the warning on rounded quaternions, the
errors of a poses CSV (wrong header, non-unit quaternion) and the printed next step.

Truths: the files are written here, so their header, every quaternion's norm, the file
line of each row and its image are known; the messages must name exactly those.
"""

from __future__ import annotations

import numpy as np
import pytest

from kinfw.cli._main import main

HAND = ["hand_x", "hand_y", "hand_z", "hand_qx", "hand_qy", "hand_qz", "hand_qw"]
PLAIN = ["x", "y", "z", "qx", "qy", "qz", "qw"]


def _run(tmp_path, poses, capsys, *extra):
    """Exit code, stdout and stderr of ``kinfw -q pose-chain POSES`` into tmp_path."""
    argv = ["-q", "pose-chain", str(poses), "--camera-frame", "cam", *extra]
    argv += ["--urdf-out", str(tmp_path / "c.urdf"), "--joints-out", str(tmp_path / "j.csv")]
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def _unit(quat):
    q = np.asarray(quat, dtype=float)
    return (q / np.linalg.norm(q)).tolist()


def test_rounded_quaternions_are_renormalised_with_one_warning(tmp_path, capsys):
    """Two of four rows printed with 4 decimals (norms off by ~1e-5 and ~1e-4, computed
    here from the written numbers): one warning line naming the file, 2 of 4 rows and the
    largest deviation; the joints file is written. Exact unit quaternions: no warning."""
    rows = [
        [0.1, 0.2, 0.3, *_unit([0.1, 0.2, 0.3, 0.9])],
        [0.2, 0.2, 0.3, 0.0, 0.0, 0.7071, 0.7071],
        [0.3, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0],
        [0.4, 0.2, 0.3, 0.5002, 0.5, 0.5, 0.5],
    ]
    path = tmp_path / "poses.csv"
    path.write_text(",".join(HAND) + "\n" + "".join(",".join(map(repr, r)) + "\n" for r in rows))
    off = [abs(np.linalg.norm(r[3:]) - 1) for r in rows]
    assert off[0] < 1e-12 and off[2] == 0 and 1e-6 < off[1] < off[3]
    code, _, err = _run(tmp_path, path, capsys)
    assert code == 0, err
    warnings = [line for line in err.splitlines() if "warning" in line]
    assert warnings == [
        f"kinfw pose-chain: warning: {path}: 2 of 4 rows have quaternions (hand_qx, hand_qy, "
        f"hand_qz, hand_qw) whose norms differ from 1 by up to {off[3]:.2g} (rounded?); "
        "renormalised"
    ]
    assert len((tmp_path / "j.csv").read_text().splitlines()) == 5
    rows[1][3:], rows[3][3:] = _unit(rows[1][3:]), _unit(rows[3][3:])
    path.write_text(",".join(HAND) + "\n" + "".join(",".join(map(repr, r)) + "\n" for r in rows))
    code, _, err = _run(tmp_path, path, capsys)
    assert code == 0 and err == ""


def test_a_header_with_neither_column_set_is_one_message_with_both_sets(tmp_path, capsys):
    """One error line: the file, the header as found, both accepted column sets (each
    once) and what is missing of the closer one."""
    path = tmp_path / "poses.csv"
    path.write_text("image,x,y,z,qx,qy,q_z,qw\na.png,0,0,0,0,0,0,1\n")
    code, out, err = _run(tmp_path, path, capsys)
    assert code == 2 and out == ""
    assert err == (
        f"kinfw pose-chain: error: {path}: line 1: the header is [image, x, y, z, qx, qy, "
        "q_z, qw]; expected the columns hand_x, hand_y, hand_z, hand_qx, hand_qy, hand_qz, "
        "hand_qw, or x, y, z, qx, qy, qz, qw (base_T_hand: position, then quaternion "
        "scalar last; optionally 'image' naming each row's image); qz missing\n"
    )
    assert not (tmp_path / "c.urdf").exists()


@pytest.mark.parametrize("columns", [HAND, PLAIN], ids=["hand_", "plain"])
@pytest.mark.parametrize("keyed", [True, False], ids=["image", "no-image"])
def test_a_non_unit_quaternion_names_its_columns_file_line_and_image(
    tmp_path, capsys, columns, keyed
):
    """The bad row is on file line 6 (a blank line before it): the message says "line
    6", the quaternion's columns as the file names them, and the row's image when the
    file has an image column."""
    good = ",".join(["0", "0", "0", "0", "0", "0", "1"])
    lines = [",".join((["image"] if keyed else []) + columns)]
    for k, row in enumerate([good, good, good, "", "0,0,0,0,0,0,2"]):
        lines.append(row if not row or not keyed else f"img_{k}.png,{row}")
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(lines) + "\n")
    code, _, err = _run(tmp_path, path, capsys)
    assert code == 2
    where = f"{path}: line 6" + (" (image 'img_4.png')" if keyed else "")
    assert err == (
        f"kinfw pose-chain: error: {where}: quaternion ({', '.join(columns[3:])}) = "
        "[0.0, 0.0, 0.0, 2.0] has norm 2, not 1 (within 0.001): quaternions are unit, "
        "stored scalar last\n"
    )


def test_the_next_step_names_the_intrinsics_file_and_unit_says_its_default(tmp_path, capsys):
    path = tmp_path / "poses.csv"
    path.write_text(",".join(PLAIN) + "\n" + "0,0,0,0,0,0,1\n" * 3)
    code, out, err = _run(tmp_path, path, capsys, "--unit", "mm")
    assert code == 0, err
    (detect,) = [line for line in out.splitlines() if line.startswith("  kinfw detect")]
    assert f"--joints {tmp_path / 'j.csv'} --camera INTRINSICS.yaml --frame cam " in detect
    assert main(["pose-chain", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "--unit {m,mm} length unit of the CSV's positions (default m)" in text
