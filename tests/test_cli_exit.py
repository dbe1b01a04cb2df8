"""The ``mlpfac`` command ends without the interpreter's teardown (mlpfac.cli.entry): what it
printed, what it wrote and what exit handlers do still happen, as at a normal exit."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

LAW = textwrap.dedent(
    """
    import atexit, os, pathlib

    class Feedforward:
        def __init__(self, T):
            self.T = T
            atexit.register(pathlib.Path(os.environ["MARK"]).write_text, "exit handler ran")

        def step(self, e, r):
            return float(r[3]), float(r[4])
    """
)


def test_a_run_through_a_pipe_prints_writes_and_runs_exit_handlers(tmp_path):
    law = tmp_path / "law.py"
    law.write_text(LAW)
    mark, out = tmp_path / "mark.txt", tmp_path / "run"
    cmd = [sys.executable, "-m", "mlpfac.cli", "run", "eight-nominal", "--duration", "0.5", "--out", str(out)]
    cmd += ["--controller", f"{law}:Feedforward", "--no-plot"]
    env = dict(os.environ, MARK=str(mark))
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.rstrip().splitlines()[-1].endswith(f"-> {out}"), proc.stdout  # buffered, yet all printed
    assert (out / "metrics.json").is_file() and (out / "run.rrd").stat().st_size > 0
    assert mark.read_text() == "exit handler ran"
