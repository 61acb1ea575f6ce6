"""Progress of ``kinfw calibrate`` on stderr: lines when piped (the stages in order, the
Levenberg-Marquardt costs decreasing), a tqdm bar on a terminal, nothing with -q."""

import io
import itertools
import re
import sys

import pytest

from kinfw.cli._main import main
from tests.paths import HEAD_URDF


class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture(scope="module")
def head_data(tmp_path_factory):
    """Both stages of the IIS-head (closed form, hand-eye, refine), with noise."""
    d = tmp_path_factory.mktemp("progress")
    argv = ["simulate", "--urdf", HEAD_URDF, "--out", d / "data.json", "--stage", "both"]
    argv += ["--truth-out", d / "true.urdf"]
    assert main([str(a) for a in (*argv, "--seed", "5")]) == 0
    return d


def _calibrate(head_data, *flags):
    out = head_data / "calibrated.urdf"
    argv = [*flags, "calibrate", "--urdf", HEAD_URDF, "--out", out, "--params", "full"]
    return main([str(a) for a in (*argv, head_data / "data.json")])


def test_piped_lines_have_the_stages_in_order_and_decreasing_costs(head_data, capsys):
    assert _calibrate(head_data) == 0
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = [line.split(" s  ", 1)[1] for line in err.splitlines() if " s  " in line]
    stages = [t for t in lines if "Levenberg-Marquardt" not in t]
    assert stages[:5] == [
        f"loading the URDF {HEAD_URDF}",
        f"reading the measurements {head_data / 'data.json'}",
        "checking the units",
        "checking that the data determine the parameters (start values)",
        "closed form (Shih et al.)",
    ]
    order = ["hand-eye", "refine: joint least squares over every unknown"]
    order += ["refine: start values", "refine: noise estimate, round 1/5"]
    order += ["report: errors after each stage"]
    at = [next(i for i, t in enumerate(stages) if t.startswith(o)) for o in order]
    assert at == sorted(at), stages
    # each Levenberg-Marquardt run of the refinement: iteration 0 first, costs never up
    runs: list[list[float]] = []
    for t in lines:
        m = re.fullmatch(r"Levenberg-Marquardt: iteration (\d+), cost (\S+)", t)
        if m:
            if m.group(1) == "0":
                runs.append([])
            runs[-1].append(float(m.group(2)))
    # a run per noise round printed (up to five: fewer once the noise estimate settles)
    rounds = [t for t in stages if t.startswith("refine: noise estimate, round ")]
    assert len(runs) == len(rounds) >= 2, (runs, rounds)
    for costs in runs:
        assert all(b <= a for a, b in itertools.pairwise(costs)), costs
    assert runs[0][-1] < runs[0][0]  # the first run starts from the closed form, off the fit


def test_quiet_prints_nothing_on_stderr(head_data, capsys):
    assert _calibrate(head_data, "-q") == 0
    out, err = capsys.readouterr()
    assert err == "" and "calibrated" in out


def test_a_terminal_gets_a_tqdm_bar(head_data, capsys, monkeypatch):
    screen = FakeTerminal()
    monkeypatch.setattr(sys, "stderr", screen)
    assert _calibrate(head_data) == 0
    text = screen.getvalue()
    assert "\r" in text and "Levenberg-Marquardt" in text and "iteration/s" in text
    assert "checking the units\n" in text  # the stages are lines above the bar


def test_quiet_and_verbose_together_are_an_argument_error(capsys):
    assert main(["-q", "-v", "calibrate"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err
