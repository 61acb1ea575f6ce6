"""Bad input to the kinfw command line: exit 2, one line naming what and where, and no
file written or changed (issue 10, items 4, 5 and the start-up part of 8).

The files a failed command leaves are compared with the ones before it by name and
SHA-256; commands that must fail before any work run with the solver replaced by one
that fails the test.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import stat
import subprocess
import sys
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from kinfw.cli._main import main
from kinfw.files import (
    OutputPathError,
    atomic_path,
    check_output_dir,
    check_outputs,
    write_text_atomic,
)
from tests.paths import HEAD_URDF

HEAD = HEAD_URDF


def _run(argv, capsys):
    """Exit code, stdout and stderr of ``kinfw -q ARGV`` (-q: no progress lines, so
    stderr holds only what the command says: its warnings and errors)."""
    code = main(["-q", *(str(a) for a in argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


def _snapshot(root: Path) -> dict[str, str]:
    """Every file and symlink under ``root``: relative name -> SHA-256 (or link target)."""
    out = {}
    for path in sorted(root.rglob("*")):
        rel = str(path.relative_to(root))
        if path.is_symlink():
            out[rel] = f"-> {path.readlink()}"
        elif path.is_file():
            out[rel] = hashlib.sha256(path.read_bytes()).hexdigest()
        else:
            out[rel] = "dir"
    return out


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A noise-free head dataset (stage 1 and 2) and its true URDF, made once."""
    d = tmp_path_factory.mktemp("sim")
    assert (
        main(
            [
                "simulate",
                "--out",
                str(d / "d.json"),
                "--truth-out",
                str(d / "t.urdf"),
                "--noise-mm",
                "0",
                "--noise-deg",
                "0",
                "--stage",
                "both",
                "--seed",
                "5",
            ]
        )
        == 0
    )
    return d


@pytest.fixture
def workdir(simulated, tmp_path, monkeypatch):
    """A directory holding the inputs of a calibration and the outputs of an earlier one
    (with recognisable contents), the current directory of the test."""
    for name in ("d.json", "t.urdf"):
        (tmp_path / name).write_bytes((simulated / name).read_bytes())
    (tmp_path / "h.json").write_bytes((simulated / "d.json").read_bytes())
    (tmp_path / "c.urdf").write_text("<robot name='earlier calibration'/>\n")
    (tmp_path / "c.kinfw.json").write_text('{"earlier": "sidecar"}\n')
    (tmp_path / "r.json").write_text('{"earlier": "report"}\n')
    (tmp_path / "notes.txt").write_text("a file, not a directory\n")
    (tmp_path / "out_dir").mkdir()
    (tmp_path / "link.urdf").symlink_to("c.urdf")
    (tmp_path / "head.urdf").write_bytes(HEAD.read_bytes())
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _no_solving(*args, **kwargs):
    raise AssertionError("the command started to work before checking its outputs")


