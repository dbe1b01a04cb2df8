"""Controllers that act on the dynamics: ``fierro-lewis`` and ``oracle-dynamic`` (the torque level,
:mod:`mlpfac.control.torque`).

``fierro-lewis`` (Fierro & Lewis 1997) is backstepping through the dynamic model of
:mod:`mlpfac.dynamics`. Kanayama's velocity law gives the velocities the base should have,

    v_c = v_r cos e3 + Kx e1,        omega_c = omega_r + v_r (Ky e2 + Ktheta sin e3),

and computed torque with the nominal model makes the measured twist (v, omega) follow them, their
derivative fed forward:

    (a, alpha) = d/dt (v_c, omega_c) + Kv ((v_c, omega_c) - (v, omega)),
    tau = B^-1 (M (a, alpha) + V(v) v + F(v)),  each clamped to the torque limit.

d/dt (v_c, omega_c) is analytic: the reference's rates (``obs.r_dot``) and the error's rates
de1/dt = omega e2 - v + v_r cos e3, de2/dt = -omega e1 + v_r sin e3, de3/dt = omega_r - omega
with the measured twist. Kv = ``VELOCITY_SHARE`` / T: the velocity error closes that share of itself
each control step. The controller's limits |v| <= v_max, |omega| <= omega_max bound (v_c, omega_c).

``oracle-dynamic`` is ``fierro-lewis`` told every change (:func:`mlpfac.control.oracle.told` and the
true model read from the changed robot after each event, :meth:`MujocoPlant.true_dynamics`): a
payload, a weak actuator, a wheel radius change its true model (a floor's friction does not enter
the rolling model: told, it changes nothing), and a wheel radius x s the twist its wheels' encoders
give (a pose source but the truth: v, and omega without a gyro) s times what they read through the
nominal radius, in its model's units (read through the nominal one, the twist and the model it
drives disagree by s: on the fused pose after a radius x1.5 it was twice as far off as itself told
nothing and lost 2 of 10 seeds, docs/results-sensing.md); a control period x c (the robot moves c T a step
while the reference moves T) the reference in the robot's time (v_r, omega_r / c, their rates / c^2),
Kx / c (Kanayama's command / c, as ``oracle-kanayama``'s) and the velocity gain / c (the torque is
held c T); a sensor delay the pose predicted over it as ``oracle`` predicts it, and the measured
twist, as old as the pose, moved forward through the torques sent since on its model (one Euler
step a control period): the velocity loop, closing ``VELOCITY_SHARE`` of its error a step, is
unstable on a twist 3 steps old (PAL TIAGo on torque motors left the floor on every seed, told the
pose alone, as ``fierro-lewis`` told nothing did). Told a ``slope`` or a ``force``
(:class:`Told`), its model carries the load they put on the robot, f_e of :mod:`mlpfac.dynamics`:
gravity's pull along the tilted floor, m g_floor, and the force the robot meets at each step (the
run's own schedule: a push, a tow, a periodic force, the noise drawn for its seed), both at the
centre of mass, turned to the heading measured, so that computed torque cancels them. It is told
nothing of the terrain (ramps, rough ground, patches).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from mlpfac.control.baselines import Stepped
from mlpfac.control.drive import drive_step, rated
from mlpfac.control.oracle import Oracle
from mlpfac.dynamics import P_FV, P_FW, P_TMAX, accelerations, torque_of
from mlpfac.elementary import cos, sin
from mlpfac.jit import kernel, seeds
from mlpfac.plants.events import DelayLine
from mlpfac.plants.world.forces import force_schedule, run_seed

VELOCITY_SHARE = 0.5  # Kv T: the velocity error's share closed each control step
# Kanayama's gains (Kx, Ky, Ktheta) of the outer law where the scenario sets none ([controller.kanayama]):
# adaptive-real's (mlpfac/control/variants.py). A robot on soft tyres turns with its heading a few mrad
# off its path (the tyres slip sideways, beta); the law holds e2 = -Ktheta beta / Ky against it, so a
# larger Ky than Kanayama's 64 halves that, which the computed torque's fast velocity loop allows.
OUTER_GAINS = (10.0, 150.0, 16.0)
G_KX, G_KY, G_KTH, G_KV, G_VMAX, G_WMAX = range(6)  # the law's constants, packed


@kernel("void(f8[:, ::1], f8[::1], f8[::1], f8[:, ::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1])")
def fierro_lewis_step(e, r, r_dot, twist, p, g, tau, vc):
    """Backstepping for B seeds: e (B, 3), r (5,), r_dot (2,), twist (B, 2) measured, p the packed
    model (:meth:`mlpfac.dynamics.RobotModel.packed`), g the gains and limits; writes the wheel
    torques ``tau`` (B, 2) and the velocities ``vc`` (B, 2) the kinematic law asked."""
    v_r, w_r, dv_r, dw_r = r[3], r[4], r_dot[0], r_dot[1]
    kx, ky, kth, kv = g[G_KX], g[G_KY], g[G_KTH], g[G_KV]
    tmax = p[P_TMAX]
    for i in range(e.shape[0]):
        e1, e2, e3 = e[i, 0], e[i, 1], e[i, 2]
        v, w = twist[i, 0], twist[i, 1]
        c3, s3 = cos(e3), sin(e3)
        v_c = v_r * c3 + kx * e1
        w_c = w_r + v_r * (ky * e2 + kth * s3)
        de1 = w * e2 - v + v_r * c3
        de2 = -w * e1 + v_r * s3
        de3 = w_r - w
        dv_c = dv_r * c3 - v_r * s3 * de3 + kx * de1
        dw_c = dw_r + dv_r * (ky * e2 + kth * s3) + v_r * (ky * de2 + kth * c3 * de3)
        if abs(v_c) > g[G_VMAX]:  # a limited command holds still
            v_c, dv_c = math.copysign(g[G_VMAX], v_c), 0.0
        if abs(w_c) > g[G_WMAX]:
            w_c, dw_c = math.copysign(g[G_WMAX], w_c), 0.0
        v_c, w_c, dv_c, dw_c = rated(p, v_c, w_c, dv_c, dw_c)  # the wheels' rated speed kept
        tl, tr = torque_of(p, v, w, dv_c + kv * (v_c - v), dw_c + kv * (w_c - w))
        tau[i, 0] = min(max(tl, -tmax), tmax)
        tau[i, 1] = min(max(tr, -tmax), tmax)
        vc[i, 0], vc[i, 1] = v_c, w_c


class FierroLewis(Stepped):
    """``fierro-lewis``: Kanayama's law backstepped through computed torque with the nominal model."""

    name = "fierro-lewis"
    level = "torque"
    labels: dict[str, list[str]] = {"vc": ["v_c", "omega_c"]}

    def __init__(self, robot, T: float, gains: tuple[float, float, float], limits: tuple[float, float]) -> None:
        self.T, self.robot = float(T), robot
        self.p = robot.packed()
        self.g = np.array([*gains, VELOCITY_SHARE / self.T, *limits], dtype=float)

    def reset(self, rng) -> None:
        rngs, self.single = seeds(rng)
        B = len(rngs)
        self._tau, self._vc = np.zeros((B, 2)), np.zeros((B, 2))
        self._tele = {"vc": self._vc[0] if self.single else self._vc}
        fierro_lewis_step(np.zeros((0, 3)), np.ones(5), np.zeros(2), np.zeros((0, 2)), self.p, self.g,
                          self._tau[:0], self._vc[:0])  # fmt: skip
        drive_step(self.p, self._tau[:0], self._tau[:0], self._tau[:0])

    def step(self, obs) -> np.ndarray:
        e, tw = _rows(obs.e, 3), _rows(obs.twist, 2)
        fierro_lewis_step(e, _flat(obs.r), _flat(obs.r_dot), tw, self.p, self.g, self._tau, self._vc)
        return self._sent(obs, tw)

    def _sent(self, obs, tw: np.ndarray) -> np.ndarray:
        """The torques the drive sends for the law's (:mod:`mlpfac.control.drive`)."""
        drive_step(self.p, tw, _rows(obs.wheel_speeds, 2), self._tau)
        return self._tau[0].copy() if self.single else self._tau

    def telemetry(self) -> dict[str, np.ndarray | float]:
        return self._tele


