"""Judging run groups against the budget's limits: each figure over the group's runs in one phase,
and, with a baseline, per seed against the baseline's run of the same scenario, controller and seed.

Position and heading figures are over the runs that finished (tracking or lost), as in
``mlpfac sweep``'s table; a group where no run finished has no such figure, which is a miss.
``lost`` and ``diverged`` count runs. Against the baseline, a run that diverged is worse than any
that finished (its position RMS counts as infinite); seeds the baseline lacks are named and left
out, never guessed.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.checks.limits import FIGURES, Group, Limit
from mlpfac.exceptions import ConfigError
from mlpfac.loop.metrics import RunMetrics
from mlpfac.sweeps.folders import metrics_problem
from mlpfac.sweeps.paired import compare, median

Runs = dict[int, RunMetrics]  # seed -> metrics.json
Value = tuple[float | None, int | None, str]  # (value, worst seed, note)


@dataclass
class Verdict:
    figure: str
    limit: float
    value: float | None
    passed: bool
    worst_seed: int | None
    baseline: float | None = None  # the same figure over the baseline's runs of the same seeds
    note: str = ""


@dataclass
class Case:
    """One limit applied to one run group: a test case of the report."""

    limit: Limit
    group: Group
    verdicts: list[Verdict] = field(default_factory=list)
    time_s: float = 0.0  # wall time of the group's runs
    missing: list[int] = field(default_factory=list)  # seeds the baseline lacks
    errors: list[int] = field(default_factory=list)  # seeds whose run raised (no metrics)

    @property
    def passed(self) -> bool:
        return not self.errors and all(v.passed for v in self.verdicts)

    @property
    def misses(self) -> list[Verdict]:
        return [v for v in self.verdicts if not v.passed]


def _values(runs: Runs, phase: str, i: int) -> dict[int, float]:
    out = {}
    for seed, m in runs.items():
        f = m.figures(phase) if m.status == "ok" else None
        if f is not None and f[i] is not None:
            out[seed] = f[i]
    return out


def _largest(values: dict[int, float]) -> int | None:
    return max(values, key=lambda s: (values[s], -s)) if values else None


def _statistic(how: Callable[[list[float]], float | None], i: int, scale: float):
    def figure(runs: Runs, phase: str, base: Runs | None) -> Value:
        vals = _values(runs, phase, i)
        if not vals:
            return None, _diverged(runs, phase, base)[1], "no run finished"
        return how(list(vals.values())) * scale, _largest(vals), ""

    return figure


def _mean(xs: list[float]) -> float:
    return math.fsum(xs) / len(xs)


def _lost(runs: Runs, phase: str, base: Runs | None) -> Value:
    rms = _values(runs, phase, 0)
    lost = {s: rms.get(s, 0.0) for s, m in runs.items() if m.outcome == "lost"}
    return len(lost), _largest(lost), ""


def _diverged(runs: Runs, phase: str, base: Runs | None) -> Value:
    bad = sorted((m.steps, s) for s, m in runs.items() if m.status != "ok")
    return len(bad), (bad[0][1] if bad else None), ""  # the first to diverge


def _ratios(runs: Runs, phase: str, base: Runs) -> dict[int, float]:
    out = {}
    for seed in sorted(set(runs) & set(base)):
        x, y = runs[seed].rms(phase), base[seed].rms(phase)
        if x is None or y is None:
            continue
        out[seed] = 1.0 if x == y else math.inf if y == 0 else 0.0 if math.isinf(y) else x / y
    return out


def _no_worse(runs: Runs, phase: str, base: Runs | None) -> Value:
    ratios = _ratios(runs, phase, base or {})
    if not ratios:
        return None, None, "no seed pairs with the baseline"
    return median(list(ratios.values())), _largest(ratios), f"{len(ratios)} seeds paired"


def _p(runs: Runs, phase: str, base: Runs | None) -> Value:
    base = base or {}
    seeds = [s for s in sorted(set(runs) & set(base)) if None not in (runs[s].rms(phase), base[s].rms(phase))]
    if not seeds:
        return None, None, "no seed pairs with the baseline"
    x = [runs[s].rms(phase) for s in seeds]
    y = [base[s].rms(phase) for s in seeds]
    _, n, p = compare(x, y, alternative="greater")
    return (1.0 if p is None else p), _largest(_ratios(runs, phase, base)), f"{n} seeds paired"


FIGURE_VALUES: dict[str, Callable[[Runs, str, Runs | None], Value]] = {
    "median_position_rms_mm": _statistic(median, 0, 1e3),
    "mean_position_rms_mm": _statistic(_mean, 0, 1e3),
    "max_position_rms_mm": _statistic(max, 0, 1e3),
    "max_error_mm": _statistic(max, 1, 1e3),
    "median_heading_rms_mrad": _statistic(median, 2, 1e3),
    "mean_heading_rms_mrad": _statistic(_mean, 2, 1e3),
    "max_heading_rms_mrad": _statistic(max, 2, 1e3),
    "lost": _lost,
    "diverged": _diverged,
    "no_worse_than_baseline": _no_worse,
    "p": _p,
}
assert set(FIGURE_VALUES) == {k for k, f in FIGURES.items() if not f.axis}  # breaking points: mlpfac.checks.breaking


def judge(limit: Limit, group: Group, metrics: dict[tuple, RunMetrics], base: Runs | None) -> Case:
    """The verdicts of ``limit`` on ``group``'s runs (``metrics`` by job key); ``base``: the
    baseline's runs of the group by seed, or None without a baseline."""
    runs = {j.seed: metrics[j.key] for j in group.jobs if j.key in metrics}
    case = Case(limit, group, errors=[j.seed for j in group.jobs if j.key not in metrics])
    case.time_s = math.fsum(m.wall_time_s for m in runs.values())
    paired = None
    if base is not None:
        case.missing = [s for s in runs if s not in base]
        paired = {s: base[s] for s in runs if s in base}
    for key, lim in limit.figures.items():
        fig = FIGURES[key]
        value, worst, note = FIGURE_VALUES[key](runs, limit.phase, base)
        passed = value is not None and (value >= lim if fig.at_least else value <= lim)
        n = len(_ratios(runs, limit.phase, base or {}))
        if key == "p" and n and 0.5**n >= lim:  # the exact test's smallest p with n pairs is 2**-n
            note += f"; with {n} pairs p cannot fall below {0.5**n:.3g}, so this limit cannot fail: add seeds"
        ref = None
        if paired and not fig.baseline:
            ref = FIGURE_VALUES[key](paired, limit.phase, None)[0]
        case.verdicts.append(Verdict(key, lim, value, passed, worst, ref, note))
    return case


