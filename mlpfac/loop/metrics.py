"""A run's figures (metrics.json): whole-run and per-phase position and heading RMS, the outcome
(tracking, lost, diverged), weights, P, timing, the position error's mean square in bins; and
:class:`RunMetrics`, the one way a metrics.json is read back (by the sweep's tables, the paired
comparisons, the budgets, the plots, the viewer and the datasets' checks)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mlpfac.loop.record import RunRecord

LOST_FRACTION = 0.05  # a finished run is "lost" when a phase's position RMS exceeds this share of the path's size
# (the scenario's lost_threshold_m, or --lost-threshold, sets the threshold in metres instead)
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
    from mlpfac.elementary import each, hypot  # here: importing the kernels' module checks MLPFAC_KERNELS

    pos = each(hypot, e[:, 0], e[:, 1])  # ours, not numpy's SIMD loop nor math's (docs/reproducibility.md)
    return {
        "start_s": lo * rec.T,
        "end_s": hi * rec.T,
        "rms_position_error_m": float(np.sqrt(np.mean(pos * pos))),
        "max_position_error_m": float(np.max(pos)),
        "rms_heading_error_rad": float(np.sqrt(np.mean(e[:, 2] * e[:, 2]))),
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
    if rec.pose_source != "truth":  # what the robot believed, beside the truth (mlpfac.loop.belief)
        from mlpfac.loop.belief import believed

        out["estimate"] = believed(rec, phase_bounds(rec), out["lost_threshold_m"], out["outcome"])
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
    "lost" (finished, but some phase's position RMS exceeds the threshold), else "tracking";
    "interrupted" when it did not end. The threshold is the scenario's ``lost_threshold_m`` where it
    sets one, else LOST_FRACTION of the path's size, the larger side of the reference's bounding box
    over the run (0.2 m on the 4 m figure of eight). A run that ends within its warm-up has no phase
    to judge: it is judged on what it has, the whole run, the warm-up included, so that a robot
    left behind is never "tracking" for want of a phase (:func:`judged_whole`)."""
    xy = rec.ref[:, :2]  # the reference over the whole run (a run stopped early too)
    finite = xy[np.all(np.isfinite(xy), axis=1)]
    size = float(np.max(np.max(finite, axis=0) - np.min(finite, axis=0))) if len(finite) else 0.0
    limit = rec.lost_threshold_m if rec.lost_threshold_m is not None else LOST_FRACTION * size
    rms = [p["rms_position_error_m"] for p in phases.values() if p["rms_position_error_m"] is not None]
    if not rms:  # within the warm-up: judged on what it has
        whole = _stats(rec, 0, rec.n)["rms_position_error_m"]
        rms = [] if whole is None else [whole]
    how = rec.status if rec.status != "ok" else "lost" if any(not x <= limit for x in rms) else "tracking"
    return {"outcome": how, "path_size_m": size, "lost_threshold_m": limit}


def judged_whole(m: dict) -> bool:
    """Whether a metrics.json's outcome was judged over the whole run, the warm-up included: no
    phase has a step (the run ends within its warm-up)."""
    return not any(p.get("rms_position_error_m") is not None for p in (m.get("phases") or {}).values())


def threshold_words(m: dict) -> str:
    """Where a metrics.json's lost threshold came from: the scenario's ``lost_threshold_m``, or
    LOST_FRACTION of the path's size."""
    size, limit = m.get("path_size_m"), m.get("lost_threshold_m")
    if size is not None and limit == LOST_FRACTION * size:
        return f"{LOST_FRACTION:.0%} of the path's {size:.3g} m size".replace("%", " %")
    return "lost_threshold_m"


def outcome_words(m: dict) -> str:
    """A metrics.json's outcome in a sentence, its threshold explained: what a run's first line, the
    title of its Figure 1 and the viewer's text say. "tracking" and "lost" name the figure that
    decided it; "diverged" and "interrupted" say why."""
    how = m.get("outcome") or m.get("status")
    if how not in ("tracking", "lost"):
        return f"{how}" + (f" ({m['reason']})" if m.get("reason") else "")
    limit = f"{m['lost_threshold_m']:.3g} m ({threshold_words(m)})"
    if judged_whole(m):
        rms = m.get("rms_position_error_m")
        where = f"the whole run's position RMS {_mm(rms)}"
        side = "beyond" if how == "lost" else "within"
        why = "; the run ends within its warm-up, so the warm-up is judged too"
        return f"{how}: {where} is {side} {limit}{why}"
    phases = {k: p["rms_position_error_m"] for k, p in m["phases"].items() if p["rms_position_error_m"] is not None}
    if how == "lost":
        name, rms = max(phases.items(), key=lambda kv: kv[1])
        when = f"{name} the event" if "after" in m["phases"] else f"after the {m['excluded_s'][1]:g} s warm-up"
        return f"{how}: the position RMS {when} ({_mm(rms)}) is beyond {limit}"
    return f"{how}: every phase's position RMS (at most {_mm(max(phases.values()))}) is within {limit}"


def _mm(x: float | None) -> str:
    return "-" if x is None else f"{x * 1e3:.3g} mm" if x < 1.0 else f"{x:.3g} m"


OUTCOMES = ("tracking", "lost", "diverged")


