"""The ``limit`` view of a results table: every controller against the physical limit, seed by seed.

Per scenario, from the runs' figures a dataset keeps (``runs.json``; the compared figure of
:mod:`mlpfac.sweeps.paired`, the position RMS after the event, a diverged run infinite):

- **limit [mm]**: the median over seeds of ``limit``'s (the run's own robot as the model, the true
  state: :mod:`mlpfac.control.mpc`);
- **mpc [mm] (x limit)**: ``mpc``'s, the same planner given the measured pose: what the information
  costs;
- **bound [mm] (law; x limit)**: the bound the other pages set every result against, per seed the
  least of the laws of :data:`mlpfac.sweeps.bound.BOUND_LAWS` that ran (the laws told the change and
  the two told nothing), with the law that gives it on most seeds: how far it is from the achievable;
- per controller asked for, its median [mm] and median ratio to the limit on the same seed, with the
  seeds it did not track (t/n).
"""

from __future__ import annotations

import math
from collections import Counter

from mlpfac.sweeps.bound import BOUND_LAWS
from mlpfac.sweeps.paired import figure, median

LIMIT, MPC = "limit", "mpc"


def _mm(x: float | None) -> str:
    return "-" if x is None else "inf" if not math.isfinite(x) else f"{x * 1e3:.3g}"


def _x(x: float | None) -> str:
    return "-" if x is None else "inf" if not math.isfinite(x) else f"{x:.2g}x" if x < 10 else f"{x:.0f}x"


def _ratio(a: float, b: float) -> float:
    return a / b if math.isfinite(a) else math.inf


def limit_table(runs: list[dict], scenarios: list[str], controllers: list[str]) -> str:
    """The Markdown table of the module's docstring, one row per scenario (in ``scenarios``' order)."""
    fig: dict[str, dict[str, dict[int, float]]] = {}
    tracked: dict[tuple[str, str, int], bool] = {}
    for r in runs:
        fig.setdefault(r["scenario"], {}).setdefault(r["controller"], {})[r["seed"]] = figure(r)
        tracked[(r["scenario"], r["controller"], r["seed"])] = r.get("outcome") == "tracking"
    head = ["scenario", "limit [mm]", "`mpc` [mm] (x limit)", "bound [mm] (law; x limit)"]
    head += [f"`{c}` [mm] (x limit)" for c in controllers]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for scn in scenarios:
        by = fig.get(scn, {})
        limit = by.get(LIMIT, {})
        seeds = sorted(s for s in limit if math.isfinite(limit[s]) and limit[s] > 0)
        cells = [scn, _mm(median([limit[s] for s in limit]) if limit else None)]

        def against(ctrl: str, by=by, limit=limit, seeds=seeds, scn=scn) -> str:
            xs = by.get(ctrl, {})
            here = [s for s in seeds if s in xs]
            if not here:
                return "-"
            ratio = median([_ratio(xs[s], limit[s]) for s in here])
            lost = sum(not tracked[(scn, ctrl, s)] for s in xs)
            text = f"{_mm(median(list(xs.values())))} ({_x(ratio)})"
            return text + (f" {len(xs) - lost}/{len(xs)}" if lost else "")

        cells.append(against(MPC))
        laws = [n for n in BOUND_LAWS if n in by and all(s in by[n] for s in seeds)]
        if laws and seeds:
            bound = {s: min(by[n][s] for n in laws) for s in seeds}
            which = Counter(min(laws, key=lambda n, s=s: by[n][s]) for s in seeds).most_common(1)[0][0]
            ratio = median([_ratio(bound[s], limit[s]) for s in seeds])
            cells.append(f"{_mm(median(list(bound.values())))} ({which}; {_x(ratio)})")
        else:
            cells.append("-")
        cells += [against(c) for c in controllers]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
