"""Many seeds of one scenario stepped together: the batched path of ``mlpfac sweep --batched``.

The closed loop of :func:`mlpfac.runner.run`, with a leading batch dimension on every array:
the networks take z (B, alpha) as they are (:mod:`mlpfac.networks`), the law (35) takes e (B, 3),
the EKF (:mod:`mlpfac.estimators`) runs per seed or per small chunk of seeds (see
:class:`BatchAdaptive`: its covariance update is memory-bound), and the kinematic plant (7) is
vectorised here. A seed that diverges is dropped from the batch at that step (its
record ends there, as a one-at-a-time run breaks out of its loop); the others go on.

Equality with one-at-a-time runs: each seed draws its initial weights and its noise from its own
generators in the same order as :func:`mlpfac.runner.run`, and every operation is the same numpy
call on a stack (stacked ``matmul`` and ``linalg.solve`` call the same BLAS/LAPACK kernel per
matrix; elementwise ufuncs round each element alike). On this machine (OpenBLAS 0.3.31, x86-64)
the per-seed records and metrics are **bit-identical** to one-at-a-time runs (tests/test_batch.py).
On another BLAS a stacked call could take another kernel and differ in the last bit; the
chaotic part of a diverging run can amplify that.

Plants other than the kinematic one (MuJoCo) are kept as a list of ordinary plant objects, one per
seed, stepped in a loop: the controller (the expensive part) is batched, the physics is exactly
the one-at-a-time physics. Controllers without a batched form run one at a time.

Per-seed records keep what :func:`mlpfac.runner.metrics` reads: all top-level arrays, and as
controller telemetry only ``z`` reduced to max |z| per step (N, 1) and ``mean_diag_P`` (N,), so
64 seeds do not store 64 x N x alpha weights. ``wall_time_s`` is the batch's wall time / B.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from collections import deque

import numpy as np

from mlpfac.controllers import Adaptive, Corradini, Kanayama
from mlpfac.error_model import tracking_error
from mlpfac.estimators import EKF, covariance
from mlpfac.record import RunRecord
from mlpfac.reference import sample
from mlpfac.runner import _diverged, run, seeded_generators
from mlpfac.scenario import Scenario

# --------------------------------------------------------------------------------------------
# Error model (2), (5)-(6) over a batch: the same arithmetic as mlpfac.error_model, rows of (B, 3)


def tracking_error_b(q: np.ndarray, q_r: np.ndarray) -> np.ndarray:
    """Eq. (2) for poses q (B, 3) and one reference pose q_r. (B, 3)"""
    c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
    dx, dy = q_r[0] - q[:, 0], q_r[1] - q[:, 1]
    d = q_r[2] - q[:, 2]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, np.pi - np.mod(np.pi - d, 2.0 * np.pi)], -1)


def pose_from_error_b(e: np.ndarray, q_r: np.ndarray) -> np.ndarray:
    """Inverse of (2) for errors e (B, 3). (B, 3)"""
    theta = q_r[2] - e[:, 2]
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([q_r[0] - (c * e[:, 0] - s * e[:, 1]), q_r[1] - (s * e[:, 0] + c * e[:, 1]), theta], -1)


# --------------------------------------------------------------------------------------------
# Controllers over a batch


class BatchAdaptive:
    """:class:`mlpfac.controllers.Adaptive` over a batch: the networks and the law see all seeds at once
    (z (B, alpha)); the EKF runs on chunks of ``chunk`` seeds, P (chunk, alpha, alpha), so that each
    chunk's covariance stays in the CPU cache: a (64, 171, 171) stack is 15 MB and made the
    memory-bound covariance update slower per seed than one run's 234 kB. Measured (32 seeds,
    2 s each, vs one at a time): chunk 1: 1.6x, 2: 1.5x, 4: 1.2x, 8: 1.0x, 32: 1.1x."""

    chunk = 1

    def __init__(self, ctrl: Adaptive) -> None:
        self.law, self.config, self.nets = ctrl.law, ctrl.config, ctrl.nets

    def reset(self, T: float, rngs: list[np.random.Generator]) -> None:
        c, a = self.config, self.nets.alpha
        self.T = T
        z0 = np.stack([rng.normal(0.0, c.weight_std, a) for rng in rngs])
        if getattr(c, "output_weight_std", None) is not None:  # as Adaptive.reset: rescale the same draws
            z0[:, self.nets.output_mask()] *= c.output_weight_std / c.weight_std
        self.ekfs = [
            EKF(
                z0=z0[i : i + self.chunk],
                P0=c.P0 * np.eye(a),
                R=covariance(c.R, 3, "R"),
                Q=c.Q * np.eye(a) if c.Q > 0 else None,
                forgetting=c.forgetting,
                P_max=c.P_max,
            )
            for i in range(0, len(z0), self.chunk)
        ]
        self.prev: tuple | None = None

    @property
    def z(self) -> np.ndarray:
        return np.concatenate([ekf.z for ekf in self.ekfs])  # (B, alpha)

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        nets = self.nets
        if self.prev is not None:  # (28)-(32): nabla_h for all seeds at once, then the EKF per chunk
            x_f, x_G, e_prev, u_prev, head = self.prev  # the hidden layers at z_k, from last step's law
            h, H = nets.h_and_jacobian(self.z, x_f, x_G, e_prev, u_prev, head)
            i = 0
            for ekf in self.ekfs:
                sl = slice(i, i + len(ekf.z))
                ekf.update(e[sl], lambda z, sl=sl: (h[sl], H[sl]))
                i = sl.stop
        x_f, x_G = nets.inputs(e, r[3], r[4])
        z = self.z
        head = nets.head(z, x_f, x_G, e)
        f_hat, G_hat = nets.forward(z, x_f, x_G, e, head)
        h_hat = np.stack([G_hat[:, 0, 1], f_hat[:, 0] - e[:, 0], f_hat[:, 2] - e[:, 2]], -1)  # (34)
        u = self.law.control(e, h_hat, r[3], self.T)
        self.prev = (x_f, x_G, e, u, head)
        return u

    def telemetry(self) -> dict[str, np.ndarray]:
        """What metrics() reads: max |z| per seed (B, 1) and mean diag P (B,)."""
        d = np.concatenate([np.diagonal(ekf.P, axis1=-2, axis2=-1) for ekf in self.ekfs])
        return {"z": np.max(np.abs(self.z), axis=-1, keepdims=True), "mean_diag_P": d.mean(axis=-1)}

    def keep(self, mask: np.ndarray) -> None:
        z = self.z[mask]
        P = np.concatenate([ekf.P for ekf in self.ekfs])[mask]
        ekfs = []
        for i in range(0, len(z), self.chunk):
            ekf = copy.copy(self.ekfs[0])
            ekf.z, ekf.P = z[i : i + self.chunk], P[i : i + self.chunk]
            ekfs.append(ekf)
        self.ekfs = ekfs
        if self.prev is not None:
            *arrays, head = self.prev
            self.prev = (*(x[mask] for x in arrays), tuple(x[mask] for x in head))


class BatchCorradini:
    """:class:`mlpfac.controllers.Corradini`: (35) with h = (T e2, T v_r cos e3, T omega_r)."""

    def __init__(self, ctrl: Corradini) -> None:
        self.law = ctrl.law

    def reset(self, T: float, rngs: list[np.random.Generator]) -> None:
        self.T = T

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        T = self.T
        h = np.stack([T * e[:, 1], T * r[3] * np.cos(e[:, 2]), np.full(len(e), T * r[4])], -1)
        return self.law.control(e, h, r[3], T)

    def telemetry(self) -> dict[str, np.ndarray]:
        return {}

    def keep(self, mask: np.ndarray) -> None:
        pass


class BatchKanayama(BatchCorradini):
    """:class:`mlpfac.controllers.Kanayama` over a batch."""

    def __init__(self, ctrl: Kanayama) -> None:
        self.law, self.g = ctrl.law, ctrl.g

    def step(self, e: np.ndarray, r: np.ndarray) -> np.ndarray:
        g, v_r = self.g, r[3]
        v = v_r * np.cos(e[:, 2]) + g.Kx * e[:, 0]
        omega = r[4] + v_r * (g.Ky * e[:, 1] + g.Ktheta * np.sin(e[:, 2]))
        if self.law.v_max is not None:
            v = np.clip(v, -self.law.v_max, self.law.v_max)
        if self.law.omega_max is not None:
            omega = np.clip(omega, -self.law.omega_max, self.law.omega_max)
        return np.stack([v, omega], -1)


# The AdaptiveConfig fields BatchAdaptive implements; any other field away from its default (the UKF,
# the cautious law, the prior, learned gains, ...) makes the seeds run one at a time.
BATCHED_ADAPTIVE_FIELDS = frozenset(
    {"networks", "P0", "R", "Q", "forgetting", "P_max", "weight_std", "output_weight_std"}
)


def batch_controller(ctrl):
    """The batched form of a controller object, or None if it has none (then seeds run one at a time)."""
    if type(ctrl) is Adaptive:
        default = type(ctrl.config)()
        for f in dataclasses.fields(ctrl.config):
            if f.name not in BATCHED_ADAPTIVE_FIELDS and getattr(ctrl.config, f.name) != getattr(default, f.name):
                return None
        return BatchAdaptive(ctrl)
    if type(ctrl) is Corradini:
        return BatchCorradini(ctrl)
    if type(ctrl) is Kanayama:
        return BatchKanayama(ctrl)
    return None


# --------------------------------------------------------------------------------------------
# Plants over a batch


class BatchKinematic:
    """:class:`mlpfac.plants.kinematic.KinematicPlant` over a batch: e (B, 3), one T_p and delay for all."""

    def __init__(self, scn: Scenario, ref: np.ndarray) -> None:
        self.one = scn.make_plant(ref)  # the one-at-a-time plant: L, event checks and texts
        self.T, self.ref = scn.T, ref
        self.N = scn.steps

    def reset(self, q0: np.ndarray, rngs: list[np.random.Generator], u0: np.ndarray | None = None) -> None:
        B, L = len(rngs), self.one.L
        self.one.reset(q0, None, u0)  # holds T_p and the delay line's length for events; never stepped
        self.k, self.T_p = 0, self.T
        self.e = np.tile(tracking_error(q0, self.ref[0]), (B, 1))
        # each seed's noise, drawn as one run draws it (3 normals per step; one call for all steps
        # gives the same stream), times L as a stack of L @ n (same kernel as the single matvec)
        self.noise = (
            None if L is None else (L @ np.stack([rng.standard_normal((self.N, 3)) for rng in rngs])[..., None])[..., 0]
        )
        self.idx = np.arange(B)
        self.history: deque[np.ndarray] = deque([self.true_pose()], maxlen=1)

    def true_pose(self) -> np.ndarray:
        return pose_from_error_b(self.e, self.ref[self.k])

    def measure(self) -> np.ndarray:
        return self.history[0]

    def step(self, u: np.ndarray) -> None:
        r, e, Tp = self.ref[self.k], self.e, self.T_p
        f = np.stack(
            [e[:, 0] + Tp * r[3] * np.cos(e[:, 2]), e[:, 1] + Tp * r[3] * np.sin(e[:, 2]), e[:, 2] + Tp * r[4]], -1
        )  # (5)
        zero = np.zeros(len(e))
        G = np.stack(
            [
                np.stack([np.full(len(e), -Tp), Tp * e[:, 1]], -1),
                np.stack([zero, -Tp * e[:, 0]], -1),
                np.stack([zero, np.full(len(e), -Tp)], -1),
            ],
            -2,
        )  # (6)
        e_next = f + (G @ u[:, :, None])[..., 0]  # (7)
        if self.noise is not None:
            e_next = e_next + self.noise[self.idx, self.k]
        self.e = e_next
        self.k += 1
        self.history.append(self.true_pose())

    def apply(self, event) -> str:
        text = self.one.apply(event)
        self.T_p = self.one.T_p
        if event.kind == "sensor_delay":
            self.history = deque(self.history, maxlen=self.one.history.maxlen)
        return text

    def diverged(self) -> list[str | None]:
        ok = np.all(np.isfinite(self.e), axis=-1)
        return [None if x else "non-finite tracking error" for x in ok]

    def sim_time(self, i: int, n: int) -> float:
        return n * self.T

    def keep(self, mask: np.ndarray) -> None:
        self.e, self.idx = self.e[mask], self.idx[mask]
        self.history = deque((h[mask] for h in self.history), maxlen=self.history.maxlen)


class PlantList:
    """Any plant (MuJoCo) as one object per seed, stepped in a loop: the physics of one-at-a-time runs."""

    def __init__(self, scns: list[Scenario], ref: np.ndarray) -> None:
        self.plants = [s.make_plant(ref) for s in scns]
        self.live = list(range(len(scns)))

    def reset(self, q0: np.ndarray, rngs: list[np.random.Generator], u0: np.ndarray | None = None) -> None:
        for p, rng in zip(self.plants, rngs, strict=True):
            p.reset(q0, rng, u0)

    def _each(self, name: str) -> np.ndarray:
        return np.stack([getattr(self.plants[i], name)() for i in self.live])

    def true_pose(self) -> np.ndarray:
        return self._each("true_pose")

    def measure(self) -> np.ndarray:
        return self._each("measure")

    def step(self, u: np.ndarray) -> None:
        for i, ui in zip(self.live, u, strict=True):
            self.plants[i].step(ui)

    def apply(self, event) -> str:
        texts = [self.plants[i].apply(event) for i in self.live]
        return texts[0] if texts else ""

    def diverged(self) -> list[str | None]:
        return [self.plants[i].diverged() for i in self.live]

    def sim_time(self, i: int, n: int) -> float:
        return float(getattr(self.plants[i], "sim_time", n * self.plants[i].T))

    def keep(self, mask: np.ndarray) -> None:
        self.live = [i for i, m in zip(self.live, mask, strict=True) if m]


# --------------------------------------------------------------------------------------------
# The batched closed loop


def same_but_seed(scns: list[Scenario]) -> bool:
    t0 = {k: v for k, v in scns[0].table.items() if k != "seed"}
    return all({k: v for k, v in s.table.items() if k != "seed"} == t0 for s in scns[1:])


def run_batch(scns: list[Scenario], plant_list: bool = False) -> list[RunRecord]:
    """Run seeds of one scenario together; one record per scenario, equal to ``run(scn)`` (see module doc).

    ``scns`` must differ in their seed only (ValueError otherwise). ``plant_list`` steps one plant
    object per seed even for the kinematic plant (the path MuJoCo takes). KeyboardInterrupt
    propagates: an interrupted batch has no whole run.
    """
    if not scns:
        return []
    if not same_but_seed(scns):
        raise ValueError("run_batch needs scenarios that differ in their seed only")
    base = scns[0]
    ctrl = base.make_controller()
    bctrl = batch_controller(ctrl)
    if bctrl is None or len(scns) == 1:
        return [_one(s) for s in scns]
    B, N, T = len(scns), base.steps, base.T
    wall0 = time.perf_counter()
    ref = sample(base.reference, np.arange(N + 1) * T)  # (N + 1, 5)
    plant = BatchKinematic(base, ref) if base.plant_kind == "kinematic" and not plant_list else PlantList(scns, ref)
    gens = [seeded_generators(s.seed) for s in scns]
    bctrl.reset(T, [c for c, _ in gens])
    q0, u0 = base.initial_state(ref)
    plant.reset(q0, [p for _, p in gens], u0)

    nan = np.full
    pose, pose_meas, e_all, e_true, u_all = (nan((B, N, d), np.nan) for d in (3, 3, 3, 3, 2))
    tele: dict[str, np.ndarray] = {}
    recs = []
    for b, s in enumerate(scns):
        rec = RunRecord(
            s.name,
            ctrl.name,
            s.seed,
            T,
            np.arange(N) * T,
            np.array(ref[:N]),
            pose[b],
            pose_meas[b],
            e_all[b],
            e_true[b],
            u_all[b],
        )
        rec.warmup_s, rec.split_s = s.warmup, s.events[0].time if s.events else None
        rec.labels = dict(ctrl.labels)
        recs.append(rec)
    active = np.arange(B)
    pending = list(base.events)
    try:
        for k in range(N):
            t = k * T
            while pending and pending[0].time <= t + 1e-9:
                ev = pending.pop(0)
                text = plant.apply(ev)
                for b in active:
                    recs[b].events.append({"time": t, "kind": ev.kind, "params": dict(ev.params), "text": text})
            q = plant.true_pose()
            q_meas = plant.measure()
            r = ref[k]
            e = tracking_error_b(q_meas, r)
            u = bctrl.step(e, r)
            pose[active, k], pose_meas[active, k], e_all[active, k] = q, q_meas, e
            e_true[active, k] = tracking_error_b(q, r)
            u_all[active, k] = u
            for key, val in bctrl.telemetry().items():
                if key not in tele:
                    tele[key] = nan((B, N, *val.shape[1:]), np.nan)
                    for b in range(B):
                        recs[b].ctrl[key] = tele[key][b]
                tele[key][active, k] = val
            for b in active:
                recs[b].n = k + 1
            # runner._diverged's test, vectorised; the reason text comes from runner._diverged itself
            bad = ~(np.all(np.isfinite(q), -1) & np.all(np.isfinite(u), -1))
            if "z" in tele:
                bad |= ~np.all(np.isfinite(tele["z"][active, k]), -1)
            bad |= np.hypot(e_true[active, k, 0], e_true[active, k, 1]) > base.divergence_m
            for b in active[bad]:
                _stop(recs[b], _diverged(recs[b], k, base.divergence_m), t)
            if bad.any():
                active = _keep(active, ~bad, plant, bctrl)
                if not len(active):
                    break
            plant.step(u[~bad])
            reasons = plant.diverged()
            gone = np.array([x is not None for x in reasons])
            if gone.any():
                for b, why in zip(active[gone], [x for x in reasons if x is not None], strict=True):
                    _stop(recs[b], why, t)
                active = _keep(active, ~gone, plant, bctrl)
                if not len(active):
                    break
    finally:
        wall = (time.perf_counter() - wall0) / B
        for b, rec in enumerate(recs):
            rec.wall_time_s = wall
            rec.sim_time_s = plant.sim_time(b, rec.n)
    return recs


def _stop(rec: RunRecord, reason: str | None, t: float) -> None:
    rec.status, rec.reason = "diverged", f"{reason} at t = {t:.2f} s"


def _keep(active: np.ndarray, mask: np.ndarray, plant, bctrl) -> np.ndarray:
    plant.keep(mask)
    bctrl.keep(mask)
    return active[mask]


def _one(scn: Scenario) -> RunRecord:
    rec = run(scn)
    if rec.status == "interrupted":
        raise KeyboardInterrupt
    return rec
