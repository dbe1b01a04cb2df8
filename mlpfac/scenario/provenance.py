"""A scenario's ``[provenance]``: what a run simulates and runs, recorded in its config.toml, and
checked when a config.toml is run again (the same compiled robot model, the same plug-in code).

:func:`recorded` builds the plant once, through :func:`mlpfac.plants.make_plant`: every check of
the robot and of the events it must apply is made before anything runs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plants import PlantSpec

if TYPE_CHECKING:
    from mlpfac.control.plugins import Plugin


class Recorded(PlantSpec, Protocol):
    """What :func:`recorded` reads of a :class:`~mlpfac.scenario.parse.Scenario`."""

    reference: object
    plugin: Plugin | None
    duration: float


def recorded(scn: Recorded) -> tuple[dict, dict]:
    """Build the plant once (every check made): what it simulates, and the [plant] keys it found."""
    from mlpfac.scenario.on_robot import torque_need
    from mlpfac.version import __version__

    plant = _plant(scn)
    out = {"mlpfac": __version__, "numpy": np.__version__}
    out |= plant.provenance()
    if scn.plugin is not None:
        out["controller"] = scn.plugin.provenance()
    ref = getattr(scn.reference, "provenance", None)
    if ref is not None and ref() is not None:  # your own reference class, a path's CSV file
        out["reference"] = ref()
    out |= torque_need(scn, plant)  # what the reference asks of torque motors, for the run's first line
    return out, plant.found()


TORQUE_KEYS = ("reference_torque", "torque_warning")


def with_torque_need(table: dict, scn: Recorded) -> dict:
    """``table`` whose [provenance] says what the reference asks of torque motors (made for another
    duration) with it said again for ``scn``: the need is over the path the run drives."""
    prov = table.get("provenance")
    if not isinstance(prov, dict) or not any(k in prov for k in TORQUE_KEYS):
        return table
    from mlpfac.scenario.on_robot import torque_need

    kept = {k: v for k, v in prov.items() if k not in TORQUE_KEYS}
    return table | {"provenance": kept | torque_need(scn, _plant(scn))}


def _plant(scn: Recorded):
    """The plant of ``scn``, built (every check made) from the reference's first two samples."""
    from mlpfac.plants import make_plant
    from mlpfac.scenario.reference import sample

    return make_plant(scn, sample(scn.reference, np.arange(2) * scn.T))


def check_model(recorded, config, where: str) -> None:
    """A config.toml's [provenance] against the model it names now: the compiled model must be the same."""
    if not isinstance(recorded, dict):
        raise ConfigError(where, f"expected a table, got {recorded!r}")
    want = recorded.get("model_sha256")
    if want is None or not hasattr(config, "path"):
        return
    from mlpfac.plants.model_file import model_fingerprint

    got = model_fingerprint(config.model)
    if got != want:
        raise ConfigError(
            f"{where} model_sha256",
            f"{config.path} is not the model this configuration was made with (compiled sha256 {got[:12]}..., "
            f"recorded {str(want)[:12]}...): the file changed, or another MuJoCo compiles it differently; "
            "remove [provenance] to run it with the model as it is now",
        )


def with_reference(table: dict, reference, source: str, check: bool) -> dict:
    """The table with ``[provenance] reference`` naming the reference class's file or the path's CSV
    file and its sha256; a config.toml whose file changed since it was made is refused (``check``)."""
    prov = table.get("provenance")
    now = reference.provenance() if hasattr(reference, "provenance") else None
    if not isinstance(prov, dict) or now is None:
        return table
    was = prov.get("reference")
    name = now.get("target", now.get("file"))
    if (
        check
        and isinstance(was, dict)
        and was.get("target", was.get("file")) == name
        and was.get("sha256") != now.get("sha256")
    ):
        raise ConfigError(
            f"{source} [provenance] reference",
            f"{name} is not the file this configuration was made with (sha256 {str(now.get('sha256'))[:12]}..., "
            f"recorded {str(was.get('sha256'))[:12]}...); remove [provenance.reference] to run it as it is now",
        )
    return {**table, "provenance": {**prov, "reference": now}}


def with_controller(table: dict, plugin: Plugin, source: str, check: bool) -> dict:
    """The table with ``[provenance] controller`` naming what runs; a config.toml whose plug-in file
    changed since it was made is refused (``check``), as a changed robot model is."""
    prov = table.get("provenance")
    if not isinstance(prov, dict):
        return table
    was = prov.get("controller")
    if check and isinstance(was, dict) and was.get("target") == plugin.target and was.get("sha256") != plugin.sha256:
        raise ConfigError(
            f"{source} [provenance] controller",
            f"{plugin.target} is not the code this configuration was made with (sha256 {str(plugin.sha256)[:12]}..., "
            f"recorded {str(was.get('sha256'))[:12]}...); remove [provenance.controller] to run it as it is now",
        )
    return {**table, "provenance": {**prov, "controller": plugin.provenance()}}
