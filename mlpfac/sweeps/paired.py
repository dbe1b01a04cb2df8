"""Paired comparisons per seed: each run against the Corradini law's and the oracle's on the same
scenario and seed, and against its own run without the event.

The figure compared is the position RMS of the last phase ("after" the event; the whole run after
the warm-up when there is none). Per scenario and controller:

- **x oracle**: the median over seeds of the run's RMS / the oracle's (same scenario and seed);
- **event cost**: the median over seeds of the run's RMS after the event / the same controller's
  RMS on the same seed over the same window of its twin without the event (the scenario of the
  sweep equal to this one but for its events: ``eight-nominal`` for every ``eight-*`` but
  ``eight-torque``). 1 means the event cost this controller nothing; a controller that is simply
  better everywhere does not get a lower cost from that edge;
- **wins / n, p**: on how many seeds the run is better (strictly lower) than the reference, and the
  two-sided Wilcoxon signed-rank test of the paired differences (scipy), against Corradini's law
  and the oracle on the RMS, and against Corradini's law on the event cost. A run that diverged
  counts as worse than any finished one (a loss, and the largest rank); a pair with a run missing
  is left out; a pair of equal figures is no win (and is dropped by the test, as Wilcoxon's rule);
- **x limit** (where the sweep ran ``limit``, ``--limit``): the median over seeds of the run's RMS /
  ``limit``'s, the run's own robot as the model given the true state: how far from what the
  physics allows (:mod:`mlpfac.control.mpc`);
- **x untold** (a law told the change: ``oracle``, ``oracle-kanayama``, ``oracle-dynamic``): the
  median over seeds of its RMS / the same law's told nothing (``corradini``, ``kanayama``,
  ``fierro-lewis``) where that ran too. A told law should be at most ``TOLD_AT_MOST`` times itself
  untold; the summary marks (``UNTOLD_MARK``) a cell where it is not (docs/robots.md says why where
  it cannot be).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from mlpfac.loop.metrics import RunMetrics
from mlpfac.sweeps.plan import Job

REFERENCES = ("corradini", "oracle")
LIMIT = "limit"  # the physical limit (mlpfac.control.mpc), where a sweep ran it
UNTOLD = {"oracle": "corradini", "oracle-kanayama": "kanayama", "oracle-dynamic": "fierro-lewis"}  # told: untold
TOLD_AT_MOST, UNTOLD_MARK = 1.1, "‡"
NAMES = {"``TOLD_AT_MOST``": f"{TOLD_AT_MOST:g}", "``UNTOLD_MARK``": UNTOLD_MARK}  # the docstring's names, in words
TWIN_IGNORES = ("name", "description", "events", "seed")  # what a scenario's twin without the event may differ in


def note() -> str:
    """What the paired figures are, for paired.md: the module's docstring but its title, its list a
    Markdown list, the names of the code in their values (1.1, ‡), code in single backticks."""
    out: list[str] = []
    for line in (__doc__ or "").split("\n\n", 1)[1].splitlines():
        line = line.strip()
        if not line or line.startswith("- ") or not out or not out[-1]:
            out.append(line)
        else:
            out[-1] += " " + line
    text = "\n".join(out).strip()
    for name, value in NAMES.items():
        text = text.replace(name, value)
    return text.replace("``", "`")


def wilcoxon(x: list[float], y: list[float], alternative: str = "two-sided") -> float | None:
    """Wilcoxon signed-rank p of the differences x - y (scipy), two-sided or, with ``alternative``
    "greater", one-sided (x larger); None when all are zero."""
    d = [a - b for a, b in zip(x, y, strict=True) if a != b]
    if not d:
        return None
    from scipy.stats import wilcoxon as test

    return float(test(d, alternative=alternative).pvalue)


def compared_rms(m: RunMetrics | None) -> float | None:
    """The compared figure: the last phase's position RMS; inf for a run that diverged or whose last
    phase has no step; None if missing."""
    if m is None:
        return None
    x = m.rms()
    return math.inf if x is None else x


def compare(
    x: list[float | None], y: list[float | None], alternative: str = "two-sided"
) -> tuple[int, int, float | None]:
    """(wins of x, pairs, Wilcoxon p (see :func:`wilcoxon`)) over the seeds where both are known;
    inf is worse than any number."""
    pairs = [(a, b) for a, b in zip(x, y, strict=True) if a is not None and b is not None and a == a and b == b]
    if not pairs:
        return 0, 0, None
    finite = [abs(v) for p in pairs for v in p if math.isfinite(v)]
    big = 2.0 * max(finite, default=0.0) + 1.0  # beyond any finite |difference|: the largest rank
    xs = [a if math.isfinite(a) else big for a, _ in pairs]
    ys = [b if math.isfinite(b) else big for _, b in pairs]
    wins = sum(a < b for a, b in pairs)
    return wins, len(pairs), wilcoxon(xs, ys, alternative)


def twins(jobs: list[Job]) -> dict[str, str]:
    """Each scenario with events -> the scenario of the plan that is the same without them."""
    tables: dict[str, dict] = {}
    for j in jobs:
        tables.setdefault(j.scenario, {k: v for k, v in j.table.items() if k not in TWIN_IGNORES and k != "controller"})
    plain = [s for s, t in tables.items() if not any(j.table.get("events") for j in jobs if j.scenario == s)]
    out = {}
    for s, t in tables.items():
        match = [p for p in plain if tables[p] == t]
        if s not in plain and match:
            out[s] = match[0]
    return out


def median(xs: list[float]) -> float | None:
    s = sorted(xs)
    n = len(s)
    if not n:
        return None
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


def _ratios(x: list[float | None], y: list[float | None]) -> list[float]:
    return [a / b for a, b in zip(x, y, strict=True) if a is not None and b and math.isfinite(a) and math.isfinite(b)]


def paired_rows(jobs: list[Job], metrics: dict[tuple, RunMetrics]) -> list[dict]:
    """One row per scenario and controller (plan order): the paired figures of the module's docstring."""
    seeds: dict[tuple[str, str], list[int]] = {}
    points = {j.scenario: j.point for j in jobs}
    for j in jobs:
        seeds.setdefault((j.scenario, j.controller), []).append(j.seed)
    twin = twins(jobs)
    rows = []
    for (scn, ctrl), ss in seeds.items():
        ms = [metrics.get((scn, ctrl, s)) for s in ss]
        x = [compared_rms(m) for m in ms]
        row: dict = {"scenario": scn, "controller": ctrl, "runs": sum(m is not None for m in ms)}
        if points[scn]:  # a grid point of --vary: its values by key (the summary's column says them)
            row["vary"] = dict(points[scn])
        for how in ("tracking", "lost", "diverged"):
            row[how] = sum(m is not None and m.outcome == how for m in ms)
        done = [m for m in ms if m is not None]
        row["phase"] = done[0].last_phase if done else None
        if any(m.estimate for m in done):  # a pose that was estimated: the belief's error, in the same phase
            est = [(m.estimate["phases"].get(row["phase"]) or {}).get("rms_position_error_m") for m in done]
            row["est_rms_m_median"] = median(
                [v for m, v in zip(done, est, strict=True) if m.finished and v is not None]
            )
        row["pos_rms_m_median"] = median([v for v in x if v is not None and math.isfinite(v)])
        refs = {r: [compared_rms(metrics.get((scn, r, s))) for s in ss] for r in REFERENCES}
        row["x_oracle_median"] = median(_ratios(x, refs["oracle"]))
        row["oracle_pos_rms_m_median"] = median([v for v in refs["oracle"] if v is not None and math.isfinite(v)])
        limit = [compared_rms(metrics.get((scn, LIMIT, s))) for s in ss]
        row["x_limit_median"] = median(_ratios(x, limit))
        row["limit_pos_rms_m_median"] = median([v for v in limit if v is not None and math.isfinite(v)])
        for r in REFERENCES:
            row[f"wins_vs_{r}"], row[f"pairs_vs_{r}"], row[f"p_vs_{r}"] = compare(x, refs[r])
        untold = [compared_rms(metrics.get((scn, UNTOLD[ctrl], s))) for s in ss] if ctrl in UNTOLD else []
        row["x_untold_median"] = median(_ratios(x, untold)) if untold else None
        cost = _event_cost(metrics, scn, ctrl, ss, twin.get(scn), x)
        base = _event_cost(metrics, scn, "corradini", ss, twin.get(scn), refs["corradini"])
        row["no_event_twin"] = twin.get(scn)
        row["event_cost_median"] = median([c for c in cost if c is not None and math.isfinite(c)])
        row["wins_cost_vs_corradini"], row["pairs_cost_vs_corradini"], row["p_cost_vs_corradini"] = compare(cost, base)
        rows.append(row)
    return rows


