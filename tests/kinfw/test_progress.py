"""kinfw.progress: what each reporter shows of stages and loops, and that nobody listens
by default."""

import io
import sys

import pytest

from kinfw import progress
from kinfw.progress import BarReporter, LineReporter, Reporter, reporting, stderr_reporter
from tests.recorder import Recorder


class FakeTerminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def _iterations(n: int) -> None:
    """A loop of ``n`` iterations of unknown length, cost 100 / step, inside a stage."""
    progress.stage("fitting")
    with progress.task("LM", unit="iteration") as bar:
        bar.advance(0, "cost 100")
        for it in range(1, n + 1):
            bar.advance(note=f"cost {100 / (it + 1):.4g}")


def _strip_seconds(text: str) -> list[str]:
    """The lines without their ``  12.3 s  `` prefix."""
    return [line.split(" s  ", 1)[1] for line in text.splitlines()]


def test_nobody_listens_by_default(capfd):
    _iterations(7)
    with progress.task("trials", total=3) as bar:
        for _ in range(3):
            bar.advance()
    assert capfd.readouterr() == ("", "")


def test_lines_show_the_first_every_fifth_and_the_last_iteration():
    out = io.StringIO()
    with reporting(LineReporter(out, every=5)):
        _iterations(12)
    assert _strip_seconds(out.getvalue()) == [
        "fitting",
        "LM: iteration 0, cost 100",
        "LM: iteration 5, cost 16.67",
        "LM: iteration 10, cost 9.091",
        "LM: iteration 12, cost 7.692",
    ]
    assert "\r" not in out.getvalue()


def test_lines_of_a_counted_loop_are_about_lines_in_all_and_the_last():
    out = io.StringIO()
    with reporting(LineReporter(out, lines=4)), progress.task("fits", total=10, unit="") as bar:
        for _ in range(10):
            bar.advance()
    # every ceil(10 / 4) = 3 steps, the first and the last
    assert _strip_seconds(out.getvalue()) == [
        "fits: 1/10",
        "fits: 3/10",
        "fits: 6/10",
        "fits: 9/10",
        "fits: 10/10",
    ]


def test_lines_show_only_the_outermost_loop_and_no_stage_inside_it():
    out = io.StringIO()
    with reporting(LineReporter(out, every=1)):
        progress.stage("model choice")
        with progress.task("fits", total=2, unit="fits") as fits:
            for _ in range(2):
                _iterations(3)  # a stage and a loop inside each fit: not shown
                fits.advance()
        progress.stage("refine")
    assert _strip_seconds(out.getvalue()) == [
        "model choice",
        "fits: 1/2 fits",
        "fits: 2/2 fits",
        "refine",
    ]


def test_a_notice_is_shown_inside_a_loop_where_a_stage_is_not(capfd):
    out = io.StringIO()
    with reporting(LineReporter(out, every=1)), progress.task("fits", total=1, unit="fit") as f:
        with progress.task("LM", unit="iteration"):
            progress.stage("refine: start values")  # inside a loop: not a line
            progress.notice("compiling a residual function")
        f.advance()
    assert _strip_seconds(out.getvalue()) == ["compiling a residual function", "fits: 1/1 fit"]
    progress.notice("compiling, nobody listening")
    assert capfd.readouterr() == ("", "")


def test_a_recorder_sees_the_depth_of_each_loop_and_the_depth_comes_back():
    recorder = Recorder()
    with reporting(recorder):
        with progress.task("fits", total=2) as fits:
            _iterations(2)
            fits.advance()
            with pytest.raises(RuntimeError), progress.task("failing"):
                raise RuntimeError("a fit fails")
            fits.advance()
        _iterations(1)
    assert [(t.name, t.depth, t.closed) for t in recorder.tasks] == [
        ("fits", 0, True),
        ("LM", 1, True),
        ("failing", 1, True),
        ("LM", 0, True),
    ]
    assert recorder.tasks[1].steps == [(0, "cost 100"), (1, "cost 50"), (2, "cost 33.33")]
    assert recorder.stages == ["fitting"]  # the one outside "fits"
    assert recorder.depth == 0


def test_a_terminal_gets_a_tqdm_bar_and_lines_above_it():
    screen = FakeTerminal()
    with reporting(BarReporter(screen)):
        _iterations(3)
        progress.write("kinfw calibrate: warning: something")
    text = screen.getvalue()
    assert "\r" in text  # tqdm redraws its line
    assert "LM" in text and "iteration" in text
    assert "fitting\n" in text and "kinfw calibrate: warning: something\n" in text


def test_stderr_reporter_is_a_bar_on_a_terminal_and_lines_on_a_pipe(monkeypatch):
    monkeypatch.setattr(sys, "stderr", FakeTerminal())
    assert isinstance(stderr_reporter(), BarReporter)
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert isinstance(stderr_reporter(), LineReporter)


def test_reporting_restores_the_reporter_before_it():
    outer, inner = Recorder(), Recorder()
    with reporting(outer):
        with reporting(inner):
            progress.stage("inner")
        with reporting(Reporter()):  # silence for a block
            progress.stage("silenced")
        progress.stage("outer")
    progress.stage("nobody")
    assert (outer.stages, inner.stages) == (["outer"], ["inner"])


def test_write_without_a_reporter_goes_to_stderr(capsys):
    progress.write("a warning")
    assert capsys.readouterr().err == "a warning\n"


def test_steps_is_a_step_per_item_after_its_body_and_a_break_closes_the_task():
    recorder = Recorder()
    seen = []
    with reporting(recorder):
        for item in progress.steps(["a", "b", "c"], "items", unit="items"):
            seen.append((item, list(recorder.tasks[0].steps)))
        for item in progress.steps(iter(range(10)), "unsized"):
            if item == 2:
                break
    assert seen == [("a", []), ("b", [(1, "")]), ("c", [(1, ""), (2, "")])]
    items, unsized = recorder.tasks
    assert (items.total, items.steps[-1], items.closed) == (3, (3, ""), True)
    assert (unsized.total, unsized.steps[-1], unsized.closed) == (None, (2, ""), True)
    assert recorder.depth == 0
