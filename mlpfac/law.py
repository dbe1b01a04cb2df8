"""The control law (35) with gains placed from closed-loop eigenvalues (36), corrected.

With omega_k = (h5 + k2 e2 + k3 e3) / T and v_k = (k1 e1 + h1 omega_k + h2) / T, the model (5)-(6)
gives e1_{k+1} = (1 - k1) e1 exactly, and the e2/e3 loop linearised about e = 0 is
[[1, T v_r], [-k2, 1 - k3]]. Its characteristic polynomial is z^2 - (2 - k3) z + (1 - k3 + T v_r k2),
so eigenvalues lambda_2, lambda_3 need

    k1 = 1 - lambda_1,   k3 = 2 - lambda_2 - lambda_3,   k2 = (1 - lambda_2)(1 - lambda_3) / (T v_r).

(36) as printed swaps k2 and k3; this is the corrected assignment (k2 is recomputed every step).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mlpfac.exceptions import ConfigError

V_R_MIN = 1e-3  # m/s: k2 divides by T v_r; the references keep v_r far above this


@dataclass(frozen=True)
class Law:
    """Eigenvalues lambda_1..3 of the closed-loop error dynamics, and optional command limits."""

    lambdas: tuple[float, float, float] = (0.8, 0.8, 0.8)
    v_max: float | None = None  # |v| limit, m/s
    omega_max: float | None = None  # |omega| limit, rad/s

    def __post_init__(self) -> None:
        lam = tuple(float(x) for x in self.lambdas)
        if len(lam) != 3:
            raise ConfigError("lambdas", f"need three eigenvalues, got {len(lam)}")
        if any(not (-1.0 < x < 1.0) for x in lam):
            raise ConfigError("lambdas", f"eigenvalues must lie inside the unit circle, got {list(lam)}")
        object.__setattr__(self, "lambdas", lam)
        for name in ("v_max", "omega_max"):
            val = getattr(self, name)
            if val is not None and not val > 0:
                raise ConfigError(name, f"must be positive, got {val}")

    def gains(self, T: float, v_r) -> tuple[float, np.ndarray, float]:
        """(k1, k2, k3) for reference speed v_r (corrected (36))."""
        l1, l2, l3 = self.lambdas
        k2 = (1.0 - l2) * (1.0 - l3) / (T * np.maximum(v_r, V_R_MIN))
        return 1.0 - l1, k2, 2.0 - l2 - l3

    def control(self, e: np.ndarray, h: np.ndarray, v_r, T: float) -> np.ndarray:
        """Eq. (35): u = (v, omega) from e (..., 3) and h = (h1, h2, h5) (..., 3); then the limits.

        omega is computed first since v uses it; the v law uses the omega actually sent (after the
        limit), so that e1 still decays as lambda_1 when only omega saturates.
        """
        k1, k2, k3 = self.gains(T, v_r)
        omega = (h[..., 2] + k2 * e[..., 1] + k3 * e[..., 2]) / T
        if self.omega_max is not None:
            omega = np.clip(omega, -self.omega_max, self.omega_max)
        v = (k1 * e[..., 0] + h[..., 0] * omega + h[..., 1]) / T
        if self.v_max is not None:
            v = np.clip(v, -self.v_max, self.v_max)
        return np.stack([v, omega], axis=-1)
