"""``adaptive-dynamic``: the paper's networks and EKF moved to the dynamic level (the torque level,
:mod:`mlpfac.control.torque`).

The nominal model of :mod:`mlpfac.dynamics` gives twist' = A0(v) + Bm tau (A0 = -M^-1 (V v + F),
Bm = M^-1 B). What it misses is learned on-line, one control step at a time:

    v_{k+1} - v_k = T (A0(v_k) + Bm tau_k) + NN_f(x_k) + NN_G(x_k) tau_k,

v the measured twist, x_k = (c v_k, c omega_k, 1) the networks' inputs (c = ``INPUT_SCALE``),
NN_f and NN_G the networks (10)-(15) (L_f hidden sigmoids, L_G = 1), their weights z tuned by the
EKF (28)-(32) on the measured change of the twist. The kernels are the paper scheme's own
(:mod:`mlpfac.control.adaptive.kernels`: the hidden layers, the outputs, the Jacobian (19)-(24), the
EKF in short form); they have three outputs, of which the dynamic level uses two: the third is
measured as 0 (it learns to stay there, and changes nothing else). The output weights start at 0,
so the controller starts as ``fierro-lewis``; forgetting and a cap on P keep it learning after a
change (adaptive-best's, :mod:`mlpfac.control.variants`).

The law is ``fierro-lewis``'s backstepping (:mod:`mlpfac.control.dynamic`), certainty equivalent in the
learned model: with (a, alpha) the accelerations Kanayama's velocities and the velocity loop ask,
(T Bm + NN_G) tau = T (a, alpha) - T A0 - NN_f, solved for tau (2 x 2), clamped to the torque limit;
each entry of the learned NN_G is projected within ``GAIN_SHARE`` of the nominal T Bm's (the input
gain's signs kept, its inverse bounded: the projection of adaptive control's input gains).
"""

from __future__ import annotations

import numpy as np

from mlpfac.control.adaptive.kernels import _ekf, _f_G, _hidden, _jacobian
from mlpfac.control.baselines import Stepped
from mlpfac.control.drive import guard, slipping
from mlpfac.control.dynamic import fierro_lewis_step
from mlpfac.dynamics import P_B, P_M11, P_M22, P_R, P_TMAX, accel_of
from mlpfac.jit import kernel, seeds
from mlpfac.normal import normal

LF, LG, NF = 8, 1, 3  # hidden sigmoids of NN_f and NN_G, inputs of NN_f
ALPHA = 3 * LF + NF * LF + 6 * LG + 3 * LG
INPUT_SCALE = 1.0  # x = (c v, c omega, 1)
HIDDEN_STD = 0.3  # initial hidden weights N(0, 0.3^2); the output weights start at 0
P0, R, FORGETTING, P_MAX = 1e-4, 1e-6, 0.999, 1e-4  # EKF: initial P, measurement noise ((m/s)^2), lambda, cap
GAIN_SHARE = 0.5  # the learned input gain NN_G within +-50 % of the nominal T Bm, entry by entry (the law)
N_S = NF + 3 + LF + LG + 6  # per seed: x_f, x_G, phi_f, phi_G, tau_{k-1}, v_{k-1}, 1 once stepped, 1 if it slipped


