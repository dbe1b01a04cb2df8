"""The blocks of a run built from a scenario's data: the plant and the controller.

The control period T is the scenario's; both blocks get it here, when they are built, and nowhere else.

A :class:`~mlpfac.scenario.parse.Scenario` is plain, validated data; the runner asks this module for the
blocks it steps. The plant is built by :func:`mlpfac.plants.make_plant` (re-exported here), which
:func:`mlpfac.scenario.parse.load` also calls once, to check before any run that the robot can be built
and can apply every event.
"""

from __future__ import annotations

import dataclasses

from mlpfac.control.adaptive.controller import VARIANTS, Adaptive
from mlpfac.control.baselines import Controller, Corradini, Kanayama, PluginController
from mlpfac.control.oracle import Oracle, told
from mlpfac.plants import make_plant  # noqa: F401 (the plant half of the factory, as mlpfac.loop.factory.make_plant)
from mlpfac.scenario.parse import Scenario


def make_controller(scn: Scenario, instance: object | None = None) -> Controller:
    """The scenario's controller: a named variant of the adaptive scheme, Corradini's or Kanayama's law,
    the oracle (the law told the scenario's events, :mod:`mlpfac.control.oracle`), or a user's own
    (:mod:`mlpfac.control.plugins`; ``instance``: an object of it, made by the caller, runs one seed)."""
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
