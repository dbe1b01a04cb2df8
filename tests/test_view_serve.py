"""`mlpfac view --serve`: saved runs in rerun's web viewer on a machine without a display, its
address and the SSH tunnel said, stopped by Ctrl-C with every port closed. (What the page draws is
the browser check's, tests/test_viewer_browser.py.)"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import pytest

import mlpfac


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


@pytest.mark.parametrize(
    ("runs", "signum", "code"), [(1, signal.SIGINT, 0), (2, signal.SIGINT, 0), (1, signal.SIGTERM, 143)]
)
def test_view_serve_serves_saved_runs_until_ctrl_c(tmp_path, runs, signum, code):
    """Ctrl-C is the way to stop serving (exit 0); SIGTERM ends it as terminated (143), the viewer stopped either way."""
    folders = []
    for seed in range(runs):  # shorter than the warm-up: a run without figures is shown all the same
        mlpfac.run("paper", controller="kanayama", seed=seed, duration=0.5, out=tmp_path / f"r{seed}")
        folders.append(str(tmp_path / f"r{seed}"))
    web, grpc = _free_port(), _free_port()
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}  # no display
    proc = subprocess.Popen(
        [sys.executable, "-m", "mlpfac.cli", "view", *folders, "--serve", "--port", str(web), "--grpc-port", str(grpc)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        said = [proc.stdout.readline() for _ in range(3)]
        assert said[0] == f"web viewer: http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy\n"
        assert f"ssh -N -L {web}:127.0.0.1:{web} -L {grpc}:127.0.0.1:{grpc} " in said[1]
        assert said[2] == "serving until Ctrl-C\n"
        with urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=120) as page:
            assert page.status == 200
        assert _listening(grpc)
        proc.send_signal(signum)
        assert proc.wait(timeout=120) == code, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    deadline = time.monotonic() + 120  # the viewer stops with it (the timeout only bounds a hang)
    while (_listening(web) or _listening(grpc)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _listening(web) and not _listening(grpc)  # the viewer stopped with it
