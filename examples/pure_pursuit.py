"""A pure-pursuit tracking law as an mlpfac plug-in: copy this file and change ``step``.

Run it (from the folder that holds this file, or give the path from where you are):

    mlpfac run eight-wheel-radius --controller pure_pursuit.py:PurePursuit
    mlpfac sweep eight-wheel-radius --controllers pure_pursuit.py:PurePursuit,oracle,corradini --seeds 0-9

The contract (mlpfac.control.plugins): a class built as ``Class(T=..., **params)`` whose ``step(e, r)``
returns (v, omega); ``reset(rng)`` and ``telemetry()`` are optional.
"""

from __future__ import annotations

import numpy as np

from mlpfac.elementary import cos, sin  # the same bits on every machine (math's differ by C library)


class PurePursuit:
    """Steer along the arc through a point ``lookahead`` metres ahead of the reference pose; the
    speed is the reference's, corrected by the along-track error.

    e = (e1, e2, e3): the reference pose seen from the robot (e1 ahead, e2 to the left, e3 the
    heading error); r = (x_r, y_r, theta_r, v_r, omega_r).
    """

    name = "pure-pursuit"  # its name in run folders and tables (default: the class name)
    labels = {"target": ["x", "y"]}  # component names of a telemetry array, for the viewer

    def __init__(self, T: float, lookahead: float = 0.15, k_v: float = 6.0, v_max: float = 2.0) -> None:
        if not lookahead > 0:
            raise ValueError(f"lookahead must be positive, got {lookahead}")
        self.T, self.lookahead, self.k_v, self.v_max = T, lookahead, k_v, v_max
        self.curvature = 0.0
        self.target = np.zeros(2)

    def reset(self, rng: np.random.Generator) -> None:
        """Called before every run; this law draws nothing from ``rng``."""
        self.curvature = 0.0
        self.target[:] = 0.0

    def step(self, e: np.ndarray, r: np.ndarray) -> tuple[float, float]:
        e1, e2, e3 = e
        v_r = r[3]
        # the point `lookahead` ahead of the reference pose, in the robot's frame
        x, y = e1 + self.lookahead * cos(e3), e2 + self.lookahead * sin(e3)
        self.target[:] = x, y
        self.curvature = 2.0 * y / (x * x + y * y)  # the arc through the robot's origin and (x, y)
        v = min(max(v_r * cos(e3) + self.k_v * e1, -self.v_max), self.v_max)
        return v, v * self.curvature

    def telemetry(self) -> dict[str, float | np.ndarray]:
        return {"curvature": self.curvature, "target": self.target}
