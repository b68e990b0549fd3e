"""What a file holds, by its suffix: the kinds of trial log the readers take (no heavy import, so
that a command telling a log from a model file loads no pandas)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

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
    if _mapping(data):
        return "mapping"
    return "log" if table_records(data) is not None or object_arrays(data) else "json"


def _mapping(data: dict) -> bool:
    from .mapping import MAPPING_KEYS

    return bool(data) and set(data) <= set(MAPPING_KEYS)


def object_arrays(data: dict[str, Any]) -> list[str]:
    """The keys of a JSON object whose values are arrays of objects (a log's records)."""
    return [k for k, v in data.items() if isinstance(v, list) and v and all(isinstance(r, dict) for r in v)]


def table_records(data: Any) -> list[Any] | None:
    """The records of a JSON log: an array of them; the one array of objects an object holds
    (``{"participants": [...]}``, pandas' ``orient="table"``); or a table as pandas writes it,
    ``orient="split"`` (``columns`` and ``data``), ``"columns"`` (its default: each column an object
    by row label) or ``"index"`` (each row an object by row label), its row labels numbers.  None
    when ``data`` holds a table in none of these shapes."""
    if isinstance(data, list):
        return data
    if not isinstance(data, dict):
        return None
    if isinstance(data.get("columns"), list) and isinstance(data.get("data"), list):  # orient="split"
        return [dict(zip(data["columns"], row, strict=False)) if isinstance(row, list) else row for row in data["data"]]
    arrays = object_arrays(data)
    if len(arrays) == 1:
        return data[arrays[0]]
    if data and all(isinstance(v, dict) for v in data.values()):
        inner = list(dict.fromkeys(k for v in data.values() for k in v))
        if _numbered(inner) and not _numbered(data):  # orient="columns": each column by row label
            return [{c: v.get(r) for c, v in data.items()} for r in inner]
        if _numbered(data) and not _numbered(inner):  # orient="index": each row by its label
            return list(data.values())
    return None


def _numbered(keys: Any) -> bool:
    return all(re.fullmatch(r"-?[0-9]+", str(k)) for k in keys)
