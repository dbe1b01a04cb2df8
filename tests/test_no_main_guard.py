"""A sweep from a plain script, from stdin and from ``python -c``, with no
``if __name__ == "__main__":``: the pool's workers do not run the user's script again (they would
start its sweep again, or fail to start and break the pool)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

SCRIPT = """\
import mlpfac
print("top of the script", flush=True)
rows = mlpfac.sweep("paper", ["corradini"], seeds="0-1", duration=0.3, workers=2)
print("rows", len(rows) > 0, "errors", len(rows.errors), flush=True)
"""


def _python(tmp_path, how: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    if how == "script":
        (tmp_path / "sweep_me.py").write_text(SCRIPT)
        args, stdin = [sys.executable, "sweep_me.py"], None
    elif how == "stdin":
        args, stdin = [sys.executable, "-"], SCRIPT
    else:
        args, stdin = [sys.executable, "-c", SCRIPT], None
    return subprocess.run(args, input=stdin, capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300)


@pytest.mark.parametrize("how", ["script", "stdin", "-c"])
def test_a_sweep_needs_no_main_guard(tmp_path, how):
    proc = _python(tmp_path, how)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("top of the script") == 1, proc.stdout  # the workers did not run it again
    assert "rows True errors 0" in proc.stdout, proc.stdout + proc.stderr


CLASS_SCRIPT = """\
from math import cos, sin

import mlpfac


class MyLaw:
    def __init__(self, T, kx=10.0, ky=64.0, kt=16.0):
        self.k = (kx, ky, kt)

    def step(self, e, r):
        return r[3] * cos(e[2]) + self.k[0] * e[0], r[4] + r[3] * (self.k[1] * e[1] + self.k[2] * sin(e[2]))


rows = mlpfac.sweep("paper", [MyLaw], seeds="0-1", duration=0.3, workers=2)
print("errors", len(rows.errors), list(rows.errors.values()), flush=True)
print("done", flush=True)
"""


def test_a_class_of_an_unguarded_script_is_defined_by_its_workers_up_to_the_sweep(tmp_path):
    """Each worker imports the script for its class, and that import ends at the call of mlpfac:
    the class is there, the sweep does not start again, nothing after it runs."""
    (tmp_path / "my_sweep.py").write_text(CLASS_SCRIPT)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run(
        [sys.executable, "my_sweep.py"], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    assert "errors 0 []" in proc.stdout, proc.stdout
    assert proc.stdout.count("done") == 1, proc.stdout
