"""mlpfac.elementary and mlpfac.normal: accuracy in units in the last place against 200-bit
references (mpmath) on the arguments runs meet, known values at zeros, infinities and NaN, the
compiled forms against the same source run as plain Python (the same bits), and no kernel module
calling the C library's maths."""

from __future__ import annotations

import ast
import importlib
import math
import types
from pathlib import Path

import mpmath
import numpy as np
import pytest

import mlpfac.jit
from mlpfac import elementary as el
from mlpfac.normal import box_muller, standard_normal

mpmath.mp.prec = 200
N = 10_000  # random arguments per domain


def ulps(got: float, ref) -> float:
    """|got - ref| in units in the last place of ref (the spacing of the doubles at ref's binade)."""
    r = float(ref)
    if r == 0.0:
        return 0.0 if got == 0.0 else math.inf
    e = math.frexp(abs(r))[1]
    if abs(r) == 2.0 ** (e - 1) and abs(ref) < abs(r):  # ref just below a power of two
        e -= 1
    return float(abs(mpmath.mpf(got) - ref)) / math.ldexp(1.0, max(e - 53, -1074))


def rng_args(seed: int, lo: float, hi: float, log: bool = False, signed: bool = False, n: int = N) -> np.ndarray:
    """n arguments uniform in [lo, hi], or in [10^lo, 10^hi] (log), of random signs (signed)."""
    g = np.random.default_rng(seed)
    x = 10.0 ** g.uniform(lo, hi, n) if log else g.uniform(lo, hi, n)
    return x * np.where(g.random(n) < 0.5, -1.0, 1.0) if signed else x


# name, reference, arguments (a seed of their own each), the largest error allowed in ulp
ONE = [
    ("sin", mpmath.sin, dict(seed=1, lo=-math.pi / 4, hi=math.pi / 4), 1.0),
    ("sin", mpmath.sin, dict(seed=2, lo=-20.0, hi=20.0), 1.0),
    ("sin", mpmath.sin, dict(seed=3, lo=-1, hi=3.5, log=True, signed=True), 1.0),  # headings over thousands of turns
    ("sin", mpmath.sin, dict(seed=4, lo=-12, hi=0, log=True, signed=True), 1.0),  # small errors
    ("sin", mpmath.sin, dict(seed=5, lo=3.5, hi=6.2, log=True, signed=True), 1.0),  # up to 1.6e6 rad
    ("cos", mpmath.cos, dict(seed=6, lo=-math.pi / 4, hi=math.pi / 4), 1.0),
    ("cos", mpmath.cos, dict(seed=7, lo=-20.0, hi=20.0), 1.0),
    ("cos", mpmath.cos, dict(seed=8, lo=-1, hi=3.5, log=True, signed=True), 1.0),
    ("cos", mpmath.cos, dict(seed=9, lo=3.5, hi=6.2, log=True, signed=True), 1.0),
    ("atan", mpmath.atan, dict(seed=10, lo=-8, hi=8, log=True, signed=True), 1.0),
    ("asin", mpmath.asin, dict(seed=11, lo=-1.0, hi=1.0), 1.0),
    ("asin", mpmath.asin, dict(seed=12, lo=-10, hi=0, log=True, signed=True), 1.0),
    ("exp", mpmath.exp, dict(seed=13, lo=-700.0, hi=700.0), 1.0),
    ("exp", mpmath.exp, dict(seed=14, lo=-12, hi=0, log=True, signed=True), 1.0),
    ("log", mpmath.log, dict(seed=15, lo=-300, hi=300, log=True), 1.0),
    ("log", mpmath.log, dict(seed=16, lo=0.5, hi=2.0), 1.0),
    ("tanh", mpmath.tanh, dict(seed=17, lo=-1.0, hi=1.0), 1.0),  # sigmoid arguments: tanh(a / 2)
    ("tanh", mpmath.tanh, dict(seed=18, lo=-12, hi=1.4, log=True, signed=True), 1.0),
]
TWO = [
    ("atan2", mpmath.atan2, 19, (-3, 3), 1.0),  # every quadrant, |y / x| from 1e-6 to 1e6
    ("atan2", mpmath.atan2, 20, (-300, 300), 1.0),  # far from 1 and near overflow and underflow
    ("hypot", lambda x, y: mpmath.sqrt(x * x + y * y), 21, (-3, 3), 1.5),  # sqrt(x x + y y): rounded three times
]