def baseline_folder(text: str | Path) -> Path:
    """The sweep folder ``--baseline`` names (the folder, or its sweep.json); ConfigError naming the
    flag when it is neither or holds no finished run."""
    p = Path(text)
    where = f"--baseline {p}"
    if not p.exists():
        raise ConfigError(where, "not found; give a sweep folder or its sweep.json")
    if p.is_file():
        if p.suffix != ".json":
            raise ConfigError(where, "expected a sweep folder or its sweep.json")
        p = p.parent
    found = sorted(p.glob("*/*/seed-*/metrics.json"))
    if not found:
        raise ConfigError(where, "holds no finished runs (<scenario>/<controller>/seed-*/metrics.json)")
    for path in found:  # a figure no run writes is found before anything runs
        try:
            json.loads(path.read_text(), parse_constant=lambda name, path=path: _not_finite(name, path))
        except ConfigError:
            raise
        except (OSError, ValueError, RecursionError):
            continue  # not a whole run: left out as missing, as before
    return p


def baseline_runs(folder: Path, group: Group) -> Runs:
    """The baseline's whole runs of ``group``'s scenario, controller and seeds, by seed (a folder
    without a valid metrics.json of that run is missing)."""
    out = {}
    for j in group.jobs:
        path = j.folder(folder) / "metrics.json"
        try:
            m = json.loads(path.read_text(), parse_constant=lambda name, path=path: _not_finite(name, path))
        except (OSError, ValueError) as err:
            if isinstance(err, ConfigError):
                raise
            continue
        if metrics_problem(m, j) is None:
            out[j.seed] = RunMetrics.from_json(m)
    return out


def _not_finite(name: str, path: Path) -> float:
    """A baseline's figure that no run writes (NaN, Infinity: a run writes null): a bad baseline, not a miss."""
    raise ConfigError(f"--baseline {path}", f"holds {name}, which no run writes (a figure that is not finite is null)")
