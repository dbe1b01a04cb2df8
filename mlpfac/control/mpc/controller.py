"""``mpc`` and ``limit``, the controller (:mod:`mlpfac.control.mpc` says what they are): one seed's
model, estimate and plan, the plan's spline and its shift, and the closed loop's contract."""

from __future__ import annotations

import math

import numpy as np

from mlpfac.control.baselines import Stepped
from mlpfac.control.mpc.config import MpcConfig
from mlpfac.control.mpc.kernels import (
    covariance_predict,
    gauss_newton,
    kalman_update,
    plan_cost,
    residual_jacobian,
)
from mlpfac.jit import seeds
from mlpfac.model import pose_from_error, wrap
from mlpfac.plants.events import DelayLine, SensorDelay

FAILED_COST = 1.0e9  # a plan whose rollout diverged (its errors FAILED) costs at least this
MU_MAX, RADIUS_MIN = 1.0e6, 1.0e-3  # the damping's ceiling, the trust radius's least (a share of the scale)
FD_STEP = 1.0e-6  # the estimator's finite-difference step in the state's tangent space (m, rad, m/s, rad/s)
_NO_A = np.zeros((0, 0))


class _Seed:
    """One seed's model, estimate and plan. The estimate is kept at the step of the newest pose
    fused (the anchor: x_a, st_a, P at step ``a``), the commands sent since (``sent``), and predicted
    from there to the current step (x, st)."""

    def __init__(self, predictor, x, st, P, knots) -> None:
        self.model, self.knots = predictor, knots
        self.x_a, self.st_a, self.P, self.a, self.fused = x, st, P, 0, -1
        self.x, self.st = x, st
        self.sent: list[np.ndarray] = []  # the commands of steps a, a + 1, ..., k - 1
        self.pending: list = []
        self.u = knots[0].copy()
        self.mu, self.radius = 0.0, 0.1  # the plan's damping and trust radius (set by the controller)
        self.J, self.age, self.cost = None, 0, math.inf  # the residuals' Jacobian, its age in steps, the plan's cost
        self.A, self.A_age = None, 0  # the estimator's step Jacobian, its age in steps
        self.pose_step = DelayLine(0)  # which step's pose the measurement is (a sensor delay told)


