"""The ``[controller.mpc]`` table of ``mpc`` and ``limit`` (:mod:`mlpfac.control.mpc`), each key
checked when it is made (a bad one names its key)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from mlpfac.exceptions import ConfigError


@dataclass(frozen=True)
class MpcConfig:
    """The ``[controller.mpc]`` table: the planner's and the estimator's settings."""

    horizon_s: float = 0.4  # s of the plan (rounded to control steps)
    knots: int = 3  # the plan's knots (a linear spline of the commands over the horizon)
    iterations: int = 3  # Gauss-Newton steps a control step, at most
    tolerance: float = 0.05  # ... fewer once a step lowers the plan's cost by less than this share
    settled_m: float = 1.0e-4  # ... or once the plan's RMS residual is below this (m)
    reuse: int = 2  # control steps a settled plan's Jacobian (and the estimator's step Jacobian) serve again (0: new ones every step)
    heading_m: float = 0.03  # m a radian of heading error costs, against the position's
    heading_end_m: float = 0.3  # ... at the horizon's last step (the plan ends along the path)
    damping: float = 1.0e-3  # mu of the Levenberg-Marquardt step (on diag(J'J)), at least
    trust: float = 1.0  # the largest step on a knot, a share of the commands' scale (the trust radius's ceiling)
    accel_std: float = 0.1  # the estimator's process noise: std of each generalized acceleration (SI units / s^2)
    told_std: float = 0.01  # ... and the std each velocity's estimate loses at an event it is told (SI units)
    slip_gate: float = 5.0  # std devs of its innovation a wheel's measured speed strays from the model's before it counts as slipping (torque level)
    fd_step: float = 1.0e-3  # the knots' finite-difference step, a share of the commands' scale

    LIMITS: ClassVar[dict[str, tuple[float, float]]] = {  # each key's accepted range, closed (horizon_s > 0)
        "horizon_s": (0.0, 10.0),
        "knots": (1, 20),
        "iterations": (1, 10),
        "tolerance": (0.0, 1.0),
        "settled_m": (0.0, 1.0),
        "reuse": (0, 100),
        "heading_m": (0.0, 1.0e3),
        "heading_end_m": (0.0, 1.0e3),
        "damping": (0.0, 1.0e6),
        "trust": (1.0e-3, 100.0),
        "accel_std": (0.0, 1.0e6),
        "told_std": (0.0, 1.0e6),
        "slip_gate": (1.0, 1.0e6),
        "fd_step": (1.0e-9, 1.0),
    }

    def __post_init__(self) -> None:
        for key, (lo, hi) in self.LIMITS.items():
            val = getattr(self, key)
            if isinstance(lo, int):
                if isinstance(val, bool) or not isinstance(val, int) or not lo <= val <= hi:
                    raise ConfigError(key, f"expected a whole number in [{lo}, {hi}], got {val!r}")
            elif not (
                isinstance(val, int | float) and not isinstance(val, bool) and math.isfinite(val) and lo <= val <= hi
            ):
                raise ConfigError(key, f"expected a number in [{lo:g}, {hi:g}], got {val!r}")
        if not self.horizon_s > 0:
            raise ConfigError("horizon_s", f"must be positive, got {self.horizon_s}")
