"""The closed loop: reference -> error (2) -> controller -> plant, one run -> a RunRecord; metrics."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mlpfac.error_model import tracking_error
from mlpfac.outputs import Terminated
from mlpfac.record import RunRecord
from mlpfac.reference import sample
from mlpfac.scenario import Scenario

FLUSH_EVERY = 250  # steps between sends to a log sink


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


def build(scn: Scenario) -> Built:
    """Sample the reference, build the plant and the controller: what can fail (a bad model, a
    missing actuator) fails here, before a run writes or sends anything."""
    ref = sample(scn.reference, np.arange(scn.steps + 1) * scn.T)  # (N + 1, 5)
    return Built(ref, scn.make_plant(ref), scn.make_controller())


def run(
    scn: Scenario, sink=None, on_step: Callable[[int], None] | None = None, built: Built | None = None
) -> RunRecord:
    """Run ``scn`` once. Returns the record; status "diverged" or "interrupted" keeps what was recorded.

    ``sink`` (see :mod:`mlpfac.log`) receives the record every ``FLUSH_EVERY`` steps and at the end,
    also after a divergence, a Ctrl-C or a SIGTERM (the reason says "interrupted" or "terminated").
    ``built``: from :func:`build`, used once (the plant and the controller keep state).
    """
    N, T = scn.steps, scn.T
    built = built or build(scn)
    ref, plant, ctrl = built.ref, built.plant, built.ctrl
    c_rng, p_rng = seeded_generators(scn.seed)
    ctrl.reset(T, c_rng)
    q0, u0 = scn.initial_state(ref)
    plant.reset(q0, p_rng, u0)

    rec = RunRecord.allocate(scn.name, ctrl.name, scn.seed, T, N)
    rec.warmup_s = scn.warmup
    rec.split_s = scn.events[0].time if scn.events else None
    rec.labels = dict(ctrl.labels)
    rec.ref[:] = ref[:N]
    pending = list(scn.events)
    wall0 = time.perf_counter()
    if sink is not None:
        sink.begin(rec, geometry=plant.geometry(), ref_path=ref[:N])
    try:
        for k in range(N):
            t = k * T
            while pending and pending[0].time <= t + 1e-9:
                ev = pending.pop(0)
                rec.events.append({"time": t, "kind": ev.kind, "params": dict(ev.params), "text": plant.apply(ev)})
            q = plant.true_pose()
            q_meas = plant.measure()
            r = ref[k]
            e = tracking_error(q_meas, r)
            u = ctrl.step(e, r)
            rec.pose[k], rec.pose_meas[k], rec.e[k] = q, q_meas, e
            rec.e_true[k] = tracking_error(q, r)
            rec.u[k] = u
            rec.put(rec.ctrl, k, ctrl.telemetry())
            rec.n = k + 1
            reason = _diverged(rec, k, scn.divergence_m)
            if reason is None:
                plant.step(u)
                rec.put(rec.plant, k, plant.telemetry())
                reason = plant.diverged()
            if reason is not None:
                rec.status, rec.reason = "diverged", f"{reason} at t = {t:.2f} s"
                break
            if on_step is not None:
                on_step(k)
            if sink is not None and (k + 1) % FLUSH_EVERY == 0:
                sink.flush(rec, k + 1)
    except KeyboardInterrupt as err:
        how = "terminated by SIGTERM" if isinstance(err, Terminated) else "interrupted"
        rec.status, rec.reason = "interrupted", f"{how} at t = {rec.n * T:.2f} s"
    finally:
        rec.wall_time_s = time.perf_counter() - wall0
        rec.sim_time_s = float(getattr(plant, "sim_time", rec.n * T))
        if sink is not None:
            sink.end(rec)
    return rec


def _diverged(rec: RunRecord, k: int, limit_m: float) -> str | None:
    pose, u, e = rec.pose[k], rec.u[k], rec.e_true[k]
    z = rec.ctrl.get("z")
    err = float(np.hypot(e[0], e[1]))  # np.hypot, as the batched path's test
    # the common case in a few float operations: every test below fails on a NaN or an infinity
    fine = err <= limit_m and math.isfinite(pose[0] + pose[1] + pose[2] + u[0] + u[1])
    if fine and (z is None or math.isfinite(np.dot(z[k], z[k]))):
        return None
    if not (np.isfinite(pose).all() and np.isfinite(u).all()):
        return "non-finite pose or command"
    if z is not None and not np.isfinite(z[k]).all():
        return "non-finite network weights"
    if err > limit_m:
        return f"position error {err:.3g} m beyond {limit_m:g} m"
    return None


def _stats(rec: RunRecord, lo: int, hi: int) -> dict:
    e = rec.e_true[lo:hi]
    if len(e) == 0:
        return {
            "start_s": lo * rec.T,
            "end_s": hi * rec.T,
            "rms_position_error_m": None,
            "max_position_error_m": None,
            "rms_heading_error_rad": None,
        }
    pos = np.hypot(e[:, 0], e[:, 1])
    return {
        "start_s": lo * rec.T,
        "end_s": hi * rec.T,
        "rms_position_error_m": float(np.sqrt(np.mean(pos**2))),
        "max_position_error_m": float(np.max(pos)),
        "rms_heading_error_rad": float(np.sqrt(np.mean(e[:, 2] ** 2))),
    }


def phase_bounds(rec: RunRecord) -> dict[str, tuple[int, int]]:
    """Step ranges of the phases: "before" the first event (after the warm-up) and "after" it.

    A scenario without events has only "before": the whole run after the warm-up.
    """
    N = len(rec.t)
    w = min(int(round(rec.warmup_s / rec.T)), N)
    if rec.split_s is None:
        return {"before": (w, N)}
    split = min(max(int(round(rec.split_s / rec.T)), w), N)
    return {"before": (w, split), "after": (split, N)}


def metrics(rec: RunRecord) -> dict:
    """The run's figures: whole-run and per-phase position/heading RMS, weights, P, timing, status."""
    n = rec.n
    out = {
        "status": rec.status,
        "reason": rec.reason,
        "scenario": rec.scenario,
        "controller": rec.controller,
        "seed": rec.seed,
        "T": rec.T,
        "steps": n,
    }
    whole = _stats(rec, 0, n)
    out.update({k: whole[k] for k in ("rms_position_error_m", "max_position_error_m", "rms_heading_error_rad")})
    phases = {}
    for name, (lo, hi) in phase_bounds(rec).items():
        phases[name] = _stats(rec, lo, min(hi, n)) | {"start_s": lo * rec.T, "end_s": hi * rec.T}
    out["phases"] = phases
    out["excluded_s"] = [0.0, min(rec.warmup_s, len(rec.t) * rec.T)]
    z = rec.ctrl.get("z")
    out["max_abs_weight"] = float(np.max(np.abs(z[:n]))) if z is not None and n else None
    P = rec.ctrl.get("mean_diag_P")
    out["mean_diag_P_final"] = float(P[n - 1]) if P is not None and n else None
    out["events"] = [{k: ev[k] for k in ("time", "kind", "params", "text")} for ev in rec.events]
    out["sim_time_s"] = rec.sim_time_s
    out["wall_time_s"] = rec.wall_time_s
    return out
