"""Controllers with one interface: the adaptive MLP-EKF law, Corradini's law with the nominal
functions, and Kanayama's law. Any controller runs on any plant.

``step(e_k, r_k)`` takes the tracking error (2) and the reference sample
r_k = (x_r, y_r, theta_r, v_r, omega_r) and returns u_k = (v, omega).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from mlpfac.error_model import h_true
from mlpfac.estimators import EKF, covariance
from mlpfac.exceptions import ConfigError
from mlpfac.law import Law
from mlpfac.networks import Networks


class Controller(Protocol):
    name: str
    labels: dict[str, list[str]]

    def reset(self, T: float, rng: np.random.Generator) -> None: ...

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray: ...

    def telemetry(self) -> dict[str, np.ndarray | float]: ...


@dataclass(frozen=True)
class AdaptiveConfig:
    """The MLP-EKF scheme's choices; the paper fixes L_f, L_G and P0 only."""

    networks: Networks = field(default_factory=Networks)
    P0: float = 5.0  # initial covariance P_0 = P0 I_alpha
    R: float | tuple[float, ...] = 1e-6  # EKF measurement noise covariance (scalar or diagonal)
    Q: float = 0.0  # EKF process noise, Q = Q I_alpha
    forgetting: float = 1.0  # P /= forgetting after each update (1: none)
    P_max: float | None = None  # cap on max diag P
    weight_std: float = 0.1  # initial weights ~ N(0, weight_std^2)

    def __post_init__(self) -> None:
        for name in ("P0", "weight_std"):
            if not getattr(self, name) > 0:
                raise ConfigError(name, f"must be positive, got {getattr(self, name)}")
        if self.Q < 0:
            raise ConfigError("Q", f"a covariance must be non-negative, got {self.Q}")
        covariance(self.R, 3, "R")


class Adaptive:
    """The paper's scheme: NN_f, NN_G tuned by the EKF (29)-(32), used in (35) through (34)."""

    name = "adaptive"

    def __init__(self, law: Law, config: AdaptiveConfig) -> None:
        self.law = law
        self.config = config
        self.nets = config.networks
        self.labels = {"z": self.nets.labels(), "h_hat": ["h1", "h2", "h5"]}

    def reset(self, T: float, rng: np.random.Generator) -> None:
        c, a = self.config, self.nets.alpha
        self.T = T
        self.ekf = EKF(
            z0=rng.normal(0.0, c.weight_std, a),
            P0=c.P0 * np.eye(a),
            R=covariance(c.R, 3, "R"),
            Q=c.Q * np.eye(a) if c.Q > 0 else None,
            forgetting=c.forgetting,
            P_max=c.P_max,
        )
        self.prev: tuple | None = None  # (x_f, x_G, e, u) of step k-1
        self.innovation = np.zeros(3)
        self.h_hat = np.zeros(3)

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        nets = self.nets
        if self.prev is not None:  # tune the weights with the error this step revealed, (28)-(32)
            x_f, x_G, e_prev, u_prev = self.prev
            self.innovation = self.ekf.update(e, lambda z: nets.h_and_jacobian(z, x_f, x_G, e_prev, u_prev))
        x_f, x_G = nets.inputs(e, r[3], r[4])
        f_hat, G_hat = nets.forward(self.ekf.z, x_f, x_G, e)
        self.h_hat = np.array([G_hat[0, 1], f_hat[0] - e[0], f_hat[2] - e[2]])  # (34)
        u = self.law.control(e, self.h_hat, r[3], self.T)
        self.prev = (x_f, x_G, e, u)
        return u

    def telemetry(self) -> dict[str, np.ndarray | float]:
        P = self.ekf.P
        d = np.diagonal(P)
        return {
            "z": self.ekf.z,
            "trace_P": float(d.sum()),
            "mean_diag_P": float(d.mean()),
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
VARIANTS: dict[str, dict] = {"adaptive": {}}

CONTROLLERS = (*VARIANTS, "corradini", "kanayama")
