"""Your own reference: ``[reference] kind = "my_route.py:Class"`` (or ``package.module:Class``), built
as ``Class(**[reference.params])``, whose ``sample(t)`` returns seven numbers
``(x, y, theta, v, omega, dv, domega)``: the reference pose, its speeds and their rates at time t (s).

It is found as a controller of yours is (:mod:`mlpfac.control.plugins`: a file relative to the
scenario file's folder, or an importable module; the file's sha256 recorded in ``[provenance]``),
built and sampled at t = 0 when the scenario is read (a class that cannot be found, whose
constructor refuses its parameters, or whose ``sample(0)`` is not seven finite numbers is refused
in one line), then sampled at every step's time before the run. Where ``sample(t)`` returns a
value that is not finite, or raises, the run ends there as diverged, saying why. ``[reference]
speed`` runs it ``speed`` times as fast (v, omega x speed, their rates x speed^2), as for every kind.
theta is unwrapped along the run's times.
"""

from __future__ import annotations

import inspect
import math
import re
from dataclasses import dataclass, field

import numpy as np

from mlpfac.exceptions import ConfigError

OWN_KEYS = ("params", "speed")
WHAT = "(x, y, theta, v, omega, dv, domega)"
FACTOR_MAX = 100.0  # the largest speed factor, as for every kind
STILL_M, STILL_SAMPLES = 1e-9, 101  # a reference whose (x, y) spans at most this over the run stands still


@dataclass(frozen=True)
class OwnReference:
    """A user's reference class, resolved and built (``obj``), and how it was found."""

    target: str  # what was loaded: "/abs/file.py:Class" or "package.module:Class"
    origin: str  # "file" or "module"
    sha256: str | None  # of the file that defines it
    params: dict = field(compare=False)
    speed: float = 1.0
    obj: object = field(default=None, compare=False, repr=False)

    def provenance(self) -> dict:
        out = {"target": self.target, "origin": self.origin}
        return out | ({"sha256": self.sha256} if self.sha256 else {})

    def rows(self, t: np.ndarray) -> np.ndarray:
        """(N, 7) rows at times ``t``: the class's samples (v, omega x speed, rates x speed^2), NaN
        from the first that is not seven finite numbers (or raises) on; theta unwrapped before it."""
        out = np.full((len(t), 7), np.nan)
        k = self.speed
        for i, ti in enumerate(np.asarray(t, dtype=float).tolist()):
            row = _row(self.obj, k * ti)
            if isinstance(row, str):
                break
            out[i] = row
        good = np.isfinite(out[:, 0])
        out[good, 2] = np.unwrap(out[good, 2])
        out[:, 3:5] *= k
        out[:, 5:7] *= k * k
        return out

    def stands_still(self, duration: float, samples: int = STILL_SAMPLES) -> bool:
        """Whether its (x, y) stays within STILL_M over ``duration`` s (``samples`` times, the finite
        ones): no path whose size a lost threshold can be a share of."""
        rows = self.rows(np.linspace(0.0, duration, samples))[:, :2]
        rows = rows[np.all(np.isfinite(rows), axis=1)]
        return bool(len(rows)) and float(np.max(np.max(rows, axis=0) - np.min(rows, axis=0))) <= STILL_M

    def why(self, t: float) -> str:
        """Why the sample at time ``t`` ended the run."""
        found = _row(self.obj, self.speed * t)
        return f"the reference {self.target.rpartition('/')[2]}: {found}" if isinstance(found, str) else ""


def _row(obj, t: float) -> tuple[float, ...] | str:
    """sample(t) as seven floats, or the reason it is not."""
    from mlpfac.control.plugins import one_line

    try:
        got = obj.sample(t)
    except Exception as err:  # their code raised: where, in their file
        return f"sample({t:g}) raised {one_line(err)}"
    try:
        row = tuple(float(x) for x in got)
    except Exception:  # it returned what is not seven numbers (their __float__ may raise anything): what it returned
        text = repr(got)
        return f"sample({t:g}) returned {text[:80] + '...' if len(text) > 80 else text}, not seven numbers {WHAT}"
    if len(row) != 7:
        return f"sample({t:g}) returned {len(row)} numbers, not 7 {WHAT}"
    if not all(math.isfinite(x) for x in row):
        return f"sample({t:g}) returned a value that is not finite: {row}"
    return row


def make_own(kind: str, params: dict, where: str) -> OwnReference:
    """The reference class ``kind`` names (``file.py:Class``, made absolute against the scenario
    file's folder when it is read; ``package.module:Class``), built with ``params[\"params\"]`` and
    checked at t = 0; a ConfigError naming ``where`` (the key) for each way it can be wrong."""
    from mlpfac.control.plugins import load_target, one_line

    for key in params:
        if key not in OWN_KEYS:
            raise ConfigError(
                f"{where} {key}",
                f"not a key of your own reference (it takes {', '.join(OWN_KEYS)}; its own parameters go in [reference.params])",
            )
    speed = params.get("speed", 1.0)
    if isinstance(speed, bool) or not isinstance(speed, int | float) or not 0 < speed <= FACTOR_MAX:
        raise ConfigError(f"{where} speed", f"must be > 0 and at most {FACTOR_MAX:g} (a factor), got {speed!r}")
    kwargs = params.get("params", {})
    if not isinstance(kwargs, dict):
        raise ConfigError(f"{where} params", f"expected a table ([reference.params]), got {kwargs!r}")
    cls, sha, kind_of = load_target(kind, f"{where} kind")
    name = kind.rpartition(":")[2]
    if not inspect.isclass(cls):
        raise ConfigError(f"{where} kind", f"{kind} is not a class (a reference is a class with sample(t))")
    if not callable(getattr(cls, "sample", None)):
        raise ConfigError(f"{where} kind", f"{kind} has no sample(t) method returning {WHAT}")
    try:
        obj = cls(**kwargs)
    except TypeError as err:
        bad = re.search(r"keyword argument '(\w+)'", str(err))
        key = f"{where.replace('[reference]', '[reference.params]')}{' ' + bad.group(1) if bad else ''}"
        raise ConfigError(key, f"{name}(**[reference.params]): {err}") from None
    except Exception as err:
        raise ConfigError(f"{where} params", f"{name}(**[reference.params]) raised {one_line(err)}") from None
    first = _row(obj, 0.0)
    if isinstance(first, str):
        raise ConfigError(f"{where} kind", f"{name}.{first} (it must return seven finite numbers {WHAT})")
    return OwnReference(kind, "file" if kind_of == "file" else "module", sha, dict(kwargs), float(speed), obj)
