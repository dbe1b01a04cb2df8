"""A dataset of the docs, as kept in ``docs/data/NAME``: its files read (one line naming the file
when it is missing or not what ``mlpfac report --collect`` writes), and what kind of data it is."""

from __future__ import annotations

import json
from pathlib import Path

from mlpfac.exceptions import ConfigError

OUTPUT = "output.txt"  # a command's printed output: run again by --verify, compared line by line
RECORDS = {  # datasets that are records of what was measured once, never run again: why, by their names' start
    "bench-": "a benchmark's timings, a record of the machine that measured them",
    "history-": "figures of earlier code, a record of what was measured on it",
}


def record(folder: Path) -> str:
    """Why a dataset is a record, never run again (``bench-*``, ``history-*``), or ""."""
    return next((why for start, why in RECORDS.items() if folder.name.startswith(start)), "")


def read_data(folder: Path, name: str) -> str:
    """A data file's text; ConfigError naming it when it is missing or cannot be read."""
    path = folder / name
    if not path.is_file():
        raise ConfigError(str(path), "missing: the data folder holds no such file")
    try:
        return path.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(str(path), f"cannot read: {err}") from None


def read_json(folder: Path, name: str) -> dict:
    """A data file's JSON; ConfigError naming it when it is not what a sweep writes."""
    text = read_data(folder, name)
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as err:
        raise ConfigError(str(folder / name), f"not valid JSON: {err}") from None
    if not isinstance(data, dict):
        raise ConfigError(str(folder / name), "expected a JSON object")
    return data
