"""Experiments at scale: scenarios x controllers x seeds -> run folders -> one table.

``mlpfac sweep`` and ``mlpfac compare`` are one engine with two tables:

1. **Plan** (:func:`plan`): every scenario is loaded and every (scenario, controller, seed) is
   resolved with :meth:`Scenario.with_overrides` before anything runs, so bad input is a
   :class:`ConfigError` and no run folder exists yet.
2. **Execute** (:func:`execute`): runs already done are skipped; the rest go to this process
   (``workers=1``), a local process pool, or a Dask cluster (``scheduler``), one run or one batch
   of seeds (``batched``, see :mod:`mlpfac.batch`) per task. Workers compute and return the
   metrics; **the client writes every run folder**, so Dask workers need no shared disk::

       DIR/<scenario>/<controller>/seed-0003/config.toml    the scenario as resolved
       DIR/<scenario>/<controller>/seed-0003/run.rrd        only with save_rrd
       DIR/<scenario>/<controller>/seed-0003/metrics.json   = runner.metrics(rec), written last

   Each file goes through a temporary file and ``os.replace``; metrics.json comes last, so a
   folder with metrics.json is whole. A run counts as done when metrics.json exists and
   config.toml equals the resolved scenario; a folder whose config differs is run again.
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
import json
import math
import os
import shlex
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.exceptions import ConfigError
from mlpfac.outputs import sigint_deferred, write_atomic, write_run_folder

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
PHASES = ("before", "after")
COMPARE_CONTROLLERS = ("adaptive", "corradini", "kanayama")


# --------------------------------------------------------------------------------------------
# Input


def parse_seeds(text: str) -> list[int]:
    """``"0-99"``, ``"3"``, ``"0,2,5"``, ``"0-4,10"`` -> sorted distinct seeds; ``"5-2"`` is an error."""
    seeds: set[int] = set()
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
            for seed in seeds:
                scn = base.with_overrides(controller=ctrl, seed=seed, duration=duration)
                jobs.append(Job(scn.name, scn.controller, seed, scn.source, scn.table, to_toml(scn.table)))
    return jobs


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


def run_task(jobs: list[Job], batched: bool = False, save_rrd: bool = False) -> list[dict]:
    """Run ``jobs`` (one, or seeds of one scenario and controller when ``batched``).

    Returns one result per job: {"key", "metrics", "rrd" (bytes or None), "error" (str or None)}.
    An interrupted run raises KeyboardInterrupt: it must never be written as done.
    """
    from mlpfac.runner import metrics
    from mlpfac.scenario import parse

    if batched and len(jobs) > 1 and not save_rrd:
        from mlpfac.runner import run_batch

        try:
            recs = run_batch([parse(j.table, j.source) for j in jobs])
        except KeyboardInterrupt:
            raise
        except Exception as err:  # a bug, not a divergence: report it per run
            return [{"key": j.key, "metrics": None, "rrd": None, "error": _error_text(err)} for j in jobs]
        return [
            {"key": j.key, "metrics": metrics(r), "rrd": None, "error": None} for j, r in zip(jobs, recs, strict=True)
        ]
    return [_run_one(j, save_rrd) for j in jobs]


def _run_one(job: Job, save_rrd: bool) -> dict:
    from mlpfac.runner import metrics, run
    from mlpfac.scenario import parse

    rrd_path = sink = None
    try:
        scn = parse(job.table, job.source)
        if save_rrd:
            sink, rrd_path = _make_sink(job)
        rec = run(scn, sink=sink)
        if rec.status == "interrupted":
            raise KeyboardInterrupt
        rrd = rrd_path.read_bytes() if rrd_path is not None and rrd_path.exists() else None
        return {"key": job.key, "metrics": metrics(rec), "rrd": rrd, "error": None}
    except KeyboardInterrupt:
        raise
    except Exception as err:
        return {"key": job.key, "metrics": None, "rrd": None, "error": _error_text(err)}
    finally:
        if rrd_path is not None:
            rrd_path.unlink(missing_ok=True)


def _make_sink(job: Job):
    """A rerun sink saving to a temporary file (its bytes go back to the client); (None, None) without mlpfac.log."""
    try:
        from mlpfac import log
    except ImportError:
        return None, None
    fd, tmp = tempfile.mkstemp(suffix=".rrd", prefix="mlpfac-")
    os.close(fd)
    path = Path(tmp)
    sink = log.make_sink(
        save=path,
        recording_name=f"{job.scenario} / {job.controller} / seed {job.seed}",
        recording_id=f"{job.scenario}-{job.controller}-{job.seed}",
    )
    return sink, path


def _error_text(err: BaseException) -> str:
    import traceback

    return "".join(traceback.format_exception(err))


def _ignore_sigint() -> None:
    """Pool workers leave Ctrl-C to the parent, which stops them; a half run is never returned."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


# --------------------------------------------------------------------------------------------
# Results folders


def write_result(out: Path, job: Job, result: dict) -> None:
    """config.toml, run.rrd, then metrics.json (its presence means the folder is whole); or error.txt."""
    d = job.folder(out)
    with sigint_deferred():  # a Ctrl-C now waits for the folder to be whole
        d.mkdir(parents=True, exist_ok=True)
        if result["error"] is not None:
            (d / "metrics.json").unlink(missing_ok=True)  # a stale run being replaced is not whole
            write_atomic(d / "config.toml", job.config)
            write_atomic(d / "error.txt", result["error"])
            return
        (d / "error.txt").unlink(missing_ok=True)
        write_run_folder(d, job.config, result["metrics"], result.get("rrd"))


