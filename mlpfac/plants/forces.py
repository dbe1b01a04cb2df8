"""What the ``force`` events of a run apply, control step by control step: the schedule the MuJoCo
plant writes into the robot's applied forces (:mod:`mlpfac.plants.mujoco_world`) and that
``oracle-dynamic`` is told (:mod:`mlpfac.control.dynamic`), made once when a run starts.

A schedule row is (fx, fy) in the world's axes, (fx, fy) in the robot's (turned with it every
control step by the compiled step) and torque_z. The noise of a force with ``std`` is drawn from a
stream of its own, named by the run's seed and the event's place among the scenario's events, so
the plant and the oracle told it draw the same, every controller of a seed meets the same noise,
and no other stream of the run moves.
"""

from __future__ import annotations

import math

import numpy as np

from mlpfac.plants.events import Force

FORCE_STREAM = 0x666F7263  # tags the streams of the forces' noise apart from every other stream of a run


def event_step(time: float, T: float) -> int:
    """The control step at which the runner applies an event at ``time`` s: the first k with
    time <= k T (within 1e-9 s)."""
    k = max(0, int(math.ceil((time - 1e-9) / T)))
    while k > 0 and time <= (k - 1) * T + 1e-9:
        k -= 1
    while time > k * T + 1e-9:
        k += 1
    return k


def schedule(force: Force, index: int, T: float, steps: int, seed) -> np.ndarray:
    """What ``force`` applies at each of a run's ``steps`` control steps (steps, 5): zero before its
    step and after a push; a sinusoid of amplitude (fx, fy, torque_z) from zero; noise of ``std``
    on (fx, fy) held a step. ``index``: its place among the scenario's events; ``seed``: the run's."""
    from mlpfac.elementary import sin
    from mlpfac.normal import standard_normal

    out = np.zeros((steps, 5))
    k0 = event_step(force.time, T)
    k1 = steps if force.steps(T) is None else min(steps, k0 + force.steps(T))
    if k0 >= k1:
        return out
    n = k1 - k0
    rows = np.tile(np.array([force.fx or 0.0, force.fy or 0.0, force.torque_z or 0.0]), (n, 1))
    if force.std:
        rng = np.random.default_rng(np.random.SeedSequence([FORCE_STREAM, index, *_entropy(seed)]))
        rows[:, :2] += force.std * standard_normal(rng, (n, 2))
    elif force.period is not None:
        w = 2.0 * math.pi / force.period
        rows *= np.array([[sin(w * (j * T))] for j in range(n)])
    cols = [0, 1] if force.frame in (None, "world") else [2, 3]
    out[k0:k1, cols] = rows[:, :2]
    out[k0:k1, 4] = rows[:, 2]
    return out


def force_schedule(events, T: float, steps: int, seed) -> np.ndarray | None:
    """The sum of the ``force`` events' schedules (:func:`schedule`) over a run, in the events' order,
    or None when there is none."""
    rows = [schedule(ev, i, T, steps, seed) for i, ev in enumerate(events) if isinstance(ev, Force)]
    if not rows:
        return None
    for more in rows[1:]:
        rows[0] += more
    return rows[0]


def run_seed(rng: np.random.Generator):
    """The seed a run's Generator was made from (the entropy of its seed sequence: the scenario's
    seed for the runner's streams, :func:`mlpfac.loop.closed_loop.seeded_generators`)."""
    return rng.bit_generator.seed_seq.entropy


def _entropy(seed) -> list[int]:
    """A seed (a whole number or a list of them, a SeedSequence's entropy) as a list of whole numbers."""
    return [int(x) for x in seed] if isinstance(seed, list | tuple) else [int(seed)]
