"""README.md stays true: its Python API example runs and says what the README shows."""

import re
import runpy
from pathlib import Path

from kinfw.cli import main

README = Path(__file__).resolve().parents[1] / "README.md"


def test_the_python_api_example_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--out", "demo_out", "--json"]) == 0
    capsys.readouterr()
    code = re.search(r"## Python API\n\n```python\n(.*?)```", README.read_text(), re.S)
    script = tmp_path / "api.py"
    script.write_text(code.group(1), encoding="utf-8")
    runpy.run_path(str(script), run_name="__main__")
    out = capsys.readouterr().out
    assert "rank 50/50" in out
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
