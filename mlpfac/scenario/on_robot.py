"""Any scenario on any robot (``--robot NAME_OR_PATH``): a scenario's reference, events, noise and
controller put on another robot, by one rule (docs/robots.md):

- the robot is its model alone (``[plant] kind = "mujoco"``, ``model``), or a robot file's
  ``[plant]`` table: every other part is found or chosen in the model
  (:mod:`mlpfac.plants.mjcf.defaults`); the scenario's pose noise and pose source (its encoders,
  gyro and fixes: :mod:`mlpfac.plants.sensors.sensing`) are kept;
- the reference is slowed in time (the same path, v and omega x k, k <= 1) until its peak wheel
  speed (|v| + |omega| b / 2) / r at ``[reference] speed = 1`` is at most ``SHARE`` of the robot's
  wheel-speed limit (a ``speed`` the file or ``--vary`` sets then runs that path as many times as fast): the
  servos' control range, or, for a drive without one, the speed at which the wheels' largest torque
  meets their joints' damping;
- the controller's limits follow the robot's: ``v_max = r w_max``, ``omega_max = 2 r w_max / b``;
- a scenario file that names its MuJoCo robot gets the same reference rule (:func:`fitted`, one
  code) where it leaves the reference's speed unset, and a warning in numbers where it sets one
  the wheels cannot drive (:func:`on_its_robot`);
- events mean the same physical change: relative ones as they are (wheel radius x1.5 is x1.5 of
  this robot's wheel, mass x3 of its base, a force of a tenth of its weight, a push that changes
  its velocity by 1 m/s), absolute ones too (a 5 kg payload, a floor of friction 0.2, a 40 ms
  delay, a 5 N force); a payload on a body of the other robot goes on this one's base.
"""

from __future__ import annotations

import contextlib
import copy
import importlib.resources
from collections.abc import Iterator
from pathlib import Path

from mlpfac.exceptions import ConfigError
from mlpfac.scenario.limits import SHARE, fitted_path, law_limits

MENAGERIE_BASES = (
    "pal_tiago",
    "pal_tiago_dual",
    "hello_robot_stretch",
    "hello_robot_stretch_3",
    "rainbow_robotics_rby1",
)
AS_SHIPPED = {  # what a Menagerie base does from its name alone (tests/test_robots.py checks each)
    "pal_tiago_dual": "a skid-steer as modelled (four plain wheels, not the mecanum wheels of its omnidirectional "
    "base): given a rotor on each wheel, it turns as a track of 1.09 m, measured as it settles (docs/robots.md)",
    "rainbow_robotics_rby1": "refused as shipped: its wheel servos (kv 1) cannot turn the wheels against their "
    "damping; --robot rby1a drives it",
}
SHIPPED = {  # this package's robots (models/): the file, and what it is beside its model
    "diffdrive": ("scene.xml", ""),
    "diffdrive-torque": ("diffdrive-torque.toml", "diffdrive with torque motors under the wheel-speed PI loop"),
    "cart": ("cart-scene.xml", ""),
    "cart-torque": ("cart-torque.toml", "cart with torque motors under the wheel-speed PI loop"),
    "tug": ("tug.xml", "24 kg, its 8 kg load 0.2 m ahead of the axle, 4 N m torque motors"),
    "rby1a": ("rby1a.toml", "rainbow_robotics_rby1 with the keys that make it drive"),
    "tiago-torque": ("tiago-torque.toml", "pal_tiago with torque motors under the wheel-speed PI loop"),
}
SPEEDS = {"eight": ("wx", "wy"), "circle": ("rate",), "line": ("v",), "lemniscate": ("rate",)}
DEFAULT_SPEEDS = {"eight": (0.25, 0.5), "circle": (0.5,), "line": (0.5,), "lemniscate": (0.3,)}
PEAK_SAMPLES = 2001


