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


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Python delivers signals: handled like Ctrl-C, but the exit code is 143."""


def _raise_terminated(signum: int, frame) -> None:
    raise Terminated()


def handle_sigterm() -> None:
    """Make SIGTERM raise :class:`Terminated` (a KeyboardInterrupt) in the main thread, as SIGINT does."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _raise_terminated)


@contextmanager
def sigint_deferred() -> Iterator[None]:
    """Hold a Ctrl-C (SIGINT) or a SIGTERM back until the block has run, then deliver it: a folder
    being written is finished, not left with its config and without its metrics. Only in the main
    thread, the one Python delivers signals to; elsewhere the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: held.append(signum)) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        for s in dict.fromkeys(held):
            handler = previous[s]
            if callable(handler):
                handler(s, None)  # the default SIGINT handler raises KeyboardInterrupt here
            elif handler == signal.SIG_DFL:
                signal.raise_signal(s)


@contextmanager
def folder_lock(target: Path, what: str = "--out") -> Iterator[None]:
    """Hold an exclusive lock on ``target`` (a run or sweep folder, which need not exist yet) while
    the block runs: a second mlpfac process writing into the same folder gets a ConfigError naming
    ``what`` instead of mixing its results with this one's. The lock is ``.NAME.lock`` beside the
    folder (flock, released by the kernel when the process dies, whatever kills it)."""
    import fcntl

    from mlpfac.exceptions import ConfigError

    target = Path(target).absolute()
    lock = target.parent / f".{target.name}.lock"
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666 & ~_umask())
    except OSError as err:
        raise ConfigError(
            f"{what} {target}", f"cannot create its lock file {lock.name} ({err.strerror or err})"
        ) from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            raise ConfigError(
                f"{what} {target}",
                f"another mlpfac process (pid {holder}) is writing into this folder; wait for it or choose another",
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)  # closing the descriptor releases the lock


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
