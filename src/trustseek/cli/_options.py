"""Options several commands take, declared once: --model and --task (and reading what they
name: a trust model or supervisor types, a task; the grid solver's two trust levels), --json,
--quiet, --widen, --counts, the inputs of the commands that fit as fit does, and those that say
how a command reads its trial log (--mapping, --column, --label, --missing, --delimiter,
--sheet, --order, --keep, --no-experience-rule), which a command takes with :func:`log_options`, as one
:class:`LogReading`."""

from __future__ import annotations

import inspect
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property, wraps
from pathlib import Path
from typing import TYPE_CHECKING, Any, get_type_hints

import typer
from rich.markup import escape

from ..errors import TrustseekError
from ..parallel import MAX_JOBS
from ..vocab import check_belief_update
from ._app import check_tol, err_console

if TYPE_CHECKING:
    from ..data.mapping import ColumnMapping
    from ..model.core import TrustModel
    from ..model.mixture import TypeMixture
    from ..model.task import Task

ModelOpt = typer.Option("paper", "--model", "-m", help="Trust model: a preset name (paper) or a JSON file.")
TaskOpt = typer.Option("paper", "--task", "-t", help="Task: a preset name (paper) or a JSON file.")
MaxIterOpt = typer.Option(1000, "--max-iter", min=1, help="Iteration cap per restart (E-steps).")
PolicyOutOpt = typer.Option(None, "--out", "-o", help="Write the policy to this JSON file.")
#: the trial log: a file, or several (a file per participant or session) or a folder of them, read as one
LogArg = typer.Argument(
    ...,
    help="Trial log (CSV, Parquet, JSON, Excel, SPSS, Stata); several files or a folder of them (a file per participant) "
    "read as one.",
)
OneRowPerTrialLogArg = typer.Argument(
    ...,
    help="Trial log (CSV, Parquet, JSON, Excel, SPSS, Stata), one row per trial; several files or a folder of them (a file "
    "per participant) read as one.",
)


def log_name(log: Sequence[Path]) -> str:
    """The trial log as messages name it: its path, or how many files it is."""
    return str(log[0]) if len(log) == 1 else f"the {len(log)} files of the log"


def log_inputs(log: Sequence[Path]) -> tuple[tuple[Path, str], ...]:
    """The trial log's files, as (path, what) for :func:`~._app.check_outputs`."""
    return tuple((p, "trial log") for p in log)


def belief_update_option(default: str, of: str = "") -> Any:
    """``--belief-update``/``-u`` (of ``of``), refused before the command runs unless bayes or paper."""
    return typer.Option(
        default,
        "--belief-update",
        "-u",
        callback=lambda value: check_belief_update(value, "--belief-update"),
        help=f"Belief update{of}: 'bayes' (the exact filter) or 'paper' (the paper's eq. 3).",
    )


def people_option(default: int, *flags: str, help: str, least: int = 1) -> Any:
    """A number of simulated participants: at least ``least``, at most a million."""
    return typer.Option(default, *flags, min=least, max=1_000_000, help=help)


def restarts_option(default: int | None, *flags: str, help: str) -> Any:
    """``--restarts`` (or ``flags``): random starts of a fit, 1 to 1000."""
    return typer.Option(default, *(flags or ("--restarts", "-r")), min=1, max=1000, help=help)


def tol_option(default: float, help: str) -> Any:
    """``--tol``: a fit's relative log-likelihood tolerance, refused unless finite and > 0."""
    return typer.Option(default, "--tol", callback=check_tol, help=help)


def bootstrap_option(default: int, help: str) -> Any:
    """``--bootstrap``/``-b``: participant-bootstrap resamples, 0 to 10,000."""
    return typer.Option(default, "--bootstrap", "-b", min=0, max=10_000, help=help)


def json_option(help: str) -> Any:
    """``--json``: print ``help``'s JSON instead of tables."""
    return typer.Option(False, "--json", help=help)


