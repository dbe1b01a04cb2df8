"""How much a run's figures depend on the machine: the same runs in this process's environment and
in environments that stand in for other machines. Not a test.

    python benchmarks/machine_spread.py [--runs SCENARIO/CONTROLLER/SEED ...] [--environments built,...]

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
- ``numpy-baseline``: numpy without the instructions beyond its baseline (``NPY_DISABLE_CPU_FEATURES``);
- ``blas-other-cpu``: OpenBLAS with the kernels of another processor (``OPENBLAS_CORETYPE``) on two
  threads, as numpy's and scipy's linear algebra would run elsewhere.
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
    "numpy-baseline": {"NPY_DISABLE_CPU_FEATURES": "AVX2 FMA3 F16C AVX AVX512F AVX512CD AVX512_SKX"},
    "blas-other-cpu": {"OPENBLAS_CORETYPE": "Prescott", "OPENBLAS_NUM_THREADS": "2"},
}


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
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args.runs)
    from mlpfac.report.verify import differ

    base, each = None, {}
    print(f"{len(args.runs)} runs: {', '.join(args.runs)}\n")
    print("| environment | bit-identical | largest relative difference (run, figure) | outcome changed | s |")
    print("|---|---:|---|---|---:|")
    for name in args.environments.split(","):
        extra = ENVIRONMENTS[name]
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
    print(f"\nper run, after the event (else the whole run): position RMS / max, mm, in {args.environments}\n")
    for r, figures in each.items():
        print(f"- {r}: {' | '.join(figures)}")


def _after(row: dict) -> str:
    """A run's position RMS and max error after its event (the tables' figures), in mm."""
    p = row["phases"].get("after") or row["phases"]["before"]
    rms, top = p["rms_position_error_m"], p["max_position_error_m"]
    return "-" if rms is None else f"{rms * 1e3:.2f} / {top * 1e3:.2f}"


if __name__ == "__main__":
    main()
