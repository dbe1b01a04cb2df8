"""Elementary functions whose bits do not depend on the machine (docs/reproducibility.md).

Every sine, cosine, arc tangent, arc sine, exponential, logarithm, hyperbolic tangent and hypotenuse
that a run computes goes through this module, in the kernels and in Python alike: ``from
mlpfac.elementary import sin`` (a kernel may call them; so may Python, one number at a time, or an
array at a time with :func:`each`).

They are the project's own, not the C library's: built from the operations IEEE 754 rounds
correctly on every machine (+, -, *, /, sqrt), from exact ones (comparisons, ``abs``,
``copysign``, ``frexp`` and ``ldexp``, which only move the exponent) and from exact splits of a
number into two (Dekker's product and Knuth's sum, which need each operation rounded once). numba
compiles them without fast-math, so nothing is fused into a multiply-add or reordered: they give the
same bits compiled or run as plain Python, on any x86-64 (or other IEEE 754) machine. ``math.sin``,
``math.hypot`` and the like do not: the C library's and the Python build's own functions differ in
the last bit between machines.

The algorithms and their minimax coefficients are those of fdlibm (Sun Microsystems, 1993: "Developed
at SunSoft, a Sun Microsystems, Inc. business. Permission to use, copy, modify, and distribute this
software is freely granted, provided that this notice is preserved."): argument reduction by pi/2
in three parts of 33 bits and the kernel polynomials of sine and cosine, arc tangent by a table of
four points and an odd polynomial, arc sine by a rational function, the exponential by a reduction
by ln 2 and a Remez polynomial, the logarithm by log(1 + f) = 2 atanh(f / (2 + f)). Where the C
library's form rounds twice on the way out (atan2 of a quotient, tanh from expm1), the last step
here is done in two-double arithmetic, so that one rounding is left.

Accuracy (``tests/test_elementary.py``, against 200-bit references): below one unit in the last
place on the domains a run meets; the measured maxima are in docs/reproducibility.md. Sine and
cosine are that accurate for |x| < 2^20 pi/2 (about 1.6e6 rad); beyond, x is first reduced exactly
modulo 2 pi rounded to a double, a deterministic, finite result whose absolute error grows as
|x| 4e-17.
"""

from __future__ import annotations

import math

import numpy as np

from mlpfac.jit import kernel

INF, NAN = math.inf, math.nan
ROUND = 6755399441055744.0  # 1.5 * 2**52: (x + ROUND) - ROUND is x rounded to an integer, |x| < 2**51
SPLIT = 134217729.0  # 2**27 + 1, Veltkamp's splitter
PI, PI_LO = 3.141592653589793, 1.2246467991473532e-16  # pi = PI + PI_LO to 107 bits
PIO2_HI, PIO2_LO = 1.5707963267948966, 6.123233995736766e-17
PIO4 = 0.7853981633974483
TWO_PI = 6.283185307179586

# pi/2 = PIO2_1 + PIO2_2 + PIO2_3 + PIO2_3T, the first three of 33 bits each: n * PIO2_k is exact
# for |n| <= 2**20, so the reduction is exact up to REDUCE_MAX.
INVPIO2 = 0.6366197723675814
PIO2_1, PIO2_2, PIO2_3, PIO2_3T = 1.5707963267341256, 6.077100506303966e-11, 2.0222662487111665e-21, 8.4784276603689e-32
REDUCE_MAX = 1647099.0  # about 2**20 pi/2

# sin(x) ~ x + S1 x^3 + ... + S6 x^13 and cos(x) ~ 1 - x^2/2 + C1 x^4 + ... + C6 x^14 on [-pi/4, pi/4]
S1, S2, S3 = -0.16666666666666632, 0.00833333333332249, -0.0001984126982985795
S4, S5, S6 = 2.7557313707070068e-06, -2.5050760253406863e-08, 1.58969099521155e-10
C1, C2, C3 = 0.0416666666666666, -0.001388888888887411, 2.480158728947673e-05
C4, C5, C6 = -2.7557314351390663e-07, 2.087572321298175e-09, -1.1359647557788195e-11

