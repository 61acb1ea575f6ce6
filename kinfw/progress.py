"""Progress of long work: stages, and steps of loops (Levenberg-Marquardt iterations,
folds, trials), told to whoever listens.

Library code reports without taking a callback argument::

    from kinfw import progress

    progress.stage("reading data.json")
    with progress.task("Levenberg-Marquardt", unit="iteration") as bar:
        for it in range(1, 101):
            ...
            bar.advance(note=f"cost {cost:#.6g}")
    for candidate in progress.steps(candidates, "model choice", unit="candidates"):
        ...

Nothing listens by default: the library prints nothing. A listener is a :class:`Reporter`
installed for a block of code with :func:`reporting` (in a context variable, so a thread
or a worker process of a pool starts silent). The ``kinfw`` command installs
:func:`stderr_reporter`'s (a tqdm bar on a terminal, plain lines when stderr is piped;
none with ``-q``), and so can a program::

    import kinfw
    from kinfw import progress

    with progress.reporting():  # stderr: a bar on a terminal, else lines
        result = kinfw.calibrate(nominal, data)

What is shown: the stages and the loops of the outermost work. A loop inside another
(the Levenberg-Marquardt iterations of each fit of a cross-validation) is a second bar
on a terminal and is not shown as lines, nor are the stages inside a loop, so the lines
of a piped run stay one per stage and one every few steps. A :func:`notice` is a stage
shown wherever it comes from: rare long work a user would otherwise wait through in
silence (compiling the residual functions, once per machine).

Like :mod:`kinfw.cli`, this module imports only the standard library (tqdm when a bar is
first shown).
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Iterable, Iterator, Sized
from contextvars import ContextVar
from typing import TextIO, TypeVar

__all__ = [
    "BarReporter",
    "LineReporter",
    "Reporter",
    "Task",
    "notice",
    "reporting",
    "stage",
    "stderr_reporter",
    "steps",
    "task",
    "write",
]


T = TypeVar("T")


class Task:
    """A loop being reported (:func:`task`): :meth:`advance` after each step. This base
    shows nothing (the task of an inner loop, or when nobody listens)."""

    def advance(self, n: int = 1, note: str = "") -> None:
        """``n`` more steps done; ``note`` says where the loop is (``"cost 12.5"``)."""

    def close(self) -> None:
        """The loop is over."""


class Reporter:
    """Shows stages and tasks; this base shows nothing, the subclasses say how.

    A subclass implements :meth:`show_stage`, :meth:`show_task` (a :class:`Task` of its
    own for a loop at ``depth`` 0, the outermost, 1 inside it, ...) and :meth:`write`.
    The base keeps the depth: stages are shown only outside every task.
    """

    def __init__(self) -> None:
        self.depth = 0
        self.t0 = time.perf_counter()

    def stage(self, text: str) -> None:
        """A stage begins (shown when no task is open)."""
        if self.depth == 0:
            self.show_stage(text)

    def notice(self, text: str) -> None:
        """A stage shown even inside a task (rare, long work: see :func:`notice`)."""
        self.show_stage(text)

    def open(self, name: str, total: int | None, unit: str) -> Task:
        """A loop of ``total`` steps (None: not known ahead) begins."""
        shown = self.show_task(name, total, unit, self.depth)
        self.depth += 1
        return _Nested(self, shown)

    def line(self, text: str) -> str:
        """``text`` after the seconds since this reporter was made: ``"  12.3 s  text"``."""
        return f"{time.perf_counter() - self.t0:6.1f} s  {text}"

    def show_stage(self, text: str) -> None:
        """Show the start of a stage (outside every task)."""

    def show_task(self, name: str, total: int | None, unit: str, depth: int) -> Task:
        """The task that shows a loop opened at ``depth`` (0: outside every other)."""
        return Task()

    def write(self, text: str) -> None:
        """A line that is not progress (a warning), shown without breaking a bar; this
        base prints it on stderr (silence is for progress only)."""
        print(text, file=sys.stderr, flush=True)


class _Nested(Task):
    """A reporter's task that gives the depth back when it closes."""

    def __init__(self, reporter: Reporter, shown: Task) -> None:
        self.reporter, self.shown, self.closed = reporter, shown, False

    def advance(self, n: int = 1, note: str = "") -> None:
        self.shown.advance(n, note)

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.shown.close()
            self.reporter.depth -= 1


