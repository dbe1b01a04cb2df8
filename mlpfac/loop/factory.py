"""The blocks of a run built from a scenario's data: the plant and the controller.

The control period T is the scenario's; both blocks get it here, when they are built, and nowhere else.

A :class:`~mlpfac.scenario.parse.Scenario` is plain, validated data; the runner asks this module for the
blocks it steps. The plant is built by :func:`mlpfac.plants.make_plant` (re-exported here), which
:func:`mlpfac.scenario.parse.load` also calls once, to check before any run that the robot can be built
and can apply every event.
"""

from __future__ import annotations

import dataclasses
import math
import threading

import numpy as np

from mlpfac.control.adaptive.controller import VARIANTS, Adaptive
from mlpfac.control.adaptive.dynamic_level import AdaptiveDynamic
from mlpfac.control.baselines import Corradini, Kanayama, PluginController, Stepped
from mlpfac.control.dynamic import OUTER_GAINS, FierroLewis, OracleDynamic, Told
from mlpfac.control.oracle import TOLD, TURNING, Oracle, told
from mlpfac.control.policy import Policy
from mlpfac.control.torque import TorquePluginController
from mlpfac.control.variants import MPC_NAMES
from mlpfac.plants import make_plant  # noqa: F401 (the plant half of the factory, as mlpfac.loop.factory.make_plant)
from mlpfac.plants.events import Force, Slope
from mlpfac.scenario.on_robot import peak_wheel_speed
from mlpfac.scenario.parse import Scenario
from mlpfac.scenario.reference import sample


def make_controller(scn: Scenario, instance: object | None = None, plant=None) -> Stepped:
    """The scenario's controller: a named variant of the adaptive scheme, Corradini's or Kanayama's law,
    the oracle (the law told the scenario's events, :mod:`mlpfac.control.oracle`), a controller of the
    wheels' torques (:mod:`mlpfac.control.dynamic`, given the nominal model of ``plant``, the run's
    MuJoCo robot, built from the scenario when not given), or a user's own (:mod:`mlpfac.control.plugins`;
    ``instance``: an object of it, made by the caller, runs one seed)."""
    if scn.controller in MPC_NAMES and scn.plugin is None:
        return _mpc(scn, plant)
    if scn.level == "torque":
        return _torque_level(scn, instance, plant)
    if scn.plugin is not None:
        return PluginController(scn.plugin, scn.T, instance)
    if scn.policy is not None:  # a trained policy's weights (mlpfac.control.policy)
        return Policy(scn.policy, scn.controller, scn.T, scn.law)
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
        if scn.plant_kind != "mujoco" or not scn.events:
            return Oracle(scn.law, scn.T, [told(ev) for ev in scn.events], scn.plant_kind == "kinematic", gains)
        probe = make_plant(scn, sample(scn.reference, np.arange(2) * scn.T))  # a robot of the scenario's to measure
        changes = [told(ev) for ev in scn.events] + _measured(scn, probe)
        return Oracle(scn.law, scn.T, changes, False, gains, (probe.ik_radius, probe.ik_track))
    return Kanayama(scn.law, scn.kanayama, scn.T)


MEASURED: dict[tuple, list] = {}  # what the oracles are told that is measured (_measured), newest last
MEASURED_MAX = 64  # scenarios kept (a sweep's seeds of a grid point run one after the other)
_LOCK = threading.Lock()


