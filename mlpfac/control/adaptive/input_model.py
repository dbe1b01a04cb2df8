"""The input model: what a command does to the robot, learned from the motion it measures.

On a robot with dynamics the one-step map of the error model (4) is not f + G u_k: the velocity
realised over a step is a filtered, delayed and scaled copy of the commands sent, and in closed loop
the networks cannot tell that scale from f (their inputs almost determine v). This part learns
the scale alone, per channel c in {v, omega}: the input gain g_c of

    y_c,k = g_c u_c,k-2 + noise,

with y the velocity realised between the poses measured at k - 1 and k (the chord over T at the
mid heading, and the heading increment over T). The newest command, u_{k-1}, is left out on
purpose: it was computed from the pose noise n_{k-1} that y_k also holds (as -n_{k-1} / T), and in
closed loop that correlation biases a regression on it upwards; u_{k-2} is uncorrelated with the noise of y_k and on a smooth path carries the same gain.
g is estimated by recursive least squares (forgetting ``input_forgetting``, from g = 1, the
kinematic model (7)) on exponentially windowed sums over about ``WINDOW`` steps,
Y = sum a^m y_k-m and U = sum a^m u_k-2-m: the pose noise of Y nearly telescopes to that of the
last pose, and a delay or an oscillation of the loop shifts the sums by a few steps out of fifty,
where a per-step regression would read a lag as a gain.

The law's u_k is what the kinematic model (7) must receive, so the command sent is u_k / g (kept
within ``GAINS``): the IK given the true wheel radius, or the law (35) redesigned for the true
period, when g is right.

Re-adaptation by detection instead of forgetting alone: per channel, the normalised one-step
innovation nu^2 = (y - g u_{k-2})^2 / r_hat (r_hat a running mean of its square) has mean about 1
while the model holds; a CUSUM s = max(0, s + nu^2 - 2) sums its excess, and when s exceeds
``detect`` the covariance of g is opened back to P0 and the sums start again, so g moves to the
changed plant within a few tenths of a second. A pose held over (a measurement delay growing) is no
new motion: skipped.

Two options for a faster re-adaptation (both 0, off, but in ``adaptive-real``). ``detect_mean > 0``:
an alarm also when a channel's leaky sum of the innovations over ``MEAN_WINDOW`` steps,
m = sum a^j i_k-j, has m^2 above ``detect_mean`` times its running mean (over ``R_WINDOW`` steps):
the pose noise in the innovations telescopes in m, so a persistent bias (a gain that is off) shows
in m within a few steps, where nu^2 must first outgrow the noise of one step (the cart's smaller
wheel-radius change was not detected by the CUSUM on every seed). ``input_P_alarm > 0``: at an
alarm, a channel whose m shows the change by that test (its running mean updated by this step) has its covariance reopened to
``input_P_alarm`` instead of P0 (then capped at P0 again once it has shrunk below it); a channel that
does not show it yet at the alarm gets ``input_P_alarm`` as soon as it does within ``HOLDOFF`` steps.
Opening both channels to it regardless made the heading rate's gain run away on the eight (omega
little excited there, the robot's lag read as a gain); the speed's channel alone was slower on the
cart, whose heading rate matters. Only an alarm after ``QUIET`` samples without one opens a channel
so (a step change, not a slip that keeps raising alarms: on eight-friction every half second), and
with ``input_P_alarm`` the gains are kept within ``GAINS`` (the range the command is divided by).

The delay (``input_delay = D > 0``): the measured pose may be d <= D steps old. d is found from the
correlations of the heading-rate increments with the command increments j steps back (:func:`_delay`),
and the law is then given the error (2) of the measured pose moved over the last d commands sent,
a unicycle step at g u each (:func:`_predict`, a Smith predictor); with d = 0 it is given e itself.

Batch-first and compiled as :mod:`mlpfac.control.adaptive.kernels`: a seed's arithmetic does not depend on the batch.
"""

from __future__ import annotations

import math

import numpy as np

from mlpfac.control.adaptive.delay_bank import HELD, DelayBank, motion, pose_of
from mlpfac.elementary import cos, sin
from mlpfac.jit import kernel

