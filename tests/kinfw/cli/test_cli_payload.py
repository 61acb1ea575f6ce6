"""``--payload FRAME:MASS_KG[:CX,CY,CZ]`` and ``--gravity GX GY GZ`` of ``kinfw import-csv``
and ``kinfw import-bag``: the file written carries the payload on every sample (the com in
the command's length unit) and the gravity, read back exactly; a malformed option is an
argument error naming the option and the expected form; a frame the URDF lacks is
refused naming the sample and the closest link."""

from __future__ import annotations

import argparse

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from kinfw.cli._args import parse_payload
from kinfw.measurements import read_measurements
from kinfw.model import STANDARD_GRAVITY
from tests.bags import simulated_recording, write_bag
from tests.cli_run import run_cli, without_dirs
from tests.erd import urdf_path
from tests.paths import DATA
from tests.robots import ARM_6R

TIAGO = urdf_path("tiago_description/robots/tiago_no_hand.urdf")
VICON_CSV = DATA / "tiago_figaroh" / "vicon_calibration_gripper3_base1.csv"
IMPORT_CSV = ["-q", "import-csv", VICON_CSV, "--urdf", TIAGO, "--frame", "arm_7_link"]


def test_parse_payload_reads_the_frame_the_mass_and_the_com():
    assert parse_payload("tool0:5") == ("tool0", 5.0, (0.0, 0.0, 0.0))
    assert parse_payload("tool0:2.5:0,-0.01,0.08") == ("tool0", 2.5, (0.0, -0.01, 0.08))
    for text, message in [
        ("tool0", r"expected FRAME:MASS_KG\[:CX,CY,CZ\] \(e\.g\. tool0:5"),
        (":5", r"expected FRAME:MASS_KG"),
        ("tool0:-1", r"MASS_KG a number >= 0 \(kg\), got '-1'"),
        ("tool0:nan", r"MASS_KG a number >= 0"),
        ("tool0:5:0,0", r"CX,CY,CZ three numbers separated by commas, got '0,0'"),
        ("tool0:5:0,0,0:1", r"expected FRAME:MASS_KG"),
    ]:
        with pytest.raises(argparse.ArgumentTypeError, match=message):
            parse_payload(text)


def test_import_csv_writes_the_payload_and_gravity(tmp_path, capsys):
    out = tmp_path / "vicon.json"
    argv = [*IMPORT_CSV, "--measured-in", "vicon", "--out", out]
    argv += ["--payload", "arm_7_link:1.5:0,0,0.12", "--gravity", "0", "0.5", "-9.8"]
    code, _, stderr = run_cli(argv, capsys)
    assert code == 0, stderr
    data = read_measurements(out)
    p = data.payloads
    assert data.n_samples == 21 and p.frames == ("arm_7_link",)
    assert_array_equal(p.frame_index, np.zeros(21))
    assert_array_equal(p.mass_kg, np.full(21, 1.5))
    assert_array_equal(p.com_m, np.tile([0.0, 0.0, 0.12], (21, 1)))
    assert_array_equal(data.gravity, [0.0, 0.5, -9.8])


def test_import_csv_reads_the_payload_com_in_its_length_unit(tmp_path, capsys):
    out = tmp_path / "vicon_mm.json"
    argv = [*IMPORT_CSV, "--length-unit", "mm", "--payload", "arm_7_link:1:0,0,120"]
    code, _, stderr = run_cli([*argv, "--out", out], capsys)
    assert code == 0, stderr
    data = read_measurements(out)
    assert_array_equal(data.payloads.com_m[0], [0.0, 0.0, 0.12])
    assert_array_equal(data.gravity, STANDARD_GRAVITY)


def test_import_csv_refuses_a_bad_payload_or_gravity_naming_the_option(tmp_path, capsys):
    out = tmp_path / "d.json"
    cases = [
        (
            ["--payload", "arm_7_link"],
            "kinfw import-csv: error: argument --payload: expected FRAME:MASS_KG[:CX,CY,CZ]",
        ),
        (["--payload", "arm_7_link:1:0,0"], "argument --payload: expected FRAME:MASS_KG"),
        (["--gravity", "0", "0"], "argument --gravity: expected 3 arguments"),
        (["--gravity", "0", "0", "down"], "argument --gravity: expected a number, got 'down'"),
        (["--gravity", "0", "0", "0"], "error: --gravity 0 0 0: gravity: its norm is 0 m/s^2"),
        (
            ["--payload", "arm_7_lnk:1"],
            "samples[0].payload.frame: 'arm_7_lnk' is not a frame of tiago_no_hand.urdf",
        ),
    ]
    for extra, message in cases:
        code, _, stderr = run_cli([*IMPORT_CSV, *extra, "--out", out], capsys)
        assert code == 2, (extra, stderr)
        assert message in without_dirs(stderr), stderr
        assert len(without_dirs(stderr.splitlines()[0])) < 200
        assert not out.exists()
    assert "closest links: 'arm_7_link', " in stderr


def test_import_bag_writes_the_payload_on_every_sample(tmp_path, capsys):
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(ARM_6R)
    bag = write_bag(tmp_path / "rec", simulated_recording())
    out = tmp_path / "d.json"
    argv = ["-q", "import-bag", bag, "--urdf", urdf, "--pose", "/mocap/pose", "--frame"]
    argv += ["flange", "--payload", "flange:4:0.01,0,0.05", "--gravity", "0", "0", "-9.79"]
    code, _, stderr = run_cli([*argv, "--out", out], capsys)
    assert code == 0, stderr
    data = read_measurements(out)
    assert data.n_samples > 300
    assert data.payloads.frames == ("flange",)
    assert_array_equal(data.payloads.mass_kg, np.full(data.n_samples, 4.0))
    assert_array_equal(data.payloads.com_m, np.tile([0.01, 0.0, 0.05], (data.n_samples, 1)))
    assert_array_equal(data.gravity, [0.0, 0.0, -9.79])
    images = ["-q", "import-bag", bag, "--urdf", urdf, "--images", "/camera/rgb"]
    code, _, stderr = run_cli([*images, "--payload", "flange:4", "--out", tmp_path / "i"], capsys)
    assert code == 2
    assert stderr.startswith("kinfw import-bag: error: --payload and --gravity go into a ")
