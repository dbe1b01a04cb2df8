"""A robustness map at scale (``--vary`` with two axes). Not a test.

    python benchmarks/bench_map.py [--seeds 20] [--pair-runs 100] [--repeat 2] [--workers-only]

1. plan: every grid point of the map checked and built (the plant once per point), the time it takes;
2. the map: ``eight-wheel-radius`` (the MuJoCo robot), ``kanayama`` and ``oracle-kanayama``,
   ``--vary events.0.scale=1.0:2.0:10 --vary plant.pose_noise_std=0:0.004:5`` (50 points), 20 seeds,
   15 s: 2,000 runs with 2 workers (the command line's sweep, from plan to robustness.png); its wall
   time, the CPU time of the sweep and every process under it, runs per second, and against
   N x the per-run floor: N runs x control steps x bare MuJoCo physics per control step
   (``perf_floor.PhysicsFloor``: ``mj_step`` x substeps on the same MJCF, constant command;
   the best of interleaved blocks), over the 2 cores;
3. 2 workers against 1 on the first ``--pair-runs`` runs of the map (interleaved, the best of ``--repeat``),
   beside what the machine itself gives two processes against one (bare physics, nothing of mlpfac).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_sweep import machine_ratio, process_tree_cpu, report, side_by_side  # noqa: E402
from perf_floor import PhysicsFloor  # noqa: E402

from mlpfac.scenario.parse import load  # noqa: E402
from mlpfac.sweeps import engine  # noqa: E402
from mlpfac.sweeps.vary import parse_vary  # noqa: E402

SCENARIO, CONTROLLERS = "eight-wheel-radius", "kanayama,oracle-kanayama"
VARY = ["events.0.scale=1.0:2.0:10", "plant.pose_noise_std=0:0.004:5"]
DURATION = 15.0


def physics_floor_s() -> tuple[float, int]:
    """(bare physics seconds per control step, control steps per run) on the scenario's own MJCF."""
    scn = load(SCENARIO)
    cfg = scn.plant_config
    import mujoco

    dt = cfg.timestep or mujoco.MjModel.from_xml_path(str(cfg.path)).opt.timestep
    floor = PhysicsFloor(str(cfg.path), round(scn.T / dt))
    best = float("inf")
    for _ in range(7):
        floor.reset()
        t0 = time.process_time()
        floor.steps_nstep(500)
        best = min(best, (time.process_time() - t0) / 500)
    return best, round(DURATION / scn.T)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--pair-runs", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--workers-only", action="store_true", help="only 3: 2 workers against 1")
    a = ap.parse_args()
    seeds = f"0-{a.seeds - 1}"
    print(
        f"map: {SCENARIO} x {CONTROLLERS} x {' x '.join(VARY)} x seeds {seeds}, {DURATION:g} s ({os.cpu_count()} CPUs)"
    )

    t0 = time.perf_counter()
    jobs = engine.plan([SCENARIO], CONTROLLERS.split(","), list(range(a.seeds)), DURATION, parse_vary(VARY))
    plan_s = time.perf_counter() - t0
    report("1. plan: grid points checked and built [s]", plan_s, "-", None, f"({len(jobs)} runs, 50 points)")

    if a.workers_only:
        return workers(jobs, a.pair_runs, a.repeat, Path(tempfile.mkdtemp(prefix="bench-map-")))
    floor_step, steps = physics_floor_s()
    tmp = Path(tempfile.mkdtemp(prefix="bench-map-"))
    with process_tree_cpu() as spent:
        t0 = time.perf_counter()
        done = engine.sweep_folder([SCENARIO], CONTROLLERS, seeds, tmp / "map", duration=DURATION, workers=2,
                                   vary=VARY, progress=False)  # fmt: skip
        wall = time.perf_counter() - t0
    assert not done.outcome.errors and len(done.outcome.metrics) == len(jobs), "some run failed"
    n = len(jobs)
    floor_run = floor_step * steps
    report("2. the map with 2 workers, wall [s]", wall, "minutes", wall < 600, f"({n} runs, {n / wall:.1f} runs/s)")
    report(
        "   wall / (N x per-run floor / 2 cores)",
        wall / (n * floor_run / 2),
        "-",
        None,
        f"(per-run floor {floor_run * 1e3:.1f} ms = {steps} steps x {floor_step * 1e6:.1f} us bare physics)",
    )
    report("   CPU of the tree / (N x per-run floor)", spent[0] / (n * floor_run), "-", None, f"({spent[0]:.0f} CPU s)")

    workers(jobs, a.pair_runs, a.repeat, tmp)


def workers(jobs: list, runs: int, repeat: int, tmp: Path) -> None:
    sub = jobs[:runs]
    i = iter(range(10**6))

    def once(workers: int):
        return lambda: engine.execute(sub, tmp / f"w{workers}-{next(i)}", workers=workers, progress=False)

    t = side_by_side({1: once(1), 2: once(2)}, repeat)
    report("3. 2 workers / 1 worker (runs per second)", t[1] / t[2], ">= 1.9", t[1] / t[2] >= 1.9,
           f"({len(sub)} runs: {t[1]:.2f} s vs {t[2]:.2f} s)")  # fmt: skip
    ceiling = machine_ratio()
    report("   the machine: bare physics, 2 processes / 1", ceiling, "-", None, "(nothing of mlpfac's: the ceiling)")
    report("   the sweep's ratio / the machine's", t[1] / t[2] / ceiling, "-", None)


if __name__ == "__main__":
    main()
