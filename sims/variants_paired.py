"""Per-seed pairing of sweep runs against corradini: one Markdown row per controller.

Reads the run folders of one or more `mlpfac sweep` outputs (SCENARIO/CONTROLLER/seed-NNNN/metrics.json)
and prints, per eight-* scenario, the median position RMS after the event (over the whole run after
the warm-up where there is none), "(k/n)" when fewer runs stayed bounded, and the seeds on which the
controller's error is below corradini's on the same seed with the two-sided sign-test p-value.
Usage: python sims/variants_paired.py SWEEP_FOLDER [SWEEP_FOLDER ...]
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

SCENARIOS = (
    "nominal",
    "torque",
    "payload",
    "friction",
    "wheel-radius",
    "weak-actuator",
    "control-period",
    "sensor-delay",
)


def errors(roots: list[Path], scenario: str, controller: str) -> dict[int, float]:
    """Seed -> post-event position RMS in mm (NaN for a run that did not stay bounded)."""
    out = {}
    for root in roots:
        for f in sorted((root / f"eight-{scenario}" / controller).glob("seed-*/metrics.json")):
            m = json.loads(f.read_text())
            ph = m["phases"].get("after") or m["phases"]["before"]
            ok = m.get("status", "ok") == "ok" and ph["rms_position_error_m"] is not None
            out[int(f.parent.name[5:])] = ph["rms_position_error_m"] * 1e3 if ok else math.nan
    return out


def sign_test(wins: int, n: int) -> float:
    """Two-sided exact sign test: P(|W - n/2| >= |wins - n/2|), W ~ Binomial(n, 1/2)."""
    k = max(wins, n - wins)
    tail = sum(math.comb(n, i) for i in range(k, n + 1)) / 2**n
    return min(1.0, 2 * tail)


def main(roots: list[Path]) -> None:
    controllers = sorted({p.name for r in roots for p in r.glob("eight-*/*") if p.is_dir()})
    print("| controller | " + " | ".join(SCENARIOS) + " |")
    print("|---|" + "---:|" * len(SCENARIOS))
    for c in controllers:
        cells = []
        for sc in SCENARIOS:
            mine, ref = errors(roots, sc, c), errors(roots, sc, "corradini")
            if not mine:
                cells.append("-")
                continue
            v = np.array(list(mine.values()))
            bounded = int(np.isfinite(v).sum())
            cell = f"{np.nanmedian(v):.2f}" + ("" if bounded == len(v) else f" ({bounded}/{len(v)})")
            pairs = [(mine[s], ref[s]) for s in mine if s in ref and math.isfinite(mine[s]) and math.isfinite(ref[s])]
            if c != "corradini" and pairs:
                wins = sum(a < b for a, b in pairs)
                cell += f" [{wins}/{len(pairs)}, p={sign_test(wins, len(pairs)):.1g}]"
            cells.append(cell)
        print(f"| `{c}` | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit("usage: python sims/variants_paired.py SWEEP_FOLDER [SWEEP_FOLDER ...]")
    main([Path(a) for a in sys.argv[1:]])
