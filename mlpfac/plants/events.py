"""Events: changes of the plant at a time of the run, never told to the controller.

Each event kind is a frozen dataclass here, once: its parameters, their types and ranges, checked
by the event itself when it is made, which is when the scenario is parsed, on every plant, before
anything runs. What a plant can apply (a body that exists, a period that is a whole number of
physics steps) is the plant's own check, also made before the first step; a plant dispatches on
the event's class. The one delay line of every plant (what ``sensor_delay`` changes) is here too.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.jit import kernel

# The physically sensible range of each event parameter (checked when the event is made): beyond
# these a robot is not a robot any more, MuJoCo blows up, or a delay line would not fit in memory.
SCALE_MIN, SCALE_MAX = 1e-3, 1e3  # mass, servo gain and torque limit scaled by at most a thousand
MASS_KG_MAX = 1e4  # a payload of at most ten tonnes
OFFSET_MAX = 10.0  # m: a load placed at most this far from the axle midpoint
MU_MIN, MU_MAX = 1e-4, 10.0  # sliding friction coefficient
RADIUS_SCALE_MIN, RADIUS_SCALE_MAX = 0.1, 10.0  # a real wheel a tenth to ten times the nominal one
PERIOD_FACTOR_MIN, PERIOD_FACTOR_MAX = 1e-3, 100.0  # the command held 0.001 T to 100 T
DELAY_STEPS_MAX = 10_000  # control steps of sensor delay (100 s at T = 0.01 s)
SLOPE_DEG_MAX = 30.0  # a floor tilted at most this much: steeper, no wheeled robot of ours stands on it
FORCE_MAX = 1e4  # N (and N m) of a force (or its noise's standard deviation) on the robot, at most
FORCE_S_MAX = 1e4  # s: a push's duration or a periodic force's period, at most


@dataclass(frozen=True)
class Param:
    """One event parameter: its type (float, int or str), whether it must be given, and its range."""

    kind: type
    required: bool = True
    minimum: float | None = None  # inclusive lower bound
    positive: bool = False  # > 0
    maximum: float | None = None  # inclusive upper bound: beyond it the value is not physics (or not memory)

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
        if (self.positive or (self.minimum or 0) > 0) and not value > 0:
            raise ConfigError(where, f"must be positive, got {value!r}")
        if self.minimum is not None and value < self.minimum:
            raise ConfigError(where, f"must be >= {self.minimum:g}, got {value!r}")
        if self.maximum is not None and value > self.maximum:
            raise ConfigError(where, f"must be <= {self.maximum:g}, got {value!r}")
        return value


def param(kind: type, required: bool = True, **limits):
    """A dataclass field checked by ``Param(kind, required, **limits)`` when the event is made."""
    p = Param(kind, required, **limits)
    return field(metadata={"param": p}) if required else field(default=None, metadata={"param": p})


def check_params(obj) -> None:
    """Check each field of the frozen dataclass ``obj`` made by :func:`param` (its type and range;
    a ConfigError naming the field), a whole number given for a float kept as a float."""
    for f in dataclasses.fields(obj):
        p = f.metadata.get("param")
        value = getattr(obj, f.name)
        if p is None or value is None:
            continue
        value = p.check(value, f.name)
        object.__setattr__(obj, f.name, float(value) if p.kind is float else value)


@dataclass(frozen=True, kw_only=True)
class Event:
    """A change of the plant at ``time`` seconds (controller clock), unknown to the controller.

    Subclasses, one per kind, name their parameters as fields; each field is checked when the
    event is made (``where`` of a ConfigError is the parameter's name)."""

    kind: ClassVar[str] = ""
    time: float

    def __post_init__(self) -> None:
        t = self.time
        if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t) or t < 0:
            raise ConfigError("time", f"an event needs a finite time >= 0 s, got {t!r}")
        check_params(self)
        self.validate()

    def validate(self) -> None:
        """Checks between parameters (a subclass's own)."""

    @property
    def params(self) -> dict[str, float | int | str]:
        """The parameters given (None: not given), by name."""
        return {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if f.name != "time" and getattr(self, f.name) is not None
        }

    def describe(self) -> str:
        args = ", ".join(f"{k}={v}" for k, v in sorted(self.params.items()))
        return f"{self.kind}({args}) at {self.time:g} s"


