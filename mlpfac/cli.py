"""The command line: mlpfac run / list / compare / sweep / view / plot.

Arguments are parsed before any heavy import; bad input prints one line and exits with code 2.
Exit codes of ``run``: 0 ok, 1 the run diverged, 2 bad input or a write that failed (nothing
changed), 130 interrupted (Ctrl-C), 143 terminated (SIGTERM).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # Ctrl-C (SIGINT)
EXIT_TERMINATED = 143  # SIGTERM: handled like Ctrl-C
EXIT_BROKEN_PIPE = 141  # stdout closed by its reader (128 + SIGPIPE), as shell tools exit


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (and exit code 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(EXIT_BAD_INPUT)


def _sink_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("rerun logging (default: save run.rrd in --out)")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--save", metavar="FILE.rrd", type=Path, help="save the recording to this file")
    x.add_argument("--spawn", action="store_true", help="open a rerun viewer and stream to it")
    x.add_argument(
        "--connect", metavar="URL", help="stream to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy"
    )
    x.add_argument("--serve", action="store_true", help="serve a web viewer on 127.0.0.1 (see --bind)")
    x.add_argument("--no-log", action="store_true", help="no recording")
    g.add_argument("--bind", metavar="ADDRESS", default="127.0.0.1", help=BIND_HELP)


BIND_HELP = "address the viewers started here listen on (default 127.0.0.1; 0.0.0.0 is every interface)"


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="mlpfac", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    p = sub.add_parser(
        "run",
        help="run one scenario",
        description="Run one scenario and write metrics.json, config.toml, figure1.png and run.rrd.",
    )
    p.add_argument("scenario", help="a shipped scenario name (see `mlpfac list`) or a path to a .toml file")
    p.add_argument("--controller", help="override the scenario's controller (adaptive, corradini, kanayama, ...)")
    p.add_argument("--seed", type=int, help="override the scenario's seed")
    p.add_argument("--duration", type=float, help="override the duration in seconds")
    p.add_argument("--out", type=Path, help="output folder (default runs/SCENARIO-CONTROLLER-sSEED)")
    p.add_argument("--baseline", default="corradini", help="controller for panel (h) of the figure, or 'none'")
    p.add_argument("--no-plot", action="store_true", help="skip figure1.png")
    _sink_args(p)

    sub.add_parser("list", help="list the shipped scenarios and controllers")

    from mlpfac import sweep

    sweep.add_compare_arguments(sub.add_parser("compare", help="controllers x scenarios x seeds -> a per-phase table"))
    sweep.add_sweep_arguments(sub.add_parser("sweep", help="Monte Carlo sweep -> mean, median, 95 %% CI per phase"))

    p = sub.add_parser(
        "view",
        help="open saved runs in one rerun viewer",
        description="Open one run, or several side by side and overlaid (one colour per controller), in rerun.",
    )
    p.add_argument("runs", nargs="+", type=Path, help="run folders (each with a run.rrd) or .rrd files")
    p.add_argument("--bind", metavar="ADDRESS", default="127.0.0.1", help=BIND_HELP)
    p.add_argument(
        "--save", metavar="FILE.rrd", type=Path, help="write the comparison of several runs to this file, open nothing"
    )

    p = sub.add_parser(
        "plot",
        help="draw a sweep's or comparison's plots again",
        description="Draw sweep.png / compare.png beside the tables of finished sweep folders.",
    )
    p.add_argument("folders", nargs="+", type=Path, help="results folders of `mlpfac sweep` or `mlpfac compare`")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from mlpfac.exceptions import MlpfacError
    from mlpfac.outputs import Terminated, handle_sigterm

    handle_sigterm()

    try:
        if args.command == "run":
            from mlpfac.plots.painter import painting
            from mlpfac.scenario import load

            load(args.scenario, build=False)  # a bad name or file fails here, before the figure's process starts
            with painting(args.baseline != "none" and not args.no_plot) as args.painter:  # figure1 drawn beside
                return cmd_run(args)
        if args.command == "list":
            return cmd_list()
        if args.command == "view":
            return cmd_view(args)
        if args.command == "plot":
            return cmd_plot(args)
        from mlpfac import sweep

        return sweep.run_compare_cli(args) if args.command == "compare" else sweep.run_sweep_cli(args)
    except MlpfacError as err:
        print(f"mlpfac: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt as err:
        print("mlpfac: terminated" if isinstance(err, Terminated) else "mlpfac: interrupted", file=sys.stderr)
        return EXIT_TERMINATED if isinstance(err, Terminated) else EXIT_INTERRUPTED
    except BrokenPipeError:  # stdout closed early (`mlpfac ... | head`): what was written stays, no traceback
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE


def cmd_list() -> int:
    from mlpfac.controllers import CONTROLLERS
    from mlpfac.scenario import load, scenario_names

    names = scenario_names()
    width = max(map(len, names), default=0)
    for name in names:
        scn = load(name, build=False)
        print(f"{name:<{width}}  {scn.plant_kind:<9}  {scn.description}")
    print(f"\ncontrollers: {', '.join(CONTROLLERS)}")
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    from mlpfac.log import sinks

    if args.save is not None:
        print(f"{len(args.runs)} runs -> {sinks.save_comparison(args.runs, args.save)}")
    else:
        sinks.view(args.runs, bind=args.bind)
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from mlpfac.exceptions import ConfigError
    from mlpfac.plots import sweep_plots

    for folder in args.folders:
        if not folder.is_dir():
            raise ConfigError(str(folder), "is not a folder")
    for folder in args.folders:
        try:
            written = sweep_plots(folder)
        except OSError as err:
            raise ConfigError(str(err.filename or folder), f"cannot write ({err.strerror or err})") from None
        if not written:
            raise ConfigError(str(folder), "holds no finished runs (<scenario>/<controller>/seed-*/metrics.json)")
        print(" ".join(map(str, written)))
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    """Check everything, build the plant and the controller, then run into a folder beside --out
    that replaces it only when whole (see :class:`mlpfac.outputs.Stage`), under --out's lock."""
    from mlpfac.exceptions import ConfigError
    from mlpfac.outputs import check_run_folder, check_save_file
    from mlpfac.scenario import load

    scn = load(args.scenario).with_overrides(args.controller, args.seed, args.duration)
    if scn.dropped_events:
        times = ", ".join(f"{t:g} s" for t in scn.dropped_events)
        print(f"note: --duration {scn.duration:g} s ends before the event at {times}: this run has no such event")
    baseline = None
    if args.baseline != "none" and not args.no_plot:
        try:
            baseline = scn.with_overrides(controller=args.baseline)
        except ConfigError as err:  # the flag that named it
            raise ConfigError("--baseline", err.what) from None
    out = args.out or Path("runs") / f"{scn.name}-{scn.controller}-s{scn.seed}"
    check_run_folder(out)
    if args.save is not None and args.save.absolute() == (out / "run.rrd").absolute():
        args.save = None  # where the recording goes anyway
    if args.save is not None:
        check_save_file(args.save)
        if out.absolute() in args.save.absolute().parents:
            raise ConfigError(f"--save {args.save}", f"is inside --out {out}, which a run replaces whole")
    from mlpfac.runner import build  # numba and the run's imports: after the checks of the input

    return _run_staged(args, scn, out, build(scn), baseline)


