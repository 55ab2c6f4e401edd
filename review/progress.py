"""Progress of a long review, as a rich progress bar on stderr (never on stdout: ``--json`` stays JSON).

:class:`Stages` hands out one callback per stage (reading, estimating, writing); each takes the
fraction of that stage done (0..1). :class:`NoProgress` is the silent stand-in (tests, ``--json``,
stderr not a terminal).
"""

from __future__ import annotations

from collections.abc import Callable
from types import TracebackType

from rich.console import Console
from rich.progress import BarColumn, Progress, TaskID, TextColumn, TimeElapsedColumn

#: Stages of a review and their share of the bar.
STAGES = {"reading": 0.3, "estimating": 0.6, "writing": 0.1}


class NoProgress:
    """Progress that shows nothing."""

    def stage(self, name: str) -> Callable[[float], None] | None:
        return None

    def __enter__(self) -> NoProgress:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:  # fmt: skip
        return None


class Stages(NoProgress):
    """One rich progress bar on stderr over the review's stages."""

    def __init__(self, label: str) -> None:
        self._bar = Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f} %"),
                             TimeElapsedColumn(), console=Console(stderr=True), transient=True)  # fmt: skip
        self._task: TaskID = self._bar.add_task(label, total=1.0)
        self._label = label
        self._base = 0.0

    def stage(self, name: str) -> Callable[[float], None] | None:
        base = sum(w for k, w in STAGES.items() if list(STAGES).index(k) < list(STAGES).index(name))
        weight = STAGES[name]

        def update(fraction: float) -> None:
            self._bar.update(self._task, completed=base + weight * min(max(fraction, 0.0), 1.0),
                             description=f"{self._label}: {name}")  # fmt: skip

        update(0.0)
        return update

    def __enter__(self) -> Stages:
        self._bar.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:  # fmt: skip
        self._bar.stop()


__all__ = ["STAGES", "NoProgress", "Stages"]
