"""On-line weight tuning of the weight model (28): the extended Kalman filter (29)-(32), and an
unscented Kalman filter in square-root form (the paper's "future work", Julier and Uhlmann 1997).

State model (28): z_{k+1} = z_k (+ process noise w_k ~ N(0, Q), optional),
measurement e_k = h(x_f, x_G, u_{k-1}, z_k) + eps_k, eps_k ~ N(0, R).
All arrays may carry leading batch dimensions: z (..., alpha), P (..., alpha, alpha).

Both filters share one interface: ``update(y, jac, h_of)`` (the EKF uses ``jac``, the UKF ``h_of``),
``z``, ``diag_P()``, ``project(J)`` = J P J', and the same "keep adapting" options applied after
each update, in this order: forgetting (P /= lambda), process noise (P += Q), cap (max diag P <= P_max).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.model import cholesky, eigh, matmul, solve_lower, solve_spd

Jacobian = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # z -> (h (..., 3), H (..., 3, alpha))


class _WeightFilter:
    """What the EKF and the UKF share: the weights z, R, and the knobs that keep adaptation alive."""

    def __init__(
        self, z0: np.ndarray, R: np.ndarray, Q: np.ndarray | None, forgetting: float, P_max: float | None
    ) -> None:
        if not 0.0 < forgetting <= 1.0:
            raise ConfigError("forgetting", f"must be in (0, 1], got {forgetting}")
        self.z = np.array(z0, dtype=float)
        self.R = np.ascontiguousarray(R, dtype=float)
        self.Q = None if Q is None or not np.any(Q) else np.ascontiguousarray(Q, dtype=float)
        self.forgetting = forgetting
        self.P_max = P_max


class EKF(_WeightFilter):
    """Extended Kalman filter over the network weights, eqs. (29)-(32), compiled
    (:func:`mlpfac.control.adaptive.kernels.ekf_update`).

    ``forgetting`` in (0, 1] divides P by itself after each update (exponential forgetting; 1 is
    the paper). ``Q`` is added after each update. ``P_max`` (optional) caps the diagonal of P so
    that forgetting cannot inflate it without bound: P is scaled down as a whole when max diag P
    exceeds it. P is kept C-ordered, (..., alpha, alpha) with the batch outermost.
    """

    def __init__(
        self,
        z0: np.ndarray,
        P0: np.ndarray,
        R: np.ndarray,
        Q: np.ndarray | None = None,
        forgetting: float = 1.0,
        P_max: float | None = None,
    ) -> None:
        super().__init__(z0, R, Q, forgetting, P_max)
        a = self.z.shape[-1]
        self.P = np.broadcast_to(P0, (*self.z.shape, a))

    def update(self, y: np.ndarray, jac: Jacobian, h_of: Callable | None = None) -> np.ndarray:
        """One step of (29)-(32) with measurement y = e_k; returns the innovation i_k (32).

        ``jac(z)`` gives h and nabla_h at the current z. The covariance update is the short form
        P+ = P - K H P, written as P - W'W (W = L^-1 H P, S = H P H' + R = L L'), which keeps P
        exactly symmetric; it costs half the Joseph form, and P stays positive definite over long
        runs (tests/test_core.py).
        """
        from mlpfac.control.adaptive.kernels import ekf_update

        a = self.z.shape[-1]
        h, H = jac(self.z)
        z = np.ascontiguousarray(self.z, dtype=float).reshape(-1, a)
        P = self._P.reshape(-1, a, a)
        # copies: a broadcast view is read-only, and the kernel's signature names writable arrays
        y2 = np.array(np.broadcast_to(y, self.z.shape[:-1] + (3,)), dtype=float).reshape(-1, 3)
        h2 = np.array(np.broadcast_to(h, y2.shape), dtype=float)
        H2 = np.array(np.broadcast_to(H, (len(z), 3, a)), dtype=float)
        innov = np.empty_like(y2)
        Q = self.Q if self.Q is not None else np.zeros((1, 1))
        P_max = np.inf if self.P_max is None else float(self.P_max)
        ekf_update(z, P, y2, h2, H2, self.R, float(self.forgetting), Q, self.Q is not None, P_max, innov)
        self.z = z.reshape(self.z.shape)
        return innov.reshape(y2.shape if self.z.ndim > 1 else (3,))

    @property
    def P(self) -> np.ndarray:
        """P_k (..., alpha, alpha). Read it before the next update: the filter updates it in place."""
        return self._P

    @P.setter
    def P(self, value: np.ndarray) -> None:
        self._P = np.array(value, dtype=float, order="C")  # our own C-ordered copy, batch outermost

    def __copy__(self) -> EKF:
        """A shallow copy that shares no storage with the original (two filters must never share it)."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new._P = self._P.copy()
        new.z = self.z.copy()
        return new

    def diag_P(self) -> np.ndarray:
        """diag P_k (..., alpha)."""
        return np.diagonal(self.P, axis1=-2, axis2=-1)

    def project(self, J: np.ndarray) -> np.ndarray:
        """J P J' (..., m, m) for J (..., m, alpha): the covariance of J z (first order)."""
        return matmul(matmul(J, self.P), np.swapaxes(J, -1, -2))


