"""The paper's simulated plant: the stochastic error model (7) with the true f, G (5)-(6).

e_k = f_{k-1} + G_{k-1} u_{k-1} + eps_k, eps_k ~ N(0, R), evaluated with the plant's own sampling
interval T_p (T until a ``control_period`` event sets T_p = factor T, the paper's T -> 1.5 T).
The pose is reconstructed from e and the reference by inverting (2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.jit import as_rows
from mlpfac.model import cholesky, pose_from_error, tracking_error
from mlpfac.normal import standard_normal
from mlpfac.plants.events import ControlPeriod, DelayLine, Event, SensorDelay
from mlpfac.tables import covariance


@dataclass(frozen=True)
class KinematicConfig:
    noise_cov: float | tuple[float, ...] | tuple[tuple[float, ...], ...] = (
        1e-6  # covariance of eps_k: scalar (R I_3), diagonal or 3x3
    )
    pose_source: str = "truth"  # the model (7) has no wheels and no gyro: only "truth"
    gyro: bool = False  # refused: the model (7) has no body to carry a gyro

    def __post_init__(self) -> None:
        covariance(self.noise_cov, 3, "noise_cov")
        if self.gyro is not False:
            raise ConfigError("gyro", "the kinematic plant (7) has no body to carry a gyro: use a MuJoCo robot")
        if self.pose_source != "truth":
            raise ConfigError(
                "pose_source",
                f"{self.pose_source!r}: the kinematic plant (7) has no wheels to count or gyro to read, its pose is "
                'the truth (with noise_cov): use a MuJoCo robot for "odometry" or "fused"',
            )


class KinematicPlant:
    """Model (7) for one run or a batch of seeds (one T_p and one delay for all, as events apply to all).

    ``reset`` with one Generator: one run, poses (3,); with a sequence of B Generators: B seeds,
    poses (B, 3). Each seed draws its noise from its own generator, all N steps at reset (the same
    stream as one draw of 3 per step), so a seed's run does not depend on the others.
    """

    supported_events = frozenset({"control_period", "sensor_delay"})
    batched = True

    def __init__(self, config: KinematicConfig, T: float, ref: np.ndarray) -> None:
        self.T = T
        self.ref = ref  # (N + 1, 5) reference samples at k T
        R = covariance(config.noise_cov, 3, "noise_cov")
        self.L = cholesky(R) if np.any(R != 0.0) else None  # L L' = R (not LAPACK's: the same bits everywhere)

    def reset(self, q0: np.ndarray, rng, u0: np.ndarray | None = None) -> None:
        """``u0`` is ignored: the error model (7) has no velocity state."""
        from mlpfac.jit import seeds
        from mlpfac.model import kinematic_step

        rngs, self.single = seeds(rng)
        B, N = len(rngs), len(self.ref) - 1
        self.k = 0
        self.T_p = self.T
        self.e = np.tile(tracking_error(q0, self.ref[0]), (B, 1))
        self.noise = np.zeros((max(N, 1), B, 3))  # step k's noise: one contiguous (B, 3)
        if self.L is not None:
            for b, g in enumerate(rngs):  # each seed alone: L eps_k, eps_k ~ N(0, I)
                self.noise[:, b] = np.einsum("nk,jk->nj", standard_normal(g, (N, 3)), self.L)  # not BLAS
        self._pose = np.array([pose_from_error(e, self.ref[0]) for e in self.e])
        self.history = DelayLine(self._pose)
        self._u, self._h = np.zeros((B, 2)), np.zeros((B, 3))
        self._tele = {"u_meas": self._u, "h_true": self._h}
        e0 = np.empty((0, 3))  # load (or compile) the kernel now, not mid-run
        self._kernel = kinematic_step
        kinematic_step(e0, self.ref[0], self.ref[0], self.T, self._u[:0], e0, e0, e0, e0)

    def true_pose(self) -> np.ndarray:
        return self._pose[0] if self.single else self._pose

    def measure(self) -> np.ndarray:
        return self.history.read()[0] if self.single else self.history.read()

    def step(self, u: np.ndarray) -> None:
        k = self.k
        U = as_rows(u, 2)
        self._u[:] = U
        e, pose = np.empty_like(self.e), np.empty_like(self._pose)
        self._kernel(self.e, self.ref[k], self.ref[k + 1], self.T_p, U, self.noise[k], e, pose, self._h)
        self.e, self._pose = e, pose
        self.k = k + 1
        self.history.push(pose)

    def terrain_record(self) -> dict:
        """No terrain: the kinematic model drives on no ground."""
        return {}

    def check_event(self, event: Event, where: str) -> None:
        if event.kind not in self.supported_events:
            raise ConfigError(
                where,
                f"the kinematic plant cannot apply a {event.kind!r} event (it supports {', '.join(sorted(self.supported_events))})",
            )

    def apply(self, event: Event) -> str:
        if isinstance(event, ControlPeriod):
            old, self.T_p = self.T_p, event.factor * self.T
            return f"plant sampling interval {old:g} -> {self.T_p:g} s (controller keeps T = {self.T:g} s)"
        assert isinstance(event, SensorDelay)
        return self.history.delay(event.steps)

    def telemetry(self) -> dict[str, np.ndarray | float]:
        """``u_meas`` (the command, held exactly) and ``h_true`` (34) at the step's start; (B, ...) for a batch."""
        if self.single:
            return {"u_meas": self._u[0], "h_true": self._h[0]}
        return self._tele

    def diverged(self) -> str | None | list[str | None]:
        """A reason, or None; a list of them, one per seed, for a batch."""
        ok = np.isfinite(self.e).all(axis=-1)
        out = [None if x else "non-finite tracking error" for x in ok]
        return out[0] if self.single else out

    def elapsed(self, n: int) -> float:
        return n * self.T

    def provenance(self) -> dict:
        return {}  # the model is all in the scenario

    def found(self) -> dict:
        return {}

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
