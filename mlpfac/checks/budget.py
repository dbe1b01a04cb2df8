"""A budget file: what to run (scenarios, controllers, seeds, duration) and the limits each run
group must keep (``[[budget]]`` tables). Every mistake is a ConfigError naming the file and key,
found before anything runs."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.checks.limits import FIGURES, PHASE_NAMES, Group, Limit
from mlpfac.exceptions import ConfigError
from mlpfac.scenario.on_robot import robots_named, split_robot, with_robots
from mlpfac.sweeps.plan import MAX_RUNS, Job, parse_controllers, parse_seeds, plan
from mlpfac.sweeps.vary import Vary

TOP_KEYS = (
    "scenarios", "robots", "controllers", "seeds", "duration", "vary", "threshold_m", "lost_threshold_m", "budget",
)  # fmt: skip
FILTER_KEYS = ("name", "scenario", "controller", "phase", "axis")


@dataclass
class Budget:
    path: Path
    scenarios: list[str]  # as given to plan: names, or absolute paths
    controllers: list[str | None]
    seeds: list[int]
    seeds_text: str
    duration: float | None
    limits: list[Limit]
    vary: Vary = field(default_factory=Vary)
    threshold: float | None = None
    robots_by: str = "--robot"  # the flag or key of its robots, which their errors name
    lost_threshold: float | None = None  # every run's lost_threshold_m (lost_threshold_m, --lost-threshold)

    def needs_baseline(self) -> Limit | None:
        return next((b for b in self.limits if any(FIGURES[f].baseline for f in b.figures)), None)

    def plan(self) -> tuple[list[Job], list[Group]]:
        """The runs (ConfigError naming this file's ``scenarios`` key for a scenario that cannot
        load) and their groups; each limit's filters must match a group, and "after" needs an event."""
        try:
            with robots_named(self.robots_by):
                jobs = plan(self.scenarios, self.controllers, self.seeds, self.duration, self.vary, self.lost_threshold)
        except ConfigError as err:
            if err.where.startswith(self.robots_by):  # a robot's, named already
                raise
            raise ConfigError(
                f"{self.path} {'vary' if err.where.startswith('--vary') else 'scenarios'}", str(err)
            ) from None
        groups: dict[tuple[str, str], Group] = {}
        sources = dict(zip(dict.fromkeys(j.family for j in jobs), self.scenarios, strict=True))
        for i, j in enumerate(jobs):  # each scenario and grid point: every controller in order, each with every seed
            spec = self.controllers[(i // len(self.seeds)) % len(self.controllers)]
            group = Group(j.scenario, j.controller, sources[j.family], spec, family=j.family)
            groups.setdefault((j.scenario, j.controller), group).jobs.append(j)
        names = {
            "scenario": {n for g in groups.values() for n in (g.scenario, g.source, split_robot(g.source)[0])},
            "controller": {n for g in groups.values() for n in (g.controller, g.spec)},
        }
        for b in self.limits:
            if b.breaking:
                from mlpfac.checks.breaking import check_axis

                check_axis(b, self.vary, f"{self.path} {b.where}")
            for key, known_names in names.items():
                value = getattr(b, key)
                if value is not None and value not in known_names:
                    known = ", ".join(dict.fromkeys(getattr(g, key) for g in groups.values()))
                    raise ConfigError(
                        f"{self.path} {b.where} {key}", f"{value!r} matches no {key} of this budget ({known})"
                    )
            matched = [g for g in groups.values() if b.matches(g)]
            if not matched:
                raise ConfigError(f"{self.path} {b.where}", "its scenario and controller match no run group together")
            if b.phase == "after" and not any(g.has_event for g in matched):
                raise ConfigError(
                    f"{self.path} {b.where} phase", "'after' needs a scenario with an event; these have none"
                )
        return jobs, list(groups.values())


def read_budget(
    path: Path, robot: str | None = None, flags: Vary | None = None, lost_threshold: float | None = None
) -> Budget:
    """The budget file at ``path``, checked; scenario paths and ``file.py:Class`` controllers are
    taken from the file's own folder. ``lost_threshold`` (``--lost-threshold``) over the file's
    ``lost_threshold_m``."""
    from mlpfac.scenario.parse import lost_threshold_m
    from mlpfac.tables import read_toml

    table = read_toml(path, "budget file")
    _known(table, TOP_KEYS, str(path))
    here = path.absolute().parent
    scenarios = _strings(table, "scenarios", path, required=True)
    scenarios = [str(here / s) if s.endswith(".toml") and not Path(s).is_absolute() else s for s in scenarios]
    given = _strings(table, "robots", path, required=False)
    robots = [robot] if robot is not None else [_near_robot(r, here) for r in given] if given else None
    robots_by = "--robot" if robot is not None else f"{path} robots"  # what names a robot's errors
    with robots_named(robots_by):  # every scenario on each robot, as SCENARIO@ROBOT (mlpfac.scenario.on_robot)
        scenarios = with_robots(scenarios, robots)
    specs = _strings(table, "controllers", path, required=False)
    controllers: list[str | None] = [None]
    if specs is not None:
        try:
            controllers = parse_controllers(",".join(_near(s, here) for s in specs))
        except ConfigError as err:
            raise ConfigError(f"{path} controllers", err.what) from None
    seeds_text = _seeds_text(table.get("seeds", "0"), path)
    try:
        seeds = parse_seeds(seeds_text)
    except ConfigError as err:
        raise ConfigError(f"{path} seeds", err.what) from None
    duration = table.get("duration")
    if duration is not None and not (_is_number(duration) and math.isfinite(duration) and duration > 0):
        raise ConfigError(f"{path} duration", f"expected a positive number of seconds, got {duration!r}")
    if lost_threshold is not None:
        lost_threshold = lost_threshold_m(lost_threshold, "--lost-threshold")
    elif table.get("lost_threshold_m") is not None:
        lost_threshold = lost_threshold_m(table["lost_threshold_m"], f"{path} lost_threshold_m")
    n = len(dict.fromkeys(scenarios)) * len(controllers) * len(seeds)
    if n > MAX_RUNS:
        raise ConfigError(f"{path} seeds", f"{n} runs is more than the limit of {MAX_RUNS}; split the budget")
    raw = table.get("budget")
    if not isinstance(raw, list) or not raw or not all(isinstance(b, dict) for b in raw):
        raise ConfigError(f"{path} budget", "expected one or more [[budget]] tables")
    limits = [_limit(b, i + 1, path, here) for i, b in enumerate(raw)]
    from mlpfac.checks.breaking import read_vary

    vary, threshold = read_vary(table, path, flags)
    if any(b.breaking for b in limits) and not vary.axes:
        raise ConfigError(f"{path} vary", 'holds_up_to / holds_down_to need an axis: vary = ["KEY=VALUES"]')
    n *= vary.size
    if n > MAX_RUNS:
        raise ConfigError(f"{path} vary", f"{n} runs is more than the limit of {MAX_RUNS}; split the budget")
    return Budget(
        path, list(dict.fromkeys(scenarios)), controllers, seeds, seeds_text, duration, limits, vary, threshold,
        robots_by, lost_threshold,
    )  # fmt: skip


def _limit(b: dict, index: int, path: Path, here: Path) -> Limit:
    where = f"{path} budget #{index}"
    _known(b, (*FILTER_KEYS, *FIGURES), where)
    for key in FILTER_KEYS:
        if key in b and not (isinstance(b[key], str) and b[key]):
            raise ConfigError(f"{where} {key}", f"expected a non-empty string, got {b[key]!r}")
    phase = b.get("phase", "whole")
    if phase not in PHASE_NAMES:
        raise ConfigError(f"{where} phase", f"expected one of {', '.join(PHASE_NAMES)}, got {phase!r}")
    scenario, controller = b.get("scenario"), b.get("controller")
    if scenario is not None and scenario.endswith(".toml") and not Path(scenario).is_absolute():
        scenario = str(here / scenario)
    controller = controller and _near(controller, here)
    if any(k in FIGURES and FIGURES[k].axis for k in b) or "axis" in b:
        from mlpfac.checks.breaking import breaking_limit

        return breaking_limit(b, Limit(index, b.get("name"), scenario, controller, phase, {}), where)
    figures = {}
    for key, fig in FIGURES.items():
        if key not in b:
            continue
        v = b[key]
        ok = _is_number(v) and math.isfinite(v) and v >= 0
        if fig.count:
            ok = ok and isinstance(v, int)
        elif key == "p":
            ok = ok and 0 < v < 1
        elif fig.baseline:
            ok = ok and v > 0
        if not ok:
            want = (
                "a whole number of runs >= 0"
                if fig.count
                else "a number between 0 and 1"
                if key == "p"
                else "a number >= 0"
            )
            raise ConfigError(f"{where} {key}", f"expected {want}, got {v!r}")
        figures[key] = float(v) if not fig.count else v
    if not figures:
        raise ConfigError(where, f"limits no figure; give at least one of {', '.join(FIGURES)}")
    return Limit(index, b.get("name"), scenario, controller, phase, figures)


def _known(table: dict, keys: tuple[str, ...], where: str) -> None:
    for key in table:
        if key not in keys:
            raise ConfigError(f"{where} {key}", f"unknown key; known keys: {', '.join(keys)}")


def _strings(table: dict, key: str, path: Path, required: bool) -> list[str] | None:
    v = table.get(key)
    if v is None and not required:
        return None
    if not (isinstance(v, list) and v and all(isinstance(s, str) and s.strip() for s in v)):
        raise ConfigError(f"{path} {key}", f'expected a non-empty list of names, like ["eight-nominal"], got {v!r}')
    return [s.strip() for s in v]


def _seeds_text(v, path: Path) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, int) and not isinstance(v, bool):
        return str(v)
    if isinstance(v, list) and v and all(isinstance(s, int) and not isinstance(s, bool) for s in v):
        return ",".join(map(str, v))
    raise ConfigError(f"{path} seeds", f'expected seeds like "0-3", 3 or [0, 2, 5], got {v!r}')


def _near(spec: str, here: Path) -> str:
    """``file.py:Class`` (or a policy's ``file.npz``) with a relative file -> the file from the budget's
    folder, as an absolute path."""
    file, sep, rest = spec.partition(":")
    if sep and file.endswith(".py") and not Path(file).is_absolute():
        return f"{here / file}:{rest}"
    if spec.endswith(".npz") and not Path(spec).is_absolute():
        return str(here / spec)
    return spec


def _near_robot(robot: str, here: Path) -> str:
    """A budget's robot: an MJCF or robot file from the budget's folder, else a name."""
    return str(here / robot) if robot.endswith((".xml", ".toml")) and not Path(robot).is_absolute() else robot


def _is_number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)