class UKF(_WeightFilter):
    """Unscented Kalman filter over the weights, square-root form; same model (28) as :class:`EKF`.

    The state model is the identity, so the prediction is trivial (P += Q, or forgetting) and only the
    measurement update uses sigma points: with n = alpha, lambda = a^2 (n + kappa) - n, gamma = sqrt(n + lambda)
    and S any square root of P (P = S S'),

        Z_0 = z,  Z_i^+- = z +- gamma s_i          (2 n + 1 points, s_i the columns of S)
        Y = h(Z)                                   (one batched call)
        y_bar = W0m Y_0 + Wm sum_i (Y_i^+ + Y_i^-),  W0m = lambda / (n + lambda),  Wm = 1 / (2 (n + lambda))
        P_zy = sum W (Z - z)(Y - y_bar)' = S D',    D = gamma Wm [Y_i^+ - Y_i^-]_i          (3, n)
        P_yy = D D' + R',  R' = R + W0c c c' + 2 Wm sum_i m_i m_i'
                           c = Y_0 - y_bar,  m_i = (Y_i^+ + Y_i^-) / 2 - y_bar,  W0c = W0m + 1 - a^2 + beta
        K = P_zy P_yy^-1,  z+ = z + K (y - y_bar),  P+ = P - K P_yy K' = S (I - D' P_yy^-1 D) S'.

    So the update is that of a linear Kalman filter with H S = D and noise R' >= R (the second-order
    spread of the sigma points). R' is kept positive semi-definite (the part beyond R is clipped at 0,
    which matters only when W0c < 0), and S is updated in square-root form, so P = S S' stays
    positive definite by construction: whiten with R' = L L' (D~ = L^-1 D), then for each row d of D~
    in turn (Potter's scalar update, noise 1), with a = the current (H S)' for that row,

        s = a'a + 1,  g = 1 / (1 + sqrt(1 / s)),  S <- S - (g / s) (S a) a',

    and carry the remaining rows along: a_next <- a_next - (g / s) a (a' a_next). No factorisation of
    P is needed, so a step costs O(n^2) plus the 2 n + 1 evaluations of h; only Q > 0 refactorises
    (Cholesky of S S' + Q, O(n^3)). For h linear in z (h = H z), D = H S, R' = R, and the filter is
    the exact Kalman filter for any spread a, beta, kappa.
    """

    def __init__(
        self,
        z0: np.ndarray,
        P0: np.ndarray,
        R: np.ndarray,
        Q: np.ndarray | None = None,
        forgetting: float = 1.0,
        P_max: float | None = None,
        alpha: float = 1.0,
        beta: float = 2.0,
        kappa: float = 0.0,
    ) -> None:
        super().__init__(z0, R, Q, forgetting, P_max)
        n = self.z.shape[-1]
        P0 = np.array(np.broadcast_to(P0, (*self.z.shape, n)), dtype=float)
        self.S = cholesky(P0)  # (..., n, n), P = S S'
        lam = alpha * alpha * (n + kappa) - n
        if not n + lam > 0:
            raise ConfigError("ukf_alpha", f"need alpha^2 (n + kappa) > 0, got alpha = {alpha}, kappa = {kappa}")
        self.gamma = np.sqrt(n + lam)
        self.W0m = lam / (n + lam)
        self.Wm = 0.5 / (n + lam)
        self.W0c = self.W0m + 1.0 - alpha * alpha + beta

    @property
    def P(self) -> np.ndarray:
        """P = S S' (..., n, n); O(n^3), for inspection and tests, not for the loop."""
        return matmul(self.S, np.swapaxes(self.S, -1, -2))

    def diag_P(self) -> np.ndarray:
        return np.einsum("...ij,...ij->...i", self.S, self.S)

    def project(self, J: np.ndarray) -> np.ndarray:
        A = matmul(J, self.S)  # (..., m, n)
        return matmul(A, np.swapaxes(A, -1, -2))

    def sigma_points(self) -> np.ndarray:
        """Z (..., 2 n + 1, n): z, then z + gamma s_i, then z - gamma s_i."""
        dZ = self.gamma * np.swapaxes(self.S, -1, -2)  # (..., n, n), row i = gamma s_i
        z = self.z[..., None, :]
        return np.concatenate([z, z + dZ, z - dZ], axis=-2)

    def update(self, y: np.ndarray, jac: Jacobian | None = None, h_of: Callable | None = None) -> np.ndarray:
        """One measurement update with y = e_k; ``h_of(Z)`` maps sigma points (..., m, n) to (..., m, 3).

        Returns the innovation y - y_bar. ``jac`` is accepted for interface parity with the EKF and unused.
        """
        if h_of is None:
            raise ConfigError("estimator", "the UKF needs h_of(z) to evaluate the sigma points")
        n = self.z.shape[-1]
        Y = h_of(self.sigma_points())  # (..., 2n + 1, 3)
        Y0, Yp, Ym = Y[..., 0, :], Y[..., 1 : n + 1, :], Y[..., n + 1 :, :]
        y_bar = self.W0m * Y0 + self.Wm * np.sum(Yp + Ym, axis=-2)  # (..., 3)
        D = self.gamma * self.Wm * np.swapaxes(Yp - Ym, -1, -2)  # (..., 3, n), P_zy = S D'
        c = Y0 - y_bar
        M = 0.5 * (Yp + Ym) - y_bar[..., None, :]  # (..., n, 3)
        extra = self.W0c * c[..., :, None] * c[..., None, :] + 2.0 * self.Wm * matmul(np.swapaxes(M, -1, -2), M)
        if self.W0c < 0.0:  # 3x3: keep R' >= R (a sum of semi-definite terms when W0c >= 0)
            w, V = eigh(extra)
            extra = matmul(V * np.maximum(w, 0.0)[..., None, :], np.swapaxes(V, -1, -2))
        Rp = self.R + extra
        Pyy = matmul(D, np.swapaxes(D, -1, -2)) + Rp  # (..., 3, 3)
        i = y - y_bar
        SDt = matmul(self.S, np.swapaxes(D, -1, -2))  # P_zy (..., n, 3)
        self.z = self.z + np.einsum("...ak,...k->...a", SDt, solve_spd(Pyy, i[..., None])[..., 0])  # K i (30)
        L = cholesky(Rp)
        A = np.swapaxes(solve_lower(L, D), -1, -2)  # (..., n, 3): whitened (H S)', noise I
        S = self.S
        for j in range(A.shape[-1]):  # Potter's square-root update, one whitened row at a time
            a = A[..., :, j]  # (..., n)
            s = np.einsum("...i,...i->...", a, a) + 1.0
            g = 1.0 / (1.0 + np.sqrt(1.0 / s))
            Sa = np.einsum("...ij,...j->...i", S, a)
            S = S - (g / s)[..., None, None] * Sa[..., :, None] * a[..., None, :]
            if j + 1 < A.shape[-1]:
                aA = np.einsum("...i,...ik->...k", a, A[..., :, j + 1 :])
                A = A.copy()
                A[..., :, j + 1 :] -= (g / s)[..., None, None] * a[..., :, None] * aA[..., None, :]
        if self.forgetting < 1.0:
            S = S / np.sqrt(self.forgetting)
        if self.Q is not None:
            S = cholesky(matmul(S, np.swapaxes(S, -1, -2)) + self.Q)
        if self.P_max is not None:
            peak = np.max(np.einsum("...ij,...ij->...i", S, S), axis=-1)
            S = S * np.sqrt(np.minimum(1.0, self.P_max / peak))[..., None, None]
        self.S = S
        return i
