"""The robot's own estimate of its pose, compiled into the plant's control step: wheel odometry
(encoder angles, quantized to counts), a gyro's heading rate, and an EKF that fuses delayed
absolute fixes (:mod:`mlpfac.plants.sensors.sensing` says what each key does; docs/equations.md writes the
equations with these symbols).

State x = (x, y, theta, s_l, s_r): the pose of the pose frame and the scale factors of the two
wheels' radius (the true rolling radius over the nominal one, r), covariance P (5 x 5). Each
control step, with the encoders' increments (dphi_l, dphi_r) and the gyro's heading increment
dtheta_g, the midpoint ("second-order") prediction

    d_l = s_l r dphi_l,   d_r = s_r r dphi_r,   d = (d_l + d_r) / 2,
    dtheta = (d_r - d_l) / b          (or dtheta_g with the gyro),
    x += d cos(theta + dtheta / 2),  y += d sin(theta + dtheta / 2),  theta += dtheta,

P = F P F' + G N G' + Q dt. A fix z = (x, y, theta) + noise, taken at step j, arrives ``latency``
later at step k: the state stored at step j (ring buffer) is updated (H = [I_3 0], the heading's
innovation wrapped), and the steps j+1 .. k are predicted again from their stored increments.
``"odometry"`` is the prediction alone, the scale factors held at 1.

Everything is in one float array ``s`` (its layout below): the estimator's settings, its state,
and the ring buffer of (state, covariance, increments, fix) a step. Plain arithmetic only: the
bits do not depend on the machine.
"""

from __future__ import annotations

import math

import numpy as np

from mlpfac.elementary import cos, sin
from mlpfac.jit import kernel

# s: settings (written at reset)
O_MODE, O_GYRO, O_QL, O_QR, O_GADR, O_Q, O_OFFL, O_OFFR = range(8)  # mode 1 odometry, 2 fused; encoders' qpos
O_GNOISE, O_GBIAS, O_RATE, O_LAT, O_FNM, O_FNR, O_R, O_B = range(8, 16)  # gyro; fixes; nominal radius, track
O_SL, O_SR = 16, 17  # forward sign of each wheel's hinge
O_SLIP, O_QP, O_QTH, O_QS, O_CAP = 18, 19, 20, 21, 22  # process noise; ring slots
# s: what changes
O_K, O_CL, O_CR, O_GPREV, O_NEXT, O_PEND, O_TIME = range(23, 30)  # step; counts; gyro; next fix; fix in flight
O_X = 30  # (5,) the state now
O_P = 35  # (25,) its covariance, row-major
O_RING = 60
# a ring slot: state, covariance, increments (dphi_l, dphi_r, dtheta_g, dt), fix (flag, z (3), time taken)
R_X, R_P, R_INC, R_FIX, R_W = 0, 5, 30, 34, 39
NX = 5
# one telemetry row beside the plant's: the motion sensed (v, omega, wheel_l, wheel_r), the fix that
# arrived (x, y, theta, time taken; NaN: none), the estimate's standard deviations (x, y, theta), the
# wheels' scale factors
SENSE_TELEMETRY = (("sensed", 4), ("fix", 4), ("estimate_std", 3), ("odometry_scale", 2))
N_SENSE_TELE = sum(w for _, w in SENSE_TELEMETRY)
N_SENSE_DRAWS = 4  # a step's standard normals: gyro noise, fix noise (x, y, theta)
EPS_T = 1e-9  # s: times compared on the physics clock


