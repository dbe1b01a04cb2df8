"""Controllers with one interface: the adaptive MLP-EKF law (:mod:`mlpfac.adaptive`), Corradini's
law with the nominal functions, and Kanayama's law. Any controller runs on any plant.

``step(e_k, r_k)`` takes the tracking error (2) and the reference sample
r_k = (x_r, y_r, theta_r, v_r, omega_r) and returns u_k = (v, omega).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from mlpfac.adaptive import VARIANTS
from mlpfac.exceptions import ConfigError
from mlpfac.law import Law


class Controller(Protocol):
    name: str
    labels: dict[str, list[str]]

    def reset(self, rng: np.random.Generator) -> None: ...

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray: ...

    def telemetry(self) -> dict[str, np.ndarray | float]: ...


class Corradini:
    """The non-adaptive law (35) given the nominal functions h1 = T e2, h2 = T v_r cos e3, h5 = T omega_r."""

    name = "corradini"
    labels: dict[str, list[str]] = {"h_hat": ["h1", "h2", "h5"]}

    def __init__(self, law: Law, T: float) -> None:
        self.T = float(T)
        self.law = law
        lam = law
        self._limits = (
            np.inf if lam.v_max is None else float(lam.v_max),
            np.inf if lam.omega_max is None else float(lam.omega_max),
        )

    def reset(self, rng) -> None:
        from mlpfac.kernels import corradini_step, seeds  # numba: imported by a run, not by reading a scenario

        rngs, self.single = seeds(rng)
        T = self.T
        self._kernel = corradini_step
        self._h, self._u = np.zeros((len(rngs), 3)), np.zeros((len(rngs), 2))
        self._tele = {"h_hat": self._h[0] if self.single else self._h}
        corradini_step(np.zeros((0, 3)), 1.0, 0.0, T, *self.law.lambdas, *self._limits, self._h[:0], self._u[:0])

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        E = e[None] if self.single else e
        self._kernel(E, float(r[3]), float(r[4]), self.T, *self.law.lambdas, *self._limits, self._h, self._u)
        return self._u[0].copy() if self.single else self._u

    @property
    def h_hat(self) -> np.ndarray:
        return self._h[0] if self.single else self._h

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return self._tele

    def law_kernel(self) -> tuple[int, np.ndarray]:
        """The law for the compiled closed loop: (its number, its constants) (:func:`mlpfac.kernels.law_step`)."""
        from mlpfac.kernels import CORRADINI

        return CORRADINI, np.array([self.T, *self.law.lambdas, *self._limits], dtype=float)


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

    def __init__(self, law: Law, gains: KanayamaGains, T: float) -> None:
        self.T = float(T)
        self.law = law  # only its limits are used
        self.g = gains
        self._consts = (
            float(gains.Kx),
            float(gains.Ky),
            float(gains.Ktheta),
            np.inf if law.v_max is None else float(law.v_max),
            np.inf if law.omega_max is None else float(law.omega_max),
        )

    def reset(self, rng) -> None:
        from mlpfac.kernels import kanayama_step, seeds

        rngs, self.single = seeds(rng)
        self._kernel = kanayama_step
        self._u = np.zeros((len(rngs), 2))
        self._tele: dict = {}
        kanayama_step(np.zeros((0, 3)), 1.0, 0.0, *self._consts, self._u[:0])  # load the kernel before the run

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        E = e[None] if self.single else e
        self._kernel(E, float(r[3]), float(r[4]), *self._consts, self._u)
        return self._u[0].copy() if self.single else self._u

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return self._tele

    def law_kernel(self) -> tuple[int, np.ndarray]:
        """The law for the compiled closed loop: (its number, its constants) (:func:`mlpfac.kernels.law_step`)."""
        from mlpfac.kernels import KANAYAMA

        return KANAYAMA, np.array(self._consts, dtype=float)


CONTROLLERS = (*VARIANTS, "corradini", "kanayama", "oracle")  # oracle: mlpfac/oracle.py