# atan(c) = ATANHI + ATANLO at c = 0.5, 1, 1.5, inf; atan(x) ~ x - x^3 (AT0 + AT1 x^2 + ... + AT10 x^20)
ATANHI0, ATANHI1, ATANHI2 = 0.4636476090008061, 0.7853981633974483, 0.982793723247329
ATANLO0, ATANLO1, ATANLO2 = 2.2698777452961687e-17, 3.061616997868383e-17, 1.3903311031230998e-17
AT0, AT1, AT2, AT3 = 0.3333333333333293, -0.19999999999876483, 0.14285714272503466, -0.11111110405462356
AT4, AT5, AT6, AT7 = 0.09090887133436507, -0.0769187620504483, 0.06661073137387531, -0.058335701337905735
AT8, AT9, AT10 = 0.049768779946159324, -0.036531572744216916, 0.016285820115365782

# asin(x) ~ x + x^3 P(x^2) / Q(x^2) on [0, 0.5]
PS0, PS1, PS2 = 0.16666666666666666, -0.3255658186224009, 0.20121253213486293
PS3, PS4, PS5 = -0.04005553450067941, 0.0007915349942898145, 3.479331075960212e-05
QS1, QS2, QS3, QS4 = -2.403394911734414, 2.0209457602335057, -0.6882839716054533, 0.07703815055590194

# ln 2 = LN2HI + LN2LO, LN2HI of 32 bits (k LN2HI exact for |k| < 2**21); r (e^r + 1) / (e^r - 1) ~ 2 + P1 r^2 + ...
LN2HI, LN2LO, INVLN2 = 0.6931471803691238, 1.9082149292705877e-10, 1.4426950408889634
P1, P2, P3 = 0.16666666666666602, -0.0027777777777015593, 6.613756321437934e-05
P4, P5 = -1.6533902205465252e-06, 4.1381367970572385e-08
EXP_MAX, EXP_MIN = 709.782712893384, -745.1332191019411  # e^x overflows above, is 0 below
# log(1 + f) = 2 s + s R(s^2), s = f / (2 + f), R(z) ~ LG1 z + ... + LG7 z^7
LG1, LG2, LG3, LG4 = 0.6666666666666735, 0.3999999999940942, 0.2857142874366239, 0.22222198432149784
LG5, LG6, LG7 = 0.1818357216161805, 0.15313837699209373, 0.14798198605116586
SQRT_HALF = 0.7071067811865476
POW2 = np.array([math.ldexp(1.0, k) for k in range(-1022, 1024)])  # 2^k, exact: a product by it is ldexp's


# -- exact splits ---------------------------------------------------------------------------------


@kernel()
def _two_sum(a, b):
    """a + b = s + e exactly (Knuth)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


@kernel()
def _two_prod(a, b):
    """a b = p + e exactly (Dekker, Veltkamp's split), for |a|, |b| < 2**995 and a b far from underflow."""
    p = a * b
    c = SPLIT * a
    ah = c - (c - a)
    al = a - ah
    c = SPLIT * b
    bh = c - (c - b)
    bl = b - bh
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


# -- sine and cosine ------------------------------------------------------------------------------


@kernel()
def _ksin(x, y):
    """sin(x + y), |x + y| <= pi/4 about, y the tail of x."""
    z = x * x
    w = z * z
    r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6)
    v = z * x
    if y == 0.0:
        return x + v * (S1 + z * r)
    return x - ((z * (0.5 * y - v * r) - y) - v * S1)


@kernel()
def _kcos(x, y):
    """cos(x + y), |x + y| <= pi/4 about, y the tail of x."""
    z = x * x
    w = z * z
    r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * y))


@kernel()
def _mod_2pi(x):
    """x modulo TWO_PI, exactly (fmod's result, by subtracting TWO_PI 2^j while it fits: each difference exact)."""
    a = abs(x)
    e = math.frexp(a)[1]
    c = math.ldexp(TWO_PI, e - 3)  # a < 2 c
    while c >= TWO_PI:
        if a >= c:
            a -= c
        c *= 0.5
    return math.copysign(a, x)


@kernel()
def _reduce(x):
    """x = n pi/2 + (y0 + y1) with |y0 + y1| <= pi/4 about, y1 the tail of y0: (n mod 4, y0, y1).

    Cody and Waite's reduction, pi/2 in four parts, for finite x; beyond REDUCE_MAX, x modulo
    TWO_PI first."""
    if not abs(x) < REDUCE_MAX:
        x = _mod_2pi(x)
    fn = (x * INVPIO2 + ROUND) - ROUND
    r = x - fn * PIO2_1  # exact: fn PIO2_1 is, and x is within a factor 2 of it
    r, e2 = _two_sum(r, -fn * PIO2_2)
    r, e3 = _two_sum(r, -fn * PIO2_3)
    w = fn * PIO2_3T - (e2 + e3)
    y0 = r - w
    return int(fn) & 3, y0, (r - y0) - w


