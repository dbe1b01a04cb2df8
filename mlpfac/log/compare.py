"""Saved runs in a viewer: one run's recording as it is; several in one recording, to compare them
with the default layout.

Each run's recording is read back and sent again under ``runs/<controller>-s<seed>/``; its plotted
lines, driven path and heading arrow take its controller's colour (a second run of one controller
a paler shade of it), the reference and the event diamonds keep theirs. Every view of the layout
then overlays that view's series of every run; the text panel lists the runs, their colours and
their figures (from each folder's metrics.json).
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import rerun as rr

from mlpfac.exceptions import ConfigError
from mlpfac.io.interrupts import Terminated
from mlpfac.log.layout import ABOUT, layout
from mlpfac.log.recorder import APPLICATION_ID, disconnect
from mlpfac.log.schema import REFSPEED_COLOR, RGB, entity_part
from mlpfac.log.sinks import (
    LOCALHOST,
    _check_display,
    _check_ports,
    _check_writable,
    _free_port,
    _start_viewer,
    _stop,
    _url_host,
    check_bind,
    check_recording,
    start_web_viewer,
)
from mlpfac.loop.metrics import RunMetrics
from mlpfac.loop.record import force_windows
from mlpfac.plots.colors import NAMES, controller_colors

COMPARE_REF_COLOR: RGB = (110, 110, 110)  # the reference, when the runs' colours include orange
SCALAR_ROOTS = ("errors", "controls", "wheels", "weight_change", "weights", "ekf", "h", "plant", "ctrl")


def run_files(runs: Sequence[Path | str]) -> list[tuple[Path, RunMetrics | None]]:
    """(run.rrd, metrics) of each run folder (or .rrd file beside its metrics.json); ConfigError
    naming the first that has no recording."""
    out = []
    for d in map(Path, runs):
        f = d if d.suffix == ".rrd" and d.is_file() else d / "run.rrd"
        if not f.is_file():
            raise ConfigError(str(d), "no run.rrd in this folder")
        try:
            m = RunMetrics.read(f.parent / "metrics.json")
        except (OSError, ValueError, KeyError, TypeError, AttributeError, RecursionError):
            m = None  # none, or of another shape: the run is shown without its figures
        out.append((f, m))
    if not out:
        raise ConfigError("view", "name at least one run folder")
    return out


def view(run_dirs: Sequence[Path | str], bind: str = LOCALHOST) -> subprocess.Popen:
    """Open one native rerun viewer with the run.rrd of each folder; returns the viewer process.
    Several runs are sent as one comparison (:mod:`mlpfac.log.compare`): the same layout, every
    run overlaid in its controller's colour.

    The viewer runs on its own (it outlives this process) once it listens. Raises ConfigError for
    a folder without run.rrd, when there is no display, and when the viewer exits at once or
    never listens.
    """
    check_bind(bind)
    files = run_files(run_dirs)
    _check_display("view")
    port = _free_port()
    if len(files) == 1:
        return _start_viewer("view", ["--bind", bind, "--port", str(port), str(files[0][0])], ports=(port,), host=bind)
    proc = _start_viewer("view", ["--bind", bind, "--port", str(port)], ports=(port,), host=bind)
    rec = rr.RecordingStream(APPLICATION_ID, recording_id="compare", send_properties=False)
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    rec.set_sinks(rr.GrpcSink(f"rerun+http://{_url_host(bind)}:{port}/proxy"))
    send_comparison(rec, files)
    try:
        disconnect(rec)
    except OSError as err:
        raise ConfigError("view", f"the viewer took no data ({err})") from None
    return proc


def serve(run_dirs: Sequence[Path | str], bind: str, ports: tuple[int, int], say=print) -> None:
    """Serve the runs in rerun's web viewer on ``bind`` (``ports``: gRPC, web page), for a machine
    without a display: one run's recording as it is, several as one comparison (as :func:`view`).
    Says the page's address and the SSH tunnel that shows it elsewhere; serves until Ctrl-C."""
    from mlpfac.log.sinks import tunnel_line

    check_bind(bind)
    _check_ports(bind, ports)
    files = run_files(run_dirs)
    server, grpc_url, page = start_web_viewer(bind, ports, [files[0][0]] if len(files) == 1 else [])
    try:
        if len(files) > 1:
            rec = rr.RecordingStream(APPLICATION_ID, recording_id="compare", send_properties=False)
            rec.set_log_time_enabled(False)
            rec.set_log_tick_enabled(False)
            rec.set_sinks(rr.GrpcSink(grpc_url))
            send_comparison(rec, files)
            rec.flush()
            rec.disconnect()
        say(f"web viewer: {page}")
        if bind in (LOCALHOST, "localhost", "::1"):
            say(tunnel_line(ports))
        say("serving until Ctrl-C")
        while server.poll() is None:
            time.sleep(0.5)
    except KeyboardInterrupt as err:  # Ctrl-C: the way to stop serving; SIGTERM ends the command as terminated
        if isinstance(err, Terminated):
            raise
        return
    finally:
        _stop(server)
    raise ConfigError("--serve", f"the rerun web viewer stopped by itself (code {server.returncode})")


