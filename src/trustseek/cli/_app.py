"""The Typer application shared by the CLI modules, and its console helpers."""

from __future__ import annotations

import functools
import inspect
import json
import math
import os
import secrets
import shutil
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.table import Table

from ..errors import TrustseekError
from ._lazy import COMMANDS, LazyGroup

app = typer.Typer(
    name="trustseek",
    cls=LazyGroup,
    help="Trust-aware assistance-seeking: fit trust models, solve POMDP policies, simulate, run experiments.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)
LazyGroup.typer_app = app


@app.callback()
def _group() -> None:
    # makes ``app`` a group of commands before any command module has registered its commands
    pass


def command(name: str) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Register the command ``name`` in its help panel of :data:`~._lazy.COMMANDS`; its help is
    the listing's summary, then the function's docstring (the rest of the help, if any).  A
    command that runs to its end (all but :data:`SERVERS`) first keeps freed memory
    (:func:`keep_freed_memory`)."""
    entry = COMMANDS[name]

    def register(function: Callable[..., None]) -> Callable[..., None]:
        function.__doc__ = entry.summary + (f"\n\n{inspect.cleandoc(function.__doc__)}" if function.__doc__ else "")
        if name in SERVERS:
            return app.command(name, rich_help_panel=entry.panel)(function)

        @functools.wraps(function)
        def run(*args: Any, **kwargs: Any) -> None:
            keep_freed_memory()
            function(*args, **kwargs)

        return app.command(name, rich_help_panel=entry.panel)(run)

    return register


#: the commands that run until stopped: what they free goes back to the system
SERVERS = frozenset({"serve"})
#: glibc's ``mallopt`` parameters (``malloc.h``)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: the largest block served from the C heap, and the freed memory the heap keeps
HEAP_BYTES = 1 << 30


def keep_freed_memory() -> bool:
    """Have the C library's allocator serve blocks up to :data:`HEAP_BYTES` (a log's arrays: 57 MB
    per column of 7.1 M trials) from its heap and keep what is freed there for the next ones.  Its
    default maps each block of 32 MB or more afresh and unmaps it when freed, so the kernel zeroes
    every page of every temporary array again: the fit of 100,000 x 71 trials spent twice the
    system time (1.0 against 0.57 s) and 7 % more wall time.  pyarrow's memory pool is then the
    same allocator (unless ``ARROW_DEFAULT_MEMORY_POOL`` names one).  The process ends with the
    command, so what it keeps is returned then; its peak is higher (blocks on the heap fragment: a
    simulation of 100,000 participants into a CSV, 10 % higher).  Whether it was set: glibc only
    (Linux), else nothing changes."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # a C library without mallopt
        return False
    if not (mallopt(M_MMAP_THRESHOLD, HEAP_BYTES) and mallopt(M_TRIM_THRESHOLD, HEAP_BYTES)):
        return False
    # pyarrow's blocks from that heap too (its own allocator, mimalloc, gives freed pages back to the
    # system: reading a CSV of 7.1 M rows took 22 % longer); a pool the user chose stays
    os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    return True


console = Console()
err_console = Console(stderr=True)


def print_written(*outputs: tuple[str, Any]) -> None:
    """``<what> written to <where>`` for each output given (``where`` not None)."""
    for what, where in outputs:
        if where is not None:
            console.print(f"{what} written to {where}")


def make_table(title: str, *columns: str, left: int = 1, no_wrap: bool = False, **options: Any) -> Table:
    """A table titled on the left (unless ``options`` say otherwise); its first ``left`` columns
    justified left, the others right."""
    out = Table(title=title, **{"title_justify": "left", **options})
    for i, column in enumerate(columns):
        out.add_column(column, justify="left" if i < left else "right", no_wrap=no_wrap)
    return out


def print_json(obj: Any) -> None:
    """Machine-readable output: one JSON object on stdout, nothing else (numpy values as numbers
    and lists, NaN and infinities as null: :func:`~trustseek.model.jsonfile.json_safe`)."""
    from ..model.jsonfile import json_safe

    sys.stdout.write(json.dumps(json_safe(obj), indent=2, allow_nan=False) + "\n")