# columns of the per-seed state S, per channel c (v: +0, omega: +1)
Y, U, G, P, R, CUSUM = 0, 2, 4, 6, 8, 10
N, HOLD, ALARMS = 12, 13, 14
DY, DELAY, NC, CAND, RUN = 15, 16, 17, 18, 19  # last y_omega, delay found, samples, candidate, its run
M, RM, ARM = 20, 22, 24  # per channel: the leaky sum of the innovations, the running mean of its square, armed
SINCE = 26  # samples since the last alarm
WIDTH = 27
CORR_WINDOW = 200  # steps in the exponential window of the delay's correlations
CORR_MIN = 100  # samples in the correlations before they decide
ACCEPT = 2.0  # a lag j >= 2 is the delay when its step C_j - C_j-1 exceeds this multiple of |C_0|
SWITCH = 1.25  # and a new choice must beat the current one's by this factor (hysteresis)
PERSIST = 100  # steps a new choice must stay the best before it is taken
WINDOW = 50  # steps in the exponential window of the sums: a = 1 - 1 / WINDOW
DRIFT = 2.0  # the CUSUM's allowance: nu^2 has mean about 1 while the model holds
R_WINDOW = 1000  # steps in the running mean of the innovation's square (the noise variance, learned)
WARMUP = 100  # steps before the first alarm
HOLDOFF = 50  # steps between alarms
QUIET = 200  # samples without an alarm before one may open a channel to input_P_alarm (a step, not a drift)
MEAN_WINDOW = 20  # steps in the leaky sum of the innovations (``detect_mean``)
GAINS = (0.8, 2.0)  # the input gains sent are kept within these (the law divides by them)


@kernel()
def _biased(Sb, c, detect_mean):
    """Channel c's leaky sum of the innovations shows a bias (``detect_mean``'s test)."""
    return detect_mean > 0.0 and Sb[M + c] * Sb[M + c] > detect_mean * max(Sb[RM + c], 1e-12)


@kernel()
def _delay(Sb, C, h, y_w, ac):
    """The delay from the correlations C_j of the omega channel's increments, Delta y_omega,k with
    Delta u_omega,k-1-j = u_k-1-j - u_k-2-j: the closed loop's pose noise makes the commands' increments
    nearly white, so C_j is the increment response: for a delay d it steps from negative at d - 1 to
    positive at d (measured on the robot: C_d - C_d-1 = 2.7-5.6 |C_0| with 30 ms, at most 0.9 |C_0|
    after the payload, actuator, friction and drive changes, whose slower response spreads over the
    lags without a step). Lags 0 and 1 share pose noise with Delta y_k (biased); a lag j >= 2 is taken
    when C_j - C_j-1 exceeds ACCEPT |C_0|, after CORR_MIN samples since the last alarm (which restarts
    them), and replaces the current choice only when SWITCH times larger for PERSIST steps in a row."""
    if Sb[N] > 1.0:
        dy = y_w - Sb[DY]
        for j in range(C.shape[0]):
            C[j] = ac * C[j] + dy * (h[j] - h[j + 1])
        Sb[NC] += 1.0
        if Sb[NC] >= CORR_MIN:
            cur = int(Sb[DELAY])
            best, arg = ACCEPT * abs(C[0]), 0  # no delay stands for itself
            for j in range(2, C.shape[0]):
                if C[j] - C[j - 1] > best:
                    best, arg = C[j] - C[j - 1], j
            now = C[cur] - C[cur - 1] if cur > 0 else ACCEPT * abs(C[0])
            cand = arg if arg != cur and best > SWITCH * now else cur
            Sb[RUN] = Sb[RUN] + 1.0 if cand == Sb[CAND] else 0.0
            Sb[CAND] = cand
            if cand != cur and Sb[RUN] >= PERSIST:
                Sb[DELAY] = cand
    Sb[DY] = y_w


@kernel()
def _predict(q, r, h, Sb, d, T, out):
    """The error (2) to r of the pose q moved over the last d commands sent (h, newest first), each a
    unicycle step at g u: the measured pose is d steps old (a Smith predictor)."""
    x, y, th = q[0], q[1], q[2]
    for j in range(d - 1, -1, -1):
        v, om = Sb[G] * h[0, j], Sb[G + 1] * h[1, j]
        mid = th + 0.5 * T * om
        x += T * v * cos(mid)
        y += T * v * sin(mid)
        th += T * om
    c, s = cos(th), sin(th)
    dx, dy = r[0] - x, r[1] - y
    out[0] = c * dx + s * dy
    out[1] = -s * dx + c * dy
    out[2] = math.pi - ((math.pi - (r[2] - th)) % (2.0 * math.pi))


