"""What a robot's ``[plant]`` table leaves unset, chosen as a researcher expects of a real robot
(docs/robots.md): each rule below fills one key, and what it chose is written into config.toml.

- ``keyframe``: the model's keyframe named ``home``, where it has one (else its default pose);
- ``other_actuators``: ``"lock"`` when anything but the drive is actuated (an arm, a torso, a
  head): every such joint fixed where the robot starts, so it stands still and only the base steps;
- ``tyre``: ``"sphere"`` when a wheel collides through a mesh, or its contact's friction is not
  its own (its priority not above the floor's), so that it rolls: else the model's own geoms;
- ``casters``: ``"frictionless"`` when parts of the robot that are neither wheels nor jointed
  (a skid standing in for casters) touch the floor with friction at rest: they slide (condim 1);
- ``timestep``: the model's when it divides the control period (and every period an event asks),
  else the largest one below it that does; where the wheel servos chatter at it as MuJoCo clamps
  their force (:func:`chatters`), the largest that divides them and integrates the servos
  (:func:`servo_step`), down to 1/16 of the model's;
- ``armature``: on a skid-steer whose wheels have no rotor inertia in the model, M r^2 / n on
  each of its n wheels (M the robot's mass, r the wheel radius): a wheel that moves only its own
  kilogram grips the floor along its rim with a far softer MuJoCo contact than the robot's mass
  holds it across, and a skid-steer that must scrub sideways to turn then turns at a few per cent
  of its command; a geared motor's rotor, reflected through its gear, is what a real wheel has;
- ``pi_kp``, ``pi_ki``: for the torque drive, the wheel-speed PI loop's gains scaled to the inertia a
  wheel drives, J = m r^2 / 2 + I_w (half the robot's mass at the rim and the wheel's own, its
  rotor's armature included): 0.5 N m s/rad and 10 N m/rad per J of our 5.5 kg robot (the gains
  tuned on it, which this rule gives it back), 3 digits, so that the loop closes as fast on any robot;
- ``servo_limit``: ``"control"`` where the servos chatter and no such timestep is left: the plant
  keeps their force within its limit through their control, every physics step, and MuJoCo
  integrates them implicitly (it does not a clamped servo).

:func:`check_drive` refuses, in one line with the numbers, a robot whose wheels cannot move it as
shipped, naming the keys that make it drive.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plants.mjcf.detect import ROUND

HOME = "home"
CHATTER_S = 0.3  # seconds of a steady wheel command the servos are tried with
SMALLEST_STEP = 1 / 16  # a timestep is lowered (for servos that chatter) down to this share of the model's
MAX_SUBSTEPS = 1000  # a timestep is looked for down to the period / this
SERVO_SHARE = 0.5  # a wheel servo must reach this share of its top speed against its joint's damping
FIX = 'set actuator = "torque" (the wheel-speed PI loop, pi_kp and pi_ki)'


def keyframe(config, m: mujoco.MjModel) -> dict:
    """``{"keyframe": "home"}`` when it is unset and the model has a keyframe of that name."""
    if config.keyframe is None and mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, HOME) >= 0:
        return {"keyframe": HOME}
    return {}


def others(config, m: mujoco.MjModel, keep: set[int]) -> dict:
    """``{"other_actuators": "lock"}`` when it is unset and an actuator that is not the drive moves a joint."""
    if config.other_actuators is not None:
        return {}
    if any(a not in keep and int(m.actuator_trntype[a]) in (0, 3) for a in range(m.nu)):  # joint, tendon
        return {"other_actuators": "lock"}
    return {}


def tyre(config, m: mujoco.MjModel, geoms: list[int], floor: int) -> dict:
    """``{"tyre": "sphere"}`` when it is unset and a wheel geom is a mesh or below the floor's priority."""
    if config.tyre is not None:
        return {}
    if any(int(m.geom_type[g]) not in ROUND or int(m.geom_priority[g]) <= floor for g in geoms):
        return {"tyre": "sphere"}
    return {}


def armature(config, m: mujoco.MjModel, dofs: list[int], mass: float, radius: float) -> dict:
    """``{"armature": M r^2 / n}`` (3 digits) when it is unset, the drive has more than two wheels
    (a skid-steer) and none of their hinges has rotor inertia in the model."""
    if config.armature is not None or len(dofs) <= 2 or any(float(m.dof_armature[d]) > 0 for d in dofs):
        return {}
    return {"armature": float(f"{mass * radius * radius / len(dofs):.3g}")}


