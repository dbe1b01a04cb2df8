"""The bound beside an adaptive result: per seed, the least position RMS of the laws that learn
nothing (by default the oracle, ``oracle-kanayama``, ``oracle-dynamic``, Corradini's and Kanayama's
law), and each variant against it. A law with no run on a scenario (``oracle-dynamic`` on a robot
driven by velocity servos, which a torque-level law cannot drive) is left out of that scenario's
bound, and its row says so (``without``).

Reads one or more sweep folders (``SCENARIO/CONTROLLER/seed-NNNN/metrics.json``; a later folder's
run replaces an earlier one's) and writes, per scenario, over the seeds that every bound law and
every variant ran:

- **bound [mm] (law)**: the median over seeds of the per-seed minimum, and the law that gives the
  minimum on most seeds;
- per variant, **median [mm] (x bound)**: its median RMS and the median over seeds of its RMS / the
  per-seed bound, with the worst seed's ratio; **tracking**: runs tracking / runs;
  **p worse than corradini**: the one-sided Wilcoxon signed-rank test (scipy) that the variant's
  RMS is larger than Corradini's on the same seed (a diverged run is worse than any finished one),
  wherever Corradini's law ran on every seed, one of the ``--laws`` or not.

The figure is the one of :mod:`mlpfac.sweeps.paired`: the last phase's position RMS ("after" the
first event; after the warm-up on a run without one).

    python -m mlpfac.sweeps.bound DIR [DIR ...] --variants adaptive-real,adaptive-best [--out FILE.md]
"""

from __future__ import annotations

import argparse
import json
import math
from collections import Counter
from pathlib import Path

from mlpfac.loop.metrics import RunMetrics
from mlpfac.sweeps.paired import compared_rms, median

BOUND_LAWS = ("oracle", "oracle-kanayama", "oracle-dynamic", "corradini", "kanayama")


def load(folders: list[Path]) -> dict[tuple[str, str, int], RunMetrics]:
    """(scenario, controller, seed) -> the run's metrics, from the sweep folders in order."""
    metrics: dict[tuple[str, str, int], RunMetrics] = {}
    for folder in folders:
        for path in sorted(Path(folder).glob("*/*/seed-*/metrics.json")):
            m = RunMetrics.read(path)
            metrics[(m.scenario, m.controller, m.seed)] = m
    return metrics


def p_worse(x: list[float], y: list[float]) -> float | None:
    """One-sided Wilcoxon signed-rank p that x is larger than y, paired (inf: larger than any number);
    None when every pair is equal."""
    finite = [abs(v) for v in (*x, *y) if math.isfinite(v)]
    big = 2.0 * max(finite, default=0.0) + 1.0
    d = [(a if math.isfinite(a) else big) - (b if math.isfinite(b) else big) for a, b in zip(x, y, strict=True)]
    d = [v for v in d if v != 0.0]
    if not d:
        return None
    from scipy.stats import wilcoxon

    return float(wilcoxon(d, alternative="greater").pvalue)


def bound_rows(
    metrics: dict[tuple[str, str, int], RunMetrics], variants: list[str], laws: tuple[str, ...] = BOUND_LAWS
) -> list[dict]:
    """One row per scenario (in the order first met) with the bound and each variant against it."""
    scenarios = list(dict.fromkeys(s for s, _, _ in metrics))
    rows = []
    for scn in scenarios:
        ran = {c for s, c, _ in metrics if s == scn}
        without = [n for n in laws if n not in ran]
        laws_here = tuple(n for n in laws if n in ran)
        if not laws_here:
            continue
        needed = (*laws_here, *variants)
        seeds = sorted(set.intersection(*({k for s, c, k in metrics if s == scn and c == n} for n in needed)))
        if not seeds:
            continue
        per_law = {n: [compared_rms(metrics[(scn, n, k)]) for k in seeds] for n in laws_here}
        bound = [min(per_law[n][i] for n in laws_here) for i in range(len(seeds))]
        which = Counter(min(laws_here, key=lambda n: per_law[n][i]) for i in range(len(seeds))).most_common(1)[0][0]
        row = {"scenario": scn, "seeds": seeds, "bound_m": median(bound), "bound_law": which, "variants": {}}
        row["without"] = without
        corradini = [metrics.get((scn, "corradini", k)) for k in seeds]  # a law of the bound or not
        versus = [compared_rms(m) for m in corradini] if all(corradini) else None
        for name in variants:
            runs = [metrics[(scn, name, k)] for k in seeds]
            x = [compared_rms(m) for m in runs]
            ratios = [a / b for a, b in zip(x, bound, strict=True)]
            row["variants"][name] = {
                "median_m": median(x),
                "ratio": median(ratios),
                "worst_ratio": max(ratios),
                "tracking": sum(m.outcome == "tracking" for m in runs),
                "runs": len(runs),
                "p_worse_than_corradini": None if versus is None else p_worse(x, versus),
            }
        rows.append(row)
    return rows


