#!/usr/bin/env python3
"""Where the time of one ``mlpfac run`` goes, process by process: wall-clock marks (seconds from
this script's start) and each process's own CPU time at that mark, on stderr. Not a test.

    python benchmarks/latency_marks.py [--rounds 3] [ARGS of mlpfac run, default: eight-nominal]

The command runs in this process as ``mlpfac run`` would (its children forked from it), with marks
at the forks (the figure's and the recording's processes), the run's end (its recording handed to
the writer), the run's record sent to the painter, the baseline's record sent, the answers, and
each child's end. It wraps functions of mlpfac by name, so it follows the code it was written for.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

MARKED = r"""
import os, sys, time
T0 = float(os.environ["MARKS_T0"])


def mark(what):
    t = os.times()
    sys.stderr.write(f"  {time.time() - T0:6.3f} s  pid {os.getpid():>7}  cpu {t.user + t.system:5.2f} s  {what}\n")


_fork, _exit = os.fork, os._exit


def fork():
    mark("fork")
    return _fork()


def exit_(code):
    mark("exit")
    _exit(code)


os.fork, os._exit = fork, exit_
import mlpfac.plots.painter as painter
import mlpfac.runs.replay as replay
import mlpfac.runs.writer as writer


def wrap(owner, name, before, after=None):
    f = getattr(owner, name)

    def marked(*args):
        mark(before)
        out = f(*args)
        if after:
            mark(after)
        return out

    setattr(owner, name, marked)


wrap(painter.Painter, "begin", "the run's record to the painter", "sent")
wrap(painter.Painter, "finish", "the baseline's record to the painter", "the figure answered")
wrap(replay.DeferredSink, "hand_off", "the run's recording handed to the writer")
wrap(painter, "_child", "painter starts", "painter done")
wrap(writer, "_child", "writer starts", "writer done")
from mlpfac.cli import entry

sys.argv = ["mlpfac", "run", *sys.argv[1:]]
entry()
"""


def main() -> None:
    args = sys.argv[1:]
    rounds = 3
    if args[:1] == ["--rounds"]:
        rounds, args = int(args[1]), args[2:]
    args = args or ["eight-nominal"]
    for k in range(rounds):
        out = f"/tmp/mlpfac-marks-{os.getpid()}-{k}"
        env = os.environ | {"MARKS_T0": repr(time.time())}
        print(f"round {k + 1}: mlpfac run {' '.join(args)}", file=sys.stderr)
        cmd = [sys.executable, "-P", "-c", MARKED, *args, "--out", out]  # -P: the mlpfac installed, not a folder here
        subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL)
        subprocess.run(["rm", "-rf", out])


if __name__ == "__main__":
    main()
