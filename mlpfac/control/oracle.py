"""The oracle: the law (35) told every change of the plant, the bound beside each adaptive result;
and ``oracle-kanayama``, Kanayama's law told the same changes the same way (the bound on robots
where (35) itself is not the best law: its gain k2 grows as v_r falls and amplifies pose noise).

It is the one controller that reads the scenario's events (through :func:`told`), and it is told
only what the nominal design would need to be redone for the changed robot:

- **wheel radius x s**: the IK given the true radius. The robot's body velocity is s times the
  commanded one (v = s r w, omega = s r (w_r - w_l) / track with w from the nominal IK), so the
  input gain G of (5)-(6) is s G while f is unchanged; since the IK is linear the oracle sends the
  nominal (35) divided by s. A wheel-speed limit sees the same wheel speeds either way:
  (u / s) / r_nominal = u / r_true.
- **control period x c** (the robot holds each command c T while the reference and the
  controller keep T): the one-step map (4)-(6) keeps f(e, v_r, omega_r) at T (the reference moves
  T v_r per step) and its input gain becomes c G(e, T) = G(e, c T). Redesigning (35) for it,
  omega = (h5 + k2 e2 + k3 e3) / (c T) with h5 = T omega_r, and
  v = (k1 e1 + h1' omega + h2) / (c T) with h1' = c T e2 and h2 = T v_r cos e3, the gains (36) on
  T v_r as before; this is exactly the nominal (35) divided by c (its omega is c times the one
  sent, so its h1 omega = T e2 c omega = h1' omega), not c T put everywhere. The limits |v|, |omega|
  bound the velocity the robot drives, the one sent here; the nominal law runs with limits x c.
  On the kinematic plant (7) the change is T -> c T in f and G alike, and there the oracle is (35)
  with c T everywhere.
- **sensor delay of d steps**: an exact unicycle predictor. The measured pose (rebuilt from e and
  r_k) is the pose of ``age`` steps ago, age following the plant's delay line (0, 1, ..., d after the
  event); it is moved forward through the commands actually sent over those steps, each held for its
  period at the velocity it produces, and (35) acts on the error of the predicted pose. On the
  kinematic plant (7), an Euler map, the unicycle is exact to O(T^2) per step.
- **payload, friction, weak actuator, slope, force, terrain**: nothing. The law (35) has no
  parameter that mass, friction, actuator strength or a load (a slope's pull, a push, a tow, a
  ramp, rough ground) change: a velocity law told a load would send the same velocities, which
  the drive carries; the oracle is the nominal law, bit for bit Corradini's (``oracle-dynamic``,
  which sends torques, is told the slope and the force). Its
  post-event error in the same run is the bound (the same law on the robot changed from t = 0
  measures the same over that window within noise: ``sims/oracle_from_start.py``,
  docs/results-beyond.md).
- **payload on a skid-steer** (``TURNING``): how it turns. A skid-steer's wheels slide as it
  turns, so its load sets the track it turns as and where its kinematic centre lies (the point
  that moves along its heading), measured by the factory on a robot with the event, as the plant
  measures them while it settles (:meth:`~mlpfac.plants.mujoco.plant.MujocoPlant.turning_change`): the
  track's ratio t and the centre's move a ahead of the pose frame. omega is sent x t, so the
  robot turns at the rate the law meant. With the centre a ahead, the pose frame slides sideways
  at -a omega as the robot turns, and it follows the path only with the heading led by the angle
  phi, sin phi = a omega_r / v_r (the quasi-static answer of the frame's velocity v h(theta) - a
  omega n(theta) = v_r h(theta_r)): the law acts on e3 + phi. Not told after a floor or a weak
  actuator: on a floor of 0.2 the wheels slide with the path's accelerations, and a weak actuator
  saturates in the turning test, so one steady turn does not say how the robot then turns (told
  it, Kanayama's law did no better on TIAGo++'s floor: docs/robots.md).

- **how the wheels answer a command**, with every change above (a wheel radius, a control period,
  a sensor delay, a skid-steer's payload): measured by the factory on a robot with the events, as
  the plant measures a skid-steer's turning while it settles
  (:func:`~mlpfac.plants.mjcf.settle.wheels_answer`): driving straight, its wheels asked half and
  all of the fastest speed the reference asks of a wheel, the speeds they reach, as the line w =
  gain w_asked - offset. A redesign for the changed robot is a redesign for its wheels as they
  are: on a light robot whose weak servos (kv 0.1 against 0.1 N m of joint friction,
  tests/data/weak_servo.xml) turn each wheel 1 rad/s slower than asked, the nominal law runs
  behind the path by the slip of that lag (e1 = r 1 rad/s / Kx = 3.3 mm with Kanayama's law), an
  untold radius x s or period x c drives s or c times the command and happens to offset it, and
  the law told only the change divided its command back and kept the lag, grown by s (1.7-4.1x
  worse than itself untold). Told the answer, each wheel is asked (w + offset sgn) / gain, w its
  speed through the IK of the law's command and sgn the sign of its speed along the reference
  (the friction that slows a wheel opposes its motion, which on the path is the reference's: the
  command's own sign flips with the noise Corradini's law amplifies); sent as (v, omega) through
  the IK's radius and track. The predictor moves the pose through the law's command: the wheels
  now answer it. Wheels that answer as asked (1, 0: to 3 digits, on most robots) change nothing,
  to the bit. Not told: how they answer a command that changes faster than they follow (the
  servo's time constant; Corradini's law's omega, amplified pose noise, clipped at a wheel-speed
  limit, slows a robot it drives: not a change of the robot), nor their answer after an event the
  law is told nothing of (a payload, a floor, a weak actuator: the law told nothing is the law).

Kanayama's law is a velocity law, so the same telling is simpler: its command divided by the
radius scale, and on the robot (not the Euler map (7), where f and G scale alike and the law needs
no change) by the period factor, so that the robot moves per control step as the law meant; and
the law acts on the error of the same predicted pose, its wheels asked as they answer.

What an oracle is told is the truth of each change, measured on a robot of the scenario's; never
the run's own state (its wheels' speeds, its pose beyond the measured one).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from mlpfac.control.baselines import Stepped
from mlpfac.control.law import CORRADINI, KANAYAMA, Law, law_step
from mlpfac.elementary import asin, cos, each, sin
from mlpfac.jit import as_rows, kernel, seeds
from mlpfac.model import tracking_errors
from mlpfac.plants.events import ControlPeriod, DelayLine, Event, SensorDelay, WheelRadius


def _sinc(half: float) -> float:
    """sin(half) / half, computed as ``np.sinc(half / pi)`` computes it, with glibc's sine."""
    y = math.pi * (half / math.pi or 1.0e-20)
    return sin(y) / y


