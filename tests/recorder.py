"""A :class:`kinfw.progress.Reporter` that records what the library tells it."""

from __future__ import annotations

from dataclasses import dataclass, field

from kinfw.progress import Reporter, Task


@dataclass
class Recorded(Task):
    """One task: its name, length, unit, depth and each step's ``(done, note)``."""

    name: str
    total: int | None
    unit: str
    depth: int
    steps: list[tuple[int, str]] = field(default_factory=list)
    closed: bool = False

    def advance(self, n: int = 1, note: str = "") -> None:
        done = self.steps[-1][0] + n if self.steps else n
        self.steps.append((done, note))

    def close(self) -> None:
        self.closed = True


class Recorder(Reporter):
    """Records the stages (outside every task) and every task, at any depth."""

    def __init__(self) -> None:
        super().__init__()
        self.stages: list[str] = []
        self.tasks: list[Recorded] = []

    def show_stage(self, text: str) -> None:
        self.stages.append(text)

    def show_task(self, name: str, total: int | None, unit: str, depth: int) -> Task:
        self.tasks.append(Recorded(name, total, unit, depth))
        return self.tasks[-1]
