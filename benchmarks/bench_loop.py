"""Where a kanayama run's time goes: the loop around physics, against two physics measures. Not a test.

    python benchmarks/bench_loop.py [--scenario eight-nominal] [--rounds 7]

One process, single-threaded BLAS, CPU clock, interleaved rounds (the minimum kept, the median
beside it), as ``benchmarks/perf_floor.py``. Three figures per control step:

- ``floor``: ``perf_floor``'s fixed floor, bare ``mj_step`` x substeps on the scenario's MJCF with
  a constant command (the robot drives straight);
- ``replay``: the same physics calls the plant makes (``mj_step2``, ``mj_step(nstep=n-1)``,
  ``mj_step1``) through the Python bindings, fed the wheel commands that a kanayama run recorded,
  from the run's own initial state: the physics of that very motion (turning, contacts changing)
  and three Python calls a step. The replay's final pose is checked against the run's, so it is the
  same trajectory;
- ``run``: the whole kanayama run (``runner.run``), one seed: the closed loop compiled between
  events (``mlpfac.loop.compiled``), MuJoCo's C functions called from the kernel.

``run / floor`` is the target of the loop around physics (<= 1.5); ``replay / floor`` is how much
the motion's physics takes, with the bindings' calls; ``(run - replay) / floor`` is what our loop
adds beyond that (below zero when the compiled loop costs less than the bindings' three calls).
"""

from __future__ import annotations

import os

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_k] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from perf_floor import PhysicsFloor, interleaved  # noqa: E402

from mlpfac.loop.closed_loop import seeded_generators  # noqa: E402
from mlpfac.loop.factory import make_plant  # noqa: E402
from mlpfac.loop.runner import run  # noqa: E402
from mlpfac.scenario.parse import load  # noqa: E402
from mlpfac.scenario.reference import sample  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="eight-nominal")
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()

    scn = load(args.scenario).with_overrides(controller="kanayama")
    if scn.events:
        sys.exit(f"{args.scenario}: a scenario without events, please (the replay does not apply them)")
    rec = run(scn)  # also loads the compiled kernels
    wheel_cmd = np.ascontiguousarray(rec.plant["wheel_cmd"][: rec.n])
    N = rec.n

    ref = sample(scn.reference, np.arange(scn.steps + 1) * scn.T)
    plant = make_plant(scn, ref)
    q0, u0 = scn.initial_state(ref)
    floor = PhysicsFloor(scn.plant_config.model, plant.n_substeps)

    def replay() -> float:
        plant.reset(q0, seeded_generators(scn.seed)[1], u0)
        m, d, n = plant.model, plant.data, plant.n_substeps
        (al, ar), (cl, cr) = plant.robot.acts, plant.robot.act_per_wheel
        ctrl, step, step1, step2 = d.ctrl, mujoco.mj_step, mujoco.mj_step1, mujoco.mj_step2
        c0 = time.process_time()
        for wl, wr in wheel_cmd.tolist():
            ctrl[al], ctrl[ar] = cl * wl, cr * wr
            step2(m, d)
            step(m, d, nstep=n - 1)
            step1(m, d)
        dt = (time.process_time() - c0) / N
        end = d.site_xpos[plant.robot.site][:2]
        final = rec.pose[N - 1, :2]  # the pose before the last command; the replay ends one step later
        if np.linalg.norm(end - final) > 0.05:
            sys.exit(f"the replay left the run's path ({np.linalg.norm(end - final):.3f} m apart)")
        return dt

    def whole_run() -> float:
        c0 = time.process_time()
        r = run(scn)
        assert r.n == N
        return (time.process_time() - c0) / N

    fns = {"floor": lambda: floor.per_step(N), "replay": replay, "run": whole_run}
    best, med = interleaved(fns, args.rounds)
    for k in fns:
        print(f"  {k:<8} {best[k]:7.1f} us/step (median {med[k]:.1f})")
    f = best["floor"]
    print(f"  run / floor            {best['run'] / f:5.2f}   (target <= 1.5)")
    print(f"  replay / floor         {best['replay'] / f:5.2f}   (the motion's physics, through the bindings)")
    print(f"  (run - replay) / floor {(best['run'] - best['replay']) / f:5.2f}   (our loop beyond the replay)")
    print(f"  load average {os.getloadavg()[0]:.2f}  ({N} control steps of {scn.T:g} s, {plant.n_substeps} substeps)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
