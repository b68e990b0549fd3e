"""The progress bars of the long commands, on stderr (rich's, imported only by the commands that
show one: ``trustseek --help`` starts without it)."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, ClassVar

from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from ._app import err_console


class _Progress(Progress):
    """Rich's progress display.

    The display belongs to this process.  A process forked while it is open (the workers of
    ``--jobs``) starts with it switched off, so that what the worker does draws nothing on the
    terminal; and the fork waits until the display's refresh thread is not
    drawing, whose lock the worker would otherwise inherit held, and wait on forever."""

    shown: ClassVar[list[_Progress]] = []  # the displays open in this process, innermost last

    def __enter__(self) -> _Progress:
        super().__enter__()
        _Progress.shown.append(self)
        return self

    def __exit__(self, *exc: Any) -> None:
        _Progress.shown.remove(self)
        super().__exit__(*exc)

    @staticmethod
    def _before_fork() -> None:
        for bar in _Progress.shown:
            bar.live._lock.acquire()

    @staticmethod
    def _after_fork_in_parent() -> None:
        for bar in reversed(_Progress.shown):
            bar.live._lock.release()

    @staticmethod
    def _after_fork_in_child() -> None:
        for bar in reversed(_Progress.shown):
            bar.disable = True  # the parent's display: this process draws none of it
            bar.live._lock.release()
        _Progress.shown.clear()


os.register_at_fork(
    before=_Progress._before_fork,
    after_in_parent=_Progress._after_fork_in_parent,
    after_in_child=_Progress._after_fork_in_child,
)


def progress_bar(quiet: bool, *columns: Any) -> Progress:
    """The progress bar of a long run, on stderr: off with ``--quiet`` and when stderr is not a
    terminal."""
    cols = columns or (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    return _Progress(*cols, console=err_console, transient=True, disable=quiet or not err_console.is_terminal)


def bar_task(bar: Progress, description: str, total: int | None = None) -> Callable[[float, float | None], None]:
    """A new task on ``bar`` and its progress callback ``update(done, total)``."""
    task = bar.add_task(description, total=total)
    return lambda done, of: bar.update(task, completed=done, total=of)


@contextmanager
def progress_task(quiet: bool, description: str, total: int | None = None) -> Iterator[Callable[..., None]]:
    """A :func:`progress_bar` with one task, open for the block: yields ``update(done, total,
    description=None)``, a progress callback."""
    with progress_bar(quiet) as bar:
        task = bar.add_task(description, total=total)
        yield lambda done, of, description=None: bar.update(task, completed=done, total=of, description=description)
