"""The control law (35) with gains placed from closed-loop eigenvalues (36), corrected.

With omega_k = (h5 + k2 e2 + k3 e3) / T and v_k = (k1 e1 + h1 omega_k + h2) / T, the model (5)-(6)
gives e1_{k+1} = (1 - k1) e1 exactly, and the e2/e3 loop linearised about e = 0 is
[[1, T v_r], [-k2, 1 - k3]]. Its characteristic polynomial is z^2 - (2 - k3) z + (1 - k3 + T v_r k2),
so eigenvalues lambda_2, lambda_3 need

    k1 = 1 - lambda_1,   k3 = 2 - lambda_2 - lambda_3,   k2 = (1 - lambda_2)(1 - lambda_3) / (T v_r).

(36) as printed swaps k2 and k3; this is the corrected assignment (k2 is recomputed every step).

:meth:`Law.cautious_control` generalises (35) to uncertain estimates (a cautious law, Fabri and
Kadirkamanathan 2001) and to learned input gains; certainty equivalence is its zero-variance case.

The law (35) is written once, compiled (:func:`_law`, :mod:`mlpfac.jit`): :meth:`Law.control` calls
it (one run, or a batch row by row), as do the batch-first kernels of Corradini's law
(:func:`corradini_step`, (35) with the nominal h of (34)), the adaptive step and the compiled closed
loop (:func:`law_step`, with Kanayama's law :func:`kanayama_step`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mlpfac.elementary import cos, sin
from mlpfac.exceptions import ConfigError
from mlpfac.jit import kernel

V_R_MIN = 1e-3  # m/s: k2 divides by T v_r; the references keep v_r far above this
GAIN_RANGE = (0.25, 4.0)  # learned input gains b_v, b_omega are kept within these multiples of T


@dataclass(frozen=True)
class Law:
    """Eigenvalues lambda_1..3 of the closed-loop error dynamics, and optional command limits."""

    lambdas: tuple[float, float, float] = (
        0.9,
        0.9,
        0.9,
    )  # closed-loop eigenvalues λ1..3 of (36) (0.8 chatters on noise)
    v_max: float | None = 2.0  # |v| limit, m/s (None, or inf in a scenario file: no limit)
    omega_max: float | None = 5.0  # |omega| limit, rad/s

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
        if np.ndim(e) > 1:  # a batch, row by row
            v_r = np.broadcast_to(v_r, np.shape(e)[:-1])
            return np.stack([self.control(e[i], h[i], v_r[i], T) for i in range(len(e))])
        u = np.empty(2)  # one run: the compiled law, the one the batch kernels run
        v_max, omega_max = (math.inf if x is None else x for x in (self.v_max, self.omega_max))
        _law(*map(float, e[:3]), *map(float, h[:3]), float(v_r), T, *self.lambdas, v_max, omega_max, u)
        return u

    def cautious_control(
        self,
        e: np.ndarray,
        theta: np.ndarray,
        Sigma: np.ndarray | None,
        v_r,
        T: float,
        weight: float = 1.0,
    ) -> np.ndarray:
        """The cautious law: (v, omega) minimising the expected one-step cost given uncertain estimates.

        ``theta`` = (h1, h2, h5, b_v, b_omega) (..., 5) are the means of the estimated quantities: h1, h2, h5
        of (34) and the input gains b_v = -G_11 (v -> e1) and b_omega = -G_32 (omega -> e3), which (35)
        takes to be exactly T. ``Sigma`` (..., 5, 5) is their covariance (to first order J P_k J', J the
        Jacobian of theta w.r.t. z); ``weight`` c >= 0 scales it (c = 1: the expected cost; c = 0 or
        Sigma = None: certainty equivalence).

        Derivation. By (4)-(6) and (34), with the targets of (35), t1 = (1 - k1) e1 and
        t3 = (1 - k3) e3 - k2 e2, the one-step residuals are

            r1 = e1_{k+1} - t1 = n0 + h1 omega - b_v v,     n0 = k1 e1 + h2
            r3 = e3_{k+1} - t3 = m - b_omega omega,         m  = k2 e2 + k3 e3 + h5

        (G_21 = G_31 = 0 as in (6)). Minimise J = E[r1^2] + E[r3^2] (1 m of e1 weighs as 1 rad of e3),
        with E[x y] = x_bar y_bar + c Cov(x, y). For fixed omega, dJ/dv = 0 gives

            v = (B0 + B1 omega) / E[b_v^2],     B0 = E[b_v n0],  B1 = E[b_v h1]

        and then J(omega) = E[r3^2] + A0 + 2 A1 omega + A2 omega^2 - (B0 + B1 omega)^2 / E[b_v^2] with
        A1 = E[n0 h1], A2 = E[h1^2]; dJ/domega = 0 gives

            omega = (E[b_omega m] - A1 + B0 B1 / E[b_v^2]) / (E[b_omega^2] + A2 - B1^2 / E[b_v^2]).

        With c = 0 the correction terms cancel exactly (A1 = B0 B1 / E[b_v^2], A2 = B1^2 / E[b_v^2]) and
        omega = m / b_omega, v = (n0 + h1 omega) / b_v: the CE law (35) with gains b (equal to it when
        b = T). With c > 0 the classic cautious result appears: each input is divided by
        mean^2 + variance of its gain, and omega is further shrunk by c Var(h1) (an unsure G_12 makes
        omega leak into e1) and shifted by c Cov(h1, h2). As in :meth:`control`, omega is limited
        first and v is computed with the omega actually sent.
        """
        k1, k2, k3 = self.gains(T, v_r)
        h1, h2, h5, bv, bw = (theta[..., i] for i in range(5))
        n0 = k1 * e[..., 0] + h2
        m = k2 * e[..., 1] + k3 * e[..., 2] + h5
        C = np.zeros((*np.shape(theta)[:-1], 5, 5)) if Sigma is None or weight == 0.0 else weight * np.asarray(Sigma)
        Ebv2 = bv * bv + C[..., 3, 3]
        B0 = bv * n0 + C[..., 3, 1]
        B1 = bv * h1 + C[..., 3, 0]
        A1 = n0 * h1 + C[..., 1, 0]
        A2 = h1 * h1 + C[..., 0, 0]
        num = bw * m + C[..., 4, 2] - A1 + B0 * B1 / Ebv2
        den = bw * bw + C[..., 4, 4] + A2 - B1 * B1 / Ebv2
        omega = num / den
        if self.omega_max is not None:
            omega = np.clip(omega, -self.omega_max, self.omega_max)
        v = (B0 + B1 * omega) / Ebv2
        if self.v_max is not None:
            v = np.clip(v, -self.v_max, self.v_max)
        return np.stack([v, omega], axis=-1)


@kernel()
def _law(e0, e1, e2, h1, h2, h5, v_r, T, l1, l2, l3, v_max, omega_max, u):
    """(35) with the corrected gains (36); omega first, limited, then v with the omega sent."""
    k2 = (1.0 - l2) * (1.0 - l3) / (T * max(v_r, V_R_MIN))
    omega = (h5 + k2 * e1 + (2.0 - l2 - l3) * e2) / T
    omega = min(max(omega, -omega_max), omega_max)
    v = ((1.0 - l1) * e0 + h1 * omega + h2) / T
    u[0] = min(max(v, -v_max), v_max)
    u[1] = omega


@kernel("void(f8[:, ::1], f8, f8, f8, f8, f8, f8, f8, f8, f8[:, ::1], f8[:, ::1])")
def corradini_step(e, v_r, omega_r, T, l1, l2, l3, v_max, omega_max, h_hat, u):
    """(35) given the nominal h1 = T e2, h2 = T v_r cos e3, h5 = T omega_r, for B seeds."""
    for b in range(e.shape[0]):
        e0, e1, e2 = e[b, 0], e[b, 1], e[b, 2]
        h1, h2, h5 = T * e1, T * v_r * cos(e2), T * omega_r
        h_hat[b, 0], h_hat[b, 1], h_hat[b, 2] = h1, h2, h5
        _law(e0, e1, e2, h1, h2, h5, v_r, T, l1, l2, l3, v_max, omega_max, u[b])


@kernel("void(f8[:, ::1], f8, f8, f8, f8, f8, f8, f8, f8[:, ::1])")
def kanayama_step(e, v_r, omega_r, Kx, Ky, Ktheta, v_max, omega_max, u):
    """Kanayama's law for B seeds: v = v_r cos e3 + Kx e1, omega = omega_r + v_r (Ky e2 + Ktheta sin e3)."""
    for b in range(e.shape[0]):
        v = v_r * cos(e[b, 2]) + Kx * e[b, 0]
        omega = omega_r + v_r * (Ky * e[b, 1] + Ktheta * sin(e[b, 2]))
        u[b, 0] = min(max(v, -v_max), v_max)
        u[b, 1] = min(max(omega, -omega_max), omega_max)


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
