"""The measurement behind each of the project's default choices on the paper's experiment.

Runs the `paper` scenario (project defaults) and, for each choice, the same scenario with that one
choice put back to the paper's value, over a range of seeds, and prints one Markdown table row each:
runs that stayed bounded, median and worst position RMS after the T -> 1.5 T change, and the largest
weight. Usage: python sims/paper_choices.py [--seeds 50] [--workers 2]
"""

from __future__ import annotations

import argparse
import copy
import math
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from mlpfac.loop.metrics import metrics
from mlpfac.loop.runner import run
from mlpfac.scenario.parse import load, parse

# (label, controller-table changes, adaptive-table changes)
CHOICES = [
    ("project defaults (sims/paper.toml)", {}, {}),
    ("error inputs not scaled (error_scale = 1)", {}, {"error_scale": 1.0}),
    ("EKF R = noise covariance 1e-6", {}, {"R": 1e-6}),
    ("P0 = 5 (the paper's)", {}, {"P0": 5.0}),
    ("all initial weights ~ N(0, 1)", {}, {"weight_std": 1.0, "output_weight_std": 1.0}),
    ("no limits on v, omega", {"v_max": math.inf, "omega_max": math.inf}, {}),
    ("eigenvalues 0.9", {"lambdas": [0.9, 0.9, 0.9]}, {}),
    ("eigenvalues 0.7", {"lambdas": [0.7, 0.7, 0.7]}, {}),
]


def one(args: tuple[int, int, float | None]) -> tuple[str, float | None, float]:
    i, seed, duration = args
    _, ctrl, adaptive = CHOICES[i]
    table = copy.deepcopy(load("paper").table)
    table["seed"] = seed
    if duration is not None:  # a quick check: the change at half the shorter run
        table["duration"] = duration
        table["events"][0]["time"] = duration / 2
    table["controller"].update(ctrl)
    table["controller"]["adaptive"].update(adaptive)
    m = metrics(run(parse(table, "sims/paper.toml")))
    return m["status"], m["phases"]["after"]["rms_position_error_m"], m["max_abs_weight"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--duration", type=float, help="shorter runs, the change at half of them, for a quick check (default: 25 s)"
    )
    args = ap.parse_args()
    print(
        f"| choice (seeds 0-{args.seeds - 1}) | bounded | median RMS after change | worst bounded RMS after | max abs weight |"
    )
    print("|---|---|---|---|---|")
    with ProcessPoolExecutor(args.workers) as pool:
        for i, (label, _, _) in enumerate(CHOICES):
            res = list(pool.map(one, [(i, s, args.duration) for s in range(args.seeds)]))
            after = [r[1] for r in res if r[0] == "ok" and r[1] is not None]
            med = f"{1e3 * np.median(after):.1f} mm" if after else "-"
            worst = f"{1e3 * max(after):.1f} mm" if after else "-"
            print(f"| {label} | {len(after)}/{len(res)} | {med} | {worst} | {max(r[2] for r in res):.3g} |", flush=True)


if __name__ == "__main__":
    main()