@kernel("void(f8[:, ::1], f8[::1], b1, f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1])")
def observe(e, r, first, hist, q_prev, S, C, e_hat, params):
    """Update the gains (and the delay) with the motion measured since the last step; e_hat the
    error (2) of the pose predicted over the delay (e itself when it is 0).

    e (B, 3), r (>= 3,); hist (B, 2, H) the commands sent, newest first (H = max(2, D + 2));
    q_prev (B, 3) the last measured pose; S (B, WIDTH) the scalars (columns above); C (B, D + 1)
    the correlations of the delay. params = (T, P0, forgetting, detect, held, P_alarm, detect_mean):
    a pose within ``held`` of the last one (0: equal to it) is the same measurement held over;
    P_alarm, detect_mean: 0 off (the module docstring).
    """
    T, P0, forgetting, detect, tol = params[0], params[1], params[2], params[3], params[4]
    P_alarm, detect_mean = params[5], params[6]
    am = 1.0 - 1.0 / MEAN_WINDOW
    D = C.shape[1] - 1
    a = 1.0 - 1.0 / WINDOW
    ac = 1.0 - 1.0 / CORR_WINDOW
    q = np.empty(3)
    y = np.empty(2)
    for b in range(e.shape[0]):
        Sb = S[b]
        pose_of(e[b], r, q)
        held = max(abs(q[0] - q_prev[b, 0]), abs(q[1] - q_prev[b, 1]), abs(q[2] - q_prev[b, 2])) <= tol
        if not first and not held:
            motion(q, q_prev[b], T, y)
            Sb[N] += 1.0
            Sb[SINCE] += 1.0
            w = 1.0 / min(Sb[N], R_WINDOW)
            alarm = False
            for c in range(2):
                u2 = hist[b, c, 1]
                i = y[c] - Sb[G + c] * u2  # the one-step innovation
                rc = Sb[R + c]
                i2 = i * i if Sb[N] == 1.0 else min(i * i, 25.0 * rc)
                Sb[R + c] = rc + (i2 - rc) * w
                if Sb[N] > 1.0:
                    Sb[CUSUM + c] = max(0.0, Sb[CUSUM + c] + i * i / max(rc, 1e-12) - DRIFT)
                alarm = alarm or Sb[CUSUM + c] > detect
                if detect_mean > 0.0:  # a persistent bias: the leaky sum of the innovations, normalised
                    mc = am * Sb[M + c] + i
                    rm = Sb[RM + c]
                    m2 = mc * mc if Sb[N] == 1.0 else min(mc * mc, 25.0 * rm)
                    Sb[M + c], Sb[RM + c] = mc, rm + (m2 - rm) * w
                    if Sb[N] > MEAN_WINDOW:
                        alarm = alarm or mc * mc > detect_mean * max(rm, 1e-12)
                # RLS on the windowed sums
                Yc = a * Sb[Y + c] + y[c]
                Uc = a * Sb[U + c] + u2
                Sb[Y + c], Sb[U + c] = Yc, Uc
                Pc = Sb[P + c]
                s = Uc * Pc * Uc + max(Sb[R + c], 1e-12)
                Sb[G + c] += Pc * Uc * (Yc - Sb[G + c] * Uc) / s
                if P_alarm > 0.0:  # the gain kept within those the command may be divided by; P
                    Sb[G + c] = min(max(Sb[G + c], GAINS[0]), GAINS[1])  # reopened above P0 (below)
                    Sb[P + c] = min((Pc - Pc * Uc * Uc * Pc / s) / forgetting, max(P0, Pc))  # shrinks to it
                else:
                    Sb[P + c] = min((Pc - Pc * Uc * Uc * Pc / s) / forgetting, P0)
            if Sb[HOLD] > 0.0 or Sb[N] <= WARMUP:
                Sb[HOLD] = max(Sb[HOLD] - 1.0, 0.0)
                Sb[CUSUM], Sb[CUSUM + 1] = 0.0, 0.0
                for c in range(2):  # a channel whose bias shows within HOLDOFF steps of the alarm: P_alarm
                    if Sb[ARM + c] > 0.0 and _biased(Sb, c, detect_mean):
                        Sb[P + c] = max(Sb[P + c], P_alarm)
                        Sb[ARM + c] = 0.0
                    if Sb[HOLD] == 0.0:
                        Sb[ARM + c] = 0.0
            elif detect > 0.0 and alarm:  # open the covariance, and start the sums again from the change
                fresh = P_alarm > 0.0 and Sb[SINCE] > QUIET
                for c in range(2):  # to P_alarm where the channel's leaky sum shows the change, else P0
                    boost = fresh and _biased(Sb, c, detect_mean)
                    Sb[P + c] = P_alarm if boost else P0
                    Sb[ARM + c] = 1.0 if fresh and not boost else 0.0
                Sb[SINCE] = 0.0
                Sb[M], Sb[M + 1] = 0.0, 0.0
                Sb[Y], Sb[Y + 1], Sb[U], Sb[U + 1] = 0.0, 0.0, 0.0, 0.0
                Sb[HOLD], Sb[CUSUM], Sb[CUSUM + 1], Sb[ALARMS] = HOLDOFF, 0.0, 0.0, Sb[ALARMS] + 1.0
                Sb[NC] = 0.0  # the delay's correlations start again too
                for j in range(D + 1):
                    C[b, j] = 0.0
            if D > 0:
                _delay(Sb, C[b], hist[b, 1], y[1], ac)
        q_prev[b, 0], q_prev[b, 1], q_prev[b, 2] = q[0], q[1], q[2]
        d = int(Sb[DELAY])
        if d == 0:
            e_hat[b, 0], e_hat[b, 1], e_hat[b, 2] = e[b, 0], e[b, 1], e[b, 2]
        else:
            _predict(q, r, hist[b], Sb, d, T, e_hat[b])


