"""robustness.png: where each controller breaks, drawn from robustness.json
(:mod:`mlpfac.sweeps.robustness`).

One axis: per scenario, the median position RMS after the change against the value, per
controller, with its 95 % interval as a band, the bound (the best law told the change) dashed
black, the threshold dotted, the nominal value marked; ``limit`` (the run's own robot as the
model, given the true state: :mod:`mlpfac.control.mpc`) solid black, and beyond the value where it
lets go, shaded (the physical breaking point where no controller holds beyond it; robustness.md
says where one does); below it, the share of seeds tracking.
Two axes or more: per scenario and controller a map over the first two axes (the others at their
first value) of the median position RMS, each point that holds ringed.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plots.colors import controller_colors, mpl

LIMIT = "limit"  # the physical limit (mlpfac.control.mpc): its curve and breaking point drawn apart
LIMIT_LABEL = "limit (the robot as its model, the true state)"


def robustness_plot(out: Path) -> list[Path]:
    """Draw ``out``/robustness.png from ``out``/robustness.json; returns the file written."""
    data = read_robustness(out / "robustness.json")
    rows, points = data["curves"], data.get("breaking_points", [])
    if not rows:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    families = list(dict.fromkeys(r["scenario"] for r in rows))
    axes_of = {f: list(next(r["point"] for r in rows if r["scenario"] == f)) for f in families}
    ctrls = list(dict.fromkeys(r["controller"] for r in rows))
    colors = {k: mpl(v) for k, v in controller_colors(ctrls).items()}
    path = out / "robustness.png"
    if all(len(a) == 1 for a in axes_of.values()):
        fig, axs = plt.subplots(2, len(families), figsize=(6.5 * len(families), 6.5), squeeze=False,
                                gridspec_kw={"height_ratios": [2.2, 1]}, layout="constrained")  # fmt: skip
        for i, fam in enumerate(families):
            _curves(
                axs[0, i], axs[1, i], fam, axes_of[fam][0], [r for r in rows if r["scenario"] == fam], points, colors
            )
    else:
        pairs = [
            (f, c) for f in families for c in ctrls if any(r["scenario"] == f and r["controller"] == c for r in rows)
        ]
        cols = min(len(pairs), 3)
        nrows = math.ceil(len(pairs) / cols)
        fig, axs = plt.subplots(nrows, cols, figsize=(5.2 * cols, 4.3 * nrows), squeeze=False, layout="constrained")
        for ax, (fam, ctrl) in zip(axs.flat, pairs, strict=False):
            _map(
                fig, ax, fam, ctrl, axes_of[fam], [r for r in rows if r["scenario"] == fam and r["controller"] == ctrl]
            )
        for ax in list(axs.flat)[len(pairs) :]:
            ax.set_visible(False)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return [path]


def _finite(x) -> float:
    return math.nan if x is None or not math.isfinite(x) else x


def _curves(ax, share_ax, fam: str, key: str, rows: list[dict], points: list[dict], colors: dict) -> None:
    for ctrl in dict.fromkeys(r["controller"] for r in rows):
        rs = sorted((r for r in rows if r["controller"] == ctrl), key=lambda r: r["point"][key])
        x = [r["point"][key] for r in rs]
        med = np.array([_finite(r["median_m"]) for r in rs]) * 1e3
        c = "k" if ctrl == LIMIT else colors[ctrl]
        ax.plot(
            x, med, "o-", color=c, label=LIMIT_LABEL if ctrl == LIMIT else ctrl, ms=4, lw=2.2 if ctrl == LIMIT else 1.5
        )
        lo = np.array([_finite(r["ci_lo_m"]) for r in rs]) * 1e3
        hi = np.array([_finite(r["ci_hi_m"]) for r in rs]) * 1e3
        ax.fill_between(x, lo, hi, color=c, alpha=0.15, lw=0)
        share_ax.plot(x, [100 * (r["tracking_share"] or 0.0) for r in rs], "o-", color=c, ms=3)
    one = [r for r in rows if r["bound_m"] is not None]
    if one:
        bx = sorted({r["point"][key] for r in one})
        by = [1e3 * _finite(next(r["bound_m"] for r in one if r["point"][key] == v)) for v in bx]
        ax.plot(bx, by, "k--", lw=1.2, label="bound (best law told the change)")
    ax.axhline(1e3 * rows[0]["threshold_m"], color="0.4", ls=":", lw=1, label="threshold")
    values = [r["point"][key] for r in rows]
    for p in points:  # beyond where limit lets go (the physics, where no controller holds there)
        if p["scenario"] != fam or p["controller"] != LIMIT or p["axis"] != key or p["at"]:
            continue
        for side, end in (("below", min(values)), ("above", max(values))):
            b = p.get(side)
            if b and not b["whole_axis"] and b["fails_at"] is not None:
                for a in (ax, share_ax):
                    a.axvspan(b["fails_at"], end, color="0.88", zorder=0, lw=0)
                ax.axvline(b["fails_at"], color="k", lw=0.8, ls="-.", label=f"limit lets go ({b['fails_at']:g})")
    nominal = next((p["nominal"] for p in points if p["scenario"] == fam and p["axis"] == key), None)
    for a in (ax, share_ax):
        if nominal is not None:
            a.axvline(nominal, color="0.7", lw=0.8)
    ax.set_yscale("log")
    ax.set_title(fam, fontsize=10)
    ax.set_ylabel("median position RMS after the change [mm]")
    ax.legend(fontsize=7)
    for a in (ax, share_ax):
        _xscale(a, [r["point"][key] for r in rows])
    share_ax.set_ylabel("seeds tracking [%]")
    share_ax.set_ylim(-5, 105)
    share_ax.set_xlabel(key)


def _xscale(ax, values: list[float]) -> None:
    """A log scale for values over more than a decade (a friction from 1 to 0.05), else linear."""
    if min(values) > 0 and max(values) >= 10 * min(values):
        ax.set_xscale("log")
        ax.set_xticks(sorted(set(values)), [f"{v:g}" for v in sorted(set(values))], minor=False)
        ax.minorticks_off()


def _map(fig, ax, fam: str, ctrl: str, keys: list[str], rows: list[dict]) -> None:
    kx, ky = keys[0], keys[1]
    rest = {k: rows[0]["point"][k] for k in keys[2:]}
    rows = [r for r in rows if all(r["point"][k] == v for k, v in rest.items())]
    xs = sorted({r["point"][kx] for r in rows})
    ys = sorted({r["point"][ky] for r in rows})
    z = np.full((len(ys), len(xs)), np.nan)
    for r in rows:
        med = _finite(r["median_m"])
        z[ys.index(r["point"][ky]), xs.index(r["point"][kx])] = 1e3 * med if med > 0 else np.nan
    from matplotlib.colors import LogNorm

    seen = z[np.isfinite(z)]
    if seen.size:  # cells where no run finished (or all diverged) stay blank
        norm = LogNorm(vmin=seen.min() / 1.1, vmax=seen.max() * 1.1)
        im = ax.pcolormesh(_edges(xs), _edges(ys), z, norm=norm, shading="flat", cmap="viridis")
        fig.colorbar(im, ax=ax, label="median position RMS [mm]")
    held = [(r["point"][kx], r["point"][ky]) for r in rows if r["holds"]]
    if held:
        ax.plot(*zip(*held, strict=True), "o", mfc="none", mec="white", ms=5)
    ax.set_title(f"{fam} / {ctrl}" + ("".join(f", {k} = {v:g}" for k, v in rest.items())), fontsize=9)
    ax.set_xlabel(kx)
    ax.set_ylabel(ky)


def _edges(v: list[float]) -> np.ndarray:
    """Cell edges around sorted centres ``v`` (one cell of width 1 around a single value)."""
    a = np.asarray(v, dtype=float)
    if len(a) == 1:
        return np.array([a[0] - 0.5, a[0] + 0.5])
    mid = (a[1:] + a[:-1]) / 2
    return np.concatenate([[a[0] - (mid[0] - a[0])], mid, [a[-1] + (a[-1] - mid[-1])]])


TOP_MM = 3e3  # where a median of diverged runs is drawn (x) on the panels


def panels_plot(folders: list[Path]) -> bytes | None:
    """A PNG: one figure of small panels from several sweeps' robustness.json, one panel per scenario with
    one axis: the median position RMS after the change against the value per controller (a hollow
    marker where not every seed tracks, an x at the top where the median diverged), the bound dashed,
    the threshold (the tracking limit) dotted; one legend. None when no scenario has one axis."""
    found = []
    for folder in folders:
        data = read_robustness(folder / "robustness.json")  # edited by hand: a ConfigError naming the field
        for fam in dict.fromkeys(r["scenario"] for r in data["curves"]):
            rows = [r for r in data["curves"] if r["scenario"] == fam]
            if len(rows[0]["point"]) == 1:
                found.append((fam, next(iter(rows[0]["point"])), rows))
    if not found:
        return None
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ctrls = list(dict.fromkeys(r["controller"] for _, _, rows in found for r in rows))
    colors = {k: mpl(v) for k, v in controller_colors(ctrls).items()}
    cols = min(len(found), 4)
    nrows = math.ceil(len(found) / cols)
    fig, axs = plt.subplots(nrows, cols, figsize=(3.4 * cols, 2.9 * nrows + 0.6), squeeze=False, sharey=True,
                            layout="constrained")  # fmt: skip
    for ax, (fam, key, rows) in zip(axs.flat, found, strict=False):
        for ctrl in dict.fromkeys(r["controller"] for r in rows):
            rs = sorted((r for r in rows if r["controller"] == ctrl), key=lambda r: r["point"][key])
            x = np.array([r["point"][key] for r in rs], dtype=float)
            med = np.array([_finite(r["median_m"]) for r in rs]) * 1e3
            c = colors[ctrl]
            ax.plot(x, np.minimum(med, TOP_MM), "-", color=c, lw=1.2)
            whole = np.array([r["tracking"] == r["runs"] for r in rs])
            ax.plot(x[whole], med[whole], "o", color=c, ms=3.5)
            ax.plot(x[~whole], np.minimum(med[~whole], TOP_MM), "o", mfc="white", mec=c, ms=4)
            lost = np.isnan(med) | (med > TOP_MM)
            ax.plot(x[lost], np.full(lost.sum(), TOP_MM), "x", color=c, ms=5)
        one = sorted((r for r in rows if r["bound_m"] is not None), key=lambda r: r["point"][key])
        bx = list(dict.fromkeys(r["point"][key] for r in one))
        by = [1e3 * _finite(next(r["bound_m"] for r in one if r["point"][key] == v)) for v in bx]
        ax.plot(bx, by, "k--", lw=1.1)
        ax.axhline(1e3 * rows[0]["threshold_m"], color="0.3", ls=":", lw=1.2)
        ax.set_yscale("log")
        _xscale(ax, [r["point"][key] for r in rows])
        ax.set_title(f"{fam}\n{key}", fontsize=8.5)
        ax.tick_params(labelsize=7.5)
    for ax in axs[:, 0]:
        ax.set_ylabel("median position RMS\nafter the change [mm]", fontsize=8)
    for ax in list(axs.flat)[len(found) :]:
        ax.set_visible(False)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=colors[c], marker="o", ms=3.5, label=c) for c in ctrls] + [
        Line2D([], [], color="k", ls="--", label="bound (best law told the change)"),
        Line2D([], [], color="0.3", ls=":", label="tracking limit"),
        Line2D([], [], color="0.5", marker="o", mfc="white", ls="", label="not every seed tracks"),
        Line2D([], [], color="0.5", marker="x", ls="", label="median diverged"),
    ]
    ncol = min(len(handles), 5 if cols >= 3 else max(2, 2 * cols - 1))  # within the width: 3.4 in a panel
    fig.legend(handles=handles, loc="outside lower center", ncol=ncol, fontsize=7.5, frameon=False)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()


THRESHOLD_MAX = 1e4  # m: a median position RMS beyond 10 km (the largest reference) is no limit


def check_threshold(threshold: float | None, where: str = "--threshold") -> float | None:
    """The breaking points' limit on the median position RMS in metres (None: each run's tracking
    limit); a ConfigError naming ``where`` for one that is not a number, not positive, or absurd."""
    if threshold is None:
        return None
    if isinstance(threshold, bool) or not isinstance(threshold, int | float):
        raise ConfigError(where, f"expected a number of metres, got {threshold!r}")
    if not 0 < threshold <= THRESHOLD_MAX:
        raise ConfigError(where, f"must be a number of metres above 0 and at most {THRESHOLD_MAX:g}, got {threshold!r}")
    return float(threshold)


MIN_INTERVAL_RUNS = 6  # the fewest runs whose median has a 95 % interval (median_interval)
CURVE_FIELDS: dict[str, tuple[type, ...]] = {
    "scenario": (str,), "controller": (str,), "point": (dict,), "runs": (int,), "finished": (int,),
    "tracking": (int,), "tracking_share": (int, float, type(None)), "median_m": (int, float, type(None)),
    "ci_lo_m": (int, float, type(None)), "ci_hi_m": (int, float, type(None)), "threshold_m": (int, float),
    "bound_m": (int, float, type(None)), "holds": (bool,),
}  # fmt: skip
POINT_FIELDS: dict[str, tuple[type, ...]] = {
    "scenario": (str,), "controller": (str,), "axis": (str,), "at": (dict,), "nominal": (int, float, type(None)),
}  # fmt: skip
SIDE_FIELDS: dict[str, tuple[type, ...]] = {
    "holds_to": (int, float, type(None)), "fails_at": (int, float, type(None)), "whole_axis": (bool,),
}  # fmt: skip


TYPE_NAMES = {
    int: "a number",
    float: "a number",
    type(None): "null",
    str: "a text",
    dict: "a table",
    bool: "true or false",
}


def _typed(row, fields: dict[str, tuple[type, ...]], where: str) -> None:
    if not isinstance(row, dict):
        raise ConfigError(where, f"expected a table of {', '.join(fields)}, got {type(row).__name__}")
    for key, types in fields.items():
        if key not in row:
            raise ConfigError(f"{where}.{key}", "missing")
        v = row[key]
        if not isinstance(v, types) or (isinstance(v, bool) and bool not in types):
            names = " or ".join(dict.fromkeys(TYPE_NAMES.get(t, t.__name__) for t in types))
            raise ConfigError(f"{where}.{key}", f"expected {names}, got {v!r}")


def _numbers(table: dict, where: str) -> None:
    for k, v in table.items():
        if not isinstance(k, str) or isinstance(v, bool) or not isinstance(v, int | float):
            raise ConfigError(f"{where}.{k}", f"expected a number, got {v!r}")


def read_robustness(path: Path) -> dict:
    """robustness.json as :func:`mlpfac.sweeps.robustness.write_robustness` wrote it, every field it holds checked (a ConfigError
    naming the file and the field), the medians and intervals of diverged runs infinite again: null
    where runs finished (an earlier file's ``Infinity`` reads too). A null bound is no finite bound."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise ConfigError(str(path), f"cannot read it as JSON ({getattr(err, 'strerror', None) or err})") from None
    if not isinstance(data, dict) or not isinstance(data.get("curves"), list):
        raise ConfigError(f"{path} curves", "expected the list of rows a sweep writes")
    if not isinstance(data.get("breaking_points", []), list) or not isinstance(data.get("meta", {}), dict):
        raise ConfigError(str(path), "expected breaking_points (a list) and meta (a table) as a sweep writes them")
    check_threshold(data.get("meta", {}).get("threshold_m"), f"{path} meta.threshold_m")  # a number or null
    for i, r in enumerate(data["curves"]):
        where = f"{path} curves[{i}]"
        _typed(r, CURVE_FIELDS, where)
        check_threshold(r["threshold_m"], f"{where}.threshold_m")  # drawn on a log scale
        _numbers(r["point"], f"{where}.point")
        if not isinstance(r.get("set", {}), dict):
            raise ConfigError(f"{where}.set", f"expected a table of settings, got {r['set']!r}")
        _numbers(r.get("set", {}), f"{where}.set")
        if r["finished"]:
            r["median_m"] = math.inf if r["median_m"] is None else r["median_m"]
        if r["finished"] >= MIN_INTERVAL_RUNS:
            r["ci_lo_m"] = math.inf if r["ci_lo_m"] is None else r["ci_lo_m"]
            r["ci_hi_m"] = math.inf if r["ci_hi_m"] is None else r["ci_hi_m"]
    for i, b in enumerate(data.get("breaking_points", [])):
        where = f"{path} breaking_points[{i}]"
        _typed(b, POINT_FIELDS, where)
        _numbers(b["at"], f"{where}.at")
        for side in ("below", "above"):  # (mlpfac.sweeps.robustness.SIDES)
            if side in b:
                _typed(b[side], SIDE_FIELDS, f"{where}.{side}")
    return data
