"""The measurement delay found by a bank of predictors over the candidate delays d = 0..D, with a
likelihood ratio: the input model's ``delay_finder = "bank"``.

Candidate d says the measured pose is d control steps old, so the velocity realised between the
poses measured at k - 1 and k (:mod:`mlpfac.control.adaptive.input_model`: the chord over T at the mid heading, and
the heading increment over T) is the input gain times the command sent d steps before the one the
undelayed robot answers with (the last one sent, u_k-1), per channel c in {v, omega}:

    y_c,k = g_c u_c,k-1-d + n_c,k,     n_c ~ N(0, s_c^2).

Each candidate's prediction error r_c,d = y_c,k - g_c u_c,k-1-d, less its running mean m_c,d over
``MEAN_WINDOW`` steps, scores its log-likelihood, exponentially windowed over ``WINDOW`` steps,

    L_d <- a L_d - sum_c min((r_c,d - m_c,d)^2 / s_c^2, CAP) / 2,       a = 1 - 1 / WINDOW,

with s_c^2 the running mean of the chosen candidate's (r_c - m_c)^2. A delay shows in the fast
part of the error (the commands' step-to-step moves, which the closed loop's pose noise excites);
a wrong input gain (after a wheel or period change, before the input model has relearnt it) adds
g_err u, slow, which the running mean takes out: otherwise the oldest command would fit best while
the robot slows down. The cap bounds what one step can add. And when the input model detects a
change (its CUSUM alarm), no choice is made for ``QUIET_STEPS``: while g is relearnt, a fast
change of the commands makes any lag fit (measured: delay 6 chosen 0.5 s after a wheel-radius
change without this). The scores are kept: clearing them there let a delay of 1 be chosen on a
nominal run (before candidate 0's lead, below, had built up again). The choice moves to the best
candidate as soon as its log-likelihood ratio over the current one exceeds ``THRESHOLD``: no
correlation held for a hundred steps, no persistence count. The closed loop's own pose noise
excites the commands; what the ratio gains per step is that excitation over the measurement noise.

A measurement stream that stalls (the same pose again, to the rounding of rebuilding it from e and
r: the delay grew by one step, the sample is that much older) is evidence too, and exact: every
candidate's score moves one delay up (L_d+1 <- L_d) and so does the choice, at that step.
Candidate 0 then starts ``THRESHOLD`` below the worst.

Candidate 0 alone is compared with the command u_k-1, which answered the pose noise n_k-1 that
y_k also holds (as -n_k-1 / T): in closed loop its error is smaller than the plant explains (the
law's noise gain, T v_r K_theta = 0.16 on omega for Kanayama's gains at 1 m/s), and once a
delay is found it gains on the true candidate (measured on eight-sensor-delay: from 40 below it
to 4 above within 4.5 s). So the likelihood never moves the choice back to 0 (a delay that
returns to 0 is left at 1 at most), and moves it away from 0 only past ``FROM_ZERO``: with
``THRESHOLD`` a delay of 1 was chosen on 2 of 240 runs without one (seeds 20-39 of the eight-*,
tiago-* and cart-* scenarios), each costing about 10 mm. Lags of two steps and more have no such
bias, but on them the loop's own excitation at 1 mm of pose noise does not tell neighbouring delays
apart within seconds (candidates on u_k-2-d chose a delay of 4 before any event).

Batch-first and compiled as :mod:`mlpfac.control.adaptive.kernels`: a seed's arithmetic does not depend on the batch.
"""

from __future__ import annotations

import math

import numpy as np

from mlpfac.elementary import cos, sin
from mlpfac.jit import kernel

# columns of the per-seed state S
N, S2, DELAY = 0, 1, 3  # samples, the noise variances s_v^2 and s_omega^2 (1, 2), the delay chosen
ALARMS, QUIET = 4, 5  # the input model's alarms seen, steps left without a decision
WIDTH = 6
HELD = 1e-9  # m, rad: a pose within this of the last one is the same measurement (rebuilt from e and r)
WINDOW = 100  # steps in the exponential window of the log-likelihoods (1 s at T = 10 ms)
THRESHOLD = 4.0  # the log-likelihood ratio that moves the choice (about 55 : 1)
FROM_ZERO = 12.0  # the ratio that moves the choice away from 0 (candidate 0 leads a delay-free loop, below)
CAP = 9.0  # a step's normalised squared error counts at most this (3 s_c)
MEAN_WINDOW = 10  # steps in the running mean of each candidate's error
S2_WINDOW = 1000  # steps in the running mean of the noise variances
WARMUP = 200  # samples before the first decision by likelihood (50: a delay of 1 at 0.7 s on a nominal run)
QUIET_STEPS = 300  # steps without a decision after the input model's alarm (g settles within about 2 s)


@kernel()
def pose_of(e, r, q):
    """The pose q whose error (2) to r is e: (2) inverted."""
    th = r[2] - e[2]
    c, s = cos(th), sin(th)
    q[0] = r[0] - (c * e[0] - s * e[1])
    q[1] = r[1] - (s * e[0] + c * e[1])
    q[2] = th