ROBOT_HELP = (
    "run the scenario on this robot: diffdrive, cart, tug, rby1a, diffdrive-torque, cart-torque, tiago-torque, "
    "a MuJoCo Menagerie base (pal_tiago, hello_robot_stretch_3, "
    "menagerie:NAME/ENTRY, ...), an MJCF file, or a TOML file of one [plant] table; the reference is slowed to "
    "what it can drive (docs/robots.md)"
)
AT = "@"  # SCENARIO@ROBOT: a scenario of a sweep on a robot (--robot, --robots, a budget's robots)
ROBOT_FLAG = "--robot"  # what a message about a robot names first: renamed to what brought it (robots_named)


def robot_where(robot: str) -> str:
    """Where a message about ``robot`` points: ``--robot ROBOT``, which :func:`robots_named` renames
    to the flag or key that brought the robot (``--robots ROBOT``, ``budget.toml robots ROBOT``)."""
    return f"{ROBOT_FLAG} {robot}"


@contextlib.contextmanager
def robots_named(by: str) -> Iterator[None]:
    """A ConfigError about a robot raised inside (its ``where`` begins with ``--robot``) named by
    ``by``, the flag or key that brought the robots: one rule for ``--robot``, ``--robots``, a
    budget's ``robots`` and the Python API's ``robots`` (docs/errors.md)."""
    try:
        yield
    except ConfigError as err:
        head, sep, rest = err.where.partition(" ")
        if head != ROBOT_FLAG or by == ROBOT_FLAG:
            raise
        raise type(err)(f"{by}{sep}{rest}", err.what) from None


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
        raise ConfigError(ROBOT_FLAG, f"expected a robot's name or an MJCF file, got {robot!r}")
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
        raise ConfigError(robot_where(robot), f"neither a robot ({known}) nor an MJCF (.xml) or robot (.toml) file")
    if not path.is_file():
        raise ConfigError(robot_where(robot), "MJCF model file not found")
    return str(path.resolve())


def _shipped(robot: str) -> str:
    return str(importlib.resources.files("mlpfac.models") / SHIPPED[robot][0])


def robot_table(robot: str) -> dict:
    """The ``[plant]`` table of a robot: a TOML file's (a robot with the keys that make it drive,
    its model relative to the file), else ``model`` alone."""
    path = Path(_shipped(robot) if robot in SHIPPED else robot).expanduser()
    if path.suffix.lower() != ".toml":
        return {"kind": "mujoco", "model": model_of(robot)}
    from mlpfac.tables import read_toml

    try:
        table = read_toml(path, "robot file")
    except ConfigError as err:  # named by the flag: "--robot r.toml: robot file not found"
        raise ConfigError(robot_where(robot), err.what) from None
    plant = table.get("plant")
    if set(table) != {"plant"} or not isinstance(plant, dict) or not isinstance(plant.get("model"), str):
        raise ConfigError(robot_where(robot), "a robot file holds one [plant] table with its model")
    if plant.get("kind", "mujoco") != "mujoco":
        raise ConfigError(
            f"{robot_where(robot)} [plant] kind", f'must be "mujoco" (a robot file\'s model), got {plant["kind"]!r}'
        )
    plant = {"kind": "mujoco", **plant}
    if not plant["model"].startswith("menagerie:"):
        plant["model"] = str((path.parent / plant["model"]).resolve())
    return plant


def robots_here() -> list[tuple[str, str]]:
    """(name, where it is, or why it cannot run here) of each robot ``--robot`` knows by name."""
    out = [(name, f"shipped (models/{file}){': ' + note if note else ''}") for name, (file, note) in SHIPPED.items()]
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
    return on_robot_fit(table, robot)[0]