@pytest.mark.parametrize("name, ref, domain, most", ONE, ids=[f"{c[0]}-{i}" for i, c in enumerate(ONE)])
def test_one_argument_functions_are_within_an_ulp(name, ref, domain, most):
    x = rng_args(**domain)
    got = el.each(getattr(el, name), x)
    err = max(ulps(g, ref(mpmath.mpf(a))) for g, a in zip(got.tolist(), x.tolist(), strict=True))
    assert err < most, f"{name}: {err:.3f} ulp"


@pytest.mark.parametrize("name, ref, seed, decades, most", TWO, ids=[f"{c[0]}-{c[2]}" for c in TWO])
def test_two_argument_functions_are_within_an_ulp(name, ref, seed, decades, most):
    g = np.random.default_rng(seed)
    y, x = (10.0 ** g.uniform(*decades, N) * np.where(g.random(N) < 0.5, -1.0, 1.0) for _ in range(2))
    got = el.each(getattr(el, name), y, x)
    err = max(
        ulps(r, ref(mpmath.mpf(a), mpmath.mpf(b))) for r, a, b in zip(got.tolist(), y.tolist(), x.tolist(), strict=True)
    )
    assert err < most, f"{name}: {err:.3f} ulp"


def test_the_reduction_is_exact_next_to_multiples_of_pi_over_2():
    """The doubles nearest n pi/2 (where sine or cosine cancels most) up to 2^20 pi/2, within an ulp."""
    pio2 = mpmath.pi / 2
    ns = np.unique(np.r_[1:200, np.random.default_rng(22).integers(200, 2**20, 600)])
    for n in ns.tolist():
        x = float(n * pio2)
        for name, ref in (("sin", mpmath.sin), ("cos", mpmath.cos)):
            err = ulps(getattr(el, name)(x), ref(mpmath.mpf(x)))
            assert err < 1.0, f"{name}({x!r}) (n = {n}): {err:.3f} ulp"


def test_beyond_the_exact_reduction_sine_is_finite_and_deterministic():
    for x in (2.0e6, 1.0e15, 1.0e300, -1.7976931348623157e308):
        s, c = el.sin(x), el.cos(x)
        assert -1.0 <= s <= 1.0 and -1.0 <= c <= 1.0 and abs(s * s + c * c - 1.0) < 1e-15
        assert abs(s - float(mpmath.sin(mpmath.fmod(mpmath.mpf(x), mpmath.mpf(el.TWO_PI))))) < 1e-15
    assert abs(el.sin(2.0e6) - math.sin(2.0e6)) < 1e-9  # |x| 4e-17 away from sin x


def bits(x: float) -> tuple[float, bool]:
    return (x, math.copysign(1.0, x) > 0) if x == x else ("nan", True)


INF, NAN = math.inf, math.nan
KNOWN = [
    ("sin", (0.0,), 0.0),
    ("sin", (-0.0,), -0.0),
    ("sin", (INF,), NAN),
    ("sin", (NAN,), NAN),
    ("cos", (0.0,), 1.0),
    ("cos", (-INF,), NAN),
    ("atan", (-0.0,), -0.0),
    ("atan", (INF,), math.pi / 2),
    ("atan", (-INF,), -math.pi / 2),
    ("asin", (1.0,), math.pi / 2),
    ("asin", (-1.0,), -math.pi / 2),
    ("asin", (-0.0,), -0.0),
    ("asin", (1.0000000000000002,), NAN),
    ("exp", (0.0,), 1.0),
    ("exp", (-INF,), 0.0),
    ("exp", (INF,), INF),
    ("exp", (710.0,), INF),
    ("exp", (-746.0,), 0.0),
    ("exp", (NAN,), NAN),
    ("log", (1.0,), 0.0),
    ("log", (0.0,), -INF),
    ("log", (-1.0,), NAN),
    ("log", (INF,), INF),
    ("log", (5e-324,), -744.4400719213812),
    ("tanh", (-0.0,), -0.0),
    ("tanh", (INF,), 1.0),
    ("tanh", (-30.0,), -1.0),
    ("tanh", (NAN,), NAN),
    ("hypot", (3.0, 4.0), 5.0),
]
# atan2 at zeros and infinities: C99's Annex F, the same in every C library
EDGES = [0.0, -0.0, 1.0, -1.0, INF, -INF, NAN]
KNOWN += [("atan2", (y, x), math.atan2(y, x) if x == x and y == y else NAN) for y in EDGES for x in EDGES]


