"""cli/_options.log_options: a command's ``reading`` parameter becomes the log options, listed
after the command's own, and their values reach the command as one LogReading."""

from __future__ import annotations

from pathlib import Path

import typer
from typer.testing import CliRunner

from trustseek.cli._options import FROM_OPTIONS, LogReading, log_options

READING = ["--mapping", "--column", "--label", "--missing", "--delimiter", "--order"]


def _options(app) -> list[str]:
    return [p.opts[0] for p in typer.main.get_command(app).commands["run"].params]


def _group() -> typer.Typer:
    app = typer.Typer()
    app.callback()(lambda: None)
    return app


def test_the_log_options_follow_the_commands_own_and_reach_it_as_one_reading(tmp_path):
    app, seen = _group(), {}

    @app.command()
    @log_options(keep=True, quiet=True)
    def run(n: int = typer.Option(1, "--n"), reading: LogReading = FROM_OPTIONS, quiet: bool = False) -> None:
        seen.update(n=n, reading=reading, quiet=quiet)

    assert _options(app) == ["--n", *READING, "--keep", "--quiet", "--no-experience-rule"]
    args = ["run", "--n", "3", "--mapping", str(tmp_path / "m.json"), "--column", "a=b", "--column", "c=d"]
    result = CliRunner().invoke(app, [*args, "--order", "block,trial", "--keep", "x", "-q", "--no-experience-rule"])
    assert result.exit_code == 0, result.output
    assert seen["n"] == 3 and seen["quiet"] is True
    assert seen["reading"] == LogReading(
        mapping=Path(tmp_path / "m.json"), column=["a=b", "c=d"], order=["block,trial"], keep=["x"], no_rule=True
    )


def test_a_command_takes_only_the_log_options_it_names():
    plain, some = _group(), _group()

    @plain.command()
    @log_options()
    def run(reading: LogReading = FROM_OPTIONS) -> None:
        pass

    @some.command("run")
    @log_options(names=("mapping", "order"))
    def run_some(reading: LogReading = FROM_OPTIONS) -> None:
        pass

    assert _options(plain) == [*READING, "--no-experience-rule"]
    assert _options(some) == ["--mapping", "--order"]
