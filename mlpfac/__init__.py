"""mlpfac: multilayer-perceptron functional adaptive control of a wheeled mobile robot, tested on MuJoCo.

The public API::

    import mlpfac

    scn = mlpfac.load("eight-payload").with_overrides(controller="kanayama", seed=4)
    rec = mlpfac.run(scn)                      # one closed-loop run -> a RunRecord
    m = mlpfac.metrics(rec)                    # what metrics.json holds
    mlpfac.scenario_names()                    # the shipped scenarios
    mlpfac.check("budget.toml").code           # run a budget's sweep and judge it (``mlpfac check``)

Names are imported on first use, so ``import mlpfac`` (and the command line) stays light.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from mlpfac.version import __version__

_WHERE = {
    "load": "mlpfac.scenario.parse",
    "parse": "mlpfac.scenario.parse",
    "scenario_names": "mlpfac.scenario.parse",
    "Scenario": "mlpfac.scenario.parse",
    "run": "mlpfac.api",
    "sweep": "mlpfac.api",
    "PluginError": "mlpfac.exceptions",
    "metrics": "mlpfac.loop.metrics",
    "RunRecord": "mlpfac.loop.record",
    "CONTROLLERS": "mlpfac.control.baselines",
    "check": "mlpfac.checks",
    "ConfigError": "mlpfac.exceptions",
    "MlpfacError": "mlpfac.exceptions",
}
__all__ = [
    "CONTROLLERS",
    "ConfigError",
    "MlpfacError",
    "PluginError",
    "RunRecord",
    "Scenario",
    "__version__",
    "check",
    "load",
    "metrics",
    "parse",
    "run",
    "scenario_names",
    "sweep",
]

if TYPE_CHECKING:
    from mlpfac.api import run, sweep
    from mlpfac.checks import check
    from mlpfac.control.baselines import CONTROLLERS
    from mlpfac.exceptions import ConfigError, MlpfacError, PluginError
    from mlpfac.loop.metrics import metrics
    from mlpfac.loop.record import RunRecord
    from mlpfac.scenario.parse import Scenario, load, parse, scenario_names


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'mlpfac' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
