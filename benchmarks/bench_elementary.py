"""The cost of one call of mlpfac.elementary's functions against the C library's (``math``), in a
compiled loop, and their largest error. Not a test.

    python benchmarks/bench_elementary.py [--n 1000000] [--rounds 7] [--ulps 100000]

Each function is called on n arguments of the range that runs meet (headings of a few turns,
angles within a turn, sigmoid arguments, ...) inside a numba kernel that sums the results; the best
of the rounds' CPU time per call is printed, ours against math's (which numba compiles to the C
library's function; numba compiles mlpfac's kernels here, ``MLPFAC_KERNELS=jit``, so that they can
be called from the loop). With ``--ulps N``: the largest error in units in the last place over N
random arguments of each domain of tests/test_elementary.py (which checks 10000 of each), against
mpmath at 200 bits, ours and the C library's.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

os.environ["MLPFAC_KERNELS"] = "jit"  # numba's dispatchers, which a numba loop can call (not the built module's)

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from mlpfac import elementary as el  # noqa: E402


def looped(fn, two: bool):
    if two:

        @njit
        def loop(a, b):
            s = 0.0
            for i in range(a.shape[0]):
                s += fn(a[i], b[i])
            return s

    else:

        @njit
        def loop(a, b):
            s = 0.0
            for i in range(a.shape[0]):
                s += fn(a[i])
            return s

    return loop


def math_of(name: str):
    f = getattr(math, name)
    return njit(lambda *a: f(*a))


CASES = {  # name: (arguments' range of the first, of the second or None)
    "sin": ((-20.0, 20.0), None),
    "cos": ((-20.0, 20.0), None),
    "atan2": ((-2.0, 2.0), (-2.0, 2.0)),
    "asin": ((-1.0, 1.0), None),
    "exp": ((-10.0, 10.0), None),
    "log": ((1e-3, 1e3), None),
    "tanh": ((-8.0, 8.0), None),
    "hypot": ((-2.0, 2.0), (-2.0, 2.0)),
}


def accuracy(n: int) -> None:
    """The largest error in ulp per function over the test's domains, ours and math's."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("t", Path(__file__).resolve().parents[1] / "tests/test_elementary.py")
    t = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(t)
    worst: dict[str, list[float]] = {}
    cases = [(name, ref, (t.rng_args(**domain, n=n),)) for name, ref, domain, _ in t.ONE]
    for name, ref, seed, decades, _ in t.TWO:
        g = np.random.default_rng(seed)
        cases.append(
            (name, ref, tuple(10.0 ** g.uniform(*decades, n) * np.where(g.random(n) < 0.5, -1, 1) for _ in "yx"))
        )
    for name, ref, xs in cases:
        ours = el.each(getattr(el, name), *xs).tolist()
        theirs = [getattr(math, name)(*a) for a in zip(*(x.tolist() for x in xs), strict=True)]
        refs = [ref(*(t.mpmath.mpf(v) for v in a)) for a in zip(*(x.tolist() for x in xs), strict=True)]
        w = worst.setdefault(name, [0.0, 0.0])
        w[0] = max(w[0], max(t.ulps(o, r) for o, r in zip(ours, refs, strict=True)))
        w[1] = max(w[1], max(t.ulps(o, r) for o, r in zip(theirs, refs, strict=True)))
    print(f"{'function':8s} {'ours ulp':>9s} {'math ulp':>9s}  (largest error, {n} arguments a domain)")
    for name, (a, b) in worst.items():
        print(f"{name:8s} {a:9.3f} {b:9.3f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1_000_000)
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--ulps", type=int, default=0, help="measure the largest errors over this many arguments a domain")
    args = p.parse_args()
    if args.ulps:
        accuracy(args.ulps)
        return
    rng = np.random.default_rng(0)
    print(f"{'function':8s} {'ours ns':>8s} {'math ns':>8s} {'ratio':>6s}")
    for name, (ra, rb) in CASES.items():
        a = rng.uniform(*ra, args.n)
        b = rng.uniform(*rb, args.n) if rb else a
        ours, theirs = looped(getattr(el, name), rb is not None), looped(math_of(name), rb is not None)
        ours(a[:10], b[:10]), theirs(a[:10], b[:10])  # compile
        best = {}
        for _ in range(args.rounds):
            for label, loop in (("ours", ours), ("math", theirs)):
                t = time.process_time()
                loop(a, b)
                best[label] = min(best.get(label, math.inf), (time.process_time() - t) / args.n * 1e9)
        print(f"{name:8s} {best['ours']:8.1f} {best['math']:8.1f} {best['ours'] / best['math']:6.2f}")


if __name__ == "__main__":
    main()
