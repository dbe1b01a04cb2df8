"""SIGINT and SIGTERM as a run and a sweep meet them: SIGTERM raised like Ctrl-C (exit code 143
instead of 130), and both held back while a file or folder is being written; a child process forked
to work beside the run (:class:`ForkedChild`), which this process ends.

Only the standard library: the sweep's parent process imports this module too.
"""

from __future__ import annotations

import os
import pickle
import queue
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, suppress


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Python delivers signals: handled like Ctrl-C, but the exit code is 143."""


def _raise_terminated(signum: int, frame) -> None:
    raise Terminated()


_swallowed: list[BaseException] = []  # interrupts raised inside a __del__, which Python only reports


def _unraisable(unraisable) -> None:
    if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
        _swallowed.append(unraisable.exc_value or unraisable.exc_type())
    else:
        sys.__unraisablehook__(unraisable)


def die_with_parent(sig: int = signal.SIGKILL, parent: int | None = None) -> None:
    """Linux: this process gets ``sig`` from the kernel when its parent ends (prctl
    PR_SET_PDEATHSIG); with ``parent``, it exits at once if that parent has already ended."""
    if sys.platform.startswith("linux"):
        with suppress(OSError, AttributeError):
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, int(sig), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
    if parent is not None and os.getppid() != parent:  # it ended before the line above
        os._exit(1)


def handle_sigterm() -> None:
    """Make SIGTERM raise :class:`Terminated` (a KeyboardInterrupt) in the main thread, as SIGINT
    does, and keep an interrupt that lands in a ``__del__`` (rerun's recording streams flush in
    theirs), where Python would print it as ignored and go on: :func:`raise_swallowed` raises it."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _raise_terminated)
        sys.unraisablehook = _unraisable


def raise_swallowed() -> None:
    """Raise the interrupt a ``__del__`` swallowed since the last call, if any: called between
    steps and before a run's folder is put in place, so that no Ctrl-C or SIGTERM is lost."""
    if _swallowed:
        err = _swallowed[-1]
        _swallowed.clear()
        raise err


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


class ForkedChild:
    """A child process forked now, which runs ``work(read_fd)`` and sends back the answer it returns
    (pickled; None: nothing to answer), talking to this process through two pipes, ``_send`` and
    ``_receive``; ``pid`` None: no child (a platform where fork is not the default), the work is done
    here. The child takes no part in Ctrl-C (this process ends it), closes this process's ends and
    the ``inherited`` descriptors (the pipes of this process's other children), and exits without
    running this process's exit handlers."""

    def __init__(self, work: Callable[[int], tuple | None], inherited: Sequence[int] = ()) -> None:
        self.pid: int | None = None
        if sys.platform != "linux":  # fork is safe to use here only where it is the default
            return
        sys.stdout.flush()
        sys.stderr.flush()
        child_in, parent_out = os.pipe()  # (read end, write end)
        parent_in, child_out = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: never returns
            for fd in (parent_out, parent_in, *inherited):
                with suppress(OSError):
                    os.close(fd)
            _serve(work, child_in, child_out)
        os.close(child_in)
        os.close(child_out)
        self.pid, self._send, self._receive = pid, os.fdopen(parent_out, "wb"), os.fdopen(parent_in, "rb")

    def fds(self) -> list[int]:
        """This process's ends of the pipes to the child (for a process forked after it to close)."""
        return [] if self.pid is None else [self._send.fileno(), self._receive.fileno()]

    def answer(self):
        """The child's answer (what its work returned), None when there is none (it failed, or is
        gone); the child is reaped."""
        try:
            answer = pickle.load(self._receive)
        except (OSError, EOFError, pickle.UnpicklingError):
            answer = None
        self.close()
        return answer

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


def read_in_background(receive_fd: int, count: int) -> queue.Queue:
    """The messages a :class:`ForkedChild`'s work is sent, read by a thread while the work goes on
    (imports; a message may be larger than a pipe holds): a queue that gets up to ``count`` of
    them, then None if the pipe closed (or a message could not be read) before the last: the work
    waiting for one is never left waiting."""
    got: queue.Queue = queue.Queue()

    def read() -> None:
        try:
            with os.fdopen(receive_fd, "rb") as f:
                for _ in range(count):
                    got.put(pickle.load(f))
        except Exception:  # noqa: BLE001 - nothing (more) to read: no run, it failed, the pipe broke
            got.put(None)

    threading.Thread(target=read, name="mlpfac-child-read", daemon=True).start()
    return got


def _serve(work: Callable[[int], tuple | None], receive_fd: int, send_fd: int) -> None:
    """The forked child: ``work``, its answer sent back, then exit (never returns)."""
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        answer = work(receive_fd)
        if answer is not None:
            with os.fdopen(send_fd, "wb") as f:
                pickle.dump(answer, f)
    except BaseException:
        code = 1
    finally:
        os._exit(code)
