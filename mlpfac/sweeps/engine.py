"""Experiments at scale: scenarios x controllers x seeds -> run folders -> one table.

``mlpfac sweep`` and ``mlpfac compare`` (:mod:`mlpfac.sweeps.cli`) and :func:`mlpfac.sweep` are one
engine with two tables. It lives in :mod:`mlpfac.sweeps` (``plan``, ``worker``, ``folders``,
``execute``, ``tables``); this module runs it into a folder (:func:`sweep_folder`), and every name
below is importable from here:

1. **Plan** (:func:`plan`): every scenario is loaded and resolved once per controller with
   :meth:`Scenario.with_overrides` before anything runs, so bad input is a :class:`ConfigError`
   and no run folder exists yet; each seed's table is that table with its seed (the table
   ``with_overrides(seed=...)`` gives). More than ``MAX_RUNS`` runs is refused.
2. **Execute** (:func:`execute`): runs already done are skipped; the rest go to this process
   (``workers=1``), a local process pool, or a Dask cluster (``scheduler``), one run or one batch
   of seeds (``batched``, see :func:`mlpfac.loop.runner.run_batch`) per task. Workers compute and return the
   metrics; **the client writes every run folder**, so Dask workers need no shared disk::

       DIR/<scenario>/<controller>/seed-0003/config.toml    the scenario as resolved
       DIR/<scenario>/<controller>/seed-0003/run.rrd        only with save_rrd
       DIR/<scenario>/<controller>/seed-0003/metrics.json   = run_metrics.metrics(rec)

   Each folder is written beside its place and renamed into it whole
   (:func:`mlpfac.io.files.write_folder_whole`): a killed sweep leaves it as it was or whole. A run counts as done (:func:`check_done`) when config.toml
   equals the resolved scenario, metrics.json is a metrics dict of this scenario, controller and
   seed, and with ``save_rrd`` run.rrd has the size and sha256 recorded in metrics.json; any other
   folder is run again, and the summary says how many and why.

   The sweep holds ``folder_lock(DIR)`` throughout: a second sweep into DIR stops with one line.
   Recordings are made in ``DIR/.tmp`` (removed at the end; a killed sweep's is removed by the
   next one); a recording without rerun's footer (a full disk) is a failed run. Local workers are
   forked from a warm fork server (:func:`mlpfac.sweeps.worker.pool_context`) with one BLAS thread
   each and the sweep's environment, and die with the sweep (``PR_SET_PDEATHSIG`` and threads
   watching it), so a killed sweep leaves no worker behind.
3. **Aggregate** (:func:`aggregate`): per scenario, controller and phase ("before" / "after" the
   first event; only "before" when the scenario has no event); and **pair** (:func:`paired_rows`,
   :mod:`mlpfac.sweeps.paired`): per seed against Corradini's law, the oracle and the controller's
   own run without the event, in paired.csv / .md / .json and summary.md.

How runs enter the statistics: each run is tracking, lost or diverged (``outcome`` in
metrics.json, :func:`mlpfac.loop.metrics.outcome`); the position / heading RMS statistics (mean, median,
95 % confidence interval of the mean, Student t) are over the runs that finished (tracking or lost;
status "ok"), next to the three counts. The worst seed is the diverged run that
diverged first (fewest steps, then lowest seed) if any diverged, else the bounded run with the
largest position RMS in that phase. A run that raised an exception (a bug, not a divergence)
leaves ``error.txt`` and no metrics.json; it is reported, left out of the table, and re-run on
resume.

Each run is seeded by its own seed only, so the table does not depend on the number of workers,
the scheduler or batching. Dask workers need this package importable (``pip install -e .`` on
every worker) and, for MuJoCo scenarios, the model files at the same absolute path.
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.exceptions import ConfigError, OutputError, WorkerLostError  # noqa: F401 (also as mlpfac.sweeps.engine.*)
from mlpfac.io.files import folder_lock
from mlpfac.io.targets import check_results_folder
from mlpfac.sweeps.execute import (  # noqa: F401  (the engine's API, used as mlpfac.sweeps.engine.*)
    TMP_DIR,
    Outcome,
    connect,
    execute,
    make_tasks,
)
from mlpfac.sweeps.folders import (  # noqa: F401
    PHASES,
    _oserror,
    check_done,
    metrics_problem,
    write_result,
)
from mlpfac.sweeps.paired import paired_rows, summary  # noqa: F401
from mlpfac.sweeps.plan import MAX_RUNS, Job, check_writable, parse_controllers, parse_seeds, plan  # noqa: F401
from mlpfac.sweeps.tables import (  # noqa: F401
    COMPARE_COLUMNS,
    CSV_FIELDS,
    SWEEP_COLUMNS,
    aggregate,
    markdown,
    table_files,
    write_paired,
    write_tables,
)
from mlpfac.sweeps.worker import BLAS_THREAD_VARIABLES, rrd_is_whole, run_task, worker_environment  # noqa: F401

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143
WORKERS_PER_CORE = 4  # --workers above this many per core is refused (each worker holds ~130 MB)


def check_execution_flags(
    workers: int | None, batch_size: int = 64, scheduler: str | None = None, scheduler_timeout: float = 10.0
) -> int:
    """The number of local workers; ConfigError naming the flag for a value that cannot work."""
    for flag, value, kind in (("--workers", workers, int), ("--batch-size", batch_size, int),
                              ("--scheduler-timeout", scheduler_timeout, int | float)):  # fmt: skip
        if (value is not None or flag != "--workers") and (isinstance(value, bool) or not isinstance(value, kind)):
            raise ConfigError(flag, f"expected a {'whole ' if kind is int else ''}number, got {value!r}")
    cores = os.cpu_count() or 1
    workers = cores if workers is None else workers
    most = WORKERS_PER_CORE * cores
    if workers < 1:
        raise ConfigError("--workers", f"need at least 1, got {workers}")
    if workers > most and not scheduler:
        raise ConfigError("--workers", f"at most {most} ({WORKERS_PER_CORE} per core on this machine), got {workers}")
    if batch_size < 1:
        raise ConfigError("--batch-size", f"need at least 1, got {batch_size}")
    t = scheduler_timeout
    if not (math.isfinite(t) and t > 0):
        raise ConfigError("--scheduler-timeout", f"must be a positive number of seconds, got {t}")
    return workers


@dataclass
class Swept:
    """What :func:`sweep_into` made: the runs' outcome, the table rows, the paired rows, the files
    written; ``code`` is the exit code when the sweep stopped before its tables (else None)."""

    jobs: list[Job]
    outcome: Outcome
    rows: list[dict] = field(default_factory=list)
    paired: list[dict] = field(default_factory=list)
    paths: list[Path] = field(default_factory=list)
    code: int | None = None


def sweep_into(
    jobs: list[Job],
    out: Path,
    stem: str,
    columns,
    meta: dict,
    cmd: str,
    *,
    workers: int = 1,
    client=None,
    batched: bool = False,
    batch_size: int = 64,
    save_rrd: bool = False,
    progress: bool | None = None,
    cache=None,
) -> Swept:
    """Run ``jobs`` into ``out`` under its lock (runs already done are skipped), then write the
    tables (``stem``.csv / .md / .json, paired.*, summary.md) and ``stem``.png. Stopped by Ctrl-C or
    SIGTERM, or by a lost worker, it says so on stderr with ``cmd``, the command that resumes it,
    and returns with ``code`` set; a failed write is an :class:`OutputError` naming the path."""
    with folder_lock(out, "--out"):
        try:
            oc = execute(
                jobs,
                out,
                workers=workers,
                client=client,
                batched=batched,
                batch_size=batch_size,
                save_rrd=save_rrd,
                progress=progress,
                locked=True,
                cache=cache,
            )
        except OutputError as err:
            raise OutputError(f"{err}; the runs written before are whole, resume with: {cmd}") from None
        except WorkerLostError as err:
            print(f"mlpfac: error: {err}; every run written is whole, resume with: {cmd}", file=sys.stderr)
            return Swept(jobs, Outcome(jobs, {}, {}, 0, 0), code=EXIT_FAILED)
        done = Swept(jobs, oc)
        if oc.interrupted:  # stop now: no table (aggregating imports scipy, seconds on a loaded machine)
            print(
                f"mlpfac: {'terminated' if oc.terminated else 'interrupted'}; {len(oc.metrics)} of {len(jobs)} runs"
                f" are done and kept in {out}.\nResume with the same command:\n  {cmd}",
                file=sys.stderr,
            )
            done.code = EXIT_TERMINATED if oc.terminated else EXIT_INTERRUPTED
            return done
        done.rows, done.paired = aggregate(jobs, oc.metrics), paired_rows(jobs, oc.metrics)
        try:
            done.paths = write_tables(out, stem, done.rows, columns, meta) + write_paired(out, done.paired, meta)
            if any(j.point for j in jobs):  # an axis: where each controller breaks, in place of <stem>.png
                from mlpfac.sweeps.robustness import write_robustness

                done.paths += write_robustness(out, jobs, oc.metrics, meta)
            else:
                from mlpfac.plots import sweep_plots

                done.paths += sweep_plots(out, (stem,))  # <stem>.png beside the table
        except OSError as err:
            raise OutputError(f"{_oserror(err, str(out))}; every run folder is whole, resume with: {cmd}") from None
    return done


def sweep_folder(
    scenarios: list[str],
    controllers: str | None,
    seeds: str,
    out: Path,
    *,
    duration: float | None = None,
    workers: int | None = None,
    batched: bool = False,
    batch_size: int = 64,
    scheduler: str | None = None,
    scheduler_timeout: float = 10.0,
    save_rrd: bool = False,
    stem: str = "sweep",
    columns=SWEEP_COLUMNS,
    command: str | None = None,
    progress: bool | None = None,
    vary: list[str] | dict | None = None,
    threshold: float | None = None,
    lost_threshold: float | None = None,
    limit: bool = False,
    limit_cache: Path | None = None,
) -> Swept:
    """Validate everything (a ConfigError naming the flag before anything runs), plan, then
    :func:`sweep_into` ``out``; what ``mlpfac sweep`` / ``compare`` and :func:`mlpfac.sweep` do.
    ``command`` is what re-runs it (for messages); ``vary`` the ``--vary`` axes and draws
    (:mod:`mlpfac.sweeps.vary`), ``threshold`` the breaking points' limit in metres
    (:mod:`mlpfac.sweeps.robustness`), ``lost_threshold`` every run's ``lost_threshold_m``; ``limit``
    adds ``limit`` on every scenario and seed, taken from (and kept in) the cache folder
    ``limit_cache`` (:mod:`mlpfac.sweeps.limits`)."""
    from mlpfac.sweeps.limits import DEFAULT_CACHE, LimitCache, with_limit
    from mlpfac.sweeps.robustness import NO_AXIS, check_threshold
    from mlpfac.sweeps.vary import parse_vary

    seed_list = parse_seeds(seeds)
    names = with_limit(parse_controllers(controllers), limit)
    cache = LimitCache(limit_cache or DEFAULT_CACHE) if limit else None
    if cache is not None:
        check_writable(cache.root, "--limit-cache")
    workers = check_execution_flags(workers, batch_size, scheduler, scheduler_timeout)
    axes = parse_vary(vary)
    threshold = check_threshold(threshold)
    if lost_threshold is not None:
        from mlpfac.scenario.parse import lost_threshold_m

        lost_threshold = lost_threshold_m(lost_threshold, "--lost-threshold")
    if threshold is not None and not axes.axes:
        raise ConfigError("--threshold", NO_AXIS.replace("vary", "--vary"))
    scenarios = list(dict.fromkeys(scenarios))
    n = len(scenarios) * len(names) * len(seed_list) * axes.size
    if n > MAX_RUNS:
        raise ConfigError(
            "--seeds",
            f"{len(scenarios)} scenarios x {len(names)} controllers x {len(seed_list)} seeds"
            + (f" x {axes.size} grid points" if axes.axes else "")
            + f" = {n} runs is more than the limit of {MAX_RUNS} per sweep; split the seeds into several sweeps",
        )
    if progress is not False:
        print(f"mlpfac: planning {n} runs ...", file=sys.stderr, flush=True)
    if workers > 1 and not scheduler:
        from mlpfac.sweeps.worker import start_pool_server

        start_pool_server()  # the workers' fork server warms up while the runs are planned
    jobs = plan(scenarios, names, seed_list, duration, axes, lost_threshold)
    check_writable(out)
    check_results_folder(out, table_files(stem))
    meta = sweep_meta(stem, scenarios, seeds, duration, jobs) | ({"vary": axes.texts()} if axes else {})
    meta |= {"lost_threshold_m": lost_threshold} if lost_threshold is not None else {}
    meta |= {"threshold_m": threshold} if axes.axes else {}
    client = connect(scheduler, scheduler_timeout) if scheduler else None
    try:
        return sweep_into(jobs, out, stem, columns, meta, command or f"mlpfac {stem} ...", workers=workers,
                          client=client, batched=batched, batch_size=batch_size, save_rrd=save_rrd,
                          progress=progress, cache=cache)  # fmt: skip
    finally:
        if client is not None:
            client.close()


def sweep_meta(command: str, scenarios: list[str], seeds: str, duration: float | None, jobs: list[Job]) -> dict:
    """What sweep.json and paired.json say of how they were made (their ``meta``)."""
    return {
        "command": command,
        "scenarios": list(scenarios),
        "controllers": sorted({j.controller for j in jobs}),
        "seeds": seeds,
        "duration": duration,
        "runs": len(jobs),
    }


def report(done: Swept) -> int:
    """One line on the runs (done before, run now, run again and why, files written) and one on
    stderr per run that raised; EXIT_FAILED if some run raised, else EXIT_OK."""
    oc = done.outcome
    redo = sum(oc.redo.values())
    why = "; ".join(f"{k} {v}" for k, v in oc.redo.items())
    print(
        f"{len(done.jobs)} runs ({oc.skipped} already done"
        + (f", {oc.cached} limits from the cache" if oc.cached else "")
        + f", {oc.ran} run now in {oc.wall_s:.1f} s"
        + (f", of which {redo} were found but run again: {why}" if redo else "")
        + f") -> {', '.join(map(str, done.paths))}"
    )
    for key, err in oc.errors.items():
        last = err.strip().splitlines()[-1] if err.strip() else "error"
        print(
            f"mlpfac: error: run {key[0]} / {key[1]} / seed {key[2]} raised: {last} (see error.txt; re-run to retry)",
            file=sys.stderr,
        )
    return EXIT_FAILED if oc.errors else EXIT_OK
