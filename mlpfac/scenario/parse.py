"""Scenario files (TOML) -> frozen, validated configuration; the factories for plant and controller.

A scenario names the reference, the plant, the controller and its parameters, the events that
change the plant mid-run, the duration and the seed. See ``sims/*.toml`` and docs/scenarios.md.
"""

from __future__ import annotations

import copy
import dataclasses
import importlib.resources
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mlpfac.control.adaptive.config import AdaptiveConfig
from mlpfac.control.adaptive.networks import Networks
from mlpfac.control.baselines import KanayamaGains
from mlpfac.control.law import Law
from mlpfac.control.mpc.config import MpcConfig
from mlpfac.control.plugins import Plugin, absolute_spec, is_plugin_spec, resolve
from mlpfac.control.policy import PolicyFile, is_policy_spec, policy_file, policy_name, read_policy
from mlpfac.control.variants import CONTROLLERS, MPC_NAMES, TORQUE_LEVEL, VARIANTS
from mlpfac.exceptions import ConfigError
from mlpfac.model import pose_from_error
from mlpfac.plants import refuse_torque
from mlpfac.plants.events import Event, parse_event
from mlpfac.plants.world.layout import Terrain
from mlpfac.plants.world.table import World, parse_world
from mlpfac.scenario import provenance
from mlpfac.scenario.draws import check_ends
from mlpfac.scenario.draws import put as put_value
from mlpfac.scenario.draws import resolve as draw_values
from mlpfac.scenario.draws import restore as restore_draws
from mlpfac.scenario.reference import make_reference
from mlpfac.scenario.world import SAMPLE_BYTES, ground, recorded, recorded_bumps
from mlpfac.tables import (  # noqa: F401 (mlpfac.scenario.parse.to_toml)
    FOLDER_NAME,
    build,
    check_keys,
    number,
    read_toml,
    subtable,
    to_toml,
    typed,
)

INITIAL_ERROR_MAX = 1e3  # m (e1, e2) and rad (e3): a start beyond this is not a tracking problem
MEMORY_SHARE = 0.8  # a run may plan to use at most this share of the memory available now
LOST_MAX = 1e4  # m: the largest lost_threshold_m

