"""Your own path: waypoints turned into a smooth, timed reference (x_r, y_r, theta_r, v_r, omega_r)
with its rates (dv_r/dt, domega_r/dt), within the limits of the robot that drives it.

1. **Corners.** Each waypoint where the route turns is rounded: the curve leaves the straight line
   ``d = 2 sqrt(2) radius`` before the waypoint and joins the next one as far after it (at most a
   quarter of either leg): a right angle's smallest radius of curvature is then ``radius``, a gentler
   corner's larger and a sharper one's smaller (the timing slows for it). Between corners the path is
   exactly straight (omega_r = 0).
2. **The curve.** One quintic B-spline (:class:`scipy.interpolate.BSpline`) whose control points lie
   on the legs (at d and 2 d on either side of each corner) and at the corners: a span whose
   control points all lie on one leg is that leg, and the curve's derivatives up to the third are continuous, so
   its curvature, and omega_r, are continuous (each corner's curvature rises from zero to 1 / radius
   and back). A closed route is a periodic B-spline, started in the middle of its first corner.
3. **Arc length.** s(u) by 5-point Gauss-Legendre quadrature on a grid of the spline's parameter
   (exact on the straight spans); a point at arc length s is found by Newton's method on it.
4. **Timing.** The time-optimal speed profile along s (the numerical integration of Bobrow, Dubowsky
   & Gibson, 1985, and Shin & McKay, 1985: a backward pass for the braking that the corners ahead
   need, a forward pass for the acceleration): at every grid point the speed keeps
   ``|v| + |omega| track / 2 <= v_max`` (each wheel's rim speed; ``track = 0``: ``|v| <= v_max``) and
   ``|omega| <= omega_max``, and within each cell the constant path acceleration keeps
   ``|dv| + |domega| track / 2 <= a_max`` and ``|domega| <= alpha_max`` (domega = kappa' v^2 + kappa dv).
   v_r stays above zero: an open route starts and ends at the speed its limits allow (the robot
   starts moving), and goes on straight along its last leg after its end; a closed route loops.

Only arithmetic, square roots and :mod:`mlpfac.elementary` (atan2) are computed, and scipy's
B-spline evaluation (Cython, no BLAS): the same bits on every processor.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from mlpfac.elementary import atan2, each
from mlpfac.exceptions import ConfigError
from mlpfac.scenario.timing import profile

ROOT2 = math.sqrt(2.0)
K = 5  # the spline's degree: quintic, so that omega_r's rate is continuous too
CORNER_D = 4.0 * ROOT2 / 3.0  # d of a right angle whose smallest radius of curvature is 1 (at its middle)
MIN_LEG = 1e-3  # m: consecutive waypoints closer than this are a repeated point
MIN_RADIUS = 1e-3  # m: a corner rounded tighter than this (as a repeated point) is no corner the spline can draw
MAX_TURN_COS = -0.985  # a waypoint may turn the route by up to about 170 degrees (cos 170 = -0.985)
GRID_DS = 0.02  # m: the timing's grid along a span, at most
CORNER_NODES = 64  # grid points per span of a corner, at least (the limits hold between two to 0.1 %)
STRAIGHT_NODES = 4  # ... of a straight span
MAX_NODES = 500_000  # the timing's grid: a path longer or finer than this is refused
NEWTON = 4  # Newton steps from a point's linear guess to its arc length (quadratic convergence)
# 5-point Gauss-Legendre on [-1, 1]: exact for polynomials of degree 9 (the straight spans' |C'|)
GL_X = np.array([-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831, 0.9061798459386640])
GL_W = np.array([0.2369268850561891, 0.4786286704993665, 0.5688888888888889, 0.4786286704993665, 0.2369268850561891])


@dataclass(frozen=True)
class Path:
    """A route through waypoints, timed within limits (the module's docstring); every field is a
    key of ``[reference]`` with ``kind = "path"`` (``points`` read from ``file`` where it names one)."""

    points: tuple[tuple[float, float], ...]
    closed: bool = False  # the route returns to its first waypoint and loops
    v_max: float = 1.0  # m/s: |v| + |omega| track / 2 (a wheel's rim speed), and |v|
    omega_max: float = 2.5  # rad/s: |omega|
    a_max: float = 1.0  # m/s^2: |dv| + |domega| track / 2 (a wheel's rim acceleration), and |dv|
    alpha_max: float = 2.5  # rad/s^2: |domega|
    track: float = 0.0  # m: the wheels' track (0: v and omega limited apart, as on the kinematic model)
    radius: float = (
        0.0  # m: a right angle's smallest radius of curvature (0: max(v_max / 2 omega_max, track / 2, 1 mm))
    )
    speed: float = 1.0  # x, the same path traversed this many times as fast
    file: str = ""  # the CSV file the points were read from ("": given inline)
    sha256: str = ""  # of that file
    geometry: Geometry = field(init=False, compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "geometry", timed(*self.key()))

    def provenance(self) -> dict | None:
        """What ``[provenance] reference`` records: the CSV file and its sha256 (None: points inline)."""
        return {"file": self.file, "sha256": self.sha256} if self.file else None

    def key(self) -> tuple:
        """What the curve and its timing depend on (not ``speed``): the timed path is made once per key."""
        radius = self.radius or max(self.v_max / (2.0 * self.omega_max), self.track / 2.0, MIN_RADIUS)
        return (self.points, self.closed, radius, self.v_max, self.omega_max, self.a_max, self.alpha_max, self.track)

    @property
    def duration(self) -> float:
        """s: the route once (open), or one lap (closed), at this ``speed``."""
        return self.geometry.t[-1] / self.speed

    def rows(self, t: np.ndarray) -> np.ndarray:
        """(N, 7) rows (x_r, y_r, theta_r, v_r, omega_r, dv_r/dt, domega_r/dt) at times ``t``; theta_r
        continuous along the route (over laps too), whatever the spacing of ``t``."""
        k = self.speed
        out = self.geometry.rows(k * np.asarray(t, dtype=float))
        out[:, 3:5] *= k
        out[:, 5:7] *= k * k
        return out


class Geometry:
    """A route's spline, arc-length grid and speed profile (made by :func:`timed`, cached)."""

    def __init__(
        self, points: np.ndarray, closed: bool, radius: float, limits: tuple[float, float, float, float, float]
    ):
        from scipy.interpolate import BSpline

        c, t, self.u0, self.u1 = control_polygon(points, closed, radius)
        self.closed = closed
        self.C = BSpline.construct_fast(t, c, K, extrapolate=False)  # the knots are ours: no checks (np.unique sorts)
        self.dC = [self.C.derivative(n) for n in (1, 2, 3)]
        self._arc_grid()
        self.v, self.a, self.t = profile(self.s, self.kappa, self.dkappa, limits, closed)
        self.theta_nodes = np.unwrap(each(atan2, self.d1[:, 1], self.d1[:, 0]))
        end = self.d1[-1] / np.sqrt(self.d1[-1, 0] * self.d1[-1, 0] + self.d1[-1, 1] * self.d1[-1, 1])
        self.end = (self.C(self.u1), end)  # an open route goes on along its last leg

    # -- arc length

    def _speed(self, u: np.ndarray) -> np.ndarray:
        """|C'(u)|."""
        d = self.dC[0](u)
        return np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1])

    def _gauss(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The arc length from u = a to u = b (arrays), 5-point Gauss-Legendre."""
        half = 0.5 * (b - a)
        mid = 0.5 * (b + a)
        f = self._speed(mid[:, None] + half[:, None] * GL_X[None, :])
        return half * (
            f[:, 0] * GL_W[0] + f[:, 1] * GL_W[1] + f[:, 2] * GL_W[2] + f[:, 3] * GL_W[3] + f[:, 4] * GL_W[4]
        )

    def _arc_grid(self) -> None:
        """The grid of u (each span cut into cells of at most GRID_DS, and at least CORNER_NODES in
        a corner's), its arc lengths s, and the curvature there."""
        spans = np.arange(self.u0, self.u1)
        eighths = spans[:, None] + np.arange(9)[None, :] / 8.0
        rough = self._gauss(eighths[:, :-1].ravel(), eighths[:, 1:].ravel()).reshape(len(spans), 8).sum(axis=1)
        bent = curvature(*(d(eighths[:, :-1].ravel()) for d in self.dC))[0].reshape(len(spans), 8)
        least = np.where(np.abs(bent).max(axis=1) * rough > 1e-9, CORNER_NODES, STRAIGHT_NODES)
        n = np.maximum(least, np.ceil(rough / GRID_DS)).astype(int)
        if n.sum() > MAX_NODES:
            raise ConfigError(
                "", f"the path needs {n.sum()} grid points to be timed (at most {MAX_NODES}): it is too long"
            )
        u = np.concatenate(
            [s + np.arange(m) / m for s, m in zip(spans.tolist(), n.tolist(), strict=True)] + [[self.u1]]
        )
        self.u = u
        self.s = np.concatenate([[0.0], np.cumsum(self._gauss(u[:-1], u[1:]))])
        self.length = float(self.s[-1])
        d1, d2, d3 = (d(u) for d in self.dC)
        self.d1 = d1
        self.kappa, self.dkappa = curvature(d1, d2, d3)
        if self.closed:  # the same point: the same curvature, to the bit
            self.kappa[-1], self.dkappa[-1] = self.kappa[0], self.dkappa[0]

    def u_at(self, s: np.ndarray) -> np.ndarray:
        """The spline's parameter at arc lengths ``s`` (within [0, length]): Newton's method on the
        grid cell's quadrature, from the linear guess."""
        i = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.s) - 2)
        a, b = self.u[i], self.u[i + 1]
        sa = self.s[i]
        u = a + (b - a) * (s - sa) / (self.s[i + 1] - sa)
        for _ in range(NEWTON):
            u = np.minimum(np.maximum(u - (sa + self._gauss(a, u) - s) / self._speed(u), a), b)
        return u

    # -- timing

    # -- sampling

    def rows(self, tau: np.ndarray) -> np.ndarray:
        """(N, 7) rows at times ``tau`` (speed 1)."""
        lap = self.t[-1]
        turns = np.zeros_like(tau)
        beyond = np.zeros_like(tau)
        if self.closed:
            turns = np.floor(tau / lap)
            tau = tau - turns * lap
        else:
            beyond = np.maximum(tau - lap, 0.0)
            tau = np.minimum(tau, lap)
        i = np.clip(np.searchsorted(self.t, tau, side="right") - 1, 0, len(self.t) - 2)
        dt = tau - self.t[i]
        a = self.a[i]
        v = self.v[i] + a * dt
        s = np.minimum(self.s[i] + self.v[i] * dt + 0.5 * a * dt * dt, self.s[i + 1])
        u = self.u_at(s)
        d1, d2, d3 = (d(u) for d in self.dC)
        kappa, dkappa = curvature(d1, d2, d3)
        p = self.C(u)
        theta = each(atan2, d1[:, 1], d1[:, 0])
        near = self.theta_nodes[i]  # the grid's continuous heading: theta_r put within pi of it
        theta = theta + 2.0 * math.pi * np.round((near - theta) / (2.0 * math.pi))
        if self.closed:
            theta = theta + turns * (self.theta_nodes[-1] - self.theta_nodes[0])
        out = np.stack([p[:, 0], p[:, 1], theta, v, kappa * v, a, dkappa * v * v + kappa * a], axis=-1)
        after = beyond > 0
        if np.any(after):  # past an open route's end: straight on along its last leg, at its last speed
            (x1, y1), e = self.end
            ve = self.v[-1]
            out[after, 0] = x1 + e[0] * ve * beyond[after]
            out[after, 1] = y1 + e[1] * ve * beyond[after]
            out[after, 2] = self.theta_nodes[-1]
            out[after, 3] = ve
            out[after, 4:7] = 0.0
        return out