def timestep(config, dt: float, periods: tuple[float, ...]) -> dict:
    """``{"timestep": s}`` when it is unset and the model's ``dt`` does not divide every period: the
    largest timestep below ``dt`` that does (nothing when none does: the plant says so)."""
    if config.timestep is not None or not periods or all(_whole(p, dt) for p in periods):
        return {}
    for n in range(1, MAX_SUBSTEPS + 1):
        step = periods[0] / n
        if step <= dt * (1 + 1e-9) and all(_whole(p, step) for p in periods):
            return {"timestep": float(f"{step:.12g}")}
    return {}


def chatters(robot) -> bool:
    """Whether the wheel servos, asked a steady speed (half their limit, else 1 rad/s) from rest,
    chatter (their force flips sign at most steps of the last half of CHATTER_S) or blow up: a
    stiff servo whose force limit clamps it overshoots within one timestep."""
    m = robot.model
    d = mujoco.MjData(m)
    d.qpos[:], d.ctrl[:] = robot.qpos_rest, robot.ctrl_rest
    mujoco.mj_forward(m, d)
    w = 0.5 * robot.max_wheel_speed if robot.max_wheel_speed is not None else 1.0
    for a, c in zip((*robot.acts, *robot.seconds), (*robot.act_per_wheel, *robot.second_per_wheel), strict=True):
        if a >= 0:
            d.ctrl[a] = c * w
    n = int(round(CHATTER_S / float(m.opt.timestep)))
    flips, last = 0, 0.0
    for k in range(n):
        mujoco.mj_step(m, d)
        f = float(np.sign(d.actuator_force[robot.acts[0]]))
        flips += k >= n // 2 and f != last
        last = f
        if not np.all(np.isfinite(d.qvel)) or np.max(np.abs(d.qvel)) > 1e3:
            return True
    return flips > n // 8


def servo_step(robot) -> float:
    """The largest timestep at which a clamped wheel servo cannot overshoot: 2 M / (kv gear^2), M
    the wheel's inertia about its hinge (the explicit bound; a servo whose force is clamped is
    integrated explicitly), the smallest over the drive's servos."""
    m = robot.model
    pairs = [(a, int(m.jnt_dofadr[m.actuator_trnid[a, 0]])) for a in (*robot.acts, *robot.seconds) if a >= 0]
    return min(2 * float(m.dof_M0[dof]) / (float(m.actuator_gainprm[a, 0]) * float(m.actuator_gear[a, 0]) * float(m.actuator_gear[a, 0]))
               for a, dof in pairs)  # fmt: skip


def smaller_timestep(dt: float, periods: tuple[float, ...], floor: float) -> float | None:
    """The largest timestep at most ``dt`` that divides every period, None below ``floor``."""
    chosen = timestep(_Unset(), dt, periods).get("timestep", dt)
    return chosen if chosen >= floor * (1 - 1e-9) else None


class _Unset:
    timestep = None


def _whole(period: float, dt: float) -> bool:
    n = period / dt
    return round(n) >= 1 and abs(n - round(n)) <= 1e-6 * n


PI_KP, PI_KI = 0.5, 10.0  # the wheel-speed PI loop's gains tuned on our robot (models/diffdrive.xml) ...
PI_INERTIA = 5.5 * 0.05 * 0.05 / 2 + 0.0003125 + 0.001  # ... whose wheel drives J = m r^2 / 2 + I_w (kg m^2)


def pi_gains(config, mass: float, radius: float, wheel_inertia: float) -> dict:
    """``{"pi_kp": .., "pi_ki": ..}`` for the unset gains of a torque drive: our robot's, scaled by the
    inertia J = m r^2 / 2 + I_w a wheel drives against ours (3 digits)."""
    if config.actuator != "torque":
        return {}
    scale = (mass * radius * radius / 2 + wheel_inertia) / PI_INERTIA
    out = {"pi_kp": float(f"{PI_KP * scale:.3g}")} if config.pi_kp is None else {}
    return out | ({"pi_ki": float(f"{PI_KI * scale:.3g}")} if config.pi_ki is None else {})


def said(chosen: dict, config) -> str:
    """What the rules chose, for the run's first line ("" when nothing)."""
    parts = []
    if "keyframe" in chosen:
        parts.append(f"keyframe {config.keyframe}")
    if "other_actuators" in chosen:
        parts.append("the other actuated joints locked where it starts")
    if "tyre" in chosen:
        parts.append("sphere tyres")
    if "casters" in chosen:
        parts.append("frictionless skids")
    if "armature" in chosen:
        parts.append(f"rotor inertia {config.armature:g} kg m^2 on each wheel")
    if "timestep" in chosen:
        parts.append(f"timestep {config.timestep:g} s")
    if "pi_kp" in chosen or "pi_ki" in chosen:
        parts.append(
            f"wheel-speed PI gains kp {config.pi_kp:g} N m s/rad, ki {config.pi_ki:g} N m/rad (for its inertia)"
        )
    return f"; chosen: {', '.join(parts)}" if parts else ""