@kernel(
    "void(f8[:, ::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8, f8[:, ::1], f8[:, :, ::1], "
    "f8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1])"
)
def adaptive_dynamic_step(e, r, r_dot, twist, wheels, p, g, T, z, P, S, H, tau, vc, innov, ekf):
    """One step for B seeds: the EKF update on the change of the twist since the last step, then
    the law, then the drive (:func:`mlpfac.control.drive.guard`, the encoders' ``wheels`` (B, 2)).
    State per seed (in place): z (B, alpha), P (B, alpha, alpha), S (B, N_S); out: tau (the torques
    sent), vc (the velocities Kanayama's law asked) and innov (B, 3); ekf = (R, forgetting, P_max)."""
    B, a = z.shape
    PHt, W = np.empty((3, a)), np.empty((3, a))
    f, G = np.empty(3), np.empty((3, 2))
    Rm = np.zeros((3, 3))
    for j in range(3):
        Rm[j, j] = ekf[0]
    Q = np.zeros((1, 1))
    o = NF + 3 + LF + LG
    fierro_lewis_step(e, r, r_dot, twist, p, g, tau, vc)  # the velocities asked, and the nominal torques
    for b in range(B):
        zb, Sb = z[b], S[b]
        xf, xG, phif, phiG = Sb[0:NF], Sb[NF : NF + 3], Sb[NF + 3 : NF + 3 + LF], Sb[NF + 3 + LF : o]
        v, w = twist[b, 0], twist[b, 1]
        slips = slipping(p, v, w, wheels[b, 0], wheels[b, 1])
        if Sb[o + 4] != 0.0 and not slips and Sb[o + 5] == 0.0:  # (32) on the twist's change, less the nominal model's
            t0, t1, v0, w0 = Sb[o], Sb[o + 1], Sb[o + 2], Sb[o + 3]
            a0, a1 = accel_of(p, v0, w0, t0, t1)
            _f_G(zb, LF, LG, NF, phif, phiG, f, G)
            y0, y1 = (v - v0) - T * a0, (w - w0) - T * a1
            innov[b, 0] = y0 - (f[0] + (G[0, 0] * t0 + G[0, 1] * t1))
            innov[b, 1] = y1 - (f[1] + (G[1, 0] * t0 + G[1, 1] * t1))
            innov[b, 2] = 0.0 - (f[2] + (G[2, 0] * t0 + G[2, 1] * t1))
            _jacobian(zb, LF, LG, xf, xG, phif, phiG, Sb[o : o + 2], H[b])
            _ekf(zb, P[b], innov[b], H[b], Rm, ekf[1], Q, False, ekf[2], PHt, W)
        elif Sb[o + 4] != 0.0:  # a wheel slipped: the rolling model's error is not there to learn
            innov[b, 0], innov[b, 1], innov[b, 2] = 0.0, 0.0, 0.0
        xf[0], xf[1], xf[2] = INPUT_SCALE * v, INPUT_SCALE * w, 1.0
        xG[0], xG[1], xG[2] = xf[0], xf[1], 1.0
        _hidden(zb, LF, LG, xf, xG, phif, phiG)
        _f_G(zb, LF, LG, NF, phif, phiG, f, G)
        # the accelerations asked: the nominal torques' through the nominal model (fierro-lewis's law)
        vdot, wdot = accel_of(p, v, w, tau[b, 0], tau[b, 1])
        c0, c1 = accel_of(p, v, w, 0.0, 0.0)  # A0
        rhs0, rhs1 = T * (vdot - c0) - f[0], T * (wdot - c1) - f[1]
        r_, b_ = p[P_R], p[P_B]
        k11, k22 = T / (r_ * p[P_M11]), T * b_ / (r_ * p[P_M22])
        # (T Bm + NN_G), tau = (tau_l, tau_r), each learned gain projected within GAIN_SHARE of its
        # nominal one: its signs kept, the inverse bounded (det >= 2 (1 - GAIN_SHARE)^2 k11 k22)
        g00, g01 = GAIN_SHARE * k11, GAIN_SHARE * k22
        m00 = k11 + min(max(G[0, 0], -g00), g00)
        m01 = k11 + min(max(G[0, 1], -g00), g00)
        m10 = -k22 + min(max(G[1, 0], -g01), g01)
        m11 = k22 + min(max(G[1, 1], -g01), g01)
        det = m00 * m11 - m01 * m10
        if abs(det) > 1e-3 * abs(k11 * k22):
            tl = (m11 * rhs0 - m01 * rhs1) / det
            tr = (m00 * rhs1 - m10 * rhs0) / det
            tmax = p[P_TMAX]
            tau[b, 0] = min(max(tl, -tmax), tmax)
            tau[b, 1] = min(max(tr, -tmax), tmax)
        tau[b, 0], tau[b, 1] = guard(p, v, w, wheels[b, 0], wheels[b, 1], tau[b, 0], tau[b, 1])  # the drive's
        Sb[o], Sb[o + 1], Sb[o + 2], Sb[o + 3], Sb[o + 4] = tau[b, 0], tau[b, 1], v, w, 1.0
        Sb[o + 5] = 1.0 if slips else 0.0


class AdaptiveDynamic(Stepped):
    """``adaptive-dynamic``: ``fierro-lewis`` on a dynamic model whose error NN_f, NN_G learn on-line."""

    name = "adaptive-dynamic"
    level = "torque"
    labels: dict[str, list[str]] = {"vc": ["v_c", "omega_c"], "innov": ["v", "omega", "unused"]}

    def __init__(self, robot, T: float, gains: tuple[float, float, float], limits: tuple[float, float]) -> None:
        from mlpfac.control.dynamic import VELOCITY_SHARE

        self.T, self.robot = float(T), robot
        self.p = robot.packed()
        self.g = np.array([*gains, VELOCITY_SHARE / self.T, *limits], dtype=float)
        self.ekf = np.array([R, FORGETTING, P_MAX])

    def reset(self, rng) -> None:
        rngs, self.single = seeds(rng)
        B = len(rngs)
        self.z = np.zeros((B, ALPHA))
        hidden = np.zeros(ALPHA, dtype=bool)
        hidden[3 * LF : 3 * LF + NF * LF] = True
        hidden[3 * LF + NF * LF + 6 * LG :] = True
        for b, g in enumerate(rngs):
            self.z[b, hidden] = normal(g, 0.0, HIDDEN_STD, int(hidden.sum()))
        self.P = np.zeros((B, ALPHA, ALPHA))
        for b in range(B):
            self.P[b][np.diag_indices(ALPHA)] = P0
        self.S, self.H = np.zeros((B, N_S)), np.zeros((B, 3, ALPHA))
        self._tau, self._vc, self._innov = np.zeros((B, 2)), np.zeros((B, 2)), np.zeros((B, 3))
        one = (lambda x: x[0]) if self.single else (lambda x: x)
        self._tele = {"vc": one(self._vc), "innov": one(self._innov), "z": one(self.z)}
        adaptive_dynamic_step(
            np.zeros((0, 3)),
            np.ones(5),
            np.zeros(2),
            np.zeros((0, 2)),
            np.zeros((0, 2)),
            self.p,
            self.g,
            self.T,
            self.z[:0],
            self.P[:0],
            self.S[:0],
            self.H[:0],
            self._tau[:0],
            self._vc[:0],
            self._innov[:0],
            self.ekf,
        )  # fmt: skip  (the kernel loaded before the run)

    def step(self, obs) -> np.ndarray:
        e = np.ascontiguousarray(obs.e, dtype=float).reshape(-1, 3)
        tw = np.ascontiguousarray(obs.twist, dtype=float).reshape(-1, 2)
        wheels = np.ascontiguousarray(obs.wheel_speeds, dtype=float).reshape(-1, 2)
        r = np.ascontiguousarray(obs.r, dtype=float).reshape(-1)
        r_dot = np.ascontiguousarray(obs.r_dot, dtype=float).reshape(-1)
        adaptive_dynamic_step(e, r, r_dot, tw, wheels, self.p, self.g, self.T, self.z, self.P, self.S, self.H,
                              self._tau, self._vc, self._innov, self.ekf)  # fmt: skip
        return self._tau[0].copy() if self.single else self._tau

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return self._tele
