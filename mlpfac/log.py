"""Logging a run to rerun: the robot in 3D, a top view, the tracking error, the commands, every
network weight, the EKF's covariance, the plant events and the final status, with a default layout.

This module and :mod:`mlpfac.sinks` (which opens the sinks) are the only ones that import rerun;
import them lazily, so runs without logging do not pay rerun's import. The runner drives a sink::

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
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

# rerun's file sink logs its own write errors (and keeps going); mlpfac reads the file back instead
# (sinks.check_recording) and reports one line. An explicit RUST_LOG is left alone.
os.environ.setdefault("RUST_LOG", "warn,re_log_encoding::rrd=off,re_sdk::recording_stream=off")
import rerun as rr  # noqa: E402
import rerun.blueprint as rrb

from mlpfac.record import RunRecord

APPLICATION_ID = "mlpfac"
POSE_STRIDE = 5  # robot transform, reference arrow, top-view markers: every 5th step
PATH_STRIDE = 25  # the driven path is re-sent every 25th step ...
PATH_POINT_STRIDE = 5  # ... through every 5th pose
BATCH_ROWS = 1000  # flush() sends once this many rows are pending ...
BATCH_SECONDS = 1.0  # ... or this much wall time has passed since the last send

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
        self.server = None  # a viewer process started for this sink (--serve), stopped by close()

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
            if self.server is not None and self.server.poll() is None:
                self.server.terminate()
                self.server.wait()

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


def __getattr__(name: str):
    """Opening sinks and viewers lives in :mod:`mlpfac.sinks`; ``log.make_sink`` and friends still work."""
    if name in ("make_sink", "view", "rerun_executable", "check_recording"):
        from mlpfac import sinks

        return getattr(sinks, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
