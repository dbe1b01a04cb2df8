"""Where a recording goes: a file, a viewer started here (native or web), a running viewer; and
opening saved runs in a viewer. Every output is checked before the run starts (a bad one raises
ConfigError naming it), every port opened here binds to 127.0.0.1 unless ``bind`` says otherwise,
and a saved file is read back after it is closed (:func:`check_recording`).

Part of :mod:`mlpfac.log`: it imports rerun, so import it lazily.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from urllib.parse import quote, urlsplit

import rerun as rr

from mlpfac.exceptions import ConfigError
from mlpfac.io.interrupts import die_with_parent
from mlpfac.log.recorder import APPLICATION_ID, RerunSink

SPAWN_PORT = 9876  # the native viewer's gRPC port, rerun's default
SERVE_GRPC_PORT = 9876
SERVE_WEB_PORT = 9090
LOCALHOST = "127.0.0.1"
ANSI = re.compile(r"\x1b\[[0-9;]*m")
START_TIMEOUT_S = 20.0  # a viewer that does not listen by then is reported as not starting
WINDOW_GRACE_S = 2.0  # a native viewer listens before it opens its window: it must still run this long after


def make_sink(
    save: Path | str | None = None,
    spawn: bool = False,
    connect: str | None = None,
    serve: bool = False,
    recording_name: str = "",
    recording_id: str | None = None,
    bind: str = LOCALHOST,
    description: str = "",
    ports: tuple[int, int] = (SERVE_GRPC_PORT, SERVE_WEB_PORT),
) -> RerunSink | None:
    """A sink for the outputs asked for, or None when none is. Bad outputs raise ConfigError now.

    ``save``: write an .rrd file (the folder is created); ``spawn``: start (or reuse) a native
    viewer on port 9876; ``connect``: stream to a running viewer at a ``rerun+http://.../proxy``
    URL; ``serve``: start a web viewer on http://BIND:9090 (its gRPC server on 9876; ``ports``:
    gRPC, web) that serves the recording until :meth:`RerunSink.wait` returns. Viewers started
    here listen on ``bind``.
    ``description``: the scenario's, for the recording's text panel.
    """
    if save is None and not spawn and connect is None and not serve:
        return None
    # Check every output before anything starts, so a bad one costs nothing.
    if connect is not None:
        _check_reachable(connect)
    if save is not None:
        save = Path(save)
        _check_writable(save)
    if serve or spawn:
        check_bind(bind)
    if serve:
        _check_ports(bind, ports)
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id, send_properties=False)
    rec.set_log_time_enabled(False)  # no wall clock in the data: same run, same contents
    rec.set_log_tick_enabled(False)
    sinks: list = [rr.FileSink(save)] if save is not None else []
    urls = [connect] if connect is not None else []
    if spawn:
        urls.append(_spawn_viewer(bind, SPAWN_PORT))
    server = viewer_url = None
    if serve:
        server, grpc_url, viewer_url = start_web_viewer(bind, ports)
        urls.append(grpc_url)
    sinks += [rr.GrpcSink(url) for url in dict.fromkeys(urls)]  # --spawn and --connect may name one viewer
    try:
        rec.set_sinks(*sinks)
    except RuntimeError as err:  # the file sink writes its header at once: a full disk fails here
        _stop(server)
        raise ConfigError(str(save), f"cannot write the recording ({_first_line(err)})") from None
    sink = RerunSink(rec, recording_name=recording_name, serving=serve, viewer_url=viewer_url, description=description)
    sink.server = server
    return sink


def check_bind(bind: str) -> None:
    """ConfigError naming ``--bind`` when it is no IP address (the rerun viewer takes nothing else)."""
    import ipaddress

    try:
        ipaddress.ip_address(bind)
    except ValueError:
        raise ConfigError(
            "--bind", f"{bind!r} is not an IP address (127.0.0.1, 0.0.0.0 for every interface, ::1, ...)"
        ) from None


def _check_ports(bind: str, ports: tuple[int, int]) -> None:
    """ConfigError naming the flag of a port out of range, the same twice, or in use on ``bind``."""
    for flag, port in zip(("--grpc-port", "--port"), ports, strict=True):
        if not 1 <= port <= 65535:
            raise ConfigError(flag, f"{port} is not a port (1-65535)")
    if ports[0] == ports[1]:
        raise ConfigError("--port", f"the web viewer and its gRPC server cannot share port {ports[0]}")
    for flag, port in zip(("--grpc-port", "--port"), ports, strict=True):
        if _listening(bind, port):
            raise ConfigError(flag, f"port {port} is in use; stop what listens there, or choose another port")


def start_web_viewer(bind: str, ports: tuple[int, int] = (SERVE_GRPC_PORT, SERVE_WEB_PORT), files=()) -> tuple:
    """Start rerun's web viewer on ``bind`` (``ports``: its gRPC server, the page), stopped when this
    process dies, holding ``files`` (.rrd) if given; (process, gRPC URL, the page's URL)."""
    grpc, web = ports
    server = _start_viewer(
        "--serve",
        ["--serve-web", "--bind", bind, "--port", str(grpc), "--web-viewer-port", str(web), *map(str, files)],
        ports=ports,
        host=bind,
        outlive=False,
        window=False,
    )
    grpc_url = f"rerun+http://{_url_host(bind)}:{grpc}/proxy"
    return server, grpc_url, f"http://{_url_host(bind)}:{web}/?url={quote(grpc_url, safe='')}"


def tunnel_line(ports: tuple[int, int]) -> str:
    """How to see a web viewer served on a machine without a display from another one."""
    forwards = " ".join(f"-L {p}:{LOCALHOST}:{p}" for p in reversed(ports))
    return f"from another machine: ssh -N {forwards} USER@THIS_HOST, then open the address above there"


def check_recording(path: Path, shown: Path | str | None = None) -> None:
    """Read a closed .rrd back: a file cut short (a full disk, a file-size limit, a write error of
    rerun's file sink) has no footer or a truncated message, and raises ConfigError naming ``shown``.
    It reads the footer and decodes every chunk: ~20 ms for the 5.5 MB of a 25 s run."""
    from rerun.chunk import RrdReader

    shown = str(shown or path)
    size = path.stat().st_size if path.exists() else 0
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # "RRD file has no footer": the encoder never finished
            chunks = sum(1 for _ in RrdReader(path).store().stream().to_chunks())
    except Exception:  # no footer (rerun's encoder never finished), or a message cut short
        raise ConfigError(
            shown, f"the recording was cut short at {size} bytes (a full disk or a file-size limit?); nothing was kept"
        ) from None
    if chunks == 0:
        raise ConfigError(shown, "the recording holds no data")


def _check_writable(path: Path) -> None:
    where = str(path)
    if path.is_dir():
        raise ConfigError(where, "is a folder; --save needs a file name such as run.rrd")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb"):
            pass
    except OSError as err:
        raise ConfigError(where, f"cannot write the recording here ({err.strerror or err})") from None


def _check_reachable(url: str) -> None:
    parts = urlsplit(url)
    if parts.scheme not in ("rerun", "rerun+http", "rerun+https") or parts.path != "/proxy":
        raise ConfigError(url, "a viewer URL looks like rerun+http://127.0.0.1:9876/proxy")
    try:
        host, port = parts.hostname or LOCALHOST, parts.port or (443 if parts.scheme == "rerun+https" else 9876)
    except ValueError as err:
        raise ConfigError(url, f"bad viewer URL ({err})") from None
    if not _listening(host, port):
        raise ConfigError(url, "no rerun viewer is listening there; start one with `rerun` or use --save")
    if not _answers(host, port):
        raise ConfigError(
            url, f"something accepts connections there but does not answer within {ANSWER_S:g} s: not a rerun viewer?"
        )


ANSWER_S = 3.0  # seconds a viewer has to answer a request (or close the connection) before it is given up


def _answers(host: str, port: int) -> bool:
    """Whether what listens at host:port answers an HTTP request (with anything, or by closing the
    connection) within ANSWER_S: a server that accepts and never answers would hang the run's end."""
    host = LOCALHOST if host in ("0.0.0.0", "") else "::1" if host == "::" else host  # noqa: S104
    try:
        with socket.create_connection((host, port), timeout=ANSWER_S) as conn:
            conn.sendall(f"GET / HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
            conn.recv(1)
    except TimeoutError:
        return False
    except OSError:  # reset, refused: it answered, if not as a viewer would
        return True
    return True


def _listening(host: str, port: int, timeout: float = 1.0) -> bool:
    host = LOCALHOST if host in ("0.0.0.0", "") else "::1" if host == "::" else host  # noqa: S104
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return True
    except OSError:
        return False


def _url_host(bind: str) -> str:
    if bind in ("0.0.0.0", "::", ""):  # noqa: S104
        return LOCALHOST
    return f"[{bind}]" if ":" in bind else bind


def _check_display(where: str) -> None:
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ConfigError(
            where,
            "no display for the native viewer (DISPLAY and WAYLAND_DISPLAY are unset); "
            "add --serve to serve a web viewer instead (docs/runs.md: on a machine without a display)",
        )


def rerun_executable() -> str:
    """The rerun viewer binary installed with rerun-sdk (not its Python wrapper), else `rerun` on PATH."""
    try:
        import rerun_cli

        exe = Path(rerun_cli.__file__).with_name("rerun.exe" if sys.platform.startswith("win") else "rerun")
        if exe.is_file():
            return str(exe)
    except ImportError:
        pass
    exe = shutil.which("rerun")
    if exe is None:
        raise ConfigError("rerun", "the rerun viewer is not installed (pip install rerun-sdk)")
    return exe


def _start_viewer(
    where: str,
    args: list[str],
    ports: Sequence[int],
    host: str = LOCALHOST,
    outlive: bool = True,
    window: bool = True,
) -> subprocess.Popen:
    """Start the rerun binary in its own session and wait until it listens on every port in
    ``ports``; a viewer that exits first or never listens raises ConfigError naming ``where``.
    ``window``: a native viewer opens its window after it listens, and one that cannot exits then:
    it must still run ``WINDOW_GRACE_S`` after it listens. ``outlive=False``: on Linux the viewer
    gets SIGTERM when this process dies, however it dies."""
    with tempfile.TemporaryFile() as log:  # a file, not a pipe: the viewer outlives us and must not block
        try:
            proc = subprocess.Popen(
                [rerun_executable(), *args],
                start_new_session=True,
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=log,
                preexec_fn=None
                if outlive or not sys.platform.startswith("linux")
                else partial(die_with_parent, signal.SIGTERM),
            )
        except OSError as err:
            raise ConfigError(where, f"cannot start the rerun viewer ({err.strerror or err})") from None
        deadline, listening_since = time.monotonic() + START_TIMEOUT_S, None
        while time.monotonic() < deadline:
            code = proc.poll()
            if code is not None:
                log.seek(0)
                said = [ANSI.sub("", ln).strip() for ln in log.read().decode(errors="replace").splitlines()]
                said = [ln for ln in said if ln]
                raise ConfigError(
                    where, f"the rerun viewer exited at once (code {code}{': ' + said[-1] if said else ''})"
                )
            if listening_since is None and all(_listening(host, p, timeout=0.2) for p in ports):
                listening_since = time.monotonic()
            if listening_since is not None and (not window or time.monotonic() - listening_since >= WINDOW_GRACE_S):
                return proc
            time.sleep(0.1)
    _stop(proc)
    raise ConfigError(where, f"the rerun viewer did not listen on port {ports[0]} within {START_TIMEOUT_S:g} s")


def _stop(proc: subprocess.Popen | None) -> None:
    if proc is not None and proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _spawn_viewer(bind: str, port: int) -> str:
    """Start a native viewer listening on ``bind:port`` (or reuse the one there); its URL."""
    url = f"rerun+http://{_url_host(bind)}:{port}/proxy"
    if _listening(bind, port):
        return url  # a viewer is already running there: reuse it, as rerun's own spawn does
    _check_display("--spawn")
    _start_viewer("--spawn", ["--bind", bind, "--port", str(port), "--expect-data-soon"], ports=(port,), host=bind)
    return url


def _free_port() -> int:
    with socket.socket() as s:
        s.bind((LOCALHOST, 0))
        return s.getsockname()[1]


def _first_line(err: BaseException) -> str:
    lines = str(err).strip().splitlines()
    return lines[0] if lines else type(err).__name__
