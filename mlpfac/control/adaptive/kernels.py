"""Compiled kernels of the adaptive controller's hot path, batch-first: the networks (10)-(15) and
their closed-form Jacobian (19)-(24), the EKF update (29)-(32), the law (35) with the corrected
(36) (:func:`mlpfac.control.law._law`), and the adaptive step made of them. The baseline laws are
in :mod:`mlpfac.control.law`, the error (2) and the kinematic plant (7) in :mod:`mlpfac.model`.

Every kernel takes a leading batch dimension B and loops over it inside, one seed after another,
so a seed's arithmetic does not depend on B or on the other seeds: a seed in a batch of 64 gets
the same bits as the same seed run alone (B = 1). They are built when mlpfac is installed, or
compiled by numba on first use (:mod:`mlpfac.jit`). With ``error_model="numpy"`` a division by
zero gives inf or NaN as numpy does: a diverging run is detected by the runner, not by an
exception here.

Weight layout (16)-(18), as :mod:`mlpfac.control.adaptive.networks`: z = [W_f (3, L_f), S_f (L_f, n_f), W_G (3, 2, L_G),
S_G (L_G, 3)], row-major blocks.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from mlpfac.control.law import _law
from mlpfac.elementary import cos, sin, tanh
from mlpfac.jit import kernel


@kernel()
def _sigmoid(a):
    return 0.5 * (1.0 + tanh(0.5 * a))


@kernel("void(f8[::1], f8[::1])")
def sigmoids(a, out):
    """Eqs. (10)-(11) on every element of ``a``: the numpy forms' sigmoid, to the kernels' bits."""
    for i in range(a.shape[0]):
        out[i] = _sigmoid(a[i])


@kernel()
def _hidden(z, Lf, LG, xf, xG, phif, phiG):
    """(10)-(11): phi_f (L_f,), phi_G (L_G,) at weights z (alpha,) and inputs x_f (n_f,), x_G (3,)."""
    nf = xf.shape[0]
    o = 3 * Lf
    for i in range(Lf):
        a = 0.0
        for m in range(nf):
            a += z[o + nf * i + m] * xf[m]
        phif[i] = _sigmoid(a)
    o = (3 + nf) * Lf + 6 * LG
    for i in range(LG):
        a = 0.0
        for m in range(3):
            a += z[o + 3 * i + m] * xG[m]
        phiG[i] = _sigmoid(a)


@kernel()
def _f_G(z, Lf, LG, nf, phif, phiG, f, G):
    """(14)-(15): NN_f (3,) and NN_G (3, 2) from the hidden layers (without the residual e); n_f inputs of NN_f."""
    for j in range(3):
        a = 0.0
        for i in range(Lf):
            a += z[j * Lf + i] * phif[i]
        f[j] = a
    o = (3 + nf) * Lf
    for j in range(3):
        for n in range(2):
            a = 0.0
            for i in range(LG):
                a += z[o + (2 * j + n) * LG + i] * phiG[i]
            G[j, n] = a


@kernel()
def _jacobian(z, Lf, LG, xf, xG, phif, phiG, u, H):
    """nabla_h (3, alpha), (19)-(24), at the hidden layers phi_f, phi_G of (z, x_f, x_G); H is all written."""
    alpha, nf = H.shape[1], xf.shape[0]
    for j in range(3):
        for c in range(alpha):
            H[j, c] = 0.0
    o = 3 * Lf
    for i in range(Lf):
        d = phif[i] * (1.0 - phif[i])
        for j in range(3):
            H[j, j * Lf + i] = phif[i]  # (21)
            w = z[j * Lf + i] * d
            for m in range(nf):
                H[j, o + nf * i + m] = w * xf[m]  # (22)
    o2 = (3 + nf) * Lf
    o3 = o2 + 6 * LG
    for i in range(LG):
        d = phiG[i] * (1.0 - phiG[i])
        for j in range(3):
            sigma = 0.0
            for n in range(2):
                H[j, o2 + (2 * j + n) * LG + i] = phiG[i] * u[n]  # (23)
                sigma += z[o2 + (2 * j + n) * LG + i] * u[n]
            w = sigma * d
            for m in range(3):
                H[j, o3 + 3 * i + m] = w * xG[m]  # (24)


@kernel()
def _ekf(z, P, innov, H, R, forgetting, Q, has_Q, P_max, PHt, W):
    """One EKF update (29)-(32) of z (alpha,), P (alpha, alpha) in place, innovation i (3,) given.

    Short form P+ = P - K H P written as P - W'W with W = L^-1 (P H')', S = H P H' + R = L L':
    each element of W'W is the same sum in either order of its indices, so P stays exactly
    symmetric (it is symmetric on entry) with no symmetrisation pass. K i = W' L^-1 i.
    Then forgetting (P /= lambda), process noise (P += Q) and the cap max diag P <= P_max.
    PHt, W: work arrays (3, alpha).
    """
    a = z.shape[0]
    P0, P1, P2 = PHt[0], PHt[1], PHt[2]
    for c in range(a):
        P0[c] = 0.0
        P1[c] = 0.0
        P2[c] = 0.0
    r = 0
    while r + 1 < a:  # (P H')' = H P: P is symmetric, so rows r, r + 1 of P times H[:, r], H[:, r + 1]
        pa, pb = P[r], P[r + 1]
        a0, a1, a2 = H[0, r], H[1, r], H[2, r]
        b0, b1, b2 = H[0, r + 1], H[1, r + 1], H[2, r + 1]
        for c in range(a):
            x, y = pa[c], pb[c]
            P0[c] += x * a0 + y * b0
            P1[c] += x * a1 + y * b1
            P2[c] += x * a2 + y * b2
        r += 2
    if r < a:
        pa = P[r]
        a0, a1, a2 = H[0, r], H[1, r], H[2, r]
        for c in range(a):
            x = pa[c]
            P0[c] += x * a0
            P1[c] += x * a1
            P2[c] += x * a2
    S = np.empty((3, 3))
    for k in range(3):
        for m in range(k + 1):
            s = 0.0
            for c in range(a):
                s += H[k, c] * PHt[m, c]
            S[k, m] = s + 0.5 * (R[k, m] + R[m, k])
    # Cholesky S = L L' (lower triangle of S)
    L00 = math.sqrt(S[0, 0])
    L10 = S[1, 0] / L00
    L20 = S[2, 0] / L00
    L11 = math.sqrt(S[1, 1] - L10 * L10)
    L21 = (S[2, 1] - L20 * L10) / L11
    L22 = math.sqrt(S[2, 2] - L20 * L20 - L21 * L21)
    v0 = innov[0] / L00
    v1 = (innov[1] - L10 * v0) / L11
    v2 = (innov[2] - L20 * v0 - L21 * v1) / L22
    for c in range(a):
        w0 = PHt[0, c] / L00
        w1 = (PHt[1, c] - L10 * w0) / L11
        w2 = (PHt[2, c] - L20 * w0 - L21 * w1) / L22
        W[0, c], W[1, c], W[2, c] = w0, w1, w2
        z[c] += w0 * v0 + w1 * v1 + w2 * v2  # (30): z += K i
    W0, W1, W2 = W[0], W[1], W[2]
    if forgetting == 1.0:
        for r in range(a):  # (29): P -= W'W
            pr = P[r]
            w0, w1, w2 = W0[r], W1[r], W2[r]
            for c in range(a):
                pr[c] = pr[c] - (w0 * W0[c] + w1 * W1[c] + w2 * W2[c])
    else:  # the same pass with forgetting, P /= lambda (one sweep over P, not two)
        inv = 1.0 / forgetting
        for r in range(a):
            pr = P[r]
            w0, w1, w2 = W0[r], W1[r], W2[r]
            for c in range(a):
                pr[c] = (pr[c] - (w0 * W0[c] + w1 * W1[c] + w2 * W2[c])) * inv
    if has_Q:
        for r in range(a):
            pr, qr = P[r], Q[r]
            for c in range(a):
                pr[c] = pr[c] + qr[c]
    peak = 0.0
    for r in range(a):
        if P[r, r] > peak or P[r, r] != P[r, r]:
            peak = P[r, r]
    if P_max < peak:
        s = P_max / peak
        for r in range(a):
            pr = P[r]
            for c in range(a):
                pr[c] *= s


@kernel(
    "void(f8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8, f8[:, ::1], b1, f8, f8[:, ::1])"
)
def ekf_update(z, P, y, h, H, R, forgetting, Q, has_Q, P_max, innov):
    """:func:`_ekf` for a batch: z (B, alpha), P (B, alpha, alpha), y, h (B, 3), H (B, 3, alpha); innov (B, 3) out."""
    a = z.shape[1]
    PHt = np.empty((3, a))
    W = np.empty((3, a))
    for b in range(z.shape[0]):
        for k in range(3):
            innov[b, k] = y[b, k] - h[b, k]  # (32)
        _ekf(z[b], P[b], innov[b], H[b], R, forgetting, Q, has_Q, P_max, PHt, W)


@kernel()
def _law_kanayama(e0, e1, e2, h2, h5, v_r, T, Kx, Ky, Ktheta, v_max, omega_max, u):
    """Kanayama's structure with the estimates of (34) in its feedforward: v = h2 / T + Kx e1,
    omega = h5 / T + v_r (Ky e2 + Ktheta sin e3); with the nominal h2 = T v_r cos e3, h5 = T omega_r
    it is Kanayama's law. Its feedback does not divide by T v_r: pose noise is not amplified as v_r falls."""
    v = h2 / T + Kx * e0
    omega = h5 / T + v_r * (Ky * e1 + Ktheta * sin(e2))
    u[0] = min(max(v, -v_max), v_max)
    u[1] = min(max(omega, -omega_max), omega_max)