TOP_KEYS = {
    "name",
    "description",
    "duration",
    "T",
    "seed",
    "warmup",
    "divergence_m",
    "lost_threshold_m",
    "reference",
    "initial",
    "plant",
    "controller",
    "events",
    "world",
    "provenance",
    "drawn",
}
CONTROLLER_KEYS = {"name", "lambdas", "v_max", "omega_max", "adaptive", "kanayama", "mpc", "params"}
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
    plugin: Plugin | None = None  # a user's controller (mlpfac.control.plugins); None: a shipped one
    policy: PolicyFile | None = None  # a policy's weights (mlpfac.control.policy): policy-dr or a .npz file
    plant_from: str = ""  # the robot its [plant] came from (--robot NAME: messages name it); "": the file's own
    world: World = World()  # the [world] table: ramps, rough ground, floor patches
    terrain: Terrain | None = None  # ... resolved for this run: where the ramps lie, the ground drawn for its seed
    lost_threshold_m: float | None = None  # position RMS beyond which a run is lost; None: 5 % of the path's size
    mpc: MpcConfig = MpcConfig()  # [controller.mpc]: the model-predictive controllers' settings

    @property
    def drawn(self) -> dict[str, float]:
        """What was drawn for this seed in place of each distribution of the file, by key (:mod:`mlpfac.scenario.draws`)."""
        return dict(self.table.get("drawn", {}))

    @property
    def level(self) -> str:
        """What the controller commands: "velocity" (v, omega), or "torque" (the wheels' torques)."""
        if self.plugin is not None:
            return self.plugin.level
        if self.controller in MPC_NAMES:  # the drive the robot has: torques to torque motors
            return "torque" if getattr(self.plant_config, "actuator", None) == "torque" else "velocity"
        return "torque" if self.controller in TORQUE_LEVEL else "velocity"

    @property
    def steps(self) -> int:
        return int(round(self.duration / self.T))

    def with_overrides(
        self,
        controller: str | None = None,
        seed: int | None = None,
        duration: float | None = None,
        flag: str = "--controller",
        lost_threshold: float | None = None,
    ) -> Scenario:
        """The same scenario with the command line's --controller, --seed, --duration and
        --lost-threshold applied; a bad value is a ConfigError naming the flag, not the file. A
        plug-in's ``file.py:Class`` is taken from the current folder; another controller than the
        file's drops its ``[controller.params]``."""
        table = copy.deepcopy(self.table)
        table.pop("drawn", None)  # drawn again, for the seed it runs
        if lost_threshold is not None:
            table["lost_threshold_m"] = lost_threshold_m(lost_threshold, "--lost-threshold")
        if controller is not None:
            if not isinstance(controller, str) or not controller:
                raise ConfigError(flag, f"expected a controller's name, got {controller!r}")
            controller = absolute_spec(controller, Path.cwd())
            ctrl = table.setdefault("controller", {})
            if ctrl.get("name", "adaptive") != controller:
                ctrl.pop("params", None)
                ctrl["name"] = controller
            if is_plugin_spec(controller):  # checked here, so that an error names the flag
                _plugin(ctrl, self.T, flag, self.source)
            elif is_policy_spec(controller):
                _policy(controller, flag)
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                raise ConfigError("--seed", f"expected a whole number >= 0, got {seed!r}")
            table["seed"] = seed
        if duration is None:
            return parse(table, self.source, check_model=False, plant_from=self.plant_from)
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
        if isinstance(table.get("world"), dict) and self.world:  # the world stays laid out as the file's run
            table["world"] = {"over": self.world.over or self.duration} | table["world"]
        try:
            scn = parse(table, self.source, check_model=False, plant_from=self.plant_from)
        except ConfigError as err:
            if err.where.endswith(" duration"):
                raise ConfigError(f"--duration {duration:g}", err.what) from None
            raise
        if duration != self.duration:  # what the reference asks of torque motors, over the run it is now
            scn = dataclasses.replace(scn, table=provenance.with_torque_need(scn.table, scn))
        return dataclasses.replace(scn, dropped_events=self.dropped_events + dropped) if dropped else scn

    def initial_state(self, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The initial pose (the reference's at t = 0, offset by the initial error) and velocity."""
        q0 = pose_from_error(np.array(self.initial_error), ref[0])
        return q0, (ref[0, 3:5].copy() if self.start_moving else None)


def lost_threshold_m(value, where: str) -> float:
    """A lost threshold in metres (``lost_threshold_m``, ``--lost-threshold``): above 0, at most
    LOST_MAX; a ConfigError naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(where, f"expected a number of metres, got {value!r}")
    if not 0 < value <= LOST_MAX:
        raise ConfigError(where, f"must be a number of metres above 0 and at most {LOST_MAX:g}, got {value!r}")
    return float(value)


def _after(t, duration: float) -> bool:
    return isinstance(t, int | float) and not isinstance(t, bool) and t >= duration


def shipped_dir() -> Path:
    """The folder of the shipped scenarios (sims/, installed as package data mlpfac.sims)."""
    return Path(str(importlib.resources.files("mlpfac.sims")))


def scenario_names() -> list[str]:
    """Names of the shipped scenarios."""
    return sorted(p.stem for p in shipped_dir().glob("*.toml"))


def load(
    name_or_path: str | Path,
    build: bool = True,
    robot: str | None = None,
    values: dict | None = None,
    ends: bool = True,
) -> Scenario:
    """A scenario by name (``paper`` -> the shipped paper.toml) or by path to a TOML file.

    Relative paths in the file (``[plant] model``) are taken from the file's own folder. The plant
    is built once here, so that a robot or an event it cannot apply is an error before anything
    runs, and what it simulates is recorded in the table's ``[provenance]`` (config.toml). A file
    that already has ``[provenance]`` (a run's config.toml) must simulate the same compiled model.
    The robot's parts the file leaves to the model (its wheels, its pose frame) are written into the
    table's ``[plant]`` as found, so that config.toml names them. ``build=False`` reads and checks
    the file alone (a listing), without building the plant. ``robot`` (``--robot``) puts the
    scenario on another robot (:mod:`mlpfac.scenario.on_robot`); without it, a MuJoCo robot's file
    whose reference leaves its speed unset gets it fitted to the robot by the same rule, and one that
    asks more than the wheels give is warned (``[provenance] reference_fit``, ``reference_warning``);
    on torque motors, what the reference asks of them is said, and warned beyond their limit
    (``reference_torque``, ``torque_warning``: :func:`mlpfac.scenario.on_robot.torque_need`). ``values`` sets numbers of the file by
    their dotted keys (:mod:`mlpfac.scenario.draws`) before it is checked, as if written in it.
    Every distribution of the file is checked at both ends of what it can draw (``ends``; a sweep's
    grid checks them itself), so that no seed's draw fails where another's ran.
    """
    if not isinstance(name_or_path, str | os.PathLike) or not str(name_or_path):
        raise ConfigError("scenario", f"expected a shipped scenario's name or a .toml file, got {name_or_path!r}")
    path = Path(name_or_path)
    if path.suffix != ".toml":
        if str(name_or_path) not in scenario_names():
            raise ConfigError(str(name_or_path), f"no such scenario; shipped ones: {', '.join(scenario_names())}")
        path = shipped_dir() / f"{name_or_path}.toml"
    table = read_toml(path, "scenario file")
    table.setdefault("name", path.stem)
    for key, value in (values or {}).items():
        if not put_value(table, key, value):
            raise ConfigError(f"{path} {key}", "no such key in this scenario file")
    ctrl = table.get("controller")
    if isinstance(ctrl, dict) and isinstance(ctrl.get("name"), str):  # file.py:Class, from the file's folder
        ctrl["name"] = absolute_spec(ctrl["name"], path.parent)
    ref = table.get("reference")
    if isinstance(ref, dict):  # your own reference class, or a path's CSV file, from the file's folder too
        if isinstance(ref.get("kind"), str):
            ref["kind"] = absolute_spec(ref["kind"], path.parent)
        if isinstance(ref.get("file"), str) and ref["file"]:
            ref["file"] = str((path.parent / Path(ref["file"]).expanduser()).resolve())
    plant = table.get("plant")
    if (
        isinstance(plant, dict)
        and isinstance(plant.get("model"), str)
        and plant["model"]
        and not plant["model"].startswith("menagerie:")
    ):
        plant["model"] = str((path.parent / Path(plant["model"]).expanduser()).resolve())
    if ends:  # each distribution at both ends of what it can draw, loaded as the file is
        check_ends(table, str(path), lambda at_end: _built(at_end, path, build, robot, values))
    return _built(table, path, build, robot, values)


def _built(table: dict, path: Path, build: bool, robot: str | None, values: dict | None) -> Scenario:
    """:func:`load`'s scenario from the file's table as read (its values set, its paths resolved)."""
    plant_from, said = "", {}
    if robot is not None:
        from mlpfac.scenario.on_robot import on_robot_fit, robot_where

        parse(table, str(path), check_model=False)  # the file's own errors first, named as its own
        (table, said), plant_from = on_robot_fit(table, robot), robot_where(robot)
        for key, value in (values or {}).items():  # a limit asked for wins over the robot's (--vary controller.v_max)
            if key.startswith("controller."):
                put_value(table, key, value)
    scn = parse(table, str(path), plant_from=plant_from)
    if not build:  # the file's data only (a listing): no robot is read, none downloaded
        return scn
    if robot is None and scn.plant_kind == "mujoco":  # its reference fitted to its robot, or warned
        from mlpfac.scenario.on_robot import on_its_robot

        fitted, said = on_its_robot(table, scn)
        if fitted is not table:
            table, scn = fitted, parse(fitted, str(path), check_model=False)  # (no robot: its own [plant])
    table["provenance"], found = provenance.recorded(scn)
    table["provenance"] |= said
    if found:  # the robot's parts the file left to the model: written in, so its config.toml re-runs the same
        table["plant"] = table["plant"] | found
        return parse(table, str(path), check_model=False, plant_from=plant_from)
    return dataclasses.replace(scn, table=scn.table | {"provenance": table["provenance"]})


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


def parse(table: dict, source: str = "<scenario>", check_model: bool = True, plant_from: str = "") -> Scenario:
    """Validate a scenario table (as read from TOML) into a :class:`Scenario`.

    A table with ``[provenance]`` (a run's config.toml) must name the same compiled model it was
    made with; ``check_model=False`` skips that compile where the table's model was just checked.
    ``plant_from``: the robot (``--robot NAME``) the table's ``[plant]`` came from, which messages
    about it name in place of the file."""
    if not isinstance(table, dict):
        raise ConfigError(source, "expected a table of scenario keys")
    check_keys(table, TOP_KEYS, source)
    seed = table.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"{source} seed", f"expected a whole number >= 0, got {seed!r}")
    table, bumps_drawn = recorded_bumps(table, source)
    table, draws = draw_values(table, seed, source)  # each distribution replaced by its draw for this seed
    T = number(table, "T", 0.01, source)
    duration = number(table, "duration", 25.0, source)
    if duration < T:
        raise ConfigError(f"{source} duration", f"{duration:g} s is shorter than one control period T = {T:g} s")
    name = table.get("name", "scenario")
    if not isinstance(name, str) or not FOLDER_NAME.fullmatch(name):
        raise ConfigError(
            f"{source} name", f"a scenario name is letters, digits and . _ + - (it names folders), got {name!r}"
        )
    description = table.get("description", "")
    if not isinstance(description, str):
        raise ConfigError(f"{source} description", f"expected a string, got {description!r}")

    initial = subtable(table, "initial", source)
    check_keys(initial, {"error", "moving"}, f"{source} [initial]")
    moving = initial.get("moving", True)
    if not isinstance(moving, bool):
        raise ConfigError(f"{source} [initial] moving", f"expected true or false, got {moving!r}")
    e0 = initial.get("error", [0.0, 0.0, 0.0])
    if not typed(e0, tuple[float, float, float], "error") or max(map(abs, e0)) > INITIAL_ERROR_MAX:
        raise ConfigError(
            f"{source} [initial] error",
            f"expected three numbers within +-{INITIAL_ERROR_MAX:g} (e1, e2, e3), got {e0!r}",
        )

    plant_table = subtable(table, "plant", source, {"kind": "kinematic"})
    plant_kind = plant_table.pop("kind", "kinematic")
    where = f"{plant_from} [plant]" if plant_from else f"{source} [plant]"
    if plant_kind == "kinematic":
        from mlpfac.plants.kinematic import KinematicConfig

        plant_config = build(KinematicConfig, plant_table, where)
    elif plant_kind == "mujoco":
        from mlpfac.plants.config import MujocoConfig

        plant_config = build(MujocoConfig, plant_table, where)
        from mlpfac.plants.sensors.sensing import check_run

        check_run(plant_config, duration, T, where)  # the fixes against the run's length and period
    else:
        raise ConfigError(f"{where} kind", f"unknown plant {plant_kind!r}; choose kinematic or mujoco")
    if "provenance" in table and check_model:
        provenance.check_model(table["provenance"], plant_config, f"{source} [provenance]")

    ctrl = subtable(table, "controller", source)
    where = f"{source} [controller]"
    check_keys(ctrl, CONTROLLER_KEYS, where)
    name_c = ctrl.get("name", "adaptive")
    if not isinstance(name_c, str) or not name_c:
        raise ConfigError(f"{where} name", f"expected a controller's name, got {name_c!r}")
    plugin = policy = None
    if is_plugin_spec(name_c):
        plugin = _plugin(ctrl, T, f"{where} name", source)
        name_c = plugin.name
        table = provenance.with_controller(table, plugin, source, check_model)
    elif is_policy_spec(name_c):
        policy = _policy(name_c, f"{where} name")
        name_c = policy_name(name_c)
        table = provenance.with_controller(table, policy, source, check_model)
    if plugin is None and "params" in ctrl:
        raise ConfigError(
            f"{where} params", f"[controller.params] is for a plug-in controller; {name_c} takes its own keys"
        )
    if name_c in MPC_NAMES and plant_kind != "mujoco":
        raise ConfigError(
            f"{where} name", f"{name_c} plans with the run's MuJoCo robot as its model; this plant is {plant_kind}"
        )
    level = plugin.level if plugin is not None else "torque" if name_c in TORQUE_LEVEL else "velocity"
    if level == "torque":
        refuse_torque(name_c, plant_kind, getattr(plant_config, "actuator", None), source, plant_from, read=False)
    law = build(Law, {k: ctrl[k] for k in ("lambdas", "v_max", "omega_max") if k in ctrl}, where)
    ref_table = subtable(table, "reference", source, {"kind": "eight"})
    kind = ref_table.pop("kind", "eight")
    reference = make_reference(kind, ref_table, f"{source} [reference]", (law.v_max, law.omega_max))
    table = provenance.with_reference(table, reference, source, check_model)
    if "duration" not in table and hasattr(reference, "duration"):  # a path: once along it (one lap)
        duration = max(T, T * math.ceil(reference.duration / T - 1e-9))
    ad = subtable(ctrl, "adaptive", where)
    check_keys(ad, ADAPTIVE_KEYS, f"{where}.adaptive")
    nets = build(Networks, {k: ad.pop(k) for k in list(ad) if k in NETWORK_KEYS}, f"{where}.adaptive")
    adaptive = build(AdaptiveConfig, ad, f"{where}.adaptive")
    adaptive = dataclasses.replace(adaptive, networks=nets)
    kanayama = build(KanayamaGains, subtable(ctrl, "kanayama", where), f"{where}.kanayama")
    mpc = build(MpcConfig, subtable(ctrl, "mpc", where), f"{where}.mpc")

    steps = int(round(duration / T))
    alpha = nets.alpha if name_c in VARIANTS else 0
    need, have = memory_needed(steps, alpha, adaptive.estimator), _memory_available()
    if need > MEMORY_SHARE * have:
        said = f"{_count(steps)} steps of {alpha} weights need about {need / 2**30:.3g} GiB; {have / 2**30:.3g} GiB of memory is available"
        if "duration" not in table and hasattr(reference, "duration"):  # the path's time once along it: its key
            from mlpfac.scenario.waypoints import slowest

            def fits(s: float) -> bool:
                return memory_needed(int(round(s / T)), alpha, adaptive.estimator) <= MEMORY_SHARE * have

            key = slowest(ref_table, f"{source} [reference]", (law.v_max, law.omega_max), fits)
            raise ConfigError(
                f"{source} [reference]{' ' + key if key else ''}",
                f"the path takes {duration:.3g} s to drive once, the run's duration: {said}; "
                + (f"raise {key}" if key else "raise its limits")
                + " or set the run's duration",
            )
        raise ConfigError(f"{source} duration", f"{said}: shorten the duration, lengthen T or shrink the networks")

    raw_events = table.get("events", [])
    if not isinstance(raw_events, list):
        raise ConfigError(f"{source} events", f"expected [[events]] tables, got {raw_events!r}")
    events = [parse_event(ev, duration, f"{source} [[events]] #{i + 1}") for i, ev in enumerate(raw_events)]
    events.sort(key=lambda ev: ev.time)

    lost = table.get("lost_threshold_m")
    lost = None if lost is None else lost_threshold_m(lost, f"{source} lost_threshold_m")
    if lost is None and hasattr(reference, "stands_still") and reference.stands_still(duration):
        raise ConfigError(
            f"{source} [reference] kind",
            f"{kind.rpartition(':')[2]} stands still over the run ((x, y) the same at every time): no path's size "
            "bounds its error (a run is lost beyond 5 % of it); set lost_threshold_m = METRES to judge the run",
        )
    world = parse_world(table.get("world", {}), f"{source} [world]")
    samples = int(round((world.over or duration) / T)) + 1 if world else 0  # the reference it is laid out along
    if SAMPLE_BYTES * samples > MEMORY_SHARE * have:
        raise ConfigError(
            f"{source} [world] over" if world.over else f"{source} duration",
            f"the world is laid out along {samples} samples of the reference, about "
            f"{SAMPLE_BYTES * samples / 2**30:.3g} GiB; {have / 2**30:.3g} GiB of memory is available: shorten it or "
            "lengthen T",
        )
    terrain = ground(world, plant_kind, reference, world.over or duration, T, e0, seed, source)
    out = recorded(restore_draws(table, draws), terrain, bumps_drawn, seed, source)

    return Scenario(
        name=name,
        description=description,
        source=source,
        duration=duration,
        T=T,
        seed=seed,
        warmup=number(table, "warmup", 2.0, source, positive=False),
        divergence_m=number(table, "divergence_m", 5.0, source),
        lost_threshold_m=lost,
        initial_error=tuple(float(x) for x in e0),
        start_moving=moving,
        reference=reference,
        plant_kind=plant_kind,
        plant_config=plant_config,
        controller=name_c,
        law=law,
        adaptive=adaptive,
        kanayama=kanayama,
        mpc=mpc,
        events=tuple(events),
        table=out,
        plugin=plugin,
        policy=policy,
        plant_from=plant_from,
        world=world,
        terrain=terrain,
    )


def _count(n: int) -> str:
    """A count in words a line can hold: 1200000240, or 3.48e+305 beyond a billion."""
    return f"{n}" if n < 10**10 else f"{n:.3g}"


def _policy(name: str, where: str) -> PolicyFile:
    """The policy ``name`` names (shipped, or a .npz file), read and checked; its name a folder's."""
    short = policy_name(name)
    if name not in CONTROLLERS and (not FOLDER_NAME.fullmatch(short) or short in CONTROLLERS):
        raise ConfigError(where, f"{name}: a policy file's name ({short!r}) names its folders: letters, digits and "
                          ". _ + -, not a shipped controller's name")  # fmt: skip
    return read_policy(policy_file(name), where)


def _plugin(ctrl: dict, T: float, where: str, source: str) -> Plugin:
    """The plug-in ``[controller] name`` names (``where`` names that), with its ``[controller.params]``."""
    params = ctrl.get("params", {})
    if not isinstance(params, dict):
        raise ConfigError(f"{source} [controller] params", f"expected a table ([controller.params]), got {params!r}")
    return resolve(ctrl["name"], params, T, where, f"{source} [controller.params]")
