"""How much does saving a run to rerun cost? Times the same run with and without a sink, side by side.

    python benchmarks/bench_logging.py                      # the 'paper' scenario, adaptive, seed 1
    python benchmarks/bench_logging.py --controller corradini --seed 2 --repeats 7
    python benchmarks/bench_logging.py --synthetic          # log a synthetic 2500-step, 171-weight record

Default: ``mlpfac.loop.runner.run(scenario)`` and ``run(scenario, sink=make_sink(save=...))`` alternate
``--repeats`` times; the medians and their ratio are printed (target: at most 1.3).
``--synthetic``: the sink's whole life (make_sink, begin, a flush every 250 steps, end) on a
synthetic record of ``--steps`` rows and ``--alpha`` weights, filled without simulating, against the
no-log time of a real run of the same length; ratio = (run + logging) / run.

rerun's import (about 0.3-0.5 s, paid once per process and only when logging) is reported apart.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def synthetic_record(steps: int, alpha: int, seed: int = 0):
    """A figure-of-eight run with every telemetry key of the adaptive controller on the kinematic plant."""
    from mlpfac.loop.record import RunRecord
    from mlpfac.scenario.reference import Eight, sample

    T = 0.01
    rng = np.random.default_rng(seed)
    rec = RunRecord.allocate("synthetic", "adaptive", seed, T, steps)
    rec.ref[:] = sample(Eight(), rec.t)
    rec.pose[:] = rec.ref[:, :3] + rng.normal(0.0, 0.01, (steps, 3))
    rec.pose_meas[:] = rec.pose
    rec.e[:] = rec.e_true[:] = rng.normal(0.0, 0.01, (steps, 3))
    rec.u[:] = rec.ref[:, 3:5]
    rec.plant = {"u_meas": rec.u + rng.normal(0.0, 1e-3, (steps, 2)), "h_true": rng.normal(0.0, 0.01, (steps, 3))}
    rec.ctrl = {
        "z": np.cumsum(rng.normal(0.0, 0.01, (steps, alpha)), axis=0),
        "trace_P": np.linspace(5.0 * alpha, 1.0, steps),
        "mean_diag_P": np.linspace(5.0, 1.0 / alpha, steps),
        "innovation": rng.normal(0.0, 1e-3, (steps, 3)),
        "h_hat": rng.normal(0.0, 0.01, (steps, 3)),
    }
    rec.labels = {"z": [f"NN_f/output/w{i}" for i in range(alpha)]}
    rec.events = [{"time": steps * T / 2, "kind": "control_period", "params": {"factor": 1.5}, "text": "T -> 1.5 T"}]
    rec.n = steps
    return rec


def log_whole(rec, path: Path, flush_every: int) -> float:
    """Seconds for the sink's whole life on a finished record, flushing as the runner does."""
    from mlpfac import log

    t0 = time.perf_counter()
    sink = log.make_sink(save=path, recording_name="bench", recording_id="bench")
    sink.begin(rec, geometry=[{"name": "chassis", "type": "box", "size": [0.15, 0.1, 0.04], "pos": [0, 0, 0.06]}])
    for k in range(flush_every, rec.n + 1, flush_every):
        sink.flush(rec, k)
    sink.end(rec)
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--controller", default="adaptive")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--synthetic", action="store_true", help="log a synthetic record instead of a real run")
    ap.add_argument("--steps", type=int, default=2500)
    ap.add_argument("--alpha", type=int, default=171)
    args = ap.parse_args()

    from mlpfac.loop.closed_loop import FLUSH_EVERY
    from mlpfac.loop.runner import run
    from mlpfac.scenario.parse import load

    scn = load(args.scenario).with_overrides(args.controller, args.seed, None)
    if args.synthetic:
        scn = scn.with_overrides(duration=args.steps * scn.T)
    run(scn)  # warm up: imports, caches
    t0 = time.perf_counter()
    from mlpfac import log

    print(f"import mlpfac.log (rerun): {time.perf_counter() - t0:.3f} s, once per process")

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.rrd"
        bare, logged = [], []
        for _ in range(args.repeats):
            t = time.perf_counter()
            rec = run(scn)
            bare.append(time.perf_counter() - t)
            if args.synthetic:
                logged.append(log_whole(synthetic_record(args.steps, args.alpha), path, FLUSH_EVERY))
            else:
                t = time.perf_counter()
                sink = log.make_sink(save=path, recording_name="bench", recording_id="bench")
                run(scn, sink=sink)
                logged.append(time.perf_counter() - t)
        size_mb = path.stat().st_size / 1e6

    b, g = statistics.median(bare), statistics.median(logged)
    what = f"{scn.name} / {scn.controller} / seed {scn.seed}: {rec.n} steps, status {rec.status}"
    alpha = rec.ctrl["z"].shape[1] if "z" in rec.ctrl else 0
    print(f"run without logging: {what}, alpha {alpha}")
    if args.synthetic:
        ratio = (b + g) / b
        print(f"logging a synthetic record ({args.steps} steps, {args.alpha} weights): median {g:.3f} s")
        print(f"run alone: median {b:.3f} s;  (run + logging) / run = {ratio:.2f}  ({args.repeats} repeats)")
    else:
        ratio = g / b
        print(f"median without sink {b:.3f} s, with sink (saving run.rrd) {g:.3f} s", end="")
        print(f": ratio {ratio:.2f} ({args.repeats} repeats)")
    print(f"run.rrd: {size_mb:.1f} MB")
    if rec.status != "ok":
        print("note: the run did not finish; pick a seed that does for a fair figure", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