@dataclass(frozen=True, kw_only=True)
class Payload(Event):
    """Mass (and inertia) scaled by ``mass_scale``, or ``mass_kg`` added, spread like the mass it
    joins: on the robot's root body by default, on a named ``body``, or on every body of the robot
    (``body = "*"``). Or a load placed off-centre: ``mass_kg`` as a point mass on the root body at
    ``offset`` m ahead of the axle midpoint and ``lateral`` m to its left, at the height of the
    body's centre of mass (the body's mass, centre of mass and inertia tensor become those of the
    two together)."""

    kind: ClassVar[str] = "payload"
    mass_scale: float | None = param(float, required=False, minimum=SCALE_MIN, maximum=SCALE_MAX)
    mass_kg: float | None = param(float, required=False, positive=True, maximum=MASS_KG_MAX)
    body: str | None = param(str, required=False)
    offset: float | None = param(float, required=False, minimum=-OFFSET_MAX, maximum=OFFSET_MAX)
    lateral: float | None = param(float, required=False, minimum=-OFFSET_MAX, maximum=OFFSET_MAX)

    def validate(self) -> None:
        if (self.mass_scale is None) == (self.mass_kg is None):
            raise ConfigError("", "a payload event takes either 'mass_scale' or 'mass_kg' (not both, not neither)")
        if self.placed and (self.mass_kg is None or self.body is not None):
            raise ConfigError(
                "offset" if self.offset is not None else "lateral",
                "a load placed off-centre takes 'mass_kg' (a point mass on the root body), not 'mass_scale' or 'body'",
            )

    @property
    def placed(self) -> bool:
        """A point mass placed off-centre (``offset`` or ``lateral`` given)."""
        return self.offset is not None or self.lateral is not None


@dataclass(frozen=True, kw_only=True)
class Friction(Event):
    """Tyre/floor sliding friction set to ``mu``."""

    kind: ClassVar[str] = "friction"
    mu: float = param(float, minimum=MU_MIN, maximum=MU_MAX)


@dataclass(frozen=True, kw_only=True)
class WheelRadius(Event):
    """Real wheel radius scaled by ``scale`` while the IK keeps the nominal one."""

    kind: ClassVar[str] = "wheel_radius"
    scale: float = param(float, minimum=RADIUS_SCALE_MIN, maximum=RADIUS_SCALE_MAX)


@dataclass(frozen=True, kw_only=True)
class Actuator(Event):
    """Wheel drive weakened: servo gain (``kv_scale``) and/or torque limit (``force_scale``) scaled."""

    kind: ClassVar[str] = "actuator"
    kv_scale: float | None = param(float, required=False, minimum=SCALE_MIN, maximum=SCALE_MAX)
    force_scale: float | None = param(float, required=False, minimum=SCALE_MIN, maximum=SCALE_MAX)

    def validate(self) -> None:
        if self.kv_scale is None and self.force_scale is None:
            raise ConfigError("", "an actuator event needs 'kv_scale' and/or 'force_scale'")


@dataclass(frozen=True, kw_only=True)
class ControlPeriod(Event):
    """The plant holds each command ``factor`` T."""

    kind: ClassVar[str] = "control_period"
    factor: float = param(float, minimum=PERIOD_FACTOR_MIN, maximum=PERIOD_FACTOR_MAX)


@dataclass(frozen=True, kw_only=True)
class SensorDelay(Event):
    """The measured pose is ``steps`` control steps old."""

    kind: ClassVar[str] = "sensor_delay"
    steps: int = param(int, minimum=0, maximum=DELAY_STEPS_MAX)


@dataclass(frozen=True, kw_only=True)
class Slope(Event):
    """The floor tilted by ``angle_deg`` from the horizontal, uphill towards ``heading_deg`` (in the
    world's frame, counter-clockwise from x): gravity turned in the floor's frame (its component
    g sin(angle) pulls downhill). An angle of 0 levels the floor again."""

    kind: ClassVar[str] = "slope"
    angle_deg: float = param(float, minimum=0.0, maximum=SLOPE_DEG_MAX)
    heading_deg: float | None = param(float, required=False, minimum=-360.0, maximum=360.0)

    def gravity(self, g: float) -> tuple[float, float, float]:
        """Gravity of magnitude ``g`` in the floor's frame (x, y along the floor, z its normal)."""
        from mlpfac.elementary import cos, sin

        a, h = self.angle_deg * (math.pi / 180.0), (self.heading_deg or 0.0) * (math.pi / 180.0)
        return -g * sin(a) * cos(h), -g * sin(a) * sin(h), -g * cos(a)


FRAMES = ("world", "robot")
SHARE_MAX = 10.0  # a force given as a share of the robot's weight m g: at most ten times it
DV_MAX = 100.0  # m/s: the velocity change of a push, at most
TAU_MAX = 1e4  # s: a gust's correlation time, at most