class LineReporter(Reporter):
    """Plain lines (no carriage return), for a log or a pipe: one per stage, and for the
    outermost loop its first step, every ``every``-th (a loop of known length: about
    ``lines`` in all) and its last; inner loops are not shown.

    Parameters
    ----------
    stream : file, optional
        Where the lines go (default ``sys.stderr`` at each line).
    every : int
        A loop of unknown length (iterations) shows every ``every``-th step.
    lines : int
        A loop of known length (folds, trials) shows about this many steps.
    """

    def __init__(self, stream: TextIO | None = None, *, every: int = 5, lines: int = 20) -> None:
        super().__init__()
        self.stream, self.every, self.lines = stream, max(int(every), 1), max(int(lines), 1)

    def write(self, text: str) -> None:
        stream = self.stream or sys.stderr
        stream.write(text + "\n")
        stream.flush()

    def show_stage(self, text: str) -> None:
        self.write(self.line(text))

    def show_task(self, name: str, total: int | None, unit: str, depth: int) -> Task:
        if depth:
            return Task()
        every = self.every if total is None else max(-(-total // self.lines), 1)
        return _LineTask(self, name, total, unit, every)


class _LineTask(Task):
    """The outermost loop of a :class:`LineReporter`: ``name: unit 5, note`` or
    ``name: 3/10 units, note`` at the steps the reporter shows, and the last at close."""

    def __init__(
        self, reporter: LineReporter, name: str, total: int | None, unit: str, every: int
    ) -> None:
        self.reporter, self.name, self.total, self.unit = reporter, name, total, unit
        self.every = every
        self.done, self.note, self.shown = 0, "", -1  # shown: the step last shown

    def advance(self, n: int = 1, note: str = "") -> None:
        first = self.shown < 0
        self.done += n
        self.note = note
        if first or self.done % self.every == 0 or self.done == self.total:
            self._show()

    def _show(self) -> None:
        if self.total is None:
            where = f"{self.unit} {self.done}"
        else:
            where = f"{self.done}/{self.total} {self.unit}".rstrip()
        self.reporter.write(
            self.reporter.line(f"{self.name}: {where}" + (f", {self.note}" if self.note else ""))
        )
        self.shown = self.done

    def close(self) -> None:
        if self.shown != self.done:
            self._show()


class BarReporter(Reporter):
    """tqdm bars on a terminal: a line per stage above the bars, a bar per loop (an inner
    loop's below its outer one), each removed when its loop ends.

    Parameters
    ----------
    stream : file, optional
        The terminal (default ``sys.stderr`` when the reporter is made).
    """

    def __init__(self, stream: TextIO | None = None) -> None:
        super().__init__()
        self.stream = stream or sys.stderr

    def write(self, text: str) -> None:
        from tqdm import tqdm

        tqdm.write(text, file=self.stream)

    def show_stage(self, text: str) -> None:
        self.write(self.line(text))

    def show_task(self, name: str, total: int | None, unit: str, depth: int) -> Task:
        from tqdm import tqdm

        bar = tqdm(
            total=total,
            desc=name,
            unit=f" {unit}" if unit else "",
            file=self.stream,
            position=depth,
            leave=False,
            dynamic_ncols=True,
            disable=False,
            mininterval=0.1,
        )
        return _BarTask(bar)


class _BarTask(Task):
    """A loop of a :class:`BarReporter`: its tqdm bar, the note as its postfix."""

    def __init__(self, bar) -> None:
        self.bar = bar

    def advance(self, n: int = 1, note: str = "") -> None:
        if note:  # shown now when no step is (the start of a loop), else with the step
            self.bar.set_postfix_str(note, refresh=n == 0)
        self.bar.update(n)

    def close(self) -> None:
        self.bar.close()


def stderr_reporter() -> Reporter:
    """What ``kinfw`` shows on stderr: a :class:`BarReporter` when stderr is a terminal,
    else a :class:`LineReporter`."""
    return BarReporter(sys.stderr) if sys.stderr.isatty() else LineReporter()


#: The reporter of the running code (None: :data:`_NOBODY`).
_REPORTER: ContextVar[Reporter | None] = ContextVar("kinfw_progress", default=None)

#: Who listens by default: nobody (progress is not shown; :meth:`Reporter.write` prints).
_NOBODY = Reporter()


def _current() -> Reporter:
    return _REPORTER.get() or _NOBODY


@contextlib.contextmanager
def reporting(reporter: Reporter | None = None) -> Iterator[Reporter]:
    """Install ``reporter`` for the block (default :func:`stderr_reporter`; the base
    :class:`Reporter` shows nothing: silence); the one before it is back after."""
    chosen = stderr_reporter() if reporter is None else reporter
    token = _REPORTER.set(chosen)
    try:
        yield chosen
    finally:
        _REPORTER.reset(token)


def stage(text: str) -> None:
    """Tell the listener that a stage begins: ``"reading data.json"``."""
    _current().stage(text)


def notice(text: str) -> None:
    """Tell the listener that rare, long work begins, shown as a stage even inside a
    loop: ``"compiling a residual function into C for this machine, once"``."""
    _current().notice(text)


@contextlib.contextmanager
def task(name: str, total: int | None = None, unit: str = "step") -> Iterator[Task]:
    """A loop of ``total`` steps (None: not known ahead, as iterations) for the listener;
    call the task's :meth:`Task.advance` after each step."""
    opened = _current().open(name, total, unit)
    try:
        yield opened
    finally:
        opened.close()


def steps(items: Iterable[T], name: str, *, unit: str = "step") -> Iterator[T]:
    """``items``, each a step of a :func:`task` called ``name`` (of ``len(items)`` steps
    when they have a length), as ``for item in tqdm(items)``: the step is done when the
    loop's body is."""
    total = len(items) if isinstance(items, Sized) else None
    with task(name, total, unit) as bar:
        for item in items:
            yield item
            bar.advance()


def write(text: str) -> None:
    """A line on the listener's stream without breaking its bar (a warning; on stderr
    when nobody listens)."""
    _current().write(text)