TURNING = ("payload",)  # the events whose turning a skid-steer's oracle is told
# the changes the law is told (with them, how the wheels answer a command)
TOLD = ("wheel_radius", "control_period", "sensor_delay", "turning_track")


def told(event: Event) -> tuple[float, str, float]:
    """An event as the oracle is told it: time, kind, and the one number the law needs (1 if none)."""
    if isinstance(event, WheelRadius):
        number = event.scale
    elif isinstance(event, ControlPeriod):
        number = event.factor
    elif isinstance(event, SensorDelay):
        number = event.steps
    else:
        number = 1.0
    return float(event.time), event.kind, float(number)


@kernel()
def _sign(x: float) -> float:
    """np.sign of one number: -1, 0 (either zero), 1; NaN stays NaN."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0 if x == 0.0 else x


@kernel("void(i8, f8[::1], f8[::1], f8[:, ::1], f8, f8, f8[:, ::1], f8[:, ::1], f8[:, ::1])")
def told_step(law, c, told, e, v_r, omega_r, u, out, tele):
    """The law told the changes, for B seeds, in the Python loop and the compiled one alike: ``law``
    and its constants ``c`` as :func:`~mlpfac.control.law.law_step` takes them (:meth:`Oracle._told`),
    then ``told`` = (divide, turn, ahead, gain, offset, IK radius, IK track). The heading is led by
    asin(ahead omega_r / v_r) where ahead != 0 and v_r > 0; the command (after the limits) divided
    by ``divide`` (the period's factor x the radius's scale) and its omega x ``turn`` is ``u`` (what
    the predictor moves the pose through); ``out`` is the command whose wheel speeds, through the
    IK, the wheels answer with the ones ``u`` asks: each wheel w asked (w + offset s) / gain, s the
    sign of its speed along the reference (the friction that slows it opposes its motion, which on
    the path is the reference's: the command's own sign flips with the noise a law amplifies); as
    (v, omega) through the IK's radius and track, v + radius offset (s_l + s_r) / 2 and omega +
    radius offset (s_r - s_l) / track, both / gain. ``e`` is not written; ``tele``: (35)'s h_hat (B, 3)."""
    divide, turn, ahead, gain, offset = told[0], told[1], told[2], told[3], told[4]
    E = e
    if ahead != 0.0 and v_r > 0.0:  # the sliding pose frame follows the path with its heading led
        E = e.copy()
        lead = asin(min(max(ahead * omega_r / v_r, -1.0), 1.0))
        for b in range(E.shape[0]):
            E[b, 2] += lead
    law_step(law, c, E, v_r, omega_r, u, tele)
    for b in range(u.shape[0]):
        if divide != 1.0:
            u[b, 0] /= divide
            u[b, 1] /= divide
        if turn != 1.0:
            u[b, 1] *= turn
        out[b, 0], out[b, 1] = u[b, 0], u[b, 1]
    if gain != 1.0 or offset != 0.0:
        radius, track = told[5], told[6]
        half = 0.5 * omega_r * track
        s_l, s_r = _sign(v_r - half), _sign(v_r + half)
        lift = radius * offset
        for b in range(u.shape[0]):
            out[b, 0] = (u[b, 0] + lift * 0.5 * (s_l + s_r)) / gain
            out[b, 1] = (u[b, 1] + lift * (s_r - s_l) / track) / gain


