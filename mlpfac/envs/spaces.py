"""What the environments show and take: the observation's layout and bounds, the action's, and the
default reward. Batch-first: every function fills rows (B, ...) of the environments it is given.

The observation (a float64 :class:`gymnasium.spaces.Box`, named component by component in
:data:`VELOCITY` and :data:`TORQUE`) is what a controller of the scenario's level sees, from the
scenario's pose source (the truth, odometry or the fused estimate): the tracking error (2) of the
measured pose, the reference sample, and the last command; at the torque level also the reference's
rates, the measured pose, twist and wheel speeds. Headings are wrapped to [-pi, pi]; every value is
clipped to the Box (a measured error beyond the scenario's ``divergence_m``, a reference of a
randomized episode outside the first episode's extent), while ``info`` holds them unclipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mlpfac.exceptions import ConfigError

VELOCITY = ("e1", "e2", "e3", "x_r", "y_r", "theta_r", "v_r", "omega_r", "v_prev", "omega_prev")
TORQUE = (*VELOCITY[:8], "dv_r", "domega_r", "x", "y", "theta", "v", "omega", "wheel_l", "wheel_r",
          "tau_l_prev", "tau_r_prev")  # fmt: skip
HEADINGS = ("e3", "theta_r", "theta")  # wrapped to [-pi, pi]
G = 9.81  # m/s^2: a torque motor without a limit is bounded by what lifts the robot at 2 g


def wrap(x: np.ndarray) -> np.ndarray:
    """Angles to [-pi, pi], in plain arithmetic (no library call)."""
    return x - 2.0 * math.pi * np.round(x / (2.0 * math.pi))


@dataclass(frozen=True)
class Layout:
    """The observation's names and bounds, and the action's bounds (in the robot's units)."""

    names: tuple[str, ...]
    low: np.ndarray
    high: np.ndarray
    act_high: np.ndarray  # (2,): v_max, omega_max; or each wheel's torque limit

    def index(self, name: str) -> int:
        return self.names.index(name)


def layout(level: str, ref: np.ndarray, rates: np.ndarray, divergence_m: float, act_high, robot=None) -> Layout:
    """The bounds of a scenario's observation: the reference's extent over the run (its samples
    ``ref`` (N + 1, 5), its rates (N + 1, 2)), the pose within ``divergence_m`` of it, the twist and
    wheel speeds within twice what the command's bounds ``act_high`` ask (torque level: of the
    robot's nominal model ``robot``, :class:`mlpfac.dynamics.RobotModel`)."""
    D = float(divergence_m)
    finite = ref[np.isfinite(ref).all(axis=1)]
    big = np.max(np.abs(finite[:, 3:5]), axis=0)
    b = {"e1": D, "e2": D, "e3": math.pi, "theta_r": math.pi, "theta": math.pi}
    lo = {k: -v for k, v in b.items()}
    hi = dict(b)
    for i, key in enumerate(("x_r", "y_r")):
        lo[key], hi[key] = float(finite[:, i].min()), float(finite[:, i].max())
        lo[key[0]], hi[key[0]] = lo[key] - D, hi[key] + D
    for key, (m, a) in zip(("v_r", "omega_r"), zip(big, (act_high[0], act_high[1]), strict=True), strict=True):
        hi[key] = float(m)
        lo[key] = -hi[key]
        if level == "velocity":
            prev = key.removesuffix("_r") + "_prev"
            hi[prev] = hi[key] = max(hi[key], float(a))
            lo[prev] = lo[key] = -hi[key]
    if level == "torque":
        fin = rates[np.isfinite(rates).all(axis=1)]
        for i, key in enumerate(("dv_r", "domega_r")):
            hi[key] = float(np.max(np.abs(fin[:, i]))) if len(fin) else 0.0
            lo[key] = -hi[key]
        v, w = 2.0 * float(big[0]) + 1.0, 2.0 * float(big[1]) + 1.0
        wheel = (v + w * robot.b) / robot.wheel_radius_m
        for key, x in (("v", v), ("omega", w), ("wheel_l", wheel), ("wheel_r", wheel)):
            lo[key], hi[key] = -x, x
        for key, x in (("tau_l_prev", act_high[0]), ("tau_r_prev", act_high[1])):
            lo[key], hi[key] = -float(x), float(x)
    names = VELOCITY if level == "velocity" else TORQUE
    low = np.array([lo[n] for n in names], dtype=np.float64)
    high = np.array([hi[n] for n in names], dtype=np.float64)
    return Layout(names, low, np.maximum(high, low), np.asarray(act_high, dtype=np.float64))


def velocity_limits(law) -> np.ndarray:
    """(v_max, omega_max): the controller's limits (``[controller] v_max``, ``omega_max``; on another
    robot, ``robot=`` sets them from its wheels), which bound the velocity level's action."""
    if law.v_max is None or law.omega_max is None:
        raise ConfigError(
            "scenario [controller] v_max, omega_max",
            "the action's bounds are the controller's limits: set both in the scenario (or give robot=)",
        )
    return np.array([float(law.v_max), float(law.omega_max)])


def torque_limits(robot) -> np.ndarray:
    """Each wheel's torque limit (N m) of the robot's nominal model; where it has none, what lifts
    the robot at 2 g."""
    t = robot.torque_limit_Nm
    if not math.isfinite(t):
        t = 2.0 * G * robot.mass_kg * robot.wheel_radius_m
    return np.array([t, t])


def fill(
    out: np.ndarray,
    e: np.ndarray,
    r: np.ndarray,
    prev: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    torque: tuple | None = None,
) -> np.ndarray:
    """Rows (B, D) of observations: errors ``e`` (B, 3), reference samples ``r`` (B, 5), last
    commands ``prev`` (B, 2); at the torque level ``torque`` = (r_dot (B, 2), pose (B, 3), twist
    (B, 2), wheel speeds (B, 2)). Headings wrapped, not-finite values 0, then clipped to the Box."""
    out[:, 0:3], out[:, 3:8] = e, r
    if torque is None:
        out[:, 8:10] = prev
        angles = (2, 5)
    else:
        r_dot, pose, twist, wheels = torque
        out[:, 8:10], out[:, 10:13], out[:, 13:15], out[:, 15:17], out[:, 17:19] = r_dot, pose, twist, wheels, prev
        angles = (2, 5, 12)
    for j in angles:
        out[:, j] = wrap(out[:, j])
    np.nan_to_num(out, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    np.clip(out, low, high, out=out)
    return out


@dataclass(frozen=True)
class Reward:
    """The default reward of a step, of the true error after it (the metrics' error) and the command:

        reward = -((e1^2 + e2^2) / position_m^2 + e3^2 / heading_rad^2) - effort * |u / u_max|^2

    with ``u_max`` the action's bounds: 0 while tracking exactly, -1 at a ``position_m`` error.
    Replace it by any callable ``reward(e_true, u, info) -> float`` (``make(..., reward=...)``)."""

    position_m: float = 0.05
    heading_rad: float = 0.5
    effort: float = 0.01

    def __post_init__(self) -> None:
        for key in ("position_m", "heading_rad"):
            if not getattr(self, key) > 0:
                raise ConfigError(f"reward {key}", f"must be positive, got {getattr(self, key)!r}")
        if not self.effort >= 0:
            raise ConfigError("reward effort", f"must be at least 0, got {self.effort!r}")

    def batch(self, e_true: np.ndarray, u: np.ndarray, u_max: np.ndarray) -> np.ndarray:
        """(B,) rewards for the true errors (B, 3) and commands (B, 2)."""
        p = (e_true[:, 0] ** 2 + e_true[:, 1] ** 2) / self.position_m**2
        h = wrap(e_true[:, 2]) ** 2 / self.heading_rad**2
        a = u / u_max
        out = -(p + h) - self.effort * (a[:, 0] ** 2 + a[:, 1] ** 2)
        return np.nan_to_num(out, nan=-1e6, posinf=-1e6, neginf=-1e6)