@kernel()
def sincos(x):
    """(sin x, cos x), one reduction for both."""
    if abs(x) <= PIO4:
        if abs(x) < 7.450580596923828e-09:  # 2**-27: sin x = x, cos x = 1 to the last bit
            return x, 1.0
        return _ksin(x, 0.0), _kcos(x, 0.0)
    if not abs(x) < INF:
        return x - x, x - x
    n, y0, y1 = _reduce(x)
    s, c = _ksin(y0, y1), _kcos(y0, y1)
    if n == 0:
        return s, c
    if n == 1:
        return c, -s
    if n == 2:
        return -s, -c
    return -c, s


@kernel("f8(f8)")
def sin(x: float) -> float:
    """sin x."""
    if abs(x) <= PIO4:
        if abs(x) < 7.450580596923828e-09:
            return x
        return _ksin(x, 0.0)
    if not abs(x) < INF:
        return x - x
    n, y0, y1 = _reduce(x)
    if n == 0:
        return _ksin(y0, y1)
    if n == 1:
        return _kcos(y0, y1)
    if n == 2:
        return -_ksin(y0, y1)
    return -_kcos(y0, y1)


@kernel("f8(f8)")
def cos(x: float) -> float:
    """cos x."""
    if abs(x) <= PIO4:
        if abs(x) < 7.450580596923828e-09:
            return 1.0
        return _kcos(x, 0.0)
    if not abs(x) < INF:
        return x - x
    n, y0, y1 = _reduce(x)
    if n == 0:
        return _kcos(y0, y1)
    if n == 1:
        return -_ksin(y0, y1)
    if n == 2:
        return -_kcos(y0, y1)
    return _ksin(y0, y1)


# -- arc tangent and arc sine ---------------------------------------------------------------------


@kernel()
def _atan_parts(t, dt):
    """atan(t + dt) = H - S, t >= 0 finite, |dt| <= ulp(t): H exact and S small beside it, left for
    the caller to add once (atan2 adds pi to them first)."""
    corr = dt / (1.0 + t * t)  # atan(t + dt) - atan(t), to first order
    if t >= 7.378697629483821e19:  # 2**66: pi/2 to the last bit
        return PIO2_HI, -PIO2_LO - corr
    if t < 0.4375:
        if t < 7.450580596923828e-09:  # 2**-27: atan t = t to the last bit
            return t, -corr
        hi, lo, x = 0.0, 0.0, t
    elif t < 0.6875:
        hi, lo, x = ATANHI0, ATANLO0, (2.0 * t - 1.0) / (2.0 + t)
    elif t < 1.1875:
        hi, lo, x = ATANHI1, ATANLO1, (t - 1.0) / (t + 1.0)
    elif t < 2.4375:
        hi, lo, x = ATANHI2, ATANLO2, (t - 1.5) / (1.0 + 1.5 * t)
    else:
        hi, lo, x = PIO2_HI, PIO2_LO, -1.0 / t
    z = x * x
    w = z * z
    s1 = z * (AT0 + w * (AT2 + w * (AT4 + w * (AT6 + w * (AT8 + w * AT10)))))
    s2 = w * (AT1 + w * (AT3 + w * (AT5 + w * (AT7 + w * AT9))))
    if hi == 0.0:
        return t, t * (s1 + s2) - corr
    return hi, ((x * (s1 + s2) - lo) - x) - corr


@kernel("f8(f8)")
def atan(x: float) -> float:
    """The arc tangent of x, in [-pi/2, pi/2]."""
    if x != x:
        return x
    H, S = _atan_parts(abs(x), 0.0)
    return math.copysign(H - S, x)