@kernel("void(f8[:, ::1], b1, f8[:, ::1], f8[:, :, ::1], f8[:, ::1])")
def command(u, gains, S, hist, out):
    """The command sent, u / g per channel (g within GAINS) with ``gains`` (else u), and the history pushed."""
    lo, hi = GAINS
    for b in range(u.shape[0]):
        for c in range(2):
            out[b, c] = u[b, c] / min(max(S[b, G + c], lo), hi) if gains else u[b, c]
            h = hist[b, c]
            for j in range(h.shape[0] - 1, 0, -1):
                h[j] = h[j - 1]
            h[0] = out[b, c]


class InputModel:
    """The batched state of the input model for B seeds, and its two steps: ``observe`` before the
    law, ``command`` after it (the command sent)."""

    def __init__(
        self,
        B: int,
        T: float,
        gains: bool,
        delay: int,
        P0: float,
        forgetting: float,
        detect: float,
        bank: bool = False,
        P_alarm: float = 0.0,
        detect_mean: float = 0.0,
    ) -> None:
        """``bank``: the delay is found by :class:`~mlpfac.control.adaptive.delay_bank.DelayBank` instead of the correlations;
        ``P_alarm``, ``detect_mean`` (0: off): see the module docstring."""
        self.gains = gains
        self.hist = np.zeros((B, 2, max(2, delay + 2)))
        self.C = np.zeros((B, 1 if bank else delay + 1))  # one column: no correlation search in the kernel
        self.bank = DelayBank(B, T, delay) if bank and delay > 0 else None
        self.e_hat = np.zeros((B, 3))
        self.q_prev = np.zeros((B, 3))
        self.S = np.zeros((B, WIDTH))
        self.S[:, G : G + 2] = 1.0
        self.S[:, P : P + 2] = P0
        self.u = np.zeros((B, 2))
        # with the bank, a held pose is told apart from a new one as the bank does (rebuilt from e and r)
        self.params = np.array([T, P0, forgetting, detect, HELD if bank else 0.0, P_alarm, detect_mean], dtype=float)
        z = (self.hist, self.q_prev, self.S, self.C, self.e_hat)  # load (or compile) now, not mid-run
        observe(np.zeros((0, 3)), np.zeros(5), True, *(x[:0] for x in z), self.params)
        command(self.u[:0], gains, self.S[:0], self.hist[:0], self.u[:0])

    def observe(self, e: np.ndarray, r: np.ndarray, first: bool) -> np.ndarray:
        e, r = np.ascontiguousarray(e, dtype=float), np.ascontiguousarray(r, dtype=float)  # the kernels' types
        if self.bank is not None:  # the delay, into S[:, DELAY], before the kernel predicts over it
            self.S[:, DELAY] = self.bank.update(
                e, r, first, self.hist, self.q_prev, self.S[:, G : G + 2], self.S[:, ALARMS]
            )
        observe(e, r, first, self.hist, self.q_prev, self.S, self.C, self.e_hat, self.params)
        return self.e_hat

    def command(self, u: np.ndarray) -> np.ndarray:
        command(np.ascontiguousarray(u, dtype=float), self.gains, self.S, self.hist, self.u)
        return self.u

    def telemetry(self) -> dict[str, np.ndarray]:
        """Per seed: the input gains (g_v, g_omega), the delay found (steps) and the alarms so far."""
        return {"input_gain": self.S[:, G : G + 2], "delay_steps": self.S[:, DELAY], "alarms": self.S[:, ALARMS]}
