"""docs/rehearse.md stays true: every command in its ``sh`` blocks runs, in order, in an
empty directory, and the numbers it states are what the commands print."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys

import pytest

from kinfw.cli._main import main
from tests.paths import REPO

PAGE = REPO / "docs" / "rehearse.md"


def _commands() -> list[str]:
    """The lines of the page's ``sh`` blocks, in order."""
    blocks = re.findall(r"```sh\n(.*?)```", PAGE.read_text(), re.S)
    return [line for block in blocks for line in block.splitlines() if line.strip()]


def _mean_calibrated_mm(text: str) -> float:
    """The calibrated column of ``kinfw crossval``'s ``mean`` row."""
    return float(next(x for x in text.splitlines() if x.startswith("mean")).split()[-1])


@pytest.mark.slow
def test_every_command_of_the_rehearsal_page_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    outputs = {}
    for line in _commands():
        argv = shlex.split(line)
        if argv[0] == "python":
            subprocess.run([sys.executable, *argv[1:]], check=True, cwd=tmp_path)
            continue
        assert argv[0] == "kinfw", line
        capsys.readouterr()
        code = main(["-q", *argv[1:]])
        out = capsys.readouterr()
        assert code == 0, (line, out.err)
        outputs[line] = out.out
    assert (tmp_path / "detected.json").is_file() and (tmp_path / "camera_cal.urdf").is_file()
    assert (tmp_path / "wall_detected.json").is_file() and (tmp_path / "wall_cal.urdf").is_file()
    # "With 40 samples ... about 0.9 mm (the noise floor ... 0.87 mm), with 20 it is larger"
    crossval = {k: _mean_calibrated_mm(v) for k, v in outputs.items() if "crossval" in k}
    forty = next(v for k, v in crossval.items() if "mocap.json" in k)
    twenty = next(v for k, v in crossval.items() if "mocap20.json" in k)
    assert 0.8 < forty < 1.0 and twenty > forty, crossval
