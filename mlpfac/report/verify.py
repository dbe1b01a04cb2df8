"""Numbers that reproduce: the per-seed results kept beside each documented table, and
``mlpfac report docs --verify N``, which runs N of every dataset's runs again from the command on
record and says, per dataset, whether they came out bit-identical or by how much they differ.

A data folder made by ``mlpfac sweep`` or ``mlpfac compare`` keeps, besides its tables' JSON, one
row per run in ``runs.json`` (:func:`per_seed`, written by ``mlpfac report --collect``): the run's
outcome, its position RMS over the whole run and per phase, and a digest of everything the run's
``metrics.json`` holds but its wall-clock time (:func:`digest`). Equal digests are equal bits.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import random
import shlex
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.exceptions import ConfigError, MlpfacError, UnavailableError
from mlpfac.flags import Parser
from mlpfac.report.data import OUTPUT, read_json, record

RUNS_FILE = "runs.json"
UNTIMED = ("wall_time_s", "rrd")  # what differs between two runs of the same bits: time, and the recording's bytes
FIGURES = ("rms_position_error_m", "max_position_error_m", "rms_heading_error_rad")


def digest(metrics: dict) -> str:
    """A hash of a run's metrics.json but its wall-clock time: equal for the same bits."""
    kept = {k: v for k, v in metrics.items() if k not in UNTIMED}
    return hashlib.sha256(json.dumps(kept, sort_keys=True).encode()).hexdigest()[:32]


def run_row(m: dict) -> dict:
    """What ``runs.json`` keeps of one run (``m``, its metrics.json)."""
    from mlpfac.loop.metrics import RunMetrics

    run = RunMetrics.from_json(m)
    return {
        "scenario": run.scenario,
        "controller": run.controller,
        "seed": run.seed,
        "digest": digest(m),
        "status": run.status,
        "outcome": run.outcome,
        "steps": run.steps,
        **{k: m[k] for k in FIGURES},
        "phases": {p: {k: getattr(v, k) for k in FIGURES} for p, v in run.phases.items()},
    }


def per_seed(results: Path) -> list[dict]:
    """The rows of ``runs.json`` for a finished results folder: every run's, from its metrics.json."""
    rows = []
    for f in sorted(results.glob("*/*/seed-*/metrics.json")):
        try:
            rows.append(run_row(json.loads(f.read_text())))
        except (OSError, ValueError, KeyError, TypeError) as err:
            raise ConfigError(str(f), f"not a run's metrics ({err})") from None
    return rows


@dataclass
class Verdict:
    """One dataset's verification: the runs re-run, how many came out the same bits, the largest
    relative difference of a kept figure, and the runs whose outcome changed. ``skipped``: it could
    not run here (a robot not available, a command that cannot be planned: ``--strict`` makes that an
    error); ``unverified``: it has nothing to re-run (a script's table, runs no longer planned)."""

    name: str
    command: str
    checked: int = 0
    identical: int = 0
    worst: float = 0.0  # max |new - kept| / |kept| over every figure kept of the runs that differ
    worst_run: str = ""
    flipped: list[str] = field(default_factory=list)  # outcome or status changed
    skipped: str = ""  # why the dataset could not be verified here
    unverified: str = ""  # why the dataset has nothing to verify
    printed: bool = False  # a command's printed output, run again whole (checked 1: its output)

    def line(self) -> str:
        if self.skipped:
            return f"{self.name}: skipped: {self.skipped}"
        if self.unverified:
            return f"{self.name}: not verified: {self.unverified}"
        if self.printed:
            what = "as recorded" if self.identical else f"differs: {self.worst_run}"
            return f"{self.name}: its printed output {what}"
        if self.identical == self.checked:
            return f"{self.name}: {self.checked} of {self.checked} runs bit-identical"
        out = (
            f"{self.name}: {self.identical} of {self.checked} runs bit-identical; "
            f"largest difference {self.worst:.3g} (relative, {self.worst_run})"
        )
        return out + (f"; outcome changed: {', '.join(self.flipped)}" if self.flipped else "")

    @property
    def differs(self) -> bool:
        return not (self.skipped or self.unverified) and self.identical != self.checked


