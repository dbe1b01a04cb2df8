"""The oracle's bound for the changes the law (35) has no parameter for: the nominal law on the robot
changed from t = 0, against the same law changed at the scenario's event time.

For eight-payload, eight-weak-actuator and eight-friction, runs Corradini's law on the scenario as
shipped and on the same scenario with the event moved to t = 0, over the same window (the shipped
event's time to the end, from the runs' 0.1 s bins), and prints one Markdown row each: the medians
and the paired wins / Wilcoxon p of the shipped run against the changed-from-the-start one.
Usage: python sims/oracle_from_start.py [--seeds 20] [--workers 1]
"""

from __future__ import annotations

import argparse
import copy
from concurrent.futures import ProcessPoolExecutor
from statistics import median

from mlpfac.loop.metrics import RunMetrics, metrics
from mlpfac.loop.runner import run
from mlpfac.scenario.parse import load, parse
from mlpfac.sweeps.paired import compare

SCENARIOS = ("eight-payload", "eight-weak-actuator", "eight-friction")


def one(args: tuple[str, int, bool]) -> float | None:
    name, seed, from_start = args
    table = copy.deepcopy(load(name).table)
    table["seed"], table["controller"]["name"] = seed, "corradini"
    start = table["events"][0]["time"]
    if from_start:
        table["events"][0]["time"] = 0.0
    m = RunMetrics.from_json(metrics(run(parse(table, f"sims/{name}.toml"))))
    return m.window_rms(start, table["duration"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args()
    print(
        f"| scenario (seeds 0-{args.seeds - 1}) | event at its time [mm] | event at 0 [mm] | wins of at-its-time | p |"
    )
    print("|---|---:|---:|---:|---:|")
    with ProcessPoolExecutor(args.workers) as pool:
        for name in SCENARIOS:
            jobs = [(name, s, f) for f in (False, True) for s in range(args.seeds)]
            out = list(pool.map(one, jobs))
            shipped, start = out[: args.seeds], out[args.seeds :]
            wins, n, p = compare(shipped, start)
            ok = [x for x in shipped if x is not None], [x for x in start if x is not None]
            print(
                f"| {name} | {median(ok[0]) * 1e3:.2f} | {median(ok[1]) * 1e3:.2f} | {wins}/{n} | "
                + ("-" if p is None else f"{p:.2g}")
                + " |"
            )


if __name__ == "__main__":
    main()
