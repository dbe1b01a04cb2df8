"""Aggregating the runs' metrics per scenario, controller and phase; the CSV, Markdown and JSON tables."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

from mlpfac.io.files import write_atomic
from mlpfac.loop.metrics import OUTCOMES, RunMetrics
from mlpfac.sweeps.folders import PHASES
from mlpfac.sweeps.paired import TOLD_AT_MOST, UNTOLD_MARK, median, summary
from mlpfac.sweeps.plan import Job


def _ci95(xs: list[float]) -> tuple[float | None, float | None]:
    """95 % confidence interval of the mean (Student t) of RMS figures, its lower end clipped at 0;
    None for fewer than two values. An RMS is never negative, so neither is the mean it estimates:
    the clipped interval holds that mean exactly when the t interval does (the same 95 % coverage),
    where a t interval of few, spread values (2 seeds) reaches below 0."""
    n = len(xs)
    if n < 2:
        return None, None
    from scipy.stats import t

    mean = math.fsum(xs) / n
    sd = math.sqrt(math.fsum((x - mean) * (x - mean) for x in xs) / (n - 1))
    half = float(t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return max(mean - half, 0.0), mean + half


def aggregate(jobs: list[Job], metrics: dict[tuple, RunMetrics]) -> list[dict]:
    """One row per scenario, controller and phase (in plan order) from the runs' metrics."""
    groups: dict[tuple[str, str], list[RunMetrics]] = {}
    runs: dict[tuple[str, str], list[Job]] = {}
    for j in jobs:
        groups.setdefault((j.scenario, j.controller), [])
        runs.setdefault((j.scenario, j.controller), []).append(j)
        if j.key in metrics:
            groups[(j.scenario, j.controller)].append(metrics[j.key])
    rows = []
    for (scn, ctrl), ms in groups.items():
        js = runs[(scn, ctrl)]
        n = len(ms)
        ok = [m for m in ms if m.status == "ok"]
        diverged = sorted((m for m in ms if m.status != "ok"), key=lambda m: (m.steps, m.seed))
        has_after = any(m.last_phase == "after" for m in ms)
        for phase in PHASES if has_after else PHASES[:1]:
            ph = [m.phases[phase] for m in ok]
            pos = [p.rms_position_error_m for p in ph if p.rms_position_error_m is not None]
            head = [p.rms_heading_error_rad for p in ph if p.rms_heading_error_rad is not None]
            mx = [p.max_position_error_m for p in ph if p.max_position_error_m is not None]
            if diverged:
                worst = diverged[0]
            else:
                scored = [(m.phases[phase].rms_position_error_m or -1.0, -m.seed, m) for m in ok]
                worst = max(scored, key=lambda s: s[:2])[2] if scored else None
            row = {"scenario": scn, "controller": ctrl, "phase": phase, "runs": n, "bounded": len(ok)}
            row |= {how: sum(m.outcome == how for m in ms) for how in OUTCOMES}
            row["bounded_share"] = len(ok) / n if n else None
            for name, xs in (("pos_rms_m", pos), ("heading_rms_rad", head)):
                lo, hi = _ci95(xs)
                row |= {
                    f"{name}_mean": math.fsum(xs) / len(xs) if xs else None,
                    f"{name}_median": median(xs),
                    f"{name}_ci_lo": lo,
                    f"{name}_ci_hi": hi,
                }
            row["max_err_m_median"] = median(mx)
            row["max_err_m_max"] = max(mx) if mx else None
            weights = [m.max_abs_weight for m in ms if m.max_abs_weight is not None]
            row["max_abs_weight"] = max(weights) if weights else None  # over every run, diverged ones too
            if any(m.estimate for m in ms):  # a pose that was estimated: its error beside the truth's
                row |= _estimate(ok, phase)
            row["worst_seed"] = worst.seed if worst else None
            row["worst_status"] = worst.status if worst else None
            if js[0].point:  # a grid point of --vary: its values by key
                row["vary"] = dict(js[0].point)
            if js[0].drawn:  # drawn per seed: each run's draw beside its figures, to plot one against the other
                row["draws"] = [_drawn(j, metrics.get(j.key), phase) for j in js]
            rows.append(row)
    return rows


def _estimate(ok: list[RunMetrics], phase: str) -> dict:
    """The estimate's error (belief against truth) in ``phase`` over the runs that finished: the median
    of its position RMS, its largest position error, and how many runs believed they tracked while the
    truth was lost."""
    phases = [m.estimate["phases"].get(phase) or {} for m in ok if m.estimate]
    rms = [p["rms_position_error_m"] for p in phases if p.get("rms_position_error_m") is not None]
    mx = [p["max_position_error_m"] for p in phases if p.get("max_position_error_m") is not None]
    fooled = sum(m.outcome == "lost" and m.estimate.get("believed_outcome") == "tracking" for m in ok if m.estimate)
    return {"est_rms_m_median": median(rms), "est_max_m_max": max(mx) if mx else None, "believed_tracking_lost": fooled}