def save_comparison(runs: Sequence[Path | str], path: Path | str) -> Path:
    """Write the runs' comparison recording to ``path`` (checked and read back like a run's): made
    beside it and renamed into place when whole, so a failure (a broken run.rrd, a full disk, a
    signal) leaves an earlier file at ``path`` as it was."""
    from mlpfac.io.files import Stage, check_save_file

    files = run_files(runs)
    path = Path(path)
    check_save_file(path, "--save")
    with Stage(path, "--save", folder=False) as stage:
        _check_writable(stage.path)
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=f"compare-{path.stem}", send_properties=False)
        rec.set_log_time_enabled(False)
        rec.set_log_tick_enabled(False)
        try:
            rec.set_sinks(rr.FileSink(stage.path))
        except RuntimeError as err:  # the file sink writes its header at once: a full disk fails here
            raise ConfigError(f"--save {path}", f"cannot write the recording ({str(err).splitlines()[0]})") from None
        try:
            send_comparison(rec, files)
        finally:
            try:
                disconnect(rec)
            except OSError as err:
                raise ConfigError(f"--save {path}", f"{err}; nothing was kept") from None
        check_recording(stage.path, path)
        stage.commit()
    return path


def _chunks(f: Path) -> list:
    """Every chunk of the recording ``f``; a ConfigError naming it when it is not a whole recording."""
    import warnings

    from rerun.chunk import RrdReader

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # "RRD file has no footer": cut short
            return list(RrdReader(f).store().stream().to_chunks())
    except Exception:  # rerun raises its own errors (and ValueError, OSError) on a file that is not whole
        raise ConfigError(str(f), "is not a whole rerun recording (truncated, or not an .rrd file)") from None


def send_comparison(rec: rr.RecordingStream, files: list[tuple[Path, RunMetrics | None]]) -> None:
    """Every run's chunks under its own prefix, recoloured; the text panel; the layout."""
    labels = _labels([m for _, m in files], [f for f, _ in files])
    colors = _colors([m.controller if m else label for (_, m), label in zip(files, labels, strict=True)])
    rec.send_recording_name(" vs ".join(labels))
    paths: set[str] = set()
    refs = []
    for i, ((f, _), label, (color, _)) in enumerate(zip(files, labels, colors, strict=True)):
        prefix = f"runs/{label}/"
        chunks = []
        for chunk in _chunks(f):
            p = str(chunk.entity_path).lstrip("/")
            if p.startswith("__") or p == ABOUT:
                continue
            chunks.append(chunk.with_entity_path("/" + prefix + p))
            if p == "top/plane/reference_path":
                refs.append(_strip_points(chunk))
            if not chunk.is_static and p.split("/")[0] in SCALAR_ROOTS:
                paths.add(p)
        rec.send_chunks(chunks)
        _recolor(rec, prefix, paths, color, 0.03 * 0.6**i)
    rec.log(ABOUT, rr.TextDocument(_about(files, labels, colors), media_type="text/markdown"), static=True)
    bp = layout(
        np.concatenate(refs) if refs else None,
        sorted("/" + p for p in paths),
        [f"runs/{label}/" for label in labels],
        one=False,
    )
    rec.send_blueprint(bp, make_active=True, make_default=True)


def _strip_points(chunk) -> np.ndarray:
    """The (x, y) points of a LineStrips2D chunk."""
    v = chunk.to_record_batch().column("LineStrips2D:strips")
    while not str(v.type).startswith("fixed_size_list"):
        v = v.flatten()
    return np.asarray(v.flatten(), dtype=float).reshape(-1, 2)


