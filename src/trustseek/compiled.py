"""numba's ``njit``, applied on a function's first call; or the plain Python function where
numba cannot be imported (a declared dependency; the fallback keeps the compiled modules and their
numpy or Python paths usable on a platform without a numba wheel; ``AVAILABLE`` says which).

Decorating imports nothing: numba (half a second to import) and the compiled code (from numba's
cache, or compiled on a first use after installation) are paid for by the first call of a compiled
function, so a program that takes only numpy paths never imports numba.  That call hands every
function decorated so far to numba and points the module attributes that named the stand-ins at
numba's functions (numba reads them when it compiles a caller).

:data:`prange` is ``range`` until numba is loaded, numba's ``prange`` from then on.  A function with
a ``prange`` loop is compiled with ``parallel=True`` and runs on numba's ``workqueue`` threading layer
unless ``NUMBA_THREADING_LAYER`` names another (not GNU OpenMP, which hangs a process forked after
using it); the layer must not be entered by two threads at once: such calls hold :data:`PARALLEL_LOCK`.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

_PACKAGE = Path(__file__).resolve().parent
AVAILABLE = importlib.util.find_spec("numba") is not None  # numba is a declared dependency

F = TypeVar("F", bound=Callable[..., Any])

_PENDING: list[_Lazy] = []  # decorated, not yet handed to numba
_LOCK = threading.RLock()
_LOADED = False
PARALLEL_LOCK = threading.Lock()  # held around every call that runs a prange loop on several threads
COMPILE_WAIT = 180.0  # seconds a process waits at most for another to compile (compiled_once)
_NOTES: list[Callable[[bool], None]] = []  # told when numba starts and ends compiling (compiling_note)


class _PRange:
    """``range`` until numba is loaded (then the module attribute is numba's ``prange``)."""

    def __call__(self, *args: int) -> range:
        return range(*args)


prange: Any = _PRange()


class _Lazy:
    """A function that numba compiles on the first call of any such function."""

    def __init__(self, func: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = func
        self.options = options
        self.dispatcher: Any = None
        self.__name__, self.__qualname__, self.__doc__ = func.__name__, func.__qualname__, func.__doc__
        self.__module__ = func.__module__
        self.__wrapped__ = func

    def __call__(self, *args: Any) -> Any:
        if self.dispatcher is None:
            _load()
        return self.dispatcher(*args)

    def __repr__(self) -> str:
        return f"<compiled on first call: {self.__module__}.{self.__qualname__}>"


def load() -> None:
    """Import numba now (a no-op without it): a caller about to do enough compiled work that
    every path should take the compiled code (see :func:`loaded`)."""
    if AVAILABLE:
        _load()


def _load() -> None:
    """Hand every pending function to numba, and point the module attributes that name a
    stand-in at numba's function."""
    global _LOADED, prange
    with _LOCK:
        import numba

        if "NUMBA_THREADING_LAYER" not in os.environ:
            numba.config.THREADING_LAYER = "workqueue"  # type: ignore[attr-defined]
        if not _LOADED:
            # the threading layer launched now: compiled code loaded from the cache that calls a
            # prange loop (the compiled run's E-step) links against the layer's symbols, and numba
            # launches it only for a cached function that has the loop itself, so such a caller run
            # first crashed the process ("LLVM ERROR: Symbol not found: allocate_sched", or a segfault)
            numba.get_num_threads()
            _stamp_our_caches()
            _listen_for_compiles()
        marker, prange = prange, numba.prange
        done = {id(lazy): lazy for lazy in _PENDING}
        for lazy in _PENDING:
            lazy.dispatcher = numba.njit(**lazy.options)(lazy.py_func)
        _PENDING.clear()
        for name, module in list(sys.modules.items()):
            if module is None or not name.startswith("trustseek"):
                continue
            for attr, value in list(vars(module).items()):
                if isinstance(value, _Lazy) and id(value) in done:
                    setattr(module, attr, value.dispatcher)
                elif value is marker:
                    setattr(module, attr, numba.prange)
        _LOADED = True


@contextmanager
def compiling_note(note: Callable[[bool], None]) -> Iterator[None]:
    """Within: ``note(True)`` when numba starts compiling (code its cache lacks: a first use after
    installation or an upgrade, up to a minute) and ``note(False)`` when it is done; loading
    compiled code from the cache says nothing.  Called on the thread that compiles."""
    with _LOCK:
        _NOTES.append(note)
    try:
        yield
    finally:
        with _LOCK:
            _NOTES.remove(note)


def _listen_for_compiles() -> None:
    """Register with numba a listener that tells :data:`_NOTES` when the outermost compile starts
    and ends (a compiled function compiles the ones it calls within its own compile)."""
    from numba.core import event

    depth = [0]
    lock = threading.Lock()

    def tell(on: bool) -> None:
        for note in list(_NOTES):
            note(on)

    class Compiling(event.Listener):
        def on_start(self, ev: Any) -> None:
            with lock:
                depth[0] += 1
                first = depth[0] == 1
            if first:
                tell(True)

        def on_end(self, ev: Any) -> None:
            with lock:
                depth[0] -= 1
                last = depth[0] == 0
            if last:
                tell(False)

    event.register("numba:compile", Compiling())


#: the package's modules compiled code is made of: those with compiled functions and those whose
#: values compiled functions read (tests/test_compiled.py checks the list against the code)
COMPILED_SOURCES = (
    "estimation/compiled_run.py",
    "estimation/compiled_steps.py",
    "estimation/em.py",
    "estimation/forward_backward.py",
    "estimation/kernels.py",
    "estimation/sticks.py",
    "estimation/structure.py",
    "solvers/type_aware.py",
)


def sources_stamp() -> bytes:
    """One digest of :data:`COMPILED_SOURCES`' contents."""
    digest = hashlib.sha256()
    for name in COMPILED_SOURCES:
        digest.update((_PACKAGE / name).read_bytes())
    return digest.digest()


def _stamp_our_caches() -> None:
    """Key every cached compiled function of the package on :func:`sources_stamp`, so that a change
    to any module of :data:`COMPILED_SOURCES` (an update, an edit) compiles them all anew: numba keys
    one on its own file alone, and its cache would keep the old code of what it calls (other numbers,
    or a crash).  numba's own locators still find the cache (``NUMBA_CACHE_DIR``, beside the source,
    or the user's cache)."""

    from numba.core import caching

    stamp = sources_stamp()

    def stamped(locator: Any) -> Any:
        class Stamped(locator):
            @classmethod
            def from_function(cls, py_func: Any, py_file: str) -> Any:
                if not os.path.realpath(py_file).startswith(str(_PACKAGE) + os.sep):
                    return None
                return super().from_function(py_func, py_file)

            def get_source_stamp(self) -> bytes:
                return stamp

        return Stamped

    # the names of numba 0.68 (earlier releases prefix them with an underscore)
    names = ("CacheImpl", "UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator")
    impl, *locators = (getattr(caching, n, None) or getattr(caching, "_" + n, None) for n in names)
    if impl is None or None in locators:  # pragma: no cover - a numba without them keeps its own keys
        return
    impl._locator_classes = [*(stamped(c) for c in locators), *impl._locator_classes]


@contextmanager
def compiled_once(name: str) -> Iterator[None]:
    """Within: no other process on this machine is inside ``compiled_once(name)`` with the same
    numba cache and sources; around the first call of a large compiled function, so that of
    several processes that need it at once (the workers of ``--jobs``, a reproduction's step
    beside its fit) one compiles it and the others wait, then load it from the cache, instead
    of each compiling it again (a minute of CPU, and half a gigabyte, each in a fresh
    environment).  A lock file in numba's cache folder (or the temporary one), released by the
    system when its holder ends however it ends; where none can be made, or after
    :data:`COMPILE_WAIT` seconds (a holder stopped, not ended), this process goes on alone."""
    if not AVAILABLE or sys.platform == "win32":  # pragma: no cover - no flock there
        yield
        return
    import fcntl
    import tempfile

    cache = os.environ.get("NUMBA_CACHE_DIR", "")
    key = hashlib.sha256(sources_stamp() + cache.encode() + name.encode()).hexdigest()[:16]
    folder = Path(cache or tempfile.gettempdir())
    try:
        folder.mkdir(parents=True, exist_ok=True)
        lock = open(folder / f"trustseek-compile-{key}.lock", "a")  # noqa: SIM115 (closed by the with below)
    except OSError:
        yield
        return
    with lock:
        held = _flock_within(lock, COMPILE_WAIT)
        try:
            yield
        finally:
            if held:
                fcntl.flock(lock, fcntl.LOCK_UN)


def _flock_within(lock: Any, seconds: float) -> bool:
    """Take ``lock``'s exclusive flock, waiting at most ``seconds`` (a holder that is stopped, not
    ended, would keep it); whether it was taken."""
    import fcntl
    import time

    end = time.monotonic() + seconds
    while True:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() >= end:
                return False
            time.sleep(0.05)


@contextmanager
def load_meanwhile(first: Callable[[], object], when: bool = True) -> Iterator[None]:
    """Within: numba is imported and ``first`` (a call of a small compiled function, which sets up
    numba's code generator and its cache: about half a second) runs on a second thread, while
    the caller does work of its own that leaves a core free (reading a large log); joined on
    leaving, before anything can fork.  The modules with compiled functions that the work
    imports meanwhile must not be needed by compiled code (the data layer has none).  A failure
    there is left for the caller's own first compiled call to meet and report."""
    if not (when and AVAILABLE) or _LOADED:
        yield
        return

    def run() -> None:
        try:
            _load()
            first()
        except Exception:  # the same call on the caller's thread meets it and reports it
            pass

    thread = threading.Thread(target=run, name="trustseek-load")
    thread.start()
    try:
        yield
    finally:
        thread.join()


def loaded() -> bool:
    """Whether this process has imported numba for its compiled code (a compiled function was
    called, or :func:`load`): from then on the compiled paths cost no more start-up."""
    return _LOADED


def njit(**options: Any) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """numba's ``njit(**options)``, applied on the first call (after that the module attribute
    is numba's function itself); without numba, the plain Python function."""

    def decorate(func: Callable[..., Any]) -> Callable[..., Any]:
        if not AVAILABLE:  # pragma: no cover - exercised only without numba
            return func
        with _LOCK:  # (numba may be loading on another thread: see load_meanwhile)
            if _LOADED:
                import numba

                return numba.njit(**options)(func)
            lazy = _Lazy(func, options)
            _PENDING.append(lazy)
        return lazy

    return decorate


def set_threads(n: int) -> int:
    """Let the calling thread's ``prange`` loops use ``n`` of numba's threads (at most as many as
    numba started); how many they will use.  1 without numba loaded."""
    if not _LOADED:
        return 1
    import numba

    n = max(1, min(int(n), numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]
    numba.set_num_threads(n)
    return n


def python(func: F) -> F:
    """The plain Python function of a compiled one (for small inputs, where numba would cost more
    to load than it saves)."""
    return getattr(func, "py_func", func)
