"""Where each controller breaks: the curves of a sweep with ``--vary`` axes and their breaking points.

Per scenario, controller and grid point, over the seeds (the figure of :mod:`mlpfac.sweeps.paired`:
the position RMS after the change, i.e. the last phase; a diverged run counts as infinite):

- the **median** and its 95 % interval (the distribution-free interval of the median: the order
  statistics whose binomial(n, 1/2) coverage is at least 95 %; none below 6 seeds);
- the **share of seeds tracking** (``outcome`` of metrics.json);
- the **bound**: the median over seeds of the least RMS of the laws told the change
  (``oracle``, ``oracle-kanayama``) that the sweep ran on the same seed and point;
- where the sweep ran ``limit`` (``--limit``: the run's own robot as the model, given the true
  state, :mod:`mlpfac.control.mpc`), its breaking point, the **physical breaking point** where no
  controller holds beyond it (what breaks is the robot: its traction, its torque); where one does,
  the note says so: there the planner lets go, not the physics;
- whether the point **holds**: every seed tracks and the median is within the threshold (default:
  the runs' own tracking limit: their scenario's ``lost_threshold_m``, else 5 % of the path's size,
  0.2 m on the 4 m figure of eight).

An axis of one value (``--vary controller.v_max=1e9``) is a setting, not an axis: each row keeps it
in ``set``, and the curves' heading says it.

The **breaking point** along an axis (the other axes held at each of their values) is, on each
side of the nominal value, the last value going away from it at which the point holds, before
the first at which it does not; "whole axis" when it holds to the axis' end. The nominal value is
the one at which an event changes nothing (1 for a scale or factor, 0 steps of delay, the robot's
own friction for a friction event's ``mu``), else the file's own value (the axis' smallest where the file leaves the key out). Written as robustness.json / .md beside the sweep's tables, and drawn in
robustness.png (:mod:`mlpfac.plots.robustness`).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

from mlpfac.exceptions import ConfigError
from mlpfac.io.files import write_atomic
from mlpfac.loop.metrics import RunMetrics
from mlpfac.plots.robustness import check_threshold  # noqa: F401 (the sweep's, the budget's and the file's)
from mlpfac.sweeps.paired import compared_rms, median
from mlpfac.sweeps.plan import Job

# the laws told the change: the bound (oracle-dynamic where it runs: a robot with torque motors)
TOLD = ("oracle", "oracle-kanayama", "oracle-dynamic")
LIMIT = "limit"  # the physical limit (mlpfac.control.mpc)
UNCHANGED = {"scale": 1.0, "factor": 1.0, "mass_scale": 1.0, "kv_scale": 1.0, "force_scale": 1.0, "steps": 0}
SIDES = ("below", "above")
FROM = re.compile(r"friction (\S+) -> ")  # the robot's own friction, in a friction event's record


NO_AXIS = "means nothing without an axis to break along (vary KEY=VALUES; a draw has no breaking point)"


def median_interval(xs: list[float]) -> tuple[float | None, float | None]:
    """The 95 % distribution-free interval of the median of ``xs``; (None, None) below 6 values."""
    from scipy.stats import binom

    n = len(xs)
    k = int(binom.ppf(0.025, n, 0.5)) if n else 0  # the largest k with P(B <= k - 1) <= 2.5 %
    while k > 0 and binom.cdf(k - 1, n, 0.5) > 0.025:
        k -= 1
    if k < 1:
        return None, None
    s = sorted(xs)
    return s[k - 1], s[n - k]


def nominal(job: Job, key: str, metrics: RunMetrics | None = None):
    """The value of ``key`` at which nothing changes: 1 for an event's scale or factor, 0 steps of
    delay, a friction event's ``mu`` the robot's own (what the event changed, as the job's run
    recorded it in ``metrics``), else the file's own value, or the default of a controller's table
    the file leaves out (``controller.mpc.fd_step``); None for another key the file leaves out."""
    from mlpfac.scenario.draws import get
    from mlpfac.scenario.parse import load

    last = key.rsplit(".", 1)[-1]
    if key.startswith("events.") and last in UNCHANGED:
        return UNCHANGED[last]
    if key.startswith("events.") and last == "mu" and metrics is not None:
        value = dict(job.point).get(key)
        for ev in metrics.events:  # "tyre/floor sliding friction 1 -> 0.2"
            if ev.get("kind") == "friction" and ev.get("params", {}).get("mu") == value:
                found = FROM.search(ev.get("text", ""))
                if found:
                    return float(found[1])
    try:
        scn = load(job.source, build=False, ends=False)
        value = get(scn.table, key)
    except ConfigError:
        return None
    except KeyError:
        parts = key.split(".")
        value = (
            getattr(getattr(scn, parts[1], None), parts[2], None)
            if len(parts) == 3 and parts[0] == "controller"
            else None
        )
    return value if isinstance(value, int | float) and not isinstance(value, bool) else None


def curves(jobs: list[Job], metrics: dict[tuple, RunMetrics], threshold: float | None) -> list[dict]:
    """One row per scenario, controller and grid point (plan order) of the jobs with a point."""
    cells: dict[tuple, list[Job]] = {}
    for j in jobs:
        if j.point:
            cells.setdefault((j.family, j.controller, j.point), []).append(j)
    told: dict[tuple, dict[int, float]] = {}  # (family, point) -> seed -> least RMS of the laws told the change
    for (fam, ctrl, point), js in cells.items():
        if ctrl in TOLD:
            best = told.setdefault((fam, point), {})
            for j in js:
                if j.key in metrics:
                    best[j.seed] = min(best.get(j.seed, math.inf), compared_rms(metrics[j.key]))
    values: dict[tuple[str, str], set] = {}  # (family, key) -> the axis's values
    for fam, _, point in cells:
        for key, v in point:
            values.setdefault((fam, key), set()).add(v)
    rows = []
    for (fam, ctrl, point), js in cells.items():
        ms = [metrics[j.key] for j in js if j.key in metrics]
        xs = [compared_rms(m) for m in ms]
        lo, hi = median_interval(xs)
        limit = threshold if threshold is not None else median([m.lost_threshold_m or 0.2 for m in ms])
        tracking = sum(m.outcome == "tracking" for m in ms)
        med = median(xs)
        bound = told.get((fam, point), {})
        axes = {k: v for k, v in point if len(values[(fam, k)]) > 1}  # an axis of one value is a setting
        rows.append({
            "scenario": fam, "controller": ctrl, "point": axes or dict(point),
            "set": {k: v for k, v in point if k not in axes} if axes else {}, "runs": len(js), "finished": len(ms),
            "tracking": tracking, "tracking_share": tracking / len(ms) if ms else None,
            "median_m": med, "ci_lo_m": lo, "ci_hi_m": hi, "threshold_m": limit,
            "bound_m": median(list(bound.values())) if bound else None,
            "holds": bool(ms) and len(ms) == len(js) and tracking == len(ms) and med is not None and med <= limit,
        })  # fmt: skip
    return rows


def breaking_points(rows: list[dict], nominals: dict[tuple[str, str], float | None]) -> list[dict]:
    """Per scenario, controller, axis and values of the other axes: the last value on each side of
    the nominal one at which the point holds (see the module's docstring)."""
    out = []
    groups: dict[tuple, dict] = {}
    for r in rows:
        for key, value in r["point"].items():
            at = tuple((k, v) for k, v in r["point"].items() if k != key)
            groups.setdefault((r["scenario"], r["controller"], key, at), {})[value] = r["holds"]
    for (fam, ctrl, key, at), holds in groups.items():
        values = sorted(holds)
        nom = nominals.get((fam, key))
        if nom is None:
            nom = values[0]
        found = {"scenario": fam, "controller": ctrl, "axis": key, "at": dict(at), "nominal": nom}
        for side in SIDES:
            way = [v for v in values if v >= nom] if side == "above" else [v for v in reversed(values) if v <= nom]
            if not way or way == [nom]:
                continue
            last, fails = None, None
            for v in way:
                if not holds[v]:
                    fails = v
                    break
                last = v
            found[side] = {"holds_to": last, "fails_at": fails, "whole_axis": fails is None}
        out.append(found)
    return out


def _num(x) -> str:
    return "-" if x is None else f"{x:g}"


def _beyond_limit(points: list[dict]) -> list[str]:
    """Where a controller holds beyond ``limit``'s breaking point (the same scenario, axis and other
    axes, on the same side): there the planner lets go, not the physics; said in a line each."""
    out = []
    for lim in (b for b in points if b["controller"] == LIMIT):
        for side, word in (("above", "up to"), ("below", "down to")):
            edge = lim.get(side)
            if edge is None or edge["whole_axis"]:
                continue
            mine = edge["holds_to"]
            past = [
                (b["controller"], b[side]["holds_to"])
                for b in points
                if b["controller"] != LIMIT
                and (b["scenario"], b["axis"], b["at"]) == (lim["scenario"], lim["axis"], lim["at"])
                and b.get(side) is not None
                and b[side]["holds_to"] is not None
                and (mine is None or (b[side]["holds_to"] > mine if side == "above" else b[side]["holds_to"] < mine))
            ]
            if past:
                who = ", ".join(f"{c} ({word} {_num(v)})" for c, v in past)
                out.append(
                    f"On {lim['scenario']} `{lim['axis']}` {who} hold beyond limit's breaking point "
                    f"({_side(edge)}): there the planner lets go, not the physics."
                )
    return out


def _side(b: dict | None) -> str:
    if b is None:
        return "-"
    if b["whole_axis"]:
        return f"{_num(b['holds_to'])} (whole axis)"
    if b["holds_to"] is None:
        return f"none (fails at {_num(b['fails_at'])})"
    return f"{_num(b['holds_to'])} (fails at {_num(b['fails_at'])})"


def curves_markdown(rows: list[dict]) -> str:
    """Per scenario with one axis: the median position RMS after the change [mm] of each controller
    at each value, with the seeds tracking where not all did, and the bound; with two, a table a
    controller, the second axis down."""
    out = []
    for fam in dict.fromkeys(r["scenario"] for r in rows):
        rs = [r for r in rows if r["scenario"] == fam]
        if len(rs[0]["point"]) == 2:
            out.extend(_grid_markdown(fam, rs))
        if len(rs[0]["point"]) != 1:
            continue
        (key,) = rs[0]["point"]
        values = sorted({r["point"][key] for r in rs})
        cell = {(r["controller"], r["point"][key]): r for r in rs}
        settings = "".join(f", {k} = {v:g}" for k, v in rs[0].get("set", {}).items())
        head = f"| {fam}: `{key}`{settings} | "
        lines = [head + " | ".join(f"{v:g}" for v in values) + " |", "|---" * (len(values) + 1) + "|"]
        for ctrl in dict.fromkeys(r["controller"] for r in rs):
            lines.append(f"| {ctrl} | " + " | ".join(_cell(cell.get((ctrl, v))) for v in values) + " |")
        bound = [
            next((r["bound_m"] for r in rs if r["point"][key] == v and r["bound_m"] is not None), None) for v in values
        ]
        if any(b is not None for b in bound):
            lines.append("| bound | " + " | ".join(_mm(b) for b in bound) + " |")
        out.append("\n".join(lines) + "\n")
    return "\n".join(out)


def _grid_markdown(fam: str, rs: list[dict]) -> list[str]:
    """A grid of two axes: per controller, the median position RMS after the change [mm] at each
    point, the first axis across and the second down."""
    across, down = rs[0]["point"]
    xs = sorted({r["point"][across] for r in rs})
    ys = sorted({r["point"][down] for r in rs})
    out = []
    for ctrl in dict.fromkeys(r["controller"] for r in rs):
        cell = {(r["point"][across], r["point"][down]): r for r in rs if r["controller"] == ctrl}
        lines = [
            f"| {fam}, {ctrl}: `{down}` \\ `{across}` | " + " | ".join(f"{x:g}" for x in xs) + " |",
            "|---" * (len(xs) + 1) + "|",
        ]
        lines += [f"| {y:g} | " + " | ".join(_cell(cell.get((x, y))) for x in xs) + " |" for y in ys]
        out.append("\n".join(lines) + "\n")
    return out


def _mm(x: float | None) -> str:
    return "-" if x is None else "inf" if not math.isfinite(x) else f"{1e3 * x:.2f}"


def _cell(r: dict | None) -> str:
    if r is None:
        return "-"
    text = _mm(r["median_m"])
    return text if r["tracking"] == r["runs"] else f"{text} ({r['tracking']}/{r['runs']})"


def markdown(points: list[dict], threshold: float | None, rows: list[dict] | None = None) -> str:
    lines = [
        "| scenario | controller | axis | other axes | nominal | holds down to | holds up to |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for b in points:
        at = ", ".join(f"{k} = {v:g}" for k, v in b["at"].items()) or "-"
        who = "limit (the robot as its model, the true state)" if b["controller"] == LIMIT else b["controller"]
        cells = [b["scenario"], who, f"`{b['axis']}`", at, _num(b["nominal"])]
        lines.append("| " + " | ".join(cells + [_side(b.get("below")), _side(b.get("above"))]) + " |")
    limit = (
        "the runs' own tracking limit (their lost_threshold_m, else 5 % of the path's size)"
        if threshold is None
        else f"{threshold:g} m"
    )
    note = (
        f"\nBreaking point: the last value, going away from the nominal one, at which every seed tracks and the "
        f"median position RMS after the change is within {limit}; the curves are in robustness.json and "
        "robustness.png.\n"
    )
    if any(b["controller"] == LIMIT for b in points):
        note += (
            "\nlimit: the run's own robot as its model, given the true state (a model-predictive controller): where it "
            "lets go and no controller holds, the physics does (the wheels' traction, the motors' torque)."
            + "".join(f" {line}" for line in _beyond_limit(points))
            + "\n"
        )
    table = curves_markdown(rows or [])
    if table:
        note += (
            "\nMedian position RMS after the change [mm] over the seeds (a diverged run counts as infinite), "
            "(k/n): seeds tracking where not all did; bound: the best law told the change, per seed.\n\n" + table
        )
    return "\n".join(lines) + "\n" + note


def write_robustness(out: Path, jobs: list[Job], metrics: dict[tuple, RunMetrics], meta: dict) -> list[Path]:
    """robustness.json / .md / .png beside the sweep's tables (nothing when no job has a grid point)."""
    if not any(j.point for j in jobs):
        return []
    threshold = meta.get("threshold_m")
    rows = curves(jobs, metrics, threshold)
    first: dict[tuple[str, str], Job] = {}  # a job of each scenario and axis, one that finished if any did
    for j in jobs:
        for key, _ in j.point:
            if (j.family, key) not in first or (j.key in metrics and first[j.family, key].key not in metrics):
                first[j.family, key] = j
    nominals = {fk: nominal(j, fk[1], metrics.get(j.key)) for fk, j in first.items()}
    points = breaking_points(rows, nominals)
    paths = [out / "robustness.json", out / "robustness.md"]
    data = {"meta": meta, "curves": rows, "breaking_points": points}
    write_atomic(paths[0], json.dumps(_finite(data), indent=2, allow_nan=False) + "\n")
    write_atomic(paths[1], markdown(points, threshold, rows))
    from mlpfac.plots.robustness import robustness_plot

    return paths + robustness_plot(out)


def _finite(x):
    """``x`` with every float that is not finite replaced by None (JSON has no Infinity), as in metrics.json."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite(v) for v in x]
    return None if isinstance(x, float) and not math.isfinite(x) else x
