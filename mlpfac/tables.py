"""TOML tables -> plain, validated data: frozen config dataclasses built from a table (unknown
keys, wrong types and bad values named by their key), and a table written back as TOML."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import re
import tomllib
import types
import typing
from pathlib import Path

import numpy as np

from mlpfac.exceptions import ConfigError

FOLDER_NAME = re.compile(
    r"[A-Za-z0-9][A-Za-z0-9._+-]*"
)  # a scenario's or a controller's name: a folder in runs/ and sweeps

BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")  # a TOML key written without quotes
INLINE_TABLES = ("uniform", "normal")  # one-key tables written inline (the distributions of mlpfac.scenario.draws)
NO_LIMIT = {"v_max", "omega_max"}  # keys where inf means "no limit" (None)
INF_OK = NO_LIMIT | {
    "max_wheel_speed"
}  # keys that take inf ("no limit"; max_wheel_speed keeps it: None is the model's)


def check_keys(table: dict, allowed: set[str], where: str) -> None:
    for key in table:
        if key not in allowed:
            raise ConfigError(f"{where} {key}", f"unknown key (known: {', '.join(sorted(allowed))})")


def subtable(table: dict, key: str, where: str, default=None) -> dict:
    val = table.get(key, {} if default is None else default)
    if not isinstance(val, dict):
        raise ConfigError(f"{where} {key}", f"expected a table ([{key}]), got {val!r}")
    return dict(val)


def number(table: dict, key: str, default: float, where: str, positive: bool = True) -> float:
    val = table.get(key, default)
    if isinstance(val, bool) or not isinstance(val, int | float) or not math.isfinite(val):
        raise ConfigError(f"{where} {key}", f"expected a finite number, got {val!r}")
    if positive and not val > 0:
        raise ConfigError(f"{where} {key}", f"must be positive, got {val}")
    if not positive and val < 0:
        raise ConfigError(f"{where} {key}", f"must be >= 0, got {val}")
    return float(val)


def typed(value, hint, key: str) -> bool:
    """Whether a TOML value fits a dataclass field's type (float: a finite number, inf where it means no limit)."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return any(typed(value, h, key) for h in typing.get_args(hint))
    if origin is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, list | tuple):
            return False
        if len(args) == 2 and args[1] is Ellipsis:
            return all(typed(v, args[0], key) for v in value)
        return len(value) == len(args) and all(typed(v, h, key) for v, h in zip(value, args, strict=True))
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        return ok and (math.isfinite(value) or (key in INF_OK and value == math.inf))
    if hint is str:
        return isinstance(value, str)
    return True  # nested configs (Networks) are built on their own


def describe(hint) -> str:
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(describe(h) for h in typing.get_args(hint) if h is not type(None))
    if origin is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {describe(args[0])}s"
        return f"a list of {len(args)} {describe(args[0])}s"
    return {bool: "true or false", int: "a whole number", float: "a finite number", str: "a string"}.get(
        hint, str(hint)
    )


@functools.cache
def _hints(cls) -> dict:
    """The types of a config dataclass's fields, read once a process (a sweep parses every run's table)."""
    return typing.get_type_hints(cls)


def build(cls, table: dict, where: str):
    """A frozen config dataclass from a TOML table: unknown keys, wrong types and bad values name the key."""
    fields = {f.name for f in dataclasses.fields(cls)}
    check_keys(table, fields, where)
    hints = _hints(cls)
    values = {}
    for key, val in table.items():
        if not typed(val, hints[key], key):
            raise ConfigError(f"{where} {key}", f"expected {describe(hints[key])}, got {val!r}")
        if key in NO_LIMIT and val == math.inf:
            val = None  # inf: no limit
        values[key] = tuple(val) if isinstance(val, list) else val
    try:
        return cls(**values)
    except ConfigError as err:
        raise ConfigError(f"{where} {err.where}".strip(), err.what) from None
    except (TypeError, ValueError) as err:
        raise ConfigError(where, str(err)) from None


def to_toml(table: dict) -> str:
    """A scenario table as TOML (scalars, lists of scalars, tables and arrays of tables)."""
    lines: list[str] = []

    def value(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v, ensure_ascii=False)  # a JSON string is a TOML basic string
        if isinstance(v, float) and math.isinf(v):
            return "inf" if v > 0 else "-inf"
        if isinstance(v, list | tuple):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{key(k)} = {value(x)}" for k, x in v.items()) + " }"
        return repr(v)

    def key(k: str) -> str:
        return k if BARE_KEY.fullmatch(k) else json.dumps(k, ensure_ascii=False)

    def inline(v) -> bool:  # a distribution in place of a number (mlpfac.scenario.draws) stays where the number was
        return isinstance(v, dict) and len(v) == 1 and next(iter(v)) in INLINE_TABLES

    def emit(t: dict, prefix: str) -> None:
        for k, v in t.items():
            if inline(v) or not (isinstance(v, dict) or (isinstance(v, list) and v and isinstance(v[0], dict))):
                lines.append(f"{key(k)} = {value(v)}")
        for k, v in t.items():
            if inline(v):
                continue
            if isinstance(v, dict):
                lines.append(f"\n[{prefix}{k}]")
                emit(v, f"{prefix}{k}.")
            elif isinstance(v, list) and v and isinstance(v[0], dict):
                for item in v:
                    lines.append(f"\n[[{prefix}{k}]]")
                    emit(item, f"{prefix}{k}.")

    emit(table, "")
    return "\n".join(lines) + "\n"


TOML_MAX = 16 * 2**20  # bytes of a TOML file (a scenario, a budget, a robot), at most


def read_toml(path: Path, kind: str) -> dict:
    """The TOML file at ``path`` (a ``kind``, e.g. "scenario file"); a ConfigError naming it when it
    cannot be read or is not UTF-8 TOML."""
    from mlpfac.io.files import NotAFileError, read_regular

    try:
        return tomllib.loads(read_regular(path, TOML_MAX).decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError(str(path), f"{kind} not found") from None
    except IsADirectoryError:
        raise ConfigError(str(path), f"is a folder, not a {kind}") from None
    except NotAFileError as err:
        if str(err).startswith("is a folder"):
            raise ConfigError(str(path), f"is a folder, not a {kind}") from None
        raise ConfigError(str(path), f"{err} (a {kind})") from None
    except OSError as err:
        raise ConfigError(str(path), f"cannot read: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise ConfigError(str(path), "not a text file (TOML is UTF-8 text)") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(str(path), f"not valid TOML: {err}") from None
    except RecursionError:  # arrays or tables nested thousands deep
        raise ConfigError(str(path), f"not a {kind}: its arrays or tables are nested too deep to read") from None


def covariance(value: float | list | np.ndarray, n: int, name: str) -> np.ndarray:
    """A covariance from a scalar (times I), a diagonal, or a full matrix; checked symmetric PSD."""
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.ndim == 1:
        if a.shape != (n,):
            raise ConfigError(name, f"expected a scalar or {n} diagonal values, got {a.shape[0]}")
        if np.any(a < 0) or not np.all(np.isfinite(a)):
            raise ConfigError(name, "a covariance must be finite and non-negative")
        return np.diag(a)
    if a.shape != (n, n) or not np.allclose(a, a.T) or np.linalg.eigvalsh(a).min() < -1e-12:
        raise ConfigError(name, f"expected a symmetric positive semi-definite {n}x{n} matrix")
    return a
