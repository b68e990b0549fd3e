"""The command line starts at once: ``import trustseek``, ``import trustseek.cli`` and ``trustseek
--help`` load none of the heavy packages, and the help listing (read from a table, no command
module imported) is what the command modules register."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys

import pytest
import typer

from cli_runner import run_cli
from trustseek.cli import _lazy, app

HEAVY = ("numba", "scipy", "pandas", "matplotlib", "fastapi", "sqlalchemy")


def heavy_modules_after(code: str, heavy: tuple[str, ...] = HEAVY) -> list[str]:
    loaded = f"import json, sys; print(json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)))"
    out = subprocess.run([sys.executable, "-c", f"{code}\n{loaded}"], capture_output=True, text=True, timeout=120, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize(
    "code",
    [
        "import trustseek.cli",
        "import trustseek",
        "import trustseek.errors, trustseek.vocab",
        # the help, as `trustseek --help` prints it
        "import contextlib, io, sys\nfrom trustseek.cli import main\nsys.argv = ['trustseek', '--help']\n"
        "with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n    main()",
    ],
    ids=["cli", "package", "errors", "help"],
)
def test_starting_loads_no_heavy_package(code):
    assert heavy_modules_after(code) == []


@pytest.mark.parametrize("command", ["fit", "check", "select-types"])
def test_a_command_s_help_loads_no_heavy_package_nor_pydantic(command):
    """typer 0.29 checks every option through pydantic, 0.1 s more on every command's start
    (``benchmarks/bench_startup.py``); pyproject.toml keeps typer below it."""
    code = (
        "import contextlib, io, sys\nfrom trustseek.cli import main\n"
        f"sys.argv = ['trustseek', {command!r}, '--help']\n"
        "with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n    main()"
    )
    assert heavy_modules_after(code, (*HEAVY, "pydantic")) == []


def test_the_check_can_fail():
    assert heavy_modules_after("import pandas") == ["pandas"]


def registered() -> dict[str, _lazy.Command]:
    """Every command as the command modules register it: module, panel, first paragraph of the help."""
    for module in dict.fromkeys(c.module for c in _lazy.COMMANDS.values()):
        __import__(f"trustseek.cli.{module}")
    out = {}
    for info in app.registered_commands:
        assert info.callback is not None
        help_text = inspect.cleandoc(info.help or inspect.getdoc(info.callback) or "")
        module = info.callback.__module__.rpartition(".")[2]
        out[_lazy.command_name(info)] = _lazy.Command(module, info.rich_help_panel or "", help_text.split("\n\n")[0].strip())
    return out


def test_the_listing_table_is_what_the_modules_register():
    """When a command is added, renamed, moved to another panel or its help's first paragraph
    changes, update COMMANDS in src/trustseek/cli/_lazy.py to match."""
    real = registered()  # in the order the modules were imported, which other tests may have done
    assert real == _lazy.COMMANDS


def test_help_lists_every_command_and_runs_a_command_from_its_module():
    code, out = run_cli(["--help"])
    assert code == 0
    for name, command in _lazy.COMMANDS.items():
        assert f" {name} " in out
        assert command.panel in out
    code, out = run_cli(["preset", "paper"])
    assert code == 0 and json.loads(out)["model"]["format"] == "trustseek.trust-model/1"


def test_the_group_has_every_command_for_tools_that_read_it():
    group = typer.main.get_command(app)
    assert isinstance(group, typer.core.TyperGroup)
    assert list(group.commands) == list(_lazy.COMMANDS)
    assert "fit" in group.commands and "nonsense" not in group.commands
    assert group.commands["fit"].params  # the real command, built from its module
    assert group.commands.get("nonsense") is None


def test_help_paragraphs_are_wrapped_by_the_terminal_not_by_the_source():
    """Typer printed a docstring's line breaks as they are: `trustseek --help` showed 'predict' as
    '... from the trials before it' and '(filtering), against ...' on a line of its own."""
    group = typer.main.get_command(app)
    assert isinstance(group, _lazy.LazyGroup)
    for name in _lazy.COMMANDS:
        for text in (_lazy.LazyGroup._summary(name).help, group.commands[name].help):
            assert text is not None
            broken = [p for p in text.split("\n\n") if "\n" in p and not p.startswith(("\b", "- "))]
            assert not broken, (name, broken)
    listed = "- one\n- two"
    assert _lazy.reflow(f"A line\nand its rest.\n\n{listed}") == f"A line and its rest.\n\n{listed}"


def test_every_submodule_is_an_attribute_of_its_package():
    """As when each package imported its modules eagerly: ``estimation.selection`` after
    ``from trustseek import estimation`` (the lazy loader reads the submodules from the stub)."""
    code = (
        "import importlib, pkgutil, sys\n"
        "import trustseek\n"
        "missing = []\n"
        "for pkg in ('data', 'design', 'estimation', 'interop', 'model', 'policies', 'pomdp', 'reproduction', 'simulation', 'solvers'):\n"
        "    mod = importlib.import_module(f'trustseek.{pkg}')\n"
        "    for info in pkgutil.iter_modules(mod.__path__):\n"
        "        if getattr(mod, info.name, None) is None:\n"
        "            missing.append(f'{pkg}.{info.name}')\n"
        "print(missing, [n for n in ('model', 'solvers', 'policies') if getattr(trustseek, n, None) is None])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[] []"


def run_main(*argv: str) -> str:
    """A program that runs ``trustseek argv`` as the command line does (output swallowed)."""
    return (
        "import contextlib, io, sys\nfrom trustseek.cli import main\n"
        f"sys.argv = ['trustseek', *{list(argv)!r}]\n"
        "with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n    main()"
    )


#: what no command's --help may load: numpy too (each of these takes 0.1-0.7 s to import)
HELP_HEAVY = ("numpy", *HEAVY)


def heavy_modules_by_help(commands: list[str], prelude: str = "") -> dict[str, list[str]]:
    """Each command's ``--help`` run in turn in one fresh interpreter (after ``prelude``): the
    heavy packages loaded by the time each command's help is printed, not loaded before it."""
    code = (
        f"import contextlib, io, json, sys\n{prelude}\nfrom trustseek.cli import main\nloaded, seen = {{}}, set()\n"
        f"for name in {commands!r}:\n"
        "    sys.argv = ['trustseek', name, '--help']\n"
        "    with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n        main()\n"
        f"    loaded[name] = sorted(m for m in {HELP_HEAVY!r} if m in sys.modules and m not in seen)\n"
        "    seen.update(loaded[name])\n"
        "print(json.dumps(loaded))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_every_commands_help_loads_no_numpy_nor_other_heavy_package():
    """A command module imports only typer, rich and light constants (trustseek.vocab,
    trustseek.solvers.defaults) at its top; everything else where the command runs."""
    loaded = heavy_modules_by_help(list(_lazy.COMMANDS))
    assert loaded == {name: [] for name in _lazy.COMMANDS}


def test_the_help_check_can_fail():
    assert heavy_modules_by_help(["preset", "fit"], prelude="import numpy") == {"preset": ["numpy"], "fit": []}


def test_checking_a_model_loads_no_heavy_package(tmp_path):
    model = tmp_path / "model.json"
    code, _ = run_cli(["preset", "paper", "--model-out", str(model)])
    assert code == 0 and model.is_file()
    assert heavy_modules_after(run_main("check", str(model)) + "\nassert sys.modules['trustseek.model.core']") == []


def test_solving_the_paper_preset_loads_no_pandas(tmp_path):
    """An output option is checked against the inputs it could overwrite; a command without a
    --mapping file reads no mapping, so pandas stays out of ``solve`` (0.45 s of its start)."""
    policy = tmp_path / "policy.json"
    code = run_main("solve", "--out", str(policy)) + f"\nassert __import__('pathlib').Path({str(policy)!r}).is_file()"
    assert "pandas" not in heavy_modules_after(code)


def test_naming_the_solvers_loads_no_scipy():
    code = "from trustseek.solvers import make_solver, solver_names\nsolver_names()\nmake_solver('trust-agnostic')"
    assert heavy_modules_after(code) == []


def test_one_blas_thread_also_limits_a_blas_loaded_after_its_first_use():
    """scipy brings its own OpenBLAS; a solver that runs before scipy is loaded (the paper's
    small problems need none) must not leave scipy's BLAS threaded for the solvers after it."""
    code = (
        "import threadpoolctl\nfrom trustseek.solvers.base import one_blas_thread\n"
        "threads = one_blas_thread()(lambda: sorted(i['num_threads'] for i in threadpoolctl.threadpool_info()))\n"
        "threads()\nimport scipy.linalg\n"
        "n = len(threadpoolctl.threadpool_info())\nprint(n, threads())"
    )
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "2", "OMP_NUM_THREADS": "2"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True, env=env)
    n, threads = out.stdout.strip().split(" ", 1)
    assert int(n) >= 2 and json.loads(threads) == [1] * int(n)