@dataclass(frozen=True)
class Phase:
    """One phase of a run as metrics.json holds it (a figure is None when the phase has no step)."""

    start_s: float
    end_s: float
    rms_position_error_m: float | None
    max_position_error_m: float | None = None
    rms_heading_error_rad: float | None = None


@dataclass(frozen=True)
class RunMetrics:
    """A run's metrics.json, read: what its readers use, typed, with ``data`` the file as read
    (every key, for its digest). Files written by earlier versions read too: a missing outcome is
    taken from ``tracking_status`` or, failing that, from ``status`` (finished = tracking)."""

    status: str
    scenario: str
    controller: str
    seed: int
    T: float
    steps: int
    phases: dict[str, Phase]
    outcome: str
    reason: str = ""
    lost_threshold_m: float | None = None
    max_abs_weight: float | None = None
    wall_time_s: float = 0.0
    excluded_s: tuple[float, float] = (0.0, 0.0)  # the warm-up left out of the phases
    events: tuple[dict, ...] = ()
    bins: tuple[int, tuple[float | None, ...]] | None = None  # position_ms_bins: (steps a bin, mean squares)
    estimate: dict | None = None  # what the robot believed (mlpfac.loop.belief); None: its pose was the truth
    data: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def from_json(cls, m: dict) -> RunMetrics:
        """``m``, a parsed metrics.json; KeyError, TypeError or ValueError when it is not one."""
        if not isinstance(m, dict):
            raise TypeError(f"a metrics.json holds an object, not {type(m).__name__}")
        bins = m.get("position_ms_bins")
        how = next((m[k] for k in ("outcome", "tracking_status", "status") if m.get(k) in OUTCOMES), None)
        return cls(
            status=m["status"],
            scenario=m["scenario"],
            controller=m["controller"],
            seed=int(m["seed"]),
            T=float(m["T"]),
            steps=int(m["steps"]),
            phases={name: Phase(**ph) for name, ph in m["phases"].items()},
            outcome=how or ("tracking" if m["status"] == "ok" else "diverged"),
            reason=m.get("reason") or "",
            lost_threshold_m=m.get("lost_threshold_m"),
            max_abs_weight=m.get("max_abs_weight"),
            wall_time_s=float(m.get("wall_time_s") or 0.0),
            excluded_s=tuple(m.get("excluded_s") or (0.0, 0.0)),
            events=tuple(m.get("events") or ()),
            bins=(int(bins["bin_steps"]), tuple(bins["m2"])) if isinstance(bins, dict) else None,
            estimate=m.get("estimate") if isinstance(m.get("estimate"), dict) else None,
            data=m,
        )

    @classmethod
    def read(cls, path: Path) -> RunMetrics:
        """The metrics.json at ``path``; OSError, or ValueError (KeyError, TypeError) when it is not one."""
        return cls.from_json(json.loads(Path(path).read_text()))

    @property
    def finished(self) -> bool:
        """The run ended by itself: ok (tracking or lost) or diverged, not interrupted."""
        return self.status in ("ok", "diverged")

    @property
    def last_phase(self) -> str:
        """ "after" when the run has steps after its first event, else "before"."""
        after = self.phases.get("after")
        return "after" if after is not None and after.end_s > after.start_s else "before"

    def figures(self, phase: str) -> tuple[float, float, float] | None:
        """(position RMS, largest position error, heading RMS) in ``phase``; "whole" is the run after
        the warm-up, the phases joined (RMS weighted by their lengths); None when the phase has no step."""
        names = ("before", "after") if phase == "whole" else (phase,)
        parts = [self.phases[k] for k in names if k in self.phases and self.phases[k].rms_position_error_m is not None]
        if not parts:
            return None
        if len(parts) == 1:
            p = parts[0]
            return p.rms_position_error_m, p.max_position_error_m, p.rms_heading_error_rad
        w = [max(p.end_s - p.start_s, 0.0) for p in parts]

        def rms(key: str) -> float:
            return math.sqrt(
                math.fsum(wi * getattr(p, key) * getattr(p, key) for wi, p in zip(w, parts, strict=True)) / math.fsum(w)
            )

        return rms("rms_position_error_m"), max(p.max_position_error_m for p in parts), rms("rms_heading_error_rad")

    def rms(self, phase: str | None = None) -> float | None:
        """The compared figure: the position RMS in ``phase`` (None: :attr:`last_phase`); inf for a
        run that diverged; None when the phase has no step."""
        if self.status != "ok":
            return math.inf
        f = self.figures(phase or self.last_phase)
        return None if f is None else f[0]

    def window_rms(self, start_s: float, end_s: float) -> float | None:
        """Position RMS over [start_s, end_s) from the run's bins (None: no bins, or no whole bin)."""
        if self.bins is None or self.status != "ok":
            return None
        w, ms = self.bins
        lo, hi = round(start_s / self.T), min(round(end_s / self.T), self.steps)
        total = count = 0.0
        for i, x in enumerate(ms):
            a, b = i * w, min((i + 1) * w, self.steps)
            if a >= lo and a < hi:
                total += x * (b - a)
                count += b - a
        return math.sqrt(total / count) if count else None

    def rms_bins(self) -> tuple[float, np.ndarray] | None:
        """(bin width [s], position RMS per bin [m]); None for a run that has no bins."""
        if self.bins is None:
            return None
        m2 = np.array([np.nan if x is None else x for x in self.bins[1]], dtype=float)
        return self.bins[0] * self.T, np.sqrt(m2)
