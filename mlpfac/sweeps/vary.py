"""``--vary KEY=VALUES``: a number of the scenario file as an axis of the sweep, or drawn per seed.

KEY is the dotted path of a number in the scenario file as a user writes it (:mod:`mlpfac.scenario.draws`):
``events.0.scale``, ``plant.pose_noise_std``, ``reference.wx``, ``controller.v_max``. VALUES is

- a list, ``1.0,1.25,1.5``, or an inclusive range with a count, ``1.0:2.0:11`` (whole numbers when
  both ends are and the step is whole): an **axis**; two or more axes make a grid;
- a distribution, ``uniform:LOW:HIGH``, ``normal:MEAN:SD`` or ``choice:X:Y:...``: the number is
  **drawn** from each run's seed, as a ``{ uniform = [LOW, HIGH] }`` written in the file would be.

Each grid point is the scenario with its values written in, named ``SCENARIO+KEY+VALUE`` (one
``+KEY+VALUE`` per axis): a folder of the sweep, a row of its tables, a scenario of the paired
statistics. Every value is checked before anything runs, as the file's own value is (the plant
built, so an event the robot cannot apply is found too): a bad one is one ConfigError naming
``--vary KEY=VALUE``; a key that is no number of the file lists the keys that can vary.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

from mlpfac.exceptions import ConfigError
from mlpfac.scenario.draws import KINDS, SKIPPED, Distribution, distribution, get, is_distribution, leaves

Point = tuple[tuple[str, Any], ...]  # (key, value) per axis, in the order of the axes
FLAG = "--vary"
MAX_RUNS = 100_000  # runs per sweep (and so values per axis): a larger plan is refused before anything is built


@dataclass(frozen=True)
class Axis:
    key: str
    values: tuple[Any, ...]
    text: str  # as given: KEY=VALUES


@dataclass(frozen=True)
class Vary:
    """The axes (a grid, in the order given) and the keys drawn per seed."""

    axes: tuple[Axis, ...] = ()
    draws: dict[str, Distribution] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return bool(self.axes or self.draws)

    def points(self) -> list[Point]:
        """Every grid point: the product of the axes (one empty point without an axis)."""
        return [tuple(zip((a.key for a in self.axes), vals, strict=True)) for vals in self._product()]

    def _product(self):
        return itertools.product(*(a.values for a in self.axes))

    @property
    def size(self) -> int:
        return math.prod(len(a.values) for a in self.axes)

    def texts(self) -> list[str]:
        return [a.text for a in self.axes] + [f"{k}={d.text()}" for k, d in self.draws.items()]


def _number(text: str, where: str) -> int | float:
    t = text.strip()
    try:
        return int(t)
    except ValueError:
        pass
    try:
        x = float(t)
    except ValueError:
        raise ConfigError(where, f"{t!r} is not a number") from None
    if not math.isfinite(x):
        raise ConfigError(where, f"{t!r} is not a finite number")
    return x


def _values(key: str, text: str, where: str) -> tuple[Any, ...] | Distribution:
    parts = text.split(":")
    if parts[0].strip() in KINDS:
        if parts[0].strip() == "choice":
            return distribution({"choice": [_number(p, where) for p in parts[1:]]}, where)
        if len(parts) != 3:
            raise ConfigError(where, f"a distribution is {parts[0]}:A:B, got {text!r}")
        a, b = (_number(p, where) for p in parts[1:])
        return distribution({parts[0].strip(): [a, b]}, where)
    if len(parts) == 3:
        lo, hi = (_number(p, where) for p in parts[:2])
        n = _number(parts[2], where)
        if not isinstance(n, int) or n < 2:
            raise ConfigError(where, f"a range is LOW:HIGH:COUNT with a whole COUNT >= 2, got {text!r}")
        if n > MAX_RUNS:  # counted before a value is made
            raise ConfigError(where, f"{n} values is more than the limit of {MAX_RUNS} runs per sweep")
        if isinstance(lo, int) and isinstance(hi, int) and (hi - lo) % (n - 1) == 0:
            values = tuple(lo + (hi - lo) // (n - 1) * i for i in range(n))
        else:  # as a user would write them: 12 significant digits (1.2, not 1.2000000000000002)
            values = tuple(float(f"{lo + (hi - lo) * i / (n - 1):.12g}") for i in range(n))
        return _distinct(values, text, where)
    if len(parts) != 1:
        raise ConfigError(
            where,
            f"expected a list 1.0,1.5, a range 1.0:2.0:11 or uniform:A:B / normal:M:SD / choice:X:Y:..., got {text!r}",
        )
    if text.count(",") >= MAX_RUNS:
        raise ConfigError(where, f"more than the limit of {MAX_RUNS} values (runs per sweep)")
    values = tuple(_number(p, where) for p in text.split(",") if p.strip())
    if not values:
        raise ConfigError(where, "no value given")
    return _distinct(values, text, where)


def _distinct(values: tuple, text: str, where: str) -> tuple:
    """``values``, each once: a value twice would be two grid points of one name (one folder)."""
    seen = set()
    for v in values:
        if v in seen:
            raise ConfigError(where, f"the value {v!r} appears twice in {text!r}: each value of an axis once")
        seen.add(v)
    return values


def parse_vary(texts: list[str] | dict | None) -> Vary:
    """``--vary`` flags (``["events.0.scale=1:2:11", ...]``), or the API's ``{key: values}`` (a list,
    a range text, or a distribution text or table), checked as text only (see :func:`grid`)."""
    if texts is None:
        return Vary()
    if not isinstance(texts, dict | list | tuple):
        raise ConfigError(
            "vary", f"expected {{KEY: VALUES}} or a list of 'KEY=VALUES' texts (as --vary), got {texts!r}"
        )
    if not texts:
        return Vary()
    items: list[tuple[str, Any]] = []
    if isinstance(texts, dict):
        items = list(texts.items())
    else:
        for text in texts:
            key, sep, values = str(text).partition("=")
            if not sep or not key.strip():
                raise ConfigError(f"{FLAG} {text}", "expected KEY=VALUES, e.g. events.0.scale=1.0:2.0:11")
            items.append((key.strip(), values))
    axes, draws = [], {}
    for key, raw in items:
        if not isinstance(key, str) or not key:
            raise ConfigError(FLAG, f"expected a dotted key, got {key!r}")
        where = f"{FLAG} {key}"
        if any(a.key == key for a in axes) or key in draws:
            raise ConfigError(where, "given twice")
        if is_distribution(raw):
            draws[key] = distribution(raw, where)
            continue
        if isinstance(raw, list | tuple):
            if len(raw) > MAX_RUNS:
                raise ConfigError(where, f"{len(raw)} values is more than the limit of {MAX_RUNS} runs per sweep")
            text = ",".join(str(v) for v in raw)
            if any(isinstance(v, bool) or not isinstance(v, int | float) for v in raw):
                raise ConfigError(where, f"expected numbers, got {list(raw)!r}")
        else:
            text = str(raw)
        got = _values(key, text, f"{where}={text}")
        if isinstance(got, Distribution):
            draws[key] = got
        else:
            axes.append(Axis(key, got, f"{key}={text}"))
    return Vary(tuple(axes), draws)


def label(name: str, point: Point) -> str:
    """The grid point's name: ``eight-wheel-radius+events.0.scale+1.5`` (a folder name)."""
    return name + "".join(f"+{k}+{v!r}" for k, v in point)


