"""Paths a user names for mlpfac to write: checked before anything runs, and written so that nothing
that is not ours is damaged.

- A path is never empty (``--out ""`` would write into the current folder).
- A report file (``check --junit``, ``--summary``): a missing or regular file is replaced atomically;
  a symbolic link is written through to its file (the link stays); a character device or a FIFO
  (``/dev/null``, a pipe) is written through, never replaced by a regular file, and so is one of
  the process's open files (``/dev/stdout`` redirected to a file: appended to); a folder, a block
  device (a disk) or a socket is refused.
- A results folder (``sweep``, ``compare``, ``check --out``): the tables a sweep writes at its top
  (``sweep.csv``, ``summary.md``, ...) replace only tables an earlier mlpfac sweep wrote there; a
  folder holding a file of that name that no sweep of ours wrote is refused, whatever it holds.

Only the standard library: the sweep's parent process imports this module too.
"""

from __future__ import annotations

import json
import os
import re
import stat
import sys
from pathlib import Path

from mlpfac.exceptions import ConfigError

STREAMS = re.compile(r"/dev/(stdout|stderr|fd/\d+)|/proc/(self|\d+)/fd/\d+")  # a process's open files


def cli_path(value: str) -> Path:
    """An argparse ``type`` for a path flag: an empty value is a usage error (one line, exit 2)."""
    import argparse

    if not value.strip():
        raise argparse.ArgumentTypeError("an empty path; name a file or folder")
    return Path(value)


def user_path(value, name: str) -> Path:
    """``value`` (a str or a Path, not empty) as a Path; a ConfigError naming the argument ``name`` else."""
    if isinstance(value, os.PathLike) and not isinstance(value, Path):
        value = os.fspath(value)
    if not isinstance(value, str | Path) or isinstance(value, bool):
        raise ConfigError(name, f"expected a path (str or pathlib.Path), got {value!r}")
    if not str(value).strip():
        raise ConfigError(name, "an empty path; name a file or folder")
    return Path(value)


def _kind(mode: int) -> str | None:
    """What a file of ``mode`` is, in words, when mlpfac must not write it; None when it may."""
    if stat.S_ISDIR(mode):
        return "a folder; name a file"
    if stat.S_ISBLK(mode):
        return "a block device (a disk); name a file"
    if stat.S_ISSOCK(mode):
        return "a socket; name a file"
    return None


def check_report_file(path: Path, flag: str) -> None:
    """Before anything runs: ``path`` may be missing (its folder writable), a regular file, a link
    to one, a character device or a FIFO; anything else is a ConfigError naming ``flag``."""
    from mlpfac.io.files import resolved

    where = f"{flag} {path}"
    real = resolved(path, where)
    try:
        mode = os.stat(path).st_mode  # the path itself: /dev/stdout leads to a pipe no resolved name reaches
    except FileNotFoundError:
        mode = None
    except OSError as err:
        raise ConfigError(where, f"cannot be read ({err.strerror or err})") from None
    if mode is not None and (bad := _kind(mode)):
        raise ConfigError(where, f"is {bad}")
    if mode is None or stat.S_ISREG(mode):
        up = real.parent
        while not up.exists():
            up = up.parent
        if not up.is_dir():
            raise ConfigError(where, f"{up} is a file, not a folder")
        if not os.access(up, os.W_OK | os.X_OK):
            raise ConfigError(where, f"cannot write into {up}")


def write_report_file(path: Path, data: str | bytes) -> Path:
    """Write ``data`` to ``path`` as :func:`check_report_file` allows: a regular (or missing) file
    replaced atomically (through a symbolic link: the file it names), a character device or a FIFO
    written through. A FIFO without a reader is an OSError (ENXIO), not a wait. Returns the path."""
    from mlpfac.io.files import write_atomic
    from mlpfac.io.interrupts import sigint_deferred

    blob = data.encode() if isinstance(data, str) else data
    try:
        st = os.stat(path)
        mode = st.st_mode
    except FileNotFoundError:
        st, mode = None, stat.S_IFREG
    for stream in (sys.stdout, sys.stderr):  # our own stdout (/dev/stdout): written in turn with what we print
        if st is not None and _same_file(st, stream):
            stream.flush()
            stream.buffer.write(blob)
            stream.flush()
            return Path(path)
    if stat.S_ISREG(mode) and not STREAMS.fullmatch(os.path.abspath(path)):
        write_atomic(Path(path).resolve(), blob)  # through a link: its file is replaced, the link stays
        return Path(path)
    if not (stat.S_ISREG(mode) or stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)):
        raise ConfigError(str(path), f"is {_kind(mode) or 'not a file'}")
    with sigint_deferred():  # a stream redirected to a file is appended to, as the process writes to it
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_APPEND)
        try:
            os.set_blocking(fd, True)
            view = memoryview(blob)
            while view:
                view = view[os.write(fd, view) :]
        finally:
            os.close(fd)
    return Path(path)


def _same_file(st: os.stat_result, stream) -> bool:
    try:
        other = os.fstat(stream.fileno())
    except (OSError, ValueError, AttributeError):
        return False
    return (st.st_dev, st.st_ino) == (other.st_dev, other.st_ino)


def is_our_results_folder(out: Path, tables: tuple[str, ...]) -> bool:
    """Whether a JSON table of ``tables`` in ``out`` is one a sweep of mlpfac wrote (its ``meta``
    and ``rows``): then the other tables beside it are a sweep's too."""
    for name in tables:
        if not name.endswith(".json"):
            continue
        try:
            data = json.loads((out / name).read_text())
        except (OSError, ValueError, UnicodeDecodeError):
            continue
        if isinstance(data, dict) and isinstance(data.get("meta"), dict) and isinstance(data.get("rows"), list):
            return True
    return False


def check_results_folder(out: Path, tables: tuple[str, ...], flag: str = "--out") -> None:
    """Before anything runs: the files of ``tables`` a sweep writes at the top of ``out`` replace
    only what an earlier sweep wrote there. A name that is not a regular file, or a folder whose
    tables no sweep of ours wrote, is a ConfigError naming ``flag`` and the file."""
    if not out.is_dir():
        return
    present = [n for n in tables if os.path.lexists(out / n)]
    if not present:
        return
    for name in present:
        st = os.lstat(out / name)
        if not stat.S_ISREG(st.st_mode):
            raise ConfigError(
                f"{flag} {out}", f"holds {name!r}, which is not a regular file; a sweep writes its table there"
            )
    if not is_our_results_folder(out, tables):
        raise ConfigError(
            f"{flag} {out}",
            f"holds {present[0]!r}, which no mlpfac sweep wrote; a sweep would replace it: choose another folder",
        )
