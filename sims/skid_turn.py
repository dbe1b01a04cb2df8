"""How a skid-steer turns in MuJoCo: PAL TIAGo++ as modelled (four plain wheels, two a side), asked
to turn in place and on an arc, open loop, with and without what the plant chooses for it.

For each row the plant gets a steady (v, omega) for 3 s and prints the yaw rate and speed the base
reaches over the last 2 s, against those asked:
- ``armature = 0, track = W``: the model as shipped, the IK turning with the wheels' own track;
- ``armature = M r^2/4, track = W``: a rotor on each wheel (the ``armature`` rule), the same IK;
- ``chosen``: the rotor and the track it turns with, W + L^2 / W (what ``menagerie:pal_tiago_dual``
  runs with from its name).
Usage: MENAGERIE_ROOT=... python sims/skid_turn.py
"""

from __future__ import annotations

import numpy as np

from mlpfac.plants.config import MujocoConfig
from mlpfac.plants.mujoco import MujocoPlant

T = 0.01
MODEL = "menagerie:pal_tiago_dual"
ASKED = ((0.0, 0.5), (0.2, 0.3))  # (v m/s, omega rad/s): in place, an arc


def reached(plant: MujocoPlant, v: float, omega: float, seconds: float = 3.0) -> tuple[float, float]:
    """Mean speed (m/s) and yaw rate (rad/s) over the last seconds - 1 of a steady command from rest."""
    plant.reset(np.zeros(3), np.random.default_rng(0))
    poses = []
    for _ in range(int(round(seconds / T))):
        plant.step(np.array([v, omega]))
        poses.append(plant.true_pose().copy())
    a, b = poses[int(round(1 / T)) - 1], poses[-1]
    return float(np.hypot(*(b - a)[:2]) / (seconds - 1)), float((b - a)[2] / (seconds - 1))


def main() -> None:
    chosen = MujocoPlant(MujocoConfig(model=MODEL), T)
    m, d = chosen.model, chosen.data
    chosen.reset(np.zeros(3), np.random.default_rng(0))
    left, right = (int(m.actuator_trnid[a, 0]) for a in chosen.robot.acts)
    shipped_track = float(np.linalg.norm(d.xanchor[left] - d.xanchor[right]))  # W: the wheels' hinges apart
    rows = {
        "armature = 0, track = W": MujocoConfig(model=MODEL, armature=0.0, track=shipped_track),
        f"armature = {chosen.config.armature:g}, track = W": MujocoConfig(
            model=MODEL, armature=chosen.config.armature, track=shipped_track
        ),
        f"chosen (armature {chosen.config.armature:g}, track {chosen.ik_track:.3g} m)": MujocoConfig(model=MODEL),
    }
    print("| plant | asked v, omega | reached v, omega | omega reached / asked |")
    print("| --- | --- | --- | --- |")
    for name, config in rows.items():
        plant = MujocoPlant(config, T)
        for v, omega in ASKED:
            rv, rw = reached(plant, v, omega)
            print(f"| {name} | {v:g} m/s, {omega:g} rad/s | {rv:.3f} m/s, {rw:.3f} rad/s | {rw / omega:.2f} |")


if __name__ == "__main__":
    main()
