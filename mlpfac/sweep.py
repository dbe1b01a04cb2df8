"""Experiments at scale: scenarios x controllers x seeds -> run folders -> one table.

``mlpfac sweep`` and ``mlpfac compare`` are one engine with two tables:

1. **Plan** (:func:`plan`): every scenario is loaded and resolved once per controller with
   :meth:`Scenario.with_overrides` before anything runs, so bad input is a :class:`ConfigError`
   and no run folder exists yet; each seed's table is that table with its seed (the table
   ``with_overrides(seed=...)`` gives). More than ``MAX_RUNS`` runs is refused.
2. **Execute** (:func:`execute`): runs already done are skipped; the rest go to this process
   (``workers=1``), a local process pool, or a Dask cluster (``scheduler``), one run or one batch
   of seeds (``batched``, see :mod:`mlpfac.batch`) per task. Workers compute and return the
   metrics; **the client writes every run folder**, so Dask workers need no shared disk::

       DIR/<scenario>/<controller>/seed-0003/config.toml    the scenario as resolved
       DIR/<scenario>/<controller>/seed-0003/run.rrd        only with save_rrd
       DIR/<scenario>/<controller>/seed-0003/metrics.json   = runner.metrics(rec), written last

   Each file goes through a temporary file and ``os.replace``; metrics.json comes last, so a
   folder with metrics.json is whole. A run counts as done (:func:`check_done`) when config.toml
   equals the resolved scenario, metrics.json is a metrics dict of this scenario, controller and
   seed, and with ``save_rrd`` run.rrd has the size and sha256 recorded in metrics.json; any other
   folder is run again, and the summary says how many and why.

   The sweep holds ``folder_lock(DIR)`` throughout: a second sweep into DIR stops with one line.
   Recordings are made in ``DIR/.tmp`` (removed at the end; a killed sweep's is removed by the
   next one); a recording without rerun's footer (a full disk) is a failed run. Local workers are
   fresh interpreters with one BLAS thread each that die with the sweep (``PR_SET_PDEATHSIG``
   and a thread watching the parent), so a killed sweep leaves no worker behind.
3. **Aggregate** (:func:`aggregate`): per scenario, controller and phase ("before" / "after" the
   first event; only "before" when the scenario has no event).

How diverged runs enter the statistics: the position / heading RMS statistics (mean, median,
95 % confidence interval of the mean, Student t) are over the **bounded runs only** (status
"ok"); next to them stands the bounded share k/n. The worst seed is the diverged run that
diverged first (fewest steps, then lowest seed) if any diverged, else the bounded run with the
largest position RMS in that phase. A run that raised an exception (a bug, not a divergence)
leaves ``error.txt`` and no metrics.json; it is reported, left out of the table, and re-run on
resume.

Each run is seeded by its own seed only, so the table does not depend on the number of workers,
the scheduler or batching. Dask workers need this package importable (``pip install -e .`` on
every worker) and, for MuJoCo scenarios, the model files at the same absolute path.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import math
import os
import shlex
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.exceptions import ConfigError, MlpfacError
from mlpfac.outputs import Terminated, folder_lock, sigint_deferred, write_atomic, write_run_folder

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143
MAX_RUNS = 100_000  # runs per sweep: a larger plan is refused before anything is loaded
WORKERS_PER_CORE = 4  # --workers above this many per core is refused (each worker holds ~130 MB)
TMP_DIR = ".tmp"  # OUT/.tmp: recordings being made; removed when the sweep ends and when the next one starts
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


class OutputError(MlpfacError):
    """Writing the sweep's results failed (a full disk, a lost permission): one line naming the path."""


class WorkerLostError(MlpfacError):
    """A local worker process died (killed from outside, out of memory): the pool cannot go on."""


PHASES = ("before", "after")
COMPARE_CONTROLLERS = ("adaptive", "corradini", "kanayama")


# --------------------------------------------------------------------------------------------
# Input


