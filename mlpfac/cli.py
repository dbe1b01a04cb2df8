"""The command line: mlpfac run / list / compare / sweep / check / view / plot / report.

Arguments are parsed before any heavy import; bad input prints one line and exits with code 2.
Exit codes of ``run``: 0 ok, 1 the run diverged, 2 bad input or a write that failed (nothing
changed), 130 interrupted (Ctrl-C), 143 terminated (SIGTERM).
"""

from __future__ import annotations

import argparse
import atexit
import os
import sys
import threading
from pathlib import Path

from mlpfac.flags import Parser, needs, not_with
from mlpfac.io import exits
from mlpfac.io.exits import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_TERMINATED  # noqa: F401 (cli.EXIT_*)
from mlpfac.io.targets import cli_path


def _sink_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("rerun logging (default: save run.rrd in --out)")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--save", metavar="FILE.rrd", type=cli_path, help="save the recording to this file")
    x.add_argument("--spawn", action="store_true", help="open a rerun viewer and stream to it")
    x.add_argument(
        "--connect", metavar="URL", help="stream to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy"
    )
    x.add_argument("--serve", action="store_true", help="serve a web viewer on 127.0.0.1 (see --bind)")
    x.add_argument("--no-log", action="store_true", help="no recording")
    g.add_argument("--bind", metavar="ADDRESS", default="127.0.0.1", help=BIND_HELP)
    needs(p, "--bind", "--serve", "--spawn")  # the viewers started here
    _port_args(p, g)


def _port_args(p: argparse.ArgumentParser, g) -> None:
    """``--port`` and ``--grpc-port`` (in ``g``, a group of ``p``): with ``--serve`` only."""
    g.add_argument("--port", type=int, default=9090, help="with --serve: the web viewer's page (default 9090)")
    g.add_argument("--grpc-port", type=int, default=9876, help="with --serve: its gRPC server (default 9876)")
    for flag in ("--port", "--grpc-port"):
        needs(p, flag, "--serve")


BIND_HELP = "address the viewers started here listen on (default 127.0.0.1; 0.0.0.0 is every interface)"