class _Parser(Parser):
    """The command line's parser (its flags' rules too), raising instead of printing its usage and exiting."""

    def error(self, message: str):
        raise ConfigError("", message)


def _parser() -> argparse.ArgumentParser:
    """The command lines of ``mlpfac sweep`` and ``mlpfac compare``, as the command reads them."""
    from mlpfac.sweeps.cli import add_compare_arguments, add_sweep_arguments

    parser = _Parser(prog="mlpfac", add_help=False)
    sub = parser.add_subparsers(dest="command", required=True)
    add_sweep_arguments(sub.add_parser("sweep", add_help=False))
    add_compare_arguments(sub.add_parser("compare", add_help=False))
    return parser


def _words(command: str, where: str) -> tuple[list[str], Path | None]:
    """The words of a recorded ``[NAME=VALUE ...] [cd DIR &&] mlpfac sweep|compare ...`` command and
    the folder it names (None: the repository's root); ConfigError naming ``where`` if it is no
    command line."""
    if not isinstance(command, str):
        raise ConfigError(where, f"expected the command line as a string, got {type(command).__name__} {command!r}")
    try:
        words = shlex.split(command)
    except ValueError as err:
        raise ConfigError(where, f"cannot be read as a command line ({err}): {command!r}") from None
    while words and "=" in words[0] and words[0].partition("=")[0].isidentifier():  # MENAGERIE_ROOT=... the reader sets
        words = words[1:]
    folder = None
    if len(words) > 3 and words[0] == "cd" and words[2] == "&&":
        folder, words = Path(words[1]), words[3:]
    return words, folder


def _plan(command: str, root: Path, where: str = "command"):
    """The jobs of a recorded ``[NAME=VALUE ...] [cd DIR &&] mlpfac sweep|compare ...`` command (its
    ``--robot``/``--robots`` too), and the folder it runs in. ConfigError naming ``where`` for a
    command that is no command line or has a flag mlpfac does not read; a :class:`Script`
    for any other command; :class:`~mlpfac.exceptions.UnavailableError` when a robot it needs is not here."""
    words, folder = _words(command, where)
    if words[:1] != ["mlpfac"] or words[1:2] not in (["sweep"], ["compare"]):
        raise ScriptTableError(command, "a script's table: run its command again to check it")
    from mlpfac.sweeps.cli import robots_named_as, scenarios_of
    from mlpfac.sweeps.limits import with_limit
    from mlpfac.sweeps.plan import parse_controllers, parse_seeds, plan
    from mlpfac.sweeps.vary import parse_vary

    try:
        args = _parser().parse_args(words[1:])
    except ConfigError as err:
        raise ConfigError(where, f"not a command mlpfac reads ({err.what}): {command!r}") from None
    where_run = root / folder if folder is not None else root
    if not where_run.is_dir():
        raise ConfigError(where, f"cd {folder}: no such folder ({where_run}): {command!r}")
    lost = args.lost_threshold
    if lost is not None:
        from mlpfac.scenario.parse import lost_threshold_m

        lost = lost_threshold_m(lost, "--lost-threshold")
    with contextlib.chdir(where_run), robots_named_as(args):
        jobs = plan(
            scenarios_of(args),
            with_limit(parse_controllers(args.controllers), args.limit),
            parse_seeds(args.seeds),
            args.duration,
            parse_vary(args.vary),  # the grid points and draws: each point's runs are its own scenario
            lost,
        )
    return jobs, where_run


class ScriptTableError(ConfigError):
    """A dataset's command is not ``mlpfac sweep|compare``: a script's table, not re-run here."""


