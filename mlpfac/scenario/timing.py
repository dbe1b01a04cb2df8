"""A path timed within a robot's limits: the time-optimal speed profile along its arc length s.

The numerical integration method of Bobrow, Dubowsky & Gibson (1985) and Shin & McKay (1985), in
the discrete form TOPP-RA (Pham & Pham, 2018) also takes: on a grid of s, x = (ds/dt)^2 at each
point and a constant path acceleration u = d2s/dt2 in each cell (so x_{i+1} = x_i + 2 ds u_i, and
t follows exactly); a backward pass gives, at each grid point, the fastest from which the rest of
the path can still be driven within the limits, and a forward pass drives it as fast as that allows.

The limits, at both ends of every cell (v = ds/dt, omega = kappa v, dv = u,
domega = kappa' x + kappa u, kappa' = dkappa/ds; h = track / 2):

- each wheel's rim speed and acceleration: |v| + h |omega| <= v_max, |dv| + h |domega| <= a_max
  (with h = 0 these are |v| <= v_max and |dv| <= a_max: limits on v and omega apart);
- |omega| <= omega_max and |domega| <= alpha_max.

Each acceleration limit is a pair of linear bounds on u for a given x, u >= lo0 + lo1 x and
u <= hi0 + hi1 x, so each pass needs only minima and maxima of straight lines: no solver. Only
arithmetic and square roots: the same bits on every processor.
"""

from __future__ import annotations

import numpy as np

from mlpfac.exceptions import ConfigError

BIG = 1e300  # a bound that does not bound


def profile(
    s: np.ndarray, kappa: np.ndarray, dkappa: np.ndarray, limits: tuple[float, ...], closed: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(v at each grid point, dv/dt in each cell, t at each grid point) of the fastest profile within
    ``limits`` = (v_max, omega_max, a_max, alpha_max, track). An open path starts and ends as fast
    as its limits allow; a closed one is periodic (its first and last grid points are the same point)."""
    v_max, omega_max, a_max, alpha_max, track = limits
    h = 0.5 * track
    cap = np.minimum(v_max / (1.0 + np.abs(kappa) * h), omega_max / np.maximum(np.abs(kappa), 1e-300))
    rows = [(np.ones_like(kappa), np.zeros_like(kappa), a_max), (kappa, dkappa, alpha_max)]
    if track > 0:  # each wheel's rim: dv + h domega and dv - h domega
        rows += [(1.0 + h * kappa, h * dkappa, a_max), (1.0 - h * kappa, -h * dkappa, a_max)]
    l0, l1, h0, h1, xcap = _lines(rows)
    X = np.minimum(cap * cap, xcap)
    two = 2.0 * np.diff(s)
    lo_a, lo_b, up_a, up_b = _cells(l0, l1, h0, h1, two)
    X[:-1] = np.minimum(X[:-1], _pairs(lo_a, lo_b, up_a, up_b))
    n = len(X) - 1
    B = X.copy()  # the fastest at each point from which the rest can still be driven (backward pass)
    for _ in range(3 if closed else 1):
        if closed:
            B[n] = min(B[n], B[0])
        for i in range(n - 1, -1, -1):
            B[i] = min(B[i], _brake(B[i + 1], two[i], lo_a[:, i].tolist(), lo_b[:, i].tolist()))
    x = np.empty_like(X)
    x[0] = B[0]
    for _ in range(4 if closed else 1):
        for i in range(n):
            up = min(a + b * x[i] for a, b in zip(up_a[:, i].tolist(), up_b[:, i].tolist(), strict=True))
            x[i + 1] = min(B[i + 1], x[i] + two[i] * up)
        if not closed or x[n] == x[0]:
            break
        x[0] = min(B[0], x[n])
    if closed:
        x[n] = x[0]
    if not np.all(x > 0):
        raise ConfigError("", "the path cannot be timed within its limits: its speed falls to zero")
    v = np.sqrt(x)
    return v, (x[1:] - x[:-1]) / two, np.concatenate([[0.0], np.cumsum(two / (v[:-1] + v[1:]))])


def _lines(rows: list) -> tuple[np.ndarray, ...]:
    """Each row (p, q, c), |p u + q x| <= c, as u >= l0 + l1 x and u <= h0 + h1 x at each grid
    point; a row with p = 0 bounds x alone (xcap)."""
    n = len(rows[0][0])
    l0, l1, h0, h1 = (np.zeros((len(rows), n)) for _ in range(4))
    xcap = np.full(n, np.inf)
    for j, (p, q, c) in enumerate(rows):
        ok = np.abs(p) > 1e-12
        ps = np.where(ok, p, 1.0)
        l0[j] = np.where(ok, -c / np.abs(ps), -BIG)
        h0[j] = np.where(ok, c / np.abs(ps), BIG)
        l1[j] = h1[j] = np.where(ok, -q / ps, 0.0)
        flat = ~ok & (np.abs(q) > 0)  # |q x| <= c whatever u
        xcap = np.where(flat, np.minimum(xcap, c / np.where(flat, np.abs(q), 1.0)), xcap)
    return l0, l1, h0, h1, xcap


def _cells(l0, l1, h0, h1, two: np.ndarray) -> tuple[np.ndarray, ...]:
    """The bounds on each cell's u as lines in x at its start: the start point's own, and the end
    point's at x + two u (u >= a + b (x + two u) is u (1 - two b) >= a + b x: a lower bound where
    1 - two b > 0, an upper one where it is < 0; and the other way round for an upper bound)."""
    lo_a, lo_b, up_a, up_b = [l0[:, :-1]], [l1[:, :-1]], [h0[:, :-1]], [h1[:, :-1]]
    for a, b, lower in ((l0[:, 1:], l1[:, 1:], True), (h0[:, 1:], h1[:, 1:], False)):
        g = 1.0 - two * b
        valid = (np.abs(a) < BIG) & (g != 0.0)
        gs = np.where(valid, g, 1.0)
        as_lower = valid & ((g > 0.0) == lower)
        as_upper = valid & ((g > 0.0) != lower)
        lo_a.append(np.where(as_lower, a / gs, -BIG))
        lo_b.append(np.where(as_lower, b / gs, 0.0))
        up_a.append(np.where(as_upper, a / gs, BIG))
        up_b.append(np.where(as_upper, b / gs, 0.0))
    return np.concatenate(lo_a), np.concatenate(lo_b), np.concatenate(up_a), np.concatenate(up_b)


def _pairs(lo_a, lo_b, up_a, up_b) -> np.ndarray:
    """The largest x at each cell's start for which some u lies within all its bounds."""
    most = np.full(lo_a.shape[1], np.inf)
    for r in range(lo_a.shape[0]):
        for q in range(up_a.shape[0]):
            slope = lo_b[r] - up_b[q]
            gap = up_a[q] - lo_a[r]
            tight = (slope > 0.0) & (np.abs(gap) < BIG)
            most = np.where(tight, np.minimum(most, gap / np.where(tight, slope, 1.0)), most)
    return most


def _brake(x_next: float, two: float, lo_a: list, lo_b: list) -> float:
    """The largest x at a cell's start from which braking as hard as its bounds allow (u = the
    largest lower bound) reaches at most ``x_next`` at its end."""
    most = np.inf
    for a, b in zip(lo_a, lo_b, strict=True):
        slope = 1.0 + two * b
        if slope > 0.0 and a > -BIG:
            most = min(most, (x_next - two * a) / slope)
    return most
