"""Executing a plan: skip what is done, run the rest here, in a local pool or on Dask, write as results come."""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.exceptions import ConfigError, WorkerLostError
from mlpfac.io.files import check_run_folder, folder_lock, remove_staged
from mlpfac.io.interrupts import Terminated, raise_swallowed, sigint_deferred
from mlpfac.loop.metrics import RunMetrics
from mlpfac.sweeps.folders import _oserror, check_done, write_result
from mlpfac.sweeps.plan import Job
from mlpfac.sweeps.worker import _worker_init, pool_context, run_task, worker_environment

TMP_DIR = ".tmp"  # OUT/.tmp: recordings being made; removed when the sweep ends and when the next one starts
EXIT_GRACE_S = 15.0  # how long a finished worker may take to exit before it is killed
POLL_S = 0.2  # the longest a Ctrl-C or SIGTERM waits while a local pool is waited on


@dataclass
class Outcome:
    """What a sweep produced: the metrics of every whole run, in plan order, and the failures."""

    jobs: list[Job]
    metrics: dict[tuple, RunMetrics]
    errors: dict[tuple, str]
    skipped: int
    ran: int
    interrupted: bool = False
    terminated: bool = False  # the interruption was a SIGTERM
    wall_s: float = 0.0
    redo: dict[str, int] = field(default_factory=dict)  # why folders found were not done -> how many
    cached: int = 0  # runs of ``limit`` taken from the cache of computed limits (mlpfac.sweeps.limits)


def make_tasks(jobs: list[Job], batched: bool, batch_size: int) -> list[list[Job]]:
    """One job per task, or with ``batched`` up to ``batch_size`` seeds of one scenario and controller
    (a run whose scenario draws per seed is a robot of its own: a task of its own)."""
    if not batched:
        return [[j] for j in jobs]
    groups: dict[tuple, list[Job]] = {}
    for j in jobs:
        groups.setdefault((j.scenario, j.controller, j.seed if j.drawn else None), []).append(j)
    return [g[i : i + batch_size] for g in groups.values() for i in range(0, len(g), batch_size)]


def execute(
    jobs: list[Job],
    out: Path,
    workers: int = 1,
    client=None,
    batched: bool = False,
    batch_size: int = 64,
    save_rrd: bool = False,
    progress: bool | None = None,
    on_result: Callable[[dict], None] | None = None,
    locked: bool = False,
    cache=None,
) -> Outcome:
    """Run the jobs not done yet; write each run's folder as its result arrives.

    ``client`` is a ``dask.distributed.Client`` or None (local). ``progress``: None shows a bar
    only when stderr is a terminal. KeyboardInterrupt (Ctrl-C, or SIGTERM as
    :class:`~mlpfac.io.interrupts.Terminated`) stops the workers and returns with ``interrupted=True``;
    every folder written so far is whole. ``out`` is locked for the sweep (``folder_lock``) unless
    the caller holds the lock (``locked``); recordings are made in ``out/.tmp``, which is removed at
    the end and, left by a killed sweep, at the start. A failed write raises :class:`OutputError`.
    ``cache`` (a :class:`~mlpfac.sweeps.limits.LimitCache`): ``limit``'s runs are taken from it where
    it holds them (written into ``out`` as if run) and kept in it when run.
    """
    with contextlib.ExitStack() as stack:
        if not locked:
            stack.enter_context(folder_lock(out, "--out"))
        try:
            return _execute(jobs, out, workers, client, batched, batch_size, save_rrd, progress, on_result, cache)
        except OSError as err:
            raise _oserror(err, str(out)) from None


class _SigtermSeen:
    """Notes a SIGTERM before the installed handler sees it: a run in this process turns any
    interruption into its own KeyboardInterrupt, so the exit code would say Ctrl-C."""

    def __init__(self) -> None:
        import signal
        import threading

        self.seen = False
        self.previous = None
        if threading.current_thread() is threading.main_thread():
            previous = signal.getsignal(signal.SIGTERM)
            if callable(previous):  # mlpfac.cli made SIGTERM raise Terminated
                self.previous = previous

                def note(signum, frame):
                    self.seen = True
                    previous(signum, frame)

                signal.signal(signal.SIGTERM, note)

    def restore(self) -> None:
        import signal

        if self.previous is not None:
            signal.signal(signal.SIGTERM, self.previous)
            self.previous = None


