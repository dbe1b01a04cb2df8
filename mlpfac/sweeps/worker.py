"""One task in this process, a local pool worker or a Dask worker: runs -> metrics (and recordings)."""

from __future__ import annotations

import contextlib
import json
import os
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from multiprocessing import context as mp_context
from pathlib import Path

from mlpfac.sweeps.plan import Job

POOL_TMP_VARIABLE = "MLPFAC_POOL_TMP"
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def run_task(jobs: list[Job], batched: bool = False, save_rrd: bool = False, tmp_dir: str | None = None) -> list[dict]:
    """Run ``jobs`` (one, or seeds of one scenario and controller when ``batched``).

    Returns one result per job: {"key", "metrics", "rrd" (bytes or None), "error" (str or None)}.
    Recordings are made in ``tmp_dir`` (OUT/.tmp for a local sweep; the system's temporary folder
    on a Dask worker). An interrupted run raises KeyboardInterrupt: it must never be written as done.
    """
    from mlpfac.loop.metrics import metrics
    from mlpfac.scenario.parse import parse

    if batched and len(jobs) > 1 and not save_rrd:
        from mlpfac.loop.runner import run_batch

        try:
            scns = [parse(j.table, j.source) for j in jobs]
            if scns[0].plugin is not None and not scns[0].plugin.batched:  # no batch form: seed by seed
                return [_run_one(j, save_rrd, tmp_dir) for j in jobs]
            recs = run_batch(scns)
        except KeyboardInterrupt:
            raise
        except Exception as err:  # a bug, not a divergence: report it per run
            return [{"key": j.key, "metrics": None, "rrd": None, "error": _error_text(err)} for j in jobs]
        return [
            {"key": j.key, "metrics": metrics(r), "rrd": None, "error": None} for j, r in zip(jobs, recs, strict=True)
        ]
    return [_run_one(j, save_rrd, tmp_dir) for j in jobs]


def _run_one(job: Job, save_rrd: bool, tmp_dir: str | None = None) -> dict:
    from mlpfac.loop.metrics import metrics
    from mlpfac.loop.runner import run
    from mlpfac.scenario.parse import parse

    rrd_path = sink = None
    try:
        scn = parse(job.table, job.source)
        if save_rrd:
            sink, rrd_path = _make_sink(job, tmp_dir)
        rec = run(scn, sink=sink)
        if rec.status == "interrupted":
            raise KeyboardInterrupt
        rrd = None
        if rrd_path is not None:
            rrd = rrd_path.read_bytes() if rrd_path.exists() else b""
            if not rrd_is_whole(rrd):
                raise OSError(
                    f"the recording is not whole ({len(rrd)} bytes, no rerun footer): "
                    "was the disk full? see the rerun messages above"
                )
        return {"key": job.key, "metrics": metrics(rec), "rrd": rrd, "error": None}
    except KeyboardInterrupt:
        raise
    except Exception as err:
        return {"key": job.key, "metrics": None, "rrd": None, "error": _error_text(err)}
    finally:
        if rrd_path is not None:
            rrd_path.unlink(missing_ok=True)


def rrd_is_whole(data: bytes) -> bool:
    """A rerun file that was closed: the stream header at the start, the footer magic at the end.

    A file cut by a full disk or a killed writer has no footer (rerun writes it when the sink closes).
    """
    return len(data) >= 16 and data[:4] == b"RRF2" and data[-12:-4] == b"RRF2FOOT"


def _make_sink(job: Job, tmp_dir: str | None = None):
    """A rerun sink saving to a temporary file (its bytes go back to the client); (None, None) without mlpfac.log."""
    try:
        from mlpfac import log
    except ImportError:
        return None, None
    fd, tmp = tempfile.mkstemp(suffix=".rrd", prefix="mlpfac-", dir=tmp_dir)
    os.close(fd)
    path = Path(tmp)
    try:
        sink = log.make_sink(
            save=path,
            recording_name=f"{job.scenario} / {job.controller} / seed {job.seed}",
            recording_id=f"{job.scenario}-{job.controller}-{job.seed}",
        )
    except BaseException:
        path.unlink(missing_ok=True)
        raise
    return sink, path


