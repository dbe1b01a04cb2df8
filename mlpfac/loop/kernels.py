"""Compiled kernels of the rest of the closed loop, batch-first as :mod:`mlpfac.control.adaptive.kernels`: the
tracking error (2), the kinematic plant (7), the baseline laws (Corradini's (35) with the nominal
h of (34), Kanayama's) and :func:`law_step`, which runs either by number in the compiled closed
loop (:mod:`mlpfac.loop.compiled`), and the runner's divergence test.
"""

from __future__ import annotations

import math

from mlpfac.control.adaptive.kernels import _law
from mlpfac.jit import kernel


@kernel("void(f8[:, ::1], f8[::1], f8[:, ::1])")
def tracking_errors(q, r, out):
    """Eq. (2) for poses q (B, 3) and one reference sample r (>= 3,): out (B, 3), e3 wrapped to (-pi, pi]."""
    for b in range(q.shape[0]):
        c, s = math.cos(q[b, 2]), math.sin(q[b, 2])
        dx, dy = r[0] - q[b, 0], r[1] - q[b, 1]
        out[b, 0] = c * dx + s * dy
        out[b, 1] = -s * dx + c * dy
        out[b, 2] = math.pi - ((math.pi - (r[2] - q[b, 2])) % (2.0 * math.pi))


@kernel("void(f8[:, ::1], f8[::1], f8[::1], f8, f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1])")
def kinematic_step(e, r, r_next, Tp, u, noise, e_out, pose_out, h_true):
    """Model (7) for B seeds: e_out = f(e) + G(e) u + noise with the true f, G (5)-(6) at period Tp;
    pose_out the pose whose error (2) to r_next is e_out; h_true (B, 3) the true (34) at e."""
    for b in range(e.shape[0]):
        e0, e1, e2 = e[b, 0], e[b, 1], e[b, 2]
        u0, u1 = u[b, 0], u[b, 1]
        h_true[b, 0], h_true[b, 1], h_true[b, 2] = Tp * e1, Tp * r[3] * math.cos(e2), Tp * r[4]
        n0 = (e0 + Tp * r[3] * math.cos(e2)) + (-Tp * u0 + Tp * e1 * u1) + noise[b, 0]
        n1 = (e1 + Tp * r[3] * math.sin(e2)) + (-Tp * e0) * u1 + noise[b, 1]
        n2 = (e2 + Tp * r[4]) + (-Tp) * u1 + noise[b, 2]
        e_out[b, 0], e_out[b, 1], e_out[b, 2] = n0, n1, n2
        th = r_next[2] - n2
        c, s = math.cos(th), math.sin(th)
        pose_out[b, 0] = r_next[0] - (c * n0 - s * n1)
        pose_out[b, 1] = r_next[1] - (s * n0 + c * n1)
        pose_out[b, 2] = th


@kernel("void(f8[:, ::1], f8, f8, f8, f8, f8, f8, f8, f8, f8[:, ::1], f8[:, ::1])")
def corradini_step(e, v_r, omega_r, T, l1, l2, l3, v_max, omega_max, h_hat, u):
    """(35) given the nominal h1 = T e2, h2 = T v_r cos e3, h5 = T omega_r, for B seeds."""
    for b in range(e.shape[0]):
        e0, e1, e2 = e[b, 0], e[b, 1], e[b, 2]
        h1, h2, h5 = T * e1, T * v_r * math.cos(e2), T * omega_r
        h_hat[b, 0], h_hat[b, 1], h_hat[b, 2] = h1, h2, h5
        _law(e0, e1, e2, h1, h2, h5, v_r, T, l1, l2, l3, v_max, omega_max, u[b])


@kernel("void(f8[:, ::1], f8, f8, f8, f8, f8, f8, f8, f8[:, ::1])")
def kanayama_step(e, v_r, omega_r, Kx, Ky, Ktheta, v_max, omega_max, u):
    """Kanayama's law for B seeds: v = v_r cos e3 + Kx e1, omega = omega_r + v_r (Ky e2 + Ktheta sin e3)."""
    for b in range(e.shape[0]):
        v = v_r * math.cos(e[b, 2]) + Kx * e[b, 0]
        omega = omega_r + v_r * (Ky * e[b, 1] + Ktheta * math.sin(e[b, 2]))
        u[b, 0] = min(max(v, -v_max), v_max)
        u[b, 1] = min(max(omega, -omega_max), omega_max)


@kernel("i8(f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8, b1[::1])")
def bad_seeds(q, u, e_true, z, limit, bad):
    """The runner's divergence test for B seeds: bad[b] when the pose or the command is not finite, the
    weights z (B, alpha) (or (B, 0)) are not, or the position error exceeds ``limit``. Returns the count."""
    n = 0
    for b in range(q.shape[0]):
        s = q[b, 0] + q[b, 1] + q[b, 2] + u[b, 0] + u[b, 1]
        for i in range(z.shape[1]):
            s += z[b, i] * 0.0
        x = math.hypot(e_true[b, 0], e_true[b, 1])
        bad[b] = not (math.isfinite(s) and x <= limit)
        n += bad[b]
    return n


KANAYAMA, CORRADINI = 1, 2  # the laws the compiled closed loop runs (mlpfac.loop.compiled), by number


@kernel()
def law_step(law, c, e, v_r, omega_r, u, tele):
    """One step of a law given by number, for B seeds: :func:`kanayama_step` with c = (Kx, Ky,
    Ktheta, v_max, omega_max) or :func:`corradini_step` with c = (T, lambda_1..3, v_max, omega_max)
    and its h_hat in ``tele`` (B, 3)."""
    if law == KANAYAMA:
        kanayama_step(e, v_r, omega_r, c[0], c[1], c[2], c[3], c[4], u)
    else:
        corradini_step(e, v_r, omega_r, c[0], c[1], c[2], c[3], c[4], c[5], tele, u)
