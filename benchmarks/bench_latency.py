"""Time to result of whole commands, as a user waits for them. Not a test.

    python benchmarks/bench_latency.py [--repeats 5] [--cold N] [--this MLPFAC] [--before MLPFAC]
                                       [--only run|quick|workers]

1. ``mlpfac run eight-nominal`` with every output written (metrics.json, config.toml, figure1.png,
   run.rrd) against the floor process of ``benchmarks/latency_floor.py`` (start Python, import
   numpy and MuJoCo, load the robot, 2500 x (4 mj_step + one reference EKF update)), interleaved
   repeats, median wall time and the CPU time of each process and its children; the same with a
   fresh, empty ``NUMBA_CACHE_DIR`` for every run of the command (all from this checkout, or
   ``--this MLPFAC``, an install's ``mlpfac`` command: a regular install runs from the bytecode
   compiled when it was installed, where a checkout may be compiled again on every run under
   ``PYTHONDONTWRITEBYTECODE``; with ``--before MLPFAC``, another install's command in the same rounds); with
   ``--cold N``, N regular installs (``pip install .`` into a new venv), each timed
   on its first run and then warm. Targets: <= 2x the floor warm, <= 5x on the first run after an
   install.
2. ``mlpfac list``, ``mlpfac --help`` and two bad inputs (an unknown scenario, a bad flag value):
   median wall time, target < 0.3 s each.
3. A sweep worker's fixed cost: the CPU time (its own clock, so other load on the machine does not
   count) a local pool worker spends before and in its first run beyond what a warm run costs, for
   the sweep's pool (forked from a warm fork server) against fresh spawned interpreters; and the
   2-workers-vs-1 speedup on ``bench_sweep.py``'s 48 runs that these costs allow when the two
   cores are free (48 warm runs + 2 fixed costs shared by 2, against 48 warm runs in one process).

The floor script is ``benchmarks/latency_floor.py`` beside this file (``$LATENCY_FLOOR`` names another).
On a machine shared with other work, compare the CPU columns as well.
"""

from __future__ import annotations

import argparse
import os
import resource
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
MODEL = ROOT / "models" / "scene.xml"
MLPFAC = [sys.executable, "-m", "mlpfac.cli"]


def floor_script() -> Path:
    env = os.environ.get("LATENCY_FLOOR")
    return Path(env) if env else Path(__file__).resolve().with_name("latency_floor.py")