@kernel("f8(f8, f8)")
def atan2(y: float, x: float) -> float:
    """The angle of (x, y) in [-pi, pi], C's atan2 at zeros and infinities: atan2(+-0, -0) = +-pi,
    atan2(+-0, +0) = +-0."""
    if x != x or y != y:
        return x + y
    ax, ay = abs(x), abs(y)
    if ay == 0.0:
        return y if math.copysign(1.0, x) > 0.0 else math.copysign(PI, y)
    if ax == 0.0 or ay == INF and ax < INF:
        return math.copysign(PIO2_HI, y)
    if ax == INF:
        if ay == INF:
            return math.copysign(PIO4 if x > 0.0 else 2.356194490192345, y)
        return math.copysign(0.0 if x > 0.0 else PI, y)
    q = ay / ax
    if q > 1.152921504606847e18:  # 2**60: pi/2 to the last bit
        return math.copysign(PIO2_HI, y)
    if q < 8.673617379884035e-19:  # 2**-60: atan q = q, pi - q = pi, to the last bit
        return math.copysign(q, y) if x > 0.0 else math.copysign(PI, y)
    xs, ys = ax, ay
    if not 1e-200 < ax < 1e200:  # scaled by a power of two, so that q x is split exactly
        m, e = math.frexp(ax)
        xs, ys = m, math.ldexp(ay, -e)
    p, pe = _two_prod(q, xs)
    dq = ((ys - p) - pe) / xs  # q + dq = y / x to twice the precision
    H, S = _atan_parts(q, dq)
    if x > 0.0:
        return math.copysign(H - S, y)
    a, b = _two_sum(PI, -H)  # pi - (H - S), rounded once
    return math.copysign(a + ((b + PI_LO) + S), y)


@kernel("f8(f8)")
def asin(x: float) -> float:
    """arcsin x, x in [-1, 1] (NaN outside)."""
    if x != x:
        return x
    ax = abs(x)
    if ax >= 1.0:
        return math.copysign(PIO2_HI, x) if ax == 1.0 else NAN
    if ax < 0.5:
        if ax < 1.4901161193847656e-08:  # 2**-26: asin x = x to the last bit
            return x
        t = x * x
        p = t * (PS0 + t * (PS1 + t * (PS2 + t * (PS3 + t * (PS4 + t * PS5)))))
        q = 1.0 + t * (QS1 + t * (QS2 + t * (QS3 + t * QS4)))
        return x + x * (p / q)
    # asin x = pi/2 - 2 asin(sqrt((1 - x) / 2))
    t = 0.5 * (1.0 - ax)
    p = t * (PS0 + t * (PS1 + t * (PS2 + t * (PS3 + t * (PS4 + t * PS5)))))
    q = 1.0 + t * (QS1 + t * (QS2 + t * (QS3 + t * QS4)))
    s = math.sqrt(t)
    if ax >= 0.975:
        r = PIO2_HI - (2.0 * (s + s * (p / q)) - PIO2_LO)
    else:
        c = SPLIT * s
        f = c - (c - s)  # s to 26 bits: f f is exact
        c = (t - f * f) / (s + f)  # f + c = sqrt(t) to twice the precision
        r = PIO4 - ((2.0 * s * (p / q) - (PIO2_LO - 2.0 * c)) - (PIO4 - 2.0 * f))
    return math.copysign(r, x)


# -- exponential, logarithm, hyperbolic tangent ---------------------------------------------------


@kernel()
def _exp_parts(x):
    """e^x = 2^k (hi + lo) for |x| <= EXP_MAX: (k, hi, lo), hi the double nearest hi + lo, the pair
    good to about 2**-60 relative."""
    kf = (x * INVLN2 + ROUND) - ROUND
    hi = x - kf * LN2HI  # exact
    lo = kf * LN2LO
    r = hi - lo  # |r| <= ln2 / 2 about
    re = (hi - r) - lo  # r + re = hi - lo
    z = r * r
    c = r - z * (P1 + z * (P2 + z * (P3 + z * (P4 + z * P5))))
    a = 1.0 + r
    b = (1.0 - a) + r  # 1 + r = a + b exactly
    # e^r = 1 + r + r c / (2 - c), and e^(r + re) = e^r (1 + re)
    b += (r * c) / (2.0 - c) + re * a
    hi = a + b
    return int(kf), hi, (a - hi) + b


@kernel()
def _scaled(x, k):
    """x 2^k, rounded once (math.ldexp, without its call where 2^k is a normal number)."""
    if -1022 <= k <= 1023:
        return x * float(POW2[k + 1022])
    return math.ldexp(x, k)


@kernel("f8(f8)")
def exp(x: float) -> float:
    """e ** x."""
    if not x <= EXP_MAX:
        return x if x != x else INF
    if x < EXP_MIN:
        return 0.0
    if abs(x) < 3.725290298461914e-09:  # 2**-28: 1 + x to the last bit
        return 1.0 + x
    k, a, b = _exp_parts(x)
    return _scaled(a + b, k)


