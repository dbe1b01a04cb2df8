"""The pictures of a sweep or a comparison, written next to its table (``sweep.png`` beside
``sweep.md``, ``compare.png`` beside ``compare.md``): one row per scenario, with

- left, the position RMS after the event per controller (whole run after the warm-up when the
  scenario has no event): one dot per finished run (tracking or lost, a lost one a cross) over a
  box (quartiles, whiskers 1.5 IQR), on a log scale when the runs spread over more than a decade;
  the share of finished runs and their median beside each controller's name, red when a run was
  lost or diverged. The runs are those the table's statistics are over, so the medians are the
  table's (sweep.md);
- right, the position error over time (the RMS per 0.1 s, from metrics.json's mean square per
  bin, ``position_ms_bins``): the median over the same runs and the band between their
  quartiles, the event marked.

Everything is read from the run folders (``<scenario>/<controller>/seed-*/metrics.json``), so the
plots can be made again from a finished sweep with ``mlpfac plot DIR``.
"""

from __future__ import annotations

import json
import textwrap
import warnings
from pathlib import Path

import numpy as np

from mlpfac.loop.metrics import RunMetrics
from mlpfac.loop.record import force_windows
from mlpfac.plots.colors import controller_colors, mpl

STEMS = ("sweep", "compare")


def load_runs(out: Path) -> dict[tuple[str, str], list[RunMetrics]]:
    """Every whole run's metrics under ``out``, by (scenario, controller), in seed order."""
    runs: dict[tuple[str, str], list[RunMetrics]] = {}
    for f in sorted(out.glob("*/*/seed-*/metrics.json")):
        try:
            m = json.loads(f.read_text())
        except (OSError, ValueError, RecursionError):
            continue
        if isinstance(m, dict) and m.get("status") in ("ok", "diverged") and "phases" in m:
            run = RunMetrics.from_json(m)  # a KeyError, TypeError or ValueError: a file edited by hand
            runs.setdefault((run.scenario, run.controller), []).append(run)
    return runs


def _order(out: Path, stem: str, runs: dict) -> list[tuple[str, str]]:
    """(scenario, controller) pairs in the table's order, then any others found in the folder."""
    pairs: list[tuple[str, str]] = []
    try:
        rows = json.loads((out / f"{stem}.json").read_text())["rows"]
        pairs = [(r["scenario"], r["controller"]) for r in rows]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return [p for p in dict.fromkeys(pairs + sorted(runs)) if p in runs]


def sweep_plots(out: Path, stems: tuple[str, ...] = STEMS) -> list[Path]:
    """Draw ``<stem>.png`` for each table ``<stem>.json`` in ``out`` (or one ``sweep.png`` when the
    folder has runs but no table); returns the files written. A folder without runs draws nothing."""
    out = Path(out)
    runs = load_runs(out)
    if not runs:
        return []
    found = [s for s in stems if (out / f"{s}.json").is_file()] or [stems[0]]
    written = []
    for stem in found:
        pairs = _order(out, stem, runs)
        written.append(draw(out / f"{stem}.png", pairs, runs))
    return written


def draw(path: Path, pairs: list[tuple[str, str]], runs: dict) -> Path:
    """One row per scenario: the error distribution per controller and the error over time."""
    from mlpfac.plots.mplconfig import quiet_config

    quiet_config()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenarios = list(dict.fromkeys(s for s, _ in pairs))
    colors = {k: mpl(v) for k, v in controller_colors(c for _, c in pairs).items()}
    fig, axes = plt.subplots(
        len(scenarios),
        2,
        figsize=(14, sum(_row_height(sum(s == scn for s, _ in pairs)) for scn in scenarios) + 0.4),
        gridspec_kw={
            "width_ratios": [1, 1.3],
            "height_ratios": [_row_height(sum(s == x for s, _ in pairs)) for x in scenarios],
        },
        squeeze=False,
        layout="constrained",
    )
    for row, scn in zip(axes, scenarios, strict=True):
        ctrls = [c for s, c in pairs if s == scn]
        _distribution(row[0], scn, ctrls, runs, colors)
        _over_time(row[1], ctrls, [runs[(scn, c)] for c in ctrls], colors)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _row_height(controllers: int) -> float:
    return max(3.4, 0.38 * controllers + 1.3)


