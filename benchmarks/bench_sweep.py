"""Costs of the experiments-at-scale path, each with its target. Not a test.

    python benchmarks/bench_sweep.py [--quick]

The per-step costs of one run against fixed floors (bare MuJoCo physics, a reference EKF update
written independently in numpy) are ``benchmarks/perf_floor.py``'s job. This script measures
what a sweep adds, side by side in one process (interleaved repeats, the minimum kept):

1. sweep throughput with 2 workers vs 1 (adaptive runs on the MuJoCo robot, eight-nominal), the
   fixed cost of starting the workers included, and the CPU time of the sweep and every process
   under it (its fork server's workers too);
2. batched seeds: ``runner.run_batch`` of 64 seeds of ``adaptive`` and ``adaptive-best``, CPU time
   per seed-step against one reference short-form EKF update of the same size (``perf_floor``'s
   ``UpdateFloor``, alpha = 171, m = 3; target <= 1.2: everything but the update amortised), and
   against the same seeds one at a time;
3. peak memory of a 100-seed sweep: ``mlpfac sweep`` in a child process, the RSS of it and all its
   workers summed and sampled every 20 ms with psutil (plus getrusage maxrss of the largest one).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

sys.path.insert(0, str(Path(__file__).resolve().parent))

from perf_floor import UpdateFloor  # noqa: E402

from mlpfac.loop.runner import run, run_batch  # noqa: E402
from mlpfac.scenario.parse import load  # noqa: E402
from mlpfac.sweeps import engine as sweep  # noqa: E402

RESULTS: list[tuple[str, str, bool | None]] = []


def report(name: str, value: float, target: str, met: bool | None, detail: str = "") -> None:
    tag = {True: "met", False: "MISSED", None: "-"}[met]
    print(f"  {name:<48} {value:8.2f}   target {target:<10} {tag:<6} {detail}", flush=True)
    RESULTS.append((name, f"{value:.2f}", met))


def side_by_side(fns: dict, repeat: int) -> dict[str, float]:
    """Each callable timed ``repeat`` times, interleaved; the minimum per callable (seconds)."""
    best = {k: float("inf") for k in fns}
    for _ in range(repeat):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            best[k] = min(best[k], time.perf_counter() - t0)
    return best


# --------------------------------------------------------------------------------------------


@contextlib.contextmanager
def process_tree_cpu(every: float = 0.05):
    """CPU seconds of this process and of every process under it while the block runs (a list
    holding one number, filled on exit). Workers forked by a fork server are the server's children,
    never reaped by this process, so getrusage's RUSAGE_CHILDREN misses them: each descendant's
    CPU time is sampled every ``every`` seconds and its last value kept (psutil; without it, this
    process and the children it reaped only)."""
    import resource

    def cpu(who: int) -> float:
        r = resource.getrusage(who)
        return r.ru_utime + r.ru_stime

    try:
        import psutil
    except ImportError:
        psutil = None
    spent, seen, stop = [0.0], {}, threading.Event()
    before = {c.pid: sum(c.cpu_times()[:2]) for c in psutil.Process().children(recursive=True)} if psutil else {}

    def sample():
        while not stop.is_set():
            for c in psutil.Process().children(recursive=True):
                with contextlib.suppress(psutil.Error):
                    seen[c.pid] = sum(c.cpu_times()[:2]) - before.get(c.pid, 0.0)
            stop.wait(every)

    th = threading.Thread(target=sample, daemon=True) if psutil else None
    own0, reaped0 = cpu(resource.RUSAGE_SELF), cpu(resource.RUSAGE_CHILDREN)
    if th:
        th.start()
    try:
        yield spent
    finally:
        stop.set()
        if th:
            th.join()
        children = sum(seen.values()) if th else cpu(resource.RUSAGE_CHILDREN) - reaped0
        spent[0] = cpu(resource.RUSAGE_SELF) - own0 + children


def _physics(steps: int) -> float:
    """Wall seconds of ``steps`` bare ``mj_step`` calls of the shipped robot's MJCF, in this process."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(ROOT / "models" / "scene.xml"))
    d = mujoco.MjData(m)
    t0 = time.perf_counter()
    mujoco.mj_step(m, d, nstep=steps)
    return time.perf_counter() - t0


def machine_ratio(steps: int = 200_000, repeat: int = 2) -> float:
    """What this machine gives two processes against one, with nothing of mlpfac's: the same bare
    MuJoCo physics run in two forked processes at once against one alone (throughput ratio, the best
    of ``repeat``). Two cores that slow each other (shared caches, memory bandwidth, a host's other
    guests) cap any two-worker sweep below 2 by this much."""
    import multiprocessing as mp

    best = 0.0
    with mp.get_context("fork").Pool(2) as pool:
        for _ in range(repeat):
            one = _physics(steps)
            t0 = time.perf_counter()
            pool.map(_physics, [steps, steps])
            best = max(best, 2 * one / (time.perf_counter() - t0))
    return best


