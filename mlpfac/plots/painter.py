"""Figure 1 drawn beside the run: a child process, forked before the run's own imports, imports
matplotlib and does its first-figure work while this process imports MuJoCo and simulates, makes
and draws the figure from the run's record while this process runs the baseline, and adds the
baseline's panel when its record arrives. On a platform without ``fork`` (or if the child is
gone) the figure is drawn here.

The child takes no part in Ctrl-C (this process handles it and closes the pipe, which ends the
child); an error writing the figure comes back as the same OSError, naming the same file.
"""

from __future__ import annotations

import gc
import pickle
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from functools import partial
from pathlib import Path

from mlpfac.io.interrupts import ForkedChild, die_with_parent, read_in_background


class Painter(ForkedChild):
    """``figure1`` of :mod:`mlpfac.plots.figure1`, drawn by a child process started now: the run's
    record is sent as soon as the run ends (:meth:`begin`), so that the child makes the figure while
    this process runs the baseline, whose record completes it (:meth:`finish`)."""

    def __init__(self) -> None:
        from mlpfac.plots.mplconfig import quiet_config

        quiet_config()  # before the child starts: it inherits the environment
        self.meanwhile: list[Callable[[], None]] = []  # done here while the child draws
        self._begun: tuple | None = None
        self._sender: threading.Thread | None = None
        self._sent_ok = True
        super().__init__(_child)

    def begin(self, rec, path: Path, h: bool) -> None:
        """The run's record, to be drawn to ``path``; ``h``: a panel (h) is expected (the baseline is
        another law)."""
        self._begun = (rec, path)
        if self.pid is not None:  # sent by a thread: the child reads it while it imports
            self._sender = threading.Thread(target=self._dump, args=((rec, path, h),), daemon=True)
            self._sender.start()

    def _dump(self, message) -> None:
        try:
            pickle.dump(message, self._send, protocol=pickle.HIGHEST_PROTOCOL)
            self._send.flush()
        except (OSError, ValueError):  # the child is gone (or the pipe closed): finish draws here
            self._sent_ok = False

    def finish(self, baseline) -> list[str]:
        """Write the figure begun with ``baseline`` for panel (h); the panels drawn (as
        :func:`mlpfac.plots.figure1.figure1`)."""
        rec, path = self._begun
        if self._sender is not None:
            self._sender.join()
        if self.pid is not None and self._sent_ok:
            with suppress(OSError):  # the child is gone: no answer, the figure is drawn here
                pickle.dump(baseline, self._send, protocol=pickle.HIGHEST_PROTOCOL)
                self._send.close()
            self._do_meanwhile()
            answer = self.answer()
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
    """Import matplotlib and warm it up; make and draw the figure from the run's record (one column
    here, the other in a process forked from this one), complete it with the baseline's panel; the
    answer ("ok", panels), ("oserror", errno, strerror, filename) or ("error", text), None when
    nothing (or not all) arrives."""
    got = read_in_background(receive_fd, 2)  # the run's record, then the baseline's
    from mlpfac.plots.figure1 import Draft, h_column, warm_up

    gc.disable()  # a process that ends with the figure: its garbage goes with it (the collector took a fifth of the figure's time)
    warm_up()  # matplotlib's first-figure work, done before the records arrive
    begun = got.get()
    if begun is None:
        return None
    rec, path, h = begun
    column = h_column(rec, h)
    rest = ForkedChild(partial(_column, rec, h, 1 - column), (receive_fd,))  # warm, as this one
    try:
        draft = Draft(rec, h, column, title=False)
        draft.draw()  # this column but (h), while the baseline runs
        baseline = got.get()
        if baseline is None:
            return None
        return ("ok", draft.finish(baseline, path, rest.answer))
    except OSError as err:
        return ("oserror", err.errno, err.strerror, err.filename)
    except Exception as err:  # drawn again in the parent, which reports it as it would have
        return ("error", repr(err))
    finally:
        rest.close()


def _column(rec, h: bool, column: int, _receive_fd: int):
    """The pixels of Figure 1's ``column`` with the title (a process forked from the painter's)."""
    from mlpfac.plots.figure1 import Draft

    die_with_parent()
    draft = Draft(rec, h, column)
    draft.draw()
    return draft.pixels()
