"""The plants a run drives: the kinematic unicycle (:mod:`~mlpfac.plants.kinematic`) and a MuJoCo
robot (:mod:`~mlpfac.plants.mujoco`); :func:`make_plant` builds the one a scenario names. Beside
them, by block: a robot read from its MJCF (:mod:`~mlpfac.plants.mjcf`), the world around it
(:mod:`~mlpfac.plants.world`), what it senses of its own pose (:mod:`~mlpfac.plants.sensors`); and
what every plant shares: the events (:mod:`~mlpfac.plants.events`), the IK (:mod:`~mlpfac.plants.ik`),
the ``[plant]`` table (:mod:`~mlpfac.plants.config`), the interface (:mod:`~mlpfac.plants.base`).

Only this package imports mujoco, and only in its modules, not here: importing the package is cheap.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from mlpfac.exceptions import ConfigError


class PlantSpec(Protocol):
    """What :func:`make_plant` reads of a :class:`~mlpfac.scenario.parse.Scenario`."""

    plant_kind: str
    plant_config: object
    T: float
    source: str
    plant_from: str  # the robot its [plant] came from (--robot NAME), "" for the file's own
    events: tuple
    controller: str
    level: str  # "torque": the controller commands the wheels' torques
    steps: int  # control steps of a run
    terrain: object  # the world resolved for the run (mlpfac.plants.world.layout.Terrain), or None


def make_plant(scn: PlantSpec, ref: np.ndarray):
    """The scenario's plant; ``ref`` (N + 1, 5) are the reference samples the kinematic plant needs.
    A plant that cannot be built, or cannot apply an event, is a ConfigError naming the file."""
    try:
        if scn.plant_kind == "kinematic":
            from mlpfac.plants.kinematic import KinematicPlant

            plant, robot = KinematicPlant(scn.plant_config, scn.T, ref), None
        else:
            from mlpfac.plants.events import ControlPeriod
            from mlpfac.plants.mujoco.plant import MujocoPlant

            periods = (scn.T, *(ev.factor * scn.T for ev in scn.events if isinstance(ev, ControlPeriod)))
            plant = robot = MujocoPlant(scn.plant_config, scn.T, periods)
    except ConfigError as err:
        where = err.where if err.where.startswith(scn.source) else f"{plant_where(scn)} {err.where}".rstrip()
        raise type(err)(where, err.what) from None  # UnavailableError stays itself
    if scn.level == "torque":  # a controller of the wheels' torques
        actuator = None if robot is None else robot.config.actuator
        refuse_torque(scn.controller, scn.plant_kind, actuator, scn.source, scn.plant_from)
        robot.torque_commands()
    for i, ev in enumerate(scn.events):
        plant.check_event(ev, f"{scn.source} [[events]] #{i + 1}")
    if robot is not None:
        _check_size(scn, robot)
        if scn.terrain is not None or any(ev.kind == "force" for ev in scn.events):  # mlpfac.plants.mujoco.world
            robot.set_world(scn.terrain, scn.events, scn.steps, f"{scn.source} [world]", f"{scn.source} [[events]]")
    return plant


def plant_where(scn: PlantSpec) -> str:
    """What a message about the scenario's plant names: its file's ``[plant]``, or the robot it was
    put on (``--robot NAME``, renamed to the flag or key that brought it: mlpfac.scenario.on_robot)."""
    return scn.plant_from or f"{scn.source} [plant]"


def refuse_torque(
    controller: str, kind: str, actuator: str | None, source: str, plant_from: str = "", read: bool = True
) -> None:
    """A torque-level controller is refused, in one line naming what chose the plant (the file
    ``source``'s ``[plant]``, or the robot ``plant_from``), on a plant (``kind``) without torque
    motors: ``actuator`` is the robot's as read (``read``), or the file's before the robot is read
    (None, unset, passes: the model answers)."""
    what = f"{controller} is a torque-level controller: it commands wheel torques"
    if kind == "mujoco" and (actuator == "torque" or (actuator is None and not read)):
        return
    if plant_from:  # the robot a flag or key named: its file sets the actuator, not the scenario's
        raise ConfigError(
            plant_from,
            f"{what}, which this robot's {actuator or 'velocity'} servos do not take; choose one with torque motors "
            '(cart-torque, diffdrive-torque, tug, tiago-torque, or a robot file with actuator = "torque" in its [plant])',
        )
    if kind != "mujoco":
        raise ConfigError(
            f"{source} [plant] kind",
            f'{what}: it drives a MuJoCo robot\'s wheel torques; set kind = "mujoco" and actuator = "torque" in [plant]',
        )
    raise ConfigError(
        f"{source} [plant] actuator",
        f'{what}, which the robot\'s {actuator} servos do not take; set actuator = "torque" in [plant] '
        "(torque motors with the same limit)",
    )


MAX_PHYSICS_STEPS = 10**9  # physics steps of one run, at most (hours of simulation)


def _check_size(scn: PlantSpec, plant) -> None:
    """A MuJoCo run of more than MAX_PHYSICS_STEPS physics steps is refused before it starts, naming
    the key that made it so (``[plant] timestep``, or ``duration``)."""
    n, steps = plant.n_substeps, scn.steps
    most = max([n] + [plant._substeps(ev.factor * scn.T, "factor") for ev in scn.events if ev.kind == "control_period"])
    if steps * most > MAX_PHYSICS_STEPS:
        raise ConfigError(
            f"{scn.source} [plant] timestep",
            f"{steps} control steps of up to {most} physics steps of {scn.T / n:g} s are {steps * most:.3g} physics "
            f"steps; the limit is {MAX_PHYSICS_STEPS:.0e} per run: lengthen the timestep or shorten the duration",
        )
