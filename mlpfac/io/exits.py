"""How the command line ends when something other than bad input stops it: a signal (also one that
failed an import it interrupted), or a write no check could foresee (stdout on a full disk, a
reader that closed it, a name too long). Each is one line on stderr and an exit code, never a
traceback.

Only the standard library: imported by the command line before anything heavy.
"""

from __future__ import annotations

import contextlib
import errno
import os
import sys

EXIT_FAILED = 1  # a run diverged, or a user's controller raised
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # Ctrl-C (SIGINT)
EXIT_TERMINATED = 143  # SIGTERM: handled like Ctrl-C
EXIT_BROKEN_PIPE = 141  # stdout closed by its reader (128 + SIGPIPE), as shell tools exit


def interrupted(err: BaseException) -> int | None:
    """The exit code of a Ctrl-C or SIGTERM that ``err`` is, or was raised while handling (MuJoCo's
    compiled module fails its import with ImportError when a signal lands as it initialises),
    said on stderr; None when ``err`` has no signal behind it."""
    from mlpfac.io.interrupts import Terminated

    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            print("mlpfac: terminated" if isinstance(err, Terminated) else "mlpfac: interrupted", file=sys.stderr)
            return EXIT_TERMINATED if isinstance(err, Terminated) else EXIT_INTERRUPTED
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return None


def failed_write(err: OSError, unnamed: str | None = None) -> int:
    """The exit code of a write that failed, said in one line naming its file (``unnamed`` when it
    names none; by default stdout when it carries a system error number, as our own writes name
    their files); stdout is then sent nowhere, so that nothing fails again at exit."""
    if err.errno != errno.EPIPE:  # a closed stdout (`| head`) is no error: what was written stays
        where = err.filename or (unnamed if unnamed is not None else "stdout" if err.errno is not None else "")
        print(f"mlpfac: error: {where + ': ' if where else ''}cannot write ({err.strerror or err})", file=sys.stderr)
    with contextlib.suppress(OSError, ValueError):
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return EXIT_BROKEN_PIPE if err.errno == errno.EPIPE else EXIT_BAD_INPUT
