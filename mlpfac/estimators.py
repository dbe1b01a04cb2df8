"""On-line weight tuning: the extended Kalman filter (29)-(32) of the weight model (28).

State model (28): z_{k+1} = z_k (+ process noise w_k ~ N(0, Q), optional),
measurement e_k = h(x_f, x_G, u_{k-1}, z_k) + eps_k, eps_k ~ N(0, R).
All arrays may carry leading batch dimensions: z (..., alpha), P (..., alpha, alpha).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mlpfac.exceptions import ConfigError

Jacobian = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # z -> (h (..., 3), H (..., 3, alpha))


def covariance(value: float | list | np.ndarray, n: int, name: str) -> np.ndarray:
    """A covariance from a scalar (times I), a diagonal, or a full matrix; checked symmetric PSD."""
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.ndim == 1:
        if a.shape != (n,):
            raise ConfigError(name, f"expected a scalar or {n} diagonal values, got {a.shape[0]}")
        if np.any(a < 0) or not np.all(np.isfinite(a)):
            raise ConfigError(name, "a covariance must be finite and non-negative")
        return np.diag(a)
    if a.shape != (n, n) or not np.allclose(a, a.T) or np.linalg.eigvalsh(a).min() < -1e-12:
        raise ConfigError(name, f"expected a symmetric positive semi-definite {n}x{n} matrix")
    return a


class EKF:
    """Extended Kalman filter over the network weights, eqs. (29)-(32).

    ``forgetting`` in (0, 1] divides P by itself after each update (exponential forgetting; 1 is
    the paper). ``Q`` is added after each update. ``P_max`` (optional) caps the diagonal of P so
    that forgetting cannot inflate it without bound: P is scaled down as a whole when max diag P
    exceeds it.
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
        if not 0.0 < forgetting <= 1.0:
            raise ConfigError("forgetting", f"must be in (0, 1], got {forgetting}")
        self.z = np.array(z0, dtype=float)
        self.P = np.array(np.broadcast_to(P0, (*self.z.shape, self.z.shape[-1])), dtype=float)
        self.R = np.asarray(R, dtype=float)
        self.Q = None if Q is None or not np.any(Q) else np.asarray(Q, dtype=float)
        self.forgetting = forgetting
        self.P_max = P_max

    def update(self, y: np.ndarray, jac: Jacobian, h_of: Callable | None = None) -> np.ndarray:
        """One step of (29)-(32) with measurement y = e_k; returns the innovation i_k (32).

        ``jac(z)`` gives h and nabla_h at the current z. The covariance update is the Joseph form
        P+ = (I - K H) P (I - K H)' + K R K', evaluated in O(alpha^2) because K H has rank 3; it keeps
        P symmetric positive definite where the short form P - K H P can lose it in round-off.
        """
        h, H = jac(self.z)
        P = self.P
        PHt = P @ np.swapaxes(H, -1, -2)  # (..., alpha, 3)
        S = H @ PHt + self.R  # (..., 3, 3) innovation covariance
        K = np.swapaxes(np.linalg.solve(S, np.swapaxes(PHt, -1, -2)), -1, -2)  # (31), solve not inv
        i = y - h  # (32)
        self.z = self.z + np.einsum("...ak,...k->...a", K, i)  # (30)
        A = P - K @ np.swapaxes(PHt, -1, -2)  # (I - K H) P: (29)
        P = A - (A @ np.swapaxes(H, -1, -2)) @ np.swapaxes(K, -1, -2) + K @ self.R @ np.swapaxes(K, -1, -2)
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
        if self.forgetting < 1.0:
            P = P / self.forgetting
        if self.Q is not None:
            P = P + self.Q
        if self.P_max is not None:
            peak = np.max(np.diagonal(P, axis1=-2, axis2=-1), axis=-1)
            P = P * np.minimum(1.0, self.P_max / peak)[..., None, None]
        self.P = P
        return i
