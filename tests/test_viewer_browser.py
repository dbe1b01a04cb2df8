"""A real run's recording, and a comparison of two runs, open in rerun's web viewer: served on
127.0.0.1, rendered by headless Chromium.

The runs are made here, short: the figure of eight on the MuJoCo robot for 8 s, its wheel radius
x1.5 at 4 s, with the adaptive scheme and with the corradini law (`mlpfac run FILE`), then
`mlpfac view A B --save` for the comparison. Chromium is driven over the DevTools protocol. The
viewer draws everything on one canvas (its DOM and accessibility tree hold only the page title), so
readiness is read from the pixels: the run's own colours must appear in the views on the left and
on the right. MLPFAC_SCREENSHOT_DIR=docs keeps the pictures as docs/viewer.png and
docs/viewer-compare.png (the README's).
"""

from __future__ import annotations

import base64
import contextlib
import copy
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
TIMEOUT_S = float(os.environ.get("MLPFAC_BROWSER_TIMEOUT", "120"))  # until the run is drawn
SETTLE_S = 60.0  # then until the picture stops changing
MIN_PIXELS = 50
WIDTH, HEIGHT = 1600, 1000


def _free_ports(n: int) -> list[int]:
    """``n`` distinct free ports (each held until all are found, so none is given twice)."""
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def _serve_web(rrd: Path, tmp_path: Path, tries: int = 3) -> tuple[subprocess.Popen, int, int]:
    """rerun's web viewer serving ``rrd``, listening: (process, web port, gRPC port). A port taken
    by another process between its choice and rerun's bind makes rerun exit at once: it is tried
    again on other ports, and its last words are in the failure."""
    from mlpfac.log import rerun_executable

    for attempt in range(tries):
        web_port, grpc_port = _free_ports(2)
        err = tmp_path / f"rerun-{attempt}.err"
        with err.open("wb") as f:
            p = subprocess.Popen(
                [rerun_executable(), "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(web_port),
                 "--port", str(grpc_port), str(rrd)],
                start_new_session=True, stdout=subprocess.DEVNULL, stderr=f,
            )  # fmt: skip
        try:
            _wait("the rerun web viewer", lambda w=web_port, g=grpc_port: _listening(w) and _listening(g), procs=(p,))
            return p, web_port, grpc_port
        except AssertionError:
            _stop(p)
            if attempt == tries - 1:
                raise AssertionError(f"the rerun web viewer did not serve: {err.read_text()[-600:]}") from None
    raise AssertionError("unreachable")


def _wait(what: str, ready, timeout: float = 120.0, procs: tuple[subprocess.Popen, ...] = ()):
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


def _shows(img: np.ndarray, left: dict, right: dict) -> dict[str, int]:
    """Pixels of each named colour: ``left`` ones in the left column, ``right`` ones in the right
    (below the top bar)."""
    body = img[60:]
    cut = img.shape[1] * 2 // 5
    return {k: _count(body[:, :cut], c) for k, c in left.items()} | {
        k: _count(body[:, cut:], c) for k, c in right.items()
    }


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """Two real short runs (adaptive, corradini) and their comparison recording."""
    from mlpfac.cli import main
    from mlpfac.scenario.parse import load, to_toml

    d = tmp_path_factory.mktemp("runs")
    table = copy.deepcopy(load("eight-wheel-radius").table)
    table["duration"] = 8.0
    table["events"][0]["time"] = 4.0
    table["description"] = (
        "Figure of eight on the MuJoCo robot; real wheel radius x1.5 at 4 s, IK keeps the nominal one."
    )
    (d / "short.toml").write_text(to_toml(table))
    assert main(["run", str(d / "short.toml"), "--out", str(d / "adaptive")]) == 0
    assert (
        main(["run", str(d / "short.toml"), "--controller", "corradini", "--out", str(d / "corradini"), "--no-plot"])
        == 0
    )
    assert main(["view", str(d / "adaptive"), str(d / "corradini"), "--save", str(d / "compare.rrd")]) == 0
    return {"run": d / "adaptive" / "run.rrd", "compare": d / "compare.rrd"}