ESTIMATE_FIELDS = ["est_rms_m_median", "est_max_m_max", "believed_tracking_lost"]
ESTIMATE_COLUMNS: list[tuple[str, Callable[[dict], str]]] = [
    ("estimate's error RMS median [mm]", lambda r: _f(r.get("est_rms_m_median"), 1e3)),
    ("estimate's error max [mm]", lambda r: _f(r.get("est_max_m_max"), 1e3)),
    ("lost, believed tracking", lambda r: str(r.get("believed_tracking_lost", "-"))),
]


def with_estimate(rows: list[dict], columns: list, fields: list) -> tuple[list, list]:
    """The columns and CSV fields, with the estimate's where a row has a pose that was estimated (a
    sweep of the truth alone keeps its tables as they were)."""
    if not any("est_rms_m_median" in r for r in rows):
        return columns, fields
    return columns + ESTIMATE_COLUMNS, fields + ESTIMATE_FIELDS


def _drawn(job: Job, m: RunMetrics | None, phase: str) -> dict:
    """One run of a scenario that draws per seed: its seed, what was drawn, its outcome and position RMS."""
    ph = m.phases.get(phase) if m else None
    return {"seed": job.seed, **job.drawn, "outcome": m.outcome if m else None,
            "pos_rms_m": ph.rms_position_error_m if ph else None}  # fmt: skip


def _f(x: float | None, scale: float = 1.0, digits: int = 2) -> str:
    return "-" if x is None else f"{x * scale:.{digits}f}"


def _ci(lo, hi, scale: float) -> str:
    """An interval of RMS figures (its lower end clipped at 0, as :func:`_ci95` makes it, in data of
    an earlier version too)."""
    return "-" if lo is None else f"[{max(lo, 0.0) * scale:.2f}, {hi * scale:.2f}]"


SWEEP_COLUMNS: list[tuple[str, Callable[[dict], str]]] = [
    ("scenario", lambda r: r["scenario"]),
    ("controller", lambda r: r["controller"]),
    ("phase", lambda r: r["phase"]),
    ("tracking / lost / diverged", lambda r: f"{r['tracking']} / {r['lost']} / {r['diverged']}"),
    ("pos RMS mean [mm]", lambda r: _f(r["pos_rms_m_mean"], 1e3)),
    ("pos RMS median [mm]", lambda r: _f(r["pos_rms_m_median"], 1e3)),
    ("pos RMS 95% CI [mm]", lambda r: _ci(r["pos_rms_m_ci_lo"], r["pos_rms_m_ci_hi"], 1e3)),
    ("heading RMS mean [mrad]", lambda r: _f(r["heading_rms_rad_mean"], 1e3)),
    ("heading RMS median [mrad]", lambda r: _f(r["heading_rms_rad_median"], 1e3)),
    ("heading RMS 95% CI [mrad]", lambda r: _ci(r["heading_rms_rad_ci_lo"], r["heading_rms_rad_ci_hi"], 1e3)),
    ("max abs weight", lambda r: _f(r["max_abs_weight"], 1.0, 3) if r["max_abs_weight"] is not None else "-"),
    (
        "worst seed",
        lambda r: (
            "-"
            if r["worst_seed"] is None
            else f"{r['worst_seed']}" + (f" ({r['worst_status']})" if r["worst_status"] != "ok" else "")
        ),
    ),
]

COMPARE_COLUMNS: list[tuple[str, Callable[[dict], str]]] = [
    ("scenario", lambda r: r["scenario"]),
    ("controller", lambda r: r["controller"]),
    ("phase", lambda r: r["phase"]),
    ("pos RMS median [mm]", lambda r: _f(r["pos_rms_m_median"], 1e3)),
    ("max error [mm]", lambda r: _f(r["max_err_m_max"], 1e3)),
    ("heading RMS median [mrad]", lambda r: _f(r["heading_rms_rad_median"], 1e3)),
    ("tracking / lost / diverged", lambda r: f"{r['tracking']} / {r['lost']} / {r['diverged']}"),
]

CSV_FIELDS = [
    "scenario", "controller", "phase", "runs", "bounded", "bounded_share", "tracking", "lost", "diverged",
    "pos_rms_m_mean", "pos_rms_m_median", "pos_rms_m_ci_lo", "pos_rms_m_ci_hi",
    "heading_rms_rad_mean", "heading_rms_rad_median", "heading_rms_rad_ci_lo", "heading_rms_rad_ci_hi",
    "max_err_m_median", "max_err_m_max", "max_abs_weight", "worst_seed", "worst_status",
]  # fmt: skip


