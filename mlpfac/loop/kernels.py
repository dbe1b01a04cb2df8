"""The runner's divergence test, compiled and batch-first as the other kernels (:mod:`mlpfac.jit`):
the step and the compiled closed loop (:mod:`mlpfac.loop.compiled`) stop a seed with it."""

from __future__ import annotations

import math

from mlpfac.elementary import hypot
from mlpfac.jit import kernel


@kernel("i8(f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], f8, b1[::1])")
def bad_seeds(q, u, e_true, z, limit, bad):
    """The runner's divergence test for B seeds: bad[b] when the pose or the command is not finite, the
    weights z (B, alpha) (or (B, 0)) are not, or the position error exceeds ``limit``. Returns the count."""
    n = 0
    for b in range(q.shape[0]):
        s = q[b, 0] + q[b, 1] + q[b, 2] + u[b, 0] + u[b, 1]
        for i in range(z.shape[1]):
            s += z[b, i] * 0.0
        x = hypot(e_true[b, 0], e_true[b, 1])
        bad[b] = not (math.isfinite(s) and x <= limit)
        n += bad[b]
    return n