def _phase(ms: list[RunMetrics]) -> str:
    return "after" if any(m.last_phase == "after" for m in ms) else "before"


def _event_text(ms: list[RunMetrics]) -> tuple[float | None, str]:
    for m in ms:
        for ev in m.events:
            return float(ev["time"]), str(ev.get("text") or ev.get("kind") or "event")
    return None, ""


def finished(m: RunMetrics) -> bool:
    """A run that reached its end (tracking or lost): the runs a sweep's statistics are over."""
    return m.outcome in ("tracking", "lost")


def log_ticks(axis, lo: float, hi: float) -> None:
    """Labels on a log axis that do not overlap: 1-2-5 steps within three decades, else powers
    of ten only; plain numbers (0.5, 20, 1000), no minor labels."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    decades = np.log10(hi / lo) if lo > 0 else 9.0
    axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0) if decades <= 3 else (1.0,)))
    axis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
    axis.set_minor_formatter(NullFormatter())


def _distribution(ax, scn: str, ctrls: list[str], runs: dict, colors: dict) -> None:
    """Controllers top to bottom; each finished run a dot (a lost one a cross) over its box; "k/n"
    finished and their median in the labels (red when a run was lost or diverged)."""
    all_ms = [m for c in ctrls for m in runs[(scn, c)]]
    phase = _phase(all_ms)
    rng = np.random.default_rng(0)  # the dots' jitter: the same picture every time
    pos = -np.arange(len(ctrls))  # the first controller on top
    labels, filled = [], []
    for p, c in zip(pos, ctrls, strict=True):
        ms = runs[(scn, c)]
        ok = [m for m in ms if finished(m)]
        pairs = [(m.phases[phase].rms_position_error_m if phase in m.phases else None, m.outcome == "lost") for m in ok]
        pairs = [(x * 1e3, lost) for x, lost in pairs if x is not None and np.isfinite(x)]
        v = np.array([x for x, _ in pairs])
        lost_v = np.array([lost for _, lost in pairs], dtype=bool)
        other = [
            f"{sum(m.outcome == k for m in ms)} {k}" for k in ("lost", "diverged") if any(m.outcome == k for m in ms)
        ]
        labels.append(f"{c}  {len(ok)}/{len(ms)}" + (f"  median {np.median(v):.3g}" if len(v) else "  none finished"))
        if other:
            labels[-1] += f"\n({', '.join(other)})"
        if len(v):
            filled.append((p, v, c, lost_v))
    if filled:
        ax.boxplot(
            [v for _, v, _, _ in filled],
            positions=[p for p, _, _, _ in filled],
            orientation="horizontal",
            widths=0.6,
            showfliers=False,
            medianprops={"color": "black", "lw": 1.5},
            boxprops={"color": "0.35"},
            whiskerprops={"color": "0.35"},
            capprops={"color": "0.35"},
        )
        for p, v, c, lost in filled:
            y = p + rng.uniform(-0.2, 0.2, len(v))
            ax.scatter(v[~lost], y[~lost], s=12, color=colors[c], alpha=0.75, zorder=3, lw=0)
            if lost.any():
                ax.scatter(v[lost], y[lost], s=22, color=colors[c], marker="x", zorder=3, lw=1.2)
        lo, hi = min(v.min() for _, v, _, _ in filled), max(v.max() for _, v, _, _ in filled)
        if lo > 0 and hi / lo > 10:
            ax.set_xscale("log")
            log_ticks(ax.xaxis, lo, hi)
    ax.set_yticks(pos, labels, fontsize=8)
    for tick, c in zip(ax.get_yticklabels(), ctrls, strict=True):
        ms = runs[(scn, c)]
        tick.set_color("black" if all(m.outcome == "tracking" for m in ms) else "firebrick")
    ax.set_ylim(pos[-1] - 0.6, 0.6)
    what = "after the event" if phase == "after" else "after the warm-up"
    ax.set_xlabel(f"position RMS {what} [mm]")
    ax.set_title(f"{scn}: one dot per finished run, x lost (finished k/n, median in mm)", fontsize=10)
    ax.grid(axis="x", alpha=0.3, which="both")


def _over_time(ax, ctrls: list[str], groups: list[list[RunMetrics]], colors: dict) -> None:
    t_event, text = _event_text([m for ms in groups for m in ms])
    warm = max((m.excluded_s[1] for ms in groups for m in ms), default=0.0)
    spans, missing, peak = [], 0, 0.0
    for c, ms in zip(ctrls, groups, strict=True):
        series = [m.rms_bins() for m in ms if finished(m)]
        missing += sum(s is None for s in series)
        series = [s for s in series if s is not None]
        if not series:
            ax.plot([], [], color=colors[c], label=f"{c} (no finished run)")
            continue
        dt = series[0][0]
        width = max(len(v) for _, v in series)
        arr = np.full((len(series), width), np.nan)
        for i, (_, v) in enumerate(series):
            arr[i, : len(v)] = v * 1e3
        t = (np.arange(width) + 0.5) * dt
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns past a short run's end
            q1, med, q3 = np.nanpercentile(arr, [25, 50, 75], axis=0)
        ax.fill_between(t, q1, q3, color=colors[c], alpha=0.22, lw=0)
        ax.plot(t, med, color=colors[c], lw=1.4, label=f"{c} ({len(series)} runs)")
        spans.append(q3[np.isfinite(q3) & (t >= warm)])
        peak = max(peak, float(np.nanmax(q3, initial=0.0)))
    if not spans:
        ax.text(0.5, 0.5, "no position_ms_bins in these runs' metrics.json", transform=ax.transAxes, ha="center")
        return
    vals = np.concatenate(spans)
    vals = vals[vals > 0]
    if len(vals) and np.percentile(vals, 99) / max(np.percentile(vals, 1), 1e-9) > 20:
        ax.set_yscale("log")
        log_ticks(ax.yaxis, float(vals.min()), max(peak, float(vals.max())))
    elif len(vals) and peak > 1.5 * vals.max():  # the start's transient would flatten the rest: clip it
        ax.set_ylim(0, 1.6 * vals.max())
        ax.annotate(
            f"start clipped\n(up to {peak:.3g} mm)", (warm, 0.97), xycoords=("data", "axes fraction"),
            xytext=(3, 0), textcoords="offset points", va="top", fontsize=7, color="0.4",
        )  # fmt: skip
    if warm > 0:
        ax.axvspan(0, warm, color="0.85", lw=0, zorder=0)
        ax.annotate(
            "warm-up", (warm / 2, 0.02), xycoords=("data", "axes fraction"), ha="center", fontsize=7, color="0.4"
        )
    end = max((float(m.steps) * float(m.T) for ms in groups for m in ms), default=0.0)
    events = next((m.events for ms in groups for m in ms if m.events), ())
    for j, (t0, t1) in enumerate(force_windows(events, end)):  # while a force acts on the robot
        ax.axvspan(
            t0, t1, color="mediumvioletred", alpha=0.15, lw=0, zorder=0, label="a force acts" if j == 0 else None
        )
    if t_event is not None:
        ax.axvline(t_event, color="firebrick", ls="--", lw=1.0)
        ax.annotate(
            "event: " + textwrap.shorten(text.split(" (")[0], 60, placeholder=" ..."),
            (t_event, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(4, -4),
            bbox={"fc": "white", "ec": "none", "alpha": 0.8, "pad": 1},
            textcoords="offset points",
            va="top",
            fontsize=8,
            color="firebrick",
        )
    ax.set_xlabel("t [s]")
    ax.set_ylabel("position error [mm]\n(RMS per 0.1 s)")
    note = f"; {missing} runs without a series" if missing else ""
    ax.set_title(f"error over time: median, band = quartiles over finished runs{note}", fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.grid(alpha=0.3, which="both")
    ax.set_xlim(0, None)