def _event_cost(metrics, scn, ctrl, seeds, twin, x) -> list[float | None]:
    """Per seed: RMS after the event / the same controller's RMS over that window without the event."""
    if twin is None:
        return [None] * len(seeds)
    out: list[float | None] = []
    for s, a in zip(seeds, x, strict=True):
        m, t = metrics.get((scn, ctrl, s)), metrics.get((twin, ctrl, s))
        if a is None or m is None or t is None:
            out.append(None)
            continue
        ph = m.phases.get("after")
        b = t.window_rms(ph.start_s, ph.end_s) if ph else None
        out.append(math.inf if not math.isfinite(a) else (a / b if b else None))
    return out


def _p(p: float | None) -> str:
    return "-" if p is None else (f"{p:.2g}" if p >= 1e-3 else f"{p:.0e}")


def _mm(x: float | None) -> str:
    return "-" if x is None else f"{x * 1e3:.2f}"


def _x(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}x"


PAIRED_COLUMNS: list[tuple[str, Callable[[dict], str]]] = [
    ("scenario", lambda r: r["scenario"]),
    ("controller", lambda r: r["controller"]),
    ("tracking / lost / diverged", lambda r: f"{r['tracking']} / {r['lost']} / {r['diverged']}"),
    ("pos RMS median [mm]", lambda r: _mm(r["pos_rms_m_median"])),
    ("oracle [mm]", lambda r: _mm(r["oracle_pos_rms_m_median"])),
    ("x oracle", lambda r: _x(r["x_oracle_median"])),
    ("event cost", lambda r: _x(r["event_cost_median"])),
    ("wins vs corradini", lambda r: f"{r['wins_vs_corradini']}/{r['pairs_vs_corradini']}"),
    ("p vs corradini", lambda r: _p(r["p_vs_corradini"])),
    ("cost wins vs corradini", lambda r: f"{r['wins_cost_vs_corradini']}/{r['pairs_cost_vs_corradini']}"),
    ("p (cost)", lambda r: _p(r["p_cost_vs_corradini"])),
    ("wins vs oracle", lambda r: f"{r['wins_vs_oracle']}/{r['pairs_vs_oracle']}"),
    ("p vs oracle", lambda r: _p(r["p_vs_oracle"])),
]
LIMIT_COLUMNS: list[tuple[str, Callable[[dict], str]]] = [
    ("limit [mm]", lambda r: _mm(r.get("limit_pos_rms_m_median"))),
    ("x limit", lambda r: _x(r.get("x_limit_median"))),
]