def _execute(jobs, out, workers, client, batched, batch_size, save_rrd, progress, on_result, cache=None) -> Outcome:
    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / TMP_DIR
    shutil.rmtree(tmp, ignore_errors=True)  # what a killed sweep left; we hold the lock
    remove_staged(d for d in out.glob("*/*") if d.is_dir())
    done: dict[tuple, dict] = {}
    todo: list[Job] = []
    redo: dict[str, int] = {}
    cached = 0
    for j in jobs:
        m, why = check_done(out, j, save_rrd)
        if m is None and os.path.lexists(j.folder(out)):  # replaced whole: nothing but a run's files in it
            check_run_folder(j.folder(out), "run folder")
        if m is None and cache is not None and j.controller == cache.controller and not save_rrd:
            m = cache.lookup(j)
            if m is not None:
                write_result(out, j, {"metrics": m, "error": None})
                cached += 1
        if m is None:
            todo.append(j)
            if why is not None:
                redo[why] = redo.get(why, 0) + 1
        else:
            done[j.key] = RunMetrics.from_json(m)
    outcome = Outcome(jobs, done, {}, skipped=len(done) - cached, ran=0, redo=redo, cached=cached)
    by_key = {j.key: j for j in todo}
    tasks = make_tasks(todo, batched, batch_size)
    bar = _progress(len(todo), progress)
    failed = 0
    results: Iterator[list[dict]] | None = None
    sigterm = _SigtermSeen()
    try:
        if save_rrd and client is None:
            tmp.mkdir(exist_ok=True)
        tmp_dir = str(tmp) if client is None else None  # Dask workers record in their own temporary folder
        if client is not None:
            results = _dask_results(client, tasks, batched, save_rrd)
        elif workers <= 1 or len(tasks) <= 1:
            results = (run_task(t, batched, save_rrd, tmp_dir) for t in tasks)
        else:
            results = _pool_results(tasks, workers, batched, save_rrd, tmp_dir)
        for res_list in results:
            raise_swallowed()  # a Ctrl-C that landed in a __del__ stops the sweep all the same
            for res in res_list:
                job = by_key[res["key"]]
                write_result(out, job, res)
                outcome.ran += 1
                if res["error"] is not None:
                    outcome.errors[job.key] = res["error"]
                    failed += 1
                else:
                    outcome.metrics[job.key] = RunMetrics.from_json(res["metrics"])
                    failed += res["metrics"]["status"] != "ok"
                    if cache is not None and job.controller == cache.controller:
                        cache.store(job, res["metrics"])
                if on_result is not None:
                    on_result(res)
                if bar is not None:
                    bar.set_postfix_str(f"failed {failed}", refresh=False)
                    bar.update(1)
    except KeyboardInterrupt as err:
        outcome.interrupted = True
        outcome.terminated = isinstance(err, Terminated) or sigterm.seen
    finally:
        sigterm.restore()
        with sigint_deferred():  # the workers stop and the temporary files go, whatever comes now
            if results is not None and hasattr(results, "close"):
                results.close()  # stops the pool or cancels the Dask futures now, not when collected
            if bar is not None:
                bar.close()
            shutil.rmtree(tmp, ignore_errors=True)
    outcome.metrics = {j.key: outcome.metrics[j.key] for j in jobs if j.key in outcome.metrics}
    outcome.wall_s = time.perf_counter() - t0
    return outcome


def _progress(total: int, progress: bool | None):
    if progress is False or total == 0:
        return None
    from tqdm import tqdm

    return tqdm(
        total=total, unit="run", desc="runs", disable=None if progress is None else not progress, dynamic_ncols=True
    )


