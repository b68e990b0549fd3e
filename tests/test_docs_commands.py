"""Every ``trustseek ...`` command line in the README and docs/ names a command and options that
the command line has (code blocks and inline code), so the docs cannot drift from the CLI."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
import typer

from trustseek.cli import app

ROOT = Path(__file__).resolve().parents[1]
FILES = sorted((ROOT / "docs").rglob("*.md")) + [ROOT / "README.md"]
GENERIC = {"trustseek --help", "trustseek <command> -h"}  # how to get help, not a command


def command_lines(text: str) -> list[str]:
    blocks = re.findall(r"```[a-z]*\n(.*?)```", text, re.S)
    inline = re.findall(r"`(trustseek [^`]+)`", re.sub(r"```.*?```", "", text, flags=re.S))
    out = []
    for block in blocks + inline:
        for line in block.replace("\\\n", " ").splitlines():
            line = re.sub(r"^\$ ", "", line.split(" #")[0].strip())
            if line.startswith("trustseek ") and line not in GENERIC:
                out.append(line)
    return out


def problems_of(line: str, group) -> list[str]:
    tokens = shlex.split(line)
    command = group.commands.get(tokens[1])
    if command is None:
        return [f"no command {tokens[1]!r}"]
    options = {o for p in command.params for o in (*p.opts, *p.secondary_opts)} | {"-h", "--help"}
    return [
        f"{tokens[1]} has no option {t.split('=')[0]!r}"
        for t in tokens[2:]
        if t.startswith("-") and not re.match(r"^-\d", t) and t.split("=")[0] not in options
    ]


def test_the_docs_have_command_lines():
    assert sum(len(command_lines(f.read_text(encoding="utf-8"))) for f in FILES) > 100


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_documented_command_line_exists(path):
    group = typer.main.get_command(app)
    found = {line: problems_of(line, group) for line in command_lines(path.read_text(encoding="utf-8"))}
    assert not {line: p for line, p in found.items() if p}


def test_a_drifted_command_line_is_caught():
    group = typer.main.get_command(app)
    assert problems_of("trustseek simulate --no-such-flag 3", group) == ["simulate has no option '--no-such-flag'"]
    assert problems_of("trustseek nonsense", group) == ["no command 'nonsense'"]
    assert problems_of("trustseek solve --types mix.json --max-seconds 5", group) == []


def help_problems(group) -> list[str]:
    """Commands and options that the CLI's own help texts name ('trustseek X', 'X --option' or
    'solve --types') but that do not exist."""
    out = []
    for name, command in group.commands.items():
        for text in [command.help or ""] + [getattr(p, "help", None) or "" for p in command.params]:
            for m in re.finditer(r"trustseek ([a-z][a-z-]*)", text):
                if m.group(1) not in group.commands:
                    out.append(f"{name}: {m.group(0)!r} is no command")
            for m in re.finditer(r"\b([a-z][a-z-]+) (--[a-z][a-z-]*)", text):
                other, option = m.groups()
                if other in group.commands and option not in {o for p in group.commands[other].params for o in p.opts}:
                    out.append(f"{name}: {m.group(0)!r} is no option of {other}")
    return out


def test_the_help_texts_name_real_commands_and_options():
    group = typer.main.get_command(app)
    assert help_problems(group) == []
    # the defect this caught: compare-types' help sent people to 'fit --types' (it is fit-types)
    fake = typer.Typer()

    @fake.command("fit")
    def fit(out: str = typer.Option("", "--out")) -> None: ...

    @fake.command("compare", help="Types (e.g. from fit --types).")
    def compare() -> None: ...

    assert help_problems(typer.main.get_command(fake)) == ["compare: 'fit --types' is no option of fit"]
