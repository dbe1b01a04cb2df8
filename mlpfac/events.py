"""Events: changes of the plant at a time of the run, never told to the controller.

Each event kind names its parameters, their types and ranges here, once; a scenario's
``[[events]]`` table is checked against them when the scenario is parsed, on every plant, before
anything runs. What a plant can apply (a body that exists, a period that is a whole number of
physics steps) is the plant's own check, also made before the first step.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from mlpfac.exceptions import ConfigError


@dataclass(frozen=True)
class Param:
    """One event parameter: its type (float, int or str), whether it must be given, and its range."""

    kind: type
    required: bool = True
    minimum: float | None = None  # inclusive lower bound
    positive: bool = False  # > 0

    def check(self, value, where: str) -> float | int | str:
        if self.kind is str:
            if not isinstance(value, str) or not value:
                raise ConfigError(where, f"expected a name, got {value!r}")
            return value
        if self.kind is int:
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(where, f"expected a whole number, got {value!r}")
        elif isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ConfigError(where, f"expected a finite number, got {value!r}")
        if self.positive and not value > 0:
            raise ConfigError(where, f"must be positive, got {value!r}")
        if self.minimum is not None and value < self.minimum:
            raise ConfigError(where, f"must be >= {self.minimum:g}, got {value!r}")
        return value


SCALE = Param(float, positive=True)
EVENT_PARAMS: dict[str, dict[str, Param]] = {
    # chassis mass (and inertia) scaled, or mass added: one of mass_scale / mass_kg; on the root body or `body`
    "payload": {
        "mass_scale": Param(float, required=False, positive=True),
        "mass_kg": Param(float, required=False, positive=True),
        "body": Param(str, required=False),
    },
    "friction": {"mu": SCALE},  # tyre/floor sliding friction set to mu
    "wheel_radius": {"scale": SCALE},  # real wheel radius scaled while the IK keeps the nominal one
    # wheel drive weakened: servo gain and/or torque limit scaled (at least one)
    "actuator": {
        "kv_scale": Param(float, required=False, positive=True),
        "force_scale": Param(float, required=False, positive=True),
    },
    "control_period": {"factor": SCALE},  # the plant holds each command factor * T
    "sensor_delay": {"steps": Param(int, minimum=0)},  # the measured pose is `steps` control steps old
}
EVENT_KINDS = tuple(EVENT_PARAMS)


@dataclass(frozen=True)
class Event:
    """A change of the plant at ``time`` seconds (controller clock), unknown to the controller."""

    time: float
    kind: str
    params: dict[str, float | int | str] = field(default_factory=dict)

    def describe(self) -> str:
        args = ", ".join(f"{k}={v}" for k, v in sorted(self.params.items()))
        return f"{self.kind}({args}) at {self.time:g} s"


def parse_event(table, duration: float, where: str) -> Event:
    """An ``[[events]]`` table -> an :class:`Event`, every parameter checked; ``where`` names it in errors."""
    if not isinstance(table, dict):
        raise ConfigError(where, f"expected a table (time, kind and parameters), got {table!r}")
    params = dict(table)
    t = params.pop("time", None)
    if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t) or t < 0:
        raise ConfigError(f"{where} time", f"an event needs a finite time >= 0 s, got {t!r}")
    if t >= duration:
        raise ConfigError(
            f"{where} time", f"the event at {t:g} s would never happen: the run lasts {duration:g} s (duration)"
        )
    kind = params.pop("kind", None)
    spec = EVENT_PARAMS.get(kind) if isinstance(kind, str) else None
    if spec is None:
        raise ConfigError(f"{where} kind", f"unknown event kind {kind!r}; choose one of {', '.join(EVENT_KINDS)}")
    for key, value in params.items():
        if key not in spec:
            raise ConfigError(f"{where} {key}", f"not a parameter of a {kind!r} event (it takes {', '.join(spec)})")
        params[key] = spec[key].check(value, f"{where} {key}")
    for key, p in spec.items():
        if p.required and key not in params:
            raise ConfigError(f"{where} {key}", f"a {kind!r} event needs {key!r}")
    if kind == "payload" and ("mass_scale" in params) == ("mass_kg" in params):
        raise ConfigError(where, "a payload event takes either 'mass_scale' or 'mass_kg' (not both, not neither)")
    if kind == "actuator" and not params:
        raise ConfigError(where, "an actuator event needs 'kv_scale' and/or 'force_scale'")
    return Event(float(t), kind, params)


class DelayLine:
    """What a ``sensor_delay`` event changes: the measurement is the one taken ``steps`` control
    steps ago (0: the newest). Every plant keeps its measurements in one."""

    def __init__(self, first) -> None:
        self._q: deque = deque([first], maxlen=1)

    def push(self, measurement) -> None:
        self._q.append(measurement)

    def read(self):
        return self._q[0]

    @property
    def steps(self) -> int:
        return self._q.maxlen - 1

    def delay(self, steps: int) -> str:
        """Set the delay; keeps what it holds (a longer delay repeats the oldest until it fills)."""
        old, self._q = self.steps, deque(self._q, maxlen=steps + 1)
        return f"sensor delay {old} -> {steps} control steps"
