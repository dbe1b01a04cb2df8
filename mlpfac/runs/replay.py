"""A short run's recording saved to a file is written after the run, not during it: nobody
watches a file while it grows, and the run then neither imports rerun nor logs on its way
(rerun's import alone is about 0.25 s), which the command does while figure1 is drawn beside it.
A long run streams its recording as it goes: rerun encodes it in its own threads beside the
simulation, and a file being written shows the run is stepping.

:class:`DeferredSink` takes the sink calls of :func:`mlpfac.loop.runner.run` (begin, flush every
``FLUSH_EVERY`` steps, end) and makes them on the real sink at :meth:`DeferredSink.replay`, with
the same arguments, but for the flushes of a run that ended: its end sends every row, in one batch
per series instead of one per flush (a quarter of the writing's time), and the recording decodes
to the same data (rerun's chunks are not part of it: tests/test_log.py).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import suppress

from mlpfac.exceptions import ConfigError

DEFER_MAX_S = 60.0  # simulated seconds up to which a run's file recording is written after the run


class DeferredSink:
    """A stand-in for a file sink (see :mod:`mlpfac.log`); ``make()`` opens the real one."""

    serving = False

    def __init__(self, make: Callable[[], object], writer=None, job: tuple = ()) -> None:
        self._make = make
        self._calls: list[tuple[str, tuple]] = []
        self._sink = None
        self._replayed = False
        self._error: Exception | None = None
        self._writer, self._job, self._sent = writer, job, False  # a Writer (mlpfac.runs.writer) and its job
        self.checked = False  # the file was read back whole where it was written

    def hand_off(self) -> None:
        """The run has ended: hand its calls to the writer's process, if there is one, now."""
        if self._writer is not None and not self._sent:
            self._sent = self._writer.send((self._calls, *self._job))

    def begin(self, record, geometry=(), ref_path=None) -> None:
        self._calls.append(("begin", (record, geometry, ref_path)))

    def flush(self, record, upto: int | None = None, force: bool = False) -> None:
        self._calls.append(("flush", (record, upto, force)))

    def end(self, record) -> None:
        self._calls = [c for c in self._calls if c[0] != "flush"]  # the end sends every row, one batch per series
        self._calls.append(("end", (record,)))

    def replay(self) -> None:
        """Open the real sink and make the calls it was spared (once); the sink closes at ``end``.
        With a writer's process: its answer (the same error), or, when it could not write, here."""
        if not self._replayed and self._sent:
            answer = self._writer.answer()
            if answer is not None:
                self._replayed = True
                kind, *details = answer
                if kind == "ok":
                    self.checked = True
                else:
                    self._error = ConfigError(*details) if kind == "config" else OSError(*details)
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
        if self._writer is not None:
            self._writer.close()
        if self._sink is not None:
            self._sink.close()