def on_robot_fit(table: dict, robot: str) -> tuple[dict, dict]:
    """:func:`on_robot`, and what it did to the reference in words (``[provenance] reference_fit``,
    said under the run's outcome): the speed factor and how long what the file drove now takes, or
    a path's new timing; ``reference_warning`` where a path's ``speed`` asks more than the wheels give."""
    from mlpfac.plants.config import MujocoConfig
    from mlpfac.plants.events import ControlPeriod, parse_event
    from mlpfac.plants.mujoco.plant import robot_of
    from mlpfac.scenario.reference import make_reference
    from mlpfac.tables import build

    out = copy.deepcopy(table)
    out.pop("provenance", None)  # what another robot's run simulated
    old = out.get("plant") if isinstance(out.get("plant"), dict) else {}
    plant = robot_table(robot)
    from mlpfac.plants.sensors.sensing import SENSOR_KEYS

    if "pose_source" not in plant:  # what the robot senses of its pose goes with the scenario, but where its file says
        for key in ("pose_noise_std", *SENSOR_KEYS):
            if key in old and key not in plant:
                plant[key] = old[key]
    T = float(out.get("T", 0.01))
    duration = float(out.get("duration", 25.0))
    raw = out.get("events", []) if isinstance(out.get("events"), list) else []
    events = [parse_event(ev, duration, f"[[events]] #{i + 1}") for i, ev in enumerate(raw)]
    periods = (T, *(ev.factor * T for ev in events if isinstance(ev, ControlPeriod)))
    where = robot_where(robot)
    config = build(MujocoConfig, {k: v for k, v in plant.items() if k != "kind"}, f"{where} [plant]")
    try:
        r = robot_of(config, periods)
    except ConfigError as err:
        raise type(err)(f"{where}: {err.where}".rstrip(": "), err.what) from None
    ref = dict(out.get("reference", {"kind": "eight"}))
    kind = ref.get("kind", "eight")
    curve = make_reference(kind, {k: v for k, v in ref.items() if k != "kind"}) if kind in SPEEDS else None
    warning = ""
    if kind == "path":
        *fit, warning = fitted_path(ref, r, out.get("controller"), True)
    else:
        fit = fitted(ref, curve, duration, r)
    said = ""
    if fit is not None:
        out["reference"], limits, said = fit
        if kind == "path":
            said += _path_durations(ref, out["reference"], out.get("controller"))
        out.setdefault("controller", {}).update(limits)
        said += _limits_said(limits) if limits else ""
        out["description"] = sentences(out.get("description", ""), f"On {robot}: {said}.")
    out["plant"] = plant
    out["events"] = [_same_change(ev) for ev in raw]
    if not out["events"]:
        del out["events"]
    out["name"] = f"{out.get('name', 'scenario')}+{robot_name(robot)}"
    return out, {k: v for k, v in (("reference_fit", said), ("reference_warning", warning)) if v}


def sentences(text: str, more: str) -> str:
    """``text`` and the sentence ``more`` after it, with the stop between them that ``text`` may lack."""
    text = text.strip()
    if text and text[-1] not in ".!?":
        text += "."
    return f"{text} {more}".strip()


def _path_durations(ref: dict, timed: dict, ctrl, other: bool = True) -> str:
    """A path's time once along it as timed for the robot, beside its time as the file times it
    (``other``: another robot's timing than the file's)."""
    from mlpfac.scenario.reference import make_reference

    def once(table: dict) -> float:
        law = law_limits(ctrl)
        return make_reference("path", {k: v for k, v in table.items() if k != "kind"}, limits=law).duration

    try:
        new, old = once(timed), once(ref) if other else None
    except ConfigError:  # said by the scenario's own checks, where it is read
        return ""
    return f": once along it takes {new:.4g} s" + (f" ({old:.4g} s as the file times it)" if other else "")


def peak_wheel_speed(curve, duration: float, r) -> float:
    """The fastest a wheel of robot ``r`` turns along the reference ``curve`` (rad/s): the peak of
    (|v_r| + |omega_r| b / 2) / r, sampled over 4 x ``duration``."""
    import numpy as np

    from mlpfac.scenario.reference import sample

    rows = sample(curve, np.linspace(0.0, 4 * duration, PEAK_SAMPLES))
    return float(np.max((np.abs(rows[:, 3]) + np.abs(rows[:, 4]) * r.real_track / 2) / r.real_radius))


