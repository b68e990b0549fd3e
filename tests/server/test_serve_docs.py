"""docs/experiments.md's table of ``trustseek serve`` options: well formed, and naming every
option the command takes (it once lacked ``--workers`` and ``--log-level``, and a broken row
split the table)."""

from __future__ import annotations

import re
from pathlib import Path

import typer.main

from trustseek.cli import app

DOC = Path(__file__).resolve().parents[2] / "docs" / "experiments.md"


def options_table() -> list[list[str]]:
    text = DOC.read_text(encoding="utf-8")
    start = text.index("| option | default | meaning |")
    rows = []
    for line in text[start:].splitlines():
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]])
    return rows


def test_the_serve_options_table_names_every_option_in_well_formed_rows():
    rows = options_table()
    assert rows[1] == ["---", "---", "---"] and all(len(r) == 3 for r in rows), rows
    documented = {m for r in rows[2:] for m in re.findall(r"`(--[a-z-]+)", r[0])}
    serve = typer.main.get_command(app).commands["serve"]  # type: ignore[attr-defined]
    options = {o for p in serve.params if p.param_type_name == "option" for o in p.opts if o.startswith("--")}
    assert options - {"--help"} <= documented, sorted(options - documented)
    assert {"--workers", "--log-level"} <= documented