CAL = ["calibrate", "d.json", "--urdf", "head.urdf"]
SIM = ["simulate", "--urdf", "head.urdf"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            [*CAL, "--out", "missing_dir/c.urdf"],
            r"--out missing_dir/c\.urdf: directory 'missing_dir' does not exist",
        ),
        (
            [*CAL, "--out", "c.urdf", "--report", "missing_dir/r.json"],
            r"--report missing_dir/r\.json: directory 'missing_dir' does not exist",
        ),
        ([*CAL, "--out", "notes.txt/c.urdf"], r"'notes\.txt' is not a directory"),
        ([*CAL, "--out", "out_dir"], r"--out out_dir: is a directory"),
        (
            ["calibrate", "d.json", "--urdf", "c.urdf", "--out", "c.urdf"],
            r"--out c\.urdf is the same file as --urdf c\.urdf: refusing to overwrite an input",
        ),
        (
            ["calibrate", "d.json", "--urdf", "link.urdf", "--out", "c.urdf"],
            r"--out c\.urdf is the same file as --urdf link\.urdf",
        ),
        (
            ["calibrate", "d.json", "--urdf", "head.urdf", "--out", "./out_dir/../head.urdf"],
            r"is the same file as --urdf head\.urdf",
        ),
        (
            [*CAL, "--out", "c.urdf", "--report", "d.json"],
            r"--report d\.json is the same file as data file d\.json",
        ),
        (
            [*CAL, "--out", "c.urdf", "--holdout", "h.json", "--report", "h.json"],
            r"--report h\.json is the same file as --holdout h\.json",
        ),
        (
            ["calibrate", "c.kinfw.json", "--urdf", "head.urdf", "--out", "c.urdf"],
            r"sidecar c\.kinfw\.json is the same file as data file c\.kinfw\.json",
        ),
        (
            [*CAL, "--out", "c.urdf", "--report", "c.urdf"],
            r"--report c\.urdf is the same file as --out c\.urdf: give two different outputs",
        ),
        (
            [*SIM, "--out", "a.json", "--truth-out", "a.json"],
            r"--truth-out a\.json is the same file as --out a\.json",
        ),
        (
            [*SIM, "--out", "head.urdf", "--truth-out", "t2.urdf"],
            r"--out head\.urdf is the same file as --urdf head\.urdf",
        ),
        (
            [*SIM, "--out", "x.json", "--truth-out", "missing_dir/t.urdf"],
            r"--truth-out missing_dir/t\.urdf: directory 'missing_dir' does not exist",
        ),
        (
            [*CAL, "--out", "c.urdf", "--camera", "left=r.json", "--report", "r.json"],
            r"--report r\.json is the same file as --camera left=r\.json: refusing",
        ),
        (
            [*CAL, "--out", "c.urdf", "--camera", "left=c.urdf"],
            r"--out c\.urdf is the same file as --camera left=c\.urdf: refusing",
        ),
        (
            [*SIM, "--out", "a.json", "--truth-out", "t.urdf", "--camera", "left=a.json"],
            r"--out a\.json is the same file as --camera left=a\.json: refusing",
        ),
        (["demo", "--out", "notes.txt"], r"--out notes\.txt: exists and is not a directory"),
        (
            ["view", "head.urdf", "--html", "head.urdf"],
            r"--html head\.urdf is the same file as nominal head\.urdf",
        ),
        (
            [
                "view",
                "head.urdf",
                "--calibrated",
                "t.urdf",
                "--html",
                "c.kinfw.json",
                "--sidecar",
                "c.kinfw.json",
            ],
            r"--html c\.kinfw\.json is the same file as sidecar",
        ),
        (
            ["reproduce", "table4", "--out", "notes.txt/sub"],
            r"--out notes\.txt/sub: cannot create it, '.*notes\.txt' is a file",
        ),
    ],
)
def test_bad_output_fails_before_any_work_and_changes_no_file(
    argv, message, workdir, capsys, monkeypatch
):
    import kinfw.identification._pipeline
    import kinfw.simulation._simulate

    monkeypatch.setattr(kinfw.identification._pipeline, "identify", _no_solving)
    monkeypatch.setattr(kinfw.simulation._simulate, "simulate_at", _no_solving)
    before = _snapshot(workdir)
    code, out, err = _run(argv, capsys)
    assert code == 2
    assert out == ""
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"kinfw {argv[0]}: error: ")
    assert re.search(message, err), err
    assert _snapshot(workdir) == before


@pytest.mark.slow
def test_a_good_calibration_replaces_the_earlier_outputs(workdir, capsys):
    """The counterpart of the test above: the same directory, correct arguments."""
    before = _snapshot(workdir)
    code, _, err = _run([*CAL, "--out", "c.urdf", "--report", "r.json"], capsys)
    assert code == 0, err
    after = _snapshot(workdir)
    assert {k for k in after if after[k] != before.get(k)} == {"c.urdf", "c.kinfw.json", "r.json"}
    assert set(after) == set(before)  # no temporary file left
    assert json.loads((workdir / "r.json").read_text())["sidecar"] == "c.kinfw.json"


