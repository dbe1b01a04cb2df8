"""Reference trajectories: (x_r, y_r, theta_r, v_r, omega_r) at time t, eq. (1) and (37).

Each reference is a smooth planar curve p(t) = (x_r(t), y_r(t)) given with its first and second
derivatives in closed form, so v_r = |p'| and omega_r = (x' y'' - y' x'') / |p'|^2 are analytic.
theta_r = atan2(y', x') (the printed ``arctan(y_r / dx_r)`` of (37) is a typo) is unwrapped
along the sampled times, so it is continuous over a run.

Every kind takes ``speed`` (default 1): the same path traversed ``speed`` times as fast,
p_s(t) = p(speed t), so v_r and omega_r are x speed and the accelerations x speed^2.

Beside these curves, a reference is your own path (``kind = "path"``: waypoints, rounded and timed
within the robot's limits, :mod:`mlpfac.scenario.path`) or your own class (``kind =
"file.py:Class"``, :mod:`mlpfac.scenario.own_reference`): both give the rates of v_r and omega_r
with the samples (:func:`sample_rates`), where the curves' are taken by finite differences.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mlpfac.elementary import atan2, cos, each, sin
from mlpfac.exceptions import ConfigError


@dataclass(frozen=True)
class Eight:
    """Figure of eight (37): x_r = ax cos(wx t), y_r = ay sin(wy t)."""

    ax: float = 2.0  # m, half the eight's width
    ay: float = 2.0  # m, half its height
    wx: float = 0.25  # rad/s
    wy: float = 0.5  # rad/s (2 wx: an eight)
    speed: float = 1.0  # x, the same path traversed this many times as fast

    def derivatives(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        cx, sx = each(cos, self.wx * t), each(sin, self.wx * t)
        cy, sy = each(cos, self.wy * t), each(sin, self.wy * t)
        return (
            self.ax * cx,
            self.ay * sy,
            -self.ax * self.wx * sx,
            self.ay * self.wy * cy,
            -self.ax * (self.wx * self.wx) * cx,
            -self.ay * (self.wy * self.wy) * sy,
        )


@dataclass(frozen=True)
class Circle:
    """Circle of radius ``radius`` about (cx, cy), travelled counter-clockwise at rate ``rate`` rad/s."""

    radius: float = 1.5  # m
    rate: float = 0.5  # rad/s
    cx: float = 0.0  # m, centre
    cy: float = 0.0  # m
    speed: float = 1.0  # x, the same path traversed this many times as fast

    def derivatives(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        c, s = each(cos, self.rate * t), each(sin, self.rate * t)
        r, w = self.radius, self.rate
        return (self.cx + r * c, self.cy + r * s, -r * w * s, r * w * c, -r * w * w * c, -r * w * w * s)


@dataclass(frozen=True)
class Line:
    """Straight line from (x0, y0) along ``heading`` at constant speed ``v``."""

    v: float = 0.5  # m/s, at speed 1
    heading: float = 0.0  # rad, from the x axis
    x0: float = 0.0  # m, the start
    y0: float = 0.0  # m
    speed: float = 1.0  # x, the same path traversed this many times as fast

    def derivatives(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        dx, dy = self.v * cos(self.heading), self.v * sin(self.heading)
        zero = np.zeros_like(t)
        return (self.x0 + dx * t, self.y0 + dy * t, dx + zero, dy + zero, zero, zero)


@dataclass(frozen=True)
class Lemniscate:
    """Lemniscate of Bernoulli with half-width ``a``, phase s = rate t:
    x = a cos s / (1 + sin^2 s), y = a sin s cos s / (1 + sin^2 s)."""

    a: float = 2.0  # m
    rate: float = 0.3  # rad/s
    speed: float = 1.0  # x, the same path traversed this many times as fast

    def derivatives(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        s, w, a = self.rate * t, self.rate, self.a
        sn, cs = each(sin, s), each(cos, s)
        d = 1.0 + sn * sn
        x = a * cs / d
        y = a * sn * cs / d
        # d/ds of x and y, then chain rule with ds/dt = w.
        s2 = sn * sn
        xs = a * sn * (s2 - 3.0) / (d * d)  # dx/ds
        ys = -a * (3.0 * s2 - 1.0) / (d * d)  # dy/ds
        xss = (
            -a * cs * (s2 * s2 - 12.0 * s2 + 3.0) / (d * d * d)
        )  # not d**3: pow is the C library's, or numpy's dispatched
        yss = -a * (14.0 * each(sin, 2.0 * s) + 3.0 * each(sin, 4.0 * s)) / (4.0 * (d * d * d))
        return x, y, w * xs, w * ys, w * w * xss, w * w * yss


REFERENCES = {"eight": Eight, "circle": Circle, "line": Line, "lemniscate": Lemniscate}


def sample(curve, t: np.ndarray) -> np.ndarray:
    """Reference samples at times ``t``: (N, 5) rows (x_r, y_r, theta_r, v_r, omega_r).

    theta_r is unwrapped along ``t`` (continuous as long as it turns less than pi between samples).
    """
    return sample_rates(curve, t)[0]


def sample_rates(curve, t: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(:func:`sample`'s rows, the rates (dv_r/dt, domega_r/dt) (N, 2) where the reference gives
    them (a path, your own class), else None: the closed-form curves' are their samples' finite
    differences, :func:`mlpfac.control.torque.reference_rates`)."""
    if hasattr(curve, "rows"):
        rows = curve.rows(np.asarray(t, dtype=float))
        return np.ascontiguousarray(rows[:, :5]), np.ascontiguousarray(rows[:, 5:7])
    return _curve(curve, t), None


