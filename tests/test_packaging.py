"""How trustseek is packaged: the version comes from the installed distribution's metadata, and
the core (fit, solve, simulate, the command line) works without the optional extras."""

from __future__ import annotations

import importlib.metadata
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import trustseek
from trustseek.cli import EXTRAS
from trustseek.version import __version__

ROOT = Path(__file__).resolve().parents[1]

#: the top-level modules of the ``server`` and ``plots`` extras (and what they bring along)
OPTIONAL_MODULES = ("fastapi", "starlette", "uvicorn", "sqlalchemy", "alembic", "httpx", "psycopg", "matplotlib", "jinja2")

# makes the optional modules look not installed: importing one raises ModuleNotFoundError
WITHOUT_EXTRAS = f"""
import sys
from importlib.abc import MetaPathFinder


class NotInstalled(MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in {OPTIONAL_MODULES!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None


sys.meta_path.insert(0, NotInstalled())
"""


def run_without_extras(code: str, *argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", WITHOUT_EXTRAS + code, *argv], capture_output=True, text=True, timeout=300, cwd=ROOT
    )


def test_version_is_the_distribution_version():
    assert __version__ == importlib.metadata.version("trustseek")
    assert trustseek.__version__ == __version__


def test_health_endpoint_reports_the_version(tmp_path):
    from fastapi.testclient import TestClient

    from trustseek.server import create_app

    with TestClient(create_app(f"sqlite:///{tmp_path / 'study.sqlite'}", token="experimenter-token")) as client:
        assert client.get("/api/health").json() == {"status": "ok", "version": __version__}


def test_core_packages_import_without_the_extras():
    code = """
import trustseek
import trustseek.model, trustseek.data, trustseek.pomdp, trustseek.policies, trustseek.solvers
import trustseek.estimation, trustseek.simulation, trustseek.interop
loaded = sorted(m for m in sys.modules if m.partition(".")[0] in OPTIONAL)
assert not loaded, loaded
print("ok")
"""
    res = run_without_extras(f"OPTIONAL = {OPTIONAL_MODULES!r}\n" + code)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "ok"


def test_cli_help_works_without_the_extras():
    res = run_without_extras("from trustseek.cli import main\nsys.argv[0] = 'trustseek'\nmain()", "--help")
    assert res.returncode == 0, res.stderr
    for command in ("simulate", "fit", "solve", "serve", "export", "plot-q"):
        assert command in res.stdout


@pytest.mark.parametrize(
    ("argv", "extra"),
    [
        (["serve", "--port", "0"], "server"),
        (["export", "study-1", "--out", "trials.csv"], "server"),
        (["plot-q", "--out", "q.png"], "plots"),
    ],
)
def test_commands_that_need_an_extra_say_so_in_one_line(argv, extra):
    res = run_without_extras("from trustseek.cli import main\nsys.argv[0] = 'trustseek'\nmain()", *argv)
    assert res.returncode == 2
    assert res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("error: ")
    assert f"pip install 'trustseek[{extra}]'" in lines[0]


def _requirement_names(requirements: list[str]) -> set[str]:
    return {re.split(r"[\[<>=!~; ]", r, maxsplit=1)[0].lower() for r in requirements}


def test_the_cli_knows_the_extras_of_pyproject():
    """The CLI's module -> extra table names packages that pyproject.toml puts in that extra, and
    no core dependency."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    extras = project["optional-dependencies"]
    core = _requirement_names(project["dependencies"])
    for module, extra in EXTRAS.items():
        assert module in _requirement_names(extras[extra]), (module, extra)
        assert module not in core
    assert set(EXTRAS.values()) | {"all", "test"} == set(extras)
    assert extras["all"] == ["trustseek[server,plots,design]"]


def _pins() -> dict[str, str]:
    """constraints.txt as {normalised name: version}."""
    from packaging.utils import canonicalize_name

    pins = {}
    for line in (ROOT / "constraints.txt").read_text(encoding="utf-8").splitlines():
        if line.strip() and not line.startswith("#"):
            name, sep, version = line.partition("==")
            assert sep and version.strip(), f"constraints.txt: {line!r} is not name==version"
            pins[canonicalize_name(name)] = version.strip()
    return pins


def test_the_lock_pins_every_requirement_within_pyproject_s_ranges():
    """constraints.txt (what scripts/setup.sh installs) pins each requirement of pyproject.toml,
    core, extras and test tools, to a version that requirement accepts."""
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    requirements = [Requirement(r) for r in project["dependencies"]]
    requirements += [Requirement(r) for extra in project["optional-dependencies"].values() for r in extra]
    pins = _pins()
    for r in requirements:
        name = canonicalize_name(r.name)
        if name == "trustseek":  # the "all" extra names the other extras
            continue
        assert name in pins, f"constraints.txt does not pin {r.name} (run scripts/lock.sh)"
        assert r.specifier.contains(pins[name], prereleases=True), f"constraints.txt: {r.name}=={pins[name]} outside {r}"


@pytest.mark.skipif(Path(sys.prefix).resolve() != (ROOT / ".venv").resolve(), reason="not the environment scripts/setup.sh made")
def test_the_environment_setup_made_is_the_lock():
    """Every package pinned in constraints.txt is installed at that version in .venv: the tests run
    on the packages the lock names (a lock changed since the last setup is installed by it)."""
    from packaging.utils import canonicalize_name

    installed = {canonicalize_name(d.metadata["Name"]): d.version for d in importlib.metadata.distributions()}
    wrong = {n: (v, installed.get(n)) for n, v in _pins().items() if installed.get(n) != v}
    assert not wrong, f"pinned, installed: {wrong}; run scripts/setup.sh"
