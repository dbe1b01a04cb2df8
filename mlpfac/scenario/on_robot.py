"""Any scenario on any robot (``--robot NAME_OR_PATH``): a scenario's reference, events, noise and
controller put on another robot, by one rule (docs/robots.md):

- the robot is its model alone (``[plant] kind = "mujoco"``, ``model``), or a robot file's
  ``[plant]`` table: every other part is found or chosen in the model
  (:mod:`mlpfac.plants.defaults`); the scenario's pose noise is kept;
- the reference is slowed in time (the same path, v and omega x k, k <= 1) until its peak wheel
  speed (|v| + |omega| b / 2) / r is at most ``SHARE`` of the robot's wheel-speed limit: the
  servos' control range, or, for a drive without one, the speed at which the wheels' largest torque
  meets their joints' damping;
- the controller's limits follow the robot's: ``v_max = r w_max``, ``omega_max = 2 r w_max / b``;
- events mean the same physical change: relative ones as they are (wheel radius x1.5 is x1.5 of
  this robot's wheel, mass x3 of its base), absolute ones too (a 5 kg payload, a floor of friction
  0.2, a 40 ms delay); a payload on a body of the other robot goes on this one's base.
"""

from __future__ import annotations

import copy
import importlib.resources
import math
from pathlib import Path

from mlpfac.exceptions import ConfigError

SHARE = 0.5  # the reference's peak wheel speed, as a share of the robot's wheel-speed limit
MENAGERIE_BASES = (
    "pal_tiago",
    "pal_tiago_dual",
    "hello_robot_stretch",
    "hello_robot_stretch_3",
    "rainbow_robotics_rby1",
)
AS_SHIPPED = {  # what a Menagerie base does from its name alone (tests/test_robots.py checks each)
    "pal_tiago_dual": "a skid-steer as modelled (four plain wheels, not the mecanum wheels of its omnidirectional "
    "base): given a rotor on each wheel, it turns as a track of 0.98 m (docs/robots.md)",
    "rainbow_robotics_rby1": "refused as shipped: its wheel servos (kv 1) cannot turn the wheels against their "
    "damping; --robot rby1a drives it",
}
SHIPPED = {"diffdrive": "scene.xml", "cart": "cart-scene.xml", "rby1a": "rby1a.toml"}  # this package's (models/)
SPEEDS = {"eight": ("wx", "wy"), "circle": ("rate",), "line": ("speed",), "lemniscate": ("rate",)}
DEFAULT_SPEEDS = {"eight": (0.25, 0.5), "circle": (0.5,), "line": (0.5,), "lemniscate": (0.3,)}
PEAK_SAMPLES = 2001


ROBOT_HELP = (
    "run the scenario on this robot: diffdrive, cart, a MuJoCo Menagerie base (pal_tiago, hello_robot_stretch_3, "
    "menagerie:NAME/ENTRY, ...), an MJCF file, or a TOML file of one [plant] table; the reference is slowed to "
    "what it can drive (docs/robots.md)"
)
AT = "@"  # SCENARIO@ROBOT: a scenario of a sweep on a robot (--robot, --robots, a budget's robots)


def with_robots(scenarios: list[str], robots: list[str] | None) -> list[str]:
    """Each scenario on each robot, as SCENARIO@ROBOT (the scenarios as they are without robots)."""
    if not robots:
        return list(scenarios)
    for r in robots:
        model_of(r)  # a bad robot is named before anything runs
    return [f"{s}{AT}{r}" for s in scenarios for r in robots]


def split_robot(src: str) -> tuple[str, str | None]:
    """(scenario, robot or None) of a sweep's SCENARIO@ROBOT."""
    head, at, robot = str(src).rpartition(AT)
    return (head, robot) if at and head else (str(src), None)


def robots_flag(text: str | None, flag: str) -> list[str] | None:
    """The robots of a comma-separated flag (None when not given)."""
    if text is None:
        return None
    robots = [r.strip() for r in text.split(",")]
    if not all(robots):
        raise ConfigError(flag, f"expected comma-separated robots, got {text!r}")
    return robots


