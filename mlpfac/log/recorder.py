"""The sink a run is logged through: the runner's three calls, batching, events and the final status.

The runner drives a sink (made by :func:`mlpfac.log.make_sink`)::

    sink.begin(record, geometry=plant.geometry(), ref_path=record.ref)  # static scene
    ...every few hundred steps: sink.flush(record, upto=k + 1)  # rows not sent yet, column-wise
    sink.end(record)  # in a finally: last rows, events, status; completes the file
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence

import numpy as np
import rerun as rr

from mlpfac.io.interrupts import Terminated
from mlpfac.log.about import about_text
from mlpfac.log.belief import send_belief, send_belief_static
from mlpfac.log.layout import ABOUT, blueprint, marked_origins
from mlpfac.log.scene import PATH_STRIDE, POSE_STRIDE, send_poses, send_static_scene, strided
from mlpfac.log.schema import EVENT_COLOR
from mlpfac.log.series import Series, ns, plan_series, send_series, style_series, time_index
from mlpfac.log.terrain import send_terrain, send_tilts, style_force
from mlpfac.loop.record import RunRecord

APPLICATION_ID = "mlpfac"
BATCH_ROWS = 1000  # flush() sends once this many rows are pending ...
BATCH_SECONDS = 1.0  # ... or this much wall time has passed since the last send
CLOSE_TIMEOUT_S = 10.0  # rerun's disconnect never returns when its file cannot be written (a full disk)


def disconnect(rec: rr.RecordingStream) -> None:
    """Flush and close ``rec``'s outputs, waiting at most CLOSE_TIMEOUT_S: an OSError when they
    could not be closed by then (rerun's file sink hangs on a write that fails), or what rerun raised."""
    failed: list[BaseException] = []

    def close() -> None:
        try:
            rec.disconnect()
        except BaseException as err:  # noqa: BLE001 - reported below, in the caller's thread
            failed.append(err)

    closer = threading.Thread(target=close, name="mlpfac-rerun-close", daemon=True)
    closer.start()
    closer.join(CLOSE_TIMEOUT_S)
    if closer.is_alive():
        raise OSError(f"the recording could not be closed within {CLOSE_TIMEOUT_S:g} s (was the disk full?)")
    if failed:
        raise failed[0]


def _bounded_rerun_exit() -> None:
    """rerun flushes every recording when the interpreter exits (its atexit handler), which, like
    disconnect, may never return once a file could not be written: wait for it CLOSE_TIMEOUT_S at
    most, so that a sweep whose recording failed still exits (seen on a loaded machine)."""
    import atexit

    def shutdown() -> None:
        t = threading.Thread(target=rr.rerun_shutdown, name="mlpfac-rerun-shutdown", daemon=True)
        t.start()
        t.join(CLOSE_TIMEOUT_S)

    rr.unregister_shutdown()
    atexit.register(shutdown)


_bounded_rerun_exit()
STATUS_LEVEL = {"ok": "INFO", "interrupted": "WARN", "diverged": "ERROR"}


class RerunSink:
    """Sends one run to rerun. Made by :func:`mlpfac.log.make_sink`; see the module docstring for the call order."""

    def __init__(
        self, rec: rr.RecordingStream, recording_name: str, serving: bool, viewer_url: str | None, description: str = ""
    ) -> None:
        self.rec = rec
        self.description = description  # the scenario's, for the text panel
        self.events_marked = 0  # events whose markers are on the plots
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

    def begin(self, record: RunRecord, geometry: Sequence[dict] = (), ref_path: np.ndarray | None = None) -> None:
        """Send the static scene: name, run properties, floor, robot shapes, reference path."""
        if self.recording_name:
            self.rec.send_recording_name(self.recording_name)
        self.rec.send_property(
            "run",
            rr.AnyValues(
                scenario=record.scenario, controller=record.controller, seed=int(record.seed), T=float(record.T)
            ),
        )
        ref = record.ref if ref_path is None else np.asarray(ref_path, dtype=float)
        self.ref_path = ref[np.all(np.isfinite(ref[:, :2]), axis=1), :2]
        send_static_scene(self.rec, self.ref_path, geometry)
        send_belief_static(self.rec, record)  # a pose that was estimated (mlpfac.log.belief)
        send_terrain(self.rec, record.world)  # the ground driven on, the force's arrows (mlpfac.log.terrain)
        style_force(self.rec)
        self._send_about(record, ended=False)

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
            send_series(self.rec, self.series, record, a, b)
            send_poses(self.rec, record, strided(a, b, POSE_STRIDE), strided(a, b, PATH_STRIDE))
            send_belief(self.rec, record, a, b)
            self.sent = b
            self._mark_events(record)
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
                send_poses(
                    self.rec,
                    record,
                    last if (n - 1) % POSE_STRIDE else last[:0],
                    last if (n - 1) % PATH_STRIDE else last[:0],
                )
                send_belief(self.rec, record, n - 1, n, last=True)
            if not self.blueprint_sent:
                self._send_blueprint(record)
            self._send_status(record)
            self._send_about(record, ended=True)
        finally:
            if not self.serving:
                self.close()

    def close(self) -> None:
        """Flush and close every output: the file gets its footer, connections and servers stop."""
        if not self.closed:
            self.closed = True
            try:
                disconnect(self.rec)
            finally:
                if self.server is not None and self.server.poll() is None:
                    self.server.terminate()
                    self.server.wait()

    def wait(self) -> None:
        """When serving: keep the web viewer up until Ctrl-C, then close. Otherwise return at once."""
        if self.serving and not self.closed:
            try:
                while True:
                    time.sleep(1.0)
            except KeyboardInterrupt as err:  # Ctrl-C: the way to stop serving; SIGTERM ends the command as terminated
                if isinstance(err, Terminated):
                    raise
            finally:
                self.close()

    def _update_series(self, record: RunRecord) -> None:
        """(Re)plan the scalar series when the record has keys not seen yet; style new ones."""
        keys = (tuple(record.plant), tuple(record.ctrl))
        if keys != self.planned_keys:
            self.planned_keys = keys
            self.series = plan_series(record)
            style_series(self.rec, self.series, self.styled)

    def _send_events(self, record: RunRecord) -> None:
        new = record.events[self.events_sent :]
        if not new:
            return
        self.events_sent = len(record.events)
        send_tilts(self.rec, record, new)  # a slope tilts the floor's frame from its time on
        times = np.array([float(ev["time"]) for ev in new])
        steps = np.round(times / record.T).astype(np.int64)
        self.rec.send_columns(
            "events",
            indexes=[rr.TimeColumn("sim_time", duration=ns(times)), rr.TimeColumn("step", sequence=steps)],
            columns=rr.TextLog.columns(text=[event_text(ev) for ev in new], level=["WARN"] * len(new)),
        )

    def _send_about(self, record: RunRecord, ended: bool) -> None:
        self.rec.log(
            ABOUT, rr.TextDocument(about_text(record, self.description, ended), media_type="text/markdown"), static=True
        )

    def _mark_events(self, record: RunRecord) -> None:
        """A diamond on the first series of every time plot at each event sent rows have reached."""
        steps = [int(round(float(ev["time"]) / record.T)) for ev in record.events[self.events_marked :]]
        steps = [k for k in steps if k < self.sent]
        if not steps:
            return
        first = self.events_marked == 0
        self.events_marked += len(steps)
        rows = np.array(steps)
        for origin in marked_origins(["/" + s.path for s in self.series]):
            s = next(s for s in self.series if ("/" + s.path + "/").startswith(origin + "/"))
            values = np.array([np.ravel(s.get(record, slice(k, k + 1)))[0] for k in steps], dtype=float)
            path = origin.lstrip("/") + "/event"
            if first:
                self.rec.log(
                    path,
                    rr.SeriesPoints(colors=[EVENT_COLOR], markers=["Diamond"], marker_sizes=[6.0], names=["event"]),
                    static=True,
                )
            self.rec.send_columns(path, indexes=time_index(record, rows), columns=rr.Scalars.columns(scalars=values))

    def _send_status(self, record: RunRecord) -> None:
        k = max(record.n - 1, 0)
        from mlpfac.loop.metrics import metrics, outcome_words

        text = outcome_words(metrics(record))  # the outcome metrics.json records, in the words of the run's first line
        text += f" ({record.n} steps, {record.scenario} / {record.controller} / seed {record.seed})"
        self.rec.send_columns(
            "status",
            indexes=time_index(record, np.array([k])),
            columns=rr.TextLog.columns(text=[text], level=[STATUS_LEVEL.get(record.status, "INFO")]),
        )

    def _send_blueprint(self, record: RunRecord) -> None:
        self.blueprint_sent = True
        layout = blueprint(record, self.ref_path, self.series if self.planned_keys else None)
        self.rec.send_blueprint(layout, make_active=True, make_default=True)


def event_text(ev: dict) -> str:
    """An event's text, or its kind and parameters when it has none."""
    text = ev.get("text")
    if text:
        return str(text)
    args = ", ".join(f"{k}={v}" for k, v in sorted((ev.get("params") or {}).items()))
    return f"{ev.get('kind', 'event')}({args}) at {float(ev['time']):g} s"
