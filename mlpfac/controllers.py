"""Controllers with one interface: the adaptive MLP-EKF law, Corradini's law with the nominal
functions, and Kanayama's law. Any controller runs on any plant.

``step(e_k, r_k)`` takes the tracking error (2) and the reference sample
r_k = (x_r, y_r, theta_r, v_r, omega_r) and returns u_k = (v, omega).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from mlpfac.error_model import G_true, f_true, h_true, wrap
from mlpfac.estimators import EKF, UKF, covariance
from mlpfac.exceptions import ConfigError
from mlpfac.law import GAIN_RANGE, Law
from mlpfac.networks import Networks


class Controller(Protocol):
    name: str
    labels: dict[str, list[str]]

    def reset(self, T: float, rng: np.random.Generator) -> None: ...

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray: ...

    def telemetry(self) -> dict[str, np.ndarray | float]: ...


@dataclass(frozen=True)
class AdaptiveConfig:
    """The MLP-EKF scheme's choices; the paper fixes L_f, L_G and P0 only.

    The defaults are the paper's scheme with the project's tuned choices (README, "The project's
    defaults"; the paper's own numbers are sims/paper-faithful.toml). The options beyond the paper,
    each off by default:

    - ``estimator = "ukf"``: tune the weights with the square-root unscented filter
      (:class:`~mlpfac.estimators.UKF`, spread ``ukf_alpha``, ``ukf_beta``, ``ukf_kappa``) instead of (29)-(32).
    - ``cautious = c > 0``: the cautious law (:meth:`~mlpfac.law.Law.cautious_control`) with the
      covariance of (h1, h2, h5, b_v, b_omega) from P_k, scaled by c; 0 is certainty equivalence.
    - ``Q``, ``forgetting``, ``P_max``: adaptation that does not switch off, with P bounded.
    - ``prior = true``: the networks learn only the correction to the nominal kinematic functions (5)-(6),
      f = f_nominal + NN_f, G = G_nominal + NN_G; the filter's measurement becomes
      e_k - f_nominal - G_nominal u_{k-1}. With zero output weights the scheme starts as Corradini's law.
    - ``learned_gains = true``: the law divides by the learned input gains b_v = -G_11, b_omega = -G_32
      (kept within ``GAIN_RANGE`` times T) instead of T, so a wrong actuator/wheel gain can be learned.
    - ``output_weight_std``: the initial spread of the output-layer weights (``weight_std`` if unset);
      0 with ``prior`` starts from the nominal functions exactly.
    """

    networks: Networks = field(default_factory=Networks)
    P0: float = 0.1  # initial covariance P_0 = P0 I_alpha (the paper: 5)
    R: float | tuple[float, ...] | tuple[tuple[float, ...], ...] = (
        1e-3  # EKF measurement noise covariance, a tuning knob (the paper: 1e-6)
    )
    Q: float = 0.0  # EKF process noise, Q = Q I_alpha
    forgetting: float = 1.0  # P /= forgetting after each update (1: none)
    P_max: float | None = None  # cap on max diag P
    weight_std: float = 0.3  # initial weights ~ N(0, weight_std^2)
    output_weight_std: float | None = 0.01  # initial output-layer weights ~ N(0, .^2); None: weight_std
    estimator: str = "ekf"  # "ekf" (29)-(32) or "ukf" (square-root unscented)
    ukf_alpha: float = 1.0  # UKF sigma-point spread a: gamma = a sqrt(n + kappa), n the number of weights
    ukf_beta: float = 2.0  # UKF weight of the centre point in the covariance (2: Gaussian)
    ukf_kappa: float = 0.0  # UKF secondary spread
    cautious: float = 0.0  # weight c of the estimate covariance in the law (0: certainty equivalence)
    prior: bool = False  # learn the correction to the nominal kinematic functions
    learned_gains: bool = False  # divide by the learned input gains -G_11, -G_32 instead of T

    def __post_init__(self) -> None:
        for name in ("P0", "weight_std", "ukf_alpha"):
            if not getattr(self, name) > 0:
                raise ConfigError(name, f"must be positive, got {getattr(self, name)}")
        if self.Q < 0:
            raise ConfigError("Q", f"a covariance must be non-negative, got {self.Q}")
        covariance(self.R, 3, "R")
        if not 0.0 < self.forgetting <= 1.0:
            raise ConfigError("forgetting", f"must be in (0, 1] (1: no forgetting), got {self.forgetting}")
        if self.P_max is not None and not self.P_max > 0:
            raise ConfigError("P_max", f"must be positive, got {self.P_max}")
        if self.output_weight_std is not None and not self.output_weight_std >= 0:
            raise ConfigError("output_weight_std", f"must be >= 0, got {self.output_weight_std}")
        if self.estimator not in ("ekf", "ukf"):
            raise ConfigError("estimator", f"choose 'ekf' or 'ukf', got {self.estimator!r}")
        if not self.cautious >= 0:
            raise ConfigError(
                "cautious", f"the caution weight must be >= 0 (0: certainty equivalence), got {self.cautious}"
            )
        if self.prior and self.networks.residual:
            raise ConfigError("prior", "prior already adds e to f (f = f_nominal + NN_f); turn residual off")


class Adaptive:
    """The paper's scheme: NN_f, NN_G tuned by the EKF (29)-(32), used in (35) through (34).

    The options of :class:`AdaptiveConfig` change the estimator, the law or the model structure;
    with all of them off, ``step`` runs exactly the paper's equations (the same floating-point operations).
    """

    name = "adaptive"

    def __init__(self, law: Law, config: AdaptiveConfig) -> None:
        self.law = law
        self.config = config
        self.nets = config.networks
        self.labels = {"z": self.nets.labels(), "h_hat": ["h1", "h2", "h5"]}
        self.plain = not (config.cautious > 0 or config.prior or config.learned_gains)

    def reset(self, T: float, rng: np.random.Generator) -> None:
        c, a = self.config, self.nets.alpha
        self.T = T
        z0 = rng.normal(0.0, c.weight_std, a)
        if c.output_weight_std is not None:  # rescale the same draws: the random stream does not change
            z0[self.nets.output_mask()] *= c.output_weight_std / c.weight_std
        common = {
            "z0": z0,
            "P0": c.P0 * np.eye(a),
            "R": covariance(c.R, 3, "R"),
            "Q": c.Q * np.eye(a) if c.Q > 0 else None,
            "forgetting": c.forgetting,
            "P_max": c.P_max,
        }
        if c.estimator == "ukf":
            self.est = UKF(**common, alpha=c.ukf_alpha, beta=c.ukf_beta, kappa=c.ukf_kappa)
        else:
            self.est = EKF(**common)
        self.ekf = self.est  # the name the telemetry and older callers use
        self.prev: tuple | None = None  # step k-1: x_f, x_G, e, u, nominal prediction of e_k, z, hidden layers
        self.innovation = np.zeros(3)
        self.h_hat = np.zeros(3)

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        nets, c, T = self.nets, self.config, self.T
        if self.prev is not None:  # tune the weights with the error this step revealed, (28)-(32)
            x_f, x_G, e_prev, u_prev, e_nom, z_prev, head = self.prev
            y = e
            if c.prior:  # the networks model only what the nominal functions miss
                y = e - e_nom
                y[2] = wrap(y[2])
            if c.estimator == "ukf":
                self.innovation = self.est.update(y, None, lambda Z: nets.h(Z, x_f, x_G, e_prev, u_prev))
            else:  # the hidden layers at z_k are last step's, unless something changed z since
                self.innovation = self.est.update(
                    y, lambda z: nets.h_and_jacobian(z, x_f, x_G, e_prev, u_prev, head if z is z_prev else None)
                )
        x_f, x_G = nets.inputs(e, r[3], r[4])
        z = self.est.z
        head = nets.head(z, x_f, x_G, e)
        if self.plain:
            f_hat, G_hat = nets.forward(z, x_f, x_G, e, head)
            self.h_hat = np.array([G_hat[0, 1], f_hat[0] - e[0], f_hat[2] - e[2]])  # (34)
            u = self.law.control(e, self.h_hat, r[3], T)
        else:
            u = self._control(e, r, x_f, x_G, head)
        e_nom = f_true(e, r[3], r[4], T) + G_true(e, T) @ u if c.prior else None
        self.prev = (x_f, x_G, e, u, e_nom, z, head)
        return u

    def _control(self, e: np.ndarray, r: np.ndarray, x_f: np.ndarray, x_G: np.ndarray, head: tuple) -> np.ndarray:
        """(35) through (34) with the options: nominal prior, learned input gains, cautious law."""
        c, T = self.config, self.T
        f, G, df, dG = self.nets.jacobians(self.est.z, x_f, x_G, e, head)
        if c.prior:
            f = f + f_true(e, r[3], r[4], T)
            G = G + G_true(e, T)
        theta = np.array([G[0, 1], f[0] - e[0], f[2] - e[2], T, T])  # h1, h2, h5 (34), b_v, b_omega
        J = np.stack([dG[0, 1], df[0], df[2], np.zeros_like(df[0]), np.zeros_like(df[0])])  # (5, alpha)
        if c.learned_gains:
            lo, hi = GAIN_RANGE[0] * T, GAIN_RANGE[1] * T
            theta[3], theta[4] = np.clip(-G[0, 0], lo, hi), np.clip(-G[2, 1], lo, hi)
            J[3], J[4] = -dG[0, 0], -dG[2, 1]
        self.theta, self.h_hat = theta, theta[:3]
        if c.cautious > 0:
            return self.law.cautious_control(e, theta, self.est.project(J), r[3], T, c.cautious)
        if c.learned_gains:
            return self.law.cautious_control(e, theta, None, r[3], T, 0.0)
        return self.law.control(e, self.h_hat, r[3], T)

    def telemetry(self) -> dict[str, np.ndarray | float]:
        trace = float(self.est.diag_P().sum())
        return {
            "z": self.est.z,
            "trace_P": trace,
            "mean_diag_P": trace / self.nets.alpha,  # what np.mean computes, to the bit
            "innovation": self.innovation,
            "h_hat": self.h_hat,
        }


class Corradini:
    """The non-adaptive law (35) given the nominal functions h1 = T e2, h2 = T v_r cos e3, h5 = T omega_r."""

    name = "corradini"
    labels: dict[str, list[str]] = {"h_hat": ["h1", "h2", "h5"]}

    def __init__(self, law: Law) -> None:
        self.law = law

    def reset(self, T: float, rng: np.random.Generator) -> None:
        self.T = T
        self.h_hat = np.zeros(3)

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        self.h_hat = h_true(e, r[3], r[4], self.T)
        return self.law.control(e, self.h_hat, r[3], self.T)

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return {"h_hat": self.h_hat}


@dataclass(frozen=True)
class KanayamaGains:
    Kx: float = 10.0
    Ky: float = 64.0
    Ktheta: float = 16.0

    def __post_init__(self) -> None:
        for name in ("Kx", "Ky", "Ktheta"):
            if not getattr(self, name) > 0:
                raise ConfigError(name, f"Kanayama gains must be positive, got {getattr(self, name)}")


class Kanayama:
    """Kanayama et al.'s law: v = v_r cos e3 + Kx e1, omega = omega_r + v_r (Ky e2 + Ktheta sin e3)."""

    name = "kanayama"
    labels: dict[str, list[str]] = {}

    def __init__(self, law: Law, gains: KanayamaGains) -> None:
        self.law = law  # only its limits are used
        self.g = gains

    def reset(self, T: float, rng: np.random.Generator) -> None:
        self.T = T

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        g, v_r = self.g, r[3]
        v = v_r * np.cos(e[2]) + g.Kx * e[0]
        omega = r[4] + v_r * (g.Ky * e[1] + g.Ktheta * np.sin(e[2]))
        if self.law.v_max is not None:
            v = np.clip(v, -self.law.v_max, self.law.v_max)
        if self.law.omega_max is not None:
            omega = np.clip(omega, -self.law.omega_max, self.law.omega_max)
        return np.array([v, omega])

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return {}


# Named variants of the adaptive controller: AdaptiveConfig fields (and Networks fields under
# "networks") that override the scenario's [controller.adaptive] table. "adaptive" is the table as is.
# One variant per option alone, and "adaptive-best": the combination that measured best on the
# MuJoCo eight-* scenarios (the nominal prior, with forgetting so that it keeps adapting after an
# event, P bounded). The README's ablation table gives the figures and the command that made them.
# With no Q and no forgetting the EKF depends on P0 and R only through P0 / R.
VARIANTS: dict[str, dict] = {
    "adaptive": {},
    "adaptive-ukf": {"estimator": "ukf", "ukf_alpha": 0.1},
    "adaptive-cautious": {"cautious": 1.0},
    "adaptive-forget": {"forgetting": 0.9999, "P_max": 0.1},
    "adaptive-q": {"Q": 1e-8, "P_max": 0.1},
    "adaptive-prior": {"prior": True, "output_weight_std": 0.0, "P0": 1e-5, "R": 0.1},
    "adaptive-gains": {"learned_gains": True},
    "adaptive-best": {
        "prior": True,
        "output_weight_std": 0.0,
        "P0": 1e-5,
        "R": 0.1,
        "forgetting": 0.999,
        "P_max": 1e-4,
    },
}

CONTROLLERS = (*VARIANTS, "corradini", "kanayama")
