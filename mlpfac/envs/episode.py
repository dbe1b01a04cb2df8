"""One episode: the run ``mlpfac run SCENARIO --seed s`` starts, stepped from outside.

The episode builds what :func:`mlpfac.loop.runner.run` builds (the reference, the plant, the
seeded streams, the events) into the same :class:`~mlpfac.loop.closed_loop.ClosedLoop`, and steps
it with the loop's own halves of a step: :meth:`~ClosedLoop.observe` (the errors (2) a controller
is given), then the command the caller gives (:meth:`~ClosedLoop.command`, the runner's divergence
test) and the plant's step (:meth:`~ClosedLoop.actuate`). So a plug-in stepped through an episode
records what ``mlpfac run --controller`` records, to the bit.
"""

from __future__ import annotations

import time

import numpy as np

from mlpfac.control.baselines import Stepped
from mlpfac.loop.closed_loop import FLUSH_EVERY, ClosedLoop
from mlpfac.loop.factory import make_plant
from mlpfac.loop.metrics import metrics
from mlpfac.loop.record import RunRecord
from mlpfac.loop.runner import reference
from mlpfac.model import tracking_errors
from mlpfac.scenario.parse import Scenario

AGENT = "agent"  # the controller's name in an episode's record and recording


class Agent(Stepped):
    """The controller slot of an episode's closed loop: the command comes from outside (the
    environment's action), so it draws nothing, keeps nothing and records no telemetry."""

    name = AGENT
    labels: dict[str, list[str]] = {}

    def __init__(self, level: str) -> None:
        self.level = level

    def reset(self, rng) -> None:
        pass

    def telemetry(self) -> dict:
        return {}


class Episode:
    """The closed loop of one run of ``scn`` (B = 1), stepped one command at a time.

    ``k`` is the step whose command is awaited; ``inputs`` what a controller is given for it
    (``(e, r)``, or ``(Observation,)`` at the torque level); ``e_true`` the true error (2) there.
    ``sink``: a recording (:mod:`mlpfac.log`) sent as a run's is."""

    def __init__(self, scn: Scenario, level: str, sink=None, plant=None, ref=None) -> None:
        self.scn, self.sink = scn, sink
        if ref is None:
            ref, rates, end = reference(scn)
        else:
            ref, rates, end = ref
        self.ref = ref
        plant = plant if plant is not None else make_plant(scn, ref)
        self.loop = ClosedLoop([scn], ref, plant, Agent(level), True, False, rates, end)
        self.rec: RunRecord = self.loop.recs[0]
        self.N, self.k = scn.steps, 0
        self.e_true = np.zeros((1, 3))
        self.ptele: np.ndarray | None = None  # the plant's telemetry rows, for a kernel stepping many robots
        self.done = False
        self.wall = time.perf_counter()
        if sink is not None:
            sink.begin(self.rec, geometry=self.loop.geometry(), ref_path=ref[: self.N if end is None else end[0]])
        self.advance(0)

    @property
    def plant(self):
        return self.loop.plant

    def advance(self, k: int) -> None:
        """Step k's inputs, or the episode's end: the run's end (k = N), the reference's, a divergence."""
        self.k = k
        if k < self.N and self.loop.live and self.loop.begin(k):
            self.inputs = self.loop.observe(k)
        else:
            self.inputs = self.loop.observe(min(k, self.N))  # the state it ended in (not recorded)
            self.finish()
        tracking_errors(self.loop._q, self.ref[min(k, self.N)], self.e_true)

    def act(self, u: np.ndarray) -> None:
        """Step k with the command ``u`` (2,): (v, omega), or the wheels' torques at the torque level."""
        k = self.k
        stepped = self.loop.command(k, np.asarray(u, dtype=float).reshape(1, 2)) and self.loop.actuate(k)
        if stepped and self.sink is not None and (k + 1) % FLUSH_EVERY == 0:
            self.sink.flush(self.rec, k + 1)
        self.advance(k + 1)

    @property
    def terminated(self) -> bool:
        """The episode ended before the run's end: it diverged (the plant, the error bound, MuJoCo's
        warning), or the reference stopped being finite."""
        return self.done and self.rec.status != "ok"

    def finish(self) -> None:
        if self.done:
            return
        self.done = True
        self.loop.finish(time.perf_counter() - self.wall)
        if self.sink is not None:
            self.sink.end(self.rec)

    def metrics(self) -> dict:
        """The run's figures (what metrics.json holds: ``phases`` against the true pose), at its end."""
        return metrics(self.rec)