# -- atomic writes -----------------------------------------------------------------------
def test_write_text_atomic_replaces_the_file_and_leaves_nothing_else(tmp_path):
    path = tmp_path / "a.txt"
    path.write_text("old")
    assert write_text_atomic(path, "new ünïcode\n") == path
    assert path.read_text(encoding="utf-8") == "new ünïcode\n"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_a_failed_write_leaves_the_earlier_file_intact(tmp_path):
    path = tmp_path / "a.txt"
    path.write_text("earlier content")
    with pytest.raises(UnicodeEncodeError):
        write_text_atomic(path, "half written, then é", encoding="ascii")
    assert path.read_text() == "earlier content"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]
    with pytest.raises(RuntimeError, match="plot failed"), atomic_path(tmp_path / "p.png") as t:
        t.write_bytes(b"partial")
        raise RuntimeError("plot failed")
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_atomic_path_keeps_the_suffix_and_the_usual_permissions(tmp_path):
    umask = os.umask(0o022)
    try:
        with atomic_path(tmp_path / "plot.png") as tmp:
            assert tmp.parent == tmp_path and tmp.suffix == ".png"
            tmp.write_bytes(b"png")
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / "plot.png").stat().st_mode) == 0o644


def test_check_outputs_without_labels_and_directory_creation(tmp_path):
    (tmp_path / "in.txt").write_text("x")
    with pytest.raises(OutputPathError, match=r"in\.txt is the same file as \S*in\.txt: refusing"):
        check_outputs({"": tmp_path / "in.txt"}, inputs={"": tmp_path / "in.txt"})
    # a directory that does not exist yet but can be created: accepted, not created
    assert check_output_dir(tmp_path / "a" / "b") == tmp_path / "a" / "b"
    assert not (tmp_path / "a").exists()
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "report.json").mkdir()
    with pytest.raises(OutputPathError, match=r"report\.json: is a directory"):
        check_output_dir(tmp_path / "d", label="--out", files=("report.json",))


# -- messages ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["view", HEAD, "--data", "D", "--sample", "999"],
            r"--sample 999: out of range, D has 6 samples \(give 0 to 5\)",
        ),
        (
            ["view", HEAD, "--data", "D", "--sample", "-1"],
            r"--sample -1: out of range, D has 6 samples \(give 0 to 5\)",
        ),
        (["view", HEAD, "--sample", "2"], r"--sample 2: give --data"),
        (["verify", HEAD, "empty.json"], r"empty\.json: the file is empty"),
        (["verify", HEAD, "blank.json"], r"blank\.json: the file is empty"),
    ],
)
def test_bad_input_names_the_range_or_the_empty_file(
    argv, message, simulated, tmp_path, capsys, monkeypatch
):
    from kinfw.measurements import read_measurements, write_measurements

    monkeypatch.chdir(tmp_path)
    write_measurements("D", read_measurements(simulated / "d.json").subset(range(6)))
    (tmp_path / "empty.json").write_text("")
    (tmp_path / "blank.json").write_text(" \n\n")
    code, _, err = _run(argv, capsys)
    assert code == 2
    assert len(err.splitlines()) == 1, err
    assert re.search(message, err), err