def bench_sweep(seeds: int, duration: float, repeat: int) -> None:
    print(f"1. sweep throughput ({os.cpu_count()} CPUs)")
    jobs = sweep.plan(["eight-nominal"], ["adaptive"], list(range(seeds)), duration)
    tmp = Path(tempfile.mkdtemp(prefix="bench-sweep-"))
    i = iter(range(10**6))

    def once(workers: int):
        return lambda: sweep.execute(jobs, tmp / f"w{workers}-{next(i)}", workers=workers, progress=False)

    cpu_s = {}

    def timed(workers: int):
        fn = once(workers)

        def go():
            with process_tree_cpu() as spent:
                fn()
            cpu_s[workers] = spent[0]

        return go

    t = side_by_side({1: timed(1), 2: timed(2)}, repeat)
    ratio = t[1] / t[2]
    detail = (
        f"({seeds} runs of {duration:g} s: {t[1]:.2f} s vs {t[2]:.2f} s wall; "
        f"CPU s of the last repeat {cpu_s[1]:.2f} vs {cpu_s[2]:.2f})"
    )
    report("2 workers / 1 worker (runs per second)", ratio, ">= 1.9", ratio >= 1.9, detail)
    ceiling = machine_ratio()
    report("   the machine: bare physics, 2 processes / 1", ceiling, "-", None, "(nothing of mlpfac's: the ceiling)")
    report("   the sweep's ratio / the machine's", ratio / ceiling, "-", None)


def bench_batched(batch_seeds: int, batch_duration: float, repeat: int) -> None:
    print(f"2. {batch_seeds} seeds batched (runner.run_batch), CPU time, one process")
    floor = UpdateFloor(171, 3, 1e-3, 0.1)
    steps = 2000

    def update() -> float:
        floor.reset()
        c = time.process_time()
        floor.short(steps)
        return (time.process_time() - c) / steps

    for ctrl in ("adaptive", "adaptive-best"):
        scns = [
            load("paper").with_overrides(controller=ctrl, seed=s, duration=batch_duration) for s in range(batch_seeds)
        ]
        seed_steps = batch_seeds * scns[0].steps
        best = {"batch": float("inf"), "one": float("inf"), "update": float("inf")}
        for _ in range(repeat):
            c = time.process_time()
            recs = run_batch(scns)
            best["batch"] = min(best["batch"], (time.process_time() - c) / seed_steps)
            best["update"] = min(best["update"], update())
            c = time.process_time()
            for s in scns:
                run(s)
            best["one"] = min(best["one"], (time.process_time() - c) / seed_steps)
        ok = sum(r.status == "ok" for r in recs)
        ratio = best["batch"] / best["update"]
        report(
            f"batched {ctrl} per seed-step / reference update",
            ratio,
            "<= 1.2",
            ratio <= 1.2,
            f"({best['batch'] * 1e6:.1f} us vs {best['update'] * 1e6:.1f} us; {ok}/{batch_seeds} ok)",
        )
        report(
            f"one at a time / batched, {ctrl}",
            best["one"] / best["batch"],
            "-",
            None,
            f"({best['one'] * 1e6:.1f} us vs {best['batch'] * 1e6:.1f} us per seed-step)",
        )


def bench_memory(seeds: int, duration: float) -> None:
    print(f"3. peak memory of a {seeds}-seed sweep (mlpfac sweep in a child process, 2 workers)")
    try:
        import psutil
    except ImportError:
        psutil = None
    out = Path(tempfile.mkdtemp(prefix="bench-mem-"))
    cmd = [
        sys.executable,
        "-m",
        "mlpfac.cli",
        "sweep",
        "paper",
        "--seeds",
        f"0-{seeds - 1}",
        "--duration",
        str(duration),
        "--workers",
        "2",
        "--out",
        str(out),
    ]
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    peak = [0]

    def sample_tree():
        proc = psutil.Process(p.pid)
        while p.poll() is None:
            try:
                total = proc.memory_info().rss + sum(c.memory_info().rss for c in proc.children(recursive=True))
                peak[0] = max(peak[0], total)
            except psutil.Error:
                pass
            time.sleep(0.02)

    th = threading.Thread(target=sample_tree) if psutil else None
    t0 = time.perf_counter()
    if th:
        th.start()
    p.wait()
    if th:
        th.join()
    wall = time.perf_counter() - t0
    import resource

    child_max = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024  # the largest single child
    if psutil:
        gib = peak[0] / 2**30
        report(
            "peak RSS, sweep process + workers [GiB]",
            gib,
            "< 1",
            gib < 1.0,
            f"(psutil, summed, 20 ms samples; {wall:.1f} s; "
            f"largest single process {child_max / 2**20:.0f} MiB by getrusage)",
        )
    else:
        report(
            "peak RSS of the largest process [GiB]",
            child_max / 2**30,
            "< 1",
            None,
            "(psutil missing: getrusage maxrss, not summed)",
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes, fewer repeats (about a minute)")
    args = ap.parse_args()
    q = args.quick
    print(
        f"numpy {np.__version__}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} "
        "(min of interleaved repeats)"
    )
    bench_sweep(seeds=8 if q else 48, duration=5.0 if q else 25.0, repeat=2)
    bench_batched(batch_seeds=64, batch_duration=2.0 if q else 5.0, repeat=2 if q else 3)
    bench_memory(seeds=100, duration=5.0 if q else 25.0)
    missed = [n for n, _, met in RESULTS if met is False]
    print(f"\n{len(missed)} target(s) missed" + (": " + "; ".join(missed) if missed else ""))


if __name__ == "__main__":
    main()