def _pool_results(
    tasks: list[list[Job]], workers: int, batched: bool, save_rrd: bool, tmp_dir: str | None = None
) -> Iterator[list[dict]]:
    """Results of ``tasks`` from a local process pool, as they finish; at most 2 tasks per worker in flight.

    Workers are forked from a warm fork server (:func:`~mlpfac.sweeps.worker.pool_context`: no copy
    of this process's threads or BLAS state), run with one BLAS thread each, and die with this
    process. Closing the generator (or an exception in it) kills the workers: a run being computed
    is lost, its folder never written.

    A Ctrl-C or SIGTERM is held while this thread is inside the pool's calls (``cf.wait`` in slices
    of POLL_S, ``submit``, the shutdown) and raised between them: raised inside, it can leave a
    future's lock taken (``cf.wait`` takes them one by one), and the pool's thread then waits for
    that lock forever, and the sweep with it (seen on a loaded machine).
    """
    import concurrent.futures as cf
    import multiprocessing as mp
    from concurrent.futures.process import BrokenProcessPool

    before = set(mp.active_children())
    with worker_environment():
        pool = cf.ProcessPoolExecutor(
            max_workers=min(workers, len(tasks)),
            mp_context=pool_context(),
            initializer=_worker_init,
            initargs=(os.getpid(), dict(os.environ)),
        )
    pending: set[cf.Future] = set()
    queue = iter(tasks)

    def submit(t: list[Job]) -> None:
        with worker_environment(), sigint_deferred():  # the pool starts its workers as tasks are submitted
            pending.add(pool.submit(run_task, t, batched, save_rrd, tmp_dir))

    try:
        for t in queue:
            submit(t)
            if len(pending) >= 2 * workers:
                break
        while pending:
            with sigint_deferred():  # Ctrl-C / SIGTERM come between the pool's calls, not inside them (see below)
                finished, pending = cf.wait(pending, timeout=POLL_S, return_when=cf.FIRST_COMPLETED)
            for f in finished:
                res = f.result()
                nxt = next(queue, None)
                if nxt is not None:
                    submit(nxt)
                yield res
        thread = _pool_thread(pool)
        pool.shutdown(wait=False)
        for p in set(mp.active_children()) - before:  # a worker whose recording hung cannot exit cleanly
            p.join(EXIT_GRACE_S)
            if p.is_alive():
                p.kill()
        with sigint_deferred():
            _join(thread)
    except BaseException as err:  # also GeneratorExit: the consumer stopped
        workers_now = set(mp.active_children()) - before
        for p in workers_now:  # this pool's workers: they ignore SIGINT and SIGTERM
            p.kill()
        with sigint_deferred():
            for p in workers_now:
                p.join(EXIT_GRACE_S)  # killed: at once, unless the machine is swamped
            _end_result_pipe(pool)
            thread = _pool_thread(pool)
            # its thread sees the workers gone, fails every future left and ends; a future cancelled
            # here would make it raise instead (Python 3.11 sets the failure on a cancelled one too)
            pool.shutdown(wait=False)
            _join(thread)
        if isinstance(err, BrokenProcessPool):  # seen by a result or by a submit, whichever comes first
            raise WorkerLostError(
                "a worker process died (killed from outside, or out of memory: see `dmesg`); "
                "the runs it was computing were not written"
            ) from None
        raise


def _end_result_pipe(pool) -> None:
    """Close this process's copy of the write end of the pool's result pipe, once its workers are
    dead. A worker killed while it sent a result leaves half a message in the pipe; the pool's
    thread, reading it, would wait for the rest forever, and the interpreter's exit for that thread
    (seen on a loaded machine: a stopped sweep that never exits). With no writer left, the read ends
    and the thread finds the pool broken and stops."""
    writer = getattr(getattr(pool, "_result_queue", None), "_writer", None)
    if writer is not None:
        with contextlib.suppress(OSError):
            writer.close()


def _pool_thread(pool):
    """The pool's thread (None before its first task), taken before ``shutdown``, which forgets it."""
    return getattr(pool, "_executor_manager_thread", None)


def _join(thread) -> None:
    """Wait for the pool's thread to end (EXIT_GRACE_S at most), once its workers are gone. A thread
    still ending when the interpreter exits races Python's own wake-up of it at exit
    (concurrent.futures writes to a pipe that the thread is closing: "Exception ignored in: <module
    'threading'> ... OSError: [Errno 9] Bad file descriptor" after the sweep's last line, about 1 in
    25 SIGTERMs); with it ended, the command exits with no thread of the pool's left to wake."""
    if thread is not None:
        thread.join(EXIT_GRACE_S)


def _dask_results(client, tasks: list[list[Job]], batched: bool, save_rrd: bool) -> Iterator[list[dict]]:
    """Results from a Dask cluster. A lost worker's tasks are rescheduled by the scheduler; ``retries``
    covers a task that failed in transit. Results come back to this process, which writes them."""
    from dask.distributed import as_completed

    futures = [client.submit(run_task, t, batched, save_rrd, pure=False, retries=2) for t in tasks]
    try:
        for f in as_completed(futures):
            yield f.result()
            f.release()
    except BaseException:
        client.cancel(futures)
        raise


def connect(address: str, timeout: float = 10.0):
    """A Dask client of the scheduler at ``address``; ConfigError if it cannot be reached in ``timeout`` s."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise ConfigError("--scheduler", "needs dask[distributed]: pip install 'mlpfac[dask]'") from None
    import threading

    got: dict = {}

    def attempt() -> None:  # in a thread: an address that accepts and never answers may hang Dask's handshake
        try:
            got["client"] = Client(address, timeout=timeout)
        except BaseException as err:
            got["error"] = err

    t = threading.Thread(target=attempt, name="mlpfac-dask-connect", daemon=True)
    t.start()
    t.join(timeout)
    err = got.get("error")
    if "client" in got:
        return got["client"]
    if err is not None and not isinstance(err, OSError | TimeoutError | ValueError):
        raise err
    msg = (str(err).splitlines()[0] if str(err) else type(err).__name__) if err is not None else "no answer"
    raise ConfigError("--scheduler", f"cannot reach a Dask scheduler at {address} within {timeout:g} s ({msg})")