class MPC(Stepped):
    """``mpc`` (``truth=False``: the state estimated from the measured pose) or ``limit``
    (``truth=True``: given the robot's true state through :meth:`watch`).

    ``build_model(seed)`` gives the model of a seed's run: a reset :class:`~mlpfac.plants.mujoco.plant.MujocoPlant`
    no run steps; ``preview`` (N + H + 1, 5) the reference ahead; ``events`` the scenario's, told
    at their times; ``limits`` the knots' bounds (2,) per command coordinate; ``scale`` (2,) the
    commands' scale (the finite differences' and the damping's); ``noise`` (3,) the pose noise's
    standard deviations the estimator is told; ``wheel_noise`` the wheels' speeds' (rad/s), which a
    controller of the torque level measures with the pose."""

    labels: dict[str, list[str]] = {"plan": ["cost", "damping"]}

    def __init__(
        self,
        name: str,
        level: str,
        T: float,
        config: MpcConfig,
        build_model,
        preview: np.ndarray,
        events,
        limits: np.ndarray,
        scale: np.ndarray,
        noise: np.ndarray,
        truth: bool,
        wheel_noise: float = 0.0,
    ) -> None:
        self.name, self.level, self.T, self.config = name, level, float(T), config
        self.build_model, self.preview = build_model, np.ascontiguousarray(preview, dtype=float)
        self.events = sorted(events, key=lambda ev: ev.time)
        self.limits, self.scale = np.asarray(limits, dtype=float), np.asarray(scale, dtype=float)
        self.noise = np.maximum(np.asarray(noise, dtype=float), 1.0e-6)  # a pose known to a micrometre at best
        self.wheel_noise = max(float(wheel_noise), 1.0e-3)  # rad/s: the wheels' speeds, at the torque level
        self.truth = truth
        self.H = max(1, int(round(config.horizon_s / self.T)))
        self.why: dict[int, str] = {}
        self._phi = _spline(self.H, config.knots)  # (H, knots)
        self._at = _knot_steps(self.H, config.knots)  # the knots' steps
        self._w = np.tile(config.fd_step * self.scale, config.knots)  # the knots' finite-difference steps
        self._scale = np.tile(self.scale, config.knots)
        self._plants: list | None = None

    def _q_velocity(self) -> float:
        """A velocity's variance gained over a control step, (accel_std T)^2 (a product: no libm pow)."""
        a = self.config.accel_std * self.T
        return a * a

    def watch(self, plants: list) -> None:
        """The run's robots, one per seed (``limit`` reads each one's true state every step)."""
        if self.truth:
            self._plants = plants

    def reset(self, rng) -> None:
        from mlpfac.plants.world.forces import run_seed

        rngs, self.single = seeds(rng)
        self.k = 0
        self.seeds = []
        for g in rngs:
            predictor = self.build_model(run_seed(g))
            x, st = predictor.capture()
            n, half = predictor.n, predictor.half
            P = np.zeros((n, n))
            for i in range(half):  # a start known to the pose noise, at rest or at the speed it is given
                P[i, i] = float(self.noise[0] * self.noise[0])
                P[half + i, half + i] = self._q_velocity()
            knots = np.zeros((self.config.knots, 2))
            if self.level == "velocity":
                for i, j in enumerate(_knot_steps(self.H, self.config.knots)):
                    knots[i] = self.preview[min(j, self.preview.shape[0] - 1), 3:5]
            s = _Seed(predictor, x, st, P, np.clip(knots, -self.limits, self.limits))
            s.mu = self.config.damping
            s.pending = list(self.events)
            self.seeds.append(s)
        self._u = np.zeros((len(rngs), 2))
        self._tele = np.zeros((len(rngs), 2))
        self.live = list(range(len(rngs)))

    def drop(self, b: int) -> None:
        if b in self.live:
            self.live.remove(b)

    def telemetry(self) -> dict[str, np.ndarray]:
        return {"plan": self._tele[0] if self.single else self._tele}

    def step(self, *args) -> np.ndarray:
        wheels = None
        if self.level == "torque":  # the pose, and the wheels' speeds as their encoders measure them
            (obs,) = args
            poses = np.asarray(obs.pose, dtype=float).reshape(-1, 3)
            wheels = np.asarray(obs.wheel_speeds, dtype=float).reshape(-1, 2)
            r = np.asarray(obs.r, dtype=float)
        else:
            e, r = args
            E = np.asarray(e, dtype=float).reshape(-1, 3)
            poses = np.array([pose_from_error(E[b], r) for b in range(E.shape[0])])
        k = self.k
        for b in self.live:
            s = self.seeds[b]
            if self.truth:
                self._observe_truth(s, b, k)
            else:
                self._estimate(s, k, poses[b], None if wheels is None else wheels[b])
            self._u[b] = self._plan(s, k, b)
            s.u = self._u[b].copy()
        self.k += 1
        return self._u[0].copy() if self.single else self._u.copy()

    # -- the state

    def _observe_truth(self, s: _Seed, b: int, k: int) -> None:
        if self._plants is None:
            raise RuntimeError("limit runs in the closed loop, which shows it the robot (watch)")
        while s.pending and s.pending[0].time <= k * self.T + 1e-9:  # the runner's rule for an event's step
            ev = s.pending.pop(0)
            s.model.apply(ev, *s.model.capture(self._plants[b]))
        s.x, s.st = s.model.capture(self._plants[b])

    def _estimate(self, s: _Seed, k: int, pose: np.ndarray, wheels: np.ndarray | None) -> None:
        """The EKF: the pose measured now (and, at the torque level, the wheels' speeds, which come
        with it) is of step m = k - its age (a sensor delay told); the anchor is moved on to m
        through the model's steps with the commands sent (the covariance with each step's
        Jacobian), the measurement fused there, and the estimate predicted from it to step k. An
        event due is told at step k, the anchor first moved on to k under the model before it."""
        if k > 0:
            s.pose_step.push(k)
            s.sent.append(s.u)
        if s.pending and s.pending[0].time <= k * self.T + 1e-9:
            self._advance(s, k)
            while s.pending and s.pending[0].time <= k * self.T + 1e-9:  # the runner's rule for an event's step
                ev = s.pending.pop(0)
                s.x_a, s.st_a = s.model.apply(ev, s.x_a, s.st_a)
                if isinstance(ev, SensorDelay):
                    s.pose_step.delay(ev.steps)
            half = s.model.half
            s.A = None  # the step's Jacobian taken afresh on the changed robot
            for i in range(half):  # told a change: the velocities less certain (it jolts the robot)
                s.P[half + i, half + i] += self.config.told_std * self.config.told_std
        m = k - (k - s.pose_step.read() if k > 0 else 0)
        if m > s.fused and m >= s.a:
            self._advance(s, m)
            Hx = s.model.pose_jacobian(s.x_a, s.st_a, m)
            st = s.st_a
            nu = np.array([pose[0] - st[4], pose[1] - st[5], wrap(pose[2] - st[6])])
            r = self.noise * self.noise
            if wheels is not None:
                Hw, predicted = s.model.wheel_rows(s.x_a)
                nu_w, r_w = wheels - predicted, self.wheel_noise * self.wheel_noise
                self._slip(s.P, Hw, nu_w, r_w)
                Hx, nu = np.vstack([Hx, Hw]), np.concatenate([nu, nu_w])
                r = np.concatenate([r, np.full(2, r_w)])
            dx = np.zeros(s.model.n)
            kalman_update(s.P, Hx, r, nu, dx)
            s.x_a, s.st_a = s.model.correct(s.x_a, s.st_a, m, dx)
            s.fused = m
        x, st = s.x_a, s.st_a
        for j, u in enumerate(s.sent):
            x1, st1, why = s.model.transition(x, st, s.a + j, u, 0.0, _NO_A)
            if why == 0:
                x, st = x1, st1
        s.x, s.st = x, st

    def _slip(self, P: np.ndarray, Hw: np.ndarray, nu: np.ndarray, r: float) -> None:
        """A wheel whose measured speed is further from the model's than ``slip_gate`` standard
        deviations of its innovation (nu^2 > gate^2 (P_ww + r)) slips as the model's wheel does not
        (at the traction limit a wheel's stick and slip turn on a micrometre of the state): its
        speed's variance grows by the innovation's square, so the encoder sets the wheel's speed
        and, through the covariance the wheel's grip built, hardly moves the chassis'."""
        gate = self.config.slip_gate
        for i in range(Hw.shape[0]):
            j = int(np.flatnonzero(Hw[i])[0])
            if nu[i] * nu[i] > gate * gate * (P[j, j] + r):
                P[j, j] += nu[i] * nu[i]

    def _advance(self, s: _Seed, m: int) -> None:
        """The anchor moved on to step m through the commands sent, the covariance with it (the
        step's Jacobian taken afresh every ``reuse`` + 1 steps, and after an event: the robot turns
        little in between)."""
        n = s.model.n
        q = np.zeros(n)
        q[s.model.half :] = self._q_velocity()
        while s.a < m:
            settled = s.cost < 3 * self.H * self.config.settled_m * self.config.settled_m
            fresh = s.A is None or s.A.shape[0] != n or s.A_age >= self.config.reuse or not settled
            A = np.zeros((n, n)) if fresh else _NO_A
            x1, st1, why = s.model.transition(s.x_a, s.st_a, s.a, s.sent.pop(0), FD_STEP, A)
            if fresh:
                s.A, s.A_age = A, 0
            else:
                s.A_age += 1
            if why == 0:
                s.x_a, s.st_a = x1, st1
                covariance_predict(s.P, s.A, q)
            s.a += 1

    # -- the plan

    def _plan(self, s: _Seed, k: int, b: int) -> np.ndarray:
        """Gauss-Newton steps on the plan's knots from the state at step k, each accepted only if
        the plan it gives costs less (Levenberg-Marquardt: the damping mu grows by 4 on a step
        refused, shrinks by 3 on one taken, and the step is cut to a trust radius in the commands'
        scale that halves or doubles with them: where the robot hardly answers its commands (its
        wheels spinning on the floor) the linear model's step is no step to take), until a step
        gains less than ``tolerance`` or the plan's residuals are within ``settled_m``. Once they
        are (the last step's plan settled), the residuals' Jacobian of the step before serves
        ``reuse`` more steps (the plan it was taken on is a step older: a step on the same knots)
        and the step is taken unchecked. The first knot is sent; the plan is shifted a step."""
        cfg, H, phi = self.config, self.H, self._phi
        M, w, scale = 2 * cfg.knots, self._w, self._scale
        settled = 3 * H * cfg.settled_m * cfg.settled_m  # a plan this close needs no second step
        delta = np.zeros(M)
        E1, U1 = np.empty((1, H, 3)), np.empty((1, H, 2))
        cost = math.inf
        if s.J is not None and s.age < cfg.reuse and s.cost < settled:
            U1[0] = np.einsum("jk,kc->jc", phi, s.knots)
            s.model.rollouts(s.x, s.st, k, U1, self.preview, E1)
            self._weigh(E1)
            cost = plan_cost(E1[0])
            if cost < settled:
                gauss_newton(s.J, E1[0], s.mu, 1.0e-12, delta)
                s.knots = np.clip(s.knots + delta.reshape(cfg.knots, 2), -self.limits, self.limits)
                s.age += 1
                return self._sent(s, b, cost)
        E = np.empty((1 + M, H, 3))
        U = np.empty((1 + M, H, 2))
        if s.J is None:
            s.J = np.empty((M, 3 * H))
        taken = True  # the knots moved since the Jacobian (after a step refused: the same J and residuals)
        for _ in range(cfg.iterations):
            if taken:
                U[:] = np.einsum("jk,kc->jc", phi, s.knots)
                for p in range(M):
                    i, c = divmod(p, 2)
                    U[1 + p, :, c] += phi[:, i] * w[p]
                s.model.rollouts(s.x, s.st, k, U, self.preview, E)
                self._weigh(E)
                cost = plan_cost(E[0])
                if not math.isfinite(cost) or cost >= FAILED_COST:
                    break
                residual_jacobian(E, w, s.J)
                s.age = 0
            gauss_newton(s.J, E[0], s.mu, 1.0e-12, delta)
            longest = float(np.max(np.abs(delta) / scale))
            if longest > s.radius:
                delta *= s.radius / longest
            knots = np.clip(s.knots + delta.reshape(cfg.knots, 2), -self.limits, self.limits)
            if cost < settled:  # close to the plan's optimum: the linear model's step is taken unchecked
                s.knots = knots
                break
            U1[0] = np.einsum("jk,kc->jc", phi, knots)
            s.model.rollouts(s.x, s.st, k, U1, self.preview, E1)
            self._weigh(E1)
            new = plan_cost(E1[0])
            taken = new < cost
            if taken:
                gain = (cost - new) / cost
                s.knots, cost = knots, new
                s.mu, s.radius = max(s.mu / 3.0, cfg.damping), min(2.0 * s.radius, cfg.trust)
                if gain < cfg.tolerance or new < settled:  # converged: the next step starts from here
                    break
            else:
                s.mu, s.radius = min(4.0 * s.mu, MU_MAX), max(0.5 * s.radius, RADIUS_MIN)
        return self._sent(s, b, cost)

    def _weigh(self, E: np.ndarray) -> None:
        """The rollouts' errors (R, H, 3) as the plan's residuals: the heading's weighed by
        ``heading_m``, at the horizon's end by ``heading_end_m`` (the plan ends along the path)."""
        E[:, :-1, 2] *= self.config.heading_m
        E[:, -1, 2] *= self.config.heading_end_m

    def _sent(self, s: _Seed, b: int, cost: float) -> np.ndarray:
        """The plan's first knot, sent; the plan shifted a step for the next."""
        s.cost = cost
        self._tele[b] = (cost, s.mu)
        u = s.knots[0].copy()
        s.knots = _shift(s.knots, self._at)
        return u


