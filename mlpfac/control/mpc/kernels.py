"""The planner's and the estimator's linear algebra, compiled: plain loops summed in order (no BLAS,
no reassociation), so the same bits on every machine. Sizes are small: the plan's knots (2 a knot),
the robot's tangent space (2 nv), the pose (3)."""

from __future__ import annotations

import math

import numpy as np

from mlpfac.jit import kernel


@kernel()
def _solve_spd(A, b, x):
    """x with A x = b, A symmetric positive definite (n, n): Cholesky in place of a copy."""
    n = b.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        d = math.sqrt(s) if s > 0.0 else 0.0
        L[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d if d > 0.0 else 0.0
    y = np.zeros(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i] if L[i, i] > 0.0 else 0.0
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i] if L[i, i] > 0.0 else 0.0


@kernel("void(f8[:, :, ::1], f8[::1], f8[:, ::1])")
def residual_jacobian(E, w, J):
    """J (M, 3 H): the residuals' Jacobian in the knots, J[p] = (E[1 + p] - E[0]) / w[p], from E
    (1 + M, H, 3) the rollouts' residuals (the plan's first, then one per knot coordinate moved by
    its step w[p])."""
    H = E.shape[1]
    for p in range(w.shape[0]):
        for j in range(H):
            for c in range(3):
                J[p, j * 3 + c] = (E[1 + p, j, c] - E[0, j, c]) / w[p]


@kernel("void(f8[:, ::1], f8[:, ::1], f8, f8, f8[::1])")
def gauss_newton(J, r, mu, floor, delta):
    """The Levenberg-Marquardt step for the knots: J (M, 3 H) the residuals' Jacobian, r (H, 3) the
    plan's residuals (e1, e2, heading_m e3); delta (M,) solves (J'J + mu diag(J'J) + floor I) delta = -J'r."""
    M = J.shape[0]
    n = J.shape[1]
    A = np.zeros((M, M))
    g = np.zeros(M)
    for p in range(M):
        s = 0.0
        for i in range(n):
            s += J[p, i] * r[i // 3, i % 3]
        g[p] = -s
        for q in range(p + 1):
            s = 0.0
            for i in range(n):
                s += J[p, i] * J[q, i]
            A[p, q] = s
            A[q, p] = s
    for p in range(M):
        A[p, p] += mu * A[p, p] + floor
    _solve_spd(A, g, delta)


@kernel("void(f8[:, ::1], f8[:, ::1], f8[::1])")
def covariance_predict(P, A, q):
    """P <- A P A' + diag(q), symmetric."""
    n = P.shape[0]
    AP = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += A[i, k] * P[k, j]
            AP[i, j] = s
    for i in range(n):
        for j in range(i + 1):
            s = 0.0
            for k in range(n):
                s += AP[i, k] * A[j, k]
            P[i, j] = s
            P[j, i] = s
    for i in range(n):
        P[i, i] += q[i]


@kernel("void(f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1])")
def kalman_update(P, Hx, r, nu, dx):
    """The measurement update: Hx (m, n) the measurement's Jacobian, r (m,) its noise variances, nu
    (m,) the innovation; dx (n,) = K nu, and P <- P - K S K' (S = Hx P Hx' + diag(r), K = P Hx' S^-1),
    symmetric."""
    n, m = P.shape[0], Hx.shape[0]
    PH = np.zeros((n, m))
    for i in range(n):
        for c in range(m):
            s = 0.0
            for k in range(n):
                s += P[i, k] * Hx[c, k]
            PH[i, c] = s
    S = np.zeros((m, m))
    for a in range(m):
        for c in range(m):
            s = 0.0
            for k in range(n):
                s += Hx[a, k] * PH[k, c]
            S[a, c] = s
        S[a, a] += r[a]
    # K' = S^-1 PH' (S symmetric positive definite), column by column
    Kt = np.zeros((m, n))
    col = np.empty(m)
    out = np.empty(m)
    for i in range(n):
        for c in range(m):
            col[c] = PH[i, c]
        _solve_spd(S, col, out)
        for c in range(m):
            Kt[c, i] = out[c]
    for i in range(n):
        s = 0.0
        for c in range(m):
            s += Kt[c, i] * nu[c]
        dx[i] = s
    for i in range(n):
        for j in range(i + 1):
            s = 0.0
            for c in range(m):
                s += PH[i, c] * Kt[c, j]
            P[i, j] -= s
            if i != j:
                P[j, i] = P[i, j]


@kernel("f8(f8[:, ::1])")
def plan_cost(E):
    """The plan's cost: the sum of the squares of its rollout's residuals E (H, 3), in order."""
    s = 0.0
    for j in range(E.shape[0]):
        for c in range(E.shape[1]):
            s += E[j, c] * E[j, c]
    return s