@dataclass(frozen=True, kw_only=True)
class Force(Event):
    """A force (``fx``, ``fy`` in N) and a torque about the vertical (``torque_z``, N m) on the robot's
    root body, at its centre of mass, in the world's axes or the robot's (``frame``: x forward, y
    left, turned with the robot every control step). A force that fits any robot is given relative
    to it: ``fx_mg``, ``fy_mg`` as shares of its weight m g (m its mass at the start, as
    config.toml's ``[provenance] mass_kg`` says), or, for a push, ``dv_x``, ``dv_y``: the velocity
    change (m/s) it gives, an impulse m dv spread over its ``duration``. From ``time`` on for
    ``duration`` s (a push; omitted: it stays, a tow or a wind); with ``period`` a sinusoid of
    amplitude (fx, fy, torque_z) starting at zero; with ``std`` (N, or ``std_mg`` of the weight) noise
    of that standard deviation on fx and fy, drawn for each control step from a stream of its own
    (the run's seed and the event's place), added to (fx, fy): white (each step's drawn afresh,
    held for the step) or, with ``tau_s``, a gust of that correlation time (a first-order
    Gauss-Markov process, discretised exactly per control step: x' = a x + std sqrt(1 - a^2) w,
    a = exp(-T / tau_s), from a draw of its stationary law)."""

    kind: ClassVar[str] = "force"
    fx: float | None = param(float, required=False, minimum=-FORCE_MAX, maximum=FORCE_MAX)
    fy: float | None = param(float, required=False, minimum=-FORCE_MAX, maximum=FORCE_MAX)
    fx_mg: float | None = param(float, required=False, minimum=-SHARE_MAX, maximum=SHARE_MAX)
    fy_mg: float | None = param(float, required=False, minimum=-SHARE_MAX, maximum=SHARE_MAX)
    dv_x: float | None = param(float, required=False, minimum=-DV_MAX, maximum=DV_MAX)
    dv_y: float | None = param(float, required=False, minimum=-DV_MAX, maximum=DV_MAX)
    torque_z: float | None = param(float, required=False, minimum=-FORCE_MAX, maximum=FORCE_MAX)
    frame: str | None = param(str, required=False)
    duration: float | None = param(float, required=False, positive=True, maximum=FORCE_S_MAX)
    period: float | None = param(float, required=False, positive=True, maximum=FORCE_S_MAX)
    std: float | None = param(float, required=False, minimum=0.0, maximum=FORCE_MAX)
    std_mg: float | None = param(float, required=False, minimum=0.0, maximum=SHARE_MAX)
    tau_s: float | None = param(float, required=False, positive=True, maximum=TAU_MAX)

    # the parameters of which at most one may be given, and why (checked here, listed by docs/scenario-file.md)
    APART: ClassVar[tuple[tuple[tuple[str, ...], str], ...]] = (
        (("fx", "fx_mg", "dv_x"), "one way of giving the force along x"),
        (("fy", "fy_mg", "dv_y"), "one way of giving the force along y"),
        (("std", "std_mg"), "one way of giving the noise's standard deviation"),
        (("period", "std", "std_mg"), "a force is periodic or noise, not both"),
        (("period", "dv_x", "dv_y"), "a push given by its velocity change is not periodic"),
        (("std", "std_mg", "dv_x", "dv_y"), "a push given by its velocity change is not noise"),
    )
    # a parameter that needs one of others, and why
    NEEDS: ClassVar[tuple[tuple[str, tuple[str, ...], str], ...]] = (
        ("dv_x", ("duration",), "the push's impulse m dv is spread over its duration"),
        ("dv_y", ("duration",), "the push's impulse m dv is spread over its duration"),
        ("tau_s", ("std", "std_mg"), "the correlation time of the force's noise"),
    )

    def validate(self) -> None:
        if self.frame is not None and self.frame not in FRAMES:
            raise ConfigError("frame", f"choose 'world' or 'robot', got {self.frame!r}")
        given = set(self.params)
        for keys, why in self.APART:
            both = [k for k in keys if k in given]
            if len(both) > 1:
                raise ConfigError(both[0], f"not with {both[1]!r}: {why}")
        for key, others, why in self.NEEDS:
            if key in given and not given & set(others):
                raise ConfigError(key, f"needs {' or '.join(map(repr, others))}: {why}")
        if not given & {"fx", "fy", "fx_mg", "fy_mg", "dv_x", "dv_y", "torque_z", "std", "std_mg"}:
            raise ConfigError(
                "",
                "a force event needs 'fx', 'fy', 'torque_z' or 'std', or 'fx_mg', 'fy_mg', 'dv_x', 'dv_y' or "
                "'std_mg' relative to the robot (0 is no force: a point of an axis)",
            )

    @property
    def relative(self) -> bool:
        """Given relative to the robot (a share of its weight, a velocity change): its newtons are the robot's."""
        return any(v is not None for v in (self.fx_mg, self.fy_mg, self.dv_x, self.dv_y, self.std_mg))

    def steps(self, T: float) -> int | None:
        """Control steps it acts for (a push: its duration in whole control steps, at least one),
        None when it stays."""
        return None if self.duration is None else max(1, int(round(self.duration / T)))


