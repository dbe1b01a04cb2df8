"""How the ``mlpfac`` command ends (mlpfac.cli.entry): without the interpreter's teardown when only
mlpfac's code ran, yet with what it printed, what it wrote and what exit handlers do all there; a
user's controller, whose files only the teardown may close, gets the normal exit."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

RUN = ["run", "eight-nominal", "--duration", "0.5", "--no-plot"]

# a user's controller that writes to a file it never closes: only the interpreter's teardown flushes it
LAW = textwrap.dedent(
    """
    import os

    LOG = open(os.environ["MARK"], "w")

    class Feedforward:
        def __init__(self, T):
            self.T = T

        def step(self, e, r):
            LOG.write("step\\n")
            return float(r[3]), float(r[4])
    """
)


def test_a_run_of_mlpfac_alone_prints_writes_and_runs_exit_handlers_through_a_pipe(tmp_path):
    out = tmp_path / "run"
    script = (
        "import atexit, sys; from mlpfac.cli import entry; "
        "atexit.register(print, 'exit handler printed'); "
        f"sys.argv = ['mlpfac', *{RUN!r}, '--out', {str(out)!r}]; entry()"
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # stdout buffered, as in a pipe
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.rstrip().splitlines()
    assert lines[-2].endswith(f"-> {out}") and lines[-1] == "exit handler printed", proc.stdout
    assert (out / "metrics.json").is_file() and (out / "run.rrd").stat().st_size > 0


def test_a_users_controller_gets_the_normal_exit_and_its_files_are_whole(tmp_path):
    law = tmp_path / "law.py"
    law.write_text(LAW)
    mark, out = tmp_path / "steps.txt", tmp_path / "run"
    cmd = [sys.executable, "-m", "mlpfac.cli", *RUN, "--out", str(out), "--controller", f"{law}:Feedforward"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=dict(os.environ, MARK=str(mark)))
    assert proc.returncode == 0, proc.stderr
    assert mark.read_text().count("step\n") == 50  # 0.5 s of 0.01 s steps, all of them written
