"""Planning a sweep: seeds and controllers from the command line, one :class:`Job` per run."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.exceptions import ConfigError
from mlpfac.io.files import resolved
from mlpfac.sweeps.vary import MAX_RUNS, Vary


def parse_seeds(text: str, limit: int | None = MAX_RUNS) -> list[int]:
    """``"0-99"``, ``"3"``, ``"0,2,5"``, ``"0-4,10"`` -> sorted distinct seeds; ``"5-2"`` is an error.

    More than ``limit`` seeds is a ConfigError, found before any list is built (``0-10000000`` is cheap).
    """
    ranges: list[tuple[int, int]] = []
    for part in str(text).split(","):
        part = part.strip()
        lo, sep, hi = part.partition("-")
        try:
            a = int(lo)
            b = int(hi) if sep else a
        except ValueError:
            raise ConfigError("--seeds", f"{part!r} is not a seed or a range like 0-99 (in {text!r})") from None
        if a < 0:
            raise ConfigError("--seeds", f"seeds are whole numbers >= 0, got {part!r}")
        if b < a:
            raise ConfigError("--seeds", f"empty range {part!r}: the end must not be below the start")
        ranges.append((a, b))
    count, end = 0, -1  # distinct seeds in the union of the ranges
    for a, b in sorted(ranges):
        if b > end:
            count += b - max(a, end + 1) + 1
            end = b
    if limit is not None and count > limit:
        raise ConfigError("--seeds", f"{count} seeds is more than the limit of {limit} runs per sweep; split them")
    seeds: set[int] = set()
    for a, b in ranges:
        seeds.update(range(a, b + 1))
    return sorted(seeds)


def parse_controllers(text: str | None, where: str = "--controllers") -> list[str | None]:
    """``"adaptive,corradini,my_law.py:MyLaw"`` -> names, checked (a plug-in's file taken from the
    current folder and made absolute, :mod:`mlpfac.control.plugins`); ``None`` -> each scenario's own controller."""
    if text is None:
        return [None]
    from pathlib import Path

    from mlpfac.control.plugins import absolute_spec, is_plugin_spec, resolve
    from mlpfac.control.policy import policy_name

    names = [absolute_spec(c.strip(), Path.cwd()) for c in text.split(",") if c.strip()]
    if not names:
        raise ConfigError(where, "no controller given")
    seen: dict[str, str] = {}
    for c in names:
        name = resolve(c, None, 0.01, where).name if is_plugin_spec(c) else policy_name(c) if c.endswith(".npz") else c
        if seen.setdefault(name, c) != c:
            raise ConfigError(where, f"{seen[name]} and {c} are both named {name!r}; their folders would collide")
    return list(dict.fromkeys(names))


@dataclass(frozen=True)
class Job:
    """One run: a scenario as resolved for one controller and seed."""

    scenario: str  # the scenario's name: the first folder level
    controller: str
    seed: int
    source: str = field(compare=False)  # file it came from (error messages, ConfigError "where")
    table: dict = field(compare=False, hash=False, repr=False)  # resolved TOML table: what a worker runs
    config: str = field(compare=False, repr=False)  # to_toml(table): config.toml
    point: tuple = field(default=(), compare=False)  # (key, value) per --vary axis (mlpfac.sweeps.vary)
    family: str = field(default="", compare=False)  # the scenario's own name, before its grid point's

    @property
    def drawn(self) -> dict:
        """What was drawn for this run in place of the file's distributions, by key."""
        return dict(self.table.get("drawn", {}))

    @property
    def key(self) -> tuple[str, str, int]:
        return (self.scenario, self.controller, self.seed)

    def folder(self, out: Path) -> Path:
        return out / self.scenario / self.controller / f"seed-{self.seed:04d}"


