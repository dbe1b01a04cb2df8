"""What an environment's step costs, one robot and N robots, against the physics floor. Not a test.

    python benchmarks/bench_envs.py [--scenario eight-nominal] [--envs 16] [--episodes 2] [--rounds 3]

One process, single-threaded BLAS, CPU clock, interleaved rounds (the minimum kept, the median
beside it), as ``benchmarks/perf_floor.py``. Each figure is CPU time per control step of one robot,
whole episodes (reset included) of a feed-forward agent (the action is the reference's (v_r,
omega_r), read from the observation):

- ``floor``: ``perf_floor``'s fixed floor, bare ``mj_step`` x substeps on the scenario's MJCF;
- ``single``: ``gymnasium.make("mlpfac/Track-v0")`` (gymnasium's wrappers included), one robot;
- ``vector``: ``gymnasium.make_vec(..., num_envs=N, vectorization_mode="vector_entry_point")``,
  N robots stepped by one kernel call a step, per robot;
- ``run``: ``mlpfac run`` of Kanayama's law (the compiled closed loop), for scale.

``vector / single`` is what the vector environment saves per env-episode (the target: <= 0.5 at
N = 16); ``single / floor`` and ``vector / floor`` what each costs beyond the physics.
"""

from __future__ import annotations

import os

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_k] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import gymnasium  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from perf_floor import PhysicsFloor, interleaved  # noqa: E402

import mlpfac.envs  # noqa: E402, F401 (registers mlpfac/Track-v0)
from mlpfac.loop.factory import make_plant  # noqa: E402
from mlpfac.loop.runner import reference, run  # noqa: E402
from mlpfac.scenario.parse import load  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="eight-nominal")
    ap.add_argument("--envs", type=int, default=16)
    ap.add_argument("--episodes", type=int, default=2, help="episodes of each robot a round")
    ap.add_argument("--duration", type=float, default=5.0, help="seconds of an episode")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    N, kw = args.envs, {"scenario": args.scenario, "duration": args.duration}

    scn = load(args.scenario).with_overrides(controller="kanayama", duration=args.duration)
    plant = make_plant(scn, reference(scn)[0])
    floor = PhysicsFloor(scn.plant_config.model, plant.n_substeps)
    steps = scn.steps
    single_env = gymnasium.make("mlpfac/Track-v0", **kw)
    vector_env = gymnasium.make_vec("mlpfac/Track-v0", num_envs=N, vectorization_mode="vector_entry_point", **kw)

    def single() -> float:
        c0, n = time.process_time(), 0
        for e in range(args.episodes):
            obs, _ = single_env.reset(seed=e)
            done = False
            while not done:
                obs, _, term, trunc, _ = single_env.step(obs[6:8])
                done, n = term or trunc, n + 1
        return (time.process_time() - c0) / n

    def vector() -> float:
        c0 = time.process_time()
        obs, _ = vector_env.reset(seed=0)
        for _ in range(args.episodes * steps):  # the next episodes start by themselves (next-step autoreset)
            obs, *_ = vector_env.step(obs[:, 6:8])
        return (time.process_time() - c0) / (args.episodes * steps * N)

    def whole_run() -> float:
        c0 = time.process_time()
        rec = run(scn)
        return (time.process_time() - c0) / rec.n

    single(), vector(), whole_run()  # load the kernels, read the robot
    fns = {"floor": lambda: floor.per_step(steps), "single": single, "vector": vector, "run": whole_run}
    best, med = interleaved(fns, args.rounds)
    for k in fns:
        print(f"  {k:<8} {best[k]:7.1f} us/step (median {med[k]:.1f})")
    f = best["floor"]
    print(f"  vector / single  {best['vector'] / best['single']:5.2f}   (target <= 0.5 at N = 16; N = {N})")
    print(f"  single / floor   {best['single'] / f:5.2f}")
    print(f"  vector / floor   {best['vector'] / f:5.2f}")
    print(f"  run / floor      {best['run'] / f:5.2f}   (Kanayama's law, the compiled closed loop)")
    print(f"  load average {os.getloadavg()[0]:.2f}  ({steps} control steps of {scn.T:g} s an episode)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