def model_of(robot: str) -> str:
    """The ``[plant] model`` a ``--robot`` names: a shipped robot, a Menagerie one (``NAME``,
    ``menagerie:NAME[/ENTRY]``), an MJCF file (from the current folder), or a robot file's."""
    if not isinstance(robot, str) or not robot:
        raise ConfigError("--robot", f"expected a robot's name or an MJCF file, got {robot!r}")
    if robot in SHIPPED:
        robot = _shipped(robot)
        return str(robot_table(robot)["model"]) if robot.endswith(".toml") else robot
    if robot.startswith("menagerie:"):
        return robot
    if robot.split("/")[0] in MENAGERIE_BASES:
        return f"menagerie:{robot}"
    path = Path(robot).expanduser()
    if path.suffix.lower() == ".toml":
        return str(robot_table(robot)["model"])
    if path.suffix.lower() != ".xml":
        known = ", ".join([*SHIPPED, *MENAGERIE_BASES])
        raise ConfigError("--robot", f"{robot!r} is neither a robot ({known}) nor an MJCF file (.xml)")
    if not path.is_file():
        raise ConfigError("--robot", f"{path}: MJCF model file not found")
    return str(path.resolve())


def _shipped(robot: str) -> str:
    return str(importlib.resources.files("mlpfac.models") / SHIPPED[robot])


def robot_table(robot: str) -> dict:
    """The ``[plant]`` table of a robot: a TOML file's (a robot with the keys that make it drive,
    its model relative to the file), else ``model`` alone."""
    path = Path(_shipped(robot) if robot in SHIPPED else robot).expanduser()
    if path.suffix.lower() != ".toml":
        return {"kind": "mujoco", "model": model_of(robot)}
    from mlpfac.tables import read_toml

    table = read_toml(path, "robot file")
    plant = table.get("plant")
    if set(table) != {"plant"} or not isinstance(plant, dict) or not isinstance(plant.get("model"), str):
        raise ConfigError(f"--robot {path}", "a robot file holds one [plant] table with its model")
    plant = {"kind": "mujoco", **plant}
    if not plant["model"].startswith("menagerie:"):
        plant["model"] = str((path.parent / plant["model"]).resolve())
    return plant


def robots_here() -> list[tuple[str, str]]:
    """(name, where it is, or why it cannot run here) of each robot ``--robot`` knows by name."""
    out = [(name, f"shipped (models/{file})") for name, file in SHIPPED.items()]
    out[-1] = (out[-1][0], f"{out[-1][1]}: rainbow_robotics_rby1 with the keys that make it drive")
    try:
        import mujoco_menagerie as mm
    except ImportError:
        why = "needs the mujoco-menagerie package: pip install 'mlpfac[menagerie]'"
        return out + [(name, why) for name in MENAGERIE_BASES]
    cache = mm.Cache()
    for name in MENAGERIE_BASES:
        if cache.root is not None:
            here = (cache.root / name).is_dir()
            where = f"MuJoCo Menagerie, {'in' if here else 'not in'} MENAGERIE_ROOT={cache.root}"
        elif cache.is_cached(mm.get(name)):
            where = f"MuJoCo Menagerie, downloaded ({cache.dir})"
        else:
            where = "MuJoCo Menagerie, not downloaded: fetched on first use online; offline set MENAGERIE_ROOT"
        out.append((name, f"{where}; {AS_SHIPPED[name]}" if name in AS_SHIPPED else where))
    return out


def robot_name(robot: str) -> str:
    """A short name of the robot for a scenario's name: letters, digits and . _ -."""
    file = robot.endswith((".xml", ".toml"))
    stem = Path(robot).stem if file else robot.removeprefix("menagerie:").split("/")[0]
    return "".join(c if c.isalnum() or c in "._-" else "-" for c in stem) or "robot"