def _run_staged(args: argparse.Namespace, scn, out: Path, built, baseline) -> int:
    """Under the locks of --out (and --save): run into the stages, then put them in place."""
    from contextlib import nullcontext

    from mlpfac.outputs import Stage, folder_lock, holds_finished_run

    with (
        folder_lock(out, "--out"),
        folder_lock(args.save, "--save") if args.save else nullcontext(),
        Stage(out, "--out") as folder,
        Stage(args.save, "--save", folder=False) if args.save else nullcontext() as saved,
    ):
        held = holds_finished_run(out), args.save is not None and holds_finished_run(args.save)
        saving = not (args.no_log or args.spawn or args.connect or args.serve)
        rrd_path = saved.path if saved else folder.path / "run.rrd"
        rrd_shown = args.save if saved else out / "run.rrd"
        from mlpfac.replay import DEFER_MAX_S, DeferredSink

        if saving and scn.duration <= DEFER_MAX_S:  # written after the run, while the figure is drawn
            sink = DeferredSink(lambda: _open_sink(args, scn, (rrd_path, rrd_shown)))
            if args.painter is not None:
                args.painter.meanwhile.append(sink.replay_quietly)
        else:
            sink = _open_sink(args, scn, (rrd_path, rrd_shown) if saving else None)
        try:
            rec, m = _run_into(folder, out, scn, built, sink, baseline, args.painter)
            if saving:
                if isinstance(sink, DeferredSink):
                    sink.replay()
                from mlpfac.log.sinks import check_recording

                check_recording(rrd_path, rrd_shown)
        except BaseException:
            if sink is not None:
                sink.close()  # a web viewer started for --serve stops with the run
            raise
        if rec.status == "interrupted" and any(held):  # the stage is removed on leaving the block
            if sink is not None:
                sink.close()
            kept = " and ".join(str(p) for p, h in zip((out, args.save), held, strict=True) if h)
            print(f"mlpfac: {rec.reason}; {kept} kept the earlier run, this one was discarded", file=sys.stderr)
            return _interrupt_code(rec)
        if saved:
            saved.commit()
        folder.commit()
    _print_summary(m, out)
    if sink is not None and sink.serving:
        print("serving the recording; Ctrl-C stops the web viewer", flush=True)
        sink.wait()
    return {"ok": 0, "diverged": 1}.get(rec.status) if rec.status != "interrupted" else _interrupt_code(rec)


