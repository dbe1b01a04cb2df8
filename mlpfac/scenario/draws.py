"""Numbers of a scenario by their dotted path, and distributions in place of a number.

A key is the dotted path of a value in the scenario file as a user writes it: ``events.0.scale``
(the first ``[[events]]`` table of the file, in the file's order), ``plant.pose_noise_std``,
``reference.wx``, ``controller.lambdas.1``. Any number of the file may be replaced by a
distribution, drawn from the run's seed when the scenario is parsed::

    scale = { uniform = [0.9, 1.1] }      # uniform on [0.9, 1.1]
    mass_scale = { normal = [2.0, 0.3] }  # normal, mean 2, standard deviation 0.3, cut at mean +- 3 sd
    steps = { choice = [0, 1, 2, 4] }     # one of these, each as likely (a whole number stays whole)

Each draw takes its numbers from ``(seed, key)`` alone, so seed k is the same robot for every
controller (paired statistics stay paired) and adding a distribution changes no other draw; the
run's own noise is drawn from other streams. What was drawn is written to the table's ``[drawn]``
(config.toml), and checked against a fresh draw when a config.toml is run again.
"""

from __future__ import annotations

import copy
import math
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from mlpfac.exceptions import ConfigError

KINDS = ("uniform", "normal", "choice")
NORMAL_CUT = 3.0  # a normal draw is cut at mean +- NORMAL_CUT standard deviations (drawn again beyond)
DRAW_STREAM = 0x6D6C7066  # tags the draws' seed sequence apart from every other stream of a run
SKIPPED = ("provenance", "drawn", "seed", "name", "description")  # top-level keys that are no number to vary
RECORDS = ("provenance", "drawn")  # top-level tables the program writes: never set by a key


@dataclass(frozen=True)
class Distribution:
    """``uniform`` on [a, b], ``normal`` with mean a and standard deviation b (cut at +- 3 b), or
    ``choice`` of ``values`` (a and b their least and greatest)."""

    kind: str
    a: float
    b: float
    values: tuple = ()

    def support(self) -> tuple:
        """The smallest and largest value a draw can take (a choice: every value it can take)."""
        if self.kind == "uniform":
            return self.a, self.b
        if self.kind == "choice":
            return self.values
        return self.a - NORMAL_CUT * self.b, self.a + NORMAL_CUT * self.b

    def draw(self, seed: int, key: str) -> float:
        """The value of ``key`` for ``seed``: the same for every controller and every run of the seed."""
        rng = np.random.default_rng(np.random.SeedSequence([DRAW_STREAM, seed, zlib.crc32(key.encode())]))
        if self.kind == "uniform":
            return float(self.a + (self.b - self.a) * rng.random())
        if self.kind == "choice":
            return self.values[int(rng.integers(len(self.values)))]
        from mlpfac.normal import normal  # here: importing the kernels' module checks MLPFAC_KERNELS

        while True:
            x = normal(rng, self.a, self.b)
            if abs(x - self.a) <= NORMAL_CUT * self.b:
                return x

    def table(self) -> dict:
        return {self.kind: list(self.values) if self.kind == "choice" else [self.a, self.b]}

    def text(self) -> str:
        """As ``--vary`` writes it: ``uniform:1:2``, ``choice:0:1:2``."""
        return ":".join([self.kind, *(f"{x:g}" for x in (self.values if self.kind == "choice" else (self.a, self.b)))])

    def __str__(self) -> str:
        nums = self.values if self.kind == "choice" else (self.a, self.b)
        return f"{self.kind}({', '.join(f'{x:g}' for x in nums)})"


def is_distribution(value: Any) -> bool:
    """Whether a TOML value is a distribution's table (one key: uniform or normal)."""
    return isinstance(value, dict) and len(value) == 1 and next(iter(value)) in KINDS


def distribution(value: Any, where: str) -> Distribution:
    """The distribution a table ``{uniform = [a, b]}``, ``{normal = [mean, sd]}`` or ``{choice = [x, y, ...]}``
    names; a ConfigError naming ``where``."""
    ((kind, ab),) = value.items()
    if kind == "choice":
        ok = isinstance(ab, list | tuple) and len(ab) >= 2
        ok = ok and all(isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in ab)
        if not ok:
            raise ConfigError(where, f"choice takes two or more finite numbers, got {ab!r}")
        if len(set(ab)) != len(ab):
            raise ConfigError(where, f"choice names a value twice in {list(ab)!r}: each value once")
        return Distribution(kind, float(min(ab)), float(max(ab)), tuple(ab))
    ok = isinstance(ab, list | tuple) and len(ab) == 2
    ok = ok and all(isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in ab)
    if not ok:
        raise ConfigError(
            where, f"{kind} takes two finite numbers ({'low, high' if kind == 'uniform' else 'mean, sd'}), got {ab!r}"
        )
    a, b = float(ab[0]), float(ab[1])
    if kind == "uniform" and not a < b:
        raise ConfigError(where, f"uniform needs low < high, got [{a:g}, {b:g}]")
    if kind == "normal" and not b > 0:
        raise ConfigError(where, f"normal needs a standard deviation > 0, got {b:g}")
    return Distribution(kind, a, b)