@pytest.mark.parametrize(
    ("argv", "flag", "expected"),
    [
        (["simulate", "--noise-mm", "-1"], "--noise-mm", r"a number >= 0 \(mm\), got '-1'"),
        (["simulate", "--noise-deg", "-0.5"], "--noise-deg", r">= 0 \(deg\), got '-0.5'"),
        (["simulate", "--stereo-mm", "nan"], "--stereo-mm", r">= 0 \(mm\), got 'nan'"),
        (["simulate", "--error-mm", "-2"], "--error-mm", r">= 0 \(mm\)"),
        (["simulate", "--error-deg", "inf"], "--error-deg", r">= 0 \(deg\), got 'inf'"),
        (["simulate", "--per-joint", "0"], "--per-joint", r"an integer >= 1, got '0'"),
        (["simulate", "--per-joint", "2.5"], "--per-joint", r"an integer >= 1, got '2.5'"),
        (["simulate", "--stage2-samples", "0"], "--stage2-samples", r"an integer >= 1"),
        (["simulate", "--fraction", "0"], "--fraction", r"a number > 0 and <= 1, got '0'"),
        (["simulate", "--fraction", "1.5"], "--fraction", r"> 0 and <= 1, got '1.5'"),
        (["simulate", "--seed", "-1"], "--seed", r"an integer >= 0"),
        (["calibrate", "d.json", "--sigma-mm", "0"], "--sigma-mm", r"a number > 0 \(mm\)"),
        (["calibrate", "d.json", "--sigma-deg", "-1"], "--sigma-deg", r"> 0 \(deg\)"),
        (["calibrate", "d.json", "--prior-mm", "-1"], "--prior-mm", r"> 0 \(mm\)"),
        (["calibrate", "d.json", "--prior-deg", "x"], "--prior-deg", r"> 0 \(deg\), got 'x'"),
        (["calibrate", "d.json", "--prior", "offsets=0.5"], "--prior", r"GROUP=VALUE UNIT"),
        (["crossval", "d.json", "--k", "1"], "--k", r"an integer >= 2, got '1'"),
        (["crossval", "d.json", "--sigma-mm", "-3"], "--sigma-mm", r"> 0 \(mm\)"),
        (["crosscheck", "u.urdf", "-n", "0"], "-n", r"an integer >= 1, got '0'"),
        (["view", "u.urdf", "--residual-scale", "0"], "--residual-scale", r"a number > 0"),
        (["view", "u.urdf", "--up", "0 0 0"], "--up", r"three numbers \"x y z\", not all"),
        (["reproduce", "fig11", "--trials", "0"], "--trials", r"an integer >= 1, got '0'"),
    ],
)
def test_numbers_are_checked_in_the_users_units_naming_the_flag(argv, flag, expected, capsys):
    code, out, err = _run(argv, capsys)
    assert code == 2
    assert out == ""
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"kinfw {argv[0]}: error: argument {flag}: expected "), err
    assert re.search(expected, err), err
    assert "noise_m" not in err and "Traceback" not in err


def test_argument_errors_are_one_line_too(capsys):
    code, _, err = _run(["calibrate", "d.json"], capsys)
    assert code == 2
    assert err == (
        "kinfw calibrate: error: the following arguments are required: --urdf, "
        "--out (see 'kinfw calibrate --help')\n"
    )


MISSING_PARENT = """<robot name="r">
  <link name="base"/>
  <link name="l1"/>
  <joint name="j1" type="revolute">
    <parent link="bse"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>
"""


@pytest.mark.parametrize(
    ("xml", "message"),
    [
        (
            MISSING_PARENT,
            r"joint 'j1': its parent link 'bse' is not a <link> of the URDF "
            r"\(links: base, l1\); did you mean 'base'\?",
        ),
        (
            MISSING_PARENT.replace('"bse"', '"base"').replace('"l1"/><axis', '"l2"/><axis'),
            r"joint 'j1': its child link 'l2' is not a <link> of the URDF",
        ),
        (
            MISSING_PARENT.replace('"bse"', '"base"').replace('<parent link="base"/>', ""),
            r"joint 'j1' has no <parent link=\.\.\.>",
        ),
        (
            MISSING_PARENT.replace('<link name="l1"/>', '<link name="base"/>'),
            r"link 'base' is declared twice",
        ),
    ],
)
def test_a_urdf_with_an_undeclared_link_names_the_joint_and_the_link(xml, message):
    from kinfw.model import RobotModelError, load_robot

    with pytest.raises(RobotModelError, match=message):
        load_robot(xml)


def test_a_missing_parent_link_is_one_line_and_urdfdom_prints_nothing(tmp_path, capfd):
    (tmp_path / "bad.urdf").write_text(MISSING_PARENT)
    code = main(["-q", "crosscheck", str(tmp_path / "bad.urdf")])  # -q: no progress
    out, err = capfd.readouterr()  # file descriptors: C++ output would be here
    assert code == 2
    assert out == ""
    assert err.splitlines() == [
        f"kinfw crosscheck: error: {tmp_path / 'bad.urdf'}: joint "
        "'j1': its parent link 'bse' is not a <link> of the URDF "
        "(links: base, l1); did you mean 'base'?"
    ]


def test_urdfdom_errors_become_the_message_not_stderr_lines(capfd):
    """A URDF that only urdfdom refuses (a revolute joint without limits): its reason is
    in the one error, nothing else reaches the terminal."""
    from kinfw.model import RobotModelError, load_robot

    xml = MISSING_PARENT.replace('"bse"', '"base"').replace(
        '<limit lower="-1" upper="1" effort="1" velocity="1"/>', ""
    )
    with pytest.raises(
        RobotModelError,
        match=r"Pinocchio cannot load this URDF \(Joint \[j1\] "
        r"is of type REVOLUTE but it does not specify limits",
    ):
        load_robot(xml)
    assert capfd.readouterr().err == ""


