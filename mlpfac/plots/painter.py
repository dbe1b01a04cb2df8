"""Figure 1 drawn beside the run: a child process, forked before the run's own imports, imports
matplotlib and does its first-figure work while this process imports MuJoCo and simulates, then
draws the records it is sent. On a platform without ``fork`` (or if the child is gone) the figure
is drawn here.

The child takes no part in Ctrl-C (this process handles it and closes the pipe, which ends the
child); an error writing the figure comes back as the same OSError, naming the same file.
"""

from __future__ import annotations

import os
import pickle
import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path


class Painter:
    """``figure1`` of :mod:`mlpfac.plots.figure1`, drawn by a child process started now."""

    def __init__(self) -> None:
        from mlpfac.plots.mplconfig import quiet_config

        quiet_config()  # before the child starts: it inherits the environment
        self.pid: int | None = None
        self.meanwhile: list[Callable[[], None]] = []  # done here while the child draws
        if sys.platform != "linux":  # fork is safe to use here only where it is the default
            return
        sys.stdout.flush()
        sys.stderr.flush()
        child_in, parent_out = os.pipe()  # (read end, write end)
        parent_in, child_out = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: never returns
            os.close(parent_out)
            os.close(parent_in)
            _child(child_in, child_out)
        os.close(child_in)
        os.close(child_out)
        self.pid, self._send, self._receive = pid, os.fdopen(parent_out, "wb"), os.fdopen(parent_in, "rb")

    def fds(self) -> list[int]:
        """This process's ends of the pipes to the child (for a process forked after it to close)."""
        return [] if self.pid is None else [self._send.fileno(), self._receive.fileno()]

    def figure1(self, rec, baseline, path: Path) -> list[str]:
        """Write Figure 1 to ``path``; the panels drawn (as :func:`mlpfac.plots.figure1.figure1`)."""
        if self.pid is not None:
            try:
                pickle.dump((rec, baseline, path), self._send, protocol=pickle.HIGHEST_PROTOCOL)
                self._send.close()
                self._do_meanwhile()
                answer = pickle.load(self._receive)
            except (OSError, EOFError, pickle.UnpicklingError):
                answer = None  # the child is gone: draw here
            self.close()
            if answer is not None:
                kind, *details = answer
                if kind == "oserror":
                    raise OSError(*details)
                if kind == "ok":
                    return details[0]
        from mlpfac.plots.figure1 import figure1

        self._do_meanwhile()
        return figure1(rec, baseline, path)

    def _do_meanwhile(self) -> None:
        jobs, self.meanwhile = self.meanwhile, []
        for job in jobs:
            job()

    def close(self) -> None:
        """End the child (if it still runs) and reap it."""
        if self.pid is None:
            return
        pid, self.pid = self.pid, None
        for f in (self._send, self._receive):
            with suppress(OSError):
                f.close()
        with suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)


@contextmanager
def painting(wanted: bool) -> Iterator[Painter | None]:
    """A :class:`Painter` while the block runs (None if no figure is ``wanted``), its child ended after."""
    painter = Painter() if wanted else None
    try:
        yield painter
    finally:
        if painter is not None:
            painter.close()


def _child(receive_fd: int, send_fd: int) -> None:
    """Import matplotlib and warm it up, draw what arrives, answer ("ok", panels), ("oserror",
    errno, strerror, filename) or ("error", text), and exit without running the parent's exit
    handlers."""
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        from mlpfac.plots.figure1 import figure1, warm_up

        warm_up()  # matplotlib's first-figure work, done before the records arrive

        with os.fdopen(receive_fd, "rb") as f:
            try:
                rec, baseline, path = pickle.load(f)
            except EOFError:  # nothing to draw (no run, or it failed)
                os._exit(0)
        try:
            answer: tuple = ("ok", figure1(rec, baseline, path))
        except OSError as err:
            answer = ("oserror", err.errno, err.strerror, err.filename)
        except Exception as err:  # drawn again in the parent, which reports it as it would have
            answer = ("error", repr(err))
        with os.fdopen(send_fd, "wb") as f:
            pickle.dump(answer, f)
    except BaseException:
        code = 1
    finally:
        os._exit(code)
