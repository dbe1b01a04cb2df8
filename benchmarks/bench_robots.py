"""What each MuJoCo Menagerie wheeled base costs from its name alone: one control step of the plant
(only what moves stepped: the other actuated joints locked) against bare physics of the same model
as shipped (``mj_step`` of every DOF, as often, at the same timestep).

    MENAGERIE_ROOT=/path/to/mujoco_menagerie python benchmarks/bench_robots.py
    python benchmarks/bench_robots.py --steps 500 --repeats 3

Each figure is the median of ``--repeats`` timings (CPU clock of this process) of ``--steps``
control steps driving at (0.05 m/s, 0.1 rad/s), in us per control step; "physics" is ``mj_step``
of the shipped model (its home keyframe where it has one, its controls held) for the same
simulated time; ratio = control step / physics: below 1, the plant costs less than the bare
shipped model would.
"""

from __future__ import annotations

import argparse

import mujoco
import numpy as np
from bench_tiago import timed  # this folder's: the median CPU time of repeated calls

from mlpfac.exceptions import ConfigError
from mlpfac.plants.config import MujocoConfig
from mlpfac.plants.model_file import model_path
from mlpfac.plants.mujoco import MujocoPlant
from mlpfac.scenario.on_robot import MENAGERIE_BASES, robot_table

T = 0.01


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for flag, n, what in (("--steps", 500, "control steps per timing"), ("--repeats", 3, "timings (median kept)")):
        ap.add_argument(flag, type=int, default=n, help=f"{what} (default {n})")
    args = ap.parse_args()
    u = np.array([0.05, 0.1])
    print(
        f"{'robot':22} {'nv shipped':>10} {'nv run':>6} {'timestep s':>10} {'physics us':>11} {'step us':>8} {'ratio':>6}"
    )
    for name in ("diffdrive", *(b for b in MENAGERIE_BASES if b != "rainbow_robotics_rby1"), "rby1a"):
        plant_table = robot_table(name)
        try:
            plant = MujocoPlant(MujocoConfig(**{k: v for k, v in plant_table.items() if k != "kind"}), T, (T,))
        except ConfigError as err:  # refused from its name alone (docs/robots.md)
            print(f"{name:22} refused: {err.what[:80]}...")
            continue
        shipped = mujoco.MjModel.from_xml_path(str(model_path(plant_table["model"])))
        shipped.opt.timestep = plant.model.opt.timestep
        d = mujoco.MjData(shipped)
        home = mujoco.mj_name2id(shipped, mujoco.mjtObj.mjOBJ_KEY, "home")
        if home >= 0:
            mujoco.mj_resetDataKeyframe(shipped, d, home)
        n = plant.n_substeps
        plant.reset(np.zeros(3), np.random.default_rng(0))

        def control(plant=plant):
            for _ in range(args.steps):
                plant.step(u)

        def physics(m=shipped, d=d, n=n):
            mujoco.mj_step(m, d, nstep=args.steps * n)

        step = timed(control, args.repeats) / args.steps * 1e6
        phys = timed(physics, args.repeats) / args.steps * 1e6
        print(
            f"{name:22} {shipped.nv:10d} {plant.model.nv:6d} {plant.model.opt.timestep:10.3g} "
            f"{phys:11.1f} {step:8.1f} {step / phys:6.2f}"
        )


if __name__ == "__main__":
    main()
