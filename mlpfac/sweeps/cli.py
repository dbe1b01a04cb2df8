"""The command line of sweeps: ``mlpfac sweep`` and ``mlpfac compare``, a shell over
:func:`mlpfac.sweeps.engine.sweep_folder` (one engine, two tables). Its arguments are defined
without importing the engine, which every other command's parser would pay for."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from mlpfac.flags import needs
from mlpfac.io.targets import cli_path

COMPARE_CONTROLLERS = ("adaptive", "corradini", "kanayama")
CONTROLLERS_HELP = "shipped names, path/to/file.py:Class, package.module:Class or installed names"
LOST_HELP = (
    "a finished run is lost when a phase's position RMS exceeds this many metres (sets every scenario's "
    "lost_threshold_m; default: each file's, else 5 %% of the path's size)"
)


def _add_common(p: argparse.ArgumentParser, seeds: str, out: str) -> None:
    from mlpfac.scenario.on_robot import ROBOT_HELP

    r = p.add_mutually_exclusive_group()
    r.add_argument("--robot", help=ROBOT_HELP)
    r.add_argument("--robots", help="comma-separated robots: every scenario on each (an axis, as --controllers)")
    p.add_argument("--seeds", default=seeds, help=f"seeds: 0-99, 3, 0,2,5 or 0-4,10 (default {seeds})")
    p.add_argument("--duration", type=float, help="override every scenario's duration in seconds")
    p.add_argument(
        "--vary",
        action="append",
        metavar="KEY=VALUES",
        help="a number of the scenario file by its dotted key (events.0.scale, plant.pose_noise_std, ...) as an "
        "axis: 1.0,1.25,1.5 or LOW:HIGH:COUNT (repeat: a grid); or drawn per seed: uniform:LOW:HIGH, normal:MEAN:SD",
    )
    p.add_argument(
        "--threshold",
        type=float,
        metavar="METRES",
        help="with --vary: the median position RMS a breaking point allows (default: the tracking limit, 0.2 m on "
        "the figure of eight)",
    )
    p.add_argument("--lost-threshold", type=float, metavar="METRES", help=LOST_HELP)
    p.add_argument(
        "--out", type=cli_path, default=Path(out), help=f"results folder (default {out}); re-running skips whole runs"
    )
    p.add_argument(
        "--limit",
        action="store_true",
        help="add the physical limit on every scenario and seed (controller `limit`: the run's own robot as the "
        "model, given the true state), each computed once and kept in --limit-cache; the tables gain x limit",
    )
    p.add_argument(
        "--limit-cache",
        type=cli_path,
        metavar="DIR",
        help="with --limit: the folder of computed limits, reused across sweeps (default runs/limits)",
    )
    g = p.add_argument_group("execution")
    g.add_argument("--workers", type=int, default=None, help="local worker processes (default: number of CPUs)")
    g.add_argument(
        "--batched",
        action="store_true",
        help="step the seeds of one scenario and controller together (runner.run_batch)",
    )
    g.add_argument("--batch-size", type=int, default=64, help="seeds per batch with --batched (default 64)")
    g.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on an existing Dask cluster, e.g. tcp://10.0.0.5:8786 (workers need `pip install -e .`)",
    )
    g.add_argument(
        "--scheduler-timeout", type=float, default=10.0, help="seconds to wait for the scheduler (default 10)"
    )
    g.add_argument("--save-rrd", action="store_true", help="also save each run's rerun recording as run.rrd")
    for flag, other in (
        ("--threshold", "--vary"),
        ("--batch-size", "--batched"),
        ("--scheduler-timeout", "--scheduler"),
        ("--limit-cache", "--limit"),
    ):
        needs(p, flag, other)


def add_sweep_arguments(p: argparse.ArgumentParser) -> None:
    p.description = (
        "Monte Carlo sweep: scenarios x controllers x seeds -> mean, median, 95 % CI per phase (CSV, Markdown, JSON)."
    )
    p.add_argument("scenarios", nargs="+", help="shipped scenario names or paths to .toml files")
    p.add_argument(
        "--controllers", help=f"comma-separated controllers: {CONTROLLERS_HELP} (default: each scenario's own)"
    )
    _add_common(p, "0-99", "runs/sweep")


def add_compare_arguments(p: argparse.ArgumentParser) -> None:
    p.description = (
        "Compare controllers on scenarios and seeds: position RMS, max error, heading RMS, bounded k/n per phase."
    )
    p.add_argument("scenarios", nargs="*", help="scenario names or .toml paths (default: every shipped scenario)")
    p.add_argument(
        "--controllers",
        default=",".join(COMPARE_CONTROLLERS),
        help=f"comma-separated: {CONTROLLERS_HELP} (default {','.join(COMPARE_CONTROLLERS)})",
    )
    _add_common(p, "0-9", "runs/compare")


def run_sweep_cli(args: argparse.Namespace) -> int:
    return _run_cli(args, "sweep")


def run_compare_cli(args: argparse.Namespace) -> int:
    return _run_cli(args, "compare")


def scenarios_of(args: argparse.Namespace) -> list[str]:
    """The scenarios a parsed ``sweep`` / ``compare`` command line runs, each on its robots
    (``--robot``, ``--robots``); ``compare`` without scenarios: every shipped one. The command and
    ``report --verify``, which plans a dataset's recorded command again, read a command line the
    same way, and plan it inside :func:`robots_named_as` (a robot named by its flag)."""
    from mlpfac.scenario.on_robot import robots_flag, with_robots
    from mlpfac.scenario.parse import scenario_names

    robots = [args.robot] if args.robot is not None else robots_flag(args.robots, "--robots")
    return with_robots(args.scenarios or scenario_names(), robots)


def robots_named_as(args: argparse.Namespace):
    """Messages about a robot inside named by the flag that brought it (``--robots``, ``--robot``)."""
    from mlpfac.scenario.on_robot import robots_named

    return robots_named("--robots" if args.robots is not None else "--robot")


def _run_cli(args: argparse.Namespace, stem: str) -> int:
    """Validate everything, then run; 0 done, 1 some run failed or a worker was lost, 2 bad input
    or a failed write (one line naming the path), 130 interrupted (Ctrl-C), 143 terminated (SIGTERM)."""
    from mlpfac.sweeps.engine import COMPARE_COLUMNS, SWEEP_COLUMNS, markdown, report, summary, sweep_folder

    columns = SWEEP_COLUMNS if stem == "sweep" else COMPARE_COLUMNS
    cmd = shlex.join(["mlpfac", *sys.argv[1:]]) if sys.argv[1:] else f"mlpfac {stem} ..."
    with robots_named_as(args):  # a robot's errors, found as the scenarios are put on it, name its flag
        done = sweep_folder(
            scenarios_of(args), args.controllers, args.seeds, args.out, duration=args.duration, workers=args.workers,
            batched=args.batched, batch_size=args.batch_size, scheduler=args.scheduler,
            scheduler_timeout=args.scheduler_timeout, save_rrd=args.save_rrd, stem=stem, columns=columns, command=cmd,
            vary=args.vary, threshold=args.threshold, lost_threshold=args.lost_threshold, limit=args.limit,
            limit_cache=args.limit_cache,
        )  # fmt: skip
    if done.code is not None:
        return done.code
    print(markdown(done.rows, columns), end="")
    print("\n" + summary(done.paired), end="")
    return report(done)