def _narrow_pan(tmp_path: Path) -> Path:
    """The head URDF with the pan joint limited to +-0.1 rad (the data go to pi/2)."""
    tree = ET.parse(HEAD)
    limit = tree.getroot().find("joint[@name='pan']/limit")
    limit.set("lower", "-0.1")
    limit.set("upper", "0.1")
    path = tmp_path / "narrow.urdf"
    tree.write(path)
    return path


def test_the_joint_limit_warning_is_printed_once_as_one_line(simulated, tmp_path, capsys):
    code, _, err = _run(
        [
            "calibrate",
            simulated / "d.json",
            "--urdf",
            _narrow_pan(tmp_path),
            "--out",
            tmp_path / "c.urdf",
        ],
        capsys,
    )
    assert code == 0, err
    lines = err.splitlines()
    limit_lines = [line for line in lines if "outside its URDF limits" in line]
    assert len(limit_lines) == 1, err
    assert limit_lines[0].startswith("kinfw calibrate: warning: ")
    assert "joint 'pan'" in limit_lines[0] and "[-0.1, 0.1] rad" in limit_lines[0]
    assert not any("UserWarning" in line or line.startswith("  ") for line in lines), err


def test_the_joint_limit_warning_is_attributed_to_one_place(simulated, tmp_path):
    """Every pipeline stage checks the data from its own line: Python's default filter
    must still show the warning once (it keys on text and place)."""
    from kinfw.measurements import check_against_robot, read_measurements
    from kinfw.model import load_robot

    robot = load_robot(_narrow_pan(tmp_path))
    data = read_measurements(simulated / "d.json")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        check_against_robot(data, robot)  # as the closed form does
        check_against_robot(data, robot)  # as the refinement does, from another line
    assert [str(w.message).split(": ", 1)[1][:24] for w in caught] == ["joint 'pan' is outside i"]


# -- start-up ----------------------------------------------------------------------------
def test_the_command_line_loads_no_heavy_module_to_start():
    heavy = ("numpy", "pinocchio", "casadi", "matplotlib", "meshcat", "yourdfpy")
    code = (
        "import contextlib, io, sys\n"
        "import kinfw.cli\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    assert kinfw.cli.main(['--help']) == 0\n"
        "    assert kinfw.cli.main(['calibrate', '--help']) == 0\n"
        f"print(sorted(m for m in {heavy!r} if m in sys.modules))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_the_lazy_package_still_exports_every_name():
    import kinfw

    for name in kinfw.__all__:
        assert getattr(kinfw, name).__module__.startswith("kinfw."), name
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        kinfw.nope  # noqa: B018


def test_warnings_and_logged_warnings_are_printed_once_each(capsys):
    """The command line's printer on its own: the same warning from three places, a
    logged warning twice, an info line that only --verbose shows; a third-party
    DeprecationWarning (pyzmq under meshcat) is not the user's and is not shown."""
    import logging

    from kinfw.cli._main import _warnings_printed_once

    with _warnings_printed_once("demo", verbose=False):
        for _ in range(2):
            warnings.warn("the same\n  text", UserWarning, stacklevel=1)
        warnings.warn("the same text", UserWarning, stacklevel=1)
        warnings.warn("another", RuntimeWarning, stacklevel=1)
        warnings.warn("a library's deprecation", DeprecationWarning, stacklevel=1)
        logging.getLogger("identification.x").warning("logged %d", 1)
        logging.getLogger("identification.x").warning("logged %d", 1)
        logging.getLogger("identification.x").info("not shown")
    assert capsys.readouterr().err.splitlines() == [
        "kinfw demo: warning: the same text",
        "kinfw demo: warning: another",
        "kinfw demo: warning: logged 1",
    ]
    with _warnings_printed_once("demo", verbose=True):
        logging.getLogger("identification.x").info("shown")
    assert capsys.readouterr().err == "INFO identification.x: shown\n"