def paired_columns(rows: list[dict]) -> list[tuple[str, Callable[[dict], str]]]:
    """The paired table's columns: with the limit's beside the oracle's where a row has it."""
    if not any(r.get("limit_pos_rms_m_median") is not None for r in rows):
        return PAIRED_COLUMNS
    at = next(i for i, (name, _) in enumerate(PAIRED_COLUMNS) if name == "x oracle") + 1
    return PAIRED_COLUMNS[:at] + LIMIT_COLUMNS + PAIRED_COLUMNS[at:]


def _times(x: float) -> str:
    return f"{x:.2g}x" if x < 10 else f"{x:.0f}x"


def column_name(scenario: str, point: dict | None) -> str:
    """A summary's column: the scenario, and a grid point of ``--vary`` by its values, each named by
    its key's last part where that is unique (``eight-slope: angle_deg 12, fy 6``), not by the
    folder's name (``eight-slope+events.0.angle_deg+12.0+events.1.fy+6.0``)."""
    if not point:
        return scenario
    from mlpfac.sweeps.vary import label

    family = scenario.removesuffix(label("", tuple(point.items())))
    short = [k.rsplit(".", 1)[-1] for k in point]
    names = short if len(set(short)) == len(short) else list(point)
    return f"{family}: " + ", ".join(f"{n} {v:g}" for n, v in zip(names, point.values(), strict=True))