def seed_option(help: str) -> Any:
    """``--seed``: a random seed (>= 0)."""
    return typer.Option(0, "--seed", min=0, help=help)


def processes_option(what: str) -> Any:
    """``--jobs``: the processes that run ``what`` side by side."""
    help_text = f"Processes: {what} side by side (default: all cores); numbers do not depend on it."
    return typer.Option(None, "--jobs", "-j", min=1, max=MAX_JOBS, help=help_text)


JsonOpt = json_option("Print one JSON object instead of tables.")
PrintJsonOpt = json_option("Print JSON.")
SeedOpt = seed_option("Random seed.")
SelectionJobsOpt = processes_option("the fits of each number compared,")
QuietOpt = typer.Option(False, "--quiet", "-q", help="No progress bar on stderr (there is none when stderr is not a terminal).")
#: the inputs of the commands that fit as ``fit`` does
AsForFitTransitionsOpt = typer.Option(None, "--transitions-on", help="Inputs of the transitions (as for fit).")
AsForFitEmissionsOpt = typer.Option(None, "--emissions-on", help="Inputs of the emissions (as for fit).")
RatingPerOpt = typer.Option(
    None,
    "--rating-per",
    metavar="COLUMN",
    help="The rating is given once per block of this column and copied onto its trials: count it once, on the "
    "block's last trial (the mapping's rating 'per').",
)


def widen_option(most: int, otherwise: str) -> Any:
    """--widen/--no-widen of a model selection that compares up to ``most``."""
    return typer.Option(
        True,
        "--widen/--no-widen",
        help="While the best by BIC or held-out log-likelihood is the largest number compared, compare one more "
        f"(up to {most}); --no-widen compares {otherwise} only.",
    )


def model_and_task(model: str, task: str) -> tuple[TrustModel, Task]:
    """The trust model and the task that --model and --task name (a preset or a file)."""
    from ..model.presets import load_model, load_task

    return load_model(model), load_task(task)


def mixture_of(spec: str, types: str | None = None) -> TypeMixture | None:
    """The supervisor types --types names (``types``, when given), else those ``spec`` names when
    it is a mixture (a mixture preset such as paper+conservative, or a trustseek.mixture/1 file);
    None for a plain trust model."""
    from ..model.jsonfile import load_json
    from ..model.mixture import MIXTURE_FORMAT
    from ..model.presets import MIXTURE_PRESETS, MODEL_PRESETS, load_mixture

    if types is not None:
        return load_mixture(types)
    if spec in MODEL_PRESETS:
        return None
    if spec in MIXTURE_PRESETS:
        return load_mixture(spec)
    p = Path(spec)
    if p.is_file():
        d, _ = load_json(p)
        if isinstance(d, dict) and (d.get("format") == MIXTURE_FORMAT or "types" in d):
            return load_mixture(p)
    return None


def need_two_levels(model: TrustModel, command: str) -> None:
    """The belief-grid solver handles two trust levels; say what to use for more."""
    if model.n_trust != 2:
        alternative = {
            "solve": "use --solver point",
            "plot-q": "solve it with 'trustseek solve --solver point' (the plot needs a two-level model)",
            "simulate": "solve it with 'trustseek solve --solver point --out policy.json' and pass --policy policy.json",
        }[command]
        raise TrustseekError([f"the default grid solver needs two trust levels; this model has {model.n_trust}: {alternative}"])


