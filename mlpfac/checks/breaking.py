"""Budgets on where a controller breaks: a ``[[budget]]`` with ``holds_up_to`` / ``holds_down_to``
on a budget that has ``vary`` axes (``vary = ["events.0.scale=1.0:2.0:11"]``).

``holds_up_to = 1.4`` holds when the breaking point above the nominal value
(:mod:`mlpfac.sweeps.robustness`) is at 1.4 or beyond: every grid value from the nominal one to
1.4 holds (every seed tracks, the median position RMS after the change within ``threshold_m``,
default the tracking limit); ``holds_down_to`` the same below it. With other axes, the breaking
point must hold at each of their values: the case's value is the nearest one. One case per
budget, scenario and controller, over every grid point; its misses, JUnit and summary are those
of the other figures.
"""

from __future__ import annotations

import dataclasses
import math

from mlpfac.checks.judge import Case, Verdict
from mlpfac.checks.limits import AFTER_THE_CHANGE, FIGURES, Group, Limit
from mlpfac.exceptions import ConfigError
from mlpfac.loop.metrics import RunMetrics
from mlpfac.sweeps.robustness import NO_AXIS, breaking_points, check_threshold, curves, nominal
from mlpfac.sweeps.vary import Vary, parse_vary

SIDE = {"holds_up_to": "above", "holds_down_to": "below"}


def read_vary(table: dict, path, flags: Vary | None = None) -> tuple[Vary, float | None]:
    """The budget's ``vary`` axes (as ``--vary``) with those of the ``--vary`` flags, and ``threshold_m``, checked."""
    raw = table.get("vary")
    vary = Vary()
    if raw is not None:
        if not (isinstance(raw, list) and raw and all(isinstance(x, str) for x in raw)):
            raise ConfigError(f"{path} vary", f'expected a list like ["events.0.scale=1.0:2.0:11"], got {raw!r}')
        try:
            vary = parse_vary(raw)
        except ConfigError as err:
            raise ConfigError(f"{path} vary", str(err)) from None
    if flags:
        given = {a.key for a in vary.axes} | set(vary.draws)
        again = next((k for k in [a.key for a in flags.axes] + list(flags.draws) if k in given), None)
        if again is not None:
            raise ConfigError(f"--vary {again}", f"the budget {path} varies it already")
        vary = Vary(vary.axes + flags.axes, vary.draws | flags.draws)
    threshold = check_threshold(table.get("threshold_m"), f"{path} threshold_m")
    if threshold is not None and not vary.axes:
        raise ConfigError(f"{path} threshold_m", NO_AXIS)
    return vary, threshold


def breaking_limit(b: dict, limit: Limit, where: str) -> Limit:
    """A ``[[budget]]`` with ``holds_up_to`` / ``holds_down_to`` (and only those figures)."""
    if "phase" in b:
        raise ConfigError(
            f"{where} phase", "a breaking point is judged after the change (the last phase): leave it out"
        )
    figures = {}
    for key in SIDE:
        if key in b:
            v = b[key]
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ConfigError(f"{where} {key}", f"expected a value of the axis, got {v!r}")
            figures[key] = v
    if not figures:
        raise ConfigError(f"{where} axis", "names the axis of holds_up_to / holds_down_to: give one of them")
    other = next((k for k in b if k in FIGURES and not FIGURES[k].axis), None)
    if other is not None:
        raise ConfigError(f"{where} {other}", "a [[budget]] on a breaking point limits nothing else: give it its own")
    axis = b.get("axis")
    if axis is not None and not (isinstance(axis, str) and axis):
        raise ConfigError(f"{where} axis", f"expected a key of vary, got {axis!r}")
    return dataclasses.replace(limit, phase=AFTER_THE_CHANGE, figures=figures, axis=axis)


def check_axis(limit: Limit, vary: Vary, where: str) -> None:
    """The limit's axis is one of ``vary`` of more than one value (the only one when it names none; an
    axis of one value is a setting, :mod:`mlpfac.sweeps.robustness`) and reaches its values."""
    keys = [a.key for a in vary.axes if len(a.values) > 1]
    if limit.axis is None and len(keys) != 1:
        raise ConfigError(f"{where} axis", f"name the axis of the breaking point: one of {', '.join(keys) or '(none)'}")
    if limit.axis is not None and limit.axis not in keys:
        raise ConfigError(
            f"{where} axis",
            f"{limit.axis!r} is not an axis of vary of more than one value ({', '.join(keys) or 'none'})",
        )
    limit.axis = limit.axis or keys[0]
    values = next(a.values for a in vary.axes if a.key == limit.axis)
    for fig, lim in limit.figures.items():
        if not (max(values) >= lim if SIDE[fig] == "above" else min(values) <= lim):
            raise ConfigError(
                f"{where} {fig}",
                f"{lim:g} is beyond {limit.axis} = {min(values):g} to {max(values):g}: no grid point reaches it",
            )


def judge_breaking(
    limit: Limit, groups: list[Group], metrics: dict[tuple, RunMetrics], threshold: float | None
) -> list[Case]:
    """One case per scenario and controller of the grid groups ``limit`` matches."""
    families: dict[tuple[str, str], Group] = {}
    for g in groups:
        if limit.matches(g):
            f = families.setdefault(
                (g.family, g.controller), Group(g.family, g.controller, g.source, g.spec, family=g.family)
            )
            f.jobs += g.jobs
    cases = []
    for (fam, _), g in families.items():
        axis = limit.axis
        ran = next((j for j in g.jobs if j.key in metrics), g.jobs[0])  # a run that finished tells a friction's own
        found = [
            p
            for p in breaking_points(
                curves(g.jobs, metrics, threshold), {(fam, axis): nominal(ran, axis, metrics.get(ran.key))}
            )
            if p["axis"] == axis
        ]
        case = Case(limit, g, errors=sorted({j.seed for j in g.jobs if j.key not in metrics}))
        case.time_s = math.fsum(metrics[j.key].wall_time_s for j in g.jobs if j.key in metrics)
        for fig, lim in limit.figures.items():
            case.verdicts.append(_verdict(fig, lim, found))
        cases.append(case)
    return cases


def _verdict(fig: str, lim: float, found: list[dict]) -> Verdict:
    side = SIDE[fig]
    sides = [(p, p.get(side)) for p in found]
    if not sides or any(b is None for _, b in sides):
        return Verdict(
            fig,
            lim,
            None,
            False,
            None,
            note=f"no grid value {side} the nominal {found[0]['nominal']:g}" if found else "no run",
        )
    far = 1 if side == "above" else -1
    worst_p, worst = min(sides, key=lambda pb: -math.inf if pb[1]["holds_to"] is None else far * pb[1]["holds_to"])
    at = ", ".join(f"{k} = {v:g}" for k, v in worst_p["at"].items())
    where = f" at {at}" if at else ""
    if worst["holds_to"] is None:
        return Verdict(fig, lim, None, False, None, note=f"fails at {worst['fails_at']:g} already{where}")
    value = worst["holds_to"]
    note = "holds along the whole axis" if worst["whole_axis"] else f"fails at {worst['fails_at']:g}{where}"
    return Verdict(fig, lim, value, value * far >= lim * far, None, note=note)