def timed(cmd: list[str], env: dict | None = None, ok: tuple[int, ...] = (0,)) -> tuple[float, float]:
    """Wall and CPU (user + system, the process and its children) seconds of one command."""
    if COLD_DISK:
        drop_page_cache()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode not in ok:
        sys.exit(f"failed (rc {r.returncode}): {shlex.join(cmd)}: {r.stderr.strip()[-300:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


COLD_DISK = False  # --cold-disk: every timed process reads its files from the disk


def drop_page_cache() -> None:
    """Write back and drop the kernel's page cache (clean pages, dentries, inodes): the next process
    reads everything from the disk."""
    os.sync()
    Path("/proc/sys/vm/drop_caches").write_text("3\n")


def line(name: str, samples: list[tuple[float, float]], ref: float | None = None, target: str = "") -> float:
    wall = statistics.median(w for w, _ in samples)
    cpu = statistics.median(c for _, c in samples)
    ratio = f"  {wall / ref:5.2f}x floor" if ref else ""
    print(f"  {name:<34} wall {wall:5.2f} s (min {min(w for w, _ in samples):4.2f})  cpu {cpu:5.2f} s{ratio}  {target}")
    return wall


def bench_run(repeats: int, cold: int, before: str | None, warm_only: bool = False, this: str | None = None) -> None:
    floor = [sys.executable, str(floor_script()), str(MODEL), "--child"]
    out = Path(tempfile.mkdtemp(prefix="bench-latency-"))
    runs = {"": [*([this] if this else MLPFAC), "run", "eight-nominal", "--out", str(out / "run")]}
    if before:  # another install's command, timed in the same rounds
        runs["before: "] = [before, "run", "eight-nominal", "--out", str(out / "before")]
    for cmd in runs.values():
        timed(cmd)  # the files read once (warm case)
    fl, warm, fresh = [], {k: [] for k in runs}, {k: [] for k in runs}
    for i in range(repeats):
        fl.append(timed(floor))
        for k, cmd in runs.items():
            warm[k].append(timed(cmd))
            if warm_only:
                continue
            cache = out / f"numba-{i}"
            fresh[k].append(timed(cmd, env=dict(os.environ, NUMBA_CACHE_DIR=str(cache))))
            shutil.rmtree(cache, ignore_errors=True)
    disk = ", the page cache dropped before each process" if COLD_DISK else ""
    print(f"mlpfac run eight-nominal, all outputs, {repeats} interleaved repeats{disk} (median):")
    ref = line("floor process", fl)
    cores = len(os.sched_getaffinity(0))
    for k in runs:
        line(f"{k}warm", warm[k], ref, "target <= 2x")
        cpu = statistics.median(c for _, c in warm[k])  # no schedule of its processes ends before its CPU time / cores
        print(
            f"  {k}its CPU time / {cores} cores:{'':<10} {cpu / cores:5.2f} s, {cpu / cores / ref:5.2f}x floor (a bound)"
        )
    # paired by round: what load on a shared machine does to both cancels
    pairs = {"this / floor": (warm[""], fl)} | ({"this / before": (warm[""], warm["before: "])} if before else {})
    for name, (a, b) in pairs.items():
        ratios = sorted(x[0] / y[0] for x, y in zip(a, b, strict=True))
        print(f"  {name}, per round: median {statistics.median(ratios):.2f} (range {ratios[0]:.2f}-{ratios[-1]:.2f})")
    if not warm_only:
        for k in runs:
            line(f"{k}fresh NUMBA_CACHE_DIR", fresh[k], ref, "target <= 5x")
    if cold:
        first, again, fl = [], [], []
        for i in range(cold):  # a new venv, `pip install .` (not timed), its first run, then warm runs
            venv = out / f"venv-{i}"
            subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
            subprocess.run([str(venv / "bin" / "pip"), "install", "-q", str(ROOT)], check=True, capture_output=True)
            cmd = [str(venv / "bin" / "mlpfac"), "run", "eight-nominal", "--out", str(out / f"installed-{i}")]
            fl.append(timed(floor))
            first.append(timed(cmd))
            for _ in range(repeats):
                fl.append(timed(floor))
                again.append(timed(cmd))
            shutil.rmtree(venv, ignore_errors=True)
        print(
            f"a regular install (`pip install .` into a new venv), {cold} install(s), {repeats} warm runs each (median):"
        )
        ref = line("floor process", fl)
        line("the first run after the install", first, ref, "target <= 5x")
        line("warm", again, ref, "target <= 2x")
    shutil.rmtree(out, ignore_errors=True)


def bench_quick(repeats: int) -> None:
    cases = {
        "mlpfac list": ([*MLPFAC, "list"], (0,)),
        "mlpfac --help": ([*MLPFAC, "--help"], (0,)),
        "mlpfac run nosuch (bad name)": ([*MLPFAC, "run", "nosuch"], (2,)),
        "mlpfac run ... --seed x (bad flag)": ([*MLPFAC, "run", "eight-nominal", "--seed", "x"], (2,)),
    }
    got: dict[str, list] = {k: [] for k in cases}
    for _ in range(repeats):
        for k, (cmd, ok) in cases.items():
            got[k].append(timed(cmd, ok=ok))
    print(f"commands that need no simulation, {repeats} interleaved repeats (median):")
    for k, samples in got.items():
        line(k, samples, target="target < 0.3 s")


def _task_cpu(jobs: list) -> float:
    """A pool task: this worker's CPU seconds so far (imports, its first run) after running ``jobs``."""
    from mlpfac.sweeps.worker import run_task

    run_task(jobs)
    t = os.times()
    return t.user + t.system


def bench_workers(repeats: int) -> None:
    import concurrent.futures as cf
    import multiprocessing as mp

    from mlpfac.sweeps import engine as sweep
    from mlpfac.sweeps.worker import _worker_init, one_blas_thread, pool_context

    jobs = sweep.plan(["eight-nominal"], ["adaptive"], list(range(3)), 25.0)
    c0 = time.process_time()
    for j in jobs:  # warm runs in this process: what a run costs
        _task_cpu([j])
    warm = (time.process_time() - c0) / len(jobs)
    print(f"sweep workers, eight-nominal adaptive 25 s runs; a warm run costs {warm:.3f} s CPU:")
    for name, ctx in (("spawned (before)", mp.get_context("spawn")), ("forked from the fork server", pool_context())):
        fixed = []
        for _ in range(repeats):
            with one_blas_thread():
                pool = cf.ProcessPoolExecutor(
                    1, mp_context=ctx, initializer=_worker_init, initargs=(os.getpid(), dict(os.environ))
                )
                fixed.append(pool.submit(_task_cpu, [jobs[0]]).result() - warm)
            pool.shutdown()
        cost = statistics.median(fixed)
        speedup = 2 * 48 * warm / (48 * warm + 2 * cost)
        print(f"  {name:<34} fixed cost {cost:5.2f} s CPU per worker -> 2 vs 1 worker at most {speedup:.2f}x")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument(
        "--cold",
        type=int,
        default=0,
        metavar="N",
        help="also the first run after N fresh installs (needs the package index)",
    )
    ap.add_argument("--this", metavar="MLPFAC", help="the run: an install's mlpfac command instead of this checkout's")
    ap.add_argument("--before", metavar="MLPFAC", help="another install's mlpfac command, timed beside this one")
    ap.add_argument("--only", choices=("run", "quick", "workers"))
    ap.add_argument("--warm-only", action="store_true", help="the run: warm only, no fresh NUMBA_CACHE_DIR")
    ap.add_argument(
        "--cold-disk",
        action="store_true",
        help="drop the page cache before every timed process (root, Linux): imports read from the disk",
    )
    a = ap.parse_args()
    if a.cold_disk:
        global COLD_DISK
        try:
            drop_page_cache()
        except OSError as err:
            ap.error(f"--cold-disk: cannot drop the page cache ({err.strerror}): needs root on Linux")
        COLD_DISK = True
    if a.only in (None, "run"):
        bench_run(a.repeats, a.cold, a.before, a.warm_only, a.this)
    if a.only in (None, "quick"):
        bench_quick(a.repeats)
    if a.only in (None, "workers"):
        bench_workers(a.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
