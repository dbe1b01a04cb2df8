"""A run's folder: metrics.json, config.toml (the scenario as resolved), written atomically.

Only the standard library at import time: the sweep's parent process imports this module too.
"""

from __future__ import annotations

import json
import os
import signal
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def write_atomic(path: Path, data: str | bytes) -> None:
    """Write through a temporary file in the same folder and a rename: readers never see half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode() if isinstance(data, str) else data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextmanager
def sigint_deferred() -> Iterator[None]:
    """Hold a Ctrl-C (SIGINT) back until the block has run, then deliver it: a folder being written
    is finished, not left with its config and without its metrics. Only in the main thread, the
    one Python delivers signals to; elsewhere the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: held.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if held and callable(previous):
            previous(signal.SIGINT, None)  # the default handler raises KeyboardInterrupt here


def write_run_folder(out: Path, config: str, metrics: dict, rrd: bytes | None = None) -> None:
    """config.toml, run.rrd (if given), then metrics.json: its presence means the folder is whole."""
    with sigint_deferred():
        (out / "metrics.json").unlink(missing_ok=True)  # a run being replaced is not whole meanwhile
        write_atomic(out / "config.toml", config)
        if rrd is not None:
            write_atomic(out / "run.rrd", rrd)
        write_atomic(out / "metrics.json", json.dumps(metrics, indent=2) + "\n")


def write_run(out: Path, scn, rec) -> dict:
    """The folder of one run from the command line (run.rrd is written by its sink). Returns the metrics."""
    from mlpfac.runner import metrics
    from mlpfac.scenario import to_toml

    m = metrics(rec)
    write_run_folder(out, to_toml(scn.table), m)
    return m