def parse_counts(text: str, complexities: Sequence[str], option: str = "--counts") -> tuple[int, ...]:
    """Trials per complexity, ``17,17`` (in the task's order) or ``low=17,high=17`` (a complexity
    left out has none): whole numbers 0 or more, at least one trial in all; else one error naming
    ``option``, the value and what is expected."""
    parts = [p.strip() for p in text.split(",")]
    named = [p.partition("=") for p in parts]
    problem = None
    if any(sep for _, sep, _ in named):
        keys = [k.strip() for k, _, _ in named]
        values = {k.strip(): v.strip() for k, _, v in named}
        unknown = [k for k in keys if k not in complexities]
        if not all(sep for _, sep, _ in named):
            problem = "mixes numbers and names"
        elif unknown:
            problem = f"{unknown[0]!r} is not a complexity of the task"
        elif len(set(keys)) != len(keys):
            problem = "a complexity is named twice"
        numbers = [values.get(c, "0") for c in complexities]
    else:
        numbers = parts
        if len(parts) != len(complexities):
            problem = f"{len(parts)} number{'s' * (len(parts) != 1)} for {len(complexities)} complexities"
    bad = [n for n in numbers if not re.fullmatch(r"[0-9]+", n)]
    if problem is None and bad:
        problem = f"{bad[0]!r} is negative" if re.fullmatch(r"-[0-9]+", bad[0]) else f"{bad[0]!r} is not a whole number"
    if problem is None and not any(int(n) for n in numbers):
        problem = "no trials"
    if problem is not None:
        examples = f"{','.join('17' for _ in complexities)} or {','.join(f'{c}=17' for c in complexities)}"
        raise TrustseekError(
            [
                f"{option} {text!r}: {problem}; expected a whole number 0 or more per complexity "
                f"({', '.join(complexities)}), at least one trial in all, e.g. {examples}"
            ]
        )
    return tuple(int(n) for n in numbers)


#: the options :func:`log_options` adds, in the order the help lists them (their types: :class:`LogReading`'s fields)
_OPTIONS: dict[str, Any] = {
    "mapping": typer.Option(None, "--mapping", help="Column/label mapping file (JSON or TOML) for a log with other names."),
    "column": typer.Option(None, "--column", help="Map a column: canonical=theirs (e.g. human_action=rely). Repeatable."),
    "label": typer.Option(None, "--label", help="Map a label: column:theirs=canonical (e.g. human_action:1=rely). Repeatable."),
    "missing": typer.Option(None, "--missing", help="A cell text meaning not recorded, e.g. NA (besides empty). Repeatable."),
    "delimiter": typer.Option(None, "--delimiter", help="A CSV's delimiter (default: sniffed from the header; 'tab' for TAB)."),
    "sheet": typer.Option(
        None, "--sheet", help="An Excel workbook's sheet holding the log (default: its only sheet with values)."
    ),
    "order": typer.Option(
        None,
        "--order",
        metavar="COLUMN[,COLUMN]",
        help="Columns that order each participant's trials, e.g. block,trial for a trial number that restarts every "
        "block (the mapping's 'order'); the trials are numbered 1, 2, ... in that order.",
    ),
    "keep": typer.Option(None, "--keep", help="Carry this column of the log into the output (e.g. a condition). Repeatable."),
    "no_rule": typer.Option(
        False,
        "--no-experience-rule",
        help="Do not check the paper's experience rule (an intervention ends faulty, an ask as the task says): "
        'for a study where it does not hold, e.g. advice taking; as the mapping\'s "experience_rule": false.',
    ),
}
_DEFAULT = ("mapping", "column", "label", "missing", "delimiter", "sheet", "order")


