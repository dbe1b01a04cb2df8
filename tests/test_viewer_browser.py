"""The saved recording opens in rerun's web viewer: served on 127.0.0.1, rendered by headless Chromium.

Chromium is driven over the DevTools protocol. The viewer draws everything on one canvas (its DOM
and accessibility tree hold only the page title), so readiness is read from the pixels: the
orange reference path and the blue driven path must appear in the 3D and top views on the left,
and a network-weight colour in the plots on the right. Set MLPFAC_SCREENSHOT=docs/viewer.png to
keep the picture.
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import os
import shutil
import signal
import socket
import subprocess
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.browser

CHROMIUM = next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
TIMEOUT_S = float(os.environ.get("MLPFAC_BROWSER_TIMEOUT", "60"))  # until the run is drawn
SETTLE_S = 60.0  # then until the picture stops changing
MIN_PIXELS = 200
WIDTH, HEIGHT = 1600, 1000


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(what: str, ready, timeout: float = 30.0, procs: tuple[subprocess.Popen, ...] = ()):
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        for p in procs:
            assert p.poll() is None, f"{what}: process {p.args[0]} exited with code {p.returncode}"
        with contextlib.suppress(OSError):
            result = ready()
            if result:
                return result
        time.sleep(0.2)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")


def _listening(port: int) -> bool:
    with socket.create_connection(("127.0.0.1", port), timeout=1.0):
        return True


def _stop(proc: subprocess.Popen) -> None:
    """Stop a process started in its own session and every process of its group (its children)."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, sig)
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(10)
        if _group_gone(proc.pid, 10.0):
            return


def _group_gone(pgid: int, timeout: float) -> bool:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.1)
    return False


class DevTools:
    """The few DevTools-protocol calls the test needs, over one page's websocket."""

    def __init__(self, ws) -> None:
        self.ws, self.next_id = ws, 0

    def call(self, method: str, **params):
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:  # skip events until our answer arrives
            msg = json.loads(self.ws.recv(timeout=120))
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]

    def screenshot(self) -> tuple[bytes, np.ndarray]:
        from PIL import Image

        png = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return png, np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int16)


def _count(img: np.ndarray, rgb: tuple[int, int, int], tol: int = 40) -> int:
    return int((np.abs(img - np.array(rgb)).sum(axis=-1) < tol).sum())


def shows_run(img: np.ndarray) -> dict[str, int]:
    """Pixels of the run's own colours: paths in the left column, weights in the right (below the top bar)."""
    from mlpfac.log import PATH_COLOR, REF_COLOR, WEIGHT_COLORS

    body = img[60:]
    left, right = body[:, : img.shape[1] * 2 // 5], body[:, img.shape[1] * 2 // 5 :]
    return {
        "reference path": _count(left, REF_COLOR),
        "driven path": _count(left, PATH_COLOR),
        "weights": _count(right, WEIGHT_COLORS["NN_f/hidden"]),
    }


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (Debian: apt-get install chromium)")
def test_web_viewer_renders_saved_run(tmp_path: Path, make_record, save_rrd) -> None:
    ws_client = pytest.importorskip("websockets.sync.client")
    pytest.importorskip("PIL")
    from mlpfac.log import rerun_executable

    rrd = tmp_path / "run" / "run.rrd"
    save_rrd(make_record(), rrd)
    web_port, grpc_port, devtools_port = _free_port(), _free_port(), _free_port()
    procs: list[subprocess.Popen] = []
    try:
        procs.append(
            subprocess.Popen(
                [rerun_executable(), "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(web_port),
                 "--port", str(grpc_port), str(rrd)],
                start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )
        )  # fmt: skip
        procs.append(
            subprocess.Popen(
                [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 f"--user-data-dir={tmp_path / 'chromium'}", f"--remote-debugging-port={devtools_port}",
                 f"--window-size={WIDTH},{HEIGHT}", "about:blank"],
                start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )
        )  # fmt: skip
        _wait("the rerun web viewer", lambda: _listening(web_port) and _listening(grpc_port), procs=procs[:1])

        def page_ws() -> str | None:
            with urllib.request.urlopen(f"http://127.0.0.1:{devtools_port}/json/list", timeout=2) as r:
                pages = [t for t in json.load(r) if t.get("type") == "page"]
            return pages[0]["webSocketDebuggerUrl"] if pages else None

        url = _wait("chromium's DevTools endpoint", page_ws, procs=procs[1:])
        with ws_client.connect(url, max_size=None, open_timeout=30) as ws:
            dt = DevTools(ws)
            dt.call("Page.enable")
            dt.call("Emulation.setDeviceMetricsOverride", width=WIDTH, height=HEIGHT, deviceScaleFactor=1, mobile=False)
            viewer = f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}%2Fproxy"
            dt.call("Page.navigate", url=viewer)
            # Ready: the run's colours are drawn (the welcome screen and the loading spinner have none).
            t0 = time.monotonic()
            seen: dict[str, int] = {}
            while not seen or min(seen.values()) < MIN_PIXELS:
                assert time.monotonic() - t0 < TIMEOUT_S, (
                    f"the viewer did not show the run in {TIMEOUT_S:.0f} s: {seen}"
                )
                time.sleep(2.0)
                with contextlib.suppress(RuntimeError):  # "Not attached to an active page" while navigating
                    png, img = dt.screenshot()
                    seen = shows_run(img)
                    print(f"{time.monotonic() - t0:5.1f} s: {seen}")  # shown with pytest -s
            # The viewer streams the file in for a while after it first draws: keep the picture once
            # two screenshots in a row agree (or after SETTLE_S, with whatever it shows then).
            t1 = time.monotonic()
            while time.monotonic() - t1 < SETTLE_S:
                time.sleep(2.0)
                png, img = dt.screenshot()
                previous, seen = seen, shows_run(img)
                print(f"{time.monotonic() - t0:5.1f} s: {seen}")
                if seen == previous:
                    break
            assert min(seen.values()) >= MIN_PIXELS, seen
            assert dt.call("Runtime.evaluate", expression="document.title")["result"]["value"] == "Rerun Viewer"
        out = os.environ.get("MLPFAC_SCREENSHOT")
        if out:
            Path(out).parent.mkdir(parents=True, exist_ok=True)
            Path(out).write_bytes(png)
    finally:
        for p in reversed(procs):
            _stop(p)
    for p in procs:
        assert p.poll() is not None and _group_gone(p.pid, 0.5), f"{p.args[0]} left processes behind"