def fitted(ref: dict, curve, duration: float, r) -> tuple[dict, dict, str] | None:
    """The module's rule on robot ``r``: the reference table ``ref`` (its curve ``curve``) slowed in
    time to a peak wheel speed of at most SHARE of the robot's limit at speed 1 (its ``speed`` kept,
    applied on top), the controller's limits from the
    robot, and what was done in words; None where the robot has no wheel-speed limit or the reference
    no speed (``--robot`` and a scenario file that leaves the reference's speed unset both come here)."""
    from mlpfac.plants.mjcf.wheels import wheel_speed_limit

    w_max = wheel_speed_limit(r)
    kind = ref.get("kind", "eight")
    if w_max is None or kind not in SPEEDS:
        return None
    import dataclasses

    speed = float(getattr(curve, "speed", 1.0))  # the path fitted at speed 1, then run as fast as the file asks
    peak = peak_wheel_speed(dataclasses.replace(curve, speed=1.0) if speed != 1.0 else curve, duration, r)
    k = min(1.0, SHARE * w_max / peak)
    said = f"reference x{k:.3g} in speed (peak wheel speed {k * peak:.3g} of {w_max:.3g} rad/s)"
    if speed != 1.0:
        said += f", then x{speed:g} as [reference] speed asks"
    if k < 1.0:
        said += f": what the file's {duration:g} s drive of it now takes {duration / k:.4g} s"
    ref = dict(ref)
    if k < 1.0:
        for key, default in zip(SPEEDS[kind], DEFAULT_SPEEDS[kind], strict=True):
            ref[key] = float(f"{k * float(ref.get(key, default)):.6g}")
    limits = {
        "v_max": float(f"{r.real_radius * w_max:.6g}"),
        "omega_max": float(f"{2 * r.real_radius * w_max / r.real_track:.6g}"),
    }
    return ref, limits, said


def _limits_said(ctrl: dict) -> str:
    return f"; the controller's v_max {ctrl['v_max']:g} m/s, omega_max {ctrl['omega_max']:g} rad/s"


def on_its_robot(table: dict, scn) -> tuple[dict, dict]:
    """A scenario file's reference on the MuJoCo robot it names (``scn``, the file parsed; ``table``,
    as read): where the reference's speed is left to the defaults, the table fitted by the module's
    rule (:func:`fitted`; the controller's limits only where the file leaves them unset); where the
    file sets it and asks more than the robot's wheels give, the table as it is, warned. Returns the
    table and ``[provenance]`` words for the run's first line (``reference_fit``, ``reference_warning``)."""
    import numpy as np

    from mlpfac.plants import make_plant
    from mlpfac.scenario.reference import sample

    ref = dict(table.get("reference", {"kind": "eight"}))
    kind = ref.get("kind", "eight")
    if kind not in SPEEDS and kind != "path":
        return table, {}
    r = make_plant(scn, sample(scn.reference, np.arange(2) * scn.T)).robot  # every check made; its read cached
    if kind == "path":
        ref, limits, said, warning = fitted_path(ref, r, table.get("controller"), False)
        ctrl = dict(table.get("controller", {}))
        ctrl |= {k: v for k, v in limits.items() if k not in ctrl}
        out = table | {"reference": ref, "controller": ctrl}
        said += _path_durations(ref, ref, ctrl, False)
        fit = {"reference_fit": said + (_limits_said(ctrl) if limits else "")}
        return out, fit | ({"reference_warning": warning} if warning else {})
    if not any(key in ref for key in (*SPEEDS[kind], "speed")):
        fit = fitted(ref, scn.reference, scn.duration, r)
        if fit is None:
            return table, {}
        ref, limits, said = fit
        ctrl = dict(table.get("controller", {}))
        ctrl |= {k: v for k, v in limits.items() if k not in ctrl}
        said += _limits_said(ctrl) + " (the rule of --robot)"
        out = table | {"reference": ref, "controller": ctrl}
        out["description"] = sentences(table.get("description", ""), f"Fitted to the robot: {said}.")
        return out, {"reference_fit": said}
    from mlpfac.plants.mjcf.wheels import wheel_speed_limit

    w_max = wheel_speed_limit(r)
    if w_max is None:
        return table, {}
    peak = peak_wheel_speed(scn.reference, scn.duration, r)
    if peak <= w_max:
        return table, {}
    speed = float(f"{SHARE * w_max / peak * scn.reference.speed:.3g}")
    return table, {
        "reference_warning": f"the reference asks a peak wheel speed of {peak:.3g} rad/s of wheels that give "
        f"{w_max:.3g} rad/s (x{peak / w_max:.3g}): beyond it the IK slows both wheels (the path's curvature kept) "
        f"and the robot falls behind; [reference] speed = {speed:g} drives it at {SHARE:g} of the limit"
    }


