"""The compiled code's cache: keyed on every module compiled code is made of."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import trustseek
from trustseek import compiled

PACKAGE = Path(trustseek.__file__).resolve().parent


def _compiled_functions(tree: ast.Module) -> list[ast.FunctionDef]:
    return [
        node
        for node in tree.body
        if isinstance(node, ast.FunctionDef) and any("njit" in ast.unparse(d) for d in node.decorator_list)
    ]


def _imported(tree: ast.Module, here: Path) -> dict[str, Path]:
    """Each name a module imports from the package: the file it comes from."""
    out = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.level > 0:
            base = here.parent
            for _ in range(node.level - 1):
                base = base.parent
            for alias in node.names:
                target = base / (node.module or "").replace(".", "/")
                as_module = target / f"{alias.name}.py"
                out[alias.asname or alias.name] = as_module if as_module.exists() else target.with_suffix(".py")
    return out


def test_the_compiled_sources_are_every_module_compiled_code_is_made_of():
    """A module with compiled functions, and a module whose values (constants, compiled functions)
    a compiled function reads, are in COMPILED_SOURCES: a change to one of them recompiles all."""
    needed = set()
    for path in PACKAGE.rglob("*.py"):
        tree = ast.parse(path.read_text())
        functions = _compiled_functions(tree)
        if not functions:
            continue
        needed.add(path.relative_to(PACKAGE).as_posix())
        imported = _imported(tree, path)
        for fn in functions:
            for node in ast.walk(fn):
                if isinstance(node, ast.Name) and node.id in imported:
                    needed.add(imported[node.id].resolve().relative_to(PACKAGE).as_posix())
    needed.discard("compiled.py")  # the decorator itself
    assert needed <= set(compiled.COMPILED_SOURCES), sorted(needed - set(compiled.COMPILED_SOURCES))
    assert set(compiled.COMPILED_SOURCES) <= {p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py")}
    assert "estimation/kernels.py" in needed and "estimation/structure.py" in needed  # the scan finds them


def test_the_stamp_changes_with_any_compiled_source(tmp_path, monkeypatch):
    for name in compiled.COMPILED_SOURCES:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(PACKAGE / name, tmp_path / name)
    monkeypatch.setattr(compiled, "_PACKAGE", tmp_path)
    before = compiled.sources_stamp()
    assert before == compiled.sources_stamp()
    for name in compiled.COMPILED_SOURCES:
        with (tmp_path / name).open("a") as fh:
            fh.write("\n")
        after = compiled.sources_stamp()
        assert after != before, name
        before = after


def test_a_cached_package_function_is_stamped_with_every_compiled_source(tmp_path):
    """In a fresh process with its own cache: the package's compiled functions are cached under the
    stamp of all compiled sources (not their own file's), anything else as numba does."""
    code = """
import numba
from numba.core import caching
from trustseek import compiled
from trustseek.estimation import forward_backward
compiled.load()
def mine(x):
    return x + 1
ours = caching.FunctionCache(forward_backward.step_codes.py_func)
theirs = caching.FunctionCache(mine)
print(ours._impl.locator.get_source_stamp() == compiled.sources_stamp(),
      theirs._impl.locator.get_source_stamp() == compiled.sources_stamp(),
      type(theirs._impl.locator).__name__)
"""
    script = tmp_path / "probe.py"
    script.write_text(code)
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, check=True).stdout.split()
    assert out == ["True", "False", "UserProvidedCacheLocator"]


def test_numba_loads_on_a_second_thread_joined_on_leaving(tmp_path):
    """load_meanwhile (a large log's read): in a fresh process, nothing without ``when``; else numba
    and the first kernel load on a thread of their own, joined on leaving; a failure there is left
    for the caller's own first compiled call (no exception, no thread left behind)."""
    code = """
import threading
from trustseek import compiled
from trustseek.estimation import forward_backward
from trustseek.estimation.warm import first_kernel
with compiled.load_meanwhile(first_kernel, when=False):
    pass
print(compiled.loaded())
def broken():
    raise RuntimeError("left for the caller")
with compiled.load_meanwhile(broken):
    during = sorted(t.name for t in threading.enumerate())
print(during == ["MainThread", "trustseek-load"], compiled.loaded(), threading.active_count())
with compiled.load_meanwhile(first_kernel):
    pass
first_kernel()
print(type(forward_backward.step_codes).__name__)
"""
    script = tmp_path / "probe.py"
    script.write_text(code)
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, check=True, timeout=300).stdout.split()
    assert out == ["False", "True", "True", "1", "CPUDispatcher"], out