def _knot_steps(H: int, knots: int) -> list[int]:
    if knots == 1:
        return [0]
    return [int(round(i * (H - 1) / (knots - 1))) for i in range(knots)]


def _spline(H: int, knots: int) -> np.ndarray:
    """(H, knots): the commands at each step of the horizon as the linear spline of the knots."""
    at = _knot_steps(H, knots)
    phi = np.zeros((H, knots))
    for j in range(H):
        if knots == 1 or j >= at[-1]:
            phi[j, -1] = 1.0
            continue
        i = max(i for i in range(knots - 1) if at[i] <= j)
        span = at[i + 1] - at[i]
        a = (j - at[i]) / span
        phi[j, i], phi[j, i + 1] = 1.0 - a, a
    return phi


def _shift(knots: np.ndarray, at: list[int]) -> np.ndarray:
    """The plan one step on: each knot (at its step ``at``) the spline's value a step later (the last held)."""
    out = knots.copy()
    for i, j in enumerate(at):
        t = j + 1
        if knots.shape[0] == 1 or t >= at[-1]:
            out[i] = knots[-1]
            continue
        m = max(m for m in range(len(at) - 1) if at[m] <= t)
        a = (t - at[m]) / (at[m + 1] - at[m])
        out[i] = (1.0 - a) * knots[m] + a * knots[m + 1]
    return out