def torque_need(scn, plant) -> dict:
    """What the reference asks of a torque-driven robot's motors (``scn``, the scenario parsed;
    ``plant``, built from it by :func:`mlpfac.scenario.provenance.recorded`): the
    largest wheel torque the nominal dynamic model (:class:`mlpfac.dynamics.RobotModel`) needs to follow
    it without error, against the motors' limit, and the reference's ``speed`` at which the two meet:
    at speed k the torque of each sample is k^2 A + k C (inertia and the offset mass's coupling x k^2,
    the joints' damping x k), A and C from the model at speed 1 and -1. ``[provenance]`` words for
    the run's first line: ``reference_torque``, and ``torque_warning`` where the motors cannot give
    it. Empty for a robot on velocity servos."""
    import dataclasses

    import numpy as np

    from mlpfac.scenario.reference import FACTOR_MAX, sample

    if scn.plant_kind != "mujoco" or plant.config.actuator != "torque":  # the file's, or the model's answer
        return {}
    model = plant.dynamics()
    k0 = float(scn.reference.speed)
    n = max(int(round(scn.duration * k0 / scn.T)), 2)  # the path once traversed at speed k0, at speed 1
    rows = sample(dataclasses.replace(scn.reference, speed=1.0), np.arange(n + 1) * scn.T)
    twist = rows[:, 3:5]
    accel = np.gradient(twist, scn.T, axis=0)
    ahead, back = model.torques(twist, accel), model.torques(-twist, accel)  # speed 1 and -1
    A, C = 0.5 * (ahead + back), 0.5 * (ahead - back)

    def peak(k: float) -> float:
        return float(np.max(np.abs(k * k * A + k * C)))

    need, limit = peak(k0), model.torque_limit_Nm
    if not np.isfinite(limit):
        return {"reference_torque": f"the reference needs up to {need:.3g} N m a wheel (the motors have no limit)"}
    said = f"the reference needs up to {need:.3g} N m a wheel of the motors' {limit:.3g} N m ({need / limit:.0%}, the nominal model)"
    if peak(FACTOR_MAX) < limit:
        return {"reference_torque": f"{said}; they can drive it at every [reference] speed up to {FACTOR_MAX:g}"}
    lo, hi = 0.0, FACTOR_MAX
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if peak(mid) < limit else (lo, mid)
    said += f"; they can drive it up to [reference] speed = {lo:.3g}"
    out = {"reference_torque": said}
    if need > limit:
        out["torque_warning"] = f"{said}: beyond it no law follows the reference; the motors saturate"
    return out


def _same_change(ev: dict) -> dict:
    """An event of the scenario as the same physical change on robot ``r``."""
    if not isinstance(ev, dict) or ev.get("kind") != "payload":
        return ev
    ev = dict(ev)
    ev.pop("body", None)  # a body of the other robot: the base of this one
    return ev
