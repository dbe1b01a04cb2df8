"""What ``mpc`` costs a control step, against the physics it runs: CPU per control step of an
``mpc`` run on the figure of eight, on each robot, and the same number of bare ``mj_step`` calls on
the robot's own compiled model (its physics floor). Not a test.

    python benchmarks/bench_mpc.py [--robots diffdrive,diffdrive-torque,...|all] [--steps N] [--rounds 3]

One process, single-threaded BLAS, CPU clock, rounds interleaved (the best kept, the median beside
it), as ``benchmarks/perf_floor.py``. Per robot: ``mpc`` the whole run (``runner.run``, one seed:
the estimator, the plan's rollouts, the loop) per control step; ``physics`` the physics steps the
controller's model took per control step (its rollouts and the estimator's steps, counted by the
model) plus the run's own; ``floor`` bare ``mj_step`` on a copy of the robot's compiled model per
physics step; ``mpc / (physics x floor)`` what mlpfac adds over MuJoCo itself (1 is the physics
alone). ``ms`` per control step is the figure the goal (10 ms at T = 0.01 on our robot: a 25-s run
within its 25 s on one core) is set in: by default each timed run is the whole figure of eight
(eight-nominal's 25 s); ``--steps N`` times its first N control steps, where the plan is still
settling (the costly steps).
"""

from __future__ import annotations

import os

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_k] = "1"

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from mlpfac.loop.runner import build, run  # noqa: E402
from mlpfac.scenario.on_robot import robots_here  # noqa: E402
from mlpfac.scenario.parse import load  # noqa: E402


def robot_names(text: str) -> list[str]:
    if text != "all":
        return text.split(",")
    cannot = ("not in MENAGERIE_ROOT", "refused", "not downloaded", "needs the")
    return [name for name, where in robots_here() if not any(c in where for c in cannot)]


def timed(scn, counted: dict) -> float:
    """CPU seconds per control step of one ``mpc`` run; ``counted``: the physics steps it took per
    control step (the model's and the run's own) and the run's steps."""
    b = build(scn)
    c0 = time.process_time()
    rec = run(scn, built=b)
    cpu = time.process_time() - c0
    model_steps = sum(s.model.control_steps for s in b.ctrl.seeds)
    counted["physics"] = (model_steps + rec.n) * b.plant.n_substeps / rec.n
    counted["n"] = rec.n
    return cpu / rec.n


def floor(m, d, k: int = 2000) -> float:
    """CPU seconds per bare ``mj_step`` of the robot's compiled model ``m`` from the data ``d``."""
    c0 = time.process_time()
    for _ in range(k):
        mujoco.mj_step(m, d)
    return (time.process_time() - c0) / k


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default="diffdrive", help="comma-separated robots, or all (those mlpfac list names)")
    ap.add_argument("--steps", type=int, default=None, help="control steps of each timed run (default: the whole run)")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    print(f"{'robot':<24} {'mpc ms':>7} {'physics':>8} {'floor us':>9} {'ratio':>6}  (median ms)")
    for robot in robot_names(args.robots):
        scn = load("eight-nominal", robot=robot).with_overrides(controller="mpc")
        if args.steps is not None:
            scn = scn.with_overrides(duration=args.steps * scn.T)
        counted: dict = {}
        b = build(scn)
        m = b.plant.model
        d = mujoco.MjData(m)
        d.qpos[:] = b.plant.data.qpos
        d.ctrl[:] = b.plant.data.ctrl
        mujoco.mj_forward(m, d)
        timed(scn, counted)  # the kernels loaded, the robot read
        mpc, phys = [], []
        for _ in range(args.rounds):
            mpc.append(timed(scn, counted))
            phys.append(floor(m, d))
        best, f = min(mpc), min(phys)
        ratio = best / (counted["physics"] * f)
        print(f"{robot:<24} {best * 1e3:7.2f} {counted['physics']:8.0f} {f * 1e6:9.2f} {ratio:6.2f}  "
              f"({statistics.median(mpc) * 1e3:.2f}; {counted['n']} steps of {scn.T:g} s)", flush=True)  # fmt: skip
    print(f"load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    np.seterr(all="ignore")
    sys.exit(main())
