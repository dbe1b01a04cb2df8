"""The tracking error (2) and the discrete error model e_k = f_{k-1} + G_{k-1} u_{k-1}, (4)-(6);
compiled and batch-first (:mod:`mlpfac.jit`): the error (2) of B poses and the kinematic plant (7)."""

from __future__ import annotations

import math

import numpy as np

from mlpfac.elementary import cos, sin
from mlpfac.jit import kernel

# Maths whose bits do not depend on the machine (docs/reproducibility.md): mlpfac.elementary's sine and
# cosine, and small linear algebra written out in correctly rounded arithmetic (+, -, *, /, sqrt;
# einsum, which never calls BLAS), never numpy's SIMD transcendental loops nor BLAS or LAPACK, whose
# results depend on the processor's instruction set, nor the C library's maths, which differ between libraries.


def dot(a: np.ndarray, b: np.ndarray) -> float:
    """a . b of two vectors, summed in order."""
    total = 0.0
    for x, y in zip(np.ravel(a).tolist(), np.ravel(b).tolist(), strict=True):
        total += x * y
    return total


def norm(a: np.ndarray) -> float:
    """|a| of a vector."""
    return math.sqrt(dot(a, a))


def matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A B over the last two axes, batched like ``@`` (einsum's own loops, not BLAS)."""
    return np.einsum("...ij,...jk->...ik", A, B)


def cholesky(A: np.ndarray) -> np.ndarray:
    """L lower-triangular with L L' = A (..., n, n) for A symmetric positive semi-definite (a pivot
    that is not positive gives a zero column)."""
    A = np.asarray(A, dtype=float)
    L = np.zeros_like(A)
    for j in range(A.shape[-1]):
        row = L[..., j, :j]
        d = np.sqrt(np.maximum(A[..., j, j] - np.einsum("...k,...k->...", row, row), 0.0))
        L[..., j, j] = d
        col = A[..., j + 1 :, j] - np.einsum("...ik,...k->...i", L[..., j + 1 :, :j], row)
        with np.errstate(divide="ignore", invalid="ignore"):
            L[..., j + 1 :, j] = np.where(d[..., None] > 0.0, col / d[..., None], 0.0)
    return L


def solve_lower(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    """X with L X = B, L (..., n, n) lower-triangular, B (..., n, k): forward substitution."""
    X = np.array(np.broadcast_to(B, np.broadcast_shapes(L.shape[:-2], B.shape[:-2]) + B.shape[-2:]), dtype=float)
    for i in range(L.shape[-1]):
        X[..., i, :] = (X[..., i, :] - np.einsum("...j,...jk->...k", L[..., i, :i], X[..., :i, :])) / L[..., i, i, None]
    return X


def solve_spd(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """X with A X = B for A (..., n, n) symmetric positive definite (Cholesky), B (..., n, k)."""
    L = cholesky(A)
    Y = solve_lower(L, B)
    U = np.swapaxes(L, -1, -2)
    for i in reversed(range(U.shape[-1])):
        Y[..., i, :] = (Y[..., i, :] - np.einsum("...j,...jk->...k", U[..., i, i + 1 :], Y[..., i + 1 :, :])) / U[
            ..., i, i, None
        ]
    return Y


def eigh(A: np.ndarray, sweeps: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues w (..., n) and eigenvectors V (columns, (..., n, n)) of symmetric A, A = V diag(w) V',
    by cyclic Jacobi rotations (at most ``sweeps``: quadratic convergence, for small n; compiled)."""
    A = np.asarray(A, dtype=float)
    rows = np.ascontiguousarray(A.reshape(-1, *A.shape[-2:]))
    w, V = np.empty(rows.shape[:2]), np.empty_like(rows)
    jacobi(rows, sweeps, w, V)
    return w.reshape(A.shape[:-1]), V.reshape(A.shape)


@kernel("void(f8[:, :, ::1], i8, f8[:, ::1], f8[:, :, ::1])")
def jacobi(A, sweeps, w, V):
    """:func:`eigh` of each symmetric A[b] (B, n, n) into w[b] (B, n) and V[b] (B, n, n)."""
    n = A.shape[1]
    for b in range(A.shape[0]):
        a = A[b].copy()
        v = V[b]
        v[:] = 0.0
        for i in range(n):
            v[i, i] = 1.0
        for _ in range(sweeps):
            off = False
            for p in range(n):
                for q in range(n):
                    off = off or (p != q and a[p, q] != 0.0)
            if not off:  # diagonal to the bit: a rotation would change nothing
                break
            for p in range(n - 1):
                for q in range(p + 1, n):
                    apq = a[p, q]
                    if apq == 0.0:
                        continue
                    theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                    t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                    if not math.isfinite(t) or t == 0.0:
                        continue
                    c = 1.0 / math.sqrt(t * t + 1.0)
                    s = t * c
                    for k in range(n):  # columns p, q of a and v, then rows p, q of a
                        ap, aq = a[k, p], a[k, q]
                        a[k, p], a[k, q] = c * ap - s * aq, s * ap + c * aq
                        vp, vq = v[k, p], v[k, q]
                        v[k, p], v[k, q] = c * vp - s * vq, s * vp + c * vq
                    for k in range(n):
                        ap, aq = a[p, k], a[q, k]
                        a[p, k], a[q, k] = c * ap - s * aq, s * ap + c * aq
        for i in range(n):
            w[b, i] = a[i, i]


def wrap(angle: np.ndarray | float) -> np.ndarray | float:
    """Angle wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - angle, 2.0 * np.pi)


def tracking_error(q: np.ndarray, q_r: np.ndarray) -> np.ndarray:
    """Eq. (2): the error of pose q = (x, y, theta) to q_r, in the robot's frame; e3 wrapped. (3,)"""
    c, s = cos(q[2]), sin(q[2])
    dx, dy = q_r[0] - q[0], q_r[1] - q[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, wrap(q_r[2] - q[2])])


def pose_from_error(e: np.ndarray, q_r: np.ndarray) -> np.ndarray:
    """The pose q whose error (2) to q_r is e (the inverse of :func:`tracking_error`). (3,)"""
    theta = q_r[2] - e[2]
    c, s = cos(theta), sin(theta)
    return np.array([q_r[0] - (c * e[0] - s * e[1]), q_r[1] - (s * e[0] + c * e[1]), theta])


def f_true(e: np.ndarray, v_r: float, omega_r: float, T: float) -> np.ndarray:
    """Eq. (5): the drift of the Euler-discretised error dynamics (3). (3,)"""
    return np.array([e[0] + T * v_r * cos(e[2]), e[1] + T * v_r * sin(e[2]), e[2] + T * omega_r])


def G_true(e: np.ndarray, T: float) -> np.ndarray:
    """Eq. (6): the input matrix of the Euler-discretised error dynamics (3). (3, 2)"""
    return np.array([[-T, T * e[1]], [0.0, -T * e[0]], [0.0, -T]])


def h_true(e: np.ndarray, v_r: float, omega_r: float, T: float) -> np.ndarray:
    """Eq. (34) with the true functions: (h1, h2, h5) = (G_12, f_1 - e1, f_3 - e3). (3,)"""
    return np.array([T * e[1], T * v_r * cos(e[2]), T * omega_r])


@kernel("void(f8[:, ::1], f8[::1], f8[:, ::1])")
def tracking_errors(q, r, out):
    """Eq. (2) for poses q (B, 3) and one reference sample r (>= 3,): out (B, 3), e3 wrapped to (-pi, pi]."""
    for b in range(q.shape[0]):
        c, s = cos(q[b, 2]), sin(q[b, 2])
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
        h_true[b, 0], h_true[b, 1], h_true[b, 2] = Tp * e1, Tp * r[3] * cos(e2), Tp * r[4]
        n0 = (e0 + Tp * r[3] * cos(e2)) + (-Tp * u0 + Tp * e1 * u1) + noise[b, 0]
        n1 = (e1 + Tp * r[3] * sin(e2)) + (-Tp * e0) * u1 + noise[b, 1]
        n2 = (e2 + Tp * r[4]) + (-Tp) * u1 + noise[b, 2]
        e_out[b, 0], e_out[b, 1], e_out[b, 2] = n0, n1, n2
        th = r_next[2] - n2
        c, s = cos(th), sin(th)
        pose_out[b, 0] = r_next[0] - (c * n0 - s * n1)
        pose_out[b, 1] = r_next[1] - (s * n0 + c * n1)
        pose_out[b, 2] = th