def differ(kept: dict, new: dict) -> tuple[float, str]:
    """The largest relative difference of the figures both rows have, and which."""
    worst, which = 0.0, ""
    pairs = [(k, kept.get(k), new.get(k)) for k in FIGURES]
    for p, v in kept.get("phases", {}).items():
        pairs += [(f"{p} {k}", v.get(k), new.get("phases", {}).get(p, {}).get(k)) for k in FIGURES]
    for k, a, b in pairs:
        if isinstance(a, float) and isinstance(b, float) and a != b:
            d = abs(b - a) / max(abs(a), 1e-300)
            if d > worst:
                worst, which = d, k
    return worst, which


KEPT = {"scenario": str, "controller": str | None, "seed": int, "digest": str, "status": str, "outcome": str | None}


def kept_runs(folder: Path) -> dict[tuple, dict]:
    """The rows of a dataset's runs.json by (scenario, controller, seed); ConfigError naming the
    file and the row when it is not what ``report --collect`` writes."""
    path = folder / RUNS_FILE
    runs = read_json(folder, RUNS_FILE).get("runs")
    if not isinstance(runs, list):
        raise ConfigError(f"{path} runs", f"expected a list of runs, got {type(runs).__name__}")
    out = {}
    for i, r in enumerate(runs):
        bad = [k for k, t in KEPT.items() if not isinstance(r, dict) or not isinstance(r.get(k), t)]
        bad += [] if not isinstance(r, dict) or isinstance(r.get("phases", {}), dict) else ["phases"]
        if isinstance(r, bool) or bad:
            fields = ", ".join(f"{k} ({t})" for k, t in KEPT.items())
            raise ConfigError(
                f"{path} runs[{i}]", f"expected a run's row with {fields}; wrong or missing: {', '.join(bad)}"
            )
        out[(r["scenario"], r["controller"], r["seed"])] = r
    return out


@dataclass
class Planned:
    """A dataset read and planned, before any run: its verdict so far, its kept rows and its jobs."""

    verdict: Verdict
    kept: dict = field(default_factory=dict)
    jobs: list = field(default_factory=list)
    where: Path | None = None
    output: bool = False  # a command's printed output (output.txt), run again whole


def prepare(folder: Path, root: Path) -> Planned:
    """A dataset's files read and checked and its command planned again: ConfigError (bad input)
    for files or a command that are not what ``report --collect`` writes."""
    meta = folder / "meta.json"
    command = read_json(folder, "meta.json").get("command")
    if command is None or (
        isinstance(command, str) and not command.strip()
    ):  # what made the dataset is what --verify runs, and what its page says
        raise ConfigError(
            f"{meta} command",
            "missing: a dataset's meta.json names the command that made it (report --collect NAME=... --command ...)",
        )
    p = Planned(Verdict(folder.name, command if isinstance(command, str) else ""))
    _words(command, f"{meta} command")  # a command that is no command line is bad input, even for a script's table
    if not (folder / RUNS_FILE).is_file():
        if (folder / OUTPUT).is_file():  # a command's printed output: run again and compared, or a record
            p.verdict.unverified = record(folder)
            p.output = not p.verdict.unverified
            return p
        table = (folder / "table.md").is_file()
        p.verdict.unverified = "a script's table: run its command again to check it" if table else ""
        p.verdict.unverified = (
            p.verdict.unverified or f"no per-seed results ({RUNS_FILE}): collect it again from its command"
        )
        return p
    p.kept = kept_runs(folder)
    try:
        jobs, p.where = _plan(command, root, f"{meta} command")
    except ScriptTableError as err:
        p.verdict.unverified = err.what
        return p
    except UnavailableError as err:
        p.verdict.skipped = f"not available here: {err}"
        return p
    except ConfigError as err:
        if err.where == f"{meta} command":
            raise
        p.verdict.skipped = f"its command cannot be planned again ({err})"
        return p
    p.jobs = [j for j in jobs if j.key in p.kept]
    if not p.jobs:
        p.verdict.unverified = (
            f"none of its {len(p.kept)} runs is in its command's plan: collect it again from its command"
        )
    return p


