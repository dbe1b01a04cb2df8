"""Files and folders written whole: a file written atomically (:func:`write_atomic`), a folder
staged and renamed into place (:func:`write_folder_whole`, :class:`Stage`: a run folder or a
recording written beside its target and put in place only when whole, so a run never replaces a
finished run by half of one), a folder's lock, and the checks of a path before anything is written.

Only the standard library at import time: the sweep's parent process imports this module too.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from mlpfac.io.interrupts import sigint_deferred

KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
         (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))  # fmt: skip


class NotAFileError(ValueError):
    """What :func:`read_regular` refuses to read: not a regular file, or larger than asked."""


def read_regular(path: Path, most: int) -> bytes:
    """The bytes of the regular file at ``path``, if it holds at most ``most``: OSError as reading
    raises it (FileNotFoundError...); :class:`NotAFileError` saying what it is for a folder, a FIFO, a
    device or a socket (opened without waiting for a FIFO's writer, never read: /dev/zero is not
    read whole), or saying its size for a file larger than ``most`` (found before it is read)."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY)
    try:
        mode, size = os.fstat(fd).st_mode, os.fstat(fd).st_size
        kind = next((name for test, name in KINDS if test(mode)), None if stat.S_ISREG(mode) else "not a file")
        if kind is not None:
            raise NotAFileError(f"is {kind}, not a regular file")
        chunks, got = [], 0
        while size <= most and got <= most:  # a file that grows while it is read stops at most + 1 bytes
            chunk = os.read(fd, min(1 << 20, most + 1 - got))
            if not chunk:
                return b"".join(chunks)
            chunks.append(chunk)
            got += len(chunk)
        raise NotAFileError(f"{max(size, got) / 2**20:.3g} MiB is more than the {most / 2**20:.3g} MiB allowed")
    finally:
        os.close(fd)


def write_atomic(path: Path, data: str | bytes) -> None:
    """Write through a temporary file in the same folder and a rename: readers never see half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode() if isinstance(data, str) else data)
        os.replace(tmp, path)
    except BaseException as err:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(err, OSError) and err.filename != str(path):  # name the file, not its temporary
            raise OSError(err.errno, err.strerror, str(path)) from err
        raise


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextmanager
def folder_lock(target: Path, what: str = "--out") -> Iterator[None]:
    """Hold an exclusive lock on ``target`` (a run or sweep folder, which need not exist yet) while
    the block runs: a second mlpfac process writing into the same folder gets a ConfigError naming
    ``what`` instead of mixing its results with this one's. The lock is ``.NAME.lock`` beside the
    folder (flock, released by the kernel when the process dies, whatever kills it)."""
    import fcntl

    from mlpfac.exceptions import ConfigError

    where = f"{what} {target}"
    target = resolved(target, where)  # one folder, one lock, whatever name it is reached by
    lock = target.parent / f".{target.name}.lock"
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666 & ~_umask())
    except OSError as err:
        raise ConfigError(where, f"cannot write here ({err.strerror or err})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            raise ConfigError(
                where,
                f"another mlpfac process (pid {holder}) is writing into this folder; wait for it or choose another",
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)  # closing the descriptor releases the lock


def write_folder_whole(target: Path, files: dict[str, str | bytes]) -> None:
    """The folder ``target`` holding just ``files`` (name -> text or bytes), written beside it at
    ``.NAME.tmp-XXXX`` and renamed into place: even a killed process leaves ``target`` as it was or
    whole, never half written. What a killed write leaves is cleared by :func:`remove_staged`. An
    OSError names ``target`` (or its file), never the temporary."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with sigint_deferred():
        staged = None
        try:
            staged = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.tmp-"))
            os.chmod(staged, 0o777 & ~_umask())
            for name, data in files.items():
                try:
                    (staged / name).write_bytes(data.encode() if isinstance(data, str) else data)
                except OSError as err:  # name the file as it will be, not its staging place
                    raise OSError(err.errno, err.strerror, str(target / name)) from err
            _replace(staged, target)
            staged = None
        except OSError as err:
            if err.filename is not None and str(target) in str(err.filename):
                raise
            raise OSError(err.errno, err.strerror, str(target)) from err
        finally:
            if staged is not None:
                _remove(staged)


STAGED = re.compile(r"\.(?P<name>seed-\d+)\.tmp-[A-Za-z0-9_]+(?P<old>-old)?")  # a sweep's run folder, staged


def remove_staged(folders: Iterable[Path]) -> None:
    """Clear what :func:`write_folder_whole` left in ``folders`` (a sweep's controller folders) when
    killed: a staged folder is removed; a finished run renamed aside (``-old``, where the system
    cannot exchange two folders) is put back if its place is empty. Hold the sweep's lock."""
    for folder in folders:
        with suppress(OSError):
            for name in os.listdir(folder):
                m = STAGED.fullmatch(name)
                if m is not None:
                    with suppress(OSError):  # one that cannot be cleared now is tried by the next sweep
                        _clear_staged(folder / name, folder / m["name"])


def _clear_staged(path: Path, target: Path) -> None:
    """A temporary of ``target`` left by a killed write: a finished folder renamed aside
    (``-old``, where two folders could not be exchanged) goes back if its place is empty; anything
    else is removed."""
    if path.name.endswith("-old") and not os.path.lexists(target):
        os.rename(path, target)
    else:
        _remove(path)


# ----------------------------------------------------------------------------------------------
# A run folder (or file) written beside its target, then renamed into place

RUN_FILES = ("config.toml", "metrics.json", "figure1.png", "run.rrd", "error.txt")