def parse_seeds(text: str, limit: int | None = MAX_RUNS) -> list[int]:
    """``"0-99"``, ``"3"``, ``"0,2,5"``, ``"0-4,10"`` -> sorted distinct seeds; ``"5-2"`` is an error.

    More than ``limit`` seeds is a ConfigError, found before any list is built (``0-10000000`` is cheap).
    """
    ranges: list[tuple[int, int]] = []
    for part in str(text).split(","):
        part = part.strip()
        lo, sep, hi = part.partition("-")
        try:
            a = int(lo)
            b = int(hi) if sep else a
        except ValueError:
            raise ConfigError("--seeds", f"{part!r} is not a seed or a range like 0-99 (in {text!r})") from None
        if a < 0:
            raise ConfigError("--seeds", f"seeds are whole numbers >= 0, got {part!r}")
        if b < a:
            raise ConfigError("--seeds", f"empty range {part!r}: the end must not be below the start")
        ranges.append((a, b))
    count, end = 0, -1  # distinct seeds in the union of the ranges
    for a, b in sorted(ranges):
        if b > end:
            count += b - max(a, end + 1) + 1
            end = b
    if limit is not None and count > limit:
        raise ConfigError("--seeds", f"{count} seeds is more than the limit of {limit} runs per sweep; split them")
    seeds: set[int] = set()
    for a, b in ranges:
        seeds.update(range(a, b + 1))
    return sorted(seeds)


def parse_controllers(text: str | None) -> list[str | None]:
    """``"adaptive,corradini"`` -> names, checked; ``None`` -> each scenario's own controller."""
    if text is None:
        return [None]
    from mlpfac.controllers import CONTROLLERS

    names = [c.strip() for c in text.split(",") if c.strip()]
    if not names:
        raise ConfigError("--controllers", "no controller given")
    for c in names:
        if c not in CONTROLLERS:
            raise ConfigError("--controllers", f"unknown controller {c!r}; choose from {', '.join(CONTROLLERS)}")
    return list(dict.fromkeys(names))


@dataclass(frozen=True)
class Job:
    """One run: a scenario as resolved for one controller and seed."""

    scenario: str  # the scenario's name: the first folder level
    controller: str
    seed: int
    source: str = field(compare=False)  # file it came from (error messages, ConfigError "where")
    table: dict = field(compare=False, hash=False, repr=False)  # resolved TOML table: what a worker runs
    config: str = field(compare=False, repr=False)  # to_toml(table): config.toml

    @property
    def key(self) -> tuple[str, str, int]:
        return (self.scenario, self.controller, self.seed)

    def folder(self, out: Path) -> Path:
        return out / self.scenario / self.controller / f"seed-{self.seed:04d}"


def plan(
    scenarios: Iterable[str], controllers: list[str | None], seeds: list[int], duration: float | None = None
) -> list[Job]:
    """Load and resolve every run; raises ConfigError on the first bad scenario, controller or seed."""
    from mlpfac.scenario import load, to_toml

    scenarios = list(dict.fromkeys(scenarios))
    if not scenarios:
        raise ConfigError("scenarios", "no scenario given")
    if not seeds:
        raise ConfigError("--seeds", "no seed given")
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise ConfigError("--duration", f"must be a positive number of seconds, got {duration}")
    jobs: list[Job] = []
    names: dict[str, str] = {}
    for src in scenarios:
        base = load(src)
        if base.name in names:
            raise ConfigError(
                src,
                f"scenario name {base.name!r} is also the name of {names[base.name]}; their folders would collide",
            )
        names[base.name] = src
        for ctrl in controllers:
            # parsed once; only the seed varies, so each seed's table is this one with its seed
            # (what with_overrides(seed=...) gives: parse checks a seed >= 0, which parse_seeds did)
            scn = base.with_overrides(controller=ctrl, duration=duration)
            configs = _seed_configs(scn.table, seeds, to_toml)
            for seed in seeds:
                table = {**scn.table, "seed": seed}
                jobs.append(Job(scn.name, scn.controller, seed, scn.source, table, configs(seed, table)))
    return jobs


def _seed_configs(table: dict, seeds: list[int], to_toml) -> Callable[[int, dict], str]:
    """``configs(seed, table)`` = ``to_toml(table)``, made by replacing the seed line of one rendering."""
    marker = max(seeds, default=0) + 10**18 + 7  # a number no seed line has
    text = to_toml({**table, "seed": marker})
    line = f"seed = {marker!r}\n"
    if text.count(str(marker)) != 1 or text.count(line) != 1:
        return lambda seed, t: to_toml(t)
    head, tail = text.split(line)
    return lambda seed, t: f"{head}seed = {seed!r}\n{tail}"


def check_writable(out: Path) -> None:
    """ConfigError unless ``out`` is (or can be created as) a writable folder; creates nothing."""
    p = out.resolve()
    while not p.exists():
        p = p.parent
    if not p.is_dir():
        raise ConfigError(str(out), f"{p} is a file, not a folder")
    if not os.access(p, os.W_OK | os.X_OK):
        raise ConfigError(str(out), f"cannot write into {p}")


