"""The run record: every per-step array of one closed-loop run, and the metrics computed from it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class RunRecord:
    """Arrays are preallocated for the whole run; the first ``n`` rows are valid.

    Row k holds step k: the controller clock ``t[k] = k T``, the reference ``ref[k]``
    = (x_r, y_r, theta_r, v_r, omega_r), the pose before the command, the error (2) the controller
    saw, and the command ``u[k]`` = (v, omega) it sent.
    """

    scenario: str
    controller: str
    seed: int
    T: float
    t: np.ndarray  # (N,)
    ref: np.ndarray  # (N, 5)
    pose: np.ndarray  # (N, 3) true pose of the robot
    pose_meas: np.ndarray  # (N, 3) pose the controller saw (noise, delay)
    e: np.ndarray  # (N, 3) tracking error (2) from the measured pose: what the controller used
    e_true: np.ndarray  # (N, 3) tracking error (2) from the true pose: what the metrics use
    u: np.ndarray  # (N, 2) command (v, omega)
    plant: dict[str, np.ndarray] = field(default_factory=dict)  # telemetry, (N, ...) each
    ctrl: dict[str, np.ndarray] = field(default_factory=dict)  # telemetry, (N, ...) each
    events: list[dict] = field(default_factory=list)  # {"time", "kind", "params", "text"}
    n: int = 0
    status: str = "ok"
    reason: str = ""
    warmup_s: float = 2.0  # learning span excluded from the phase metrics
    lost_threshold_m: float | None = None  # the scenario's; None: a share of the path's size (mlpfac.loop.metrics)
    split_s: float | None = None  # time of the first scheduled event: "before" / "after" phases
    labels: dict[str, list[str]] = field(default_factory=dict)  # per-component names of telemetry
    sim_time_s: float = 0.0  # physical time simulated by the plant
    wall_time_s: float = 0.0
    pose_source: str = "truth"  # where pose_meas came from ([plant] pose_source): "truth", "odometry", "fused"
    world: dict = field(default_factory=dict)  # the terrain driven on, as drawn (plants.world.layout.Terrain.as_dict)

    @property
    def estimate_error(self) -> np.ndarray | None:
        """(N, 2) the estimate's error a step, believed - true: |(x, y)| (m) and the heading (rad,
        wrapped); None when the pose was the truth (``pose_source``)."""
        if self.pose_source == "truth":
            return None
        from mlpfac.model import wrap

        d = self.pose_meas - self.pose
        return np.c_[np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]), wrap(d[:, 2])]

    @classmethod
    def allocate(cls, scenario: str, controller: str, seed: int, T: float, N: int) -> RunRecord:
        nan = np.full
        return cls(
            scenario=scenario,
            controller=controller,
            seed=seed,
            T=T,
            t=np.arange(N) * T,
            ref=nan((N, 5), np.nan),
            pose=nan((N, 3), np.nan),
            pose_meas=nan((N, 3), np.nan),
            e=nan((N, 3), np.nan),
            e_true=nan((N, 3), np.nan),
            u=nan((N, 2), np.nan),
        )


def force_windows(events, end: float) -> list[tuple[float, float]]:
    """When a ``force`` event of ``events`` (a record's or a metrics.json's) acts: (start, stop) in
    s, a push for its duration, a force that stays until ``end``."""
    out = []
    for ev in events:
        if isinstance(ev, dict) and ev.get("kind") == "force":
            t, d = float(ev["time"]), (ev.get("params") or {}).get("duration")
            out.append((t, min(end, t + float(d)) if d is not None else end))
    return out
