"""The command line's application (cli/_app.py): what every command does before it runs."""

import os
import subprocess
import sys

import pytest
from tests.cli_runner import run_cli

from trustseek.cli import _app

# a 256 MB block written, freed, and the resident memory in MB after it (with the setting first)
FREED = """
import sys
import numpy as np
from trustseek.cli._app import keep_freed_memory
set_ = keep_freed_memory() if sys.argv[1] == "keep" else None
def rss():
    return int(open("/proc/self/statm").read().split()[1]) * 4096 / 2**20
before = rss()
a = np.ones(2**25)
del a
kept = round(rss() - before)
import pyarrow as pa
print(set_, kept, pa.default_memory_pool().backend_name)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")
def test_freed_memory_is_kept_for_the_next_arrays():
    """With the setting, a freed 256 MB array stays with the process for the next one (its pages are
    not zeroed again); without it, the C library gives it back at once."""

    def after(mode, pool=None):
        env = {k: v for k, v in os.environ.items() if k != "ARROW_DEFAULT_MEMORY_POOL"}
        env |= {"ARROW_DEFAULT_MEMORY_POOL": pool} if pool else {}
        run = subprocess.run([sys.executable, "-c", FREED, mode], capture_output=True, text=True, check=True, env=env)
        kept, rss, arrow = run.stdout.split()
        return kept, int(rss), arrow

    # pyarrow's memory from the same allocator, unless the user named a pool
    assert after("keep") == ("True", pytest.approx(256, abs=16), "system")
    assert after("keep", pool="jemalloc")[2] == "jemalloc"
    assert after("default")[1:] == (pytest.approx(0, abs=16), "mimalloc")


def test_every_command_but_the_server_keeps_freed_memory(monkeypatch, tmp_path):
    calls = []
    monkeypatch.setattr(_app, "keep_freed_memory", lambda: calls.append(1))
    code, _ = run_cli(["preset", "paper", "--model-out", str(tmp_path / "m.json")])
    assert code == 0 and calls == [1]
    assert run_cli(["preset", "--help"])[0] == 0 and calls == [1]  # --help runs nothing
    import trustseek.cli.serve  # noqa: F401  (registers its commands)

    commands = {c.name: c.callback for c in _app.app.registered_commands}
    assert not hasattr(commands["serve"], "__wrapped__")
    assert all(hasattr(f, "__wrapped__") for name, f in commands.items() if name not in _app.SERVERS)
