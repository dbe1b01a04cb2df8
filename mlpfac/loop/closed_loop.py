"""The closed loop's steps for B seeds of one scenario: reference -> error (2) -> controller ->
plant, each seed's record a row of shared (B, N, ...) arrays; stepped in Python, or compiled from
one event or log flush to the next (:mod:`mlpfac.loop.compiled`) for a MuJoCo plant with a law
kernel, to the same bits. :mod:`mlpfac.loop.runner` builds what it needs and runs it."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mlpfac.control.baselines import LawKernel, StateKernel, Stepped
from mlpfac.control.torque import Observation, reference_rates
from mlpfac.elementary import hypot
from mlpfac.io.interrupts import raise_swallowed
from mlpfac.loop.compiled import ADAPTIVE, BAD, no_state, segment
from mlpfac.loop.kernels import bad_seeds
from mlpfac.loop.record import RunRecord
from mlpfac.model import tracking_errors
from mlpfac.plants.base import CompiledPlant, Plant
from mlpfac.scenario.parse import Scenario

FLUSH_EVERY = 250  # steps between sends to a log sink
SEGMENT_PHYSICS = 5_000  # physics steps of one compiled segment, at most: a signal waits for no more


def seeded_generators(seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    """Independent streams for the controller's initial weights and the plant's noise."""
    c, p = np.random.SeedSequence(seed).spawn(2)
    return np.random.default_rng(c), np.random.default_rng(p)


class PlantList:
    """Plants without a batch form (MuJoCo) as one object per seed, stepped in a loop: each seed's
    physics is exactly its one-at-a-time physics. Poses (B, 3); ``live`` seeds only are stepped."""

    batched = True

    def __init__(self, plants: list) -> None:
        self.plants = plants

    def reset(self, q0: np.ndarray, rngs: list[np.random.Generator], u0: np.ndarray | None = None) -> None:
        for p, rng in zip(self.plants, rngs, strict=True):
            p.reset(q0, rng, u0)
        self.live = list(range(len(self.plants)))
        self._q, self._m, self._w = (np.zeros((len(self.plants), d)) for d in (3, 3, 4))
        self._read()

    def _read(self) -> None:
        for i in self.live:
            self._q[i] = self.plants[i].true_pose()
            self._m[i] = self.plants[i].measure()

    def true_pose(self) -> np.ndarray:
        return self._q

    def measure(self) -> np.ndarray:
        return self._m

    def step(self, u: np.ndarray) -> None:
        for i in self.live:
            self.plants[i].step(u[i])
        self._read()

    def apply(self, event) -> str:
        texts = [self.plants[i].apply(event) for i in self.live]
        return texts[0] if texts else ""

    def put_telemetry(self, store: dict[str, np.ndarray], recs: list[RunRecord], k: int) -> None:
        """Row k of each live seed's plant telemetry, into ``store`` (B, N, ...) (allocated on first use)."""
        for i in self.live:
            tele = self.plants[i].telemetry()
            if not store:
                _allocate(
                    store,
                    {key: np.asarray(v)[None] for key, v in tele.items()},
                    recs,
                    "plant",
                    len(recs),
                    len(recs[0].t),
                    True,
                )
            for key, val in tele.items():
                store[key][i, k] = val

    def diverged(self) -> list[str | None]:
        return [self.plants[i].diverged() if i in self.live else None for i in range(len(self.plants))]

    def motion(self) -> np.ndarray:
        """(B, 4) (v, omega, wheel_l, wheel_r) as each live seed's robot measures them (torque commands)."""
        for i in self.live:
            self._w[i] = self.plants[i].motion()
        return self._w

    def drop(self, i: int) -> None:
        self.live.remove(i)