def _mm(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{1e3 * x:.2f}"


def _ratio(x: float) -> str:
    return "inf" if not math.isfinite(x) else f"{x:.2g}x" if x < 10 else f"{x:.0f}x"


def markdown(rows: list[dict], variants: list[str]) -> str:
    """The table: bound [mm] (law), then per variant its median [mm] (median x bound, worst seed's),
    tracking runs and the one-sided p that it is worse than Corradini's law."""
    head = ["scenario", "seeds", "bound [mm] (law)"]
    for name in variants:
        head += [f"`{name}` [mm] (x bound; worst seed)", "tracking", "p worse than corradini"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for r in rows:
        s = r["seeds"]
        cells = [r["scenario"], f"{s[0]}-{s[-1]}" if s == list(range(s[0], s[-1] + 1)) else ",".join(map(str, s))]
        cells.append(
            f"{_mm(r['bound_m'])} ({r['bound_law']})" + (f"; without {', '.join(r['without'])}" if r["without"] else "")
        )
        for name in variants:
            v = r["variants"][name]
            p = v["p_worse_than_corradini"]
            cells += [
                f"{_mm(v['median_m'])} ({_ratio(v['ratio'])}; {_ratio(v['worst_ratio'])})",
                f"{v['tracking']} / {v['runs']}",
                "-" if p is None else f"{p:.2g}",
            ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def window_rows(metrics: dict[tuple[str, str, int], RunMetrics], names: list[str], seconds: float) -> list[dict]:
    """Per scenario with an event and per controller of ``names``: the median over seeds of the
    position RMS in the ``seconds`` after the first event and from then to the end (0.1 s bins)."""
    rows = []
    for scn in dict.fromkeys(s for s, _, _ in metrics):
        row: dict = {"scenario": scn, "windows": {}}
        for name in names:
            runs = [m for (s, c, _), m in sorted(metrics.items()) if s == scn and c == name and m.events]
            if runs:
                t = runs[0].events[0]["time"]
                first = [m.window_rms(t, t + seconds) for m in runs]
                then = [m.window_rms(t + seconds, m.steps * m.T) for m in runs]
                row["windows"][name] = tuple(median([x for x in xs if x is not None]) for xs in (first, then))
        if row["windows"]:
            rows.append(row)
    return rows


def windows_markdown(rows: list[dict], names: list[str], seconds: float) -> str:
    head = ["scenario"] + [f"`{n}` {w} [mm]" for n in names for w in (f"first {seconds:g} s", "then")]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for r in rows:
        cells = [r["scenario"]]
        for n in names:
            cells += [_mm(x) for x in r["windows"].get(n, (None, None))]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m mlpfac.sweeps.bound", description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="+", type=Path, help="sweep folders; a later one's run replaces an earlier's")
    ap.add_argument("--variants", required=True, help="comma-separated controllers to set against the bound")
    ap.add_argument(
        "--windows",
        type=float,
        metavar="SECONDS",
        help="instead: the median RMS of the variants and the laws in the SECONDS after the event, and after them",
    )
    ap.add_argument("--laws", default=",".join(BOUND_LAWS), help="the laws of the bound (default: %(default)s)")
    ap.add_argument("--out", type=Path, help="write the Markdown table (and FILE.json) here; default: print")
    a = ap.parse_args(argv)
    variants = [v for v in a.variants.split(",") if v]
    laws = tuple(n for n in a.laws.split(",") if n)
    if a.windows is not None:
        names = [*variants, *laws]
        rows = window_rows(load(a.folders), names, a.windows)
        text = windows_markdown(rows, names, a.windows)
    else:
        rows = bound_rows(load(a.folders), variants, laws)
        text = markdown(rows, variants)
    if a.out is None:
        print(text, end="")
        return
    a.out.write_text(text)
    a.out.with_suffix(".json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
