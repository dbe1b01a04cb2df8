"""One run into a folder: config.toml, metrics.json, figure1.png and run.rrd, written beside the
folder and put in place only when whole (:class:`mlpfac.io.files.Stage`), under its lock. What
``mlpfac run`` does, and :func:`mlpfac.run` with ``out``.
"""

from __future__ import annotations

import json
import sys
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path

from mlpfac.exceptions import ConfigError, PluginError
from mlpfac.io.files import Stage, check_run_folder, check_save_file, folder_lock, write_atomic
from mlpfac.io.interrupts import raise_swallowed, sigint_deferred
from mlpfac.loop.metrics import metrics
from mlpfac.runs.replay import DEFER_MAX_S, DeferredSink


@dataclass
class Recording:
    """Where the run's rerun recording goes: ``run.rrd`` in the folder (the default), another file
    (``save``), a viewer (``spawn``, ``connect``, ``serve`` on ``bind``), or nowhere (``off``)."""

    save: Path | None = None
    spawn: bool = False
    connect: str | None = None
    serve: bool = False
    bind: str = "127.0.0.1"
    off: bool = False
    ports: tuple[int, int] = (9876, 9090)  # with serve: the web viewer's gRPC server and its page

    @property
    def to_file(self) -> bool:
        return not (self.off or self.spawn or self.connect or self.serve)


@dataclass
class FolderRun:
    """What a run into a folder gave: the record, its metrics (None when nothing was put in place),
    whether an earlier finished run was kept instead (``kept``: its paths), and the sink (a viewer
    being served stays up)."""

    rec: object
    metrics: dict | None
    kept: list[Path]
    sink: object = None


def check_outputs(out: Path, recording: Recording) -> Recording:
    """Before anything runs: ``out`` can hold a run, and ``recording.save`` is a file outside it.
    Returns the recording with ``save`` dropped where it is ``out/run.rrd`` (where it goes anyway)."""
    try:
        check_run_folder(out)
        _check_length(out, "--out")
    except OSError as err:  # the system refused the path itself
        raise ConfigError(f"--out {out}", f"cannot be a folder here ({err.strerror or err})") from None
    save = recording.save
    if save is not None and save.absolute() == (out / "run.rrd").absolute():
        save = None
    if save is not None:
        try:
            check_save_file(save)
            _check_length(save, "--save")
        except OSError as err:
            raise ConfigError(f"--save {save}", f"cannot be a file here ({err.strerror or err})") from None
        if out.absolute() in save.absolute().parents:
            raise ConfigError(f"--save {save}", f"is inside --out {out}, which a run replaces whole")
    return replace(recording, save=save)


STAGED_NAME = ".{}.tmp-XXXXXXXX"  # what a name becomes while it is written beside its place (mlpfac.io.files.Stage)


def _check_length(path: Path, flag: str) -> None:
    """A ConfigError naming ``flag`` when ``path``, or its name as staged beside it, is longer than
    the file system takes (found before the run, not when its folder is put in place)."""
    import os

    here = path.absolute().parent
    while not here.exists() and here != here.parent:
        here = here.parent
    try:
        name_max, path_max = os.pathconf(here, "PC_NAME_MAX"), os.pathconf(here, "PC_PATH_MAX")
    except (OSError, ValueError):
        return
    long = next((p for p in path.parts if len(os.fsencode(p)) > name_max), None)
    if long is None and len(os.fsencode(STAGED_NAME.format(path.name))) > name_max:
        long = path.name
    if long is not None:
        raise ConfigError(
            f"{flag} {path}", f"the name {long[:40]!r}... is longer than the {name_max} bytes allowed here"
        )
    if len(os.fsencode(str(path.absolute()))) + len(STAGED_NAME) + 16 > path_max:
        raise ConfigError(f"{flag} {path}", f"is longer than the {path_max} bytes a path may have here")


def run_into_folder(scn, out: Path, built, recording: Recording, baseline=None, painter=None, writer=None) -> FolderRun:
    """Under the locks of ``out`` (and ``recording.save``): run into the stages, then put them in
    place. ``baseline`` (a scenario) is run for panel (h) of figure1.png (None: no figure).

    An interrupted run is kept only where no finished run was (``kept`` names those that stay); a
    run whose controller raised leaves error.txt and config.toml, unless ``out`` holds a finished
    run, and the :class:`PluginError` propagates. A write that fails is a ConfigError naming the file."""
    save = recording.save
    with (
        folder_lock(out, "--out"),
        folder_lock(save, "--save") if save else nullcontext(),
        Stage(out, "--out") as folder,
        Stage(save, "--save", folder=False) if save else nullcontext() as saved,
    ):
        held = holds_finished_run(out), save is not None and holds_finished_run(save)
        rrd_path = saved.path if saved else folder.path / "run.rrd"
        rrd_shown = save if saved else out / "run.rrd"
        if recording.to_file and scn.duration <= DEFER_MAX_S:  # written after the run, while the figure is drawn
            names = Names(scn.name, scn.controller, scn.seed, scn.description)
            job = (recording, names, (rrd_path, rrd_shown))
            sink = DeferredSink(lambda: open_sink(recording, names, job[2]), writer, job)  # written by ``writer``
            if painter is not None:
                painter.meanwhile.append(sink.replay_quietly)
        else:
            sink = open_sink(recording, scn, (rrd_path, rrd_shown) if recording.to_file else None)
        try:
            rec, m = _run_into(folder, out, scn, built, sink, baseline, painter)
            if recording.to_file:
                if isinstance(sink, DeferredSink):
                    try:
                        sink.replay()
                    except OSError as err:  # rerun could not write or close the file (a full disk, say)
                        raise _unwritten(str(rrd_shown), err, out) from None
                if not (isinstance(sink, DeferredSink) and sink.checked):  # (the writer read it back)
                    from mlpfac.log.sinks import check_recording

                    check_recording(rrd_path, rrd_shown)
            raise_swallowed()  # a Ctrl-C that landed in a __del__ (rerun's) stops the run's folder too
        except BaseException as err:
            if sink is not None:
                sink.close()  # a web viewer started for --serve stops with the run
            if isinstance(err, PluginError):
                _keep_error(folder, out, scn, err, held[0])
            raise
        if rec.status == "interrupted" and any(held):  # the stage is removed on leaving the block
            if sink is not None:
                sink.close()
            return FolderRun(rec, None, [p for p, h in zip((out, save), held, strict=True) if h])
        if saved:
            saved.commit()
        folder.commit()
    return FolderRun(rec, m, [], sink)