def _curve(curve: Eight | Circle | Line | Lemniscate, t: np.ndarray) -> np.ndarray:
    t = np.asarray(t, dtype=float)
    k = curve.speed  # k = 1 changes no bit: 1 * t == t
    x, y, dx, dy, ddx, ddy = curve.derivatives(k * t)
    dx, dy, ddx, ddy = k * dx, k * dy, k * k * ddx, k * k * ddy
    speed2 = dx * dx + dy * dy
    theta = np.unwrap(each(atan2, dy, dx))
    v = np.sqrt(speed2)
    omega = (dx * ddy - dy * ddx) / speed2
    return np.stack([x, y, theta, v, omega], axis=-1)


# The physically sensible size of a reference's parameters, by key (absolute values; lengths in m,
# rates in rad/s, speeds in m/s), and of the speeds it asks of a wheeled robot.
RATE_KEYS, SPEED_KEYS = frozenset({"wx", "wy", "rate"}), frozenset({"v"})
LENGTH_MAX, RATE_MAX, SPEED_MAX, ANGLE_MAX, FACTOR_MAX = 1e4, 10.0, 20.0, 1e3, 100.0
OMEGA_MAX = 100.0  # rad/s of omega_r along the curve


def _limit(key: str) -> tuple[float, str]:
    if key in RATE_KEYS:
        return RATE_MAX, "rad/s"
    if key in SPEED_KEYS:
        return SPEED_MAX, "m/s"
    if key == "heading":
        return ANGLE_MAX, "rad"
    if key == "speed":
        return FACTOR_MAX, "x"
    return LENGTH_MAX, "m"


def make_reference(kind: str, params: dict, where: str = "[reference]", limits: tuple = (None, None)):
    """Build a reference from its scenario table (``kind`` plus its parameters): a curve, a path
    (``limits``: the controller's (v_max, omega_max), for the path's limits the table leaves unset)
    or your own class."""
    if kind == "path":
        from mlpfac.scenario.waypoints import make_path

        return make_path(params, where, limits)
    if isinstance(kind, str) and ":" in kind:
        from mlpfac.scenario.own_reference import make_own

        return make_own(kind, params, where)
    cls = REFERENCES.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise ConfigError(
            f"{where} kind",
            f"unknown reference kind {kind!r}; choose one of {', '.join(REFERENCES)}, path (your waypoints), "
            "or your own class as path/to/file.py:Class or package.module:Class",
        )
    for key, val in params.items():
        if isinstance(val, bool) or not isinstance(val, int | float) or not math.isfinite(val):
            raise ConfigError(f"{where} {key}", f"expected a finite number, got {val!r}")
    fields = cls.__dataclass_fields__
    for key in params:
        if key not in fields:
            raise ConfigError(f"{where} {key}", f"not a parameter of {kind!r} (it takes {', '.join(fields)})")
    for key, value in params.items():
        most, unit = _limit(key)
        if isinstance(value, int | float) and not isinstance(value, bool) and not abs(value) <= most:
            raise ConfigError(f"{where} {key}", f"must lie within +-{most:g} {unit}, got {value!r}")
    speed = params.get("speed", 1.0)
    if isinstance(speed, int | float) and not isinstance(speed, bool) and not speed > 0:
        raise ConfigError(f"{where} speed", f"must be > 0 (the path traversed speed times as fast), got {speed!r}")
    try:
        curve = cls(**{k: float(v) for k, v in params.items()})
    except (TypeError, ValueError) as err:
        raise ConfigError(where, f"bad parameter value: {err}") from None
    with np.errstate(all="ignore"):
        ok = _curve(curve, np.linspace(0.0, 60.0, 601))
    if np.any(ok[:, 3] <= 1e-6):  # first: where v_r is 0, omega_r = 0 / 0 is not finite (speed = 1e-300)
        raise ConfigError(where, "the reference speed v_r must stay above zero (the gains divide by T v_r)")
    if not np.all(np.isfinite(ok)):
        raise ConfigError(where, "the reference is not finite along its path: its parameters overflow")
    if np.max(ok[:, 3]) > SPEED_MAX or np.max(np.abs(ok[:, 4])) > OMEGA_MAX:
        raise ConfigError(
            where,
            f"the reference asks for speeds beyond a wheeled robot's (v_r up to {SPEED_MAX:g} m/s, |omega_r| up to "
            f"{OMEGA_MAX:g} rad/s; this one: {np.max(ok[:, 3]):.3g} m/s, {np.max(np.abs(ok[:, 4])):.3g} rad/s)",
        )
    return curve
