"""Your own reference as an mlpfac plug-in: an ellipse, with its speeds and their rates in closed form.
Copy this file and change ``sample``.

Name it in a scenario file (relative to the file's folder), its parameters in ``[reference.params]``:

    [reference]
    kind = "my_route.py:Ellipse"
    speed = 1.0            # optional: the same ellipse this many times as fast, as for every kind

    [reference.params]
    a = 2.0
    b = 1.0

and run it, or vary a parameter by its dotted key:

    mlpfac run my_ellipse.toml --controller kanayama
    mlpfac sweep my_ellipse.toml --controllers kanayama,corradini --seeds 0-4 --vary reference.params.b=0.5:1.5:3

The contract (mlpfac.scenario.own_reference): a class built as ``Class(**[reference.params])`` whose
``sample(t)`` returns seven numbers (x, y, theta, v, omega, dv, domega) at time t in s: the pose
(m, rad), the speeds (m/s, rad/s) and their rates (m/s^2, rad/s^2, what a torque-level controller is
given as r_dot). It is checked at t = 0 before anything runs; a value that is not finite later ends the
run there, as diverged. mlpfac.elementary's sine, cosine and arc tangent give the same bits on every
processor (math's may not, from one C library to another; its sqrt is exact).
"""

from __future__ import annotations

from math import sqrt

from mlpfac.elementary import atan2, cos, sin


class Ellipse:
    """x = cx + a cos(w t), y = cy + b sin(w t): counter-clockwise, once round every 2 pi / w s."""

    def __init__(self, a: float = 2.0, b: float = 1.0, w: float = 0.4, cx: float = 0.0, cy: float = 0.0) -> None:
        if not (a > 0 and b > 0 and w > 0):
            raise ValueError(f"a, b and w must be positive, got a={a}, b={b}, w={w}")
        self.a, self.b, self.w, self.cx, self.cy = a, b, w, cx, cy

    def sample(self, t: float) -> tuple[float, float, float, float, float, float, float]:
        a, b, w = self.a, self.b, self.w
        s, c = sin(w * t), cos(w * t)
        dx, dy = -a * w * s, b * w * c  # the velocity
        q = a * a * s * s + b * b * c * c  # |velocity|^2 / w^2
        dq = 2.0 * w * (a * a - b * b) * s * c  # its rate
        v = w * sqrt(q)
        omega = a * b * w / q  # (dx ddy - dy ddx) / v^2
        dv = w * dq / (2.0 * sqrt(q))
        domega = -a * b * w * dq / (q * q)
        return self.cx + a * c, self.cy + b * s, atan2(dy, dx), v, omega, dv, domega