def on_robot(table: dict, robot: str) -> dict:
    """The scenario ``table`` (as read from its file) put on ``robot`` by the module's rule."""
    import numpy as np

    from mlpfac.plants.config import MujocoConfig
    from mlpfac.plants.events import ControlPeriod, parse_event
    from mlpfac.plants.robot import read_robot
    from mlpfac.scenario.reference import make_reference, sample

    out = copy.deepcopy(table)
    out.pop("provenance", None)  # what another robot's run simulated
    old = out.get("plant") if isinstance(out.get("plant"), dict) else {}
    plant = robot_table(robot)
    if "pose_noise_std" in old and "pose_noise_std" not in plant:
        plant["pose_noise_std"] = old["pose_noise_std"]
    T = float(out.get("T", 0.01))
    duration = float(out.get("duration", 25.0))
    raw = out.get("events", []) if isinstance(out.get("events"), list) else []
    events = [parse_event(ev, duration, f"[[events]] #{i + 1}") for i, ev in enumerate(raw)]
    periods = (T, *(ev.factor * T for ev in events if isinstance(ev, ControlPeriod)))
    try:
        r = read_robot(MujocoConfig(**{k: v for k, v in plant.items() if k != "kind"}), periods)
    except TypeError as err:
        raise ConfigError(f"--robot {robot}", f"not a [plant] key: {err}") from None
    except ConfigError as err:
        raise type(err)(f"--robot {robot}: {err.where}".rstrip(": "), err.what) from None
    w_max = wheel_speed_limit(r)
    ref = dict(out.get("reference", {"kind": "eight"}))
    kind = ref.get("kind", "eight")
    if w_max is not None and kind in SPEEDS:
        curve = make_reference(kind, {k: v for k, v in ref.items() if k != "kind"})
        rows = sample(curve, np.linspace(0.0, 4 * duration, PEAK_SAMPLES))
        peak = float(np.max((np.abs(rows[:, 3]) + np.abs(rows[:, 4]) * r.real_track / 2) / r.real_radius))
        k = min(1.0, SHARE * w_max / peak)
        said = f"reference x{k:.3g} in speed (peak wheel speed {k * peak:.3g} of {w_max:.3g} rad/s)"
        if k < 1.0:
            for key, default in zip(SPEEDS[kind], DEFAULT_SPEEDS[kind], strict=True):
                ref[key] = float(f"{k * float(ref.get(key, default)):.6g}")
        out["reference"] = ref
        ctrl = out.setdefault("controller", {})
        ctrl["v_max"] = float(f"{r.real_radius * w_max:.6g}")
        ctrl["omega_max"] = float(f"{2 * r.real_radius * w_max / r.real_track:.6g}")
        said += f", v_max {ctrl['v_max']:g} m/s, omega_max {ctrl['omega_max']:g} rad/s"
        out["description"] = f"{out.get('description', '')} On {robot}: {said}.".strip()
    out["plant"] = plant
    out["events"] = [_same_change(ev) for ev in raw]
    if not out["events"]:
        del out["events"]
    out["name"] = f"{out.get('name', 'scenario')}+{robot_name(robot)}"
    return out


def wheel_speed_limit(r) -> float | None:
    """The robot's wheel-speed limit (rad/s): its servos', else where its largest wheel torque meets
    its wheel joints' damping; None when the model sets neither."""
    if r.max_wheel_speed is not None:
        return float(r.max_wheel_speed)
    from mlpfac.plants.edits import torque_limit

    m = r.model
    damping = min(float(m.dof_damping[dof]) for dof in r.dofs)
    if r.mix is not None:
        from mlpfac.plants.drive import wheel_torque_limits

        torque = min(wheel_torque_limits(r.mix, r.umax)) / 2  # both wheels at once
    else:
        torque = min(torque_limit(m, a, c, True) for a, c in zip(r.acts, r.act_per_wheel, strict=True))
    return torque / damping if damping > 0 and math.isfinite(torque) else None


def _same_change(ev: dict) -> dict:
    """An event of the scenario as the same physical change on robot ``r``."""
    if not isinstance(ev, dict) or ev.get("kind") != "payload":
        return ev
    ev = dict(ev)
    ev.pop("body", None)  # a body of the other robot: the base of this one
    return ev
