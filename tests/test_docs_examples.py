"""The ```python blocks of the README and docs/ run as written: each file's blocks in order, in one
fresh namespace, in a working directory holding the files the docs name (made from the shipped
examples). A block is left out only when the line before its fence says why:
``<!-- not run: needs a running server (trustseek serve) -->``."""

from __future__ import annotations

import json
import logging
import re
import shutil
import traceback
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
FILES = sorted((ROOT / "docs").rglob("*.md")) + [ROOT / "README.md"]
WITH_PYTHON = [f for f in FILES if "```python" in f.read_text(encoding="utf-8")]
NOT_RUN = re.compile(r"^<!--\s*not run:(.*?)-->$")


@dataclass
class Block:
    index: int  # 1-based, among the file's python blocks
    line: int  # 1-based line of the fence
    code: str
    skip: str | None  # the reason of a "not run" comment right before the fence, else None

    @property
    def first_line(self) -> str:
        return next((s for s in self.code.splitlines() if s.strip()), "")


def python_blocks(text: str) -> list[Block]:
    """The ```python blocks of a markdown text, in order."""
    lines = text.splitlines()
    blocks, i = [], 0
    while i < len(lines):
        if lines[i].strip() == "```python":
            start = i
            i += 1
            body = []
            while i < len(lines) and lines[i].strip() != "```":
                body.append(lines[i])
                i += 1
            m = NOT_RUN.match(lines[start - 1].strip()) if start > 0 else None
            blocks.append(Block(len(blocks) + 1, start + 1, "\n".join(body) + "\n", m.group(1).strip() if m else None))
        i += 1
    return blocks


class BlockFailed(AssertionError):
    pass


def run_blocks(blocks: list[Block], name: str) -> int:
    """Run the blocks in order in one fresh namespace; returns how many were skipped. A failing
    block raises BlockFailed naming the file, the block (index, line, first line) and the exception."""
    namespace: dict = {"__name__": "__docs__"}
    skipped = 0
    for b in blocks:
        if b.skip is not None:
            skipped += 1
            continue
        try:
            exec(compile(b.code, f"{name} block {b.index}", "exec"), namespace)
        except Exception as e:
            where = "".join(traceback.format_exception(e)[-3:])
            raise BlockFailed(
                f"{name}: block {b.index} (line {b.line}: {b.first_line!r}) failed: {type(e).__name__}: {e}\n{where}"
            ) from e
    return skipped


# --------------------------------------------------------------------------- the files the docs name


def example_log() -> pd.DataFrame:
    from trustseek.data import example_path

    return pd.read_csv(example_path(), dtype=str)


def common_files(tmp: Path) -> None:
    """log.csv and paper_trials.csv (the shipped example log), model.json (the paper's model)."""
    from trustseek.data import example_path
    from trustseek.model import paper_model

    shutil.copy(example_path(), tmp / "log.csv")
    shutil.copy(example_path(), tmp / "paper_trials.csv")
    paper_model().save(tmp / "model.json")


def condition_of(participants: pd.Series) -> pd.Series:
    """A between-subject condition: every other participant in the aid condition."""
    order = {p: i for i, p in enumerate(dict.fromkeys(participants))}
    return participants.map(lambda p: "aid" if order[p] % 2 else "control")


def data_format_files(tmp: Path) -> None:
    """study.csv in another study's names (mapping.json, the shipped other_study_mapping.json) with a
    `cond` column; study.jsonl in canonical names ordered by a `time` column, one decision `NA`."""
    from trustseek.data import example_path

    log = example_log()
    study = pd.DataFrame(
        {
            "subject": log["participant"],
            "trial_no": log["trial"],
            "automation_correct": (log["experience"] == "reliable").astype(int),
            "rely": (log["human_action"] == "rely").astype(int),
            "cond": condition_of(log["participant"]),
        }
    )
    study.to_csv(tmp / "study.csv", index=False)
    shutil.copy(example_path("other_study_mapping.json"), tmp / "mapping.json")
    timed = log.drop(columns="trial").assign(time=pd.Timestamp("2024-05-01 09:00") + pd.to_timedelta(log.index, "s"))
    timed["time"] = timed["time"].dt.strftime("%Y-%m-%dT%H:%M:%S")
    timed.loc[timed["robot_action"] == "ask", "human_action"] = "NA"  # no decision recorded when asked
    timed.to_json(tmp / "study.jsonl", orient="records", lines=True)