def _interrupt_code(rec) -> int:
    return EXIT_TERMINATED if rec.reason.startswith("terminated") else EXIT_INTERRUPTED


def _open_sink(args: argparse.Namespace, scn, save: tuple[Path, Path] | None):
    """The sink the flags ask for; ``save``: (the file written, the name it will have)."""
    if args.no_log:
        return None
    from mlpfac.exceptions import ConfigError

    try:
        return _make_sink(args, scn, save[0] if save else None)
    except ConfigError as err:
        if save is None or str(save[0]) not in err.where:
            raise
        raise ConfigError(err.where.replace(str(save[0]), str(save[1])), err.what) from None


def _make_sink(args: argparse.Namespace, scn, save: Path | None):
    from mlpfac.log import sinks

    sink = sinks.make_sink(
        save=save,
        spawn=args.spawn,
        connect=args.connect,
        serve=args.serve,
        recording_name=f"{scn.name} / {scn.controller} / seed {scn.seed}",
        recording_id=f"{scn.name}-{scn.controller}-{scn.seed}",
        bind=args.bind,
        description=scn.description,
    )
    if sink is not None and args.serve:
        print(f"web viewer: {sink.viewer_url}", flush=True)
    return sink


def _run_into(folder, out: Path, scn, built, sink, baseline, painter) -> tuple:
    """The run, then its folder (config.toml, metrics.json, figure1.png) in the stage. A write that
    fails is a ConfigError naming the file where it would have gone."""
    from mlpfac.exceptions import ConfigError
    from mlpfac.outputs import Terminated, write_run
    from mlpfac.runner import run

    rec = run(scn, sink=sink, built=built)
    writing = folder.path / "metrics.json"
    try:
        m = write_run(folder.path, scn, rec)
        if baseline is not None and rec.status != "interrupted":
            base = run(baseline)
            if base.status == "interrupted":  # Ctrl-C while the figure's baseline ran
                raise Terminated() if base.reason.startswith("terminated") else KeyboardInterrupt()
            writing = folder.path / "figure1.png"
            painter.figure1(rec, base, writing)
    except OSError as err:
        name = folder.shown(err.filename or writing)
        raise ConfigError(name, f"cannot write ({err.strerror or err}); nothing was changed in {out}") from None
    return rec, m


def _fmt(x: float | None, scale: float = 1.0, unit: str = "") -> str:
    return "-" if x is None else f"{x * scale:.2f}{unit}"


def _print_summary(m: dict, out: Path) -> None:
    print(
        f"{m['scenario']} / {m['controller']} / seed {m['seed']}: {m['status']}"
        + (f" ({m['reason']})" if m["reason"] else "")
        + (
            f", {m['outcome']} (lost: a phase's position RMS beyond {m['lost_threshold_m']:.3g} m)"
            if m["status"] == "ok"
            else ""
        )
    )
    for ev in m["events"]:
        print(f"  event at {ev['time']:g} s: {ev['text']}")
    print(
        f"  position RMS {_fmt(m['rms_position_error_m'], 1e3, ' mm')}, max {_fmt(m['max_position_error_m'], 1e3, ' mm')}, heading RMS {_fmt(m['rms_heading_error_rad'], 1e3, ' mrad')}"
    )
    for name, ph in m["phases"].items():
        print(
            f"  {name:>6} [{ph['start_s']:g}, {ph['end_s']:g}) s: position RMS {_fmt(ph['rms_position_error_m'], 1e3, ' mm')}, heading RMS {_fmt(ph['rms_heading_error_rad'], 1e3, ' mrad')}"
        )
    if m["max_abs_weight"] is not None:
        print(f"  max |weight| {m['max_abs_weight']:.3g}, final mean diag P {m['mean_diag_P_final']:.3g}")
    print(f"  {m['sim_time_s']:.1f} s simulated in {m['wall_time_s']:.2f} s wall -> {out}")


if __name__ == "__main__":
    sys.exit(main())