@kernel("f8(f8)")
def log(x: float) -> float:
    """The natural logarithm of x > 0 (-inf at 0, NaN below)."""
    if not x > 0.0:
        return -INF if x == 0.0 else NAN
    if x == INF:
        return x
    m, k = math.frexp(x)  # x = m 2^k, m in [0.5, 1)
    if m < SQRT_HALF:
        m *= 2.0
        k -= 1
    f = m - 1.0  # exact; 1 + f in [sqrt(1/2), sqrt(2))
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    R = z * (LG1 + w * (LG3 + w * (LG5 + w * LG7))) + w * (LG2 + w * (LG4 + w * LG6))
    hfsq = 0.5 * f * f
    dk = float(k)
    return dk * LN2HI - ((hfsq - (s * (hfsq + R) + dk * LN2LO)) - f)


@kernel("f8(f8)")
def tanh(x: float) -> float:
    """tanh x = (1 - e^-2|x|) / (1 + e^-2|x|), signed, with e^-2|x| and the quotient in two-double
    arithmetic (one rounding at the end)."""
    a = abs(x)
    if not a < 22.0:  # tanh 22 = 1 - 1.6e-19: 1 to the last bit
        return x if x != x else math.copysign(1.0, x)
    if a < 3.725290298461914e-09:  # 2**-28: x to the last bit
        return x
    k, eh, el = _exp_parts(-2.0 * a)
    eh, el = _scaled(eh, k), _scaled(el, k)
    nh, nl = _two_sum(1.0, -eh)  # 1 - e^-2a
    nl -= el
    dh, dl = _two_sum(1.0, eh)  # 1 + e^-2a
    dl += el
    inv = 1.0 / dh
    q = nh * inv  # the quotient to 2 ulp, then corrected by its exact remainder
    p, pe = _two_prod(q, dh)
    return math.copysign(q + (((nh - p) - pe) + nl - q * dl) * inv, x)


@kernel("f8(f8, f8)")
def hypot(x: float, y: float) -> float:
    """sqrt(x x + y y), each operation rounded once (not :func:`math.hypot`, which differs between
    Python builds)."""
    return math.sqrt(x * x + y * y)


# -- on arrays ------------------------------------------------------------------------------------


@kernel("void(f8[::1], f8[::1])")
def sin_each(x, out):
    """out[i] = sin(x[i])."""
    for i in range(x.shape[0]):
        out[i] = sin(x[i])


@kernel("void(f8[::1], f8[::1])")
def cos_each(x, out):
    """out[i] = cos(x[i])."""
    for i in range(x.shape[0]):
        out[i] = cos(x[i])


@kernel("void(f8[::1], f8[::1])")
def tanh_each(x, out):
    """out[i] = tanh(x[i])."""
    for i in range(x.shape[0]):
        out[i] = tanh(x[i])


@kernel("void(f8[::1], f8[::1])")
def exp_each(x, out):
    """out[i] = exp(x[i])."""
    for i in range(x.shape[0]):
        out[i] = exp(x[i])


@kernel("void(f8[::1], f8[::1])")
def log_each(x, out):
    """out[i] = log(x[i])."""
    for i in range(x.shape[0]):
        out[i] = log(x[i])


@kernel("void(f8[::1], f8[::1], f8[::1])")
def atan2_each(y, x, out):
    """out[i] = atan2(y[i], x[i])."""
    for i in range(x.shape[0]):
        out[i] = atan2(y[i], x[i])


@kernel("void(f8[::1], f8[::1], f8[::1])")
def hypot_each(x, y, out):
    """out[i] = hypot(x[i], y[i])."""
    for i in range(x.shape[0]):
        out[i] = hypot(x[i], y[i])


EACH = {
    sin: sin_each,
    cos: cos_each,
    tanh: tanh_each,
    exp: exp_each,
    log: log_each,
    atan2: atan2_each,
    hypot: hypot_each,
}


def each(fn, *xs) -> np.ndarray:
    """``fn`` (a function of this module, or any function of floats built from them) on every element
    of the arrays ``xs``, broadcast together: numpy's own sin, arctan2, hypot, ... take the processor's
    SIMD forms, whose bits depend on the machine. This module's functions run as one compiled loop."""
    arrays = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in xs))
    shape = arrays[0].shape
    loop = EACH.get(fn)
    if loop is None:
        flat = np.fromiter(map(fn, *(a.ravel().tolist() for a in arrays)), float, arrays[0].size)
        return flat.reshape(shape)
    out = np.empty(shape)
    loop(*(np.ascontiguousarray(a).ravel() for a in arrays), out.reshape(-1))
    return out
