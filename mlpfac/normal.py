"""Normal deviates whose bits do not depend on the machine (docs/reproducibility.md).

numpy's ``Generator.standard_normal`` and ``normal`` (a ziggurat) call the C library's ``exp`` for
the deviates that fall in a wedge of the ziggurat and ``log1p`` for those in its tail (beyond 3.65):
those deviates' bits follow the machine's maths library. Here the Generator gives uniform doubles
only (integer arithmetic and an exact scaling, the same bits everywhere), and Box and Muller's
transform makes each pair of them a pair of independent standard normal deviates through
:mod:`mlpfac.elementary`: z0 = sqrt(-2 log u0) cos(2 pi u1), z1 = sqrt(-2 log u0) sin(2 pi u1).
n deviates take 2 ceil(n / 2) uniforms of the stream.
"""

from __future__ import annotations

import math

import numpy as np

from mlpfac.elementary import TWO_PI, log, sincos
from mlpfac.jit import kernel


@kernel("void(f8[::1], f8[::1])")
def box_muller(u, out):
    """out[2i], out[2i + 1] = the deviates of the uniforms u[2i], u[2i + 1] in [0, 1)."""
    for i in range(0, u.shape[0] - 1, 2):
        r = math.sqrt(-2.0 * log(1.0 - u[i]))  # 1 - u in (0, 1], exactly
        s, c = sincos(TWO_PI * u[i + 1])
        out[i] = r * c
        out[i + 1] = r * s


def standard_normal(rng: np.random.Generator, size: int | tuple[int, ...] | None = None) -> np.ndarray | float:
    """Standard normal deviates of shape ``size`` (one float without), as ``rng.standard_normal``."""
    n = 1 if size is None else math.prod((size,) if isinstance(size, int) else size)
    u = rng.random(n + n % 2)
    out = np.empty_like(u)
    box_muller(u, out)
    return float(out[0]) if size is None else out[:n].reshape(size)


def normal(rng: np.random.Generator, loc: float, scale: float, size: int | tuple[int, ...] | None = None):
    """Normal deviates of mean ``loc`` and standard deviation ``scale``, as ``rng.normal``."""
    return loc + scale * standard_normal(rng, size)


CHUNK = 1024  # rows of deviates a stream draws at once


class Stream:
    """Standard normal draws (n, width) of one seeded stream, drawn CHUNK rows at a time: the values
    one draw of ``width`` a step gives, however the steps are grouped. ``rng`` None: zeros."""

    def __init__(self, rng: np.random.Generator | None, width: int) -> None:
        self.rng, self.width, self.left = rng, width, 0

    def take(self, n: int) -> np.ndarray:
        out = np.zeros((n, self.width))
        i = 0
        while self.rng is not None and i < n:
            if not self.left:
                self.buf, self.left = standard_normal(self.rng, (CHUNK, self.width)), CHUNK
            j = CHUNK - self.left
            k = min(n - i, self.left)
            out[i : i + k] = self.buf[j : j + k]
            self.left -= k
            i += k
        return out