def _measured(scn: Scenario, probe) -> list[tuple[float, str, float]]:
    """What the oracle is told that is measured on ``probe`` (a robot of the scenario's, not the run's
    own): each payload's turning of a skid-steer, then how the wheels answer a command after each
    change it is told. Measured once a process for a scenario as resolved (its table but its seed;
    with its seed where it has a world, whose rough ground is drawn for each), its robot's compiled
    model (sha256) and the fastest a wheel turns along its reference (the speeds it is measured at):
    the seeds of a sweep's grid point are told the same numbers, which cost 500 control steps of
    the probe a change (:func:`~mlpfac.plants.mjcf.settle.wheels_answer`), a third of a 15-s run's."""
    table = {k: v for k, v in scn.table.items() if k != "seed" or scn.terrain is not None}
    peak = peak_wheel_speed(scn.reference, scn.duration, probe.robot)
    key = (repr(table), probe.robot.sha256, peak)
    with _LOCK:  # a Dask worker may run several tasks in threads
        out = MEASURED.pop(key, None)
    if out is None:
        out = _turning_told(scn, probe)
        times = {float(ev.time) for ev in scn.events if ev.kind in TOLD} | {t for t, *_ in out}
        out += _answer_told(scn, probe, times, peak)
    with _LOCK:
        MEASURED[key] = out
        while len(MEASURED) > MEASURED_MAX:
            del MEASURED[next(iter(MEASURED))]
    return list(out)


def _turning_told(scn: Scenario, probe) -> list[tuple[float, str, float]]:
    """What each payload does to a skid-steer's turning (:mod:`mlpfac.control.oracle`), measured on
    ``probe``, a robot of the scenario's (not the run's own); none on another robot."""
    if probe.robot.seconds == (-1, -1):  # not a skid-steer: nothing to measure
        return []
    out = []
    for i, ev in enumerate(scn.events):
        if ev.kind in TURNING and (change := probe.turning_change(scn.events[: i + 1])) is not None:
            out += [(float(ev.time), "turning_track", change[0]), (float(ev.time), "kinematic_centre", change[1])]
    return out


def _answer_told(scn: Scenario, probe, times: set[float], peak: float) -> list[tuple[float, str, float]]:
    """How the wheels answer a command (:func:`mlpfac.plants.mjcf.settle.wheels_answer`, at the speeds
    the reference asks: ``peak`` the fastest), measured on ``probe`` with the events applied in turn up
    to each one at ``times`` (those whose change the oracle is told), where it differs from what it
    was told last."""
    from mlpfac.plants.mjcf.settle import wheels_answer  # here: importing the factory imports no MuJoCo

    out, last = [], (1.0, 0.0)
    for i, ev in enumerate(scn.events):
        if float(ev.time) in times and (answer := wheels_answer(probe, peak, scn.events[: i + 1])) != last:
            out += [(float(ev.time), "wheel_gain", answer[0]), (float(ev.time), "wheel_offset", answer[1])]
            last = answer
    return out


def _torque_level(scn: Scenario, instance: object | None, plant) -> Stepped:
    """A controller of the wheels' torques, given the robot's nominal model (``oracle-dynamic``: and
    the true one after each event, read from a robot the scenario's events are applied to in turn)."""
    ref = sample(scn.reference, np.arange(2) * scn.T)
    plant = plant if plant is not None else make_plant(scn, ref)
    robot = plant.dynamics()
    if scn.plugin is not None:
        return TorquePluginController(scn.plugin, scn.T, robot, instance)
    g, law = scn.kanayama, scn.law
    own = isinstance(scn.table.get("controller"), dict) and "kanayama" in scn.table["controller"]
    gains = (g.Kx, g.Ky, g.Ktheta) if own else OUTER_GAINS  # the file's [controller.kanayama], else its own
    limits = (math.inf if law.v_max is None else law.v_max, math.inf if law.omega_max is None else law.omega_max)
    if scn.controller == "fierro-lewis":
        return FierroLewis(robot, scn.T, gains, limits)
    if scn.controller == "adaptive-dynamic":
        return AdaptiveDynamic(robot, scn.T, gains, limits)
    changes = []
    if scn.events:
        changed = make_plant(scn, ref)
        changed.reset(np.zeros(3), np.random.default_rng(0))
        for ev in scn.events:
            changed.apply(ev)
            dynamic = ev.kind in ("payload", "actuator", "wheel_radius")
            changes.append((*told(ev), changed.true_dynamics() if dynamic else None))
    cfg = scn.plant_config
    sensed = cfg.pose_source != "truth"  # its twist from the encoders through the nominal radius (omega: or a gyro)
    encoders = (sensed, sensed and not cfg.gyro)
    return OracleDynamic(robot, scn.T, gains, limits, changes, _world_told(scn, plant), encoders)


