"""What a file holds, by its suffix: the kinds of trial log the readers take (no heavy import, so
that a command telling a log from a model file loads no pandas)."""

from __future__ import annotations

import json
from pathlib import Path

CSV_SUFFIXES = (".csv", ".txt", ".tsv")
COMPRESSED = {".gz": "gzip", ".bz2": "bz2", ".zst": "zstd"}  # a CSV's compressions, by suffix (log.csv.gz)
PARQUET_SUFFIXES = (".parquet", ".pq")
JSONL_SUFFIXES = (".jsonl", ".ndjson")
JSON_SUFFIXES = (".json",)
WORKBOOK_SUFFIXES = (".xlsx", ".xlsm")
STAT_SUFFIXES = (".sav", ".zsav", ".por", ".dta", ".sas7bdat", ".xpt")  # SPSS, Stata, SAS
OTHER_SHEET_SUFFIXES = (".xls", ".ods", ".numbers")  # spreadsheets not read: saved as .xlsx or CSV first
PACKED_SUFFIXES = (".gz", ".zip", ".bz2", ".xz", ".zst", ".7z")
#: the files a folder's log reads, by the suffix that says what they hold
FOLDER_SUFFIXES = (".csv", ".tsv", *PARQUET_SUFFIXES, *JSONL_SUFFIXES, *JSON_SUFFIXES, *WORKBOOK_SUFFIXES, *STAT_SUFFIXES)


def kind_suffix(path: Path) -> str:
    """The suffix that says what the file holds: ``.csv`` of ``log.csv`` and of ``log.csv.gz``."""
    suffixes = [s.lower() for s in path.suffixes]
    return suffixes[-2] if len(suffixes) > 1 and suffixes[-1] in COMPRESSED else path.suffix.lower()


def file_kind(path: Path) -> str:
    """What ``path`` names, as ``trustseek check`` reads it: ``"log"`` (a folder, a log's suffix
    such as ``.csv``, ``.parquet``, ``.xlsx``, ``.sav``, or a ``.json`` file of records: an array, or
    an object holding them), ``"mapping"`` (a ``.toml`` file, or a ``.json`` object of a mapping's
    entries only) or ``"json"`` (a model, task or policy file, or one the model reader says is not).
    A ``.json`` file is read once, and only when its suffix leaves the kind open."""
    suffix = kind_suffix(path)
    if path.is_dir() or (suffix in (*CSV_SUFFIXES, *FOLDER_SUFFIXES) and suffix not in JSON_SUFFIXES):
        return "log"
    if suffix == ".toml":
        return "mapping"
    if suffix not in JSON_SUFFIXES or not path.is_file():
        return "json"
    try:
        data = json.loads(path.read_bytes())
    except (OSError, ValueError, RecursionError):
        return "json"  # the model reader says what is wrong with it
    if isinstance(data, list):
        return "log"
    if not isinstance(data, dict) or "format" in data:
        return "json"
    return "mapping" if _mapping(data) else "log" if _holds_records(data) else "json"


def _mapping(data: dict) -> bool:
    from .mapping import MAPPING_KEYS

    return bool(data) and set(data) <= set(MAPPING_KEYS)


def _holds_records(data: dict) -> bool:
    """Whether a JSON object holds a table, as the log reader finds one: an array of objects in
    it, pandas' ``split`` (``columns`` and ``data``), or objects by row number and column (pandas'
    ``index`` and ``columns``); not a mapping file (objects by name)."""
    values = list(data.values())
    if any(isinstance(v, list) and v and all(isinstance(r, dict) for r in v) for v in values):
        return True
    if isinstance(data.get("columns"), list) and isinstance(data.get("data"), list):
        return True
    if not values or not all(isinstance(v, dict) and v for v in values):
        return False
    numbered = [*data] if all(k.isdigit() for k in data) else [k for v in values for k in v]  # pandas' orient="index"
    return all(k.isdigit() for k in numbered)  # orient="columns": each column an object by row number