def plan(
    scenarios: Iterable[str],
    controllers: list[str | None],
    seeds: list[int],
    duration: float | None = None,
    vary: Vary | None = None,
    lost_threshold: float | None = None,
) -> list[Job]:
    """Load and resolve every run (each grid point of ``vary``; ``lost_threshold``: every run's
    ``lost_threshold_m``, ``--lost-threshold``); raises ConfigError on the first bad scenario,
    controller, seed or value."""
    from mlpfac.scenario.on_robot import split_robot
    from mlpfac.scenario.parse import to_toml
    from mlpfac.sweeps.vary import grid, label

    scenarios = list(dict.fromkeys(scenarios))
    if not scenarios:
        raise ConfigError("scenarios", "no scenario given")
    if not seeds:
        raise ConfigError("--seeds", "no seed given")
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise ConfigError("--duration", f"must be a positive number of seconds, got {duration}")
    if lost_threshold is not None:
        from mlpfac.scenario.parse import lost_threshold_m

        lost_threshold_m(lost_threshold, "--lost-threshold")  # named before any scenario is read
    jobs: list[Job] = []
    names: dict[str, str] = {}
    for src in scenarios:
        name, robot = split_robot(src)  # SCENARIO@ROBOT: on that robot (mlpfac.scenario.on_robot)
        for point, base in grid(name, vary or Vary(), duration, robot):
            if base.name in names:
                raise ConfigError(
                    src,
                    f"scenario name {base.name!r} is also the name of {names[base.name]}; their folders would collide",
                )
            names[base.name] = src
            family = base.name.replace(label("", point), "", 1) if point else base.name  # the scenario (on its robot)
            if duration is not None or lost_threshold is not None:  # once a scenario: what its reference asks of
                base = _overridden(base, duration, lost_threshold, point)  # torque motors is said again here
            for ctrl in controllers:
                # parsed once; only the seed varies, so each seed's table is this one with its seed
                # (what with_overrides(seed=...) gives: parse checks a seed >= 0, which parse_seeds did);
                # a scenario that draws per seed is parsed per seed
                scn = base.with_overrides(controller=ctrl, flag="--controllers")
                configs = _seed_configs(scn.table, seeds, to_toml)
                for seed in seeds:
                    table = {**scn.table, "seed": seed}
                    if "drawn" in scn.table:
                        table = scn.with_overrides(seed=seed).table
                        config = to_toml(table)
                    else:
                        config = configs(seed, table)
                    jobs.append(Job(scn.name, scn.controller, seed, scn.source, table, config, point, family))
    return jobs


def _overridden(base, duration: float | None, lost_threshold: float | None, point: tuple):
    """``base`` with ``--duration`` and ``--lost-threshold`` applied; where a grid point's value does
    not hold over the shorter run, a ConfigError naming that value of ``--vary`` beside ``--duration``."""
    try:
        return base.with_overrides(duration=duration, lost_threshold=lost_threshold)
    except ConfigError as err:
        blamed = [(k, v) for k, v in point if err.where.split()[-1] == k.split(".")[-1]]  # the key it names
        if duration is None or not blamed:
            raise
        values = " ".join(f"{k}={v!r}" for k, v in blamed)
        raise ConfigError(f"--vary {values} with --duration {duration:g}", err.what) from None


def _seed_configs(table: dict, seeds: list[int], to_toml) -> Callable[[int, dict], str]:
    """``configs(seed, table)`` = ``to_toml(table)``, made by replacing the seed line of one rendering."""
    marker = max(seeds, default=0) + 10**18 + 7  # a number no seed line has
    text = to_toml({**table, "seed": marker})
    line = f"seed = {marker!r}\n"
    if text.count(str(marker)) != 1 or text.count(line) != 1:
        return lambda seed, t: to_toml(t)
    head, tail = text.split(line)
    return lambda seed, t: f"{head}seed = {seed!r}\n{tail}"


def check_writable(out: Path, flag: str = "--out") -> None:
    """ConfigError unless ``out`` is (or can be created as) a writable folder; creates nothing."""
    p = resolved(out, f"{flag} {out}")
    while not p.exists():
        p = p.parent
    if not p.is_dir():
        raise ConfigError(str(out), f"{p} is a file, not a folder")
    if not os.access(p, os.W_OK | os.X_OK):
        raise ConfigError(str(out), f"cannot write into {p}")