def _world_told(scn: Scenario, plant) -> Told | None:
    """The slopes and forces ``oracle-dynamic`` is told (None: none): gravity along the floor after
    each slope, of the robot's own magnitude, and the force events whose schedule it meets, in the
    newtons the plant applies (a force given relative to the robot: the plant's own)."""
    g0 = plant.robot.model.opt.gravity
    g = float(np.sqrt(np.sum(g0 * g0)))
    slopes = [(ev.time, *ev.gravity(g)[:2]) for ev in scn.events if isinstance(ev, Slope)]
    if not slopes and not any(isinstance(ev, Force) for ev in scn.events):
        return None
    return Told(slopes, plant.forces, scn.steps)


def _mpc(scn: Scenario, plant=None) -> Stepped:
    """``mpc`` or ``limit`` (:mod:`mlpfac.control.mpc`): its model of each seed's run a robot built
    from the scenario for that seed (its terrain and forces' noise are the seed's), with the true
    pose and no noise, reset where the run starts; the reference sampled over the run and a
    horizon beyond; the drive's limits (the controller's (v, omega) limits, or the motors'
    torques); the pose noise the estimator is told (the scenario's, at least 1 mm on a pose a
    source estimates)."""
    from mlpfac.control.mpc.controller import MPC
    from mlpfac.plants.mujoco.predict import Predictor

    T, cfg = scn.T, scn.mpc
    H = max(1, int(round(cfg.horizon_s / T)))
    preview = sample(scn.reference, np.arange(scn.steps + H + 1) * T)
    ref = preview[: scn.steps + 1]
    model_scn = _model_scenario(scn)
    probe = plant if plant is not None else make_plant(model_scn, ref[:2])

    def build_model(seed) -> Predictor:
        s = model_scn
        if isinstance(seed, int) and seed != scn.seed:  # a seed of a batch: its own world
            s = _model_scenario(scn.with_overrides(seed=seed))
        p = make_plant(s, ref[:2])
        q0, u0 = s.initial_state(ref)
        p.reset(q0, np.random.default_rng(np.random.SeedSequence(seed)), u0)  # the seed's forces' schedule
        return Predictor(p)

    if scn.level == "torque":
        limits = np.array(probe._torque_max)
        scale = limits.copy()
    else:
        v_r, w_r = np.abs(preview[:, 3]).max(), np.abs(preview[:, 4]).max()
        scale = np.array([max(float(v_r), 0.1), max(float(w_r), 0.5)])
        law = scn.law
        limits = np.array(
            [
                10.0 * scale[0] if law.v_max is None else float(law.v_max),
                10.0 * scale[1] if law.omega_max is None else float(law.omega_max),
            ]
        )
    pc = scn.plant_config
    noise = pc.noise_std()
    noise = np.zeros(3) if noise is None else np.asarray(noise, dtype=float)
    if getattr(pc, "pose_source", "truth") != "truth":
        noise = np.maximum(noise, 1.0e-3)
    wheel_noise = float(getattr(pc, "wheel_speed_noise_std", 0.0))
    return MPC(scn.controller, scn.level, T, cfg, build_model, preview, scn.events, limits, scale, noise,
               scn.controller == "limit", wheel_noise)  # fmt: skip


def _model_scenario(scn: Scenario) -> Scenario:
    """The scenario a model of its robot is built from: the same robot, world and events, its pose
    the true one without noise (the estimator is told the noise, the model does not make it)."""
    from mlpfac.plants.sensors.sensing import SENSOR_KEYS, TRUTH_ONLY

    pc = scn.plant_config
    unsensed = {f.name: f.default for f in dataclasses.fields(pc) if f.name in SENSOR_KEYS}  # no sensor: the truth
    unsensed |= {k: 0.0 for k in TRUTH_ONLY if hasattr(pc, k)}
    return dataclasses.replace(scn, plant_config=dataclasses.replace(pc, **unsensed))