def curvature(d1: np.ndarray, d2: np.ndarray, d3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The signed curvature kappa and its rate along the arc dkappa/ds from a curve's first three derivatives."""
    q = d1[:, 0] * d1[:, 0] + d1[:, 1] * d1[:, 1]
    speed = np.sqrt(q)
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    kappa = cross / (q * speed)
    dcross = d1[:, 0] * d3[:, 1] - d1[:, 1] * d3[:, 0]
    dot = d1[:, 0] * d2[:, 0] + d1[:, 1] * d2[:, 1]
    dkappa = (dcross / (q * speed) - 3.0 * cross * dot / (q * q * speed)) / speed
    return kappa, dkappa


def control_polygon(points: np.ndarray, closed: bool, radius: float) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The B-spline of degree K through a route: (coefficients, knots, first and last parameter).

    Each corner's control points are its waypoint and K - 1 points on either leg, d apart: the K
    spans whose K + 1 control points hold points of both legs are its curve (leaving the legs
    (K - 1) d / 2 before and after the waypoint); every other span has its points on one leg and
    is that leg. An open route's ends are clamped (the curve starts at the first waypoint, along the
    first leg), K - 1 control points between the end and the corner keeping the corner's knots uniform."""
    n = len(points)
    legs = np.roll(points, -1, axis=0) - points if closed else points[1:] - points[:-1]
    length = np.sqrt(legs[:, 0] * legs[:, 0] + legs[:, 1] * legs[:, 1])
    unit = legs / length[:, None]
    m = len(legs)
    corner = np.zeros(n)  # d of each waypoint (0: an open route's ends)
    share = 1.0 / (2.0 * (K - 1))  # a corner takes at most half of either leg
    for i in range(n) if closed else range(1, n - 1):
        corner[i] = min(CORNER_D * radius, share * length[i - 1], share * length[i])
    steps = np.arange(1, K, dtype=float)
    c: list[np.ndarray] = [] if closed else [points[0]]
    for i in range(m):
        start, end = i == 0 and not closed, i == m - 1 and not closed
        j = (i + 1) % n
        near = [] if start else list(corner[i] * steps)
        far = [] if end else list(length[i] - corner[j] * steps[::-1])
        if start or end:  # a clamped end: K - 1 control points between it and the corner
            lo = 0.0 if start else near[-1]
            hi = length[i] if end else far[0]
            near += list(lo + (hi - lo) * steps / K)
        if near and far and far[0] - near[-1] <= 1e-9 * length[i]:  # both corners take half the leg
            far = far[1:]
        c += [points[i] + s * unit[i] for s in near + far]
        c.append(points[j])
    c = np.array(c)
    if closed:  # periodic, the first waypoint at the middle of the domain's first K control points
        c = np.concatenate([c[-(K + 1) // 2 :], c[: -(K + 1) // 2]])
        return np.concatenate([c, c[:K]]), np.arange(len(c) + 2 * K + 1, dtype=float), float(K), float(len(c) + K)
    knots = np.concatenate([np.zeros(K), np.arange(len(c) - K + 1, dtype=float), np.full(K, len(c) - K, dtype=float)])
    return c, knots, 0.0, float(len(c) - K)


@functools.lru_cache(maxsize=16)
def timed(points, closed, radius, v_max, omega_max, a_max, alpha_max, track) -> Geometry:
    """The route's spline and profile, made once per set of inputs (a sweep parses a scenario many times)."""
    return Geometry(np.array(points, dtype=float), closed, radius, (v_max, omega_max, a_max, alpha_max, track))