class ClosedLoop:
    """One closed loop's state: the seeds' records (rows of shared (B, N, ...) arrays), the seeds
    still live, where each stopped; stepped in Python (:meth:`run_steps`) or compiled between
    events and flushes (:meth:`run_segments`, a MuJoCo plant with a law kernel)."""

    def __init__(
        self,
        scns: list[Scenario],
        ref: np.ndarray,
        plant,
        ctrl: Stepped,
        full: bool,
        compiled: bool,
        rates: np.ndarray | None = None,
        end: tuple[int, str] | None = None,
    ):
        """``rates``: the reference's (dv_r, domega_r) where it gives them (else its samples' finite
        differences); ``end``: (step, why) where the reference stops being finite (your own class):
        every seed ends there, as diverged."""
        base = scns[0]
        self.end = end
        self.base, self.ref, self.ctrl, self.full = base, ref, ctrl, full
        B, N = len(scns), base.steps
        self.B, self.N, self.T = B, N, base.T
        if isinstance(plant, list) or not plant.batched:
            plant = PlantList(plant if isinstance(plant, list) else [plant])
        self.plant: Plant | PlantList = plant
        self.listed = isinstance(plant, PlantList)
        gens = [seeded_generators(s.seed) for s in scns]
        ctrl.reset([c for c, _ in gens])
        q0, u0 = base.initial_state(ref)
        plant.reset(q0, [p for _, p in gens], u0)
        ctrl.watch(plant.plants if isinstance(plant, PlantList) else [plant])
        self.pose, self.pose_meas, self.e, self.e_true, self.u = (np.full((B, N, d), np.nan) for d in (3, 3, 3, 3, 2))
        self.recs = [self._record(b, s) for b, s in enumerate(scns)]
        for b, rec in enumerate(self.recs):  # the terrain each seed's robot drives on (its own rough ground)
            rec.world = (plant.plants[b] if self.listed else plant).terrain_record()
        self.ctrl_store: dict[str, np.ndarray] = {}
        self.plant_store: dict[str, np.ndarray] = {}
        self._e, self._et = np.zeros((B, 3)), np.zeros((B, 3))  # step k's errors (2), measured and true
        self.bad = np.zeros(B, dtype=np.bool_)
        self.no_z = np.zeros((B, 0))
        self.live = list(range(B))
        self.pending = list(base.events)
        self.stopped: dict[int, tuple[int, int]] = {}  # seed -> (its record's rows, its plant telemetry's rows)
        e = np.zeros((0, 3))
        tracking_errors(e, ref[0], e)  # load (or compile) the loop's kernels before it starts
        bad_seeds(e, np.zeros((0, 2)), e, self.no_z[:0], 1.0, self.bad[:0])
        self.torque = ctrl.level == "torque"  # step(obs) -> wheel torques
        if self.torque:
            self.r_dot = reference_rates(ref, self.T) if rates is None else rates
        self.compiled = compiled and self.listed and _compiled(plant, ctrl)
        if self.compiled:
            self._prepare_segments()

    def _record(self, b: int, scn: Scenario) -> RunRecord:
        """Seed b's record, its arrays rows of the loop's."""
        rec = RunRecord(scn.name, self.ctrl.name, scn.seed, self.T, np.arange(self.N) * self.T,
                        np.array(self.ref[: self.N]), self.pose[b], self.pose_meas[b], self.e[b], self.e_true[b],
                        self.u[b])  # fmt: skip
        rec.warmup_s, rec.split_s = scn.warmup, scn.events[0].time if scn.events else None
        rec.lost_threshold_m = scn.lost_threshold_m
        rec.labels = dict(self.ctrl.labels)
        rec.pose_source = getattr(scn.plant_config, "pose_source", "truth")  # what pose_meas is
        return rec

    def geometry(self) -> list[dict]:
        return self.plant.plants[0].geometry() if self.listed else self.plant.geometry()

    # -- compiled between events and flushes (mlpfac.loop.compiled)

    def _prepare_segments(self) -> None:
        """The telemetry arrays a compiled segment writes, and its kernels loaded by a segment of no step."""
        plants = self.plant.plants
        self.ctele = _allocate(self.ctrl_store, self.ctrl.telemetry(), self.recs, "ctrl", self.B, self.N, self.full)
        self.ptele = self.plant_rows()
        if isinstance(self.ctrl, LawKernel):
            self.law, self.states = self.ctrl.law_kernel(0), [no_state()] * self.B
        else:
            none = np.zeros(0)
            self.law, self.states = (ADAPTIVE, none, none), [self.ctrl.kernel_state(b) for b in range(self.B)]
        pose = self.pose[0]
        segment(0, 0, self.ref, *self.law, 1.0, pose, pose, pose, pose, self.u[0], self.ctele[0], self.ptele[0],
                np.zeros((0, 3)), self.states[0], plants[0].kernel_args())  # fmt: skip

    def plant_rows(self) -> np.ndarray:
        """The plant's telemetry (B, N, W), allocated now: each row what a compiled step writes."""
        tele = {k: v[None] for k, v in self.plant.plants[0].telemetry().items()}
        return _allocate(self.plant_store, tele, self.recs, "plant", self.B, self.N, True)

    def run_segments(self, sink) -> None:
        k, N, T = 0, self.N, self.T
        while k < N and self.live:
            raise_swallowed()
            if self._reference_ended(k):
                break
            _apply_due(self.pending, k, T, self.plant, self.recs, self.live)
            if self.law[0] != ADAPTIVE:  # an oracle takes the changes it is told with the events
                self.law = self.ctrl.law_kernel(k)
            most = max(1, SEGMENT_PHYSICS // max(p._n for p in self.plant.plants))  # a signal waits no longer
            k1 = min(N, (k // FLUSH_EVERY + 1) * FLUSH_EVERY, k + most)
            if self.pending:  # up to the next event
                k1 = next((j for j in range(k + 1, k1) if self.pending[0].time <= j * T + 1e-9), k1)
            if self.end is not None and k < self.end[0]:
                k1 = min(k1, self.end[0])
            for b in list(self.live):
                self._segment(b, k, k1)
            k = k1
            if self.live and sink is not None and k % FLUSH_EVERY == 0:
                sink.flush(self.recs[0], k)

    def _segment(self, b: int, k: int, k1: int) -> None:
        """Seed b's steps k to k1, compiled; it stops where the runner's test or its plant stops it."""
        p, limit = self.plant.plants[b], self.base.divergence_m
        end, why = segment(k, k1, self.ref, *self.law, limit, self.pose[b], self.pose_meas[b], self.e[b],
                           self.e_true[b], self.u[b], self.ctele[b], self.ptele[b], p.draws(k1 - k),
                           self.states[b], p.kernel_args())  # fmt: skip
        self.recs[b].n = min(end + 1, k1)
        if why == BAD:
            z = self.states[b].z[0] if self.law[0] == ADAPTIVE else None  # the weights after step ``end``
            self.stop(b, _diverged(self.pose[b, end], self.u[b, end], self.e_true[b, end], z, limit), end, end)
        elif why:
            self.stop(b, p.why(why), end, end + 1)

    # -- step by step in Python

    def run_steps(self, sink, on_step: Callable[[int], None] | None) -> None:
        for k in range(self.N):
            raise_swallowed()
            if not self.begin(k) or not self._control(k) or not self.actuate(k):
                break
            if on_step is not None:
                on_step(k)
            if sink is not None and (k + 1) % FLUSH_EVERY == 0:
                sink.flush(self.recs[0], k + 1)

    def begin(self, k: int) -> bool:
        """Step k about to start: the events due applied. False: the reference stopped being finite
        here, and every live seed ended."""
        if self._reference_ended(k):
            return False
        _apply_due(self.pending, k, self.T, self.plant, self.recs, self.live)
        return True

    def _control(self, k: int) -> bool:
        """Step k's errors (2) and command, recorded; the seeds whose step diverged stop. False: none live."""
        return self.command(k, self.ctrl.step(*self.observe(k)))

    def observe(self, k: int) -> tuple:
        """Step k's errors (2) of the measured pose, and what the controller is given for them:
        ``(e, r)``, or ``(Observation,)`` at the torque level. A caller that commands the plant
        itself (:mod:`mlpfac.envs`) then hands its command to :meth:`command` and :meth:`actuate`."""
        q, q_meas, r, e = self.plant.true_pose(), self.plant.measure(), self.ref[k], self._e
        tracking_errors(q_meas, r, e)
        self._q, self._q_meas = q, q_meas
        if self.torque:
            w = self.plant.motion()
            return (Observation(e, r, self.r_dot[k], q_meas, w[:, :2], w[:, 2:], k * self.T),)
        return e, r

    def command(self, k: int, u: np.ndarray) -> bool:
        """Step k's command ``u`` (B, 2), recorded with its errors; the seeds whose step diverged stop. False: none live."""
        q, q_meas, r, e, et = self._q, self._q_meas, self.ref[k], self._e, self._et
        tracking_errors(q, r, et)
        self.pose[:, k], self.pose_meas[:, k], self.e[:, k], self.e_true[:, k], self.u[:, k] = q, q_meas, e, et, u
        z = self._record_ctrl(k)
        for b in self.live:
            self.recs[b].n = k + 1
        zk = (
            self.no_z if z is None else np.ascontiguousarray(z, dtype=float).reshape(len(q), -1)
        )  # a plug-in's: any shape
        if bad_seeds(q, u, et, zk, self.base.divergence_m, self.bad):
            for b in [b for b in self.live if self.bad[b]]:
                why = self.ctrl.why.get(b)  # a controller's own reason for a seed it stopped
                zb = None if z is None else z[b]
                self.stop(b, why or _diverged(q[b], u[b], et[b], zb, self.base.divergence_m), k, k)
        self._u = u
        return bool(self.live)

    def _record_ctrl(self, k: int):
        """Row k of the controller's telemetry (max |z| unless ``full``); returns its weights z or None."""
        tele = self.ctrl.telemetry()
        if not self.ctrl_store:
            _allocate(self.ctrl_store, tele, self.recs, "ctrl", self.B, self.N, self.full)
        for key, val in tele.items():
            if key == "z" and not self.full:
                self.ctrl_store[key][:, k, 0] = np.max(np.abs(val), axis=-1)
            else:
                self.ctrl_store[key][:, k] = val
        return tele.get("z")

    def actuate(self, k: int) -> bool:
        """The plant stepped with step k's command, its telemetry recorded; the seeds whose plant
        left its valid range stop. False: none live."""
        self.plant.step(self._u)
        if self.listed:
            self.plant.put_telemetry(self.plant_store, self.recs, k)
        else:
            tele = self.plant.telemetry()
            if not self.plant_store:
                _allocate(self.plant_store, tele, self.recs, "plant", self.B, self.N, True)
            for key, val in tele.items():
                self.plant_store[key][:, k] = val
        reasons = self.plant.diverged()
        if isinstance(reasons, str) or reasons is None:
            reasons = [reasons]
        for b in [b for b in self.live if reasons[b] is not None]:
            self.stop(b, reasons[b], k, k + 1)
        return bool(self.live)

    # -- the end of a seed, and of the run

    def _reference_ended(self, k: int) -> bool:
        """Whether step k is where the reference stopped being finite: every live seed ends there."""
        if self.end is None or k != self.end[0]:
            return False
        for b in list(self.live):
            self.stop(b, self.end[1], k, k)
        return True

    def stop(self, b: int, reason: str, k: int, plant_rows: int) -> None:
        """Seed b diverged at step k: its record ends here, its plant is no longer stepped, and the
        rows after its end (which the batch went on computing) are cleared in :meth:`finish`."""
        rec = self.recs[b]
        rec.status, rec.reason = "diverged", f"{reason} at t = {k * self.T:.2f} s"
        self.live.remove(b)
        if self.listed:
            self.plant.drop(b)
        self.ctrl.drop(b)  # a batched controller stops stepping the seed
        self.stopped[b] = (rec.n, plant_rows)

    def interrupted(self, how: str) -> None:
        for b in self.live:
            self.recs[b].status, self.recs[b].reason = "interrupted", f"{how} at t = {self.recs[b].n * self.T:.2f} s"

    def finish(self, wall: float) -> None:
        """Each record cut at its end (NaN after it), its wall and simulated time."""
        for b, rec in enumerate(self.recs):
            _clear_after(rec, self.stopped.get(b), self.plant_store)
            rec.wall_time_s = wall
            rec.sim_time_s = (self.plant.plants[b] if self.listed else self.plant).elapsed(rec.n)


def _compiled(plant: PlantList, ctrl: Stepped) -> bool:
    """Whether the closed loop can run compiled: every plant has a compiled step, the controller's
    step is a kernel."""
    if ctrl.level != "velocity" or not all(isinstance(p, CompiledPlant) for p in plant.plants):
        return False  # the segment's plant step takes (v, omega)
    if isinstance(ctrl, LawKernel):
        return ctrl.law_kernel(0) is not None
    return isinstance(ctrl, StateKernel) and ctrl.kernel_state(0) is not None


def _apply_due(pending: list, k: int, T: float, plant, recs: list[RunRecord], live: list[int]) -> None:
    """Apply the events due at step k (time <= k T), each recorded in the live seeds' records."""
    t = k * T
    while pending and pending[0].time <= t + 1e-9:
        ev = pending.pop(0)
        text = plant.apply(ev)
        for b in live:
            recs[b].events.append({"time": t, "kind": ev.kind, "params": dict(ev.params), "text": text})


def _allocate(store: dict, tele: dict, recs: list[RunRecord], which: str, B: int, N: int, full: bool) -> np.ndarray:
    """Per-seed telemetry arrays (B, N, ...), each record's rows a view of its seed's; all of them
    columns of one (B, N, W) array, which is returned (what a compiled step writes a row of)."""
    shapes = {key: (1,) if key == "z" and not full else np.shape(val)[1:] for key, val in tele.items()}
    widths = [int(np.prod(shape)) for shape in shapes.values()]
    packed = np.full((B, N, sum(widths)), np.nan)
    lo = 0
    for (key, shape), w in zip(shapes.items(), widths, strict=True):
        store[key] = packed[:, :, lo : lo + w].reshape(B, N, *shape)
        assert np.shares_memory(store[key], packed)
        lo += w
        for b, rec in enumerate(recs):
            getattr(rec, which)[key] = store[key][b]
    return packed


def _clear_after(rec: RunRecord, stop: tuple[int, int] | None, plant_store: dict) -> None:
    if stop is None:
        n, plant_rows = rec.n, rec.n
    else:
        n, plant_rows = stop
    for name in ("pose", "pose_meas", "e", "e_true", "u"):
        getattr(rec, name)[n:] = np.nan
    for val in rec.ctrl.values():
        val[n:] = np.nan
    for val in rec.plant.values():
        val[plant_rows:] = np.nan


def _diverged(q: np.ndarray, u: np.ndarray, e_true: np.ndarray, z: np.ndarray | None, limit_m: float) -> str | None:
    """Why one seed's step diverged (the reasons of :func:`mlpfac.loop.kernels.bad_seeds`), or None."""
    err = hypot(e_true[0], e_true[1])
    if not (np.isfinite(q).all() and np.isfinite(u).all()):
        return "non-finite pose or command"
    if z is not None and not np.isfinite(z).all():
        return "non-finite network weights"
    if not err <= limit_m:
        return f"position error {err:.3g} m beyond {limit_m:g} m"
    return None
