"""The closed loop: reference -> error (2) -> controller -> plant, one run or a batch of seeds -> RunRecords."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mlpfac.interrupts import Terminated, raise_swallowed
from mlpfac.loop.compiled import BAD, segment
from mlpfac.loop.factory import make_controller, make_plant
from mlpfac.loop.kernels import bad_seeds
from mlpfac.loop.record import RunRecord
from mlpfac.model import tracking_errors
from mlpfac.scenario.parse import Scenario
from mlpfac.scenario.reference import sample

FLUSH_EVERY = 250  # steps between sends to a log sink
SEGMENT_PHYSICS = 5_000  # physics steps of one compiled segment, at most: a signal waits for no more


def seeded_generators(seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    """Independent streams for the controller's initial weights and the plant's noise."""
    c, p = np.random.SeedSequence(seed).spawn(2)
    return np.random.default_rng(c), np.random.default_rng(p)


@dataclass
class Built:
    """What a run needs before its first step: the reference, the plant and the controller."""

    ref: np.ndarray
    plant: object
    ctrl: object


def build(scn: Scenario, instance: object | None = None) -> Built:
    """Sample the reference, build the plant and the controller: what can fail (a bad model, a
    missing actuator) fails here, before a run writes or sends anything. ``instance``: an object of
    the scenario's plug-in controller to run (:func:`mlpfac.loop.factory.make_controller`)."""
    ref = sample(scn.reference, np.arange(scn.steps + 1) * scn.T)  # (N + 1, 5)
    return Built(ref, make_plant(scn, ref), make_controller(scn, instance))


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
        self._q, self._m = np.zeros((len(self.plants), 3)), np.zeros((len(self.plants), 3))
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

    def sim_time(self, i: int, n: int, T: float) -> float:
        return float(getattr(self.plants[i], "sim_time", n * T))

    def drop(self, i: int) -> None:
        self.live.remove(i)


def run(
    scn: Scenario, sink=None, on_step: Callable[[int], None] | None = None, built: Built | None = None
) -> RunRecord:
    """Run ``scn`` once. Returns the record; status "diverged" or "interrupted" keeps what was recorded.

    ``sink`` (see :mod:`mlpfac.log`) receives the record every ``FLUSH_EVERY`` steps and at the end,
    also after a divergence, a Ctrl-C or a SIGTERM (the reason says "interrupted" or "terminated").
    ``built``: from :func:`build`, used once (the plant and the controller keep state).
    ``on_step(k)`` is called after every step k; the loop then goes step by step in Python. Without
    it, a MuJoCo plant with Kanayama's or Corradini's law runs compiled from one event or flush to
    the next (:mod:`mlpfac.loop.compiled`), to the same bits.
    A run is the closed loop of :func:`run_batch` with one seed (B = 1).
    """
    built = built or build(scn)
    return _loop([scn], built.ref, built.plant, built.ctrl, sink, on_step, full=True)[0]


def same_but_seed(scns: list[Scenario]) -> bool:
    t0 = {k: v for k, v in scns[0].table.items() if k != "seed"}
    return all({k: v for k, v in s.table.items() if k != "seed"} == t0 for s in scns[1:])


def run_batch(scns: list[Scenario], plant_list: bool = False) -> list[RunRecord]:
    """Run seeds of one scenario together, one record per scenario, each equal to ``run(scn)``.

    ``scns`` must differ in their seed only (ValueError otherwise). Every controller and variant
    runs batched: the compiled controllers step all seeds in one kernel call per step, the numpy
    parts (UKF, cautious law, learned gains) seed by seed; the kinematic plant is batched, any
    other plant (MuJoCo) is one object per seed (``plant_list`` forces that for the kinematic one
    too). Each seed's arithmetic does not depend on the others, so its record is its B = 1 run's
    to the last bit (tests/test_batch.py). A seed that diverges stops recording there; the others
    go on. Weights are recorded as max |z| per step (what :func:`metrics` reads), not all alpha
    of them. ``wall_time_s`` is the batch's wall time / B. KeyboardInterrupt propagates: an
    interrupted batch has no whole run.
    """
    if not scns:
        return []
    if not same_but_seed(scns):
        raise ValueError("run_batch needs scenarios that differ in their seed only")
    base = scns[0]
    ref = sample(base.reference, np.arange(base.steps + 1) * base.T)  # (N + 1, 5)
    plant = make_plant(base, ref)
    if plant_list or not getattr(plant, "batched", False):
        plant = [plant] + [make_plant(s, ref) for s in scns[1:]]
    recs = _loop(scns, ref, plant, make_controller(base), None, None, full=False)
    if any(r.status == "interrupted" for r in recs):
        raise KeyboardInterrupt
    return recs


