"""Options several commands take, declared once: --model and --task (and reading what they
name), --json, --quiet, --widen, and those that say how a command reads its trial log
(--mapping, --column, --label, --missing, --delimiter, --order, --keep, --no-experience-rule),
which a command takes with :func:`log_options`, as one :class:`LogReading`."""

from __future__ import annotations

import atexit
import inspect
import json
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property, wraps
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer
from rich.markup import escape

from ..vocab import check_belief_update
from ._app import check_mapping_file, err_console

if TYPE_CHECKING:
    from ..model.core import TrustModel
    from ..model.task import Task

ModelOpt = typer.Option("paper", "--model", "-m", help="Trust model: a preset name (paper) or a JSON file.")
TaskOpt = typer.Option("paper", "--task", "-t", help="Task: a preset name (paper) or a JSON file.")
JsonOpt = typer.Option(False, "--json", help="Print one JSON object instead of tables.")
PrintJsonOpt = typer.Option(False, "--json", help="Print JSON.")


def widen_option(most: int, otherwise: str) -> Any:
    """--widen/--no-widen of a model selection that compares up to ``most``."""
    return typer.Option(
        True,
        "--widen/--no-widen",
        help="While the best by BIC or held-out log-likelihood is the largest number compared, compare one more "
        f"(up to {most}); --no-widen compares {otherwise} only.",
    )


def model_and_task(model: str, task: str, belief_update: str | None = None) -> tuple[TrustModel, Task]:
    """The trust model and the task that --model and --task name (a preset or a file), after the
    --belief-update given is checked."""
    from ..model.presets import load_model, load_task

    if belief_update is not None:
        check_belief_update(belief_update, "--belief-update")
    return load_model(model), load_task(task)


MappingOpt = typer.Option(None, "--mapping", help="Column/label mapping file (JSON or TOML) for a log with other names.")
ColumnOpt = typer.Option(None, "--column", help="Map a column: canonical=theirs (e.g. human_action=rely). Repeatable.")
LabelOpt = typer.Option(None, "--label", help="Map a label: column:theirs=canonical (e.g. human_action:1=rely). Repeatable.")
DelimiterOpt = typer.Option(None, "--delimiter", help="A CSV's delimiter (default: sniffed from the header; 'tab' for TAB).")
MissingOpt = typer.Option(None, "--missing", help="A cell text meaning not recorded, e.g. NA (besides empty). Repeatable.")
OrderOpt = typer.Option(
    None,
    "--order",
    metavar="COLUMN[,COLUMN]",
    help="Columns that order each participant's trials, e.g. block,trial for a trial number that restarts every block "
    "(the mapping's 'order'); the trials are numbered 1, 2, ... in that order.",
)
RatingPerOpt = typer.Option(
    None,
    "--rating-per",
    metavar="COLUMN",
    help="The rating is given once per block of this column and copied onto its trials: count it once, on the "
    "block's last trial (the mapping's rating 'per').",
)
KeepOpt = typer.Option(None, "--keep", help="Carry this column of the log into the output (e.g. a condition). Repeatable.")
QuietOpt = typer.Option(False, "--quiet", "-q", help="No progress bar on stderr (there is none when stderr is not a terminal).")
NoExperienceRuleOpt = typer.Option(
    False,
    "--no-experience-rule",
    help="Do not check the paper's experience rule (an intervention ends faulty, an ask as the task says): for a "
    'study where it does not hold, e.g. advice taking; as the mapping\'s "experience_rule": false.',
)

#: the options :func:`log_options` adds, in the order the help lists them: (annotation, option)
_OPTIONS: dict[str, tuple[Any, Any]] = {
    "mapping": (Path | None, MappingOpt),
    "column": (list[str] | None, ColumnOpt),
    "label": (list[str] | None, LabelOpt),
    "missing": (list[str] | None, MissingOpt),
    "delimiter": (str | None, DelimiterOpt),
    "order": (list[str] | None, OrderOpt),
    "keep": (list[str] | None, KeepOpt),
    "quiet": (bool, QuietOpt),
    "no_rule": (bool, NoExperienceRuleOpt),
}
_PASSED_ON = ("quiet",)  # options the command takes itself, not as part of its LogReading