class Oracle(Stepped):
    """The law (35) with the nominal functions, told the changes ``changes`` = [:func:`told` (event)].

    One interface with the other controllers: one run (``reset`` with one Generator) or B seeds.
    Before the first event it sends Corradini's commands to the last bit.
    """

    name = "oracle"
    labels: dict[str, list[str]] = {"h_hat": ["h1", "h2", "h5"]}

    def __init__(
        self,
        law: Law,
        T: float,
        changes: list[tuple[float, str, float]],
        kinematic: bool,
        kanayama: tuple[float, float, float] | None = None,
        ik: tuple[float, float] = (1.0, 1.0),
    ) -> None:
        """``kanayama``: the gains (Kx, Ky, Ktheta) of Kanayama's law, told instead of (35); ``ik``: the
        wheel radius and track the robot's IK turns (v, omega) into wheel speeds with (its wheels'
        answer, when told, is undone through them)."""
        self.T = float(T)
        self.ik = (float(ik[0]), float(ik[1]))
        self.kanayama = kanayama
        if kanayama is not None:
            self.name, self.labels = "oracle-kanayama", {}
        self.law = law
        self.changes = sorted(changes, key=lambda c: c[0])
        self.kinematic = kinematic
        self._limits = (
            np.inf if law.v_max is None else float(law.v_max),
            np.inf if law.omega_max is None else float(law.omega_max),
        )
        self._depth = max([int(v) for _, kind, v in self.changes if kind == "sensor_delay"], default=0)

    def reset(self, rng) -> None:
        rngs, self.single = seeds(rng)
        B = len(rngs)
        self.k, self.pending = 0, list(self.changes)
        self.radius, self.hold = 1.0, 1.0  # the robot drives radius x the command, held hold x T
        self.turn, self.ahead = 1.0, 0.0  # a skid-steer's track ratio, its kinematic centre's move [m]
        self.gain, self.offset = 1.0, 0.0  # the wheels turn at gain x the speed asked - offset [rad/s]
        self.pose_step = DelayLine(0)  # which step's pose the plant's measurement is
        self.sent: deque = deque(maxlen=max(self._depth, 1))  # (velocity driven (B, 2), seconds) per step
        self._h, self._u, self._out = np.zeros((B, 3)), np.zeros((B, 2)), np.zeros((B, 2))
        self._q, self._e = np.zeros((B, 3)), np.zeros((B, 3))
        self._tele = {"h_hat": self._h[0] if self.single else self._h} if self.kanayama is None else {}
        self._told()
        told_step(*self._kernel, np.zeros((0, 3)), 1.0, 0.0, self._u[:0], self._out[:0], self._h[:0])  # loaded

    def _apply(self, kind: str, value: float) -> None:
        if kind == "wheel_radius":
            self.radius *= value
        elif kind == "control_period":
            self.hold = value
        elif kind == "sensor_delay":
            self.pose_step.delay(int(value))
        elif kind == "turning_track":
            self.turn = value
        elif kind == "kinematic_centre":
            self.ahead = value
        elif kind == "wheel_gain":
            self.gain = value
        elif kind == "wheel_offset":
            self.offset = value

    def _due(self, k: int) -> None:
        """Take the changes due at step k (the runner's rule for an event's step)."""
        if not (self.pending and self.pending[0][0] <= k * self.T + 1e-9):
            return
        while self.pending and self.pending[0][0] <= k * self.T + 1e-9:
            _, kind, value = self.pending.pop(0)
            self._apply(kind, value)
        self._told()

    def _told(self) -> None:
        """The law and what it is told as :func:`told_step` takes them. On the robot a velocity law's
        c T per step is c times the motion meant: the limits x c, the command / c; on the kinematic
        plant (7) c T is in f and G alike: (35) with c T."""
        T, c = (self.hold * self.T, 1.0) if self.kinematic else (self.T, self.hold)
        v_max, omega_max = self._limits
        if self.kanayama is not None:
            law, consts = KANAYAMA, [*self.kanayama, c * v_max, c * omega_max]
        else:
            law, consts = CORRADINI, [T, *self.law.lambdas, c * v_max, c * omega_max]
        told = [c * self.radius, self.turn, self.ahead, self.gain, self.offset, *self.ik]
        self._kernel = (law, np.array(consts, dtype=float), np.array(told, dtype=float))

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        E = as_rows(e, 3)
        k = self.k
        if k > 0:
            self.pose_step.push(k)
        self._due(k)
        age = k - self.pose_step.read()
        if age > 0:
            E = self._predict(E, r, list(self.sent)[-age:])
        told_step(*self._kernel, E, float(r[3]), float(r[4]), self._u, self._out, self._h)
        if self._depth:
            self.sent.append((self._u * [self.radius, self.radius / self.turn], self.hold * self.T))
        self.k += 1
        return self._out[0].copy() if self.single else self._out

    def law_kernel(self, k: int = 0) -> tuple[int, np.ndarray, np.ndarray] | None:
        """The told law for the compiled closed loop from step k on (the changes due by then taken):
        (its number, its constants, what it is told) (:func:`told_step`); None with a sensor delay,
        whose predictor runs in Python."""
        if self._depth:
            return None
        self._due(k)
        return self._kernel

    def _predict(self, E: np.ndarray, r: np.ndarray, sent: list) -> np.ndarray:
        """The error (2) to r of the pose the measured one reaches through ``sent``: exact unicycle arcs."""
        th = r[2] - E[:, 2]
        c, s = each(cos, th), each(sin, th)
        x, y = r[0] - (c * E[:, 0] - s * E[:, 1]), r[1] - (s * E[:, 0] + c * E[:, 1])
        for u, dt in sent:
            half = 0.5 * u[:, 1] * dt
            ds = u[:, 0] * dt * each(_sinc, half)  # chord of the arc: v dt sin(half) / half
            x, y, th = x + ds * each(cos, th + half), y + ds * each(sin, th + half), th + 2.0 * half
        self._q[:, 0], self._q[:, 1], self._q[:, 2] = x, y, th
        tracking_errors(self._q, r, self._e)
        return self._e

    @property
    def h_hat(self) -> np.ndarray:
        return self._h[0] if self.single else self._h

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return self._tele