def load_done(out: Path, job: Job) -> dict | None:
    """The metrics of ``job`` if its folder is whole and was run with the same configuration."""
    d = job.folder(out)
    try:
        if (d / "config.toml").read_text() != job.config:
            return None
        return json.loads((d / "metrics.json").read_text())
    except (OSError, ValueError):
        return None


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
    wall_s: float = 0.0


def make_tasks(jobs: list[Job], batched: bool, batch_size: int) -> list[list[Job]]:
    """One job per task, or with ``batched`` up to ``batch_size`` seeds of one scenario and controller."""
    if not batched:
        return [[j] for j in jobs]
    groups: dict[tuple[str, str], list[Job]] = {}
    for j in jobs:
        groups.setdefault((j.scenario, j.controller), []).append(j)
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
) -> Outcome:
    """Run the jobs not done yet; write each run's folder as its result arrives.

    ``client`` is a ``dask.distributed.Client`` or None (local). ``progress``: None shows a bar
    only when stderr is a terminal. KeyboardInterrupt stops the workers and returns with
    ``interrupted=True``; every folder written so far is whole.
    """
    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    done: dict[tuple, dict] = {}
    todo: list[Job] = []
    for j in jobs:
        m = load_done(out, j)
        if m is None:
            todo.append(j)
        else:
            done[j.key] = m
    outcome = Outcome(jobs, done, {}, skipped=len(done), ran=0)
    by_key = {j.key: j for j in todo}
    tasks = make_tasks(todo, batched, batch_size)
    bar = _progress(len(todo), progress)
    failed = 0
    try:
        if client is not None:
            results = _dask_results(client, tasks, batched, save_rrd)
        elif workers <= 1 or len(tasks) <= 1:
            results = (run_task(t, batched, save_rrd) for t in tasks)
        else:
            results = _pool_results(tasks, workers, batched, save_rrd)
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
    except KeyboardInterrupt:
        outcome.interrupted = True
    finally:
        if bar is not None:
            bar.close()
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


def _pool_results(tasks: list[list[Job]], workers: int, batched: bool, save_rrd: bool) -> Iterator[list[dict]]:
    """Results of ``tasks`` from a local process pool, as they finish; at most 2 tasks per worker in flight."""
    import concurrent.futures as cf

    pool = cf.ProcessPoolExecutor(max_workers=min(workers, len(tasks)), initializer=_ignore_sigint)
    pending: set[cf.Future] = set()
    queue = iter(tasks)
    try:
        for t in queue:
            pending.add(pool.submit(run_task, t, batched, save_rrd))
            if len(pending) >= 2 * workers:
                break
        while pending:
            finished, pending = cf.wait(pending, return_when=cf.FIRST_COMPLETED)
            for f in finished:
                nxt = next(queue, None)
                if nxt is not None:
                    pending.add(pool.submit(run_task, nxt, batched, save_rrd))
                yield f.result()
        pool.shutdown()
    except BaseException:
        for f in pending:
            f.cancel()
        for p in list((getattr(pool, "_processes", None) or {}).values()):
            p.terminate()  # a running run is lost; its folder was never written
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


def _run_cli(args: argparse.Namespace, stem: str, columns) -> int:
    """Validate everything, then run; 0 done, 1 some run raised, 2 bad input (ConfigError), 130 interrupted."""
    seeds = parse_seeds(args.seeds)
    controllers = parse_controllers(args.controllers)
    workers = (os.cpu_count() or 1) if args.workers is None else args.workers
    if workers < 1:
        raise ConfigError("--workers", f"need at least 1, got {workers}")
    if args.batch_size < 1:
        raise ConfigError("--batch-size", f"need at least 1, got {args.batch_size}")
    jobs = plan(args.scenarios, controllers, seeds, args.duration)
    check_writable(args.out)
    client = connect(args.scheduler, args.scheduler_timeout) if args.scheduler else None
    try:
        oc = execute(
            jobs,
            args.out,
            workers=workers,
            client=client,
            batched=args.batched,
            batch_size=args.batch_size,
            save_rrd=args.save_rrd,
        )
    finally:
        if client is not None:
            client.close()
    rows = aggregate(jobs, oc.metrics)
    if oc.interrupted:
        cmd = shlex.join(["mlpfac", *sys.argv[1:]]) if sys.argv[1:] else f"mlpfac {stem} ..."
        print(
            f"mlpfac: interrupted; {len(oc.metrics)} of {len(jobs)} runs are done and kept in {args.out}.\n"
            f"Resume with the same command:\n  {cmd}",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    meta = {
        "command": stem,
        "scenarios": list(args.scenarios),
        "controllers": sorted({j.controller for j in jobs}),
        "seeds": args.seeds,
        "duration": args.duration,
        "runs": len(jobs),
    }
    paths = write_tables(args.out, stem, rows, columns, meta)
    print(markdown(rows, columns), end="")
    print(
        f"{len(jobs)} runs ({oc.skipped} already done, {oc.ran} run now in {oc.wall_s:.1f} s)"
        f" -> {', '.join(map(str, paths))}"
    )
    for key, err in oc.errors.items():
        last = err.strip().splitlines()[-1] if err.strip() else "error"
        print(
            f"mlpfac: error: run {key[0]} / {key[1]} / seed {key[2]} raised: {last} (see error.txt; re-run to retry)",
            file=sys.stderr,
        )
    return EXIT_FAILED if oc.errors else EXIT_OK