def leaves(table: dict) -> dict[str, Any]:
    """Every number of a scenario table and every distribution, by dotted path, in the file's order."""
    out: dict[str, Any] = {}

    def walk(node: Any, path: str) -> None:
        if is_distribution(node) or (isinstance(node, int | float) and not isinstance(node, bool)):
            out[path] = node
        elif isinstance(node, dict):
            for k, v in node.items():
                walk(v, f"{path}.{k}" if path else str(k))
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, f"{path}.{i}")

    walk({k: v for k, v in table.items() if k not in SKIPPED}, "")
    return out


def get(table: dict, key: str) -> Any:
    """The value at dotted ``key`` (KeyError when there is none)."""
    node: Any = table
    for part in key.split("."):
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise KeyError(key)
            node = node[int(part)]
        elif isinstance(node, dict) and part in node:
            node = node[part]
        else:
            raise KeyError(key)
    return node


def put(table: dict, key: str, value: Any) -> bool:
    """Set the value at dotted ``key`` in place (a key the file leaves out is added to its table);
    False when the path leads through no table or list of the file."""
    *head, last = key.split(".")
    node: Any = table
    for part in head:
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict) and isinstance(node.get(part), dict | list):
            node = node[part]
        elif isinstance(node, dict) and part not in node and (node is not table or part not in RECORDS):
            node = node.setdefault(part, {})  # a table the file leaves out, as [plant] or [controller.mpc]
        else:
            return False
    if isinstance(node, list):
        if not (last.isdigit() and int(last) < len(node)):
            return False
        node[int(last)] = value
        return True
    if not isinstance(node, dict) or (node is table and last in RECORDS):
        return False
    node[last] = value
    return True


def resolve(table: dict, seed: int, source: str) -> tuple[dict, dict[str, tuple[Distribution, float]]]:
    """The table with each distribution replaced by its draw for ``seed`` (a copy; the table itself
    when it has none), and the draws by key. A bad distribution, or a ``[drawn]`` value that is not
    this seed's draw (an edited config.toml), is a ConfigError."""
    found = {k: v for k, v in leaves(table).items() if isinstance(v, dict)}
    recorded = table.get("drawn")
    if recorded is not None and not isinstance(recorded, dict):
        raise ConfigError(f"{source} drawn", f"expected a table ([drawn]), got {recorded!r}")
    if not found and not recorded:
        return table, {}
    out = copy.deepcopy(table)
    out.pop("drawn", None)
    draws: dict[str, tuple[Distribution, float]] = {}
    for key, spec in found.items():
        dist = distribution(spec, f"{source} {key}")
        value = dist.draw(seed, key)
        draws[key] = (dist, value)
        put(out, key, value)
    for key, value in (recorded or {}).items():
        if key not in draws:
            raise ConfigError(f"{source} [drawn] {key}", "no distribution at this key: remove it from [drawn]")
        if value != draws[key][1]:
            raise ConfigError(
                f"{source} [drawn] {key}",
                f"{value!r} is not what seed {seed} draws from {draws[key][0]} ({draws[key][1]!r}): write the value "
                "in place of the distribution to run it",
            )
    return out, draws


def check_ends(table: dict, where: str, load) -> None:
    """Each distribution of ``table`` at both ends of what it can draw: ``load(table)`` of the table
    with that end in its place (and out of a config.toml's ``[drawn]``), so that a seed whose draw
    lands out of range is found before anything runs, whatever seed runs first (a sweep's grid
    checks them so too); a ConfigError naming the distribution and its end (``where``: the file)."""
    for key, spec in leaves(table).items():
        if not is_distribution(spec):
            continue
        dist = distribution(spec, f"{where} {key}")
        for end in dist.support():
            at_end = copy.deepcopy(table)
            put(at_end, key, end)
            drawn = at_end.get("drawn")
            if isinstance(drawn, dict) and key in drawn:  # a config.toml's record of the draw: this end instead
                at_end["drawn"] = {k: v for k, v in drawn.items() if k != key}
            try:
                load(at_end)
            except ConfigError as err:
                raise ConfigError(f"{where} {key} = {dist} (its end {end:g})", f"{err.what} ({err.where})") from None


def restore(table: dict, draws: dict[str, tuple[Distribution, float]]) -> dict:
    """A parsed table with its distributions back in place and what was drawn in ``[drawn]``."""
    if not draws:
        return table
    out = copy.deepcopy(table)
    for key, (dist, _) in draws.items():
        put(out, key, dist.table())
    out["drawn"] = {key: value for key, (_, value) in draws.items()}
    return out
