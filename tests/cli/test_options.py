"""cli/_options.log_options: a command's ``reading`` parameter becomes the log options, listed
where it stands among the command's own, and their values reach the command as one LogReading."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from cli_runner import run_cli
from trustseek.cli._options import FROM_OPTIONS, LogReading, QuietOpt, log_options
from trustseek.data.trials import example_path

LOG = str(example_path("paper_trials.csv"))
READING = ["--mapping", "--column", "--label", "--missing", "--delimiter", "--sheet", "--order"]


def _options(app) -> list[str]:
    return [p.opts[0] for p in typer.main.get_command(app).commands["run"].params]


def _group() -> typer.Typer:
    app = typer.Typer()
    app.callback()(lambda: None)
    return app


def test_the_log_options_follow_the_commands_own_and_reach_it_as_one_reading(tmp_path):
    app, seen = _group(), {}

    @app.command()
    @log_options(keep=True)
    def run(n: int = typer.Option(1, "--n"), reading: LogReading = FROM_OPTIONS, quiet: bool = QuietOpt) -> None:
        seen.update(n=n, reading=reading, quiet=quiet)

    assert _options(app) == ["--n", *READING, "--keep", "--no-experience-rule", "--quiet"]
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


def _count_reads(monkeypatch, name: str) -> list[str]:
    """Every read of a file called ``name`` from now on (through Path.read_bytes or read_text)."""
    reads: list[str] = []
    for method in ("read_bytes", "read_text"):
        original = getattr(Path, method)

        def counted(self, *args, _original=original, **kwargs):
            if self.name == name:
                reads.append(str(self))
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(Path, method, counted)
    return reads


@pytest.mark.parametrize("rule", [[], ["--no-experience-rule"]])
def test_a_mapping_file_is_read_once_per_command(tmp_path, monkeypatch, rule):
    """fit reads its --mapping once (the joined file, the inputs it declares and the log's reading
    all come from that one read), and --no-experience-rule switches the rule off without writing
    a second mapping file."""
    mapping = tmp_path / "mapping.json"
    mapping.write_text(json.dumps({"columns": {"participant": "participant"}}))
    reads = _count_reads(monkeypatch, "mapping.json")
    code, output = run_cli(["fit", LOG, "--mapping", str(mapping), "-r", "1", "--max-iter", "2", "-q", *rule])
    assert code == 0, output
    assert reads == [str(mapping)]
    assert ("--no-experience-rule: the paper's experience rule is not checked" in output) == bool(rule), output


def test_a_toml_mapping_is_refused_naming_the_option_and_the_file(tmp_path):
    mapping = tmp_path / "mapping.toml"
    mapping.write_text("columns = [")
    code, output = run_cli(["fit", LOG, "--mapping", str(mapping), "-r", "1"])
    assert code == 2 and f"{mapping}: --mapping: invalid TOML" in output and "Traceback" not in output, output


def test_a_toml_mapping_is_read_as_a_json_one(tmp_path):
    log = tmp_path / "log.csv"
    log.write_text(Path(LOG).read_text().replace("participant,", "person,", 1))
    mapping = tmp_path / "mapping.toml"
    mapping.write_text('[columns]\nparticipant = "person"\n')
    code, output = run_cli(["agnostic", "--data", str(log), "--mapping", str(mapping), "--json"])
    assert code == 0 and json.loads(output)["kind"] == "trust-agnostic", output


def _shared(flag: str) -> dict[str, object]:
    """Every command's option ``flag``, by command (design takes its bounds in DesignConfig)."""
    from trustseek.cli import app

    group = typer.main.get_command(app)
    found = {}
    for name in group.commands:
        for p in group.commands[name].params:
            if flag in p.opts and name != "design":
                found[name] = p
    return found


@pytest.mark.parametrize(
    ("flag", "low", "high"),
    [("--restarts", 1, 1000), ("--bootstrap", 0, 10_000), ("--participants", 1, 1_000_000), ("--seed", 0, None)],
)
def test_an_option_several_commands_take_has_one_range_in_all(flag, low, high):
    """--restarts, --bootstrap, --participants and --seed are declared once (cli/_options): a command
    that declares its own instead, with other bounds, fails here."""
    options = _shared(flag)
    assert len(options) >= 2
    for name, p in options.items():
        least = 2 if (name, flag) == ("schedule", "--participants") else low
        assert (p.type.min, p.type.max) == (least, high), (name, flag)


def test_every_tolerance_is_refused_unless_finite_and_positive():
    names = sorted(_shared("--tol"))
    assert len(names) >= 5
    for name in names:
        args = [name, LOG] if name in {"fit", "select", "fit-types", "select-types", "validate", "personalize"} else [name]
        code, output = run_cli([*args, "--tol", "0"])
        assert code == 2 and "--tol" in output and "must be a finite number > 0" in output, (name, output)


@pytest.mark.parametrize(
    "name, content",
    [
        ("mapping.json", '{"columns": {"participant": "person",}}'),
        ("mapping.json", '["columns"]'),
        ("mapping.json", b"\x00\x01"),
        ("mapping.toml", "columns = ["),
        ("mapping.toml", "columns = " + "[" * 100_000 + "]" * 100_000),
        ("folder.json", None),
    ],
)
def test_a_mapping_file_is_read_by_one_reader_for_the_option_and_the_api(tmp_path, name, content):
    """--mapping and ColumnMapping.load (read_trials, check) read a mapping file the same way: a
    problem with the file is the same text, the option naming itself in front."""
    from trustseek.data.cells import DataError
    from trustseek.data.mapping import ColumnMapping

    path = tmp_path / name
    if content is None:
        path.mkdir()
    elif isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    with pytest.raises(DataError) as caught:
        ColumnMapping.load(path)
    (problem,) = caught.value.problems
    code, output = run_cli(["fit", LOG, "--mapping", str(path), "-r", "1"])
    assert code == 2 and f"{path}: --mapping: {problem}" in " ".join(output.split()), (problem, output)
    assert "Traceback" not in output