def render(rrd: Path, tmp_path: Path, ready) -> bytes:
    """Serve ``rrd`` in rerun's web viewer, open it in headless Chromium, wait until ``ready(img)``
    (a dict of pixel counts) has every count at least MIN_PIXELS and the picture settles; the PNG."""
    ws_client = pytest.importorskip("websockets.sync.client")
    pytest.importorskip("PIL")
    procs: list[subprocess.Popen] = []
    try:
        viewer_proc, web_port, grpc_port = _serve_web(rrd, tmp_path)
        procs.append(viewer_proc)
        (devtools_port,) = _free_ports(1)
        procs.append(
            subprocess.Popen(
                [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 f"--user-data-dir={tmp_path / 'chromium'}", f"--remote-debugging-port={devtools_port}",
                 f"--window-size={WIDTH},{HEIGHT}", "about:blank"],
                start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )
        )  # fmt: skip

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
                    (tmp_path / "last.png").write_bytes(png)  # what it showed, kept on failure
                    seen = ready(img)
                    print(f"{time.monotonic() - t0:5.1f} s: {seen}")  # shown with pytest -s
            # The viewer streams the file in for a while after it first draws: keep the picture once
            # two screenshots in a row agree (or after SETTLE_S, with whatever it shows then).
            t1 = time.monotonic()
            while time.monotonic() - t1 < SETTLE_S:
                time.sleep(2.0)
                png, img = dt.screenshot()
                previous, seen = seen, ready(img)
                print(f"{time.monotonic() - t0:5.1f} s: {seen}")
                if seen == previous:
                    break
            assert min(seen.values()) >= MIN_PIXELS, seen
            assert dt.call("Runtime.evaluate", expression="document.title")["result"]["value"] == "Rerun Viewer"
    finally:
        for p in reversed(procs):
            _stop(p)
    for p in procs:
        assert p.poll() is not None and _group_gone(p.pid, 0.5), f"{p.args[0]} left processes behind"
    return png


def _keep(png: bytes, name: str) -> None:
    folder = os.environ.get("MLPFAC_SCREENSHOT_DIR")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        (Path(folder) / name).write_bytes(png)


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (Debian: apt-get install chromium)")
def test_web_viewer_renders_a_real_run(tmp_path: Path, runs) -> None:
    """The default layout: paths on the left, the event diamonds and the weights' change on the right."""
    from mlpfac.log import PATH_COLOR, REF_COLOR, WEIGHT_COLORS
    from mlpfac.log.schema import EVENT_COLOR, ROBOT_COLOR

    png = render(
        runs["run"],
        tmp_path,
        lambda img: _shows(
            img,
            {"reference path": REF_COLOR, "driven path": PATH_COLOR, "heading arrow": ROBOT_COLOR},
            {"event marks": EVENT_COLOR, "weights": WEIGHT_COLORS["NN_f/hidden"]},
        ),
    )
    _keep(png, "viewer.png")


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (Debian: apt-get install chromium)")
def test_web_viewer_renders_a_comparison(tmp_path: Path, runs) -> None:
    """Two runs overlaid in one layout, each in its controller's colour."""
    from mlpfac.log.compare import COMPARE_REF_COLOR
    from mlpfac.plots import controller_colors

    colors = controller_colors(["adaptive", "corradini"])
    png = render(
        runs["compare"],
        tmp_path,
        lambda img: _shows(
            img,
            {
                "reference": COMPARE_REF_COLOR,
                "adaptive path": colors["adaptive"],
                "corradini path": colors["corradini"],
            },
            {"adaptive": colors["adaptive"], "corradini": colors["corradini"]},
        ),
    )
    _keep(png, "viewer-compare.png")


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (Debian: apt-get install chromium)")
@pytest.mark.menagerie
def test_web_viewer_renders_tiago_from_its_meshes(tmp_path: Path) -> None:
    """A short run of PAL TIAGo (MuJoCo Menagerie, base-only): the robot drawn from its own meshes,
    the paths and the error plots in the same default layout. Kept as docs/tiago-viewer.png."""
    pytest.importorskip("mujoco_menagerie")
    from mlpfac.cli import main
    from mlpfac.log import PATH_COLOR, REF_COLOR
    from mlpfac.log.schema import EVENT_COLOR
    from mlpfac.scenario.parse import load, to_toml

    table = copy.deepcopy(load("tiago-wheel-radius").table)
    table["duration"], table["events"][0]["time"] = 8.0, 4.0
    table["description"] = table["description"].replace("at 15 s", "at 4 s")
    (tmp_path / "tiago.toml").write_text(to_toml(table))
    assert main(["run", str(tmp_path / "tiago.toml"), "--out", str(tmp_path / "tiago"), "--no-plot"]) == 0
    png = render(
        tmp_path / "tiago" / "run.rrd",
        tmp_path,
        lambda img: _shows(img, {"reference path": REF_COLOR, "driven path": PATH_COLOR}, {"event marks": EVENT_COLOR}),
    )
    _keep(png, "tiago-viewer.png")