def check_run_folder(out: Path, what: str = "--out") -> None:
    """Before anything is written: ``out`` may be missing, or a folder holding nothing but a run's
    files (it is replaced whole); a file, or a folder with other files in it, is refused."""
    from mlpfac.exceptions import ConfigError

    where = f"{what} {out}"
    _check_ancestors(out, where)
    if out.exists() and not out.is_dir():
        raise ConfigError(where, "is a file; name a folder (it is created)")
    if out.is_dir():
        try:
            names = os.listdir(out)
        except OSError as err:
            raise ConfigError(where, f"cannot read this folder ({err.strerror or err})") from None
        other = sorted(n for n in names if n not in RUN_FILES and not n.startswith(tuple(f".{f}." for f in RUN_FILES)))
        if other:
            raise ConfigError(
                where, f"holds {other[0]!r}, not a run's file; a run replaces its whole folder: choose another"
            )


def check_save_file(path: Path, what: str = "--save") -> None:
    """Before anything is written: ``path`` may be missing or a regular file (it is replaced)."""
    from mlpfac.exceptions import ConfigError

    _check_ancestors(path, f"{what} {path}")
    if path.is_dir():
        raise ConfigError(f"{what} {path}", "is a folder; name a file such as run.rrd")
    if path.exists() and not stat.S_ISREG(path.stat().st_mode):
        raise ConfigError(f"{what} {path}", "is not a regular file (a device or a pipe); name a file such as run.rrd")


def resolved(path: Path, where: str) -> Path:
    """``path`` with its symbolic links followed (it need not exist); a link that leads back to
    itself on the way (a symlink loop) is a ConfigError naming ``where`` (a flag and its value)."""
    from mlpfac.exceptions import ConfigError

    try:
        return Path(path).resolve()
    except (RuntimeError, OSError) as err:  # a loop: RuntimeError before Python 3.13, OSError (ELOOP) since
        loop = isinstance(err, RuntimeError) or err.errno == errno.ELOOP
        what = (
            "a symbolic link in this path leads back to itself (a symlink loop)"
            if loop
            else f"cannot be followed ({err.strerror or err})"
        )
        raise ConfigError(where, f"{what}; name another path") from None


def _check_ancestors(path: Path, where: str) -> None:
    from mlpfac.exceptions import ConfigError

    resolved(path, where)
    for up in Path(path).absolute().parents:
        if up.exists():
            if not up.is_dir():
                raise ConfigError(where, f"{up} is a file, not a folder")
            return


class Stage:
    """The new version of ``target`` (a run folder, or with ``folder=False`` a file), written at
    ``.NAME.tmp-XXXX`` beside it (same folder, so renames are atomic). :meth:`commit` puts it in
    place; leaving the ``with`` block without a commit removes it, and the target is untouched.
    Entering also clears ``.NAME.tmp-*`` left by a killed run (a finished one renamed aside is put
    back): hold :func:`folder_lock` first."""

    def __init__(self, target: Path, what: str, folder: bool = True) -> None:
        self.target = resolved(target, f"{what} {target}")  # a symlink's folder is replaced, not the link
        self.what = what
        self.folder = folder
        self.path: Path | None = None

    def __enter__(self) -> Stage:
        from mlpfac.exceptions import ConfigError

        parent, prefix = self.target.parent, f".{self.target.name}.tmp-"
        try:
            parent.mkdir(parents=True, exist_ok=True)
            for name in os.listdir(parent):
                if name.startswith(prefix):  # a killed run's
                    _clear_staged(parent / name, self.target)
            if self.folder:
                self.path = Path(tempfile.mkdtemp(dir=parent, prefix=prefix))
                os.chmod(self.path, 0o777 & ~_umask())
            else:
                fd, tmp = tempfile.mkstemp(dir=parent, prefix=prefix)
                os.fchmod(fd, 0o666 & ~_umask())
                os.close(fd)
                self.path = Path(tmp)
        except OSError as err:
            raise ConfigError(f"{self.what} {self.target}", f"cannot write here ({err.strerror or err})") from None
        return self

    def shown(self, path: str | Path) -> str:
        """A path inside the stage, named as it will be once in place (for messages)."""
        try:
            return str(self.target / Path(path).relative_to(self.path)) if self.folder else str(self.target)
        except ValueError:
            return str(path)

    def commit(self) -> None:
        from mlpfac.exceptions import ConfigError

        with sigint_deferred():
            try:
                _replace(self.path, self.target)
            except OSError as err:
                raise ConfigError(
                    f"{self.what} {self.target}", f"cannot put the new version in place ({err.strerror or err})"
                ) from None
            self.path = None

    def __exit__(self, *exc) -> None:
        if self.path is not None:
            with sigint_deferred():
                _remove(self.path)
                self.path = None


def _remove(path: Path) -> None:
    """Best effort: a temporary that cannot be removed now is removed by the next run."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with suppress(OSError):
            path.unlink(missing_ok=True)


def _replace(new: Path, target: Path) -> None:
    """Rename ``new`` to ``target``. A folder that is not empty is exchanged with ``new`` in one
    step where the system can (Linux renameat2), else renamed aside first; the old one is deleted."""
    try:
        os.replace(new, target)  # a file; or a folder onto a missing or empty one
        return
    except OSError as err:
        if err.errno not in (errno.ENOTEMPTY, errno.EEXIST) or not new.is_dir():
            raise
    if _exchange(new, target):
        _remove(new)  # now the old folder
        return
    old = new.with_name(f"{new.name}-old")  # killed in between: the next sweep puts it back (remove_staged)
    os.rename(target, old)
    try:
        os.rename(new, target)
    except BaseException:
        os.rename(old, target)
        raise
    _remove(old)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (renameat2 RENAME_EXCHANGE); False where not supported."""
    import ctypes

    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))