@kernel()
def wrap(a):
    """a in [-pi, pi)."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


@kernel()
def _column(M, j, dd, dth, d, c, sn):
    """Column j of a Jacobian of the prediction: x, y, theta's derivatives by a quantity that moves d
    by dd and dtheta by dth."""
    M[0, j] = dd * c - d * sn * 0.5 * dth
    M[1, j] = dd * sn + d * c * 0.5 * dth
    M[2, j] = dth


@kernel("void(f8[::1], f8[::1], f8, f8, i8, f8[::1], f8[:, ::1], f8[:, ::1])")
def motion(x, u, r, b, gyro, out, F, G):
    """The prediction f(x, u) over one step into ``out`` (5,), and its Jacobians F = df/dx (5, 5),
    G = df/du (5, 3); u = (dphi_l, dphi_r, dtheta_g) the encoders' increments (rad) and the gyro's
    heading increment (rad, used with ``gyro``)."""
    sl, sr, dpl, dpr = x[3], x[4], u[0], u[1]
    d = 0.5 * (sl * r * dpl + sr * r * dpr)
    if gyro:
        dth, th_sl, th_sr, th_ul, th_ur, th_g = u[2], 0.0, 0.0, 0.0, 0.0, 1.0
    else:
        dth = (sr * r * dpr - sl * r * dpl) / b
        th_sl, th_sr, th_ul, th_ur, th_g = -r * dpl / b, r * dpr / b, -sl * r / b, sr * r / b, 0.0
    m = x[2] + 0.5 * dth
    c, sn = cos(m), sin(m)
    out[0], out[1], out[2], out[3], out[4] = x[0] + d * c, x[1] + d * sn, x[2] + dth, sl, sr
    for i in range(NX):
        for j in range(NX):
            F[i, j] = 1.0 if i == j else 0.0
    F[0, 2], F[1, 2] = -d * sn, d * c
    # a quantity q moves x by dd c - d sn dtheta_q / 2, y by dd sn + d c dtheta_q / 2, theta by dtheta_q
    # (dd, dtheta_q: d's and dtheta's derivatives by q)
    for i in range(NX):
        for j in range(3):
            G[i, j] = 0.0
    _column(F, 3, 0.5 * r * dpl, th_sl, d, c, sn)
    _column(F, 4, 0.5 * r * dpr, th_sr, d, c, sn)
    _column(G, 0, 0.5 * sl * r, th_ul, d, c, sn)
    _column(G, 1, 0.5 * sr * r, th_ur, d, c, sn)
    _column(G, 2, 0.0, th_g, d, c, sn)


@kernel()
def _predict(s, src, dst, dpl, dpr, dthg, dt, x, u, xn, F, G, N):
    """The state and covariance at ``src`` (offsets of x and P in s) predicted over one step into
    ``dst`` (may be ``src``): x = f(x, u), P = F P F' + G N G' + Q dt. x, u, xn, F, G, N: work arrays."""
    for i in range(NX):
        x[i] = s[src + i]
    u[0], u[1], u[2] = dpl, dpr, dthg
    motion(x, u, s[O_R], s[O_B], int(s[O_GYRO]), xn, F, G)
    q = s[O_Q]
    base = q * q / 6.0  # an increment's two rounding errors, each uniform over a count
    sl, sr, sg = s[O_SLIP] * dpl, s[O_SLIP] * dpr, s[O_SLIP] * dthg
    N[0] = base + sl * sl
    N[1] = base + sr * sr
    g = s[O_GNOISE]
    N[2] = dt * dt * (0.5 * g * g + s[O_GBIAS] * s[O_GBIAS]) + sg * sg
    po = src + NX
    FP = np.empty((NX, NX))
    for i in range(NX):
        for j in range(NX):
            acc = 0.0
            for m in range(NX):
                acc += F[i, m] * s[po + m * NX + j]
            FP[i, j] = acc
    qd = (s[O_QP] * dt, s[O_QP] * dt, s[O_QTH] * dt, s[O_QS] * dt, s[O_QS] * dt)
    for i in range(NX):
        s[dst + i] = xn[i]
    for i in range(NX):
        for j in range(i, NX):
            acc = 0.0
            for m in range(NX):
                acc += FP[i, m] * F[j, m]
            for m in range(3):
                acc += G[i, m] * N[m] * G[j, m]
            if i == j:
                acc += qd[i]
            s[dst + NX + i * NX + j] = acc
            s[dst + NX + j * NX + i] = acc


@kernel("void(f8[::1], i8, f8[::1], f8[::1])")
def update(s, at, z, R):
    """The fix z = (x, y, theta) with noise variances R (3,) applied to the state and covariance at
    offset ``at`` of s: S = P_pp + R = L L', W = P_:p L^-T, x += W L^-1 nu, P -= W W' (the heading's
    innovation nu_3 wrapped to [-pi, pi))."""
    po = at + NX
    L = np.zeros((3, 3))
    for i in range(3):
        for j in range(i + 1):
            acc = s[po + i * NX + j] + (R[i] if i == j else 0.0)
            for m in range(j):
                acc -= L[i, m] * L[j, m]
            L[i, j] = math.sqrt(acc) if i == j else acc / L[j, j]
    W = np.empty((NX, 3))
    for i in range(NX):  # W L' = P[:, :3], row by row: L w' = p'
        for j in range(3):
            acc = s[po + i * NX + j]
            for m in range(j):
                acc -= L[j, m] * W[i, m]
            W[i, j] = acc / L[j, j]
    nu = np.empty(3)
    nu[0], nu[1], nu[2] = z[0] - s[at], z[1] - s[at + 1], wrap(z[2] - s[at + 2])
    a = np.empty(3)
    for j in range(3):  # a = L^-1 nu
        acc = nu[j]
        for m in range(j):
            acc -= L[j, m] * a[m]
        a[j] = acc / L[j, j]
    for i in range(NX):
        s[at + i] += W[i, 0] * a[0] + W[i, 1] * a[1] + W[i, 2] * a[2]
    for i in range(NX):
        for j in range(i, NX):
            p = s[po + i * NX + j] - (W[i, 0] * W[j, 0] + W[i, 1] * W[j, 1] + W[i, 2] * W[j, 2])
            s[po + i * NX + j] = p
            s[po + j * NX + i] = p


@kernel()
def _slot(s, k):
    return O_RING + (k % int(s[O_CAP])) * R_W


@kernel()
def _arrivals(s, k, time, tele, o, x, u, xn, F, G, N):
    """The fixes in flight whose latency has passed, oldest first: each applied to the state stored
    at the step it was taken, and the steps since predicted again from their increments."""
    cap = int(s[O_CAP])
    R = np.empty(3)
    R[0] = R[1] = s[O_FNM] * s[O_FNM] + 1e-12  # a fix of no noise still leaves S invertible
    R[2] = s[O_FNR] * s[O_FNR] + 1e-12
    z = np.empty(3)
    while s[O_PEND] >= 0.0:
        j = int(s[O_PEND])
        at = _slot(s, j)
        taken = s[at + R_FIX + 4]
        if time < taken + s[O_LAT] - EPS_T:
            return
        if k - j < cap:  # always: the ring holds a latency's steps
            z[0], z[1], z[2] = s[at + R_FIX + 1], s[at + R_FIX + 2], s[at + R_FIX + 3]
            update(s, at, z, R)
            for i in range(j + 1, k + 1):
                prev, now = _slot(s, i - 1), _slot(s, i)
                inc = now + R_INC
                _predict(s, prev, now, s[inc], s[inc + 1], s[inc + 2], s[inc + 3], x, u, xn, F, G, N)
            last = _slot(s, k)
            for i in range(NX + NX * NX):
                s[O_X + i] = s[last + i]
            tele[o + 4], tele[o + 5], tele[o + 6], tele[o + 7] = z[0], z[1], z[2], taken
        s[O_PEND] = -1.0
        for i in range(j + 1, k + 1):
            if s[_slot(s, i) + R_FIX] == 1.0:
                s[O_PEND] = i
                break


@kernel("void(f8[::1], f8, f8, f8, f8, f8, f8, f8, f8[::1], f8[::1], i8)")
def sense_step(s, phl, phr, rate, time, tx, ty, tth, draw, tele, o):
    """One control step of the estimator: the wheels' forward angles (phl, phr) in rad, the gyro's
    yaw rate (rad/s, before its noise and bias), the physics clock ``time``, the true pose (tx, ty,
    tth) a fix is taken of; ``draw`` (4,) standard normals (gyro noise, fix noise x, y, theta);
    ``tele[o:]`` its telemetry row (SENSE_TELEMETRY). The estimate is s[O_X : O_X + 3] after it."""
    k = int(s[O_K]) + 1
    s[O_K] = k
    q = s[O_Q]
    if q > 0.0:
        cl, cr = math.floor(phl / q + s[O_OFFL]), math.floor(phr / q + s[O_OFFR])
        dpl, dpr = (cl - s[O_CL]) * q, (cr - s[O_CR]) * q
    else:
        cl, cr = phl, phr
        dpl, dpr = cl - s[O_CL], cr - s[O_CR]
    s[O_CL], s[O_CR] = cl, cr
    dt = time - s[O_TIME]
    s[O_TIME] = time
    r, b = s[O_R], s[O_B]
    wl, wr = dpl / dt, dpr / dt
    if s[O_GYRO]:
        g = rate + s[O_GBIAS] + s[O_GNOISE] * draw[0]
        dthg = 0.5 * (s[O_GPREV] + g) * dt  # trapezoid between the control steps' readings
        s[O_GPREV] = g
        omega = g
    else:
        dthg = 0.0
        omega = r * (wr - wl) / b
    x, u, xn = np.empty(NX), np.empty(3), np.empty(NX)
    F, G, N = np.empty((NX, NX)), np.empty((NX, 3)), np.empty(3)
    tele[o], tele[o + 1], tele[o + 2], tele[o + 3] = 0.5 * r * (wl + wr), omega, wl, wr
    for i in range(4, 8):
        tele[o + i] = math.nan
    _predict(s, O_X, O_X, dpl, dpr, dthg, dt, x, u, xn, F, G, N)
    if s[O_MODE] == 2.0:
        at = _slot(s, k)
        for i in range(NX + NX * NX):
            s[at + i] = s[O_X + i]
        s[at + R_INC], s[at + R_INC + 1], s[at + R_INC + 2], s[at + R_INC + 3] = dpl, dpr, dthg, dt
        s[at + R_FIX] = 0.0
        rate_hz = s[O_RATE]
        if time >= s[O_NEXT] / rate_hz - EPS_T:  # a fix of the true pose taken now
            s[at + R_FIX] = 1.0
            s[at + R_FIX + 1] = tx + s[O_FNM] * draw[1]
            s[at + R_FIX + 2] = ty + s[O_FNM] * draw[2]
            s[at + R_FIX + 3] = tth + s[O_FNR] * draw[3]
            s[at + R_FIX + 4] = time
            s[O_NEXT] = math.floor(time * rate_hz + EPS_T) + 1.0
            if s[O_PEND] < 0.0:
                s[O_PEND] = k
        _arrivals(s, k, time, tele, o, x, u, xn, F, G, N)
    for i in range(3):
        tele[o + 8 + i] = math.sqrt(s[O_P + i * NX + i])
    tele[o + 11], tele[o + 12] = s[O_X + 3], s[O_X + 4]