class OracleDynamic(FierroLewis):
    """``oracle-dynamic``: ``fierro-lewis`` told every change: ``changes`` [(time, kind, number, the
    true model after it, or None)], in time order."""

    name = "oracle-dynamic"

    def __init__(
        self,
        robot,
        T: float,
        gains,
        limits,
        changes: list[tuple[float, str, float, object]],
        world: Told | None = None,
        encoders: tuple[bool, bool] = (False, False),
    ) -> None:
        """``encoders``: which of the measured twist's (v, omega) the wheels' encoders give through
        the nominal radius (a pose source other than the truth: v; without a gyro, omega too)."""
        super().__init__(robot, T, gains, limits)
        self.changes = sorted(changes, key=lambda c: c[0])
        self.world = world  # the slopes and forces it is told (the world's load f_e on its model)
        self.encoders = np.array(encoders, dtype=bool)
        self._depth = max([int(n) for _, kind, n, _ in changes if kind == "sensor_delay"], default=0)
        self._pred = Oracle(_NoLaw(limits), T, [], False, gains)  # its unicycle predictor, over the velocities asked

    def reset(self, rng) -> None:
        super().reset(rng)
        self.p, self._g, self.hold = self.robot.packed(), self.g.copy(), 1.0
        self.scale = np.ones(2)  # the measured twist in the told model's units: x the radius's scale from encoders
        self.k, self.pending = 0, list(self.changes)
        self.pose_step = DelayLine(0)  # which step's pose the measurement is
        self.sent: deque = deque(maxlen=max(self._depth, 1))  # (velocities asked, torques sent (B, 2), seconds)
        self._pred.reset(rng)
        self.model = self.robot
        if self.world is not None:
            self.world.reset(seeds(rng)[0], self.T)

    def step(self, obs) -> np.ndarray:
        k, T = self.k, self.T
        if k > 0:
            self.pose_step.push(k)
        while self.pending and self.pending[0][0] <= k * T + 1e-9:  # the runner's rule for an event's step
            _, kind, number, model = self.pending.pop(0)
            if model is not None:
                self.p, self.model = model.packed(), model
            if kind == "control_period":  # the robot moves c T per step: the path at 1/c of the speed
                self.hold = number
                self._g[G_KX], self._g[G_KV] = self.g[G_KX] / number, self.g[G_KV] / number
            elif kind == "sensor_delay":
                self.pose_step.delay(int(number))
            elif kind == "wheel_radius":  # encoders count the wheels' turns: the twist they give is x s
                self.scale[self.encoders] *= number
        self.k += 1
        e, r, tw = _rows(obs.e, 3), _flat(obs.r), _rows(obs.twist, 2)
        if self.scale[0] != 1.0 or self.scale[1] != 1.0:
            tw = tw * self.scale
        measured = tw  # the drive's guard reads the twist (in the model's units) and the wheel speeds as measured
        age = k - self.pose_step.read()
        if age > 0:  # the pose predicted over the delay through the velocities asked, the twist through the torques
            since = list(self.sent)[-age:]
            e = self._pred._predict(e, r, [(vc, dt) for vc, _, dt in since])
            tw = twist_ahead(self.p, tw, [(tau, dt) for _, tau, dt in since])
        r_dot = _flat(obs.r_dot)
        if self.hold != 1.0:  # v_r, omega_r / c and their rates / c^2: the reference in the robot's time
            c = self.hold
            r = np.array([r[0], r[1], r[2], r[3] / c, r[4] / c])
            r_dot = r_dot / (c * c)
        if self.world is None:
            fierro_lewis_step(e, r, r_dot, tw, self.p, self._g, self._tau, self._vc)
        else:  # each seed's model with the load it is under now
            for b, load in enumerate(self.world.loads(k, _rows(obs.pose, 3), self.model)):
                p = self.p.copy()
                p[P_FV], p[P_FW] = load
                fierro_lewis_step(e[b : b + 1], r, r_dot, tw[b : b + 1], p, self._g, self._tau[b : b + 1],
                                  self._vc[b : b + 1])  # fmt: skip
        sent = self._sent(obs, measured)
        if self._depth:
            self.sent.append((self._vc.copy(), self._tau.copy(), self.hold * T))
        return sent


