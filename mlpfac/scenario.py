"""Scenario files (TOML) -> frozen, validated configuration; the factories for plant and controller.

A scenario names the reference, the plant, the controller and its parameters, the events that
change the plant mid-run, the duration and the seed. See ``sims/*.toml`` and the README.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mlpfac.controllers import CONTROLLERS, VARIANTS, Adaptive, AdaptiveConfig, Corradini, Kanayama, KanayamaGains
from mlpfac.error_model import pose_from_error
from mlpfac.exceptions import ConfigError
from mlpfac.law import Law
from mlpfac.networks import Networks
from mlpfac.plants.base import EVENT_KINDS, Event
from mlpfac.reference import make_reference

ROOT = Path(__file__).resolve().parent.parent
SIMS = ROOT / "sims"

TOP_KEYS = {
    "name",
    "description",
    "duration",
    "T",
    "seed",
    "warmup",
    "divergence_m",
    "reference",
    "initial",
    "plant",
    "controller",
    "events",
}
CONTROLLER_KEYS = {"name", "lambdas", "v_max", "omega_max", "adaptive", "kanayama"}
NETWORK_KEYS = {f.name for f in dataclasses.fields(Networks)}
ADAPTIVE_KEYS = {f.name for f in dataclasses.fields(AdaptiveConfig)} - {"networks"} | NETWORK_KEYS


@dataclass(frozen=True)
class Scenario:
    """A validated scenario. ``table`` is the resolved TOML (overrides applied), kept for config.toml."""

    name: str
    description: str
    source: str  # the file it came from, for error messages
    duration: float
    T: float
    seed: int
    warmup: float  # seconds of learning excluded from the phase metrics
    divergence_m: float  # position error beyond which a run counts as diverged
    initial_error: tuple[float, float, float]
    start_moving: bool  # the robot starts with the reference's (v_r, omega_r), not at rest
    reference: Any
    plant_kind: str
    plant_config: Any
    controller: str
    law: Law
    adaptive: AdaptiveConfig
    kanayama: KanayamaGains
    events: tuple[Event, ...]
    table: dict

    @property
    def steps(self) -> int:
        return int(round(self.duration / self.T))

    def with_overrides(
        self, controller: str | None = None, seed: int | None = None, duration: float | None = None
    ) -> Scenario:
        """The same scenario with the command line's --controller, --seed, --duration applied."""
        table = copy.deepcopy(self.table)
        if controller is not None:
            table.setdefault("controller", {})["name"] = controller
        if seed is not None:
            table["seed"] = seed
        if duration is not None:
            table["duration"] = duration
        return parse(table, self.source)

    def initial_state(self, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The initial pose (the reference's at t = 0, offset by the initial error) and velocity."""
        q0 = pose_from_error(np.array(self.initial_error), ref[0])
        return q0, (ref[0, 3:5].copy() if self.start_moving else None)

    def make_controller(self):
        if self.controller in VARIANTS:
            over = dict(VARIANTS[self.controller])
            nets = dataclasses.replace(self.adaptive.networks, **over.pop("networks", {}))
            ctrl = Adaptive(self.law, dataclasses.replace(self.adaptive, networks=nets, **over))
            ctrl.name = self.controller
            return ctrl
        if self.controller == "corradini":
            return Corradini(self.law)
        return Kanayama(self.law, self.kanayama)

    def make_plant(self, ref: np.ndarray):
        """The plant; ``ref`` (N + 1, 5) are the reference samples the kinematic plant needs."""
        if self.plant_kind == "kinematic":
            from mlpfac.plants.kinematic import KinematicPlant

            plant = KinematicPlant(self.plant_config, self.T, ref)
        else:
            from mlpfac.plants.mujoco import MujocoPlant

            plant = MujocoPlant(self.plant_config, self.T)
        for i, ev in enumerate(self.events):
            plant.check_event(ev, f"{self.source} [[events]] #{i + 1}")
        return plant


def scenario_names() -> list[str]:
    """Names of the shipped scenarios (files in sims/)."""
    return sorted(p.stem for p in SIMS.glob("*.toml"))


def load(name_or_path: str) -> Scenario:
    """A scenario by name (``paper`` -> sims/paper.toml) or by path to a TOML file."""
    path = Path(name_or_path)
    if path.suffix != ".toml":
        path = SIMS / f"{name_or_path}.toml"
        if not path.exists():
            raise ConfigError(name_or_path, f"no such scenario; shipped ones: {', '.join(scenario_names())}")
    if not path.exists():
        raise ConfigError(str(path), "scenario file not found")
    try:
        table = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(str(path), f"not valid TOML: {err}") from None
    except OSError as err:
        raise ConfigError(str(path), f"cannot read: {err.strerror}") from None
    table.setdefault("name", path.stem)
    return parse(table, str(path))


def _check_keys(table: dict, allowed: set[str], where: str) -> None:
    for key in table:
        if key not in allowed:
            raise ConfigError(f"{where} {key}", f"unknown key (known: {', '.join(sorted(allowed))})")


def _number(table: dict, key: str, default: float, where: str, positive: bool = True) -> float:
    val = table.get(key, default)
    if isinstance(val, bool) or not isinstance(val, int | float) or not math.isfinite(val):
        raise ConfigError(f"{where} {key}", f"expected a number, got {val!r}")
    if positive and not val > 0:
        raise ConfigError(f"{where} {key}", f"must be positive, got {val}")
    return float(val)


def build(cls, table: dict, where: str):
    """A frozen config dataclass from a TOML table: unknown keys and bad values name the key."""
    fields = {f.name for f in dataclasses.fields(cls)}
    _check_keys(table, fields, where)
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in table.items()}
    try:
        return cls(**values)
    except ConfigError as err:
        raise ConfigError(f"{where} {err.where}".strip(), err.what) from None
    except (TypeError, ValueError) as err:
        raise ConfigError(where, str(err)) from None


def parse(table: dict, source: str = "<scenario>") -> Scenario:
    """Validate a scenario table (as read from TOML) into a :class:`Scenario`."""
    _check_keys(table, TOP_KEYS, source)
    T = _number(table, "T", 0.01, source)
    duration = _number(table, "duration", 25.0, source)
    seed = table.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"{source} seed", f"expected a whole number >= 0, got {seed!r}")

    ref_table = dict(table.get("reference", {"kind": "eight"}))
    kind = ref_table.pop("kind", "eight")
    reference = make_reference(kind, ref_table, f"{source} [reference]")

    initial = table.get("initial", {})
    _check_keys(initial, {"error", "moving"}, f"{source} [initial]")
    moving = initial.get("moving", True)
    if not isinstance(moving, bool):
        raise ConfigError(f"{source} [initial] moving", f"expected true or false, got {moving!r}")
    e0 = initial.get("error", [0.0, 0.0, 0.0])
    if len(e0) != 3:
        raise ConfigError(f"{source} [initial] error", "expected three values (e1, e2, e3)")

    plant_table = dict(table.get("plant", {"kind": "kinematic"}))
    plant_kind = plant_table.pop("kind", "kinematic")
    where = f"{source} [plant]"
    if plant_kind == "kinematic":
        from mlpfac.plants.kinematic import KinematicConfig

        plant_config = build(KinematicConfig, plant_table, where)
    elif plant_kind == "mujoco":
        from mlpfac.plants.mujoco import MujocoConfig

        if "model" in plant_table and not Path(plant_table["model"]).is_absolute():
            model = Path(plant_table["model"])
            here = Path(source).parent / model
            plant_table["model"] = str(here if here.exists() else ROOT / model)
        plant_config = build(MujocoConfig, plant_table, where)
    else:
        raise ConfigError(f"{where} kind", f"unknown plant {plant_kind!r}; choose kinematic or mujoco")

    ctrl = table.get("controller", {})
    where = f"{source} [controller]"
    _check_keys(ctrl, CONTROLLER_KEYS, where)
    name = ctrl.get("name", "adaptive")
    if name not in CONTROLLERS:
        raise ConfigError(f"{where} name", f"unknown controller {name!r}; choose one of {', '.join(CONTROLLERS)}")
    law = build(Law, {k: ctrl[k] for k in ("lambdas", "v_max", "omega_max") if k in ctrl}, where)
    ad = dict(ctrl.get("adaptive", {}))
    _check_keys(ad, ADAPTIVE_KEYS, f"{where}.adaptive")
    nets = build(Networks, {k: ad.pop(k) for k in list(ad) if k in NETWORK_KEYS}, f"{where}.adaptive")
    adaptive = build(AdaptiveConfig, ad, f"{where}.adaptive")
    adaptive = dataclasses.replace(adaptive, networks=nets)
    kanayama = build(KanayamaGains, ctrl.get("kanayama", {}), f"{where}.kanayama")

    events = []
    for i, ev in enumerate(table.get("events", [])):
        where = f"{source} [[events]] #{i + 1}"
        ev = dict(ev)
        t = ev.pop("time", None)
        if isinstance(t, bool) or not isinstance(t, int | float) or not t >= 0:
            raise ConfigError(f"{where} time", f"an event needs a time >= 0 s, got {t!r}")
        kind = ev.pop("kind", None)
        if kind not in EVENT_KINDS:
            raise ConfigError(f"{where} kind", f"unknown event kind {kind!r}; choose one of {', '.join(EVENT_KINDS)}")
        events.append(Event(float(t), kind, ev))
    events.sort(key=lambda ev: ev.time)

    return Scenario(
        name=str(table.get("name", "scenario")),
        description=str(table.get("description", "")),
        source=source,
        duration=duration,
        T=T,
        seed=seed,
        warmup=_number(table, "warmup", 2.0, source, positive=False),
        divergence_m=_number(table, "divergence_m", 5.0, source),
        initial_error=tuple(float(x) for x in e0),
        start_moving=moving,
        reference=reference,
        plant_kind=plant_kind,
        plant_config=plant_config,
        controller=name,
        law=law,
        adaptive=adaptive,
        kanayama=kanayama,
        events=tuple(events),
        table=table,
    )


def to_toml(table: dict) -> str:
    """A scenario table as TOML (scalars, lists of scalars, tables and arrays of tables)."""
    lines: list[str] = []

    def value(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list | tuple):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    def emit(t: dict, prefix: str) -> None:
        for k, v in t.items():
            if not isinstance(v, dict) and not (isinstance(v, list) and v and isinstance(v[0], dict)):
                lines.append(f"{k} = {value(v)}")
        for k, v in t.items():
            if isinstance(v, dict):
                lines.append(f"\n[{prefix}{k}]")
                emit(v, f"{prefix}{k}.")
            elif isinstance(v, list) and v and isinstance(v[0], dict):
                for item in v:
                    lines.append(f"\n[[{prefix}{k}]]")
                    emit(item, f"{prefix}{k}.")

    emit(table, "")
    return "\n".join(lines) + "\n"