# --------------------------------------------------------------------------------------------
# Running one task (in this process, a pool worker or a Dask worker)


def run_task(jobs: list[Job], batched: bool = False, save_rrd: bool = False, tmp_dir: str | None = None) -> list[dict]:
    """Run ``jobs`` (one, or seeds of one scenario and controller when ``batched``).

    Returns one result per job: {"key", "metrics", "rrd" (bytes or None), "error" (str or None)}.
    Recordings are made in ``tmp_dir`` (OUT/.tmp for a local sweep; the system's temporary folder
    on a Dask worker). An interrupted run raises KeyboardInterrupt: it must never be written as done.
    """
    from mlpfac.runner import metrics
    from mlpfac.scenario import parse

    if batched and len(jobs) > 1 and not save_rrd:
        from mlpfac.batch import run_batch

        try:
            recs = run_batch([parse(j.table, j.source) for j in jobs])
        except KeyboardInterrupt:
            raise
        except Exception as err:  # a bug, not a divergence: report it per run
            return [{"key": j.key, "metrics": None, "rrd": None, "error": _error_text(err)} for j in jobs]
        return [
            {"key": j.key, "metrics": metrics(r), "rrd": None, "error": None} for j, r in zip(jobs, recs, strict=True)
        ]
    return [_run_one(j, save_rrd, tmp_dir) for j in jobs]


def _run_one(job: Job, save_rrd: bool, tmp_dir: str | None = None) -> dict:
    from mlpfac.runner import metrics, run
    from mlpfac.scenario import parse

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
    import traceback

    return "".join(traceback.format_exception(err))


