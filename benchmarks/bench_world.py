"""What the world costs a control step: a Kanayama run on a scenario with terrain (default
``eight-bumps``) against the same run on ``eight-nominal``, both against the same fixed floor. Not a test.

    python benchmarks/bench_world.py [--scenario eight-bumps] [--rounds 7]

One process, single-threaded BLAS, CPU clock, interleaved rounds (the minimum kept, the median
beside it), as ``benchmarks/perf_floor.py``: ``floor`` is its fixed physics floor (bare ``mj_step``
x substeps on eight-nominal's MJCF, a constant command); ``nominal`` and ``world`` are the whole
compiled runs (``runner.run``, one seed) per control step. ``world / nominal`` is the figure of
docs/benchmarks.md (target <= 1.3).
"""

from __future__ import annotations

import os

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_k] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from perf_floor import PhysicsFloor, interleaved  # noqa: E402

from mlpfac.loop.factory import make_plant  # noqa: E402
from mlpfac.loop.runner import run  # noqa: E402
from mlpfac.scenario.parse import load  # noqa: E402
from mlpfac.scenario.reference import sample  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="eight-bumps")
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()

    nominal = load("eight-nominal").with_overrides(controller="kanayama")
    world = load(args.scenario).with_overrides(controller="kanayama")
    plant = make_plant(nominal, sample(nominal.reference, [0.0, nominal.T]))
    floor = PhysicsFloor(nominal.plant_config.model, plant.n_substeps)
    steps = {}

    def whole(scn):
        def timed() -> float:
            c0 = time.process_time()
            r = run(scn)
            steps[scn.name] = r.n
            return (time.process_time() - c0) / r.n

        return timed

    fns = {"floor": lambda: floor.per_step(nominal.steps), "nominal": whole(nominal), "world": whole(world)}
    for fn in fns.values():  # the kernels loaded, the robots read
        fn()
    best, med = interleaved(fns, args.rounds)
    for k in fns:
        print(f"  {k:<8} {best[k]:7.1f} us/step (median {med[k]:.1f})")
    f = best["floor"]
    print(f"  nominal / floor        {best['nominal'] / f:5.2f}")
    print(f"  world / floor          {best['world'] / f:5.2f}   ({args.scenario})")
    print(f"  world / nominal        {best['world'] / best['nominal']:5.2f}   (target <= 1.3)")
    print(f"  load average {os.getloadavg()[0]:.2f}  ({steps[world.name]} control steps of {world.T:g} s, "
          f"{plant.n_substeps} substeps)")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