@pytest.mark.parametrize("name, args, want", KNOWN)
def test_known_values(name, args, want):
    assert bits(getattr(el, name)(*args)) == bits(want)


def plain_module():
    """mlpfac/elementary.py run as plain Python: its source executed with :func:`mlpfac.jit.kernel`
    marking nothing."""
    src = Path(el.__file__).read_text()
    mod = types.ModuleType("elementary_plain")
    real = mlpfac.jit.kernel
    mlpfac.jit.kernel = lambda *a, **k: lambda fn: fn
    try:
        exec(compile(src, "elementary_plain", "exec"), mod.__dict__)
    finally:
        mlpfac.jit.kernel = real
    return mod


def test_compiled_and_plain_python_give_the_same_bits():
    plain = plain_module()
    g = np.random.default_rng(23)
    x = np.r_[g.uniform(-10.0, 10.0, 1500), 10.0 ** g.uniform(-10, 6.5, 1500) * np.where(g.random(1500) < 0.5, -1, 1)]
    y = g.permutation(x)
    for name in ("sin", "cos", "atan", "asin", "exp", "log", "tanh"):
        args = np.clip(x, -1.0, 1.0) if name == "asin" else np.abs(x) if name == "log" else x
        compiled = [getattr(el, name)(a) for a in args.tolist()]
        assert compiled == [getattr(plain, name)(a) for a in args.tolist()], name
        assert el.each(getattr(el, name), args).tolist() == compiled, f"{name}: the array loop"
    for name in ("atan2", "hypot"):
        compiled = [getattr(el, name)(a, b) for a, b in zip(y.tolist(), x.tolist(), strict=True)]
        assert compiled == [getattr(plain, name)(a, b) for a, b in zip(y.tolist(), x.tolist(), strict=True)], name
    s, c = zip(*(plain.sincos(a) for a in x.tolist()), strict=True)
    assert list(s) == [el.sin(a) for a in x.tolist()] and list(c) == [el.cos(a) for a in x.tolist()]
    assert isinstance(el.sin(1.0), float) and isinstance(plain.tanh(0.5), float)


def test_normal_deviates_are_box_muller_of_the_generators_uniforms():
    """Two uniforms a pair, in order: a long draw gives the values of draws of any even size in turn,
    and the deviates are standard normal (mean, variance and a Kolmogorov-Smirnov distance)."""
    z = standard_normal(np.random.default_rng(24), (50_000, 3))
    g = np.random.default_rng(24)
    parts = np.concatenate([standard_normal(g, (k, 2)).ravel() for k in (1, 3, 7, 74_989)])
    assert np.array_equal(parts, z.ravel()[: parts.size])
    u = np.random.default_rng(24).random(4)
    r = math.sqrt(-2.0 * el.log(1.0 - u[0]))
    assert z.ravel()[:2].tolist() == [r * el.cos(el.TWO_PI * u[1]), r * el.sin(el.TWO_PI * u[1])]
    assert abs(z.mean()) < 0.01 and abs(z.var() - 1.0) < 0.01
    s = np.sort(z.ravel())
    cdf = np.array([0.5 * math.erfc(-v / math.sqrt(2.0)) for v in s.tolist()])
    assert np.max(np.abs(cdf - np.arange(1, s.size + 1) / s.size)) < 0.01
    assert isinstance(standard_normal(np.random.default_rng(0)), float)
    out = np.full(3, 7.0)
    box_muller(np.array([0.0, 0.25, 0.5]), out)  # u0 = 0: radius 0; an odd last uniform is left
    assert out.tolist() == [0.0, 0.0, 7.0]


# The C library's functions of doubles that round: a kernel calling one (math.sin in numba is the C
# library's sin) gives other bits on another machine
LIBM = {"sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh", "acosh"}
LIBM |= {"atanh", "exp", "expm1", "log", "log1p", "log2", "log10", "pow", "hypot", "cbrt", "erf", "erfc"}
LIBM |= {"gamma", "lgamma", "exp2"}


@pytest.mark.parametrize("module", [m for ms in mlpfac.jit.MODULES.values() for m in ms])
def test_no_kernel_module_calls_the_c_librarys_maths(module):
    tree = ast.parse(Path(importlib.util.find_spec(module).origin).read_text())
    calls = [
        f"math.{n.attr} (line {n.lineno})"
        for n in ast.walk(tree)
        if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id in ("math", "np")
        if n.attr in LIBM or n.attr in {"arctan2", "arcsin", "power"}
    ]
    assert not calls, f"{module}: {calls}: use mlpfac.elementary's"