@dataclass(frozen=True)
class LogReading:
    """How a command reads its trial log: the values of its log options."""

    mapping: Path | None = None
    column: list[str] | None = None
    label: list[str] | None = None
    missing: list[str] | None = None
    delimiter: str | None = None
    sheet: str | None = None
    order: list[str] | None = None
    keep: list[str] | None = None
    no_rule: bool = False

    @cached_property
    def column_mapping(self) -> ColumnMapping | None:
        """The --mapping file, read once per command, with --no-experience-rule its rule switched
        off (None without either)."""
        from ..data.mapping import ColumnMapping

        read = None if self.mapping is None else read_mapping(self.mapping)
        if not self.no_rule:
            return read
        return (read or ColumnMapping()).merged(ColumnMapping(experience_rule=False))

    def inputs(self) -> tuple[tuple[Any, str], ...]:
        """The files the options name that a command reads (the --mapping file and the file it
        joins), as (path, what) for :func:`~._app.check_outputs`."""
        mapping = self.column_mapping
        joined = None if mapping is None or mapping.join is None else mapping.join["file"]
        return ((self.mapping, "--mapping file"), (joined, "file the --mapping file joins"))

    def read(self, log: Sequence[Path], needed: tuple[str, ...], rating: dict | None = None, actions: bool = True):
        """The trial log with these options applied; ``needed`` are the canonical columns the
        command uses beyond participant, trial and human_action (not required without
        ``actions``); ``rating`` a rating entry of a mapping (from --rating flags).  Rows left
        out by the mapping's drop rules are counted on stderr."""
        from ..data import ColumnMapping, read_trials

        m = ColumnMapping.from_flags(
            self.column or [], self.label or [], self.column_mapping, self.missing, self.delimiter, rating, self.order, self.sheet
        )
        outputs = ("human_action",) if actions else ()
        frame = read_trials(log[0] if len(log) == 1 else list(log), m, required=("participant", "trial", *outputs, *needed))
        for rule, count in frame.attrs.get("dropped", []):
            err_console.print(f"dropped {count} rows of {log_name(log)} ({escape(rule)})", highlight=False)
        for note in frame.attrs.get("joined", []):
            err_console.print(f"{log_name(log)}: {escape(note)}", highlight=False)
        if self.no_rule:
            err_console.print("--no-experience-rule: the paper's experience rule is not checked", highlight=False)
        elif m.experience_rule is False:
            note = "the paper's experience rule is not checked (the mapping's experience_rule: false)"
            err_console.print(f"{log_name(log)}: {note}", highlight=False)
        return frame


#: the default of a command's ``reading`` parameter, for the type checker: :func:`log_options`
#: always passes the values of the options
FROM_OPTIONS = LogReading()


def log_options(keep: bool = False, names: tuple[str, ...] | None = None) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """A command's log options: its parameter ``reading`` (a :class:`LogReading`) becomes the
    options --mapping, --column, --label, --missing, --delimiter, --sheet, --order, (--keep,)
    --no-experience-rule, or those ``names`` (keys of :data:`_OPTIONS`), in that order where
    ``reading`` stands."""
    chosen = names or (*_DEFAULT, *(["keep"] if keep else []), "no_rule")

    def decorate(command: Callable[..., None]) -> Callable[..., None]:
        own = [
            p.replace(kind=inspect.Parameter.KEYWORD_ONLY) for p in inspect.signature(command, eval_str=True).parameters.values()
        ]
        at = [p.name for p in own].index("reading")
        types = get_type_hints(LogReading)
        added = [inspect.Parameter(n, inspect.Parameter.KEYWORD_ONLY, default=_OPTIONS[n], annotation=types[n]) for n in chosen]

        @wraps(command)
        def run(**values: Any) -> None:
            command(reading=LogReading(**{n: values.pop(n) for n in chosen}), **values)

        run.__signature__ = inspect.Signature([*own[:at], *added, *own[at + 1 :]], return_annotation=None)  # type: ignore[attr-defined]
        run.__annotations__ = {p.name: p.annotation for p in run.__signature__.parameters.values()}  # type: ignore[attr-defined]
        return run

    return decorate


def read_mapping(path: Path) -> ColumnMapping:
    """A --mapping file (JSON or TOML), read once (:meth:`~trustseek.data.mapping.ColumnMapping.read`),
    a problem reading it named by the option."""
    from ..data.cells import DataError
    from ..data.mapping import ColumnMapping

    try:
        content = ColumnMapping.read(path)
    except DataError as exc:
        raise TrustseekError([f"--mapping: {p}" for p in exc.problems], str(path)) from None
    return ColumnMapping.from_file(content, path)