def test_every_option_name_is_whole_in_the_help_at_80_columns(monkeypatch):
    """Rich shrank every column of the options table to fit: at 80 columns `reproduce --help`
    showed `--schedule-participan…` and `select --help` `--no-experience-r…` and
    `column:theirs=cano…`, names and examples a person cannot type from the help."""
    from typer import rich_utils

    monkeypatch.setattr(rich_utils, "MAX_WIDTH", 80)
    group = typer.main.get_command(app)
    seen = 0
    for name in _lazy.COMMANDS:
        code, out = run_cli([name, "--help"])
        assert code == 0, out
        assert "…" not in out, (name, [line for line in out.splitlines() if "…" in line])
        names = [opt for p in group.commands[name].params for opt in (*p.opts, *p.secondary_opts) if opt.startswith("--")]
        assert all(opt in out for opt in names), (name, [opt for opt in names if opt not in out])
        seen += len(names)
    assert seen > 100


def test_on_a_narrow_terminal_the_help_text_keeps_a_readable_width(monkeypatch):
    """Keeping the names whole at 40 columns left the help's column one letter wide: `reproduce
    --help` ran to 1,036 lines, a letter each.  Below 60 columns the names may be cut again."""
    from typer import rich_utils

    monkeypatch.setattr(rich_utils, "MAX_WIDTH", 40)
    code, out = run_cli(["reproduce", "--help"])
    assert code == 0 and "Report" in out and "folder" in out
    assert len(out.splitlines()) < 300, len(out.splitlines())
