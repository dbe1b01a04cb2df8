"""A robot settled on its wheels at rest (the rest pose its runs start from), and MuJoCo's fatal
errors and warnings while it settles, each on one line naming the model."""

from __future__ import annotations

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError

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