def summary(rows: list[dict], bound: str | None = "oracle") -> str:
    """Controllers x scenarios: the median RMS [mm] with the median ratio to ``bound`` on the same
    seed ("oracle": ``x_oracle_median``; another controller: each row's ``x_bound_median``, from
    :func:`bound_ratios`; None: no ratio, where no law of the table is a bound), and
    tracking/lost/diverged unless all tracked; a told law more than TOLD_AT_MOST of itself told
    nothing marked UNTOLD_MARK."""
    key = "x_oracle_median" if bound == "oracle" else "x_bound_median"
    scns = list(dict.fromkeys(r["scenario"] for r in rows))
    ctrls = list(dict.fromkeys(r["controller"] for r in rows))
    cell = {(r["scenario"], r["controller"]): r for r in rows}

    def fmt(r: dict | None) -> str:
        if r is None or not r["runs"]:
            return "-"
        text = _mm(r["pos_rms_m_median"])
        ratios = []
        if bound is not None and r["controller"] != bound and r.get(key) is not None:
            ratios.append(_times(r[key]))
        if r["controller"] != LIMIT and r.get("x_limit_median") is not None:
            ratios.append(f"{_times(r['x_limit_median'])} limit")
        if ratios:
            text += f" ({'; '.join(ratios)})"
        if r["tracking"] != r["runs"]:
            text += f" {r['tracking']}/{r['lost']}/{r['diverged']}"
        if (r.get("x_untold_median") or 0.0) > TOLD_AT_MOST:  # worse than itself told nothing (or lost where it ran)
            text += f" {UNTOLD_MARK}"
        if r.get("est_rms_m_median") is not None:
            text += f" [belief off {_mm(r['est_rms_m_median'])}]"
        return text

    heads = [column_name(s, next(r.get("vary") for r in rows if r["scenario"] == s)) for s in scns]
    lines = ["| controller | " + " | ".join(heads) + " |", "|---|" + "---:|" * len(scns)]
    lines += [f"| `{c}` | " + " | ".join(fmt(cell.get((s, c))) for s in scns) + " |" for c in ctrls]
    return "\n".join(lines) + "\n"


def figure(r: dict) -> float:
    """A run's compared figure from its row of runs.json: the last phase's position RMS, inf if it diverged."""
    if r["status"] != "ok":
        return math.inf
    phases = r.get("phases") or {}
    after = (phases.get("after") or {}).get("rms_position_error_m")
    x = after if after is not None else (phases.get("before") or {}).get("rms_position_error_m")
    return math.inf if x is None else x


def bound_ratios(runs: list[dict], bound: str) -> dict[tuple[str, str], float | None]:
    """Per scenario and controller: the median over seeds of its compared figure / ``bound``'s on the
    same seed (as ``x oracle``, another law in place of the oracle), from the runs' figures as
    ``runs.json`` keeps them (:func:`mlpfac.report.verify.run_row`)."""

    fig = {(r["scenario"], r["controller"], r["seed"]): figure(r) for r in runs}
    out: dict[tuple[str, str], list[float]] = {}
    for (scn, ctrl, seed), x in fig.items():
        b = fig.get((scn, bound, seed))
        out.setdefault((scn, ctrl), [])
        if b is not None:
            out[(scn, ctrl)] += _ratios([x], [b])
    return {k: median(v) for k, v in out.items()}