ROBOT_PICTURES = ("cart", "pal_tiago_dual", "hello_robot_stretch", "hello_robot_stretch_3", "rby1a")
PICTURE_BYTES = 200_000  # the docs' robot pictures at most


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (Debian: apt-get install chromium)")
@pytest.mark.menagerie
@pytest.mark.parametrize("robot", ROBOT_PICTURES)
def test_web_viewer_renders_each_robot(tmp_path: Path, robot: str) -> None:
    """The first 8 s of eight-wheel-radius with kanayama on each robot of docs/robots.md that runs
    (``--robot``), drawn from its own meshes with the paths: kept, halved and in 256 colours, as
    docs/robot-ROBOT.png (PAL TIAGo's is docs/tiago-viewer.png, the shipped robot's docs/viewer.png)."""
    pytest.importorskip("mujoco_menagerie")
    from PIL import Image

    from mlpfac.cli import main
    from mlpfac.log import PATH_COLOR, REF_COLOR

    argv = ["run", "eight-wheel-radius", "--robot", robot, "--controller", "kanayama", "--duration", "8"]
    main([*argv, "--out", str(tmp_path / "run"), "--no-plot"])  # lost or not: the picture shows it
    png = render(
        tmp_path / "run" / "run.rrd",
        tmp_path,
        lambda img: _shows(img, {"reference path": REF_COLOR, "driven path": PATH_COLOR}, {}),
    )
    small = io.BytesIO()
    Image.open(io.BytesIO(png)).convert("RGB").resize((WIDTH // 2, HEIGHT // 2), Image.LANCZOS).quantize(256).save(
        small, "PNG", optimize=True
    )
    assert len(small.getvalue()) < PICTURE_BYTES
    _keep(small.getvalue(), f"robot-{robot}.png")


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary (Debian: apt-get install chromium)")
def test_web_viewer_shows_what_the_robot_believed(tmp_path: Path) -> None:
    """A pose fused from odometry and fixes: the believed path and the fixes beside the true path on
    the left, the estimate's error plotted on the right."""
    from mlpfac.cli import main
    from mlpfac.log.belief import BELIEF_COLOR, FIX_COLOR
    from mlpfac.log.schema import ESTIMATE_COLORS
    from mlpfac.scenario.parse import load, to_toml

    table = copy.deepcopy(load("eight-wheel-radius-fused").table)
    table["duration"], table["events"][0]["time"] = 8.0, 4.0
    table.pop("provenance", None)
    (tmp_path / "fused.toml").write_text(to_toml(table))
    out = tmp_path / "fused"
    assert main(["run", str(tmp_path / "fused.toml"), "--controller", "kanayama", "--no-plot", "--out", str(out)]) == 0
    png = render(
        out / "run.rrd",
        tmp_path,
        lambda img: _shows(
            img,
            {"believed path": BELIEF_COLOR, "fixes": FIX_COLOR},  # on the true path (blue, wider: tested above)
            {"estimate's error": ESTIMATE_COLORS[0]},
        ),
    )
    _keep(png, "viewer-belief.png")
