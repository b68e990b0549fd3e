"""The command group that imports a command's module only when that command runs.

``trustseek --help`` lists every command from :data:`COMMANDS` (its module, help panel and the
first paragraph of its help) without importing any command module; ``trustseek fit ...`` imports
:mod:`.fit` alone, and with it only what ``fit`` needs.  ``tests/cli/test_startup.py`` checks that the
table is what the modules register (names, panels, help texts), so it cannot drift from them.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import re
from collections.abc import Iterator, MutableMapping
from typing import Any, ClassVar, NamedTuple

import typer
import typer.core
import typer.main
from typer import _click as click  # the Click that Typer runs on (Typer carries its own copy)


class Command(NamedTuple):
    module: str  # the module of trustseek.cli that registers it
    panel: str  # its help panel
    summary: str  # the first paragraph of its help, as the listing shows it


SIM, EST, PLAN, FILES, EXP = "Simulate and reproduce", "Estimate", "Plan", "Files", "Experiments"

#: every command, in the order of the help listing (the order the modules register them)
COMMANDS: dict[str, Command] = {
    "simulate": Command("simulate", SIM, "Simulate supervisors from a trust model working with the robot under a policy."),
    "reproduce": Command("simulate", SIM, "Reproduce Sections V-VI of the paper on simulated supervisors and write a report."),
    "fit": Command("fit", EST, "Estimate the supervisor's trust model from logged trials (extended Baum-Welch)."),
    "decode": Command("fit", EST, "Per-trial smoothed P(trust | data) and the Viterbi trust path under a model."),
    "select": Command("fit", EST, "Choose the number of trust levels: BIC and participant-held-out log-likelihood."),
    "solve": Command(
        "plan",
        PLAN,
        "Solve the assistance-seeking POMDP for the optimal trust-aware policy (Section IV), or for a person of\n"
        "unknown supervisor type (--types).",
    ),
    "agnostic": Command("plan", PLAN, "The optimal trust-agnostic policy (Section VI-A)."),
    "plot-q": Command("plan", PLAN, "Plot Q(b, C, a) for both actions and complexities, with the threshold (Fig. 7)."),
    "preset": Command(
        "plan", FILES, "Print or export a built-in preset (model and task JSON), a starting point for your own files."
    ),
    "check": Command(
        "plan", FILES, "Validate model (trust or general), task, policy and mapping files and trial logs; print every problem."
    ),
    "export-pomdp": Command(
        "interop", FILES, "Export the assistance POMDP to a standard file (state augmented with the last human action)."
    ),
    "solve-pomdp-file": Command(
        "interop", FILES, "Solve a standard .pomdp file: certified lower and upper bounds at its start belief."
    ),
    "serve": Command("serve", EXP, "Run the experiment server: participant interface, dashboard, experimenter and deploy APIs."),
    "export": Command("serve", EXP, "Export a study's trials (canonical trial log), its UI events, or its whole data bundle."),
    "study": Command(
        "serve", EXP, "A study's lifecycle: its status, study link and progress; --status opens, pauses or closes it."
    ),
    "sensitivity": Command(
        "sensitivity",
        PLAN,
        "Range of the policy's threshold and of V when every reported parameter moves within its printed precision.",
    ),
    "schedule": Command(
        "schedule", PLAN, "Choose the next item's complexity jointly with asking (finite horizon, known item counts)."
    ),
    "design": Command(
        "design", SIM, "Power and regret by study design: replicated simulate → fit → solve → evaluate → test pipelines."
    ),
    "fit-types": Command(
        "types", EST, "Fit supervisor types: M trust models of the paper's structure, each participant one type."
    ),
    "select-types": Command("types", EST, "Choose the number of supervisor types: BIC and participant-held-out log-likelihood."),
    "personalize": Command(
        "types", EST, "Per-person trust models: each participant's MAP estimate, shrunk toward the pooled model or their type."
    ),
    "compare-types": Command(
        "compare",
        SIM,
        "Does planning for supervisor types pay? Pooled, type-aware, oracle and trust-agnostic policies on the same people.",
    ),
    "predict": Command(
        "validate",
        EST,
        "How well a trust model predicts each trial's human action from the trials before it\n"
        "(filtering), against baselines: log-loss, Brier score, AUC with bootstrap intervals.",
    ),
    "validate": Command(
        "validate",
        EST,
        "Does the decoded trust track self-reported trust?  Spearman and Pearson correlations with\n"
        "the ratings (pooled, within and between participants) next to simple baselines.",
    ),
}


def reflow(text: str) -> str:
    """A help text with each paragraph on one line, for the terminal to wrap: Typer prints a
    docstring's line breaks as they are, so a paragraph broke at the source's line ends and again
    at the terminal's width.  A paragraph that is a list or holds an indented block keeps its
    lines, as does one marked with ``\\b`` (Click's mark for text not to be rewrapped)."""
    paragraphs = inspect.cleandoc(text).split("\n\n")
    kept = re.compile(r"\s|[-*•]\s|\d+[.)]\s")
    return "\n\n".join(
        p if p.startswith("\b") or any(kept.match(line) for line in p.split("\n")[1:]) else " ".join(p.split())
        for p in paragraphs
    )


def command_name(info: typer.models.CommandInfo) -> str:
    """The name Typer gives a registered command."""
    assert info.callback is not None
    return info.name or typer.main.get_command_name(info.callback.__name__)


def _reflowed(command: click.Command) -> click.Command:
    """The command with its help reflowed (:func:`reflow`) and its options' names kept whole
    (:class:`WholeNamesCommand`)."""
    if command.help:
        command.help = reflow(command.help)
    if type(command) is typer.core.TyperCommand:
        command.__class__ = WholeNamesCommand  # (a subclass that only renders its help otherwise)
    return command


class WholeNamesCommand(typer.core.TyperCommand):
    """A command whose help shows every option's names whole: Rich shrinks each column of Typer's
    options table to fit the terminal, and at 80 columns cut names such as
    ``--schedule-participan…``; here the names' columns keep their width and the type and the
    help wrap instead (a word longer than the help's column folds over lines)."""

    def format_help(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        from typer import rich_utils

        rich_utils.Table = _options_table()  # type: ignore[misc]  # (Typer makes its tables from this name of its module)
        super().format_help(ctx, formatter)


WHOLE_NAMES_FROM = 60  # a table this wide or wider keeps every option's names whole


@functools.cache
def _options_table() -> Any:
    """Rich's table, whose columns but the last two (type and help) do not wrap when it is
    :data:`WHOLE_NAMES_FROM` columns wide or wider, and whose last is one text that folds a word
    longer than the column (Typer's row of texts cut it with an ellipsis: ``column:theirs=can…``)."""
    from rich.columns import Columns
    from rich.table import Table
    from rich.text import Text

    class OptionsTable(Table):
        def add_row(self, *renderables: Any, **options: Any) -> None:
            *rest, last = renderables
            texts = [r for r in last.renderables if isinstance(r, Text)] if isinstance(last, Columns) else []
            if texts and len(texts) == len(last.renderables):
                last = Text(" ", overflow="fold").join(texts)
            super().add_row(*rest, last, **options)

        def __rich_console__(self, console: Any, options: Any) -> Any:
            keep = options.max_width >= WHOLE_NAMES_FROM  # narrower, the help's column would be a letter wide
            for column in self.columns[:-2]:  # (the required mark and) the names; not the type and the help
                column.no_wrap = keep
            yield from super().__rich_console__(console, options)

    return OptionsTable


class LazyCommands(MutableMapping[str, click.Command]):
    """A group's commands by name: every name of :data:`COMMANDS`, each built on first access."""

    def __init__(self, built: MutableMapping[str, click.Command], build: Any) -> None:
        self.built = {name: _reflowed(command) for name, command in built.items()}
        self.build = build

    def __getitem__(self, name: str) -> click.Command:
        if name not in self.built:
            if name not in COMMANDS:
                raise KeyError(name)
            self.built[name] = _reflowed(self.build(name))
        return self.built[name]

    def __contains__(self, name: object) -> bool:
        return name in COMMANDS or name in self.built

    def __iter__(self) -> Iterator[str]:
        yield from COMMANDS
        yield from (name for name in self.built if name not in COMMANDS)

    def __len__(self) -> int:
        return len(COMMANDS.keys() | self.built.keys())

    def __setitem__(self, name: str, command: click.Command) -> None:
        self.built[name] = _reflowed(command)

    def __delitem__(self, name: str) -> None:
        del self.built[name]


class LazyGroup(typer.core.TyperGroup):
    """The ``trustseek`` group: lists :data:`COMMANDS` and imports a command's module when it is used."""

    #: the Typer application whose commands the modules register (set where it is made)
    typer_app: ClassVar[typer.Typer]

    def __init__(self, **attrs: Any) -> None:
        super().__init__(**attrs)
        self.commands = LazyCommands(self.commands, self._build)
        self._listing = False

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(self.commands)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        commands = self.commands
        assert isinstance(commands, LazyCommands)
        if self._listing and cmd_name not in commands.built and cmd_name in COMMANDS:
            return self._summary(cmd_name)
        return commands.get(cmd_name)

    def format_help(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The help, listing the commands from :data:`COMMANDS` (no command module imported)."""
        self._listing = True
        try:
            super().format_help(ctx, formatter)
        finally:
            self._listing = False

    @staticmethod
    def _summary(name: str) -> click.Command:
        """A stand-in for the listing: the command's name, help panel and summary."""
        return typer.core.TyperCommand(name, help=reflow(COMMANDS[name].summary), rich_help_panel=COMMANDS[name].panel)

    def _build(self, name: str) -> click.Command:
        """The command ``name``, its module imported (which registers it on the application)."""
        importlib.import_module(f".{COMMANDS[name].module}", __package__)
        app = self.typer_app
        for info in app.registered_commands:
            if command_name(info) == name:
                return typer.main.get_command_from_info(
                    info, pretty_exceptions_short=app.pretty_exceptions_short, rich_markup_mode=app.rich_markup_mode
                )
        raise LookupError(f"trustseek.cli.{COMMANDS[name].module} registers no command {name!r}")
