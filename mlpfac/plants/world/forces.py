"""What the ``force`` events of a run apply, control step by control step: the schedule the MuJoCo
plant writes into the robot's applied forces (:mod:`mlpfac.plants.mujoco.world`) and that
``oracle-dynamic`` is told (:mod:`mlpfac.control.dynamic`), made once when a run starts.

A force given relative to the robot (a share of its weight, a push's velocity change) is put in
newtons once, for the robot the run is on (:func:`in_newtons`, from the plant's mass and gravity),
and both are given those newtons. A schedule row is (fx, fy) in the world's axes, (fx, fy) in the
robot's (turned with it every control step by the compiled step) and torque_z. The noise of a force
with ``std`` is drawn from a stream of its own, named by the run's seed and the event's place among
the scenario's events, so the plant and the oracle told it draw the same, every controller of a
seed meets the same noise, and no other stream of the run moves; with ``tau_s`` the same draws
drive a first-order Gauss-Markov process (:func:`gust`).
"""

from __future__ import annotations

import math

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plants.events import FORCE_MAX, Force

FORCE_STREAM = 0x666F7263  # tags the streams of the forces' noise apart from every other stream of a run
RELATIVE = {"fx": ("fx_mg", "dv_x"), "fy": ("fy_mg", "dv_y"), "std": ("std_mg",)}  # each one's relative keys


def event_step(time: float, T: float) -> int:
    """The control step at which the runner applies an event at ``time`` s: the first k with
    time <= k T (within 1e-9 s)."""
    k = max(0, int(math.ceil((time - 1e-9) / T)))
    while k > 0 and time <= (k - 1) * T + 1e-9:
        k -= 1
    while time > k * T + 1e-9:
        k += 1
    return k


def in_newtons(force: Force, mass: float, g: float, T: float, where: str = "") -> Force:
    """``force`` on a robot of ``mass`` kg under gravity ``g`` (m/s^2), in newtons: a share of the
    weight times m g, a push's velocity change dv as the force m dv / (its steps x T) that gives it
    over the control steps it acts. A force that is already in newtons is returned as it is (its
    bits untouched). Beyond what a force may be, a ConfigError naming the relative key (``where``
    the event)."""
    if not force.relative:
        return force
    weight = mass * g
    lasts = None if force.steps(T) is None else force.steps(T) * T

    def axis(n, share, dv):
        return share * weight if share is not None else mass * dv / lasts if dv is not None else n

    values = {
        "fx": axis(force.fx, force.fx_mg, force.dv_x),
        "fy": axis(force.fy, force.fy_mg, force.dv_y),
        "std": force.std if force.std_mg is None else force.std_mg * weight,
    }
    for key, value in values.items():
        if value is not None and abs(value) > FORCE_MAX:
            rel = next(k for k in RELATIVE[key] if k in force.params)
            raise ConfigError(
                f"{where} {rel}".strip(),
                f"{force.params[rel]:g} is {value:.4g} N on this robot ({mass:.4g} kg), beyond the {FORCE_MAX:g} N "
                "a force may be",
            )
    keep = {k: v for k, v in force.params.items() if k in ("torque_z", "frame", "duration", "period", "tau_s")}
    return Force(time=force.time, **keep, **{k: v for k, v in values.items() if v is not None})


def in_newtons_all(events, mass: float, g: float, T: float, where: str = "[[events]]") -> tuple:
    """``events`` with each ``force`` among them in newtons (:func:`in_newtons`), each in its place
    (a force's noise stream is named by its place); ``where`` names the events in errors (#1 ...)."""
    return tuple(
        in_newtons(ev, mass, g, T, f"{where} #{i + 1}") if isinstance(ev, Force) else ev for i, ev in enumerate(events)
    )


def gust(w: np.ndarray, std: float, tau: float, T: float) -> np.ndarray:
    """Standard normal draws ``w`` (n, 2) as a gust of standard deviation ``std`` and correlation time
    ``tau`` s, held each control step of T s: the first-order Gauss-Markov process
    x_{k+1} = a x_k + std sqrt(1 - a^2) w_{k+1}, a = exp(-T / tau), the exact discretisation of
    dx = -x / tau dt + std sqrt(2 / tau) dW, started from its stationary law (x_0 = std w_0): its
    autocorrelation is std^2 a^|j|, exp(-|j| T / tau), its spectrum flat up to 1 / (2 pi tau) Hz."""
    from mlpfac.elementary import exp

    a = exp(-T / tau)
    b = std * math.sqrt((1.0 - a) * (1.0 + a))
    out = np.empty_like(w)
    x, y = std * float(w[0, 0]), std * float(w[0, 1])
    out[0] = x, y
    for k in range(1, len(w)):
        x, y = a * x + b * float(w[k, 0]), a * y + b * float(w[k, 1])
        out[k] = x, y
    return out


def schedule(force: Force, index: int, T: float, steps: int, seed) -> np.ndarray:
    """What ``force`` (in newtons: :func:`in_newtons`) applies at each of a run's ``steps`` control
    steps (steps, 5): zero before its step and after a push; a sinusoid of amplitude (fx, fy,
    torque_z) from zero; noise of ``std`` on (fx, fy), white or a gust of correlation time ``tau_s``
    (:func:`gust`). ``index``: its place among the scenario's events; ``seed``: the run's."""
    from mlpfac.elementary import sin
    from mlpfac.normal import standard_normal

    if force.relative:  # its newtons are the robot's: a plant's or an oracle's schedule is made from those
        raise ValueError(f"{force.describe()} is given relative to the robot: put it in newtons first (in_newtons)")
    out = np.zeros((steps, 5))
    k0 = event_step(force.time, T)
    k1 = steps if force.steps(T) is None else min(steps, k0 + force.steps(T))
    if k0 >= k1:
        return out
    n = k1 - k0
    rows = np.tile(np.array([force.fx or 0.0, force.fy or 0.0, force.torque_z or 0.0]), (n, 1))
    if force.std:
        rng = np.random.default_rng(np.random.SeedSequence([FORCE_STREAM, index, *_entropy(seed)]))
        w = standard_normal(rng, (n, 2))
        rows[:, :2] += force.std * w if force.tau_s is None else gust(w, force.std, force.tau_s, T)
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
