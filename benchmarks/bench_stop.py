"""How soon a run, a sweep and a check stop after SIGINT or SIGTERM at a random time. Not a test.

    python benchmarks/bench_stop.py [--tries 10] [--seed 0]

The commands of ``tests/test_signals.py`` (which tests what a signal leaves, not how soon): each is
first timed unsignalled, then started ``--tries`` times per signal and signalled at a random share
of that span (drawn from ``--seed``). Per command and signal: the median and the largest time from
the signal to the process's exit, over the tries it was still running for. Target: <= 2 s each.
"""

from __future__ import annotations

import argparse
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BUDGET = (
    'scenarios = ["eight-nominal"]\ncontrollers = ["kanayama"]\nseeds = "0-1"\nduration = 1.0\n[[budget]]\nlost = 0\n'
)
COMMANDS = {
    "run": ["run", "eight-nominal", "--controller", "kanayama", "--duration", "2", "--out", "R"],
    "sweep": ["sweep", "eight-nominal", "--controllers", "kanayama", "--seeds", "0-1", "--duration", "1",
              "--workers", "2", "--out", "S"],
    "check": ["check", "b.toml", "--workers", "2", "--out", "C"],
}  # fmt: skip
TARGET_S = 2.0


def once(argv: list[str], delay: float | None, sig: int) -> tuple[float, float | None]:
    """The command's wall time, and the seconds from ``sig`` (sent after ``delay``) to its exit
    (None: it had ended before)."""
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "b.toml").write_text(BUDGET)
        t0 = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", "mlpfac.cli", *argv], cwd=d,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
        if delay is None:
            proc.wait()
            return time.monotonic() - t0, None
        time.sleep(delay)
        if proc.poll() is not None:
            return time.monotonic() - t0, None
        proc.send_signal(sig)
        t1 = time.monotonic()
        proc.wait()
        return time.monotonic() - t0, time.monotonic() - t1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tries", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    draw, missed = random.Random(a.seed), 0
    for command, argv in COMMANDS.items():
        span, _ = once(argv, None, 0)
        for name, sig in (("SIGINT", signal.SIGINT), ("SIGTERM", signal.SIGTERM)):
            stops = [s for _ in range(a.tries) if (s := once(argv, draw.uniform(0, span), sig)[1]) is not None]
            worst = max(stops, default=0.0)
            missed += worst > TARGET_S
            print(f"  {command:<6} {name:<8} span {span:5.2f} s  stopped {len(stops):>2} of {a.tries}: "
                  f"median {statistics.median(stops or [0]):.2f} s, largest {worst:.2f} s  "
                  f"(target <= {TARGET_S} s: {'met' if worst <= TARGET_S else 'MISSED'})", flush=True)  # fmt: skip
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
