"""A robot settled on its wheels at rest (the rest pose its runs start from), and MuJoCo's fatal
errors and warnings while it settles, each on one line naming the model."""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

from mlpfac.elementary import cos, sin
from mlpfac.exceptions import ConfigError
from mlpfac.plants.mjcf.wheels import wheel_speed_limit

SETTLE_S = 0.5  # seconds the robot settles on its wheels at least, at construction (the rest pose)
SETTLE_MAX_S = 10.0  # ... and at most: then it must be at rest
REST_SPEED = 1e-4  # at rest: the free body moves no faster than this (m/s, rad/s)


def settle(
    m: mujoco.MjModel, d: mujoco.MjData, dt: float, qpos: np.ndarray, ctrl: np.ndarray, droot: int, where: str
) -> None:
    """From the start pose and controls, let the robot settle on its wheels with zero wheel speed:
    SETTLE_S at least, then on until its free body moves no faster than REST_SPEED (checked; a
    caster wheel may spin on)."""
    mujoco.mj_resetData(m, d)
    d.qpos[:], d.ctrl[:] = qpos, ctrl
    mujoco.mj_forward(m, d)
    chunk = max(1, int(round(0.1 / dt)))
    left = int(round(SETTLE_S / dt))
    while left > 0:  # in pieces of 0.1 s of simulated time: a signal is seen between two
        mujoco.mj_step(m, d, nstep=min(chunk, left))
        left -= chunk
        no_warning(d, where)
    while np.max(np.abs(d.qvel[droot : droot + 6])) > REST_SPEED:
        if d.time > SETTLE_MAX_S:
            raise ConfigError(
                where,
                f"the robot does not come to rest on its wheels within {SETTLE_MAX_S:g} s (speeds up to "
                f'{np.max(np.abs(d.qvel[droot : droot + 6])):.2g}); lock what moves (other_actuators = "lock") or start from a keyframe',
            )
        mujoco.mj_step(m, d, nstep=chunk)
        no_warning(d, where)
    mujoco.mj_forward(m, d)


def cannot_simulate(where: str, err: Exception) -> ConfigError:
    """MuJoCo's fatal error (an arena too small for the model, ``<size memory>``), on one line."""
    return ConfigError(where, f"MuJoCo cannot simulate the model: {' '.join(str(err).split())}")


def no_warning(d: mujoco.MjData, where: str) -> None:
    """A ConfigError naming MuJoCo's warnings of ``d`` (an unstable model, an arena too small), if any."""
    warned = [mujoco.mjtWarning(i).name for i, w in enumerate(d.warning) if w.number]
    if warned:
        raise ConfigError(
            where, f"MuJoCo warned ({', '.join(warned)}) as the robot settled at rest: the model is not stable as it is"
        )


TURN_LEAD_S = 1.5  # seconds of the turning test before it is measured (from rest)
TURN_S = 1.0  # ... and measured
TURN_SHARE = 0.5  # the outer wheels at this share of the wheel-speed limit, the inner ones at a third of that
TURN_MIN = 0.1  # a robot that turns at less than this share of the rate asked is not measured


def turning(plant, events: Sequence = ()) -> tuple[float, float, str]:
    """A skid-steer's turning, measured once it has settled: from rest at the origin, its outer
    wheels asked w = TURN_SHARE of their speed limit and its inner ones w / 3 (through its own drive and IK, on its own
    wheels and floor) for TURN_LEAD_S, then its yaw rate omega and the mean sideways speed v_y of its
    pose frame over TURN_S. Returns the track a differential drive turning as it does has,
    r (w_r - w_l) / omega, and the kinematic centre's distance ahead of the pose frame, -v_y / omega
    (the point of the base that moves along its heading: where the instantaneous centre of rotation
    projects onto its axis; Kozlowski & Pazderski 2004, Martinez et al. 2005), and what it did in
    words; (nan, nan, why) where it does not turn. ``plant`` is a :class:`~mlpfac.plants.mujoco.plant.MujocoPlant`;
    ``events``: plant events applied in turn at the start (a payload, a floor: what they do to the
    turning; the next reset undoes them)."""
    w = TURN_SHARE * (wheel_speed_limit(plant.robot) or 1.0)
    r, track = float(plant.ik_radius), float(plant.ik_track)
    w_l, w_r = w / 3, w
    v, omega = r * (w_l + w_r) / 2, r * (w_r - w_l) / track  # what its IK turns into (w_l, w_r)
    plant.reset(np.zeros(3), np.random.default_rng(0))
    for event in events:
        plant.apply(event)
    r = float(plant.real_radius)  # the wheels' own: their rims' speeds
    dt = plant.T
    lead, n = int(round(TURN_LEAD_S / dt)), int(round(TURN_S / dt))
    for _ in range(lead):
        plant.step(np.array([v, omega]))
    start = plant.true_pose()
    sideways, last = 0.0, start
    for _ in range(n):
        plant.step(np.array([v, omega]))
        pose = plant.true_pose()
        dx, dy = float(pose[0] - last[0]), float(pose[1] - last[1])
        sideways += -sin(float(last[2])) * dx + cos(float(last[2])) * dy
        last = pose
    turned = float(last[2] - start[2]) / TURN_S
    asked = f"wheels at {w_l:.3g} and {w_r:.3g} rad/s"
    if not turned > TURN_MIN * omega:
        return math.nan, math.nan, f"{asked}: it turned at {turned:.3g} of {r * (w_r - w_l) / track:.3g} rad/s"
    return r * (w_r - w_l) / turned, -(sideways / TURN_S) / turned, asked


def wheels_answer(plant, peak: float, events: Sequence = ()) -> tuple[float, float]:
    """How the wheels answer a command, measured once the robot has settled: from rest at the origin,
    driving straight through its own drive and IK, both wheels asked w1 = ``peak`` / 2 (``peak``: the
    fastest a wheel turns along the run's reference) for TURN_LEAD_S, then w2 = ``peak`` as long;
    over the last TURN_S of each, the mean speed its wheels reached, as the plant measures them
    (``wheel_meas``), over the speed asked: two ratios rho1, rho2, to 3 digits. Returns the line
    through the two, w = gain w_asked - offset, each to 3 digits: gain = 2 rho2 - rho1, offset =
    peak (rho2 - rho1) [rad/s]; an offset > 0 where the wheels turn that much slower than asked at
    every speed (a joint's friction against a weak servo's kv: its steady error, friction / kv);
    (1, 0) where they answer as asked. ``plant`` is a :class:`~mlpfac.plants.mujoco.plant.MujocoPlant`;
    ``events``: plant events applied in turn at the start (the next reset undoes them)."""
    plant.reset(np.zeros(3), np.random.default_rng(0))
    for event in events:
        plant.apply(event)
    lead, n = int(round(TURN_LEAD_S / plant.T)), int(round(TURN_S / plant.T))
    rho = []
    for w in (0.5 * peak, peak):
        reached = 0.0
        for k in range(lead + n):
            plant.step(np.array([float(plant.ik_radius) * w, 0.0]))
            if k >= lead:
                wheels = plant.telemetry()["wheel_meas"]
                reached += 0.5 * (float(wheels[0]) + float(wheels[1]))
        rho.append(float(f"{reached / n / w:.3g}"))
    return float(f"{2.0 * rho[1] - rho[0]:.3g}"), float(f"{peak * (rho[1] - rho[0]):.3g}")