def test_cached_code_calling_a_prange_loop_runs_first_in_a_fresh_process(tmp_path):
    """A cached function that calls a prange loop of another cached function links against numba's
    threading layer, which numba launches only when it loads a function with such a loop itself:
    run first in a fresh process it crashed (the compiled fit: 'LLVM ERROR: Symbol not found:
    allocate_sched', exit 134).  Once compiled code is loaded, the layer runs, whatever the cache."""
    (tmp_path / "kernels_probe.py").write_text(
        "import numba\n\n\n"
        "@numba.njit(cache=True, parallel=True)\n"
        "def loop(x):\n    s = 0.0\n    for i in numba.prange(x.size):\n        s += x[i]\n    return s\n\n\n"
        "@numba.njit(cache=True)\n"
        "def caller(x):\n    return loop(x) + 1.0\n"
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": f"{tmp_path}{os.pathsep}{PACKAGE.parent}"}
    steps = [
        "import kernels_probe as k; print(k.loop(np.ones(3)))",  # the loop alone, cached
        "import kernels_probe as k; print(k.caller(np.ones(3)))",  # the caller compiled on the cached loop
        "from trustseek import compiled; compiled.load(); import kernels_probe as k; print(k.caller(np.ones(3)))",
    ]
    outs = [
        subprocess.run([sys.executable, "-c", "import numpy as np; " + s], capture_output=True, text=True, env=env, timeout=300)
        for s in steps
    ]
    assert [(o.returncode, o.stdout.strip()) for o in outs] == [(0, "3.0"), (0, "4.0"), (0, "4.0")], [
        o.stderr[-300:] for o in outs
    ]


def test_a_compile_is_told_while_it_runs_and_a_cache_load_is_not():
    """A first use after installation compiled for up to a minute behind a progress bar that stood
    still; the command line now shows a line while numba compiles (``compiling_note``)."""
    import numba

    from trustseek.cli._app import COMPILING, progress_bar

    compiled.load()
    seen: list[bool] = []
    with compiled.compiling_note(seen.append):
        add = numba.njit(lambda x: x + 1)
        add(1)  # compiled now: told, start and end
        add(2)  # the same signature: nothing to compile
    assert seen == [True, False]
    lines: list[list[str]] = []
    with progress_bar(True) as bar:  # (off: not a terminal; its tasks are kept all the same)
        bar.add_task("restarts", total=3)
        with compiled.compiling_note(lambda on: lines.append([t.description for t in bar.tasks])):
            numba.njit(lambda x: x * 2)(1.5)
        lines.append([t.description for t in bar.tasks])
    assert lines == [["restarts", COMPILING], ["restarts"], ["restarts"]]


def test_processes_that_need_the_same_compiled_function_at_once_compile_it_once(tmp_path):
    """Several processes at a large compiled function's first call (the workers of --jobs, a
    reproduction's step beside its fit) each compiled it, a minute of CPU each in a fresh
    environment; within ``compiled_once`` one compiles and the others load it from the cache."""
    (tmp_path / "slowmod.py").write_text(
        "import numba\nimport numpy as np\n\n"
        "@numba.njit(cache=True)\n"
        "def f(x):\n"
        "    a = np.array([[2.0, 1.0], [1.0, 3.0]]) * x\n"
        "    return np.linalg.solve(a, np.ones(2)).sum() + np.linalg.det(a)\n"
    )
    script = tmp_path / "first_call.py"
    script.write_text(
        "import sys\n"
        f"sys.path.insert(0, {str(tmp_path)!r})\n"
        "from trustseek import compiled\n"
        "compiled.load()\n"
        "import slowmod\n"
        "told = []\n"
        "sys.stdout.write('ready\\n'); sys.stdout.flush(); sys.stdin.readline()\n"
        "with compiled.compiling_note(told.append), compiled.compiled_once('test-slowmod'):\n"
        "    slowmod.f(1.0)\n"
        "print('compiled' if told else 'loaded')\n"
    )
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PATH": "/usr/bin:/bin"}
    procs = [
        subprocess.Popen([sys.executable, str(script)], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        for _ in range(2)
    ]
    for p in procs:  # both imported: they reach the first call together
        assert p.stdout is not None and p.stdout.readline() == "ready\n"
    for p in procs:
        assert p.stdin is not None
        p.stdin.write("go\n")
        p.stdin.flush()
    outs = sorted(p.communicate(timeout=120)[0].strip() for p in procs)
    assert outs == ["compiled", "loaded"]


def test_a_holder_that_does_not_end_is_waited_for_only_so_long(tmp_path, monkeypatch):
    """A process stopped while it compiled (Ctrl-Z) keeps the lock: the others go on alone after
    ``COMPILE_WAIT`` seconds, as they did before there was a lock, instead of waiting for ever."""
    import time

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(compiled, "COMPILE_WAIT", 0.3)
    with compiled.compiled_once("held"):  # the stopped holder (another open file: it conflicts)
        start = time.monotonic()
        with compiled.compiled_once("held"):
            waited = time.monotonic() - start
    assert 0.3 <= waited < 5
    start = time.monotonic()
    with compiled.compiled_once("held"):  # released: taken at once
        assert time.monotonic() - start < 0.3