def _error_text(err: BaseException) -> str:
    """What error.txt holds: a user's controller's own traceback, or the whole one (a bug of ours)."""
    import traceback

    from mlpfac.exceptions import PluginError

    return err.report() if isinstance(err, PluginError) else "".join(traceback.format_exception(err))


def pool_context():
    """The multiprocessing context of a local pool: workers forked from a fork server that imported
    :mod:`mlpfac.sweeps.warm` once (started by the first pool, with its environment, and kept for
    the next ones; a fresh interpreter, no copy of this process's threads or BLAS state), or
    spawned where there is no fork server. Either way a worker does not run the user's script again
    (see :func:`_launch_without_main`): a sweep started at a script's top level, from stdin, ``python -c``
    or a notebook needs no ``if __name__ == "__main__":``."""
    import multiprocessing as mp
    from multiprocessing import util

    if "forkserver" not in mp.get_all_start_methods():
        return _SpawnContext()
    ctx = _ForkServerContext()
    ctx.set_forkserver_preload(["mlpfac.sweeps.warm"])
    # the folder of the fork server's socket, which the fork server removes when it ends (also
    # after this process was killed, when its workers have gone): see mlpfac.sweeps.warm
    os.environ[POOL_TMP_VARIABLE] = f"{os.getpid()}:{util.get_temp_dir()}"
    return ctx


MAIN_KEYS = ("init_main_from_name", "init_main_from_path")  # how a child of multiprocessing runs __main__
_MAIN_LOCK = threading.Lock()


def _launch_without_main(launch, process_obj) -> None:
    """A process started by ``launch`` (a Popen's) with preparation data that names no ``__main__``.

    A child of multiprocessing's spawn and forkserver methods runs the parent's script (or ``-m``
    module) again as ``__mp_main__``, so that what it defines can be unpickled. A sweep's workers
    are handed plain data and mlpfac's own functions only, and a script run again would start its
    sweep again in every worker (unguarded, multiprocessing refuses and the pool breaks). A user's
    controller class is imported by its name, as ever (:mod:`mlpfac.control.plugins`)."""
    from multiprocessing import spawn

    with _MAIN_LOCK:
        made = spawn.get_preparation_data
        spawn.get_preparation_data = lambda name: {k: v for k, v in made(name).items() if k not in MAIN_KEYS}
        try:
            launch(process_obj)
        finally:
            spawn.get_preparation_data = made


def _no_main(popen: type) -> type:
    class NoMain(popen):
        def _launch(self, process_obj) -> None:
            _launch_without_main(super()._launch, process_obj)

    return NoMain


class _ForkServerProcess(mp_context.ForkServerProcess):
    """A fork server's process that does not run the parent's ``__main__`` (:func:`_launch_without_main`)."""

    @staticmethod
    def _Popen(process_obj):
        from multiprocessing.popen_forkserver import Popen

        return _no_main(Popen)(process_obj)


class _SpawnProcess(mp_context.SpawnProcess):
    """A spawned process that does not run the parent's ``__main__`` (:func:`_launch_without_main`)."""

    @staticmethod
    def _Popen(process_obj):
        if os.name == "nt":
            from multiprocessing.popen_spawn_win32 import Popen
        else:
            from multiprocessing.popen_spawn_posix import Popen
        return _no_main(Popen)(process_obj)


class _ForkServerContext(mp_context.ForkServerContext):
    Process = _ForkServerProcess


class _SpawnContext(mp_context.SpawnContext):
    Process = _SpawnProcess


SYS_PATH = "MLPFAC_SYS_PATH"  # this process's sys.path, which a fork server's workers take (mlpfac.sweeps.warm)


