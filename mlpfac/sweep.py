"""Experiments at scale: scenarios x controllers x seeds -> run folders -> one table.

``mlpfac sweep`` and ``mlpfac compare`` are one engine with two tables. The engine lives in
:mod:`mlpfac.sweeps` (``plan``, ``worker``, ``folders``, ``execute``, ``tables``); this module is
the command line and the engine's API (every name below is importable from here):

1. **Plan** (:func:`plan`): every scenario is loaded and resolved once per controller with
   :meth:`Scenario.with_overrides` before anything runs, so bad input is a :class:`ConfigError`
   and no run folder exists yet; each seed's table is that table with its seed (the table
   ``with_overrides(seed=...)`` gives). More than ``MAX_RUNS`` runs is refused.
2. **Execute** (:func:`execute`): runs already done are skipped; the rest go to this process
   (``workers=1``), a local process pool, or a Dask cluster (``scheduler``), one run or one batch
   of seeds (``batched``, see :func:`mlpfac.runner.run_batch`) per task. Workers compute and return the
   metrics; **the client writes every run folder**, so Dask workers need no shared disk::

       DIR/<scenario>/<controller>/seed-0003/config.toml    the scenario as resolved
       DIR/<scenario>/<controller>/seed-0003/run.rrd        only with save_rrd
       DIR/<scenario>/<controller>/seed-0003/metrics.json   = run_metrics.metrics(rec), written last

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
   first event; only "before" when the scenario has no event); and **pair** (:func:`paired_rows`,
   :mod:`mlpfac.sweeps.paired`): per seed against Corradini's law, the oracle and the controller's
   own run without the event, in paired.csv / .md / .json and summary.md.

How runs enter the statistics: each run is tracking, lost or diverged (``outcome`` in
metrics.json, :func:`mlpfac.run_metrics.outcome`); the position / heading RMS statistics (mean, median,
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

import argparse
import math
import os
import shlex
import sys
from pathlib import Path

from mlpfac.exceptions import ConfigError
from mlpfac.outputs import folder_lock
from mlpfac.sweeps.execute import (  # noqa: F401  (the engine's API, used as mlpfac.sweep.*)
    BLAS_THREAD_VARIABLES,
    TMP_DIR,
    Outcome,
    WorkerLostError,
    connect,
    execute,
    make_tasks,
    one_blas_thread,
)
from mlpfac.sweeps.folders import (  # noqa: F401
    PHASES,
    OutputError,
    _oserror,
    check_done,
    load_done,
    metrics_problem,
    write_result,
)
from mlpfac.sweeps.paired import paired_rows, summary
from mlpfac.sweeps.plan import MAX_RUNS, Job, check_writable, parse_controllers, parse_seeds, plan  # noqa: F401
from mlpfac.sweeps.tables import (  # noqa: F401
    COMPARE_COLUMNS,
    CSV_FIELDS,
    SWEEP_COLUMNS,
    aggregate,
    markdown,
    write_paired,
    write_tables,
)
from mlpfac.sweeps.worker import rrd_is_whole, run_task  # noqa: F401

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143
WORKERS_PER_CORE = 4  # --workers above this many per core is refused (each worker holds ~130 MB)
COMPARE_CONTROLLERS = ("adaptive", "corradini", "kanayama")


def _add_common(p: argparse.ArgumentParser, seeds: str, out: str) -> None:
    p.add_argument("--seeds", default=seeds, help=f"seeds: 0-99, 3, 0,2,5 or 0-4,10 (default {seeds})")
    p.add_argument("--duration", type=float, help="override every scenario's duration in seconds")
    p.add_argument(
        "--out", type=Path, default=Path(out), help=f"results folder (default {out}); re-running skips whole runs"
    )
    g = p.add_argument_group("execution")
    g.add_argument("--workers", type=int, default=None, help="local worker processes (default: number of CPUs)")
    g.add_argument(
        "--batched",
        action="store_true",
        help="step the seeds of one scenario and controller together (runner.run_batch)",
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
    if workers > 1 and not args.scheduler:
        from mlpfac.sweeps.worker import start_pool_server

        start_pool_server()  # the workers' fork server warms up while the runs are planned
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
            prows = paired_rows(jobs, oc.metrics)
            try:
                paths = write_tables(args.out, stem, rows, columns, meta) + write_paired(args.out, prows, meta)
                from mlpfac.plots import sweep_plots

                paths += sweep_plots(args.out, (stem,))  # <stem>.png beside the table
            except OSError as err:
                raise OutputError(
                    f"{_oserror(err, str(args.out))}; every run folder is whole, resume with: {cmd}"
                ) from None
    finally:
        if client is not None:
            client.close()
    print(markdown(rows, columns), end="")
    print("\n" + summary(prows), end="")
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