@kernel()
def motion(q, qp, T, y):
    """The velocity realised between the poses qp and q one step apart: y = (the chord over T at the
    mid heading, the heading increment over T)."""
    dth = math.pi - ((math.pi - (q[2] - qp[2])) % (2.0 * math.pi))
    mid = qp[2] + 0.5 * dth
    y[0] = (cos(mid) * (q[0] - qp[0]) + sin(mid) * (q[1] - qp[1])) / T
    y[1] = dth / T


@kernel(
    "void(f8[:, ::1], f8[::1], b1, f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[:, ::1], f8[:, ::1], f8[:, :, ::1], f8)"
)
def bank_step(e, r, first, hist, q_prev, g, alarms, S, L, M, T):
    """One step for B seeds: e (B, 3) the measured error (2), r (>= 3,) the reference sample;
    hist (B, 2, >= D + 2) the commands sent, newest first; q_prev (B, 3) the last measured pose;
    g (B, 2) the input gains and alarms (B,) the input model's alarms so far; S (B, WIDTH),
    L (B, D + 1) and M (B, 2, D + 1) (the running means m_c,d): the state, updated in place."""
    D = L.shape[1] - 1
    a = 1.0 - 1.0 / WINDOW
    y = np.empty(2)
    q = np.empty(3)
    for b in range(e.shape[0]):
        Sb, Lb = S[b], L[b]
        if first:
            continue
        if alarms[b] != Sb[ALARMS]:  # the input gains are being relearnt: no choice for a while
            Sb[ALARMS], Sb[QUIET] = alarms[b], QUIET_STEPS
        pose_of(e[b], r, q)
        dq = max(abs(q[0] - q_prev[b, 0]), abs(q[1] - q_prev[b, 1]), abs(q[2] - q_prev[b, 2]))
        if dq < HELD:  # the stream stalled: the measurement is one step older
            worst = Lb.min()
            for d in range(D, 0, -1):
                Lb[d] = Lb[d - 1]
            Lb[0] = worst - THRESHOLD
            Sb[DELAY] = min(Sb[DELAY] + 1.0, D)
            continue
        motion(q, q_prev[b], T, y)
        Sb[N] += 1.0
        if Sb[N] < 2.0:  # the commands' history is not yet a step deep
            continue
        cur = int(Sb[DELAY])
        w = 1.0 / min(Sb[N] - 1.0, S2_WINDOW)
        for ch in range(2):
            rc = y[ch] - g[b, ch] * hist[b, ch, cur] - M[b, ch, cur]
            s2 = Sb[S2 + ch]
            r2 = rc * rc if Sb[N] == 2.0 else min(rc * rc, 25.0 * s2)
            Sb[S2 + ch] = s2 + (r2 - s2) * w
        for d in range(D + 1):
            ll = 0.0
            for ch in range(2):
                rc = y[ch] - g[b, ch] * hist[b, ch, d]
                dev = rc - M[b, ch, d]
                M[b, ch, d] += dev / MEAN_WINDOW
                ll += min(dev * dev / max(Sb[S2 + ch], 1e-12), CAP)
            Lb[d] = a * Lb[d] - 0.5 * ll
        Sb[QUIET] = max(Sb[QUIET] - 1.0, 0.0)
        if Sb[N] > WARMUP and Sb[QUIET] == 0.0:
            best = cur
            for d in range(0 if cur == 0 else 1, D + 1):  # 0 only while it is the choice (module doc)
                if Lb[d] > Lb[best]:
                    best = d
            if Lb[best] - Lb[cur] > (FROM_ZERO if cur == 0 else THRESHOLD):
                Sb[DELAY] = best


class DelayBank:
    """The batched state of the bank for B seeds and delays up to D steps."""

    def __init__(self, B: int, T: float, D: int) -> None:
        self.T = float(T)
        self.S = np.zeros((B, WIDTH))
        self.L = np.zeros((B, D + 1))
        self.M = np.zeros((B, 2, D + 1))
        self._g, self._alarms = np.ones((B, 2)), np.zeros(B)
        # load (or compile) the kernel now, not mid-run: zero seeds
        bank_step(np.zeros((0, 3)), np.zeros(5), True, np.zeros((0, 2, D + 2)), np.zeros((0, 3)), self._g[:0],
                  self._alarms[:0], self.S[:0], self.L[:0], self.M[:0], self.T)  # fmt: skip

    def update(
        self,
        e: np.ndarray,
        r: np.ndarray,
        first: bool,
        hist: np.ndarray,
        q_prev: np.ndarray,
        gains: np.ndarray,
        alarms: np.ndarray,
    ) -> np.ndarray:
        """The delay chosen per seed (B,), in steps, after the measurement e; ``gains`` (B, 2) g_v, g_omega
        and ``alarms`` (B,) of the input model."""
        self._g[:], self._alarms[:] = gains, alarms
        bank_step(e, r, first, hist, q_prev, self._g, self._alarms, self.S, self.L, self.M, self.T)
        return self.S[:, DELAY]

    @property
    def delay(self) -> np.ndarray:
        return self.S[:, DELAY]