def _labels(ms: list[RunMetrics | None], files: list[Path]) -> list[str]:
    labels = []
    for m, f in zip(ms, files, strict=True):
        base = f"{m.controller}-s{m.seed}" if m else f.parent.name or f.stem
        label, i = entity_part(base), 2
        while label in labels:
            label, i = f"{entity_part(base)}-{i}", i + 1
        labels.append(label)
    return labels


def _colors(controllers: list[str]) -> list[tuple[RGB, str]]:
    """The controller's colour and its name; each further run of one controller a paler shade."""
    base = controller_colors(controllers)
    seen: dict[str, int] = {}
    out = []
    for c in controllers:
        k = seen[c] = seen.get(c, -1) + 1
        f = 1.0 - 0.6**k  # 0, 0.4, 0.64, ...: towards white
        name = ("paler " * k) + NAMES.get(base[c], "rgb" + str(base[c]))
        out.append((tuple(int(round(v + (255 - v) * f)) for v in base[c]), name.replace("paler ", "pale ", 1)))
    return out


def _recolor(rec: rr.RecordingStream, prefix: str, paths: set[str], color: RGB, radius: float) -> None:
    """The run's lines in its colour; its driven path ``radius`` wide (each run's narrower than the
    one before, so that paths lying on each other all show)."""
    for p in sorted(paths):
        if p.endswith("/event"):
            continue
        leaf = p.rsplit("/", 1)[-1]
        c = REFSPEED_COLOR if leaf == "ref" else _pale(color) if leaf == "meas" else color
        rec.log(prefix + p, rr.SeriesLines.from_fields(colors=[c]), static=True)
    rec.log(prefix + "world/path", rr.LineStrips3D.from_fields(colors=[color], radii=[radius]), static=True)
    rec.log(prefix + "top/plane/path", rr.LineStrips2D.from_fields(colors=[color], radii=[radius]), static=True)
    rec.log(prefix + "top/plane/robot", rr.Arrows2D.from_fields(colors=[color]), static=True)
    # The reference in grey, thin: the runs' colours are drawn over it.
    rec.log(
        prefix + "world/reference_path",
        rr.LineStrips3D.from_fields(colors=[COMPARE_REF_COLOR], radii=[0.008]),
        static=True,
    )
    rec.log(
        prefix + "top/plane/reference_path",
        rr.LineStrips2D.from_fields(colors=[COMPARE_REF_COLOR], radii=[0.01]),
        static=True,
    )
    rec.log(prefix + "world/reference_now", rr.Arrows3D.from_fields(colors=[COMPARE_REF_COLOR]), static=True)
    rec.log(prefix + "top/plane/reference_now", rr.Points2D.from_fields(colors=[COMPARE_REF_COLOR]), static=True)


def _pale(c: RGB) -> RGB:
    return tuple(int(round(v + (255 - v) * 0.5)) for v in c)


def _about(files: list[tuple[Path, RunMetrics | None]], labels: list[str], colors: list[tuple[RGB, str]]) -> str:
    lines = ["**runs compared**: one colour per controller (pale: measured); grey: the reference", ""]
    for (f, m), label, (_, name) in zip(files, labels, colors, strict=True):
        phases = m.phases if m else {}
        after = phases.get("after") or phases.get("before")
        rms = after.rms_position_error_m if after else None  # None: ended within its warm-up
        where = " after the event" if "after" in phases else ""
        fig = (
            f", position RMS{where} {rms * 1e3:.1f} mm"
            if isinstance(rms, int | float) and not isinstance(rms, bool)
            else ""
        )
        lines.append(f"- **{label}** ({name}): {m.scenario if m else f.parent}, {m.outcome if m else '?'}{fig}")
    events = {(ev.get("time"), ev.get("text")) for _, m in files if m for ev in m.events if isinstance(ev, dict)}
    for t, text in sorted(events, key=str):
        lines.append(f"\n**event at {t:g} s**: {text} (dark-red diamonds on every plot)")
    ends = [float(m.steps) * float(m.T) for _, m in files if m]
    spans = {w for _, m in files if m for w in force_windows(m.events, max(ends, default=0.0))}
    for t0, t1 in sorted(spans):
        lines.append(f"\n**a force acts from {t0:g} to {t1:g} s** (the arrow on each robot; forces/* for its size)")
    return "\n".join(lines) + "\n"