def _typed(value: Any, current: Any) -> Any:
    """A value as the file's own number at its key is: a float where the file writes a float."""
    return float(value) if isinstance(current, float) and isinstance(value, int) else value


def _key_error(src: str, key: str, table: dict) -> ConfigError:
    """``key`` is no number of ``src`` that can vary: what can (never an empty list)."""
    parts = key.split(".")
    if parts[:2] == ["reference", "params"] and len(parts) == 3:  # a reference class's parameter: only where set
        return ConfigError(
            f"{FLAG} {key}",
            f"{src} sets no {parts[2]} in [reference.params] (your reference class's default is its own): write "
            f"{parts[2]} = VALUE there to vary it",
        )
    keys = list(leaves(table))
    sets = f"it sets {', '.join(keys)}" if keys else "it sets no number"
    return ConfigError(
        f"{FLAG} {key}",
        f"not a number of {src} that can vary; {sets}; a key it leaves to its default (duration, T, "
        "plant.pose_noise_std, ...) varies too where its table takes it: docs/scenario-file.md lists them",
    )


def _present(table: dict, key: str) -> bool:
    try:
        get(table, key)
    except KeyError:
        return False
    return True


def grid(src: str, vary: Vary, duration: float | None = None, robot: str | None = None) -> list[tuple[Point, Any]]:
    """Every grid point of scenario ``src`` and its :class:`~mlpfac.scenario.parse.Scenario` (built as
    :func:`~mlpfac.scenario.parse.load` builds the file), each value checked as the file's own is; a key
    of an event that ``duration`` (``--duration``) leaves out is a ConfigError."""
    from mlpfac.scenario.parse import load

    file = load(src, build=False, ends=False)  # the file's distributions: checked at both ends below
    numbers = leaves(file.table)
    if duration is not None:
        _check_duration(vary, numbers, duration)
    axis_keys = {a.key for a in vary.axes}
    in_file = {
        k: distribution(v, f"{src} {k}") for k, v in numbers.items() if isinstance(v, dict) and k not in axis_keys
    }
    if not vary and not in_file:
        return [((), load(src, robot=robot, ends=False))]
    drawn = {k: d.table() for k, d in vary.draws.items()}
    for key in [a.key for a in vary.axes] + list(drawn):
        if key.split(".")[0] in SKIPPED or (key not in numbers and _present(file.table, key)):
            raise _key_error(src, key, file.table)
        if key.startswith("reference.params.") and not isinstance(file.table.get("reference", {}).get("params"), dict):
            raise _key_error(src, key, file.table)  # no [reference.params]: the class's own defaults, not ours to set
        if key not in numbers:  # a key the file leaves to its default, as plant.pose_noise_std
            first = next((a.values[0] for a in vary.axes if a.key == key), None)
            try:
                load(src, build=False, values={key: 0 if first is None else first}, ends=False)
            except ConfigError as err:
                if err.what.startswith(("unknown key", "no such key", "not a parameter")):
                    raise _key_error(src, key, file.table) from None
    axes = [(a, tuple(_typed(v, numbers.get(a.key)) for v in a.values)) for a in vary.axes]
    for key, dist in (in_file | vary.draws).items():  # a draw can take any value of its support: both ends are checked
        name = f"{FLAG} {key}={dist}" if key in vary.draws else f"{src} {key} = {dist}"
        for end in dist.support():
            what = "value" if dist.kind == "choice" else "end"
            _checked(src, {**drawn, key: _typed(end, numbers.get(key))}, f"{name} (its {what} {end:g})")
    if len(axes) > 1:  # each value alone first, so that a bad one is named alone (without building the plant)
        for a, values in axes:
            for v in values:
                _checked(src, {**drawn, a.key: v}, f"{FLAG} {a.key}={v!r}", build=False)
    out = []
    if not axes:
        return [
            ((), _checked(src, drawn, "", build=True, robot=robot) if drawn else load(src, robot=robot, ends=False))
        ]
    for vals in itertools.product(*(values for _, values in axes)):
        point = tuple(zip((a.key for a, _ in axes), vals, strict=True))
        where = f"{FLAG} " + " ".join(f"{k}={v!r}" for k, v in point)
        scn = _checked(src, {**drawn, **dict(point), "name": label(file.name, point)}, where, robot=robot)
        out.append((point, scn))
    return out


