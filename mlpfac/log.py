"""Logging a run to rerun: the robot in 3D, a top view, the tracking error, the commands, every
network weight, the EKF's covariance, the plant events and the final status, with a default layout.

This is the only module that imports rerun; import it lazily, so runs without logging do not pay
rerun's import. The runner drives a sink like this::

    sink = make_sink(save=run_dir / "run.rrd", recording_name=..., recording_id=...)  # None: no sink
    sink.begin(record, geometry=plant.geometry(), ref_path=record.ref)  # static scene
    ...every few hundred steps: sink.flush(record, upto=k + 1)  # rows not sent yet, column-wise
    sink.end(record)  # in a finally: last rows, events, status; completes the file

Two timelines: ``sim_time`` (duration, the controller clock t[k] = k T) and ``step`` (k).
Per-step values are scalar series, one row per control step. The robot's pose, the reference
arrow and the top-view markers are sent every ``POSE_STRIDE`` steps, the driven path every
``PATH_STRIDE`` steps (a growing line strip through every ``PATH_POINT_STRIDE``-th pose), and the
last valid row always, so the final picture is exact.

No wall-clock time is recorded, so the same run gives the same decoded contents. The bytes of two
.rrd files still differ: rerun stamps every chunk and row with a time-based unique id.
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote, urlsplit

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb

from mlpfac.exceptions import ConfigError
from mlpfac.record import RunRecord

APPLICATION_ID = "mlpfac"
POSE_STRIDE = 5  # robot transform, reference arrow, top-view markers: every 5th step
PATH_STRIDE = 25  # the driven path is re-sent every 25th step ...
PATH_POINT_STRIDE = 5  # ... through every 5th pose
BATCH_ROWS = 1000  # flush() sends once this many rows are pending ...
BATCH_SECONDS = 1.0  # ... or this much wall time has passed since the last send
SPAWN_PORT = 9876  # the native viewer's gRPC port, rerun's default
SERVE_GRPC_PORT = 9876
SERVE_WEB_PORT = 9090

# Colours (RGB): the reference is orange, the robot's own path blue, e1/e2/e3 red/green/blue.
REF_COLOR = (255, 160, 40)
PATH_COLOR = (60, 140, 255)
ROBOT_COLOR = (230, 230, 230)
ERROR_COLORS = ((230, 70, 70), (80, 200, 90), (80, 140, 255), (240, 220, 80))
CMD_COLOR, MEAS_COLOR, REFSPEED_COLOR = (80, 160, 255), (255, 130, 60), (150, 150, 150)
TRUE_COLOR, P_COLOR, OTHER_COLOR = (150, 150, 150), (240, 200, 80), (200, 200, 200)
WEIGHT_COLORS = {  # one hue per network and layer
    "NN_f/output": (90, 160, 255),
    "NN_f/hidden": (120, 220, 160),
    "NN_G/output": (255, 150, 80),
    "NN_G/hidden": (240, 110, 200),
}
# Telemetry keys with a place of their own; any other key is logged under plant/<key> or ctrl/<key>.
_KNOWN = {
    "plant": {"u_meas", "wheel_cmd", "wheel_meas", "h_true"},
    "ctrl": {"z", "trace_P", "mean_diag_P", "innovation", "h_hat"},
}
SCALARS = rr.Scalars.descriptor_scalars()
STATUS_LEVEL = {"ok": "INFO", "interrupted": "WARN", "diverged": "ERROR"}

Getter = Callable[[RunRecord, slice], np.ndarray]


@dataclass(frozen=True)
class _Batch:
    """An arrow array of scalar values, as rr.ComponentColumn wants it."""

    array: pa.Array

    def as_arrow_array(self) -> pa.Array:
        return self.array


@dataclass(frozen=True)
class Series:
    """A scalar time series entity: an entity path, where its values come from, and its style.

    ``name`` is one name for one line per step, or a tuple of names for several lines that share
    the entity (``get`` then gives (rows, lines)): the network weights go one entity per layer,
    since a chunk per weight made saving a run three times as slow and its file three times as big.
    """

    path: str
    get: Getter
    name: str | tuple[str, ...]
    color: tuple[int, int, int]
    width: float = 1.5

    @property
    def names(self) -> list[str]:
        return list(self.name) if isinstance(self.name, tuple) else [self.name]


# ----------------------------------------------------------------------------------------------
# Opening a sink


def make_sink(
    save: Path | str | None = None,
    spawn: bool = False,
    connect: str | None = None,
    serve: bool = False,
    recording_name: str = "",
    recording_id: str | None = None,
) -> RerunSink | None:
    """A sink for the outputs asked for, or None when none is. Bad outputs raise ConfigError now.

    ``save``: write an .rrd file (the folder is created); ``spawn``: start (or reuse) a native
    viewer on port 9876; ``connect``: stream to a running viewer at a ``rerun+http://.../proxy``
    URL; ``serve``: host a web viewer on http://127.0.0.1:9090 (gRPC on 9876) while this process
    lives -- see :meth:`RerunSink.wait`.
    """
    if save is None and not spawn and connect is None and not serve:
        return None
    # Check every output before anything starts, so a bad one costs nothing.
    if connect is not None:
        _check_reachable(connect)
    if save is not None:
        save = Path(save)
        _check_writable(save)
    if serve:
        for port in (SERVE_GRPC_PORT, SERVE_WEB_PORT):
            if _listening("127.0.0.1", port):
                raise ConfigError("--serve", f"port {port} is in use; stop what listens there or use --save")
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id, send_properties=False)
    rec.set_log_time_enabled(False)  # no wall clock in the data: same run, same contents
    rec.set_log_tick_enabled(False)
    sinks: list = [rr.FileSink(save)] if save is not None else []
    urls = [connect] if connect is not None else []
    if spawn:
        urls.append(_spawn_viewer(rec, SPAWN_PORT))
    sinks += [rr.GrpcSink(url) for url in dict.fromkeys(urls)]  # --spawn and --connect may name one viewer
    viewer_url = None
    if serve:
        server = rr.GrpcServerSink(bind_ip="127.0.0.1", port=SERVE_GRPC_PORT)
        sinks.append(server)
        rr.serve_web_viewer(web_port=SERVE_WEB_PORT, open_browser=False, connect_to=server.uri)
        viewer_url = f"http://127.0.0.1:{SERVE_WEB_PORT}/?url={quote(server.uri, safe='')}"
    rec.set_sinks(*sinks)
    return RerunSink(rec, recording_name=recording_name, serving=serve, viewer_url=viewer_url)


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
        host, port = parts.hostname or "127.0.0.1", parts.port or (443 if parts.scheme == "rerun+https" else 9876)
    except ValueError as err:
        raise ConfigError(url, f"bad viewer URL ({err})") from None
    if not _listening(host, port):
        raise ConfigError(url, "no rerun viewer is listening there; start one with `rerun` or use --save")


def _listening(host: str, port: int, timeout: float = 1.0) -> bool:
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return True
    except OSError:
        return False


def _check_display(where: str) -> None:
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ConfigError(
            where,
            "no display for the native viewer (DISPLAY and WAYLAND_DISPLAY are unset); "
            "use --save and `rerun --serve-web FILE` to view it in a browser",
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


def _spawn_viewer(rec: rr.RecordingStream, port: int) -> str:
    """Start a native viewer listening on ``port`` (or reuse the one there); its URL."""
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    if _listening("127.0.0.1", port):
        return url  # a viewer is already running there: reuse it, as rerun's own spawn does
    _check_display("--spawn")
    try:
        # rr.spawn waits until the viewer listens; it needs the recording (without one it does nothing).
        rr.spawn(port=port, connect=False, executable_path=rerun_executable(), recording=rec)
    except RuntimeError as err:
        raise ConfigError("--spawn", f"could not start the rerun viewer: {str(err).splitlines()[0]}") from None
    time.sleep(0.5)  # a viewer that cannot open a window listens for a moment, then exits
    if not _listening("127.0.0.1", port):
        raise ConfigError("--spawn", "the rerun viewer started and exited; use --save and open the file instead")
    return url


# ----------------------------------------------------------------------------------------------
# The sink


class RerunSink:
    """Sends one run to rerun. Made by :func:`make_sink`; see the module docstring for the call order."""

    def __init__(self, rec: rr.RecordingStream, recording_name: str, serving: bool, viewer_url: str | None) -> None:
        self.rec = rec
        self.recording_name = recording_name
        self.serving = serving
        self.viewer_url = viewer_url  # the web viewer's address when serving
        self.sent = 0  # rows of the record already sent
        self.events_sent = 0
        self.last_send = time.monotonic()  # wall clock of the last send (batching only, never logged)
        self.series: list[Series] = []
        self.planned_keys: tuple | None = None  # telemetry keys the series were planned for
        self.styled: set[str] = set()
        self.blueprint_sent = False
        self.ref_path: np.ndarray | None = None
        self.ended = False
        self.closed = False

    # -- the three calls of the runner ---------------------------------------------------------

    def begin(self, record: RunRecord, geometry: Sequence[dict] = (), ref_path: np.ndarray | None = None) -> None:
        """Send the static scene: name, run properties, floor, robot shapes, reference path."""
        rec = self.rec
        if self.recording_name:
            rec.send_recording_name(self.recording_name)
        rec.send_property(
            "run",
            rr.AnyValues(
                scenario=record.scenario, controller=record.controller, seed=int(record.seed), T=float(record.T)
            ),
        )
        ref = record.ref if ref_path is None else np.asarray(ref_path, dtype=float)
        ref_xy = ref[np.all(np.isfinite(ref[:, :2]), axis=1), :2]
        self.ref_path = ref_xy
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        lo, hi = _bounds(ref_xy)
        center, half = (lo + hi) / 2, (hi - lo) / 2 + 1.0
        rec.log(
            "world/floor",
            rr.Boxes3D(
                half_sizes=[[half[0], half[1], 0.005]],
                centers=[[center[0], center[1], -0.006]],
                colors=[(70, 70, 75)],
                fill_mode="solid",
            ),
            static=True,
        )
        if len(ref_xy):
            rec.log(
                "world/reference_path",
                rr.LineStrips3D([np.c_[ref_xy, np.full(len(ref_xy), 0.002)]], colors=[REF_COLOR], radii=[0.008]),
                static=True,
            )
        for name, arch in _robot_shapes(geometry):
            rec.log(f"world/robot/{name}", arch, static=True)
        rec.log("world/robot", rr.TransformAxes3D(axis_length=0.15), static=True)
        rec.log(
            "world/reference_now",
            rr.Arrows3D.from_fields(colors=[REF_COLOR], radii=[0.012]),
            static=True,
        )
        rec.log("world/path", rr.LineStrips3D.from_fields(colors=[PATH_COLOR], radii=[0.01]), static=True)
        # The top view: a 2D view draws y downwards, so the plane is mirrored once, here, and the
        # entities below it keep the record's own (x, y).
        rec.log("top/plane", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        if len(ref_xy):
            rec.log(
                "top/plane/reference_path",
                rr.LineStrips2D([ref_xy], colors=[REF_COLOR], radii=[0.01]),
                static=True,
            )
        rec.log(
            "top/plane/axes",
            rr.Arrows2D(
                origins=[[0.0, 0.0], [0.0, 0.0]],
                vectors=[[0.3, 0.0], [0.0, 0.3]],
                colors=[(230, 70, 70), (80, 200, 90)],
                labels=["x", "y"],
                radii=[0.01],
            ),
            static=True,
        )
        rec.log("top/plane/path", rr.LineStrips2D.from_fields(colors=[PATH_COLOR], radii=[0.012]), static=True)
        rec.log("top/plane/robot", rr.Arrows2D.from_fields(colors=[ROBOT_COLOR], radii=[0.02]), static=True)
        rec.log("top/plane/reference_now", rr.Points2D.from_fields(colors=[REF_COLOR], radii=[0.05]), static=True)

    def flush(self, record: RunRecord, upto: int | None = None, force: bool = False) -> None:
        """Send rows [sent, upto) of the record (default: up to ``record.n``) and any new events.

        Rows are held back until ``BATCH_ROWS`` are pending or ``BATCH_SECONDS`` of wall time
        have passed (or ``force``): every send costs a chunk per series, and a 25 s run takes
        about a second, so bigger chunks are cheaper and no later on screen.
        """
        upto = record.n if upto is None else min(int(upto), record.n)  # rows past n are not valid
        a, b = self.sent, upto
        due = force or b - a >= BATCH_ROWS or time.monotonic() - self.last_send >= BATCH_SECONDS
        if b > a and due:
            self._update_series(record)
            idx = _index(record, np.arange(a, b))
            for s in self.series:  # one chunk per series; ComponentColumn skips Scalars.columns' checks (2x faster)
                values = np.ascontiguousarray(s.get(record, slice(a, b)), dtype=np.float64)
                column = rr.ComponentColumn(SCALARS, _Batch(pa.array(values.ravel())))
                if values.ndim == 2:  # several lines: each row holds one value per line
                    column = column.partition(np.full(len(values), values.shape[1]))
                self.rec.send_columns(s.path, indexes=idx, columns=[column])
            self._send_poses(record, _strided(a, b, POSE_STRIDE), _strided(a, b, PATH_STRIDE))
            self.sent = b
            self.last_send = time.monotonic()
            if not self.blueprint_sent:
                self._send_blueprint(record)
        self._send_events(record)

    def end(self, record: RunRecord) -> None:
        """Send what is left, the final pose, events and status; then close the file and connections.

        Safe to call in a ``finally`` after divergence or Ctrl-C, and more than once. When serving a
        web viewer the server stays up until :meth:`close` (see :meth:`wait`).
        """
        if self.ended:
            return
        self.ended = True
        try:
            self.flush(record, upto=record.n, force=True)
            n = record.n
            if n > 0:
                last = np.array([n - 1])
                self._send_poses(
                    record,
                    last if (n - 1) % POSE_STRIDE else last[:0],
                    last if (n - 1) % PATH_STRIDE else last[:0],
                )
            if not self.blueprint_sent:
                self._send_blueprint(record)
            self._send_status(record)
        finally:
            if not self.serving:
                self.close()

    def close(self) -> None:
        """Flush and close every output: the file gets its footer, connections and servers stop."""
        if not self.closed:
            self.closed = True
            self.rec.disconnect()

    def wait(self) -> None:
        """When serving: keep the web viewer up until Ctrl-C, then close. Otherwise return at once."""
        if self.serving and not self.closed:
            try:
                while True:
                    time.sleep(1.0)
            except KeyboardInterrupt:
                pass
            finally:
                self.close()

    # -- pieces --------------------------------------------------------------------------------

    def _update_series(self, record: RunRecord) -> None:
        """(Re)plan the scalar series when the record has keys not seen yet; style new ones."""
        keys = (tuple(record.plant), tuple(record.ctrl))
        if keys == self.planned_keys:
            return
        self.planned_keys = keys
        self.series = plan_series(record)
        for s in self.series:
            if s.path not in self.styled:
                self.styled.add(s.path)
                k = len(s.names)
                self.rec.log(
                    s.path, rr.SeriesLines(colors=[s.color] * k, names=s.names, widths=[s.width] * k), static=True
                )

    def _send_poses(self, record: RunRecord, rows: np.ndarray, path_rows: np.ndarray) -> None:
        """Robot, reference arrow and top-view markers at ``rows``; the driven path at ``path_rows``.
        A non-finite pose (the step a run diverged at) is left out of the pictures."""
        rec = self.rec
        rows = rows[
            np.all(np.isfinite(record.pose[rows, :3]), axis=1) & np.all(np.isfinite(record.ref[rows, :3]), axis=1)
        ]
        if len(rows):
            x, y, th = record.pose[rows].T
            zeros = np.zeros_like(x)
            idx = _index(record, rows)
            rec.send_columns(
                "world/robot",
                indexes=idx,
                columns=rr.Transform3D.columns(
                    translation=np.c_[x, y, zeros],
                    quaternion=np.c_[zeros, zeros, np.sin(th / 2), np.cos(th / 2)],
                ),
            )
            r = record.ref[rows]
            heading = 0.3 * np.c_[np.cos(r[:, 2]), np.sin(r[:, 2])]
            rec.send_columns(
                "world/reference_now",
                indexes=idx,
                columns=rr.Arrows3D.columns(origins=np.c_[r[:, :2], zeros + 0.02], vectors=np.c_[heading, zeros]),
            )
            rec.send_columns(
                "top/plane/robot",
                indexes=idx,
                columns=rr.Arrows2D.columns(origins=np.c_[x, y], vectors=0.25 * np.c_[np.cos(th), np.sin(th)]),
            )
            rec.send_columns("top/plane/reference_now", indexes=idx, columns=rr.Points2D.columns(positions=r[:, :2]))
        if len(path_rows):
            strips = [driven_path(record.pose, k) for k in path_rows]
            idx = _index(record, path_rows)
            rec.send_columns(
                "world/path",
                indexes=idx,
                columns=rr.LineStrips3D.columns(strips=[np.c_[p, np.full(len(p), 0.004)] for p in strips]),
            )
            rec.send_columns("top/plane/path", indexes=idx, columns=rr.LineStrips2D.columns(strips=strips))

    def _send_events(self, record: RunRecord) -> None:
        new = record.events[self.events_sent :]
        if not new:
            return
        self.events_sent = len(record.events)
        times = np.array([float(ev["time"]) for ev in new])
        steps = np.round(times / record.T).astype(np.int64)
        texts = [event_text(ev) for ev in new]
        self.rec.send_columns(
            "events",
            indexes=[rr.TimeColumn("sim_time", duration=_ns(times)), rr.TimeColumn("step", sequence=steps)],
            columns=rr.TextLog.columns(text=texts, level=["WARN"] * len(new)),
        )

    def _send_status(self, record: RunRecord) -> None:
        k = max(record.n - 1, 0)
        text = f"{record.status}: {record.reason}" if record.reason else record.status
        text += f" ({record.n} steps, {record.scenario} / {record.controller} / seed {record.seed})"
        self.rec.send_columns(
            "status",
            indexes=_index(record, np.array([k])),
            columns=rr.TextLog.columns(text=[text], level=[STATUS_LEVEL.get(record.status, "INFO")]),
        )

    def _send_blueprint(self, record: RunRecord) -> None:
        self.blueprint_sent = True
        self.rec.send_blueprint(blueprint(record, self.ref_path), make_active=True, make_default=True)


# ----------------------------------------------------------------------------------------------
# What is sent, as plain functions of the record


def plan_series(record: RunRecord) -> list[Series]:
    """Every scalar series of this record: errors, controls, wheels, weights, EKF, h; then any
    other telemetry key under ``plant/<key>`` or ``ctrl/<key>``."""
    labels: dict[str, list[str]] = getattr(record, "labels", None) or {}
    plant, ctrl = record.plant, record.ctrl
    out: list[Series] = []
    for j, name in enumerate(("e1", "e2", "e3")):
        out.append(Series(f"errors/{name}", _column("e_true", j), name, ERROR_COLORS[j]))
    out.append(Series("errors/position", position_error, "|(e1, e2)|", ERROR_COLORS[3]))
    for j, q in enumerate(("v", "omega")):
        out.append(Series(f"controls/{q}/cmd", _column("u", j), f"{q} commanded", CMD_COLOR))
        if "u_meas" in plant:
            out.append(Series(f"controls/{q}/meas", _column("u_meas", j, "plant"), f"{q} measured", MEAS_COLOR))
        out.append(Series(f"controls/{q}/ref", _column("ref", 3 + j), f"{q}_r", REFSPEED_COLOR, 1.0))
    for j, side in enumerate(("left", "right")):
        if "wheel_cmd" in plant:
            out.append(Series(f"wheels/{side}/cmd", _column("wheel_cmd", j, "plant"), f"{side} commanded", CMD_COLOR))
        if "wheel_meas" in plant:
            out.append(Series(f"wheels/{side}/meas", _column("wheel_meas", j, "plant"), f"{side} measured", MEAS_COLOR))
    if "z" in ctrl:  # one entity per network layer, one line per weight
        groups: dict[str, list[int]] = {}
        names = _labels(labels, "z", ctrl["z"], "w")
        for i, label in enumerate(names):
            groups.setdefault(label.rpartition("/")[0], []).append(i)
        for group, idx in groups.items():
            path = f"weights/{group}" if group else "weights"
            line_names = tuple(names[i].rpartition("/")[2] for i in idx)
            color = WEIGHT_COLORS.get(group, OTHER_COLOR)
            out.append(Series(path, _column("z", idx, "ctrl"), line_names, color, 1.0))
    for key, name in (("trace_P", "trace(P)"), ("mean_diag_P", "mean diag(P)")):
        if key in ctrl:
            out.append(Series(f"ekf/{key}", _column(key, None, "ctrl"), name, P_COLOR))
    if "innovation" in ctrl:
        names = _labels(labels, "innovation", ctrl["innovation"], "e", default=["e1", "e2", "e3"])
        for j, name in enumerate(names):
            out.append(Series(f"ekf/innovation/{name}", _column("innovation", j, "ctrl"), name, ERROR_COLORS[j % 3]))
    h_names = _labels(labels, "h_hat", ctrl.get("h_hat", plant.get("h_true")), "h", default=["h1", "h2", "h5"])
    for j, name in enumerate(h_names):
        if "h_hat" in ctrl:
            out.append(Series(f"h/{name}/estimate", _column("h_hat", j, "ctrl"), f"{name} estimate", CMD_COLOR))
        if "h_true" in plant:
            out.append(Series(f"h/{name}/true", _column("h_true", j, "plant"), f"{name} true", TRUE_COLOR))
    for store in ("plant", "ctrl"):
        for key, arr in getattr(record, store).items():
            if key in _KNOWN[store]:
                continue
            if arr.ndim == 1:
                out.append(Series(f"{store}/{_part(key)}", _column(key, None, store), key, OTHER_COLOR))
            else:
                flat = arr.reshape(len(arr), -1)
                for j, name in enumerate(_labels(labels, key, flat, "")):
                    out.append(Series(f"{store}/{_part(key)}/{name}", _column(key, j, store), name, OTHER_COLOR))
    return out


def position_error(record: RunRecord, s: slice) -> np.ndarray:
    """|(e1, e2)| of the true error: the distance from the reference point."""
    e = record.e_true[s]
    return np.hypot(e[:, 0], e[:, 1])


def driven_path(pose: np.ndarray, k: int) -> np.ndarray:
    """(x, y) of every ``PATH_POINT_STRIDE``-th pose up to step k, and of step k itself: (m, 2)."""
    xy = pose[: k + 1 : PATH_POINT_STRIDE, :2]
    xy = xy if k % PATH_POINT_STRIDE == 0 else np.vstack([xy, pose[k, :2]])
    return xy[np.all(np.isfinite(xy), axis=1)]


def event_text(ev: dict) -> str:
    text = ev.get("text")
    if text:
        return str(text)
    args = ", ".join(f"{k}={v}" for k, v in sorted((ev.get("params") or {}).items()))
    return f"{ev.get('kind', 'event')}({args}) at {float(ev['time']):g} s"


def blueprint(record: RunRecord, ref_xy: np.ndarray | None = None) -> rrb.Blueprint:
    """The default layout: 3D world, top view and events on the left; time series on the right."""
    plant, ctrl = record.plant, record.ctrl
    ref_xy = record.ref[: max(record.n, 1), :2] if ref_xy is None else ref_xy
    lo, hi = _bounds(ref_xy)
    center, size = (lo + hi) / 2, max(float(np.max(hi - lo)), 1.0)
    margin = 0.15 * size + 0.3
    left = rrb.Vertical(
        rrb.Spatial3DView(
            name="world",
            origin="/world",
            eye_controls=rrb.EyeControls3D(
                position=[center[0], center[1] - 1.1 * size, 0.9 * size],
                look_target=[center[0], center[1], 0.0],
                eye_up=[0.0, 0.0, 1.0],
            ),
        ),
        rrb.Spatial2DView(
            name="top view (x right, y up)",
            origin="/top",
            visual_bounds=rrb.VisualBounds2D(
                x_range=[lo[0] - margin, hi[0] + margin], y_range=[-hi[1] - margin, -lo[1] + margin]
            ),
        ),
        rrb.TextLogView(name="events and status", origin="/", contents=["/events", "/status"]),
        row_shares=[4, 4, 1.5],
    )
    speeds = [
        rrb.TimeSeriesView(name="v (m/s)", origin="/controls/v"),
        rrb.TimeSeriesView(name="omega (rad/s)", origin="/controls/omega"),
    ]
    if "wheel_cmd" in plant or "wheel_meas" in plant:
        speeds.append(rrb.TimeSeriesView(name="wheel speeds (rad/s)", origin="/wheels"))
    right = [
        rrb.TimeSeriesView(name="tracking error (true)", origin="/errors"),
        rrb.Horizontal(*speeds),
    ]
    if "z" in ctrl:
        right.append(
            rrb.TimeSeriesView(name="network weights", origin="/weights", plot_legend=rrb.PlotLegend(visible=False))
        )
    tabs = [
        rrb.TimeSeriesView(name=name, origin=f"/ekf/{key}")
        for key, name in (("trace_P", "trace(P)"), ("mean_diag_P", "mean diag(P)"))
        if key in ctrl
    ]
    if "innovation" in ctrl:
        tabs.append(rrb.TimeSeriesView(name="innovation", origin="/ekf/innovation"))
    if "h_hat" in ctrl or "h_true" in plant:
        tabs.append(rrb.TimeSeriesView(name="h1, h2, h5", origin="/h"))
    extra = [s for s in ("plant", "ctrl") if set(getattr(record, s)) - _KNOWN[s]]
    tabs += [rrb.TimeSeriesView(name=f"other {s} telemetry", origin=f"/{s}") for s in extra]
    if tabs:
        right.append(rrb.Tabs(*tabs))
    return rrb.Blueprint(
        rrb.Horizontal(left, rrb.Vertical(*right), column_shares=[2, 3]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="sim_time", play_state="following"),  # open at the end
    )


def _robot_shapes(geometry: Sequence[dict]) -> list[tuple[str, object]]:
    """rerun archetypes for plant.geometry() shapes (MuJoCo sizes: half sizes, radius, half length).

    The shapes are given relative to the measured frame, whose height differs between plants (the
    floor, the axle): they are lifted together so that the lowest point touches the floor.
    """
    out: list[tuple[str, object]] = []
    seen: set[str] = set()
    lift = -min((_lowest_point(g) for g in geometry), default=0.0)
    for i, g in enumerate(geometry):
        name = _part(str(g.get("name") or f"geom{i}"))
        if name in seen:
            name = f"{name}_{i}"
        seen.add(name)
        size = np.asarray(g.get("size", [0.05]), dtype=float)
        pos = [np.asarray(g.get("pos", [0.0, 0.0, 0.0]), dtype=float) + [0.0, 0.0, lift]]
        w, x, y, z = np.asarray(g.get("quat", [1.0, 0.0, 0.0, 0.0]), dtype=float)
        quat = [rr.Quaternion(xyzw=[x, y, z, w])]
        rgba = np.asarray(g.get("rgba", [0.7, 0.7, 0.7, 1.0]), dtype=float)
        color = [tuple(int(round(255 * c)) for c in np.clip(rgba, 0.0, 1.0))]
        kind = g.get("type")
        if kind == "box":
            arch = rr.Boxes3D(half_sizes=[size[:3]], centers=pos, quaternions=quat, colors=color, fill_mode="solid")
        elif kind == "cylinder":
            arch = rr.Cylinders3D(
                lengths=[2 * size[1]], radii=[size[0]], centers=pos, quaternions=quat, colors=color, fill_mode="solid"
            )
        elif kind == "capsule":
            arch = rr.Capsules3D(
                lengths=[2 * size[1]], radii=[size[0]], translations=pos, quaternions=quat, colors=color
            )
        elif kind == "sphere":
            arch = rr.Ellipsoids3D(half_sizes=[[size[0]] * 3], centers=pos, colors=color, fill_mode="solid")
        else:
            arch = rr.TextLog(f"geom {name!r}: type {kind!r} is not drawn", level="WARN")
        out.append((name, arch))
    return out


def _lowest_point(g: dict) -> float:
    """Height of a shape's lowest point in its frame (boxes, cylinders, capsules, spheres)."""
    size = np.asarray(g.get("size", [0.05]), dtype=float)
    w, x, y, z = np.asarray(g.get("quat", [1.0, 0.0, 0.0, 0.0]), dtype=float)
    up = np.array([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])  # row z of R(quat)
    kind = g.get("type")
    if kind == "box":
        extent = float(np.abs(up) @ size[:3])
    elif kind in ("cylinder", "capsule"):  # axis along the shape's z; a capsule adds its end caps
        r, h, c = size[0], size[1], abs(up[2])
        extent = c * h + (r if kind == "capsule" else r * np.sqrt(max(0.0, 1.0 - c * c)))
    elif kind == "sphere":
        extent = float(size[0])
    else:
        return np.inf
    return float(g.get("pos", [0.0, 0.0, 0.0])[2]) - extent


