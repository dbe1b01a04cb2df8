"""Elementary functions whose bits do not depend on the machine (docs/reproducibility.md).

Every sine, cosine, arc tangent, exponential, hyperbolic tangent and hypotenuse that a run computes
goes through this module, in the kernels and in Python alike: ``from mlpfac.elementary import sin``.

(This first form calls :mod:`math`, as the code did before; the project's own forms, built from
correctly rounded arithmetic alone, replace the bodies without changing a name or a signature.)
"""

from __future__ import annotations

import math

from mlpfac.jit import kernel


@kernel("f8(f8)")
def sin(x: float) -> float:
    """sin x."""
    return math.sin(x)


@kernel("f8(f8)")
def cos(x: float) -> float:
    """cos x."""
    return math.cos(x)


@kernel("f8(f8, f8)")
def atan2(y: float, x: float) -> float:
    """The angle of (x, y) in (-pi, pi]."""
    return math.atan2(y, x)


@kernel("f8(f8)")
def asin(x: float) -> float:
    """arcsin x, x in [-1, 1]."""
    return math.asin(x)


@kernel("f8(f8)")
def exp(x: float) -> float:
    """e ** x."""
    return math.exp(x)


@kernel("f8(f8)")
def log(x: float) -> float:
    """The natural logarithm of x > 0."""
    return math.log(x)


@kernel("f8(f8)")
def tanh(x: float) -> float:
    """tanh x."""
    return math.tanh(x)


@kernel("f8(f8, f8)")
def hypot(x: float, y: float) -> float:
    """sqrt(x x + y y), each operation rounded once (not :func:`math.hypot`, which differs between
    Python builds)."""
    return math.sqrt(x * x + y * y)