# --------------------------------------------------------------------------- outputs


#: the installed package's folder: outputs never go there (they would replace a shipped file)
PACKAGE = Path(__file__).resolve().parent.parent

#: the file suffixes a figure option takes (the formats every figure is written in)
FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


def check_output(path: Path | None, option: str, suffixes: tuple[str, ...] | None = None, directory: bool = False) -> None:
    """Refuse, before any work, an output path that cannot be written: its folder must exist and
    be writable, and the path must not be a folder (for ``directory`` outputs: not a file, and
    an existing folder must be empty) nor inside the installed package (its shipped examples and
    page assets).  ``suffixes`` are the accepted file suffixes."""
    if path is None:
        return

    def fail(what: str) -> None:
        raise TrustseekError([f"{option} {path}: {what}"])

    if path.resolve().is_relative_to(PACKAGE):
        fail(f"is inside the trustseek package ({PACKAGE}), among the files it ships; choose a folder of your own")

    if suffixes is not None and path.suffix.lower() not in suffixes:
        fail(f"expected a file ending in {' or '.join(suffixes)}")
    parent = path.resolve().parent
    if directory:
        if path.exists() and not path.is_dir():
            fail("exists and is not a folder; expected a new or empty folder")
        if path.is_dir() and any(path.iterdir()):
            fail("is a folder that is not empty; expected a new or empty folder (files would be overwritten)")
    elif path.is_dir():
        fail("is a folder; expected a file name")
    if not parent.is_dir():
        fail(f"the folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        fail(f"the folder {parent} is not writable")
    if path.exists() and not directory and not os.access(path, os.W_OK):
        fail("exists and is not writable")


def check_outputs(*outputs: tuple[Any, ...], inputs: tuple[tuple[Any, str], ...] = ()) -> None:
    """Refuse, before any work, the outputs (path, option[, suffixes]) that :func:`check_output`
    refuses, two options naming the same file, and an output naming one of the ``inputs`` (path
    or preset name, what it is): writing it would overwrite what the command reads."""
    for path, option, *suffixes in outputs:
        check_output(path, option, *suffixes)
    seen: dict[Path, str] = {}
    for path, option, *_ in outputs:
        if path is None:
            continue
        key = path.resolve()
        if key in seen:
            raise TrustseekError([f"{seen[key]} and {option} name the same file {path}"])
        seen[key] = option
        for given, what in inputs:
            if given is not None and _same_path(path, Path(given)):
                raise TrustseekError(
                    [f"{option} {path}: is the {what}; writing it would overwrite the input: choose another file"]
                )


def _same_path(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet): compare where they point
        return a.resolve() == b.resolve()


@contextmanager
def atomic_output(path: Path, directory: bool = False) -> Iterator[Path]:
    """A temporary path next to ``path`` (same suffix) to write to; it replaces ``path`` only
    when the block finishes, so a failure leaves no half-written output (and no temporary)."""
    parent = path.resolve().parent
    tmp = parent / f".{path.stem}.{os.getpid()}.{secrets.token_hex(4)}.tmp{path.suffix}"
    if directory:
        tmp.mkdir()
    try:
        yield tmp
        if directory and path.is_dir():
            path.rmdir()  # checked empty before the work started
        os.replace(tmp, path)
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        raise


def write_atomic(path: Path | None, write: Callable[[Path], Any], directory: bool = False) -> None:
    """``write(tmp)`` through :func:`atomic_output`, when ``path`` is given."""
    if path is not None:
        with atomic_output(path, directory) as tmp:
            write(tmp)


# --------------------------------------------------------------------------- options


def check_tol(value: float) -> float:
    """A tolerance option (a typer callback): a finite number > 0."""
    if not (math.isfinite(value) and value > 0):
        raise typer.BadParameter(f"must be a finite number > 0, got {value}")
    return value


def check_positive(value: float | None, option: str) -> None:
    """A number option, when given, refused unless it is finite and > 0."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise TrustseekError([f"{option} must be a finite number > 0, got {value}"])