def _loop(scns, ref, plant, ctrl, sink, on_step, full: bool) -> list[RunRecord]:
    """The closed loop for B = len(scns) seeds of one scenario. ``full``: record every weight (else
    max |z| per step). A list of plants, or a plant without a batch form, steps one per seed."""
    base = scns[0]
    B, N, T = len(scns), base.steps, base.T
    if isinstance(plant, list) or not getattr(plant, "batched", False):
        plant = PlantList(plant if isinstance(plant, list) else [plant])
    gens = [seeded_generators(s.seed) for s in scns]
    ctrl.reset([c for c, _ in gens])
    q0, u0 = base.initial_state(ref)
    plant.reset(q0, [p for _, p in gens], u0)
    listed = isinstance(plant, PlantList)

    nan = np.full
    pose, pose_meas, e_all, e_true, u_all = (nan((B, N, d), np.nan) for d in (3, 3, 3, 3, 2))
    recs = []
    for b, s in enumerate(scns):
        rec = RunRecord(s.name, ctrl.name, s.seed, T, np.arange(N) * T, np.array(ref[:N]), pose[b], pose_meas[b],
                        e_all[b], e_true[b], u_all[b])  # fmt: skip
        rec.warmup_s, rec.split_s = s.warmup, s.events[0].time if s.events else None
        rec.labels = dict(ctrl.labels)
        recs.append(rec)
    rec0 = recs[0]
    ctrl_store: dict[str, np.ndarray] = {}
    plant_store: dict[str, np.ndarray] = {}
    e, et = np.zeros((B, 3)), np.zeros((B, 3))
    bad = np.zeros(B, dtype=np.bool_)
    no_z = np.zeros((B, 0))
    live = list(range(B))
    pending = list(base.events)
    stopped: dict[int, int] = {}  # seed -> the step its record ends at
    tracking_errors(e[:0], ref[0], e[:0])  # load (or compile) the loop's kernels before it starts
    bad_seeds(e[:0], np.zeros((0, 2)), e[:0], no_z[:0], 1.0, bad[:0])
    compiled = listed and on_step is None and _compiled(plant, ctrl)
    if compiled:  # the closed loop compiled between events (mlpfac.loop.compiled)
        ctele = _allocate(ctrl_store, ctrl.telemetry(), recs, "ctrl", B, N, full)
        ptele = _allocate(
            plant_store, {k: v[None] for k, v in plant.plants[0].telemetry().items()}, recs, "plant", B, N, True
        )
        law = ctrl.law_kernel()
        segment(0, 0, ref, *law, 1.0, pose[0], pose[0], pose[0], pose[0], u_all[0], ctele[0], ptele[0],
                np.zeros((0, 3)), plant.plants[0].kernel_args())  # fmt: skip
    wall0 = time.perf_counter()
    if sink is not None:
        sink.begin(rec0, geometry=plant.plants[0].geometry() if listed else plant.geometry(), ref_path=ref[:N])
    k = 0
    try:
        if compiled:
            while k < N and live:
                raise_swallowed()
                _apply_due(pending, k, T, plant, recs, live)
                k1 = min(N, (k // FLUSH_EVERY + 1) * FLUSH_EVERY)
                k1 = min(k1, k + max(1, SEGMENT_PHYSICS // max(p._n for p in plant.plants)))  # signals seen
                if pending:  # up to the next event
                    k1 = next((j for j in range(k + 1, k1) if pending[0].time <= j * T + 1e-9), k1)
                for b in list(live):
                    p = plant.plants[b]
                    end, why = segment(k, k1, ref, *law, base.divergence_m, pose[b], pose_meas[b], e_all[b], e_true[b],
                                       u_all[b], ctele[b], ptele[b], p.draws(k1 - k), p.kernel_args())  # fmt: skip
                    recs[b].n = min(end + 1, k1)
                    if why == BAD:
                        reason = _diverged(pose[b, end], u_all[b, end], e_true[b, end], None, base.divergence_m)
                        _stop(recs, b, reason, end * T, live, plant, ctrl, listed, stopped, end)
                    elif why:
                        _stop(recs, b, p.why(why), end * T, live, plant, ctrl, listed, stopped, end + 1)
                k = k1
                if live and sink is not None and k % FLUSH_EVERY == 0:
                    sink.flush(rec0, k)
        else:
            for k in range(N):
                raise_swallowed()
                _apply_due(pending, k, T, plant, recs, live)
                q, q_meas, r = plant.true_pose(), plant.measure(), ref[k]
                tracking_errors(q_meas, r, e)
                u = ctrl.step(e, r)
                tracking_errors(q, r, et)
                pose[:, k], pose_meas[:, k], e_all[:, k], e_true[:, k], u_all[:, k] = q, q_meas, e, et, u
                tele = ctrl.telemetry()
                if not ctrl_store:
                    _allocate(ctrl_store, tele, recs, "ctrl", B, N, full)
                z = tele.get("z")
                for key, val in tele.items():
                    if key == "z" and not full:
                        ctrl_store[key][:, k, 0] = np.max(np.abs(val), axis=-1)
                    else:
                        ctrl_store[key][:, k] = val
                for b in live:
                    recs[b].n = k + 1
                zk = (
                    no_z if z is None else np.ascontiguousarray(z, dtype=float).reshape(len(q), -1)
                )  # a plug-in's: any shape
                if bad_seeds(q, u, et, zk, base.divergence_m, bad):
                    for b in [b for b in live if bad[b]]:
                        why = getattr(ctrl, "why", {}).get(b) or _diverged(
                            q[b], u[b], et[b], None if z is None else z[b], base.divergence_m
                        )
                        _stop(recs, b, why, k * T, live, plant, ctrl, listed, stopped, k)
                    if not live:
                        break
                plant.step(u)
                if listed:
                    plant.put_telemetry(plant_store, recs, k)
                else:
                    ptele = plant.telemetry()
                    if not plant_store:
                        _allocate(plant_store, ptele, recs, "plant", B, N, True)
                    for key, val in ptele.items():
                        plant_store[key][:, k] = val
                reasons = plant.diverged()
                if isinstance(reasons, str) or reasons is None:
                    reasons = [reasons]
                if any(x is not None for x in reasons):
                    for b in [b for b in live if reasons[b] is not None]:
                        _stop(recs, b, reasons[b], k * T, live, plant, ctrl, listed, stopped, k + 1)
                    if not live:
                        break
                if on_step is not None:
                    on_step(k)
                if sink is not None and (k + 1) % FLUSH_EVERY == 0:
                    sink.flush(rec0, k + 1)
    except KeyboardInterrupt as err:
        how = "terminated by SIGTERM" if isinstance(err, Terminated) else "interrupted"
        for b in live:
            recs[b].status, recs[b].reason = "interrupted", f"{how} at t = {recs[b].n * T:.2f} s"
    finally:
        wall = (time.perf_counter() - wall0) / B
        for b, rec in enumerate(recs):
            _clear_after(rec, stopped.get(b), plant_store)
            rec.wall_time_s = wall
            rec.sim_time_s = plant.sim_time(b, rec.n, T) if listed else rec.n * T
        if sink is not None:
            sink.end(rec0)
    return recs


def _compiled(plant: PlantList, ctrl) -> bool:
    """Whether the closed loop can run compiled: every plant has a compiled step, the law is a kernel."""
    return hasattr(ctrl, "law_kernel") and all(hasattr(p, "kernel_args") for p in plant.plants)


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


def _stop(recs, b, reason, t, live, plant, ctrl, listed, stopped, plant_rows) -> None:
    """Seed b diverged at time t: its record ends here, its plant is no longer stepped, and the rows
    after its end (which the batch went on computing) are cleared in ``_clear_after``."""
    recs[b].status, recs[b].reason = "diverged", f"{reason} at t = {t:.2f} s"
    live.remove(b)
    if listed:
        plant.drop(b)
    drop = getattr(ctrl, "drop", None)
    if drop is not None:
        drop(b)
    stopped[b] = (recs[b].n, plant_rows)


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
    err = float(np.hypot(e_true[0], e_true[1]))
    if not (np.isfinite(q).all() and np.isfinite(u).all()):
        return "non-finite pose or command"
    if z is not None and not np.isfinite(z).all():
        return "non-finite network weights"
    if not err <= limit_m:
        return f"position error {err:.3g} m beyond {limit_m:g} m"
    return None
