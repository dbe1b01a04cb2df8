"""What a pose source costs a control step: the same run with ``pose_source = "truth"``, "odometry"
(+ gyro) and "fused" (10 Hz fixes, 0.1 s late), against the physics floor. Not a test.

    python benchmarks/bench_sensing.py [--scenario eight-nominal] [--controllers kanayama,adaptive] [--rounds 7]

One process, single-threaded BLAS, CPU clock, interleaved rounds (the minimum kept, the median
beside it), as ``benchmarks/bench_loop.py``: per control step, ``floor`` (``perf_floor``'s bare
``mj_step`` x substeps on the scenario's MJCF), then each source's whole run (``runner.run``, one
seed, compiled between events). The target: a step of ``"fused"`` costs at most 1.2x one of
``"truth"``.
"""

from __future__ import annotations

import os

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_k] = "1"

import argparse  # noqa: E402
import copy  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from perf_floor import PhysicsFloor, interleaved  # noqa: E402

from mlpfac.loop.factory import make_plant  # noqa: E402
from mlpfac.loop.runner import run  # noqa: E402
from mlpfac.scenario.parse import load, parse  # noqa: E402
from mlpfac.scenario.reference import sample  # noqa: E402

SOURCES = {
    "truth": {},
    "odometry": {"pose_source": "odometry", "encoder_cpr": 4096},
    "odometry+gyro": {"pose_source": "odometry", "encoder_cpr": 4096, "gyro": True, "gyro_noise": 0.01},
    "fused": {"pose_source": "fused", "encoder_cpr": 4096, "fix_rate_hz": 10.0, "fix_latency_s": 0.1},
    "fused+gyro": {
        "pose_source": "fused",
        "encoder_cpr": 4096,
        "gyro": True,
        "gyro_noise": 0.01,
        "fix_rate_hz": 10.0,
        "fix_latency_s": 0.1,
    },  # fmt: skip
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="eight-nominal")
    ap.add_argument("--controllers", default="kanayama,adaptive")
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()

    base = load(args.scenario)
    runs = {}
    for ctrl in args.controllers.split(","):
        for name, keys in SOURCES.items():
            table = copy.deepcopy(base.table)
            table.pop("provenance", None)
            if keys:
                table["plant"].pop("pose_noise_std", None)
            table["plant"] |= keys
            table.setdefault("controller", {})["name"] = ctrl
            runs[f"{ctrl} {name}"] = parse(table, base.source)
    first = next(iter(runs.values()))
    plant = make_plant(first, sample(first.reference, [0.0]))
    floor = PhysicsFloor(first.plant_config.model, plant.n_substeps)
    N = first.steps
    for scn in runs.values():
        run(scn)  # the kernels loaded

    def whole(scn):
        def go() -> float:
            c0 = time.process_time()
            r = run(scn)
            assert r.n == N, r.reason
            return (time.process_time() - c0) / N

        return go

    fns = {"floor": lambda: floor.per_step(N)} | {k: whole(s) for k, s in runs.items()}
    best, med = interleaved(fns, args.rounds)
    f = best["floor"]
    for k in fns:
        print(f"  {k:<24} {best[k]:7.1f} us/step (median {med[k]:6.1f})  / floor {best[k] / f:5.2f}")
    for ctrl in args.controllers.split(","):
        truth = best[f"{ctrl} truth"]
        for name in list(SOURCES)[1:]:
            print(f"  {ctrl} {name} / truth{'':<{16 - len(name)}} {best[f'{ctrl} {name}'] / truth:5.2f}"
                  + ("   (target <= 1.2)" if name == "fused" else ""))  # fmt: skip
    print(f"  load average {os.getloadavg()[0]:.2f}  ({N} control steps of {first.T:g} s, {plant.n_substeps} substeps)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
