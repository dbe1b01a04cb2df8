"""A run's figures (metrics.json): whole-run and per-phase position and heading RMS, the outcome
(tracking, lost, diverged), weights, P, timing, the position error's mean square in bins."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from mlpfac.loop.record import RunRecord

LOST_FRACTION = 0.05  # a finished run is "lost" when a phase's position RMS exceeds this share of the path's size
BIN_S = 0.1  # seconds per bin of the position error's mean square in metrics.json (any window of whole bins)


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
    """The run's figures: whole-run and per-phase position/heading RMS, weights, P, timing, status.
    A figure that is not finite (a run that blew up) is None: metrics.json is JSON, and the
    overflow on the way is no warning."""
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite(_metrics(rec))


def _finite(x):
    """``x`` with every float that is not finite (inf, nan) replaced by None, in dicts and lists."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _metrics(rec: RunRecord) -> dict:
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
    out["ctrl_final"] = final_telemetry(rec)
    out["events"] = [{k: ev[k] for k in ("time", "kind", "params", "text")} for ev in rec.events]
    out["sim_time_s"] = rec.sim_time_s
    out["wall_time_s"] = rec.wall_time_s
    out |= outcome(rec, phases)
    w = max(1, int(round(BIN_S / rec.T)))
    pos2 = np.sum(rec.e_true[:n, :2] ** 2, axis=1)
    out["position_ms_bins"] = {
        "bin_steps": w,
        "m2": [float(np.mean(pos2[i : i + w])) for i in range(0, n, w)],
    }
    return out


def final_telemetry(rec: RunRecord, most: int = 8) -> dict:
    """The controller's telemetry at its last recorded step, for keys of at most ``most`` values
    (a float, or a list; a non-finite value is None); the weights ``z`` are max_abs_weight's."""
    out: dict = {}
    for key, arr in rec.ctrl.items():
        row = np.asarray(arr[rec.n - 1], dtype=float) if rec.n else np.zeros(most + 1)
        if key == "z" or row.size > most:
            continue
        vals = [float(x) if np.isfinite(x) else None for x in row.ravel()]
        out[key] = vals[0] if row.ndim == 0 else vals
    return out


def outcome(rec: RunRecord, phases: dict) -> dict:
    """Whether the run tracked: "diverged" (stopped: non-finite, beyond ``divergence_m``, flipped),
    "lost" (finished, but some phase's position RMS exceeds LOST_FRACTION of the path's size, the
    larger side of the reference's bounding box: 0.2 m on the 4 m figure of eight), else "tracking";
    "interrupted" when it did not end."""
    xy = rec.ref[:, :2]
    size = float(np.max(np.max(xy, axis=0) - np.min(xy, axis=0)))
    limit = LOST_FRACTION * size
    if rec.status != "ok":
        how = rec.status
    else:
        rms = [p["rms_position_error_m"] for p in phases.values() if p["rms_position_error_m"] is not None]
        how = "lost" if any(x > limit for x in rms) else "tracking"
    return {"outcome": how, "path_size_m": size, "lost_threshold_m": limit}


def holds_finished_run(out: Path) -> bool:
    """A folder whose metrics.json says the run ended (ok or diverged), or a file that exists."""
    if not out.is_dir():
        return out.exists()
    try:
        return json.loads((out / "metrics.json").read_text()).get("status") != "interrupted"
    except (OSError, ValueError, AttributeError):
        return False
