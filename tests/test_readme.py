"""README.md stays true: its Python API example runs and says what the README shows."""

import json
import re
import runpy

import pytest

from kinfw.cli._main import main
from tests.paths import REPO

README = REPO / "README.md"


def _demo_report(tmp_path, capsys) -> dict:
    assert main(["demo", "--out", str(tmp_path / "demo_out"), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.slow
def test_the_demo_numbers_in_the_readme_are_what_the_demo_prints(tmp_path, capsys):
    """The README's demo table and noise line against a fresh run of the demo, within
    the tolerance the README states (BLAS changes the last digits)."""
    report = _demo_report(tmp_path, capsys)
    text = README.read_text()
    block = (
        re.search(
            r"held-out position RMS against the true robot \(noise-free\), mm, "
            r"after each stage:\n(.*?)```",
            text,
            re.S,
        )
        .group(1)
        .splitlines()
    )
    stages = block[0].split()[3:]  # after "position RMS mm"
    by_stage = report["position_rms_mm_vs_truth_held_out_by_stage"]
    assert [s.replace("closed", "closed form") for s in stages if s != "form"] == list(by_stage)
    assert len(block) == 1 + len(by_stage["nominal"])
    for line in block[1:]:
        group, values = line.rsplit(")", 1)
        for stage, value in zip(by_stage, values.split(), strict=True):
            assert float(value) == pytest.approx(by_stage[stage][group.strip() + ")"], abs=0.005), (
                group,
                stage,
            )
    noise = re.search(r"estimated noise is printed too: ([\d.]+) mm per axis and\s+([\d.]+)°", text)
    assert float(noise.group(1)) == pytest.approx(
        report["refine"]["noise"]["position_sigma_mm"], abs=0.002
    )
    assert float(noise.group(2)) == pytest.approx(
        report["refine"]["noise"]["rotation_sigma_deg_per_component"], abs=0.002
    )


@pytest.mark.slow
def test_the_python_api_example_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _demo_report(tmp_path, capsys)
    code = re.search(r"## Python API\n\n```python\n(.*?)```", README.read_text(), re.S)
    script = tmp_path / "api.py"
    script.write_text(code.group(1), encoding="utf-8")
    runpy.run_path(str(script), run_name="__main__")
    out = capsys.readouterr().out
    assert "rank 50/50" in out
    # pan's parameters with the units of their block: axis tilts in rad, offsets in m
    units = dict(re.findall(r"  pan (\w+): \S+ \+- \S+ (\w+)", out))
    assert units == {"b_tilt_1": "rad", "b_tilt_2": "rad", "l_x": "m", "l_y": "m"}
    held_out = [float(v) for v in re.findall(r"held out \w+: ([\d.]+) mm RMS", out)]
    assert len(held_out) == 4 and all(v < 1.5 for v in held_out)
    assert (tmp_path / "scene.html").stat().st_size > 900_000
    assert (tmp_path / "my_calibrated.urdf").read_text().count("<visual") > 10


def test_the_first_command_is_the_demo_and_the_second_the_tests():
    blocks = re.findall(r"```bash\n(.*?)```", README.read_text(), re.S)
    commands = [line for line in blocks[0].splitlines() if line and not line.startswith("#")]
    assert commands[0].endswith("kinfw demo --out demo_out")
    assert commands[1].endswith("python -m pytest")
    ci = (README.parent / ".ci" / "run").read_text()
    assert commands[1].replace('pip install -e ".[test]"', 'pip install -q -e ".[test]"') in ci
