"""The drive forms beyond one actuator per wheel: four driven wheels, two a side, driven as a
skid-steer (``left_actuator_2``, ``right_actuator_2``: each side's second wheel commanded as its
first), and a drive given in (v, omega) space through two motors on fixed tendons over both wheels
(``tendon_actuators``, Hello Robot Stretch 2's ``forward`` and ``turn``).

For the tendon drive the plant's wheel-speed PI loop asks wheel torques (forward positive) and
:func:`mix` turns them into the two motors' controls: the inverse of the torque each motor's unit
control puts on each wheel, measured on the model (so any gear, gain and tendon coefficients).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plants.mjcf.detect import is_motor, names, tendon_joints, tendon_wheels

TENDON_KEY = "tendon_actuators"
UNIT = 1e-3  # the control a motor's torque on the wheels is measured with (within any force limit)


@dataclass(frozen=True)
class Drive:
    """The actuators a run commands and the two wheel joints it reads (ids of one model)."""

    acts: tuple[int, int]  # the left and right wheels' actuators, or the two tendon motors
    seconds: tuple[int, int]  # each side's second wheel's actuator (skid-steer); -1: none
    joints: tuple[int, int]  # the left and right (first) wheels' hinge joints
    tendon: bool  # acts are motors on tendons over both wheels


def resolve_ids(m: mujoco.MjModel, config, where: str) -> Drive:
    """The configuration's named drive as ids of ``m``; each name that is not there a ConfigError."""

    def act(key: str, name: str) -> int:
        a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        if a < 0:
            raise ConfigError(
                key, f"no actuator named {name!r} in {where} ({names(m, mujoco.mjtObj.mjOBJ_ACTUATOR, m.nu)})"
            )
        return a

    if config.tendon_actuators is not None:
        pair = tuple(act(TENDON_KEY, n) for n in config.tendon_actuators)
        coefs = [tendon_joints(m, a) for a in pair]
        if any(c is None or len(c) != 2 for c in coefs) or set(coefs[0]) != set(coefs[1]):
            raise ConfigError(TENDON_KEY, "expected two actuators on fixed tendons over the same two wheel joints")
        if not all(is_motor(m, a) for a in pair):
            raise ConfigError(TENDON_KEY, "the tendon actuators must be motors (<motor>: force = gain x control)")
        return Drive((pair[0], pair[1]), (-1, -1), tendon_wheels(m, (pair[0], pair[1])), True)
    seconds = tuple(
        -1 if getattr(config, k) is None else act(k, getattr(config, k))
        for k in ("left_actuator_2", "right_actuator_2")
    )
    return Drive((-1, -1), (seconds[0], seconds[1]), (-1, -1), False)


def mix(m: mujoco.MjModel, qpos: np.ndarray, acts: tuple[int, int], dofs, sign) -> tuple[np.ndarray, np.ndarray]:
    """The tendon motors' controls per forward wheel torque (2, 2) and their control limits (2,).
    Measured: each motor's unit control alone, its torque on each wheel (MuJoCo's transmission)."""
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    torque = np.empty((2, 2))  # [wheel, motor]
    for i, a in enumerate(acts):
        d.ctrl[:] = 0.0
        d.ctrl[a] = UNIT
        mujoco.mj_forward(m, d)
        torque[:, i] = [s * d.qfrc_actuator[dof] / UNIT for s, dof in zip(sign, dofs, strict=True)]
    umax = np.array([ctrl_limit(m, a) for a in acts])
    (a, b), (c, d_) = torque
    return np.array([[d_, -b], [-c, a]]) / (a * d_ - b * c), umax  # the inverse, written out (not LAPACK's)


def ctrl_limit(m: mujoco.MjModel, a: int) -> float:
    """A motor's largest control either way: its control range, and its force range over its gain."""
    out = math.inf
    if m.actuator_ctrllimited[a]:
        out = float(min(-m.actuator_ctrlrange[a, 0], m.actuator_ctrlrange[a, 1]))
    if m.actuator_forcelimited[a]:
        out = min(out, float(min(-m.actuator_forcerange[a, 0], m.actuator_forcerange[a, 1])) / m.actuator_gainprm[a, 0])
    return out


def wheel_torque_limits(inverse: np.ndarray, umax: np.ndarray) -> tuple[float, float]:
    """The largest forward torque on each wheel alone (the other's zero) within the motors' limits."""
    out = []
    for j in range(2):
        per = np.abs(inverse[:, j]) / umax  # the share of each limit a unit torque on wheel j takes
        out.append(float(1.0 / per.max()) if per.max() > 0 else math.inf)
    return out[0], out[1]