def markdown(rows: list[dict], columns: list[tuple[str, Callable[[dict], str]]]) -> str:
    head = [c for c, _ in columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(" --- " for _ in head) + "|"]
    lines += ["| " + " | ".join(fn(r) for _, fn in columns) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def table_files(stem: str) -> tuple[str, ...]:
    """The files a sweep writes at the top of its folder (:func:`write_tables`, :func:`write_paired`, the plot)."""
    return tuple(f"{stem}{ext}" for ext in (".csv", ".md", ".json", ".png")) + PAIRED_FILES


PAIRED_FILES = ("paired.csv", "paired.md", "paired.json", "summary.md")


def write_tables(out: Path, stem: str, rows: list[dict], columns, meta: dict) -> list[Path]:
    """``stem``.csv (every statistic, SI units), .md (the readable table), .json (rows + how they were made)."""
    import csv
    import io

    buf = io.StringIO()
    axes = list(dict.fromkeys(k for r in rows for k in r.get("vary", {})))  # a column per --vary axis
    columns, fields = with_estimate(rows, columns, CSV_FIELDS)
    w = csv.DictWriter(buf, fieldnames=fields[:1] + axes + fields[1:], lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r[k]) for k in fields} | r.get("vary", {}))
    paths = [out / f"{stem}.csv", out / f"{stem}.md", out / f"{stem}.json"]
    note = (
        "\nStatistics over the runs that finished (tracking or lost; not over diverged ones); 95 % CI of "
        "the mean (Student t), its lower end clipped at 0 (an RMS is never negative: the clip keeps the "
        "interval's coverage). Tracking: every phase's position RMS within the run's lost threshold (its "
        "scenario's lost_threshold_m, else 5 % of the path's size: 0.2 m on the 4 m figure of eight); lost: "
        "beyond it; diverged: stopped (non-finite, beyond divergence_m, "
        "flipped). Worst seed: the first to diverge if any diverged, else the largest position RMS; re-run "
        "it alone with `mlpfac run SCENARIO --controller C --seed S`.\n"
    )
    write_atomic(paths[0], buf.getvalue())
    write_atomic(paths[1], markdown(rows, columns) + note)
    write_atomic(paths[2], json.dumps({"meta": meta, "rows": rows}, indent=2) + "\n")
    return paths


PAIRED_FIELDS = [
    "scenario", "controller", "phase", "runs", "tracking", "lost", "diverged", "pos_rms_m_median",
    "oracle_pos_rms_m_median", "x_oracle_median", "no_event_twin", "event_cost_median",
    "wins_vs_corradini", "pairs_vs_corradini", "p_vs_corradini", "wins_cost_vs_corradini",
    "pairs_cost_vs_corradini", "p_cost_vs_corradini", "wins_vs_oracle", "pairs_vs_oracle", "p_vs_oracle",
    "limit_pos_rms_m_median", "x_limit_median",
]  # fmt: skip


def write_paired(out: Path, rows: list[dict], meta: dict) -> list[Path]:
    """paired.csv / .md / .json (per seed against Corradini's law, the oracle and the run without the
    event: :mod:`mlpfac.sweeps.paired`) and summary.md (controllers x scenarios)."""
    import csv
    import io

    from mlpfac.sweeps import paired

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=PAIRED_FIELDS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r[k]) for k in PAIRED_FIELDS})
    note = "\n" + paired.note() + "\n"
    paths = [out / name for name in PAIRED_FILES]
    write_atomic(paths[0], buf.getvalue())
    write_atomic(paths[1], markdown(rows, paired.paired_columns(rows)) + note)
    write_atomic(paths[2], json.dumps({"meta": meta, "rows": rows}, indent=2) + "\n")
    estimated = any(r.get("est_rms_m_median") is not None for r in rows)
    write_atomic(paths[3], summary(rows) + SUMMARY_NOTE + (ESTIMATE_NOTE if estimated else ""))
    return paths


SUMMARY_NOTE = (
    "\nMedian position RMS [mm] over the seeds, after the event (over the whole run after the warm-up "
    "where there is none), over the runs that finished; (k x): the median over seeds of the ratio to "
    "the oracle on the same seed (and k x limit: to the physical limit, where the sweep ran it); t/l/d: tracking / lost / diverged, where not every run tracked; "
    f"{UNTOLD_MARK}: a law told the change more than {TOLD_AT_MOST:g}x itself told nothing (the median over "
    "seeds of the ratio on the same seed).\n"
)
ESTIMATE_NOTE = (
    "[belief off X]: where the pose was estimated ([plant] pose_source), the median over the seeds of the "
    "estimate's error RMS [mm] (belief against truth) in the same phase; every other figure is the truth's.\n"
)
