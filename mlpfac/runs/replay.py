"""A short run's recording saved to a file is written after the run, not during it: nobody
watches a file while it grows, and the run then neither imports rerun nor logs on its way
(rerun's import alone is about 0.25 s), which the command does while figure1 is drawn beside it.
A long run streams its recording as it goes: rerun encodes it in its own threads beside the
simulation, and a file being written shows the run is stepping.

:class:`DeferredSink` takes the sink calls of :func:`mlpfac.loop.runner.run` (begin, flush every
``FLUSH_EVERY`` steps, end) and makes them on the real sink at :meth:`DeferredSink.replay`, with
the same arguments: rows are written once, so the rows up to each flush are the same then as
they were when it was called, and the recording holds the same data.
"""

from __future__ import annotations

import importlib
import sys
import threading
from collections.abc import Callable
from contextlib import suppress

DEFER_MAX_S = 60.0  # simulated seconds up to which a run's file recording is written after the run


class DeferredSink:
    """A stand-in for a file sink (see :mod:`mlpfac.log`); ``make()`` opens the real one."""

    serving = False

    def __init__(self, make: Callable[[], object]) -> None:
        self._make = make
        self._calls: list[tuple[str, tuple]] = []
        self._sink = None
        self._replayed = False
        self._error: Exception | None = None

    def begin(self, record, geometry=(), ref_path=None) -> None:
        self._calls.append(("begin", (record, geometry, ref_path)))

    def flush(self, record, upto: int | None = None, force: bool = False) -> None:
        self._calls.append(("flush", (record, upto, force)))

    def end(self, record) -> None:
        self._calls.append(("end", (record,)))

    def replay(self) -> None:
        """Open the real sink and make the calls it was spared (once); the sink closes at ``end``."""
        if not self._replayed:
            self._replayed = True
            try:
                self._sink = self._make()
                if self._sink is not None:
                    for name, args in self._calls:
                        getattr(self._sink, name)(*args)
            except Exception as err:  # raised now and by every later call
                self._error = err
        if self._error is not None:
            raise self._error

    def replay_quietly(self) -> None:
        """:meth:`replay`, keeping an error for the next call of :meth:`replay` (which raises it)."""
        with suppress(Exception):
            self.replay()

    def close(self) -> None:
        if self._sink is not None:
            self._sink.close()


def import_beside(name: str) -> None:
    """Start importing module ``name`` in a daemon thread, so that a short run's recording, written
    after the run, finds rerun imported: the import (about 0.25 s, 1 s where imports are slow) then
    overlaps the run's own imports and its simulation, whose compiled kernels release the GIL. Start
    it only after any fork (a child forked while a thread imports could inherit a held import lock);
    a failed import is met again, and said, where the module is used."""
    if name in sys.modules:
        return

    def load() -> None:
        with suppress(BaseException):
            importlib.import_module(name)

    threading.Thread(target=load, name=f"import {name}", daemon=True).start()
