"""A run's folder: metrics.json, config.toml (the scenario as resolved), written atomically."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from mlpfac.record import RunRecord
from mlpfac.runner import metrics
from mlpfac.scenario import Scenario, to_toml


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename: readers never see half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_run(out: Path, scn: Scenario, rec: RunRecord) -> dict:
    """config.toml, then metrics.json (last: its presence means the run folder is whole). Returns the metrics."""
    m = metrics(rec)
    write_atomic(out / "config.toml", to_toml(scn.table))
    write_atomic(out / "metrics.json", json.dumps(m, indent=2) + "\n")
    return m
