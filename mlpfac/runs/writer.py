"""A short run's recording written beside the run: a child process, forked before the run's own
imports (after the figure's, :mod:`mlpfac.plots.painter`), imports rerun (:mod:`mlpfac.log`) while
this process imports MuJoCo and simulates, then takes the sink calls the run made
(:class:`~mlpfac.runs.replay.DeferredSink`), makes them on the file sink, closes it and reads the
file back (:func:`mlpfac.log.sinks.check_recording`). Where imports are slow, rerun's (about 1 s)
is then paid while the run is computed instead of after it, in a process of its own (a thread of
this one would share its interpreter lock with the run's imports).

The child takes no part in Ctrl-C (this process handles it and ends the child); a failure comes
back as the same ConfigError or OSError, naming the same file; anything else, or a child gone, and
the recording is written here. On a platform without ``fork`` it is written here.
"""

from __future__ import annotations

import pickle
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

from mlpfac.io.interrupts import ForkedChild, read_in_background


class Writer(ForkedChild):
    """The child process that writes the recording (``pid`` None: none, write it here)."""

    def __init__(self, inherited: Sequence[int] = ()) -> None:
        super().__init__(_child, inherited)

    def send(self, job: tuple) -> bool:
        """Hand the child ``(calls, recording, names, save)``; False when there is no child (any more)."""
        if self.pid is None:
            return False
        try:
            pickle.dump(job, self._send, protocol=pickle.HIGHEST_PROTOCOL)
            self._send.close()
        except (OSError, pickle.PicklingError, TypeError, AttributeError):
            self.close()
            return False
        return True

    def answer(self) -> tuple | None:
        """The child's answer (``("ok",)``, ``("config", where, what)``, ``("oserror", errno,
        strerror, filename)``), None when it could not write (then write here); the child is reaped."""
        answer = super().answer()
        return None if answer is None or answer[0] == "error" else answer


@contextmanager
def writing(wanted: bool, inherited: Sequence[int] = ()) -> Iterator[Writer | None]:
    """A :class:`Writer` while the block runs (None if not ``wanted``), its child ended after."""
    writer = Writer(inherited) if wanted else None
    try:
        yield writer
    finally:
        if writer is not None:
            writer.close()


def _child(receive_fd: int) -> tuple | None:
    """Import rerun while the job is read (a thread: the job may be larger than a pipe holds), write
    the recording; the answer (None: nothing to write)."""
    got = read_in_background(receive_fd, 1)
    from mlpfac.exceptions import ConfigError
    from mlpfac.log.sinks import check_recording
    from mlpfac.runs.folder import open_sink

    job = got.get()
    if job is None:  # nothing to write (no run, or it failed)
        return None
    calls, recording, names, save = job
    try:
        sink = open_sink(recording, names, save)
        for name, args in calls:
            getattr(sink, name)(*args)  # the sink closes at "end"
        check_recording(*save)
        return ("ok",)
    except ConfigError as err:
        return ("config", err.where, err.what)
    except OSError as err:
        return ("oserror", err.errno, err.strerror, err.filename)
    except Exception as err:  # written again in the parent, which reports it as it would have
        return ("error", repr(err))