def _worker_init(parent: int) -> None:
    """Pool workers leave Ctrl-C and SIGTERM to the parent, which stops them (a half run is never
    returned), and die with the parent: a killed sweep leaves no worker behind."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    _die_with_parent(parent)


def _die_with_parent(parent: int) -> None:
    """Linux: the kernel sends SIGKILL when the parent dies (prctl PR_SET_PDEATHSIG). Everywhere: a
    daemon thread exits the process once it has another parent (the parent died, it was reparented)."""
    import signal
    import threading

    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
    if os.getppid() != parent:  # the parent died before the line above
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="mlpfac-parent-watch", daemon=True).start()


# --------------------------------------------------------------------------------------------
# Results folders


def write_result(out: Path, job: Job, result: dict) -> None:
    """config.toml, run.rrd, then metrics.json (its presence means the folder is whole); or error.txt.

    With a recording, metrics.json also holds its size and sha256 ("rrd"), checked on resume.
    An OSError (a full disk) leaves the folder without metrics.json: not done, run again on resume.
    """
    d = job.folder(out)
    try:
        _write_result(d, job, result)
    except OSError as err:  # a write names no file (EFBIG, ENOSPC from write()): name the folder
        raise _oserror(err, f"into {d}") from None


def _write_result(d: Path, job: Job, result: dict) -> None:
    with sigint_deferred():  # a Ctrl-C now waits for the folder to be whole
        d.mkdir(parents=True, exist_ok=True)
        if result["error"] is not None:
            (d / "metrics.json").unlink(missing_ok=True)  # a stale run being replaced is not whole
            write_atomic(d / "config.toml", job.config)
            write_atomic(d / "error.txt", result["error"])
            return
        (d / "error.txt").unlink(missing_ok=True)
        m, rrd = result["metrics"], result.get("rrd")
        if rrd is not None:
            m = m | {"rrd": {"bytes": len(rrd), "sha256": hashlib.sha256(rrd).hexdigest()}}
        write_run_folder(d, job.config, m, rrd)


def _number(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _number_or_none(x) -> bool:
    return x is None or _number(x)


PHASE_KEYS = ("rms_position_error_m", "max_position_error_m", "rms_heading_error_rad")


def metrics_problem(m, job: Job) -> str | None:
    """Why ``m`` (a parsed metrics.json) is not the metrics of ``job`` as ``runner.metrics`` writes them; None if it is."""
    if not isinstance(m, dict):
        return "not valid"
    if m.get("status") not in ("ok", "diverged"):
        return "not valid"
    if not (_number(m.get("T")) and isinstance(m.get("steps"), int) and not isinstance(m.get("steps"), bool)):
        return "not valid"
    if not all(_number_or_none(m.get(k, 0)) and k in m for k in PHASE_KEYS):
        return "not valid"
    for k in ("max_abs_weight", "mean_diag_P_final"):
        if k not in m or not _number_or_none(m[k]):
            return "not valid"
    if not (_number(m.get("sim_time_s")) and _number(m.get("wall_time_s"))):
        return "not valid"
    if not isinstance(m.get("events"), list) or not (m.get("reason") is None or isinstance(m.get("reason"), str)):
        return "not valid"
    phases = m.get("phases")
    if not isinstance(phases, dict) or "before" not in phases or not set(phases) <= set(PHASES):
        return "not valid"
    for ph in phases.values():
        if not isinstance(ph, dict) or not (_number(ph.get("start_s")) and _number(ph.get("end_s"))):
            return "not valid"
        if not all(k in ph and _number_or_none(ph[k]) for k in PHASE_KEYS):
            return "not valid"
    if (m.get("scenario"), m.get("controller"), m.get("seed")) != job.key or isinstance(m.get("seed"), bool):
        return "of another run"
    return None


def check_done(out: Path, job: Job, save_rrd: bool = False) -> tuple[dict | None, str | None]:
    """(metrics, None) if ``job``'s folder is whole and was run with the same configuration; else
    (None, why it must run again), why being None for a run never finished (no metrics.json).

    Whole: config.toml equals the job's, metrics.json is a metrics dict of this scenario, controller
    and seed, and with ``save_rrd`` run.rrd has the size and sha256 metrics.json recorded.
    """
    d = job.folder(out)
    try:
        text = (d / "metrics.json").read_text()
    except FileNotFoundError:
        return None, None
    except (OSError, ValueError):
        return None, "metrics.json unreadable"
    try:
        if (d / "config.toml").read_text() != job.config:
            return None, "configuration changed"
    except (OSError, ValueError):
        return None, "config.toml missing"
    try:
        m = json.loads(text)
    except ValueError:
        return None, "metrics.json not valid"
    problem = metrics_problem(m, job)
    if problem is not None:
        return None, f"metrics.json {problem}"
    if save_rrd:
        rec = m.get("rrd")
        if not (isinstance(rec, dict) and isinstance(rec.get("bytes"), int) and isinstance(rec.get("sha256"), str)):
            return None, "run.rrd not recorded"
        try:
            if (d / "run.rrd").stat().st_size != rec["bytes"] or _sha256(d / "run.rrd") != rec["sha256"]:
                return None, "run.rrd changed or cut"
        except OSError:
            return None, "run.rrd missing"
    return m, None


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def load_done(out: Path, job: Job, save_rrd: bool = False) -> dict | None:
    """The metrics of ``job`` if its folder is whole and was run with the same configuration (see :func:`check_done`)."""
    return check_done(out, job, save_rrd)[0]


# --------------------------------------------------------------------------------------------
# Execution


@dataclass
class Outcome:
    """What a sweep produced: the metrics of every whole run, in plan order, and the failures."""

    jobs: list[Job]
    metrics: dict[tuple, dict]
    errors: dict[tuple, str]
    skipped: int
    ran: int
    interrupted: bool = False
    terminated: bool = False  # the interruption was a SIGTERM
    wall_s: float = 0.0
    redo: dict[str, int] = field(default_factory=dict)  # why folders found were not done -> how many


def make_tasks(jobs: list[Job], batched: bool, batch_size: int) -> list[list[Job]]:
    """One job per task, or with ``batched`` up to ``batch_size`` seeds of one scenario and controller."""
    if not batched:
        return [[j] for j in jobs]
    groups: dict[tuple[str, str], list[Job]] = {}
    for j in jobs:
        groups.setdefault((j.scenario, j.controller), []).append(j)
    return [g[i : i + batch_size] for g in groups.values() for i in range(0, len(g), batch_size)]


def _oserror(err: OSError, what: str) -> OutputError:
    path = err.filename or what
    return OutputError(f"cannot write {path} ({err.strerror or err})")


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
) -> Outcome:
    """Run the jobs not done yet; write each run's folder as its result arrives.

    ``client`` is a ``dask.distributed.Client`` or None (local). ``progress``: None shows a bar
    only when stderr is a terminal. KeyboardInterrupt (Ctrl-C, or SIGTERM as
    :class:`~mlpfac.outputs.Terminated`) stops the workers and returns with ``interrupted=True``;
    every folder written so far is whole. ``out`` is locked for the sweep (``folder_lock``) unless
    the caller holds the lock (``locked``); recordings are made in ``out/.tmp``, which is removed at
    the end and, left by a killed sweep, at the start. A failed write raises :class:`OutputError`.
    """
    with contextlib.ExitStack() as stack:
        if not locked:
            stack.enter_context(folder_lock(out, "--out"))
        try:
            return _execute(jobs, out, workers, client, batched, batch_size, save_rrd, progress, on_result)
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


def _execute(jobs, out, workers, client, batched, batch_size, save_rrd, progress, on_result) -> Outcome:
    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / TMP_DIR
    shutil.rmtree(tmp, ignore_errors=True)  # what a killed sweep left; we hold the lock
    done: dict[tuple, dict] = {}
    todo: list[Job] = []
    redo: dict[str, int] = {}
    for j in jobs:
        m, why = check_done(out, j, save_rrd)
        if m is None:
            todo.append(j)
            if why is not None:
                redo[why] = redo.get(why, 0) + 1
        else:
            done[j.key] = m
    outcome = Outcome(jobs, done, {}, skipped=len(done), ran=0, redo=redo)
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
            for res in res_list:
                job = by_key[res["key"]]
                write_result(out, job, res)
                outcome.ran += 1
                if res["error"] is not None:
                    outcome.errors[job.key] = res["error"]
                    failed += 1
                else:
                    outcome.metrics[job.key] = res["metrics"]
                    failed += res["metrics"]["status"] != "ok"
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


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Worker processes started in this block run BLAS on one thread each (unless the user set the
    variables): N workers on N cores with multi-threaded BLAS are several times slower than their sum."""
    added = [v for v in BLAS_THREAD_VARIABLES if v not in os.environ]
    try:
        for v in added:
            os.environ[v] = "1"
        yield
    finally:
        for v in added:
            os.environ.pop(v, None)


