"""The plant interface shared by the kinematic model (7) and the MuJoCo robot.

One control step of the closed loop (see :mod:`mlpfac.loop.runner`)::

    q_meas = plant.measure()             # pose (x, y, theta) the controller sees
    u = controller.step(e(q_meas, r_k), r_k)
    plant.step(u)                        # hold u = (v, omega) for one control period

Events change the plant mid-run without telling the controller.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from mlpfac.plants.events import Event


class Plant(Protocol):
    """What the closed loop needs from a plant. Poses are (x, y, theta) of the axle midpoint."""

    T: float
    """Nominal control period in seconds (what the controller believes)."""

    supported_events: frozenset[str]

    batched: bool
    """True: one object steps B seeds (poses (B, 3), as the kinematic model); False: one seed, and
    the runner steps a batch as one object per seed."""

    def reset(self, q0: np.ndarray, rng: np.random.Generator, u0: np.ndarray | None = None) -> None:
        """Start a run at pose ``q0``, moving at ``u0`` = (v, omega) (None: at rest); ``rng`` drives noise."""

    def measure(self) -> np.ndarray:
        """Pose seen by the controller: (3,), with noise and delay applied."""

    def true_pose(self) -> np.ndarray:
        """Pose of the simulated robot now: (3,), heading continuous (not wrapped)."""

    def step(self, u: np.ndarray) -> None:
        """Apply u = (v, omega) for one control period."""

    def apply(self, event: Event) -> str:
        """Apply an event now; return a one-line description of what changed (old -> new)."""

    def check_event(self, event: Event, where: str) -> None:
        """Raise ConfigError(where, ...) if this plant cannot apply ``event`` (unknown kind/param/body)."""

    def telemetry(self) -> dict[str, np.ndarray | float]:
        """Per-step values for the record and the log, same keys and shapes every step.

        Keys used across the project (a plant provides what it knows):
        ``u_meas`` (2,) measured (v, omega); ``wheel_cmd`` (2,) and ``wheel_meas`` (2,) left/right
        wheel speeds in rad/s; ``h_true`` (3,) the true h1, h2, h5 (kinematic plant only).
        """

    def diverged(self) -> str | None:
        """A reason string if the simulation left its valid range (flipped, airborne, non-finite)."""

    def elapsed(self, n: int) -> float:
        """Simulated seconds after the run's ``n`` control steps: n T for the kinematic model, whose
        steps are its time; a robot's physics clock (the periods it was held for)."""

    def provenance(self) -> dict:
        """What it simulates, recorded in a scenario's ``[provenance]`` and checked when a
        config.toml runs again ({} for the kinematic model, which is all in the scenario)."""

    def found(self) -> dict:
        """The ``[plant]`` keys the scenario left unset and the plant found in its model ({}: none)."""

    def terrain_record(self) -> dict:
        """The terrain it drives on, as a recording draws it (:meth:`mlpfac.plants.world.layout.Terrain.as_dict`;
        {} without one)."""

    def geometry(self) -> list[dict]:
        """Static shapes of the robot for the 3D view, relative to the measured frame.

        Each: {"name", "type" ("box"|"cylinder"|"sphere"), "size" (MuJoCo convention),
        "pos" (3,), "quat" (w, x, y, z), "rgba" (4,)}.
        """


@runtime_checkable
class CompiledPlant(Protocol):
    """A plant whose control step is compiled (:mod:`mlpfac.plants.mujoco.compiled`): the closed loop runs
    it, with a law kernel, from one event or log flush to the next (:mod:`mlpfac.loop.compiled`)."""

    _n: int
    """Physics steps in the control step now (an event can change it)."""

    def kernel_args(self) -> tuple:
        """The compiled step's robot (its arrays), as the segment kernel takes it."""
        ...

    def draws(self, n: int) -> np.ndarray:
        """The next n pose-noise draws (n, 3) of the plant's stream."""
        ...

    def why(self, code: int) -> str | None:
        """The words for a divergence code of the compiled step."""
        ...