def twist_ahead(p: np.ndarray, twist: np.ndarray, sent: list[tuple[np.ndarray, float]]) -> np.ndarray:
    """The twists (B, 2) that ``twist`` (B, 2) reaches on the packed model ``p`` through the wheel
    torques ``sent`` [(torques (B, 2), seconds held)], one Euler step each."""
    tw, rate = twist.copy(), np.empty_like(twist)
    for tau, dt in sent:
        accelerations(p, tw, tau, rate)
        tw += dt * rate
    return tw


class Told:
    """The world ``oracle-dynamic`` is told: the slopes (time, and gravity's (g_x, g_y) along the floor
    after it) and the ``force`` events among a run's ``events`` of ``steps`` control steps, whose
    schedule it meets (:func:`mlpfac.plants.world.forces.force_schedule`, the same stream as the plant's)."""

    def __init__(self, slopes: list[tuple[float, float, float]], events, steps: int) -> None:
        self.slopes, self.events, self.steps = sorted(slopes), tuple(events), int(steps)

    def reset(self, rngs: list[np.random.Generator], T: float) -> None:
        self.T, self.pending, self.g = T, list(self.slopes), (0.0, 0.0)
        self.schedules = [force_schedule(self.events, T, self.steps, run_seed(rng)) for rng in rngs]

    def loads(self, k: int, pose: np.ndarray, model) -> list[tuple[float, float]]:
        """Each seed's external generalized force f_e on (v, omega) at step k (:mod:`mlpfac.dynamics`):
        gravity's pull along the floor and the force, at the centre of mass ``model.com_offset_m``
        ahead of the axle, for its heading ``pose[:, 2]`` as measured."""
        while self.pending and self.pending[0][0] <= k * self.T + 1e-9:  # the runner's rule for an event's step
            self.g = self.pending.pop(0)[1:]
        m, d = model.mass_kg, model.com_offset_m
        out = []
        for b, sched in enumerate(self.schedules):
            c, s = cos(float(pose[b, 2])), sin(float(pose[b, 2]))
            fx, fy, tz = m * self.g[0], m * self.g[1], 0.0
            if sched is not None and k < len(sched):
                row = sched[k]
                fx += row[0] + c * row[2] - s * row[3]
                fy += row[1] + s * row[2] + c * row[3]
                tz = row[4]
            out.append((fx * c + fy * s, tz + d * (-fx * s + fy * c)))
        return out


class _NoLaw:
    """The limits an :class:`Oracle` reads of a law (its predictor alone is used here)."""

    lambdas = (0.9, 0.9, 0.9)

    def __init__(self, limits: tuple[float, float]) -> None:
        self.v_max, self.omega_max = limits


def _rows(x, width: int) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=float).reshape(-1, width)


def _flat(x) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=float).reshape(-1)