@contextlib.contextmanager
def worker_environment() -> Iterator[None]:
    """Worker processes started in this block run BLAS on one thread each (unless the user set the
    variables): N workers on N cores with multi-threaded BLAS are several times slower than their sum.
    They import mlpfac as this process did: the fork server starts without the current folder on its
    path (``PYTHONSAFEPATH``: a folder named ``mlpfac`` there, such as another checkout, would be
    imported in place of the installed package, which this process runs), and its workers take this
    process's ``sys.path`` (multiprocessing's fork server does not pass it) for the user's modules."""
    values = dict.fromkeys(BLAS_THREAD_VARIABLES, "1") | {"PYTHONSAFEPATH": "1", SYS_PATH: json.dumps(sys.path)}
    added = [v for v in values if v not in os.environ]
    try:
        for v in added:
            os.environ[v] = values[v]
        yield
    finally:
        for v in added:
            os.environ.pop(v, None)


def start_pool_server() -> None:
    """Start the fork server of :func:`pool_context` now, with one BLAS thread: it imports and warms
    up while this process plans the sweep."""
    if pool_context().get_start_method() == "forkserver":
        from multiprocessing import forkserver

        with worker_environment():
            forkserver.ensure_running()


IN_WORKER = "MLPFAC_SWEEP_WORKER"  # set in a local pool's workers


def not_in_a_worker(what: str) -> None:
    """A script whose class a sweep's workers import (``path/to/script.py:Class``, also a class
    given to the API by the script that calls it) is run by each of them: a call of the API at its
    top level would start runs, or pools of workers, in every worker. There, while the script is
    imported, the call raises :class:`~mlpfac.exceptions.ScriptStopped`, which ends the import with
    what the script defined above the call (:mod:`mlpfac.control.plugins`); anywhere else in a worker (a
    controller that calls it) it is an MlpfacError, that run's error."""
    if os.environ.get(IN_WORKER):
        from mlpfac.control import plugins
        from mlpfac.exceptions import MlpfacError, ScriptStopped

        if plugins.IMPORTING:
            raise ScriptStopped(f"mlpfac.{what}")
        raise MlpfacError(f"mlpfac.{what} was called in a sweep worker: a controller cannot start runs")


def _worker_init(parent: int, environ: dict[str, str] | None = None) -> None:
    """Pool workers leave Ctrl-C and SIGTERM to the parent (the sweep's process), which stops them
    (a half run is never returned), and die with it: a killed sweep leaves no worker behind. A
    worker forked by the fork server watches the sweep's process and dies with the fork server.
    ``environ``: the sweep's environment now (the fork server has the one it was started with)."""
    import signal
    import tempfile

    if environ is not None:
        os.environ.clear()
        os.environ.update(environ)
        tempfile.tempdir = None  # found again from TMPDIR
    os.environ[IN_WORKER] = "1"
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    if os.getppid() != parent:  # the fork server's child: it lives as long as its children do
        _die_with_sweep(parent)
    _die_with_parent(os.getppid())


def _die_with_sweep(pid: int) -> None:
    """A daemon thread exits this process when the process ``pid`` ends (Linux: a pidfd, else polled)."""
    import select
    import threading

    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        os._exit(1)
    except (AttributeError, OSError):
        fd = None

    def watch() -> None:
        if fd is not None:
            select.select([fd], [], [])  # readable when the process has ended
        else:
            while _alive(pid):
                time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="mlpfac-sweep-watch", daemon=True).start()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


def _die_with_parent(parent: int) -> None:
    """Linux: the kernel sends SIGKILL when the parent dies (prctl PR_SET_PDEATHSIG). Everywhere: a
    daemon thread exits the process once it has another parent (the parent died, it was reparented)."""
    import threading

    from mlpfac.io.interrupts import die_with_parent

    die_with_parent(parent=parent)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="mlpfac-parent-watch", daemon=True).start()