def fitting_files(tmp: Path) -> None:
    """study.csv and its mapping study.json (fitting.md, *Named inputs*): the example log renamed,
    the aid's advice its experience, the image's difficulty the complexity, a between-subject condition."""
    log = example_log()
    study = pd.DataFrame(
        {
            "subject": log["participant"],
            "trial": log["trial"],
            "relied": log["human_action"].map({"rely": "yes", "intervene": "no"}),
            "cond": condition_of(log["participant"]).map({"control": "C", "aid": "A"}),
            "aid_says": log["experience"].map({"reliable": "agree", "faulty": "disagree"}),
            "img": log["complexity"].map({"low": 1, "high": 3}),
        }
    )
    study.loc[study.index % 5 == 2, "img"] = 2
    study.to_csv(tmp / "study.csv", index=False)
    mapping = {
        "columns": {"participant": "subject", "human_action": "relied"},
        "labels": {"human_action": {"yes": "rely", "no": "intervene"}},
        "inputs": {
            "condition": {"column": "cond", "levels": ["control", "aid"], "labels": {"C": "control", "A": "aid"}},
            "advice": {"column": "aid_says", "levels": ["disagree", "agree"]},
            "difficulty": {
                "column": "img",
                "levels": ["easy", "medium", "hard"],
                "labels": {"easy": [1], "medium": [2], "hard": [3]},
            },
        },
        "missing": ["NA"],
    }
    (tmp / "study.json").write_text(json.dumps(mapping, indent=2), encoding="utf-8")


EXTRA_FILES = {"docs/data-format.md": data_format_files, "docs/fitting.md": fitting_files}


# --------------------------------------------------------------------------- the tests


@pytest.fixture
def quiet_state(monkeypatch):
    """matplotlib without a display; the logging levels and handlers a block sets are undone."""
    monkeypatch.setenv("MPLBACKEND", "Agg")
    try:
        import matplotlib

        matplotlib.use("Agg")
    except ImportError:
        pass
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    levels = {n: lg.level for n, lg in logging.Logger.manager.loggerDict.items() if isinstance(lg, logging.Logger)}
    yield
    root.handlers[:] = handlers
    root.setLevel(level)
    for n, lg in logging.Logger.manager.loggerDict.items():
        if isinstance(lg, logging.Logger):
            lg.setLevel(levels.get(n, logging.NOTSET))
    try:
        import matplotlib.pyplot as plt

        plt.close("all")
    except ImportError:
        pass


@pytest.mark.parametrize("path", WITH_PYTHON, ids=lambda p: str(p.relative_to(ROOT)))
def test_the_python_examples_run(path, tmp_path, monkeypatch, quiet_state):
    name = str(path.relative_to(ROOT))
    blocks = python_blocks(path.read_text(encoding="utf-8"))
    common_files(tmp_path)
    if name in EXTRA_FILES:
        EXTRA_FILES[name](tmp_path)
    monkeypatch.chdir(tmp_path)
    skipped = run_blocks(blocks, name)
    assert skipped == sum(b.skip is not None for b in blocks)
    assert all(b.skip for b in blocks if b.skip is not None), f"{name}: a 'not run' comment without a reason"


def test_few_blocks_are_left_out_and_each_says_why():
    every = [(f.relative_to(ROOT), b) for f in FILES for b in python_blocks(f.read_text(encoding="utf-8"))]
    skipped = [(f, b) for f, b in every if b.skip is not None]
    assert len(every) > 15
    assert len(skipped) <= 5, [(str(f), b.index) for f, b in skipped]
    for f, b in skipped:
        assert len(b.skip) >= 10, f"{f}: block {b.index} is not run without a concrete reason: {b.skip!r}"


def test_a_broken_example_is_reported_with_its_file_and_block():
    text = "Intro.\n\n```python\nx = 1\n```\n\n```python\nfrom trustseek.simulate import x\n```\n"
    blocks = python_blocks(text)
    assert [b.index for b in blocks] == [1, 2] and blocks[1].line == 7
    with pytest.raises(BlockFailed) as e:
        run_blocks(blocks, "docs/broken.md")
    msg = str(e.value)
    assert "docs/broken.md: block 2 (line 7: 'from trustseek.simulate import x')" in msg
    assert "ModuleNotFoundError" in msg


def test_a_not_run_comment_skips_only_its_block():
    text = "<!-- not run: needs a running server (trustseek serve) -->\n```python\nraise SystemExit\n```\n\n```python\ny = undefined_name\n```\n"
    blocks = python_blocks(text)
    assert blocks[0].skip == "needs a running server (trustseek serve)" and blocks[1].skip is None
    with pytest.raises(BlockFailed, match=r"block 2 .*NameError"):
        run_blocks(blocks, "docs/x.md")
    assert run_blocks(blocks[:1], "docs/x.md") == 1