def _pool_results(
    tasks: list[list[Job]], workers: int, batched: bool, save_rrd: bool, tmp_dir: str | None = None
) -> Iterator[list[dict]]:
    """Results of ``tasks`` from a local process pool, as they finish; at most 2 tasks per worker in flight.

    Workers are fresh interpreters (``spawn``: no copy of this process's threads or BLAS state),
    started with one BLAS thread each, and die with this process. Closing the generator (or an
    exception in it) kills the workers: a run being computed is lost, its folder never written.
    """
    import concurrent.futures as cf
    import multiprocessing as mp
    from concurrent.futures.process import BrokenProcessPool

    before = set(mp.active_children())
    with one_blas_thread():
        pool = cf.ProcessPoolExecutor(
            max_workers=min(workers, len(tasks)),
            mp_context=mp.get_context("spawn"),
            initializer=_worker_init,
            initargs=(os.getpid(),),
        )
    pending: set[cf.Future] = set()
    queue = iter(tasks)

    def submit(t: list[Job]) -> None:
        with one_blas_thread():  # the pool starts its workers as tasks are submitted
            pending.add(pool.submit(run_task, t, batched, save_rrd, tmp_dir))

    try:
        for t in queue:
            submit(t)
            if len(pending) >= 2 * workers:
                break
        while pending:
            finished, pending = cf.wait(pending, return_when=cf.FIRST_COMPLETED)
            for f in finished:
                try:
                    res = f.result()
                except BrokenProcessPool:
                    raise WorkerLostError(
                        "a worker process died (killed from outside, or out of memory: see `dmesg`); "
                        "the runs it was computing were not written"
                    ) from None
                nxt = next(queue, None)
                if nxt is not None:
                    submit(nxt)
                yield res
        pool.shutdown()
    except BaseException:  # also GeneratorExit: the consumer stopped
        for f in pending:
            f.cancel()
        for p in set(mp.active_children()) - before:  # this pool's workers: they ignore SIGINT and SIGTERM
            p.kill()
        pool.shutdown(wait=True, cancel_futures=True)
        raise


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
    try:
        return Client(address, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as err:
        msg = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise ConfigError(
            "--scheduler", f"cannot reach a Dask scheduler at {address} within {timeout:g} s ({msg})"
        ) from None


# --------------------------------------------------------------------------------------------
# Aggregation and tables


def _ci95(xs: list[float]) -> tuple[float | None, float | None]:
    """95 % confidence interval of the mean (Student t); None for fewer than two values."""
    n = len(xs)
    if n < 2:
        return None, None
    from scipy.stats import t

    mean = math.fsum(xs) / n
    sd = math.sqrt(math.fsum((x - mean) ** 2 for x in xs) / (n - 1))
    half = float(t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return mean - half, mean + half


def _median(xs: list[float]) -> float | None:
    if not xs:
        return None
    s = sorted(xs)
    n = len(s)
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


def aggregate(jobs: list[Job], metrics: dict[tuple, dict]) -> list[dict]:
    """One row per scenario, controller and phase (in plan order) from the runs' metrics."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for j in jobs:
        groups.setdefault((j.scenario, j.controller), [])
        if j.key in metrics:
            groups[(j.scenario, j.controller)].append(metrics[j.key])
    rows = []
    for (scn, ctrl), ms in groups.items():
        n = len(ms)
        ok = [m for m in ms if m["status"] == "ok"]
        diverged = sorted((m for m in ms if m["status"] != "ok"), key=lambda m: (m["steps"], m["seed"]))
        has_after = any(
            "after" in m["phases"] and m["phases"]["after"]["end_s"] > m["phases"]["after"]["start_s"] for m in ms
        )
        for phase in PHASES if has_after else PHASES[:1]:
            ph = [m["phases"][phase] for m in ok]
            pos = [p["rms_position_error_m"] for p in ph if p["rms_position_error_m"] is not None]
            head = [p["rms_heading_error_rad"] for p in ph if p["rms_heading_error_rad"] is not None]
            mx = [p["max_position_error_m"] for p in ph if p["max_position_error_m"] is not None]
            if diverged:
                worst = diverged[0]
            else:
                scored = [(m["phases"][phase]["rms_position_error_m"] or -1.0, -m["seed"], m) for m in ok]
                worst = max(scored, key=lambda s: s[:2])[2] if scored else None
            row = {"scenario": scn, "controller": ctrl, "phase": phase, "runs": n, "bounded": len(ok)}
            row["bounded_share"] = len(ok) / n if n else None
            for name, xs in (("pos_rms_m", pos), ("heading_rms_rad", head)):
                lo, hi = _ci95(xs)
                row |= {
                    f"{name}_mean": math.fsum(xs) / len(xs) if xs else None,
                    f"{name}_median": _median(xs),
                    f"{name}_ci_lo": lo,
                    f"{name}_ci_hi": hi,
                }
            row["max_err_m_median"] = _median(mx)
            row["max_err_m_max"] = max(mx) if mx else None
            weights = [m["max_abs_weight"] for m in ms if m.get("max_abs_weight") is not None]
            row["max_abs_weight"] = max(weights) if weights else None  # over every run, diverged ones too
            row["worst_seed"] = worst["seed"] if worst else None
            row["worst_status"] = worst["status"] if worst else None
            rows.append(row)
    return rows


def _f(x: float | None, scale: float = 1.0, digits: int = 2) -> str:
    return "-" if x is None else f"{x * scale:.{digits}f}"


def _ci(lo, hi, scale: float) -> str:
    return "-" if lo is None else f"[{lo * scale:.2f}, {hi * scale:.2f}]"


SWEEP_COLUMNS: list[tuple[str, Callable[[dict], str]]] = [
    ("scenario", lambda r: r["scenario"]),
    ("controller", lambda r: r["controller"]),
    ("phase", lambda r: r["phase"]),
    ("bounded", lambda r: f"{r['bounded']}/{r['runs']}"),
    ("pos RMS mean [mm]", lambda r: _f(r["pos_rms_m_mean"], 1e3)),
    ("pos RMS median [mm]", lambda r: _f(r["pos_rms_m_median"], 1e3)),
    ("pos RMS 95% CI [mm]", lambda r: _ci(r["pos_rms_m_ci_lo"], r["pos_rms_m_ci_hi"], 1e3)),
    ("heading RMS mean [mrad]", lambda r: _f(r["heading_rms_rad_mean"], 1e3)),
    ("heading RMS median [mrad]", lambda r: _f(r["heading_rms_rad_median"], 1e3)),
    ("heading RMS 95% CI [mrad]", lambda r: _ci(r["heading_rms_rad_ci_lo"], r["heading_rms_rad_ci_hi"], 1e3)),
    ("max abs weight", lambda r: _f(r["max_abs_weight"], 1.0, 3) if r["max_abs_weight"] is not None else "-"),
    (
        "worst seed",
        lambda r: (
            "-"
            if r["worst_seed"] is None
            else f"{r['worst_seed']}" + (f" ({r['worst_status']})" if r["worst_status"] != "ok" else "")
        ),
    ),
]

COMPARE_COLUMNS: list[tuple[str, Callable[[dict], str]]] = [
    ("scenario", lambda r: r["scenario"]),
    ("controller", lambda r: r["controller"]),
    ("phase", lambda r: r["phase"]),
    ("pos RMS median [mm]", lambda r: _f(r["pos_rms_m_median"], 1e3)),
    ("max error [mm]", lambda r: _f(r["max_err_m_max"], 1e3)),
    ("heading RMS median [mrad]", lambda r: _f(r["heading_rms_rad_median"], 1e3)),
    ("status", lambda r: f"bounded {r['bounded']}/{r['runs']}"),
]

CSV_FIELDS = [
    "scenario", "controller", "phase", "runs", "bounded", "bounded_share",
    "pos_rms_m_mean", "pos_rms_m_median", "pos_rms_m_ci_lo", "pos_rms_m_ci_hi",
    "heading_rms_rad_mean", "heading_rms_rad_median", "heading_rms_rad_ci_lo", "heading_rms_rad_ci_hi",
    "max_err_m_median", "max_err_m_max", "max_abs_weight", "worst_seed", "worst_status",
]  # fmt: skip


def markdown(rows: list[dict], columns: list[tuple[str, Callable[[dict], str]]]) -> str:
    head = [c for c, _ in columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(" --- " for _ in head) + "|"]
    lines += ["| " + " | ".join(fn(r) for _, fn in columns) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def write_tables(out: Path, stem: str, rows: list[dict], columns, meta: dict) -> list[Path]:
    """``stem``.csv (every statistic, SI units), .md (the readable table), .json (rows + how they were made)."""
    import csv
    import io

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_FIELDS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r[k] is None else r[k]) for k in CSV_FIELDS})
    paths = [out / f"{stem}.csv", out / f"{stem}.md", out / f"{stem}.json"]
    note = (
        "\nStatistics over bounded runs (status ok); 95 % CI of the mean (Student t). Worst seed: the "
        "first to diverge if any diverged, else the largest position RMS; re-run it alone with "
        "`mlpfac run SCENARIO --controller C --seed S`.\n"
    )
    write_atomic(paths[0], buf.getvalue())
    write_atomic(paths[1], markdown(rows, columns) + note)
    write_atomic(paths[2], json.dumps({"meta": meta, "rows": rows}, indent=2) + "\n")
    return paths


# --------------------------------------------------------------------------------------------
# Command line glue (wired into mlpfac.cli)


def _add_common(p: argparse.ArgumentParser, seeds: str, out: str) -> None:
    p.add_argument("--seeds", default=seeds, help=f"seeds: 0-99, 3, 0,2,5 or 0-4,10 (default {seeds})")
    p.add_argument("--duration", type=float, help="override every scenario's duration in seconds")
    p.add_argument(
        "--out", type=Path, default=Path(out), help=f"results folder (default {out}); re-running skips whole runs"
    )
    g = p.add_argument_group("execution")
    g.add_argument("--workers", type=int, default=None, help="local worker processes (default: number of CPUs)")
    g.add_argument(
        "--batched", action="store_true", help="step the seeds of one scenario and controller together (mlpfac.batch)"
    )
    g.add_argument("--batch-size", type=int, default=64, help="seeds per batch with --batched (default 64)")
    g.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on an existing Dask cluster, e.g. tcp://10.0.0.5:8786 (workers need `pip install -e .`)",
    )
    g.add_argument(
        "--scheduler-timeout", type=float, default=10.0, help="seconds to wait for the scheduler (default 10)"
    )
    g.add_argument("--save-rrd", action="store_true", help="also save each run's rerun recording as run.rrd")


def add_sweep_arguments(p: argparse.ArgumentParser) -> None:
    p.description = (
        "Monte Carlo sweep: scenarios x controllers x seeds -> mean, median, 95 % CI per phase (CSV, Markdown, JSON)."
    )
    p.add_argument("scenarios", nargs="+", help="shipped scenario names or paths to .toml files")
    p.add_argument("--controllers", help="comma-separated controllers (default: each scenario's own)")
    _add_common(p, "0-99", "runs/sweep")


def add_compare_arguments(p: argparse.ArgumentParser) -> None:
    p.description = (
        "Compare controllers on scenarios and seeds: position RMS, max error, heading RMS, bounded k/n per phase."
    )
    p.add_argument("scenarios", nargs="*", help="scenario names or .toml paths (default: every shipped scenario)")
    p.add_argument(
        "--controllers",
        default=",".join(COMPARE_CONTROLLERS),
        help=f"comma-separated (default {','.join(COMPARE_CONTROLLERS)})",
    )
    _add_common(p, "0-9", "runs/compare")


def run_sweep_cli(args: argparse.Namespace) -> int:
    return _run_cli(args, "sweep", SWEEP_COLUMNS)


def run_compare_cli(args: argparse.Namespace) -> int:
    if not args.scenarios:
        from mlpfac.scenario import scenario_names

        args.scenarios = scenario_names()
    return _run_cli(args, "compare", COMPARE_COLUMNS)


def check_execution_flags(args: argparse.Namespace) -> int:
    """The number of local workers; ConfigError naming the flag for a value that cannot work."""
    cores = os.cpu_count() or 1
    workers = cores if args.workers is None else args.workers
    most = WORKERS_PER_CORE * cores
    if workers < 1:
        raise ConfigError("--workers", f"need at least 1, got {workers}")
    if workers > most and not args.scheduler:
        raise ConfigError("--workers", f"at most {most} ({WORKERS_PER_CORE} per core on this machine), got {workers}")
    if args.batch_size < 1:
        raise ConfigError("--batch-size", f"need at least 1, got {args.batch_size}")
    t = args.scheduler_timeout
    if not (math.isfinite(t) and t > 0):
        raise ConfigError("--scheduler-timeout", f"must be a positive number of seconds, got {t}")
    return workers


def _run_cli(args: argparse.Namespace, stem: str, columns) -> int:
    """Validate everything, then run; 0 done, 1 some run failed, 2 bad input or a failed write
    (one line naming the path), 130 interrupted (Ctrl-C), 143 terminated (SIGTERM)."""
    seeds = parse_seeds(args.seeds)
    controllers = parse_controllers(args.controllers)
    workers = check_execution_flags(args)
    scenarios = list(dict.fromkeys(args.scenarios))
    n = len(scenarios) * len(controllers) * len(seeds)
    if n > MAX_RUNS:
        raise ConfigError(
            "--seeds",
            f"{len(scenarios)} scenarios x {len(controllers)} controllers x {len(seeds)} seeds = {n} runs is more "
            f"than the limit of {MAX_RUNS} per sweep; split the seeds into several sweeps",
        )
    print(f"mlpfac: planning {n} runs ...", file=sys.stderr, flush=True)
    jobs = plan(scenarios, controllers, seeds, args.duration)
    check_writable(args.out)
    client = connect(args.scheduler, args.scheduler_timeout) if args.scheduler else None
    cmd = shlex.join(["mlpfac", *sys.argv[1:]]) if sys.argv[1:] else f"mlpfac {stem} ..."
    try:
        with folder_lock(args.out, "--out"):
            try:
                oc = execute(
                    jobs,
                    args.out,
                    workers=workers,
                    client=client,
                    batched=args.batched,
                    batch_size=args.batch_size,
                    save_rrd=args.save_rrd,
                    locked=True,
                )
            except OutputError as err:
                raise OutputError(f"{err}; the runs written before are whole, resume with: {cmd}") from None
            except WorkerLostError as err:
                print(f"mlpfac: error: {err}; every run written is whole, resume with: {cmd}", file=sys.stderr)
                return EXIT_FAILED
            rows = aggregate(jobs, oc.metrics)
            if oc.interrupted:
                print(
                    f"mlpfac: {'terminated' if oc.terminated else 'interrupted'}; {len(oc.metrics)} of {len(jobs)} runs"
                    f" are done and kept in {args.out}.\nResume with the same command:\n  {cmd}",
                    file=sys.stderr,
                )
                return EXIT_TERMINATED if oc.terminated else EXIT_INTERRUPTED
            meta = {
                "command": stem,
                "scenarios": list(args.scenarios),
                "controllers": sorted({j.controller for j in jobs}),
                "seeds": args.seeds,
                "duration": args.duration,
                "runs": len(jobs),
            }
            try:
                paths = write_tables(args.out, stem, rows, columns, meta)
            except OSError as err:
                raise OutputError(
                    f"{_oserror(err, str(args.out))}; every run folder is whole, resume with: {cmd}"
                ) from None
    finally:
        if client is not None:
            client.close()
    print(markdown(rows, columns), end="")
    redo = sum(oc.redo.values())
    why = "; ".join(f"{k} {v}" for k, v in oc.redo.items())
    print(
        f"{len(jobs)} runs ({oc.skipped} already done, {oc.ran} run now in {oc.wall_s:.1f} s"
        + (f", of which {redo} were found but run again: {why}" if redo else "")
        + f") -> {', '.join(map(str, paths))}"
    )
    for key, err in oc.errors.items():
        last = err.strip().splitlines()[-1] if err.strip() else "error"
        print(
            f"mlpfac: error: run {key[0]} / {key[1]} / seed {key[2]} raised: {last} (see error.txt; re-run to retry)",
            file=sys.stderr,
        )
    return EXIT_FAILED if oc.errors else EXIT_OK
