"""The paper's simulated plant: the stochastic error model (7) with the true f, G (5)-(6).

e_k = f_{k-1} + G_{k-1} u_{k-1} + eps_k, eps_k ~ N(0, R), evaluated with the plant's own sampling
interval T_p (T until a ``control_period`` event sets T_p = factor T, the paper's T -> 1.5 T).
The pose is reconstructed from e and the reference by inverting (2).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from mlpfac.error_model import G_true, f_true, h_true, pose_from_error, tracking_error
from mlpfac.estimators import covariance
from mlpfac.events import Event
from mlpfac.exceptions import ConfigError


@dataclass(frozen=True)
class KinematicConfig:
    noise_cov: float | tuple[float, ...] | tuple[tuple[float, ...], ...] = (
        1e-6  # covariance of eps_k: scalar (R I_3), diagonal or 3x3
    )

    def __post_init__(self) -> None:
        covariance(self.noise_cov, 3, "noise_cov")


class KinematicPlant:
    supported_events = frozenset({"control_period", "sensor_delay"})

    def __init__(self, config: KinematicConfig, T: float, ref: np.ndarray) -> None:
        self.T = T
        self.ref = ref  # (N + 1, 5) reference samples at k T
        R = covariance(config.noise_cov, 3, "noise_cov")
        w, V = np.linalg.eigh(R)
        self.L = V * np.sqrt(np.maximum(w, 0.0)) if np.any(w > 0) else None  # L L' = R

    def reset(self, q0: np.ndarray, rng: np.random.Generator, u0: np.ndarray | None = None) -> None:
        """``u0`` is ignored: the error model (7) has no velocity state."""
        self.rng = rng
        self.k = 0
        self.T_p = self.T
        self.e = tracking_error(q0, self.ref[0])
        self.delay = 0
        self.history: deque[np.ndarray] = deque([self.true_pose()], maxlen=1)
        self._tele = {"u_meas": np.zeros(2), "h_true": np.zeros(3)}

    def true_pose(self) -> np.ndarray:
        return pose_from_error(self.e, self.ref[self.k])

    def measure(self) -> np.ndarray:
        return self.history[0]

    def step(self, u: np.ndarray) -> None:
        r, e, Tp = self.ref[self.k], self.e, self.T_p
        self._tele = {"u_meas": np.array(u, dtype=float), "h_true": h_true(e, r[3], r[4], Tp)}
        e_next = f_true(e, r[3], r[4], Tp) + G_true(e, Tp) @ u  # (7)
        if self.L is not None:
            e_next = e_next + self.L @ self.rng.standard_normal(3)
        self.e = e_next
        self.k += 1
        self.history.append(self.true_pose())

    def check_event(self, event: Event, where: str) -> None:
        if event.kind not in self.supported_events:
            raise ConfigError(
                where,
                f"the kinematic plant cannot apply a {event.kind!r} event (it supports {', '.join(sorted(self.supported_events))})",
            )

    def apply(self, event: Event) -> str:
        if event.kind == "control_period":
            old, self.T_p = self.T_p, float(event.params["factor"]) * self.T
            return f"plant sampling interval {old:g} -> {self.T_p:g} s (controller keeps T = {self.T:g} s)"
        n = int(event.params["steps"])
        old, self.delay = self.delay, n
        self.history = deque(self.history, maxlen=n + 1)
        return f"sensor delay {old} -> {n} control steps"

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return self._tele

    def diverged(self) -> str | None:
        return None if np.all(np.isfinite(self.e)) else "non-finite tracking error"

    def geometry(self) -> list[dict]:
        return [
            {
                "name": "chassis",
                "type": "box",
                "size": [0.15, 0.1, 0.04],
                "pos": [0.05, 0.0, 0.06],
                "quat": [1, 0, 0, 0],
                "rgba": [0.3, 0.5, 0.8, 1],
            },
        ]