# adaptive_step's settings, by position in its ``ints`` and ``params`` (packed by :func:`settings`)
I_LF, I_LG, I_RESIDUAL, I_PRIOR, I_HAS_Q, I_NF, I_KANAYAMA = range(7)
P_C, P_T, P_L1, P_L2, P_L3, P_VMAX, P_OMEGAMAX, P_FORGETTING, P_PMAX, P_KX, P_KY, P_KTHETA = range(12)


def settings(
    L_f: int, L_G: int, residual: bool, prior: bool, has_Q: bool, n_f: int, kanayama: bool,
    c: float, T: float, lambdas: tuple[float, float, float], v_max: float, omega_max: float,
    forgetting: float, P_max: float, kanayama_gains: tuple[float, float, float],
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(ints, params) of :func:`adaptive_step`: the networks' sizes and form, the nominal prior, Q,
    the law's form; the input scale c on the errors, T, the eigenvalues of (36), the limits (inf:
    none), the EKF's forgetting factor and bound on P (inf: none), Kanayama's gains Kx, Ky, Ktheta."""
    ints = np.zeros(7, dtype=np.int64)
    ints[[I_LF, I_LG, I_RESIDUAL, I_PRIOR, I_HAS_Q, I_NF, I_KANAYAMA]] = L_f, L_G, residual, prior, has_Q, n_f, kanayama
    params = np.zeros(12)
    params[[P_C, P_T, P_VMAX, P_OMEGAMAX, P_FORGETTING, P_PMAX]] = c, T, v_max, omega_max, forgetting, P_max
    params[[P_L1, P_L2, P_L3]], params[[P_KX, P_KY, P_KTHETA]] = lambdas, kanayama_gains
    return ints, params


@kernel(
    "void(f8[:, ::1], f8, f8, b1, f8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1], i8[::1], f8[::1], f8[:, ::1], f8[:, ::1])"
)
def adaptive_step(e, v_r, omega_r, first, z, P, S, H, u, innov, h_hat, trace, ints, params, R, Q):
    """One step of the adaptive controller for B seeds, e (B, 3) -> u (B, 2).

    Unless ``first``: the EKF update (28)-(32) with measurement e_k (minus the nominal prediction
    e_nom with ``prior``), model h(x_{k-1}, u_{k-1}, z_k) and its Jacobian from the hidden layers the
    law computed at z_k the step before (same weights, same inputs). Then the inputs (8)-(9), the
    networks at the new z, h_hat (34) (plus the nominal f, G (5)-(6) with ``prior``), the law (35).

    State per seed, updated in place: z (B, alpha), P (B, alpha, alpha) and S (B, 11 + n_f + L_f + L_G) =
    [x_f (n_f), x_G (3), phi_f (L_f), phi_G (L_G), u_{k-1} (2), e_{k-1} (3), e_nom (3)].
    Out: u, innov (32), h_hat (34), trace (trace P); H (B, 3, alpha) the Jacobian of the update.
    ``ints`` and ``params``: the settings, packed by :func:`settings` (n_f = 8: x_f ends with u_{k-1};
    kanayama: :func:`_law_kanayama` instead of (35)).
    """
    Lf, LG, nf = ints[I_LF], ints[I_LG], ints[I_NF]
    residual, prior, has_Q, kanayama = (
        ints[I_RESIDUAL] != 0,
        ints[I_PRIOR] != 0,
        ints[I_HAS_Q] != 0,
        ints[I_KANAYAMA] != 0,
    )
    c, T, l1, l2, l3 = params[P_C], params[P_T], params[P_L1], params[P_L2], params[P_L3]
    v_max, omega_max, forgetting, P_max = params[P_VMAX], params[P_OMEGAMAX], params[P_FORGETTING], params[P_PMAX]
    B, a = z.shape
    PHt = np.empty((3, a))
    W = np.empty((3, a))
    f = np.empty(3)
    G = np.empty((3, 2))
    o = nf + 3 + Lf + LG
    for b in range(B):
        zb, eb, Sb = z[b], e[b], S[b]
        xb, gb, phif, phiG = Sb[0:nf], Sb[nf : nf + 3], Sb[nf + 3 : nf + 3 + Lf], Sb[nf + 3 + Lf : o]
        u_prev, e_prev, e_nom = Sb[o : o + 2], Sb[o + 2 : o + 5], Sb[o + 5 : o + 8]
        if not first:
            _f_G(zb, Lf, LG, nf, phif, phiG, f, G)
            for j in range(3):
                hj = f[j] + (G[j, 0] * u_prev[0] + G[j, 1] * u_prev[1])  # (26)
                if residual:
                    hj += e_prev[j]
                y = eb[j] - e_nom[j] if prior else eb[j]
                if prior and j == 2:
                    y = math.pi - ((math.pi - y) % (2.0 * math.pi))
                innov[b, j] = y - hj  # (32)
            _jacobian(zb, Lf, LG, xb, gb, phif, phiG, u_prev, H[b])
            _ekf(zb, P[b], innov[b], H[b], R, forgetting, Q, has_Q, P_max, PHt, W)
        tr = 0.0
        for i in range(a):
            tr += P[b, i, i]
        trace[b] = tr
        # (8)-(9)
        xb[0], xb[1], xb[2] = c * eb[0], c * eb[1], c * eb[2]
        xb[3], xb[4], xb[5] = v_r, omega_r, 1.0
        if nf == 8:  # the velocity state: the last command
            xb[6], xb[7] = u_prev[0], u_prev[1]
        gb[0], gb[1], gb[2] = xb[0], xb[1], 1.0
        _hidden(zb, Lf, LG, xb, gb, phif, phiG)
        _f_G(zb, Lf, LG, nf, phif, phiG, f, G)
        if residual:
            for j in range(3):
                f[j] += eb[j]
        if prior:  # f = f_nominal + NN_f, G = G_nominal + NN_G, (5)-(6)
            h1 = G[0, 1] + T * eb[1]
            h2 = (f[0] + (eb[0] + T * v_r * cos(eb[2]))) - eb[0]
            h5 = (f[2] + (eb[2] + T * omega_r)) - eb[2]
        else:
            h1, h2, h5 = G[0, 1], f[0] - eb[0], f[2] - eb[2]  # (34)
        h_hat[b, 0], h_hat[b, 1], h_hat[b, 2] = h1, h2, h5
        if kanayama:
            _law_kanayama(
                eb[0],
                eb[1],
                eb[2],
                h2,
                h5,
                v_r,
                T,
                params[P_KX],
                params[P_KY],
                params[P_KTHETA],
                v_max,
                omega_max,
                u[b],
            )
        else:
            _law(eb[0], eb[1], eb[2], h1, h2, h5, v_r, T, l1, l2, l3, v_max, omega_max, u[b])
        if prior:  # the nominal prediction of e_{k+1}: f_true + G_true u, (5)-(6)
            u0, u1 = u[b, 0], u[b, 1]
            e_nom[0] = (eb[0] + T * v_r * cos(eb[2])) + (-T * u0 + T * eb[1] * u1)
            e_nom[1] = (eb[1] + T * v_r * sin(eb[2])) + (-T * eb[0]) * u1
            e_nom[2] = (eb[2] + T * omega_r) + (-T) * u1
        u_prev[0], u_prev[1] = u[b, 0], u[b, 1]
        e_prev[0], e_prev[1], e_prev[2] = eb[0], eb[1], eb[2]


class AdaptiveState(NamedTuple):
    """The arguments of :func:`adaptive_step` but the error and the reference, for the seeds the
    arrays hold (one seed's rows for the compiled closed loop, :mod:`mlpfac.loop.compiled`)."""

    z: np.ndarray
    P: np.ndarray
    S: np.ndarray
    H: np.ndarray
    u: np.ndarray
    innov: np.ndarray
    h_hat: np.ndarray
    trace: np.ndarray
    ints: np.ndarray
    params: np.ndarray
    R: np.ndarray
    Q: np.ndarray


def state_type():
    """numba's type of :class:`AdaptiveState`, as :func:`adaptive_step`'s signature types its fields."""
    from numba import types

    f1, f2, f3 = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1]
    return types.NamedTuple((f2, f3, f2, f3, f2, f2, f2, f1, types.int64[::1], f1, f2, f2), AdaptiveState)


@kernel("void(f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], i8, i8, b1, f8[:, ::1], f8[:, :, ::1])")
def networks_h_jacobian(z, xf, xG, e, u, Lf, LG, residual, h, H):
    """h (B, 3) and nabla_h (B, 3, alpha) of (26), (19)-(24): for tests against :mod:`mlpfac.control.adaptive.networks`."""
    phif = np.empty(Lf)
    phiG = np.empty(LG)
    f = np.empty(3)
    G = np.empty((3, 2))
    for b in range(z.shape[0]):
        _hidden(z[b], Lf, LG, xf[b], xG[b], phif, phiG)
        _f_G(z[b], Lf, LG, xf.shape[1], phif, phiG, f, G)
        for j in range(3):
            h[b, j] = f[j] + (G[j, 0] * u[b, 0] + G[j, 1] * u[b, 1]) + (e[b, j] if residual else 0.0)
        _jacobian(z[b], Lf, LG, xf[b], xG[b], phif, phiG, u[b], H[b])