def _check_duration(vary: Vary, numbers: dict, duration: float) -> None:
    """A ConfigError for ``duration`` varied beside ``--duration`` (which would set every point's), and
    for a value of an event that ``--duration`` leaves out (it would vary nothing)."""
    if any(a.key == "duration" for a in vary.axes) or "duration" in vary.draws:
        raise ConfigError(
            f"{FLAG} duration",
            f"conflicts with --duration {duration:g}, which would run every point that long: give one",
        )
    times = {a.key: a.values for a in vary.axes if a.key.startswith("events.") and a.key.endswith(".time")}
    for key, values in times.items():
        late = next((v for v in values if v >= duration), None)
        if late is not None:
            raise ConfigError(f"{FLAG} {key}={late!r}", f"the event would be left out by --duration {duration:g}")
    for key in [a.key for a in vary.axes] + list(vary.draws):
        parts = key.split(".")
        when = f"events.{parts[1]}.time" if len(parts) >= 3 else ""
        if parts[0] != "events" or len(parts) < 3 or when in times or when in vary.draws:  # its time varies too
            continue
        t = numbers.get(f"events.{parts[1]}.time")
        if isinstance(t, int | float) and t >= duration:
            raise ConfigError(
                f"{FLAG} {key}", f"the event at {t:g} s is left out by --duration {duration:g}: it would vary nothing"
            )


def _checked(src: str, values: dict, where: str, build: bool = True, robot: str | None = None):
    from mlpfac.scenario.parse import load

    try:
        return load(src, build=build, robot=robot, values=values, ends=False)
    except ConfigError as err:
        if not where:
            raise
        raise type(err)(where, f"{err.what} ({err.where})") from None