def with_chosen(config, chosen: dict):
    return dataclasses.replace(config, **chosen) if chosen else config


def skids(m: mujoco.MjModel, qpos: np.ndarray, ctrl: np.ndarray, seconds: float, root: int, wheels) -> list[int]:
    """The robot's geoms on bodies that do not turn on a joint of their own, not its wheels, that touch another
    body (the floor) with friction once it has stood ``seconds`` from ``qpos``: skids where the
    real robot has casters."""
    d = mujoco.MjData(m)
    d.qpos[:], d.ctrl[:] = qpos, ctrl
    mujoco.mj_step(m, d, nstep=int(round(seconds / float(m.opt.timestep))))
    return [g for g in drag_geoms(m, d, root, wheels) if not _turns(m, int(m.geom_bodyid[g]))]


def _turns(m: mujoco.MjModel, body: int) -> bool:
    """Whether a body has a joint of its own other than a free joint (a caster wheel's, say)."""
    adr, n = int(m.body_jntadr[body]), int(m.body_jntnum[body])
    return any(int(m.jnt_type[j]) != mujoco.mjtJoint.mjJNT_FREE for j in range(adr, adr + n))


def frictionless(spec: mujoco.MjSpec, geoms: list[int], floor: int) -> None:
    """The geoms slide without friction on the floor (condim 1, above the floor's priority)."""
    for g in geoms:
        spec.geoms[g].condim, spec.geoms[g].priority = 1, floor + 1


def drag_geoms(m: mujoco.MjModel, d: mujoco.MjData, root: int, wheels) -> list[int]:
    """The robot's geoms other than its wheels' touching another body (the floor), with friction."""
    out = set()
    for c in d.contact[: d.ncon]:
        for g, other in (c.geom, c.geom[::-1]):
            mine, theirs = m.body_rootid[m.geom_bodyid[g]] == root, m.body_rootid[m.geom_bodyid[other]] != root
            if mine and theirs and int(m.geom_bodyid[g]) not in wheels and c.dim > 1:
                out.add(int(g))
    return sorted(out)


def check_drive(m: mujoco.MjModel, d: mujoco.MjData, robot, config, where: str) -> None:
    """Refuse a robot whose wheel servos cannot move it as shipped: a servo that at full command
    reaches less than SERVO_SHARE of its speed against its joint's damping, or floor contacts other
    than the wheels dragging harder (friction x load) than the wheels can push."""
    if config.actuator == "torque":
        return
    said = []
    push = 0.0
    for a, dof in zip(robot.acts, robot.dofs, strict=True):
        kv, gear = float(m.actuator_gainprm[a, 0]), abs(float(m.actuator_gear[a, 0]))
        top = (
            float(min(-m.actuator_ctrlrange[a, 0], m.actuator_ctrlrange[a, 1]))
            if m.actuator_ctrllimited[a]
            else math.inf
        )
        force = kv * top * gear
        if m.actuator_forcelimited[a]:
            force = min(force, float(min(-m.actuator_forcerange[a, 0], m.actuator_forcerange[a, 1])) * gear)
        push += force / robot.real_radius
        b = float(m.dof_damping[dof])
        if math.isfinite(top) and b > 0:
            speed = gear * kv * top / (b + gear * gear * kv)  # the wheel speed where the servo meets the damping
            if speed < SERVO_SHARE * top / gear:
                text = (
                    f"wheel servo kv {kv:g} gives at most {force:.3g} N m against joint damping {b:g} N m s/rad "
                    f"({speed:.2g} of {top / gear:.3g} rad/s at full command)"
                )
                said += [text] if text not in said else []
    drag = []
    geoms = drag_geoms(m, d, robot.root, set(robot.wheel_bodies))
    for g in geoms:
        f = np.zeros(6)
        load = sum(
            (mujoco.mj_contactForce(m, d, i, f), abs(f[0]))[1] for i, c in enumerate(d.contact[: d.ncon]) if g in c.geom
        )
        drag.append(float(m.geom_friction[g, 0]) * load)
    if drag and sum(drag) >= push:
        said.append(
            f"{', '.join(sorted({m.body(int(m.geom_bodyid[g])).name for g in geoms}))} drag {sum(drag):.3g} N on the "
            f"floor (friction x load) against the wheels' {push:.3g} N"
        )
    if said:
        fix = FIX + (' and casters = "frictionless"' if drag and sum(drag) >= push else "")
        raise ConfigError(where, f"cannot drive as shipped: {'; '.join(said)}: {fix} in [plant]")