@dataclass(frozen=True)
class LogReading:
    """How a command reads its trial log: the values of its log options."""

    mapping: Path | None = None
    column: list[str] | None = None
    label: list[str] | None = None
    missing: list[str] | None = None
    delimiter: str | None = None
    order: list[str] | None = None
    keep: list[str] | None = None
    no_rule: bool = False

    @cached_property
    def mapping_to_read(self) -> Path | None:
        """The --mapping to read with (:func:`rule_off`; once per command)."""
        return rule_off(self.mapping, self.no_rule)

    def read(self, log: Path, needed: tuple[str, ...], rating: dict | None = None, actions: bool = True):
        """The trial log with these options applied; ``needed`` are the canonical columns the
        command uses beyond participant, trial and human_action (not required without
        ``actions``); ``rating`` a rating entry of a mapping (from --rating flags).  Rows left
        out by the mapping's drop rules are counted on stderr."""
        from ..data import ColumnMapping, read_trials

        mapping = self.mapping_to_read
        check_mapping_file(mapping)
        m = ColumnMapping.from_flags(
            self.column or [], self.label or [], mapping, self.missing, self.delimiter, rating, self.order
        )
        outputs = ("human_action",) if actions else ()
        frame = read_trials(log, m, required=("participant", "trial", *outputs, *needed))
        for rule, count in frame.attrs.get("dropped", []):
            err_console.print(f"dropped {count} rows of {log} ({escape(rule)})", highlight=False)
        for note in frame.attrs.get("joined", []):
            err_console.print(f"{log}: {escape(note)}", highlight=False)
        if m.experience_rule is False:
            note = "the paper's experience rule is not checked (the mapping's experience_rule: false)"
            err_console.print(f"{log}: {note}", highlight=False)
        return frame


#: the default of a command's ``reading`` parameter, for the type checker: :func:`log_options`
#: always passes the values of the options
FROM_OPTIONS = LogReading()


def log_options(
    keep: bool = False, quiet: bool = False, names: tuple[str, ...] | None = None
) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """A command's log options: its parameter ``reading`` (a :class:`LogReading`) becomes the
    options --mapping, --column, --label, --missing, --delimiter, --order, (--keep, --quiet,)
    --no-experience-rule, or those ``names`` (keys of :data:`_OPTIONS`), listed in that order
    after its own; ``quiet`` is passed on to the command as itself."""
    chosen = names or (*list(_OPTIONS)[:6], *(["keep"] if keep else []), *(["quiet"] if quiet else []), "no_rule")
    unknown = [n for n in chosen if n not in _OPTIONS]
    if unknown:
        raise ValueError(f"no log option {unknown}")

    def decorate(command: Callable[..., None]) -> Callable[..., None]:
        own = [p for p in inspect.signature(command, eval_str=True).parameters.values() if p.name not in ("reading", *chosen)]
        added = [
            inspect.Parameter(n, inspect.Parameter.KEYWORD_ONLY, default=_OPTIONS[n][1], annotation=_OPTIONS[n][0])
            for n in chosen
        ]

        @wraps(command)
        def run(**values: Any) -> None:
            fields = {n: values.pop(n) for n in chosen if n not in _PASSED_ON}
            command(reading=LogReading(**fields), **values)

        run.__signature__ = inspect.Signature([*own, *added], return_annotation=None)  # type: ignore[attr-defined]
        run.__annotations__ = {p.name: p.annotation for p in run.__signature__.parameters.values()}  # type: ignore[attr-defined]
        return run

    return decorate


def rule_off(mapping: Path | None, off: bool) -> Path | None:
    """The --mapping to read with: with ``off`` (--no-experience-rule), the mapping (or none) with
    ``experience_rule`` false, written to a temporary file for this process (said on stderr)."""
    if not off:
        return mapping
    from ..data import ColumnMapping

    check_mapping_file(mapping)
    merged = (ColumnMapping.load(mapping) if mapping is not None else ColumnMapping()).merged(
        ColumnMapping(experience_rule=False)
    )
    folder = Path(tempfile.mkdtemp(prefix="trustseek-mapping-"))
    atexit.register(shutil.rmtree, folder, True)
    path = folder / "mapping.json"
    path.write_text(json.dumps(merged.to_dict()), encoding="utf-8")
    err_console.print("--no-experience-rule: the paper's experience rule is not checked", highlight=False)
    return path
