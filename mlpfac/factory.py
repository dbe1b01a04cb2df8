"""The blocks of a run built from a scenario's data: the plant and the controller.

The control period T is the scenario's; both blocks get it here, when they are built, and nowhere else.

A :class:`~mlpfac.scenario.Scenario` is plain, validated data; the runner asks this module for the
blocks it steps, and so does :func:`mlpfac.scenario.load` once, to check before any run that the
robot can be built and can apply every event.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mlpfac.adaptive import VARIANTS, Adaptive
from mlpfac.controllers import Corradini, Kanayama, PluginController
from mlpfac.exceptions import ConfigError
from mlpfac.oracle import Oracle, told
from mlpfac.scenario import Scenario


def make_controller(scn: Scenario, instance: object | None = None):
    """The scenario's controller: a named variant of the adaptive scheme, Corradini's or Kanayama's law,
    the oracle (the law told the scenario's events, :mod:`mlpfac.oracle`), or a user's own
    (:mod:`mlpfac.plugins`; ``instance``: an object of it, made by the caller, runs one seed)."""
    if scn.plugin is not None:
        return PluginController(scn.plugin, scn.T, instance)
    if scn.controller in VARIANTS:
        over = dict(VARIANTS[scn.controller])
        nets = dataclasses.replace(scn.adaptive.networks, **over.pop("networks", {}))
        g = scn.kanayama
        ctrl = Adaptive(
            scn.law, dataclasses.replace(scn.adaptive, networks=nets, **over), scn.T, (g.Kx, g.Ky, g.Ktheta)
        )
        ctrl.name = scn.controller
        return ctrl
    if scn.controller == "corradini":
        return Corradini(scn.law, scn.T)
    if scn.controller in ("oracle", "oracle-kanayama"):  # the controllers told the scenario's events
        g = scn.kanayama
        gains = (g.Kx, g.Ky, g.Ktheta) if scn.controller == "oracle-kanayama" else None
        return Oracle(scn.law, scn.T, [told(ev) for ev in scn.events], scn.plant_kind == "kinematic", gains)
    return Kanayama(scn.law, scn.kanayama, scn.T)


def make_plant(scn: Scenario, ref: np.ndarray):
    """The scenario's plant; ``ref`` (N + 1, 5) are the reference samples the kinematic plant needs.
    A plant that cannot be built, or cannot apply an event, is a ConfigError naming the file."""
    try:
        if scn.plant_kind == "kinematic":
            from mlpfac.plants.kinematic import KinematicPlant

            plant = KinematicPlant(scn.plant_config, scn.T, ref)
        else:
            from mlpfac.plants.mujoco import MujocoPlant

            plant = MujocoPlant(scn.plant_config, scn.T)
    except ConfigError as err:
        where = err.where if err.where.startswith(scn.source) else f"{scn.source} [plant] {err.where}".rstrip()
        raise ConfigError(where, err.what) from None
    for i, ev in enumerate(scn.events):
        plant.check_event(ev, f"{scn.source} [[events]] #{i + 1}")
    return plant
