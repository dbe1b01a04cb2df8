"""SIGINT and SIGTERM at a random time of a run, a sweep and a check (loading, settling the robot,
compiling, stepping, writing): the command ends with its signal's code, no traceback, and leaves no
partial folder (a folder is missing, or whole: a run's config.toml and metrics.json, nothing staged).

The time is a share, drawn from MLPFAC_SIGNAL_SEED (default 0), of how long the same command takes
on this machine unsignalled (measured first, once per command): the draws fall in the same phases
on a machine 3x faster or slower. Set another seed to try other times; a failure names the seed
and the time. How soon it stops is measured, not tested: ``benchmarks/bench_stop.py``."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

SEED = int(os.environ.get("MLPFAC_SIGNAL_SEED", "0"))
BUDGET = (
    'scenarios = ["eight-nominal"]\ncontrollers = ["kanayama"]\nseeds = "0-1"\nduration = 1.0\n[[budget]]\nlost = 0\n'
)
COMMANDS = {
    "run": ["run", "eight-nominal", "--controller", "kanayama", "--duration", "2", "--out", "R"],
    "sweep": ["sweep", "eight-nominal", "--controllers", "kanayama", "--seeds", "0-1", "--duration", "1",
              "--workers", "2", "--out", "S"],
    "check": ["check", "b.toml", "--workers", "2", "--out", "C"],
}  # fmt: skip
SIGNALS = {"SIGINT": (signal.SIGINT, 130), "SIGTERM": (signal.SIGTERM, 143)}
HANG_S = 120.0  # bounds a hang only


def start(argv: list[str], cwd: Path) -> subprocess.Popen:
    """The command started in ``cwd``, with the budget file ``check`` reads."""
    (cwd / "b.toml").write_text(BUDGET)
    return subprocess.Popen(
        [sys.executable, "-m", "mlpfac.cli", *argv], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


@pytest.fixture(scope="module")
def spans(tmp_path_factory) -> dict[str, float]:
    """How long each command takes on this machine, start to exit, unsignalled (seconds)."""
    out = {}
    for command, argv in COMMANDS.items():
        t0 = time.monotonic()
        proc = start(argv, tmp_path_factory.mktemp(command))
        _, err = proc.communicate(timeout=HANG_S)
        assert proc.returncode == 0, err
        out[command] = time.monotonic() - t0
    return out


def _not_partial(root: Path) -> list[str]:
    """What under ``root`` is a partial folder or a leftover: a staged folder or file, a sweep's
    temporary folder, a folder with a run's config.toml and no metrics.json (or one that is not JSON)."""
    bad = []
    for p in root.rglob("*"):
        if ".tmp-" in p.name or (p.name == ".tmp" and p.is_dir()):
            bad.append(f"{p.relative_to(root)} left behind")
        if p.is_dir() and (p / "config.toml").exists():
            try:
                json.loads((p / "metrics.json").read_text())
            except (OSError, ValueError):
                bad.append(f"{p.relative_to(root)} holds config.toml without a whole metrics.json")
    return bad


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("name", sorted(SIGNALS))
def test_a_signal_at_a_random_time_stops_it_and_leaves_no_partial_folder(tmp_path, spans, command, name):
    sig, code = SIGNALS[name]
    share = random.Random(f"{SEED}-{command}-{name}").uniform(0.0, 1.0)
    delay = share * spans[command]
    proc = start(COMMANDS[command], tmp_path)
    time.sleep(delay)  # a share of the command's own measured span: the random time is the test's input
    done_before = proc.poll() is not None
    proc.send_signal(sig)
    t0 = time.monotonic()
    try:
        _, err = proc.communicate(timeout=HANG_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        pytest.fail(f"{command}: {name} at {delay:.2f} s (seed {SEED}) did not stop it within {HANG_S} s: {err}")
    took = time.monotonic() - t0
    where = (
        f"{command}: {name} at {delay:.2f} s ({share:.0%} of {spans[command]:.2f} s, seed {SEED}), "
        f"exit {proc.returncode} after {took:.2f} s"
    )
    if "Fatal Python error: init_import_site" in err:  # the interpreter's own start, before any code of ours
        return
    assert "Traceback" not in err, f"{where}\n{err}"
    # the signal's own code; 0 when it came after the end; killed by it before Python set its handlers
    assert proc.returncode in (code, 0, -sig), f"{where} (done before: {done_before})\n{err}"
    assert _not_partial(tmp_path) == [], where


def test_a_signal_wrapped_by_python_in_another_error_still_ends_cleanly(tmp_path):
    """A SIGTERM that lands while Python makes a class (matplotlib's, imported to draw a sweep's
    figure) comes out as a RuntimeError caused by it: the command still ends as terminated, 143,
    in one line, with no traceback."""
    code = (
        "import mlpfac.cli as cli\n"
        "from mlpfac.io.interrupts import Terminated\n"
        "def main():\n"
        "    try:\n"
        "        raise Terminated()\n"
        "    except Terminated as err:\n"
        "        raise RuntimeError(\"Error calling __set_name__ on '_axis_method_wrapper'\") from err\n"
        "cli.main = main\n"
        "cli.entry()\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 143 and proc.stderr.strip() == "mlpfac: terminated", proc.stderr
