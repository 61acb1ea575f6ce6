"""``kinfw calibrate --holdout`` with a held-out file that is not of this setup.

Truth: held-out contacts of the same simulated robot come within a few times the
in-sample error (the parameters' share); contacts simulated with another seed are of
another true robot and probe, so no calibration of this one predicts them. A held-out file
of another robot (other joint names) is refused before any fit, naming that file.
"""

from __future__ import annotations

import json

import pytest

from kinfw.cli._main import main
from tests.cli_run import run_cli
from tests.robots import ARM_6R


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Training and held-out contacts of one simulated 6R arm (alternate samples), the
    contacts of another (seed 9), and the URDF."""
    root = tmp_path_factory.mktemp("holdout")
    (root / "arm.urdf").write_text(ARM_6R)
    for name, seed in (("one", 3), ("other", 9)):
        argv = ["-q", "simulate", "--urdf", root / "arm.urdf", "--contacts", "flange"]
        argv += ["--contact-samples", "80", "--noise-mm", "0.1", "--seed", seed]
        argv += ["--out", root / f"{name}.json", "--truth-out", root / "t.urdf"]
        assert main([str(a) for a in argv]) == 0
    doc = json.loads((root / "one.json").read_text())
    for part, samples in (("train", doc["samples"][0::2]), ("held", doc["samples"][1::2])):
        (root / f"{part}.json").write_text(json.dumps({**doc, "samples": samples}))
    return root


def _calibrate(root, held, capsys):
    argv = ["-q", "calibrate", root / "train.json", "--urdf", root / "arm.urdf"]
    return run_cli([*argv, "--out", root / "cal.urdf", "--holdout", held], capsys)


@pytest.mark.slow
def test_held_out_contacts_of_another_robot_are_warned_about(files, capsys):
    code, _, err = _calibrate(files, files / "other.json", capsys)
    assert code == 0, err
    assert "other.json: flange [probe1] (plane): the held-out error after calibration is" in err
    assert "is it of this robot and setup" in err
    code, _, err = _calibrate(files, files / "held.json", capsys)
    assert code == 0 and "held-out error after calibration is" not in err, err


def test_a_held_out_file_of_another_robot_is_refused_before_any_fit(files, tmp_path, capsys):
    doc = json.loads((files / "held.json").read_text())
    doc["joint_names"] = ["left_j1", *doc["joint_names"][1:]]
    (tmp_path / "mixed.json").write_text(json.dumps(doc))
    code, _, err = _calibrate(files, tmp_path / "mixed.json", capsys)
    assert code == 2 and f"{tmp_path / 'mixed.json'}: joint_names[0]: joint 'left_j1'" in err
    assert "<calibrated>" not in err