def _column(key: str, j: int | list[int] | None, store: str = "record") -> Getter:
    """Values of component j (of the flattened trailing axes) of a record array or telemetry key;
    (rows, len(j)) for a list of components, the whole array for None."""

    def get(record: RunRecord, s: slice) -> np.ndarray:
        arr = (getattr(record, key) if store == "record" else getattr(record, store)[key])[s]
        return arr if j is None else arr.reshape(len(arr), -1)[:, j]

    return get


def _labels(labels: dict, key: str, arr: np.ndarray | None, prefix: str, default: list[str] | None = None) -> list[str]:
    """Names of the components of a telemetry key: the record's labels, else a default, else indices."""
    width = 0 if arr is None else int(np.prod(arr.shape[1:]))
    names = labels.get(key)
    if names is None or len(names) != width:
        names = default if default is not None and len(default) == width else [f"{prefix}{i}" for i in range(width)]
    return ["/".join(_part(p) for p in str(name).split("/")) for name in names]


def _part(name: str) -> str:
    """One entity-path part: letters, digits, '_', '-', '.' kept; anything else becomes '_'."""
    return re.sub(r"[^A-Za-z0-9_.\-]", "_", name) or "_"


def _ns(seconds: np.ndarray) -> np.ndarray:
    """Seconds as whole nanoseconds, rounded (not truncated: 0.07 s * 1e9 is 69999999.99...)."""
    return np.round(np.asarray(seconds, dtype=float) * 1e9).astype(np.int64).astype("timedelta64[ns]")


