"""How a skid-steer turns in MuJoCo: PAL TIAGo++ as modelled (four plain wheels, two a side), asked
to turn in place and on an arc, open loop, with and without what the plant chooses for it.

For each row the plant gets a steady (v, omega) for 3 s and prints the yaw rate and speed the base
reaches over the last 2 s, against those asked:
- ``armature = 0, track = W``: the model as shipped, the IK turning with the wheels' own track
  (and with stiffer friction: elliptic cones with impratio 100, or MuJoCo's noslip solver);
- ``armature = A, track = W``: a rotor on each wheel (M r^2/4 is the ``armature`` rule), the same IK;
- ``rule``: the rotor and the track W + L^2 / W;
- ``chosen``: the rotor and the track measured as it settles (``turning_track``), its pose frame at
  its kinematic centre (what ``menagerie:pal_tiago_dual`` runs with from its name).
The rows other than ``chosen`` set ``turning_track`` (nothing measured) and keep the pose frame in
the middle of the wheels.

A second table measures the turning of the robot as chosen again, as it is measured while it
settles, after each shipped event that edits the model (a payload, a floor, a weak actuator,
applied at the start): the track it then turns as and where its kinematic centre then lies
against its pose frame. The oracles are told the payload's (the factory measures it the same way,
``MujocoPlant.turning_change``), not the floor's or the weak actuator's (docs/robots.md).
Usage: MENAGERIE_ROOT=... python sims/skid_turn.py [MODEL] (another skid-steer: tests/data/skid_short.xml)
"""

from __future__ import annotations

import dataclasses
import sys

import numpy as np

from mlpfac.elementary import hypot
from mlpfac.plants.config import MujocoConfig
from mlpfac.plants.mjcf.settle import turning
from mlpfac.plants.mjcf.wheels import skid_track
from mlpfac.plants.mujoco import MujocoPlant
from mlpfac.scenario.parse import load

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
    return hypot(float(b[0] - a[0]), float(b[1] - a[1])) / (seconds - 1), float((b - a)[2] / (seconds - 1))


def main(model: str = MODEL) -> None:
    chosen = MujocoPlant(MujocoConfig(model=model), T)
    m, d = chosen.model, chosen.data
    chosen.reset(np.zeros(3), np.random.default_rng(0))
    left, right = (int(m.actuator_trnid[a, 0]) for a in chosen.robot.acts)
    shipped_track = float(np.linalg.norm(d.xanchor[left] - d.xanchor[right]))  # W: the wheels' hinges apart
    arm = chosen.config.armature
    wheels = [int(m.actuator_trnid[a, 0]) for a in (*chosen.robot.acts, *chosen.robot.seconds)]
    rule, _ = skid_track([d.xanchor[j].copy() for j in wheels])  # W + L^2 / W
    w = {"track": shipped_track, "turning_track": rule}
    rows = [  # (name, [plant] keys, MuJoCo options set on the compiled model)
        ("armature = 0, track = W", {"armature": 0.0, **w}, {}),
        ("armature = 0, track = W, elliptic cones, impratio 100", {"armature": 0.0, **w}, {"cone": 1, "impratio": 100.0}),
        ("armature = 0, track = W, noslip solver", {"armature": 0.0, **w}, {"noslip_iterations": 10}),
        *((f"armature = {a:g}, track = W", {"armature": a, **w}, {}) for a in (0.01, arm, 1.0)),
        (f"rule (armature {arm:g}, track W + L^2/W = {rule:.3g} m)", {"turning_track": rule}, {}),
        (f"chosen (armature {arm:g}, track {chosen.ik_track:.3g} m measured)", {}, {}),
    ]  # fmt: skip
    print("| plant | asked v, omega | reached v, omega | omega reached / asked |")
    print("| --- | --- | --- | --- |")
    for name, keys, options in rows:
        plant = MujocoPlant(MujocoConfig(model=model, **keys), T)
        for key, value in options.items():
            setattr(plant.model.opt, key, value)
        for v, omega in ASKED:
            rv, rw = reached(plant, v, omega)
            print(f"| {name} | {v:g} m/s, {omega:g} rad/s | {rv:.3f} m/s, {rw:.3f} rad/s | {rw / omega:.2f} |")
    print()
    print("| event (of the scenario, at the start) | track turned as | kinematic centre from the pose frame |")
    print("| --- | --- | --- |")
    for scenario in (None, "eight-payload", "eight-friction", "eight-weak-actuator"):
        events = [None] if scenario is None else load(scenario, robot=model).events
        for ev in events:
            ev = ev if ev is None else dataclasses.replace(ev, time=0.0)
            track, ahead, said = turning(chosen, [] if ev is None else [ev])
            where = f"{abs(ahead) * 1e3:.1f} mm {'ahead' if ahead >= 0 else 'back'}"
            name = "none (as it settled)" if ev is None else f"{scenario}: {ev.kind} {ev.params}"
            print(f"| {name} | {track:.3f} m | {where} |")


if __name__ == "__main__":
    main(*sys.argv[1:2])