def build_parser() -> argparse.ArgumentParser:
    from mlpfac import __version__

    parser = Parser(prog="mlpfac", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"mlpfac {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    from mlpfac.sweeps import cli as sweep

    p = sub.add_parser(
        "run",
        help="run one scenario",
        description="Run one scenario and write metrics.json, config.toml, figure1.png and run.rrd.",
    )
    p.add_argument("scenario", help="a shipped scenario name (see `mlpfac list`) or a path to a .toml file")
    p.add_argument(
        "--controller",
        help="override the scenario's controller: a shipped one (adaptive, corradini, kanayama, oracle, ...), "
        "path/to/file.py:Class, package.module:Class, or an installed one (see `mlpfac list`)",
    )
    p.add_argument("--seed", type=int, help="override the scenario's seed")
    p.add_argument("--duration", type=float, help="override the duration in seconds")
    from mlpfac.scenario.on_robot import ROBOT_HELP

    p.add_argument("--robot", help=ROBOT_HELP)
    p.add_argument("--lost-threshold", type=float, metavar="METRES", help=sweep.LOST_HELP)
    p.add_argument("--out", type=cli_path, help="output folder (default runs/SCENARIO-CONTROLLER-sSEED)")
    plot = p.add_mutually_exclusive_group()  # a baseline is drawn in the figure: nothing without one
    plot.add_argument("--baseline", default="corradini", help="controller for panel (h) of the figure, or 'none'")
    plot.add_argument("--no-plot", action="store_true", help="skip figure1.png")
    _sink_args(p)

    sub.add_parser("list", help="list the shipped scenarios, and the controllers shipped and installed")

    sweep.add_compare_arguments(sub.add_parser("compare", help="controllers x scenarios x seeds -> a per-phase table"))
    sweep.add_sweep_arguments(sub.add_parser("sweep", help="Monte Carlo sweep -> mean, median, 95 %% CI per phase"))

    p = sub.add_parser(
        "check",
        help="run a budget's sweep and judge it: exit 0 every budget holds, 1 a miss, 2 a bad budget",
        description="Run the sweep a budget file names, then judge it against the budget's limits "
        "(exit 0 every budget holds, 1 at least one does not, 2 a bad budget: nothing run). See docs/ci.md.",
    )
    p.add_argument("budget", type=cli_path, help="the budget file (TOML)")
    p.add_argument("--junit", type=cli_path, metavar="FILE.xml", help="write JUnit XML for a CI page")
    p.add_argument("--summary", type=cli_path, metavar="FILE.md", help="write a Markdown summary (a CI job summary)")
    p.add_argument(
        "--baseline",
        metavar="DIR_OR_SWEEP_JSON",
        help="a previous sweep (folder or its sweep.json) to compare per seed",
    )
    p.add_argument(
        "--out", type=cli_path, default=Path("runs/check"), help="results folder (default runs/check); resumable"
    )
    p.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    from mlpfac.scenario.on_robot import ROBOT_HELP

    p.add_argument("--robot", help=ROBOT_HELP)
    p.add_argument(
        "--vary",
        action="append",
        metavar="KEY=VALUES",
        help="an axis or a draw more than the budget's vary (as sweep's)",
    )
    p.add_argument("--lost-threshold", type=float, metavar="METRES", help=sweep.LOST_HELP)

    p = sub.add_parser(
        "view",
        help="open saved runs in one rerun viewer",
        description="Open one run, or several side by side and overlaid (one colour per controller), in rerun.",
    )
    p.add_argument("runs", nargs="+", type=cli_path, help="run folders (each with a run.rrd) or .rrd files")
    x = p.add_mutually_exclusive_group()
    x.add_argument(
        "--save",
        metavar="FILE.rrd",
        type=cli_path,
        help="write the comparison of several runs to this file, open nothing",
    )
    x.add_argument(
        "--serve",
        action="store_true",
        help="no display needed: serve a web viewer (on 127.0.0.1, see --bind) until Ctrl-C, and say its address",
    )
    p.add_argument("--bind", metavar="ADDRESS", default="127.0.0.1", help=BIND_HELP)
    not_with(p, "--bind", "--save")  # --save starts no viewer
    _port_args(p, p)

    p = sub.add_parser(
        "plot",
        help="draw a sweep's or comparison's plots again",
        description="Draw sweep.png / compare.png beside the tables of finished sweep folders.",
    )
    p.add_argument("folders", nargs="+", type=cli_path, help="results folders of `mlpfac sweep` or `mlpfac compare`")
    p.add_argument(
        "--panels",
        type=cli_path,
        metavar="PNG",
        help="instead: one figure of small panels, one per one-axis sweep of the folders (or data folders) holding "
        "robustness.json: each controller's median against the value, the bound, the tracking limit",
    )

    from mlpfac.report import add_arguments

    add_arguments(sub.add_parser("report", help="write the results tables of the docs from their data"))
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from mlpfac.exceptions import MlpfacError, PluginError
    from mlpfac.io.interrupts import handle_sigterm

    handle_sigterm()

    try:
        if args.command == "run":
            import numpy  # noqa: F401 (imported once for the three processes: before the children are forked)

            from mlpfac.plots.painter import painting
            from mlpfac.runs.replay import DEFER_MAX_S
            from mlpfac.runs.writer import writing

            to_file = not (args.no_log or args.spawn or args.connect or args.serve)
            with (  # started first, so that they import matplotlib and rerun while the input is checked
                painting(args.baseline != "none" and not args.no_plot) as args.painter,  # figure1 drawn beside
                writing(to_file, args.painter.fds() if args.painter else ()) as args.writer,  # run.rrd too
            ):
                from mlpfac.scenario.parse import load

                scn = load(args.scenario, build=False, ends=False)  # a bad name or file fails here (the children
                # are ended); its distributions' ends are checked with the robot built, by cmd_run
                if args.robot is not None:
                    from mlpfac.scenario.on_robot import model_of

                    model_of(args.robot)
                if (
                    args.writer is not None
                    and (args.duration if args.duration is not None else scn.duration) > DEFER_MAX_S
                ):
                    args.writer.close()  # a long run streams its recording from this process
                _without_gl(args.controller or scn.controller, args.baseline)
                return cmd_run(args)
        if args.command == "list":
            return cmd_list()
        if args.command == "view":
            return cmd_view(args)
        if args.command == "plot":
            return cmd_plot(args)
        if args.command == "report":
            return cmd_report(args)
        if args.command == "check":
            return cmd_check(args)
        from mlpfac.sweeps import cli as sweep

        return sweep.run_compare_cli(args) if args.command == "compare" else sweep.run_sweep_cli(args)
    except PluginError as err:  # the user's controller raised: its traceback, not ours
        print(err.report(), end="", file=sys.stderr)
        return EXIT_FAILED
    except MlpfacError as err:
        print(f"mlpfac: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (KeyboardInterrupt, ImportError) as err:  # ImportError: a signal as MuJoCo's module initialised
        code = exits.interrupted(err)
        if code is None:
            raise
        return code
    except OSError as err:  # a write no check could foresee (stdout on a full disk, a name too long): one line
        return exits.failed_write(err)


def _without_gl(*controllers: str) -> None:
    """MuJoCo's import sets up an OpenGL context unless MUJOCO_GL says otherwise (glfw's import and
    a subprocess of its own, about 0.1 s): none is set up when MUJOCO_GL is not set and only the
    shipped controllers run, which never render. A user's controller gets MuJoCo as it comes."""
    from mlpfac.control.variants import CONTROLLERS

    if "MUJOCO_GL" not in os.environ and all(c in CONTROLLERS or c == "none" for c in controllers):
        os.environ["MUJOCO_GL"] = "disable"


def cmd_list() -> int:
    from mlpfac.control.baselines import CONTROLLERS
    from mlpfac.control.plugins import entry_points
    from mlpfac.scenario.parse import read_toml, scenario_names, shipped_dir

    names = scenario_names()
    width = max(map(len, names), default=0)
    for name in names:  # the files' own words: a listing times no path (which imports scipy's splines)
        table = read_toml(shipped_dir() / f"{name}.toml", "scenario file")
        plant = table.get("plant") if isinstance(table.get("plant"), dict) else {}
        print(f"{name:<{width}}  {plant.get('kind', 'kinematic'):<9}  {table.get('description', '')}")
    from mlpfac.scenario.on_robot import robots_here

    print("\nrobots (--robot NAME, or an MJCF file):")
    robots = robots_here()
    wide = max(len(n) for n, _ in robots)
    for name, where in robots:
        print(f"  {name:<{wide}}  {where}")
    print(f"\ncontrollers: {', '.join(CONTROLLERS)}")
    installed = entry_points()
    if installed:
        print("installed controllers (entry-point group mlpfac.control.baselines):")
        width = max(map(len, installed))
        for name, (target, dist) in sorted(installed.items()):
            print(f"  {name:<{width}}  {target}  (from {dist})")
    print("your own: --controller path/to/file.py:Class or package.module:Class")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from mlpfac.report import run_cli

    return run_cli(args)


def cmd_check(args: argparse.Namespace) -> int:
    from mlpfac.checks import check

    result = check(
        args.budget, args.junit, args.summary, args.baseline, args.out, args.workers, args.robot, args.vary,
        args.lost_threshold,
    )  # fmt: skip
    for line in result.lines():
        print(line)
    if result.cases:
        held = sum(c.passed for c in result.cases)
        print(f"check: {held} of {len(result.cases)} budget cases hold -> {', '.join(map(str, result.files))}")
    return result.code


def cmd_view(args: argparse.Namespace) -> int:
    from mlpfac.log import compare

    if args.save is not None:
        print(f"{len(args.runs)} runs -> {compare.save_comparison(args.runs, args.save)}")
    elif args.serve:
        compare.serve(args.runs, args.bind, (args.grpc_port, args.port), say=lambda line: print(line, flush=True))
    else:
        compare.view(args.runs, bind=args.bind)
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from mlpfac.exceptions import ConfigError
    from mlpfac.plots import sweep_plots

    for folder in args.folders:
        if not folder.is_dir():
            raise ConfigError(str(folder), "is not a folder")
    if args.panels is not None:
        return _plot_panels(args.folders, args.panels)
    for folder in args.folders:
        try:
            if (folder / "robustness.json").is_file():  # a sweep with --vary: its curves, in place of sweep.png
                from mlpfac.plots.robustness import robustness_plot

                written = robustness_plot(folder)
            else:
                written = sweep_plots(folder)
        except OSError as err:
            raise ConfigError(str(err.filename or folder), f"cannot write ({err.strerror or err})") from None
        except ConfigError:  # a robustness.json edited by hand: its field named
            raise
        except (TypeError, ValueError, KeyError, AttributeError, IndexError) as err:  # a metrics.json edited by hand
            raise ConfigError(
                str(folder), f"a metrics.json under it is not what a run writes ({type(err).__name__}: {err})"
            ) from None
        if not written:
            raise ConfigError(str(folder), "holds no finished runs (<scenario>/<controller>/seed-*/metrics.json)")
        print(" ".join(map(str, written)))
    return 0


def _plot_panels(folders: list[Path], png: Path) -> int:
    """``mlpfac plot --panels PNG FOLDER...``: every folder's robustness.json in one figure."""
    from mlpfac.exceptions import ConfigError
    from mlpfac.io.targets import check_report_file, write_report_file
    from mlpfac.plots.robustness import panels_plot

    if png.suffix.lower() != ".png":
        raise ConfigError(f"--panels {png}", "must name a .png file")
    check_report_file(png, "--panels")
    for folder in folders:
        if not (folder / "robustness.json").is_file():
            raise ConfigError(str(folder), "holds no robustness.json: not a sweep with --vary")
    data = panels_plot(folders)  # a robustness.json edited by hand: a ConfigError naming it
    if data is None:
        raise ConfigError(str(folders[0]), "no scenario of these sweeps has exactly one axis")
    try:
        print(write_report_file(png, data))
    except OSError as err:
        raise ConfigError(f"--panels {png}", f"cannot write ({err.strerror or err})") from None
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    """Check everything, build the plant and the controller, then run into a folder beside --out
    that replaces it only when whole (:mod:`mlpfac.runs.folder`), under --out's lock."""
    from mlpfac.exceptions import ConfigError
    from mlpfac.runs.folder import Recording, check_outputs, run_into_folder
    from mlpfac.scenario.parse import load

    scn = load(args.scenario, robot=args.robot).with_overrides(
        args.controller, args.seed, args.duration, lost_threshold=args.lost_threshold
    )
    baseline = None
    if args.baseline != "none" and not args.no_plot:
        try:
            baseline = scn.with_overrides(controller=args.baseline)
        except ConfigError as err:  # the flag that named it
            raise ConfigError("--baseline", err.what) from None
    out = args.out or Path("runs") / f"{scn.name}-{scn.controller}-s{scn.seed}"
    recording = check_outputs(
        out,
        Recording(args.save, args.spawn, args.connect, args.serve, args.bind, args.no_log, (args.grpc_port, args.port)),
    )
    from mlpfac.loop.runner import build  # the run's imports (MuJoCo, the kernels): after the checks of the input

    done = run_into_folder(scn, out, build(scn), recording, baseline, args.painter, args.writer)
    rec = done.rec
    if done.kept:
        kept = " and ".join(map(str, done.kept))
        print(f"mlpfac: {rec.reason}; {kept} kept the earlier run, this one was discarded", file=sys.stderr)
        return _interrupt_code(rec)
    _print_summary(done.metrics, out, built_and_changed(scn))
    if done.sink is not None and done.sink.serving:
        print("serving the recording; Ctrl-C stops the web viewer", flush=True)
        done.sink.wait()
    return {"ok": 0, "diverged": EXIT_FAILED}.get(rec.status) if rec.status != "interrupted" else _interrupt_code(rec)


def _interrupt_code(rec) -> int:
    return EXIT_TERMINATED if rec.reason.startswith("terminated") else EXIT_INTERRUPTED


def _fmt(x: float | None, scale: float = 1.0, unit: str = "") -> str:
    return "-" if x is None else f"{x * scale:.2f}{unit}"


def built_and_changed(scn) -> list[str]:
    """What a run read of its robot, built around it and changed of the file, in words (printed under
    the run's outcome): the robot's parts found, the reference fitted to its wheels or motors, the
    world, a shorter --duration, a route run past its end, and warnings of what its wheels or motors
    cannot give."""
    from mlpfac.scenario.world import said as world_said

    found = scn.table.get("provenance", {})
    warned = ("reference_warning", "torque_warning", "world_warning")
    lines = [f"warning: {found[k]}" for k in warned if found.get(k)]
    if found.get("found") and found.get("robot"):
        lines.append(f"robot: {found['robot']}")
    fit = [found[k] for k in ("reference_fit", "reference_torque") if found.get(k) and not found.get("torque_warning")]
    fit = fit or ([found["reference_fit"]] if found.get("reference_fit") else [])
    if fit:
        lines.append(f"reference: {'; '.join(fit)}")
    world = "; ".join(w for w in (world_said(scn.world, scn.terrain), found.get("world_need")) if w)
    if world:
        lines.append(f"world: {world}")
    if scn.dropped_events:
        times = ", ".join(f"{t:g} s" for t in scn.dropped_events)
        lines.append(
            f"note: --duration {scn.duration:g} s ends before the event at {times}: this run has no such event"
        )
    route = scn.reference  # an open path run past its end
    if getattr(route, "closed", True) is False and scn.duration > route.duration + scn.T:
        lines.append(
            f"note: the route ends at {route.duration:.4g} s; then the reference goes straight on along its last leg"
        )
    return lines


def _belief(m: dict) -> list[str]:
    """A run whose pose was estimated: what the truth shows (a belief that tracked while the truth was
    lost, said first), then the estimate's error beside the truth's figures."""
    est = m.get("estimate")
    if not est:
        return []
    said = [est["said"]] if est.get("said") else []
    return said + [
        f"pose from {est['pose_source']}: the estimate's error (belief against truth) RMS "
        f"{_fmt(est['rms_position_error_m'], 1e3, ' mm')}, max {_fmt(est['max_position_error_m'], 1e3, ' mm')}, "
        f"heading RMS {_fmt(est['rms_heading_error_rad'], 1e3, ' mrad')}; the figures below are the truth's"
    ]


def _print_summary(m: dict, out: Path, said: list[str] = ()) -> None:
    """The run's outcome first (as metrics.json records it, its threshold explained), then what was
    read, built and changed (``said``), then its figures."""
    from mlpfac.loop.metrics import outcome_words

    print(f"{m['scenario']} / {m['controller']} / seed {m['seed']}: {outcome_words(m)}")
    for line in [*_belief(m), *said]:
        print(f"  {line}")
    for ev in m["events"]:
        print(f"  event at {ev['time']:g} s: {ev['text']}")
    print(
        f"  position RMS {_fmt(m['rms_position_error_m'], 1e3, ' mm')}, max {_fmt(m['max_position_error_m'], 1e3, ' mm')}, heading RMS {_fmt(m['rms_heading_error_rad'], 1e3, ' mrad')}"
    )
    for name, ph in m["phases"].items():
        if ph["end_s"] > ph["start_s"] and ph["rms_position_error_m"] is not None:  # a phase with a step
            print(
                f"  {name:>6} [{ph['start_s']:g}, {ph['end_s']:g}) s: position RMS {_fmt(ph['rms_position_error_m'], 1e3, ' mm')}, heading RMS {_fmt(ph['rms_heading_error_rad'], 1e3, ' mrad')}"
            )
    learned = [
        f"{k} {m[key]:.3g}"
        for k, key in (("max |weight|", "max_abs_weight"), ("final mean diag P", "mean_diag_P_final"))
        if m[key] is not None
    ]  # fmt: skip  (a run that diverged before its first EKF update has weights, no P)
    if learned:
        print(f"  {', '.join(learned)}")
    print(f"  {m['sim_time_s']:.1f} s simulated in {m['wall_time_s']:.2f} s wall -> {out}")


def entry() -> None:
    """The ``mlpfac`` command: :func:`main`, then the process ends. When only mlpfac's own code ran
    (no controller of the user's was loaded, no thread alive but daemons), it ends without the
    interpreter's teardown, which takes about 0.1 s once rerun is imported and only frees what the
    system frees anyway: the exit handlers run first (rerun's flush of a stream still open among
    them), then the standard streams are flushed, as at a normal exit. A user's code may hold
    buffered files that only the teardown closes: then, with a thread alive that the normal exit
    would wait for, and when a stream cannot be flushed, the exit is the normal one. (A daemon
    thread, which the normal exit does not wait for, is ended either way: a recording that could
    not be closed leaves one, stuck in rerun, which the teardown would abort on.)"""
    try:
        code = main()
        sys.stdout.flush()  # stdout on a full disk (/dev/full) fails here, said in one line
    except OSError as err:
        code = exits.failed_write(err, "stdout")
    except (KeyboardInterrupt, Exception) as err:  # a signal main's own handling did not meet: while importing
        code = exits.interrupted(err)  # (an ImportError), or raised inside a class being made (a RuntimeError)
        if code is None:
            raise
    code = 0 if code is None else code
    plugins = sys.modules.get("mlpfac.control.plugins")
    others = [t for t in threading.enumerate() if t is not threading.current_thread()]
    if all(t.daemon for t in others) and not getattr(plugins, "USER_CODE", False):
        atexit._run_exitfuncs()
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except (OSError, ValueError):
            sys.exit(code)
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    entry()