def rerun(job) -> tuple[dict | None, str | None]:
    """One run of a job: its metrics, or None and the error a bug raised. A Ctrl-C or a SIGTERM
    during the run ends the verification as that signal (exit 130 or 143)."""
    from mlpfac.io.interrupts import Terminated
    from mlpfac.loop.metrics import metrics
    from mlpfac.loop.runner import run
    from mlpfac.scenario.parse import parse

    try:
        rec = run(parse(job.table, job.source))
    except (KeyboardInterrupt, MlpfacError):
        raise
    except Exception as err:  # a bug, reported as the run's difference
        return None, f"{type(err).__name__}: {err}"
    if rec.status == "interrupted":
        raise Terminated() if "SIGTERM" in rec.reason else KeyboardInterrupt()
    return metrics(rec), None


def verify_dataset(p: Planned, n: int) -> Verdict:
    """Run ``n`` of the dataset's runs again (a sample fixed by the dataset's name) and compare."""
    v = p.verdict
    for job in random.Random(v.name).sample(p.jobs, min(n, len(p.jobs))):
        with contextlib.chdir(p.where):
            new_metrics, error = rerun(job)
        name = f"{job.scenario} / {job.controller} / seed {job.seed}"
        v.checked += 1
        if error is not None:
            v.flipped.append(f"{name} raised")
            v.worst, v.worst_run = float("inf"), name
            continue
        new, old = run_row(new_metrics), p.kept[job.key]
        if new["digest"] == old["digest"]:
            v.identical += 1
            continue
        if (new["status"], new["outcome"]) != (old["status"], old["outcome"]):
            v.flipped.append(f"{name} {old['outcome'] or old['status']} -> {new['outcome'] or new['status']}")
        d, which = differ(old, new)
        if d >= v.worst:
            v.worst, v.worst_run = d, f"{name}, {which or 'another figure'}"
    return v


def verify(docs: Path, n: int, output: Callable[[Planned, Path], Verdict] | None = None) -> Iterator[Verdict]:
    """Every dataset of ``docs/data`` checked by :func:`verify_dataset`, one after the other, from
    the repository root (the folder above ``docs``, where the recorded commands run); a command's
    printed output by ``output`` (:func:`mlpfac.report.remake.verify_output`: its command run
    again; without it, left unverified). Every dataset is read and planned first: bad input raises
    ConfigError before the first run."""
    if n < 1:
        raise ConfigError("--verify", f"must be a number of runs >= 1, got {n}")
    data = docs / "data"
    if not data.is_dir():
        raise ConfigError(str(data), "no data folder: nothing to verify")
    root = docs.resolve().parent
    folders = [f for f in sorted(data.iterdir()) if (f / "meta.json").is_file()]
    planned = [(prepare(f, root), f) for f in folders]
    for p, _ in planned:
        if p.output and output is None:
            p.verdict.unverified, p.output = "a command's printed output: run its command again to check it", False
    return (output(p, f) if p.output else verify_dataset(p, n) for p, f in planned)


def run_cli(docs: Path, n: int, strict: bool = False, output: Callable[[Planned, Path], Verdict] | None = None) -> int:
    """``mlpfac report DOCS --verify N [--strict]``: a line per dataset as it is done; exit 1 if a
    run differs (or, with ``strict``, if a dataset was skipped), else 0."""
    differs, skipped = False, []
    for v in verify(docs, n, output):
        print(v.line(), flush=True)
        differs |= v.differs
        skipped += [v.name] if v.skipped else []
    if skipped:
        also = "--strict: an error" if strict else "--strict makes that an error"
        print(
            f"mlpfac: {len(skipped)} datasets skipped, not verified here: {', '.join(skipped)} ({also})",
            file=sys.stderr,
        )
    return 1 if differs or (strict and skipped) else 0
