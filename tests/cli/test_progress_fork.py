"""The command line's progress display and the workers forked while it is open (``--jobs``)."""

import io
import os
import threading
import time

from rich.console import Console
from rich.progress import TextColumn

from trustseek.cli._progress import _Progress


def display(**options) -> _Progress:
    """A display that draws, as on a terminal (the tests' stderr is not one)."""
    console = Console(file=io.StringIO(), force_terminal=True, width=80)
    return _Progress(TextColumn("{task.description}"), console=console, transient=True, **options)


def exit_code_of_child(body) -> int:
    """Fork; the child runs ``body()`` (its exit code) and ends at once; the child's exit code."""
    pid = os.fork()
    if pid == 0:
        code = 99
        try:
            code = body()
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status)


def test_a_forked_worker_draws_nothing_of_the_display():
    """A worker (``--jobs``) that touched the parent's progress bar drew it from its own copy: a
    second display on the person's terminal."""
    with display() as bar:
        bar.add_task("restarts", total=3)

        def worker() -> int:
            drawn = io.StringIO()
            bar.console.file = drawn
            bar.add_task("more", total=1)
            bar.refresh()
            return 0 if drawn.getvalue() == "" else 3

        assert exit_code_of_child(worker) == 0
        assert not bar.disable  # the parent's display goes on
    assert _Progress.shown == []


def test_a_fork_waits_until_the_display_is_not_drawing():
    """Forked while the refresh thread drew (on a slow or paused terminal), a worker inherited the
    display's lock held, by a thread it does not have: its first touch of the display waited forever."""
    with display(auto_refresh=False) as bar:
        drawing = threading.Event()

        def draw() -> None:  # the refresh thread, mid-draw
            with bar.live._lock:
                drawing.set()
                time.sleep(0.5)

        thread = threading.Thread(target=draw)
        thread.start()
        drawing.wait()
        code = exit_code_of_child(lambda: 0 if bar.live._lock.acquire(timeout=5) else 4)
        thread.join()
    assert code == 0
