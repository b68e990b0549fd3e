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
