"""What does a real robot cost? PAL TIAGo (MuJoCo Menagerie) base-only against the full robot, and
our small robot beside them: bare physics (``mj_step``) and one control step of the plant.

    python benchmarks/bench_tiago.py
    MENAGERIE_ROOT=/path/to/mujoco_menagerie python benchmarks/bench_tiago.py --steps 2000 --repeats 7

"Base-only" is the tiago-* scenarios' robot: arm, head, torso and gripper locked at the "home"
keyframe (``other_actuators = "lock"``: their joints removed with MjSpec, the bodies rigid on the
base); "full" holds them with their own servos (``other_actuators = "hold"``, 28 DOF). Each figure
is the median of ``--repeats`` timings (CPU clock of this process) of ``--steps`` control steps
driving (0.3 m/s, 0.3 rad/s), in us per step; physics is ``mj_step`` of the same model as often.
TIAGo comes from a Menagerie checkout named by ``MENAGERIE_ROOT``, mujoco-menagerie's cache or a
download; where none has it, its rows say why and our robot is measured alone.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

import mujoco
import numpy as np

from mlpfac.exceptions import MlpfacError
from mlpfac.plants.mujoco.plant import MujocoConfig, MujocoPlant
from mlpfac.scenario.parse import load


def robots() -> dict[str, MujocoConfig]:
    """Our robot, and TIAGo base-only and full where the Menagerie robot can be had."""
    tiago = dataclasses.replace(load("tiago-nominal", build=False).plant_config, pose_noise_std=0.0)
    return {
        "diffdrive": MujocoConfig(),
        "tiago base-only": tiago,  # other_actuators = "lock", as the scenarios
        "tiago full": dataclasses.replace(tiago, other_actuators="hold"),
    }


def timed(fn, repeats: int) -> float:
    out = []
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        out.append(time.process_time() - t0)
    return statistics.median(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=1000, help="control steps per timing (default 1000)")
    ap.add_argument("--repeats", type=int, default=5, help="timings per figure; the median is kept (default 5)")
    args = ap.parse_args()
    u = np.array([0.3, 0.3])
    print(f"{'robot':18} {'nv':>3} {'ngeom':>5} {'mj_step us':>11} {'control step us':>16} {'substeps':>8}")
    for name, config in robots().items():
        try:
            plant = MujocoPlant(config, 0.01)
        except MlpfacError as err:  # TIAGo offline, without MENAGERIE_ROOT: one line, the others measured
            print(f"{name:18} not measured: {err}")
            continue
        m = plant.model

        def control(plant=plant):
            for _ in range(args.steps):
                plant.step(u)

        def physics(m=m, n=plant.n_substeps, q=plant.robot.qpos_rest):
            d = mujoco.MjData(m)
            d.qpos[:] = q
            mujoco.mj_step(m, d, nstep=args.steps * n)

        plant.reset(np.zeros(3), np.random.default_rng(0))  # a run in progress: each timing drives on

        step = timed(control, args.repeats) / args.steps * 1e6
        phys = timed(physics, args.repeats) / (args.steps * plant.n_substeps) * 1e6
        print(f"{name:18} {m.nv:3d} {m.ngeom:5d} {phys:11.1f} {step:16.1f} {plant.n_substeps:8d}")


if __name__ == "__main__":
    main()