EVENTS: dict[str, type[Event]] = {
    cls.kind: cls for cls in (Payload, Friction, WheelRadius, Actuator, ControlPeriod, SensorDelay, Slope, Force)
}
EVENT_KINDS = tuple(EVENTS)


def make_event(kind: str, time: float, **params) -> Event:
    """The event of ``kind`` at ``time`` with ``params`` (checked as a scenario's would be)."""
    return EVENTS[kind](time=time, **params)


def parse_event(table, duration: float, where: str) -> Event:
    """An ``[[events]]`` table -> its event, every parameter checked; ``where`` names it in errors."""
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
    cls = EVENTS.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise ConfigError(f"{where} kind", f"unknown event kind {kind!r}; choose one of {', '.join(EVENT_KINDS)}")
    fields = {f.name: f.metadata["param"] for f in dataclasses.fields(cls) if f.name != "time"}
    for key in params:
        if key not in fields:
            raise ConfigError(f"{where} {key}", f"not a parameter of a {kind!r} event (it takes {', '.join(fields)})")
    for key, p in fields.items():
        if p.required and key not in params:
            raise ConfigError(f"{where} {key}", f"a {kind!r} event needs {key!r}")
    try:
        return cls(time=float(t), **params)
    except ConfigError as err:
        raise ConfigError(f"{where} {err.where}".rstrip(), err.what) from None


class DelayLine:
    """What a ``sensor_delay`` event changes: the measurement is the one taken ``steps`` control
    steps ago (0: the newest). Every plant keeps its measurements in one: ``hist[:fill[0]]``, oldest
    first, at most ``steps + 1`` of them (arrays, so that a compiled plant step pushes as
    :meth:`push` does)."""

    def __init__(self, first) -> None:
        first = np.asarray(first)
        integral = np.issubdtype(first.dtype, np.integer) or first.dtype == bool
        self.hist = np.empty((1, *first.shape), dtype=np.int64 if integral else np.float64)
        self.hist[0] = first
        self.fill = np.ones(1, dtype=np.int64)

    def push(self, measurement) -> None:
        h = self.hist
        rows = h.reshape(len(h), -1)  # each measurement one flat row of the same memory (a number: of one)
        x = np.ascontiguousarray(measurement, dtype=h.dtype).reshape(-1)
        if not np.may_share_memory(rows, h) or x.size != rows.shape[1]:
            raise ValueError(f"a delay line of {h.shape[1:]} measurements was pushed {np.shape(measurement)}")
        (delay_push_int if h.dtype == np.int64 else delay_push)(rows, self.fill, x)

    def read(self):
        """The oldest measurement held (a copy; a number for a line of numbers)."""
        return self.hist[0].item() if self.hist.ndim == 1 else self.hist[0].copy()

    @property
    def steps(self) -> int:
        return len(self.hist) - 1

    def delay(self, steps: int) -> str:
        """Set the delay; keeps what it holds, newest last (a longer delay repeats the oldest until it fills)."""
        old, n = self.steps, int(self.fill[0])
        keep = min(n, steps + 1)
        hist = np.empty((steps + 1, *self.hist.shape[1:]), dtype=self.hist.dtype)
        hist[:keep] = self.hist[n - keep : n]
        self.hist, self.fill[0] = hist, keep
        return f"sensor delay {old} -> {steps} control steps"


def _delay_push(hist: np.ndarray, fill: np.ndarray, x: np.ndarray) -> None:
    """Append x (k,) to a delay line hist (cap, k) (see :class:`DelayLine`): the oldest row drops
    out when it is full. Copied number by number: a row assignment makes numba compile its
    shape-mismatch message, about a second of a first run."""
    n, cap, k = fill[0], hist.shape[0], hist.shape[1]
    if n < cap:
        fill[0] = n + 1
    else:
        n = cap - 1
        for i in range(n):
            for j in range(k):
                hist[i, j] = hist[i + 1, j]
    for j in range(k):
        hist[n, j] = x[j]


delay_push = kernel("void(f8[:, ::1], i8[::1], f8[::1])", name="delay_push")(_delay_push)
delay_push_int = kernel("void(i8[:, ::1], i8[::1], i8[::1])", name="delay_push_int")(_delay_push)
