"""Scenario files (TOML) -> frozen, validated configuration; the factories for plant and controller.

A scenario names the reference, the plant, the controller and its parameters, the events that
change the plant mid-run, the duration and the seed. See ``sims/*.toml`` and the README.
"""

from __future__ import annotations

import copy
import dataclasses
import importlib.resources
import json
import math
import os
import re
import tomllib
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mlpfac.adaptive import VARIANTS, AdaptiveConfig
from mlpfac.controllers import CONTROLLERS, KanayamaGains
from mlpfac.error_model import pose_from_error
from mlpfac.events import Event, parse_event
from mlpfac.exceptions import ConfigError
from mlpfac.law import Law
from mlpfac.networks import Networks
from mlpfac.reference import make_reference

NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+-]*")  # a scenario's name is a folder name in runs/ and sweeps
NO_LIMIT = {"v_max", "omega_max"}  # keys where inf means "no limit" (None)
INF_OK = NO_LIMIT | {
    "max_wheel_speed"
}  # keys that take inf ("no limit"; max_wheel_speed keeps it: None is the model's)
MEMORY_SHARE = 0.8  # a run may plan to use at most this share of the memory available now

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
    "provenance",
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
    dropped_events: tuple[float, ...] = ()  # times of the file's events a shorter --duration left out

    @property
    def steps(self) -> int:
        return int(round(self.duration / self.T))

    def with_overrides(
        self, controller: str | None = None, seed: int | None = None, duration: float | None = None
    ) -> Scenario:
        """The same scenario with the command line's --controller, --seed, --duration applied; a bad
        value is a ConfigError naming the flag, not the file."""
        table = copy.deepcopy(self.table)
        if controller is not None:
            if controller not in CONTROLLERS:
                raise ConfigError(
                    "--controller", f"unknown controller {controller!r}; choose one of {', '.join(CONTROLLERS)}"
                )
            table.setdefault("controller", {})["name"] = controller
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                raise ConfigError("--seed", f"expected a whole number >= 0, got {seed!r}")
            table["seed"] = seed
        if duration is None:
            return parse(table, self.source, check_model=False)
        if isinstance(duration, bool) or not isinstance(duration, int | float) or not math.isfinite(duration):
            raise ConfigError("--duration", f"expected a finite number of seconds, got {duration!r}")
        if duration < self.T:
            raise ConfigError("--duration", f"{duration:g} s is shorter than one control period T = {self.T:g} s")
        events, dropped = table.get("events"), ()
        if isinstance(events, list):  # an event the shortened run never reaches cannot happen: it is left out
            kept = [ev for ev in events if not (isinstance(ev, dict) and _after(ev.get("time"), duration))]
            dropped = tuple(ev["time"] for ev in events if ev not in kept)
            table["events"] = kept
        table["duration"] = duration
        try:
            scn = parse(table, self.source, check_model=False)
        except ConfigError as err:
            if err.where.endswith(" duration"):
                raise ConfigError(f"--duration {duration:g}", err.what) from None
            raise
        return dataclasses.replace(scn, dropped_events=self.dropped_events + dropped) if dropped else scn

    def initial_state(self, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The initial pose (the reference's at t = 0, offset by the initial error) and velocity."""
        q0 = pose_from_error(np.array(self.initial_error), ref[0])
        return q0, (ref[0, 3:5].copy() if self.start_moving else None)


def _after(t, duration: float) -> bool:
    return isinstance(t, int | float) and not isinstance(t, bool) and t >= duration


def shipped_dir() -> Path:
    """The folder of the shipped scenarios (sims/, installed as package data mlpfac.sims)."""
    return Path(str(importlib.resources.files("mlpfac.sims")))


def scenario_names() -> list[str]:
    """Names of the shipped scenarios."""
    return sorted(p.stem for p in shipped_dir().glob("*.toml"))


def read_toml(path: Path, kind: str) -> dict:
    """The TOML file at ``path`` (a ``kind``, e.g. "scenario file"); a ConfigError naming it when it
    cannot be read or is not UTF-8 TOML."""
    try:
        return tomllib.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError(str(path), f"{kind} not found") from None
    except IsADirectoryError:
        raise ConfigError(str(path), f"is a folder, not a {kind}") from None
    except OSError as err:
        raise ConfigError(str(path), f"cannot read: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise ConfigError(str(path), "not a text file (TOML is UTF-8 text)") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(str(path), f"not valid TOML: {err}") from None


def load(name_or_path: str | Path, build: bool = True) -> Scenario:
    """A scenario by name (``paper`` -> the shipped paper.toml) or by path to a TOML file.

    Relative paths in the file (``[plant] model``) are taken from the file's own folder. The plant
    is built once here, so that a robot or an event it cannot apply is an error before anything
    runs, and what it simulates is recorded in the table's ``[provenance]`` (config.toml). A file
    that already has ``[provenance]`` (a run's config.toml) must simulate the same compiled model.
    ``build=False`` reads and checks the file alone (a listing), without building the plant.
    """
    path = Path(name_or_path)
    if path.suffix != ".toml":
        if str(name_or_path) not in scenario_names():
            raise ConfigError(str(name_or_path), f"no such scenario; shipped ones: {', '.join(scenario_names())}")
        path = shipped_dir() / f"{name_or_path}.toml"
    table = read_toml(path, "scenario file")
    table.setdefault("name", path.stem)
    plant = table.get("plant")
    if (
        isinstance(plant, dict)
        and isinstance(plant.get("model"), str)
        and plant["model"]
        and not plant["model"].startswith("menagerie:")
    ):
        plant["model"] = str((path.parent / Path(plant["model"]).expanduser()).resolve())
    scn = parse(table, str(path))
    if not build:  # the file's data only (a listing): no robot is read, none downloaded
        return scn
    table["provenance"] = _provenance(scn)
    return dataclasses.replace(scn, table=table)


def _provenance(scn: Scenario) -> dict:
    """Build the plant once (every check made), and what it simulates."""
    from mlpfac import __version__
    from mlpfac.factory import make_plant
    from mlpfac.reference import sample

    plant = make_plant(scn, sample(scn.reference, np.arange(2) * scn.T))
    out = {"mlpfac": __version__, "numpy": np.__version__}
    if hasattr(plant, "provenance"):
        out |= plant.provenance()
    return out


def _check_provenance(recorded, config, where: str) -> None:
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


def _check_keys(table: dict, allowed: set[str], where: str) -> None:
    for key in table:
        if key not in allowed:
            raise ConfigError(f"{where} {key}", f"unknown key (known: {', '.join(sorted(allowed))})")


def _table(table: dict, key: str, where: str, default=None) -> dict:
    val = table.get(key, {} if default is None else default)
    if not isinstance(val, dict):
        raise ConfigError(f"{where} {key}", f"expected a table ([{key}]), got {val!r}")
    return dict(val)


def _number(table: dict, key: str, default: float, where: str, positive: bool = True) -> float:
    val = table.get(key, default)
    if isinstance(val, bool) or not isinstance(val, int | float) or not math.isfinite(val):
        raise ConfigError(f"{where} {key}", f"expected a finite number, got {val!r}")
    if positive and not val > 0:
        raise ConfigError(f"{where} {key}", f"must be positive, got {val}")
    if not positive and val < 0:
        raise ConfigError(f"{where} {key}", f"must be >= 0, got {val}")
    return float(val)


def _typed(value, hint, key: str) -> bool:
    """Whether a TOML value fits a dataclass field's type (float: a finite number, inf where it means no limit)."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_typed(value, h, key) for h in typing.get_args(hint))
    if origin is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, list | tuple):
            return False
        if len(args) == 2 and args[1] is Ellipsis:
            return all(_typed(v, args[0], key) for v in value)
        return len(value) == len(args) and all(_typed(v, h, key) for v, h in zip(value, args, strict=True))
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        return ok and (math.isfinite(value) or (key in INF_OK and value == math.inf))
    if hint is str:
        return isinstance(value, str)
    return True  # nested configs (Networks) are built on their own


def _describe(hint) -> str:
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(h) for h in typing.get_args(hint) if h is not type(None))
    if origin is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_describe(args[0])}s"
        return f"a list of {len(args)} {_describe(args[0])}s"
    return {bool: "true or false", int: "a whole number", float: "a finite number", str: "a string"}.get(
        hint, str(hint)
    )


def build(cls, table: dict, where: str):
    """A frozen config dataclass from a TOML table: unknown keys, wrong types and bad values name the key."""
    fields = {f.name for f in dataclasses.fields(cls)}
    _check_keys(table, fields, where)
    hints = typing.get_type_hints(cls)
    values = {}
    for key, val in table.items():
        if not _typed(val, hints[key], key):
            raise ConfigError(f"{where} {key}", f"expected {_describe(hints[key])}, got {val!r}")
        if key in NO_LIMIT and val == math.inf:
            val = None  # inf: no limit
        values[key] = tuple(val) if isinstance(val, list) else val
    try:
        return cls(**values)
    except ConfigError as err:
        raise ConfigError(f"{where} {err.where}".strip(), err.what) from None
    except (TypeError, ValueError) as err:
        raise ConfigError(where, str(err)) from None


def _memory_available() -> int:
    """Bytes of memory available now (MemAvailable), or the physical memory where that is unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def memory_needed(steps: int, alpha: int, estimator: str) -> int:
    """Bytes a run keeps: the record (about 40 values a step, plus the alpha weights of an adaptive
    controller) and the weight filter (P and its work buffer; the UKF's 2 alpha + 1 sigma points)."""
    filt = 8 * alpha * alpha * (2 if estimator == "ekf" else 6) if alpha else 0
    return 8 * steps * (40 + alpha) + filt


def parse(table: dict, source: str = "<scenario>", check_model: bool = True) -> Scenario:
    """Validate a scenario table (as read from TOML) into a :class:`Scenario`.

    A table with ``[provenance]`` (a run's config.toml) must name the same compiled model it was
    made with; ``check_model=False`` skips that compile where the table's model was just checked."""
    if not isinstance(table, dict):
        raise ConfigError(source, "expected a table of scenario keys")
    _check_keys(table, TOP_KEYS, source)
    T = _number(table, "T", 0.01, source)
    duration = _number(table, "duration", 25.0, source)
    if duration < T:
        raise ConfigError(f"{source} duration", f"{duration:g} s is shorter than one control period T = {T:g} s")
    seed = table.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"{source} seed", f"expected a whole number >= 0, got {seed!r}")
    name = table.get("name", "scenario")
    if not isinstance(name, str) or not NAME.fullmatch(name):
        raise ConfigError(
            f"{source} name", f"a scenario name is letters, digits and . _ + - (it names folders), got {name!r}"
        )
    description = table.get("description", "")
    if not isinstance(description, str):
        raise ConfigError(f"{source} description", f"expected a string, got {description!r}")

    ref_table = _table(table, "reference", source, {"kind": "eight"})
    kind = ref_table.pop("kind", "eight")
    for key, val in ref_table.items():
        if isinstance(val, bool) or not isinstance(val, int | float) or not math.isfinite(val):
            raise ConfigError(f"{source} [reference] {key}", f"expected a finite number, got {val!r}")
    reference = make_reference(kind, ref_table, f"{source} [reference]")

    initial = _table(table, "initial", source)
    _check_keys(initial, {"error", "moving"}, f"{source} [initial]")
    moving = initial.get("moving", True)
    if not isinstance(moving, bool):
        raise ConfigError(f"{source} [initial] moving", f"expected true or false, got {moving!r}")
    e0 = initial.get("error", [0.0, 0.0, 0.0])
    if not _typed(e0, tuple[float, float, float], "error"):
        raise ConfigError(f"{source} [initial] error", f"expected three finite numbers (e1, e2, e3), got {e0!r}")

    plant_table = _table(table, "plant", source, {"kind": "kinematic"})
    plant_kind = plant_table.pop("kind", "kinematic")
    where = f"{source} [plant]"
    if plant_kind == "kinematic":
        from mlpfac.plants.kinematic import KinematicConfig

        plant_config = build(KinematicConfig, plant_table, where)
    elif plant_kind == "mujoco":
        from mlpfac.plants.config import MujocoConfig

        plant_config = build(MujocoConfig, plant_table, where)
    else:
        raise ConfigError(f"{where} kind", f"unknown plant {plant_kind!r}; choose kinematic or mujoco")
    if "provenance" in table and check_model:
        _check_provenance(table["provenance"], plant_config, f"{source} [provenance]")

    ctrl = _table(table, "controller", source)
    where = f"{source} [controller]"
    _check_keys(ctrl, CONTROLLER_KEYS, where)
    name_c = ctrl.get("name", "adaptive")
    if name_c not in CONTROLLERS:
        raise ConfigError(f"{where} name", f"unknown controller {name_c!r}; choose one of {', '.join(CONTROLLERS)}")
    law = build(Law, {k: ctrl[k] for k in ("lambdas", "v_max", "omega_max") if k in ctrl}, where)
    ad = _table(ctrl, "adaptive", where)
    _check_keys(ad, ADAPTIVE_KEYS, f"{where}.adaptive")
    nets = build(Networks, {k: ad.pop(k) for k in list(ad) if k in NETWORK_KEYS}, f"{where}.adaptive")
    adaptive = build(AdaptiveConfig, ad, f"{where}.adaptive")
    adaptive = dataclasses.replace(adaptive, networks=nets)
    kanayama = build(KanayamaGains, _table(ctrl, "kanayama", where), f"{where}.kanayama")

    steps = int(round(duration / T))
    alpha = nets.alpha if name_c in VARIANTS else 0
    need, have = memory_needed(steps, alpha, adaptive.estimator), _memory_available()
    if need > MEMORY_SHARE * have:
        raise ConfigError(
            f"{source} duration",
            f"{steps} steps of {alpha} weights need about {need / 2**30:.3g} GiB; {have / 2**30:.3g} GiB of memory "
            "is available: shorten the duration, lengthen T or shrink the networks",
        )

    raw_events = table.get("events", [])
    if not isinstance(raw_events, list):
        raise ConfigError(f"{source} events", f"expected [[events]] tables, got {raw_events!r}")
    events = [parse_event(ev, duration, f"{source} [[events]] #{i + 1}") for i, ev in enumerate(raw_events)]
    events.sort(key=lambda ev: ev.time)

    return Scenario(
        name=name,
        description=description,
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
        controller=name_c,
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
            return json.dumps(v, ensure_ascii=False)  # a JSON string is a TOML basic string
        if isinstance(v, float) and math.isinf(v):
            return "inf" if v > 0 else "-inf"
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
