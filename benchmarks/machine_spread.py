"""How much a run's figures depend on the machine: the same runs in this process's environment and
in environments that stand in for other machines. Not a test.

    python benchmarks/machine_spread.py [--runs SCENARIO/CONTROLLER/SEED ...] [--environments built,...]
    python benchmarks/machine_spread.py --libm [--environments built,libm-no-fma]

Each environment runs the same runs (full length) in a fresh process, and each run's metrics are
compared with those of the first environment, this machine as it is: bit-identical (the digest of
metrics.json but its wall-clock time, as ``mlpfac report --verify``), or the largest relative
difference of a figure ``runs.json`` keeps, and any outcome that changed. The environments:

- ``built``: the kernels built at install (this machine as it is);
- ``numba``: numba compiles them at run time (``MLPFAC_KERNELS=jit``), for this processor;
- ``numba-generic``: the same for a generic x86-64 processor (``NUMBA_CPU_NAME=generic``), as a
  build on another kind of processor would compile them;
- ``libm-no-fma``: glibc's maths library (exp, sin, cos, atan2, ...) as on a processor without
  FMA and AVX2 (``GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA``: glibc picks its functions by the
  processor's features, and their variants differ in the last bits);
- ``numpy-no-avx512``: numpy without its AVX-512 code (``NPY_DISABLE_CPU_FEATURES``), as on a
  processor with AVX2 alone (a no-op on one without AVX-512);
- ``numpy-baseline``: numpy without its AVX2, FMA and AVX-512 code, as on an older processor;
- ``blas-skylakex``, ``blas-haswell``, ``blas-sandybridge``, ``blas-prescott``: OpenBLAS with the
  kernels of that processor (``OPENBLAS_CORETYPE``) on two threads, as numpy's and scipy's linear
  algebra would run elsewhere (SkylakeX only on a processor with AVX-512: skipped elsewhere).

mlpfac's simulated path calls none of numpy's processor-dispatched maths nor BLAS/LAPACK, and
none of the C library's maths functions (its own, mlpfac.elementary; tests/test_same_bits.py traps
them all), so only ``libm-no-fma`` should move a bit, and only in runs on MuJoCo, whose physics
calls the C library's sin, cos, atan2, ...
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

RUNS = (  # one or two of each kind of run the documented tables hold
    "paper/adaptive/0",
    "paper/kanayama/0",
    "eight-nominal/corradini/0",
    "eight-nominal/adaptive-best/0",
    "eight-sensor-delay/adaptive-input-delay/0",
    "eight-sensor-delay/adaptive-input-delay/1",
    "eight-wheel-radius/adaptive-real/0",
    "eight-friction/oracle/0",
)
ENVIRONMENTS = {
    "built": {},
    "numba": {"MLPFAC_KERNELS": "jit"},
    "numba-generic": {"MLPFAC_KERNELS": "jit", "NUMBA_CPU_NAME": "generic"},
    "libm-no-fma": {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA"},
    "numpy-no-avx512": {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR"},
    "numpy-baseline": {"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"},
    **{
        f"blas-{cpu.lower()}": {"OPENBLAS_CORETYPE": cpu, "OPENBLAS_NUM_THREADS": "2"}
        for cpu in ("SkylakeX", "Haswell", "Sandybridge", "Prescott")
    },
}
PROBE = "import numpy as np; a = np.ones((64, 64)); a @ a"  # OpenBLAS's kernels run on this processor


LIBM = ("sin", "cos", "tan", "atan", "atan2", "exp", "expm1", "log", "log1p", "pow", "tanh", "hypot")
OURS = ("sin", "cos", "atan", "atan2", "exp", "log", "tanh", "hypot")  # mlpfac.elementary's, beside them
ARGUMENTS = 200_000


def libm_child() -> None:
    """Each function of glibc's maths library (through Python's math, as numba's ``math.sin`` calls
    it; MuJoCo calls some), and mlpfac.elementary's, on the same pseudo-random arguments: their bits,
    one JSON object."""
    import math
    import random

    from mlpfac import elementary

    rng = random.Random(1)
    xs = [rng.uniform(-10.0, 10.0) for _ in range(ARGUMENTS)]
    args = {"atan2": lambda x: (x, 0.7 * x + 1.0), "hypot": lambda x: (x, 0.7 * x + 1.0)}
    args |= {"pow": lambda x: (abs(x) + 0.1, 0.37), "log": lambda x: (abs(x) + 0.01,), "log1p": lambda x: (abs(x),)}
    out = {f: [getattr(math, f)(*args.get(f, lambda x: (x,))(x)).hex() for x in xs] for f in LIBM}
    out |= {f"mlpfac {f}": [getattr(elementary, f)(*args.get(f, lambda x: (x,))(x)).hex() for x in xs] for f in OURS}
    print(json.dumps(out))


def libm(environments: list[str]) -> None:
    """How many of the arguments give other bits, per function, in each environment against the first."""
    found = {}
    for name in environments:
        cmd = [sys.executable, __file__, "--libm-child"]
        out = subprocess.run(cmd, env=os.environ | ENVIRONMENTS[name], capture_output=True, text=True, check=True)
        found[name] = json.loads(out.stdout)
    first, *others = environments
    print(f"| function | {' | '.join(others)} (of {ARGUMENTS} arguments, against {first}) |")
    print("|---|" + "---:|" * len(others))
    for f in (*LIBM, *(f"mlpfac {f}" for f in OURS)):
        moved = [sum(a != b for a, b in zip(found[first][f], found[o][f], strict=True)) for o in others]
        print(f"| {f} | {' | '.join(map(str, moved))} |")


def child(runs: list[str]) -> None:
    """Run each run in this process and print its runs.json row (one JSON list)."""
    from mlpfac.report.verify import run_row
    from mlpfac.sweeps.plan import plan
    from mlpfac.sweeps.worker import run_task

    rows = []
    for r in runs:
        scenario, controller, seed = r.split("/")
        (job,) = plan([scenario], [controller], [int(seed)])
        (res,) = run_task([job])
        if res["error"] is not None:
            raise SystemExit(f"{r}: {res['error']}")
        rows.append(run_row(res["metrics"]))
    print(json.dumps(rows))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", nargs="+", default=list(RUNS), metavar="SCENARIO/CONTROLLER/SEED")
    ap.add_argument("--environments", default=",".join(ENVIRONMENTS), help="the first is the reference")
    ap.add_argument("--libm", action="store_true", help="glibc's maths functions alone, per environment")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--libm-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args.runs)
    if args.libm_child:
        return libm_child()
    if args.libm:
        return libm(args.environments.split(","))
    from mlpfac.report.verify import differ

    base, each, ran = None, {}, []
    print(f"{len(args.runs)} runs: {', '.join(args.runs)}\n")
    print("| environment | bit-identical | largest relative difference (run, figure) | outcome changed | s |")
    print("|---|---:|---|---|---:|")
    for name in args.environments.split(","):
        extra = ENVIRONMENTS[name]
        if subprocess.run([sys.executable, "-c", PROBE], env=os.environ | extra, capture_output=True).returncode:
            print(f"| {name} | not on this processor | | | |", flush=True)
            continue
        with tempfile.TemporaryDirectory() as cache:  # numba's cache of its own: nothing shared between them
            env = os.environ | extra | {"NUMBA_CACHE_DIR": cache}
            t0 = time.perf_counter()
            out = subprocess.run(
                [sys.executable, __file__, "--child", "--runs", *args.runs],
                env=env,
                capture_output=True,
                text=True,
            )
            if out.returncode:
                raise SystemExit(f"{name}: {out.stderr.strip().splitlines()[-1]}")
            took = time.perf_counter() - t0
        rows = json.loads(out.stdout.splitlines()[-1])
        ran.append(name)
        if base is None:
            base = rows
        same = sum(a["digest"] == b["digest"] for a, b in zip(base, rows, strict=True))
        worst, where, flipped = 0.0, "", []
        for r, a, b in zip(args.runs, base, rows, strict=True):
            d, which = differ(a, b)
            each.setdefault(r, []).append(_after(b))
            if d > worst:
                worst, where = d, f"{r}, {which}"
            if (a["status"], a["outcome"]) != (b["status"], b["outcome"]):
                flipped.append(f"{r}: {a['outcome']} -> {b['outcome']}")
        diff = f"{worst:.2g} ({where})" if worst else "-"
        print(f"| {name} | {same} of {len(rows)} | {diff} | {', '.join(flipped) or '-'} | {took:.0f} |", flush=True)
    print(f"\nper run, after the event (else the whole run): position RMS / max, mm, in {', '.join(ran)}\n")
    for r, figures in each.items():
        print(f"- {r}: {' | '.join(figures)}")


def _after(row: dict) -> str:
    """A run's position RMS and max error after its event (the tables' figures), in mm."""
    p = row["phases"].get("after") or row["phases"]["before"]
    rms, top = p["rms_position_error_m"], p["max_position_error_m"]
    return "-" if rms is None else f"{rms * 1e3:.2f} / {top * 1e3:.2f}"


if __name__ == "__main__":
    main()