def _keep_error(folder: Stage, out: Path, scn, err: PluginError, held: bool) -> None:
    """A run whose controller raised: its folder holds error.txt and config.toml (and what was
    recorded), unless ``out`` holds a finished run, which is kept."""
    from mlpfac.scenario.parse import to_toml

    if held:
        print(f"mlpfac: {out} kept the earlier run; this one failed", file=sys.stderr)
        return
    write_atomic(folder.path / "config.toml", to_toml(scn.table))
    write_atomic(folder.path / "error.txt", err.report())
    folder.commit()
    print(f"mlpfac: the run failed; its traceback is in {out / 'error.txt'}", file=sys.stderr)


@dataclass(frozen=True)
class Names:
    """What a recording is named by: the scenario's name, controller, seed and description."""

    name: str
    controller: str
    seed: int
    description: str


def open_sink(recording: Recording, scn, save: tuple[Path, Path] | None):
    """The sink ``recording`` asks for (``scn``: a scenario, or its :class:`Names`); ``save``: (the
    file written, the name it will have)."""
    if recording.off:
        return None
    from mlpfac.log import sinks

    try:
        sink = sinks.make_sink(
            save=save[0] if save else None,
            spawn=recording.spawn,
            connect=recording.connect,
            serve=recording.serve,
            recording_name=f"{scn.name} / {scn.controller} / seed {scn.seed}",
            recording_id=f"{scn.name}-{scn.controller}-{scn.seed}",
            bind=recording.bind,
            description=scn.description,
            ports=recording.ports,
        )
    except ConfigError as err:
        if save is None or str(save[0]) not in err.where:
            raise
        raise ConfigError(err.where.replace(str(save[0]), str(save[1])), err.what) from None
    if sink is not None and recording.serve:
        print(f"web viewer: {sink.viewer_url}", flush=True)
        if recording.bind in ("127.0.0.1", "localhost", "::1"):
            print(sinks.tunnel_line(recording.ports), flush=True)
    return sink


def _run_into(folder: Stage, out: Path, scn, built, sink, baseline, painter) -> tuple:
    """The run, then its folder (config.toml, metrics.json, figure1.png) in the stage. A write that
    fails is a ConfigError naming the file where it would have gone."""
    from mlpfac.io.interrupts import Terminated
    from mlpfac.loop.runner import run

    rec = run(scn, sink=sink, built=built)
    if isinstance(sink, DeferredSink):
        sink.hand_off()  # the recording written beside the figure's baseline run, where a writer's process waits
    writing = folder.path / "metrics.json"
    try:
        m = write_run(folder.path, scn, rec)
        if baseline is not None and rec.status != "interrupted":
            writing = folder.path / "figure1.png"
            if painter is not None:  # the figure made from the run's record while the baseline runs
                painter.begin(rec, writing, baseline.controller != scn.controller)
            base = run(baseline)
            if base.status == "interrupted":  # Ctrl-C while the figure's baseline ran
                raise Terminated() if base.reason.startswith("terminated") else KeyboardInterrupt()
            if painter is None:
                from mlpfac.plots import figure1

                figure1(rec, base, writing)
            else:
                painter.finish(base)
    except OSError as err:
        raise _unwritten(folder.shown(err.filename or writing), err, out) from None
    return rec, m


def _unwritten(name: str, err: OSError, out: Path) -> ConfigError:
    """A write that failed, as one line naming the file where it would have gone."""
    return ConfigError(name, f"cannot write ({err.strerror or err}); nothing was changed in {out}")


def write_run(out: Path, scn, rec) -> dict:
    """config.toml, then metrics.json (its presence means the folder is whole) of one run; run.rrd
    is written by its sink. Returns the metrics."""
    from mlpfac.scenario.parse import to_toml

    m = metrics(rec)
    with sigint_deferred():
        (out / "metrics.json").unlink(missing_ok=True)  # a run being replaced is not whole meanwhile
        write_atomic(out / "config.toml", to_toml(scn.table))
        write_atomic(out / "metrics.json", json.dumps(m, indent=2) + "\n")
    return m


def holds_finished_run(out: Path) -> bool:
    """A folder whose metrics.json says the run ended (ok or diverged), or a file that exists."""
    if not out.is_dir():
        return out.exists()
    try:
        return json.loads((out / "metrics.json").read_text()).get("status") != "interrupted"
    except (OSError, ValueError, AttributeError):
        return False