def _index(record: RunRecord, rows: np.ndarray) -> list[rr.TimeColumn]:
    return [rr.TimeColumn("sim_time", duration=_ns(record.t[rows])), rr.TimeColumn("step", sequence=rows)]


def _strided(a: int, b: int, stride: int) -> np.ndarray:
    """The steps k in [a, b) with k % stride == 0."""
    return np.arange(-(-a // stride) * stride, b, stride)


def _bounds(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xy = xy[np.all(np.isfinite(xy), axis=1)] if len(xy) else xy
    if not len(xy):
        return np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    return xy.min(axis=0), xy.max(axis=0)


# ----------------------------------------------------------------------------------------------
# Viewing saved runs


def view(run_dirs: Sequence[Path | str]) -> subprocess.Popen:
    """Open one native rerun viewer with the run.rrd of each folder; returns the viewer process.

    The viewer runs on its own (it outlives this process). Raises ConfigError for a folder
    without run.rrd, or when there is no display.
    """
    files = []
    for d in run_dirs:
        d = Path(d)
        f = d if d.suffix == ".rrd" and d.is_file() else d / "run.rrd"
        if not f.is_file():
            raise ConfigError(str(d), "no run.rrd in this folder")
        files.append(str(f))
    if not files:
        raise ConfigError("view", "name at least one run folder")
    _check_display("view")
    return subprocess.Popen([rerun_executable(), *files], start_new_session=True)
