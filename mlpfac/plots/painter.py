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
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from mlpfac.interrupts import ForkedChild


class Painter(ForkedChild):
    """``figure1`` of :mod:`mlpfac.plots.figure1`, drawn by a child process started now."""

    def __init__(self) -> None:
        from mlpfac.plots.mplconfig import quiet_config

        quiet_config()  # before the child starts: it inherits the environment
        self.meanwhile: list[Callable[[], None]] = []  # done here while the child draws
        super().__init__(_child)

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


@contextmanager
def painting(wanted: bool) -> Iterator[Painter | None]:
    """A :class:`Painter` while the block runs (None if no figure is ``wanted``), its child ended after."""
    painter = Painter() if wanted else None
    try:
        yield painter
    finally:
        if painter is not None:
            painter.close()


def _child(receive_fd: int) -> tuple | None:
    """Import matplotlib and warm it up, draw what arrives; the answer ("ok", panels), ("oserror",
    errno, strerror, filename) or ("error", text), None when nothing arrives."""
    from mlpfac.plots.figure1 import figure1, warm_up

    warm_up()  # matplotlib's first-figure work, done before the records arrive

    with os.fdopen(receive_fd, "rb") as f:
        try:
            rec, baseline, path = pickle.load(f)
        except EOFError:  # nothing to draw (no run, or it failed)
            return None
    try:
        return ("ok", figure1(rec, baseline, path))
    except OSError as err:
        return ("oserror", err.errno, err.strerror, err.filename)
    except Exception as err:  # drawn again in the parent, which reports it as it would have
        return ("error", repr(err))
