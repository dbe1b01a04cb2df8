"""Numbers that reproduce: the per-seed results kept beside each documented table, and
``mlpfac report docs --verify N``, which runs N of every dataset's runs again from the command on
record and says, per dataset, whether they came out bit-identical or by how much they differ.

A data folder made by ``mlpfac sweep`` or ``mlpfac compare`` keeps, besides its tables' JSON, one
row per run in ``runs.json`` (:func:`per_seed`, written by ``mlpfac report --collect``): the run's
outcome, its position RMS over the whole run and per phase, and a digest of everything the run's
``metrics.json`` holds but its wall-clock time (:func:`digest`). Equal digests are equal bits.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import random
import shlex
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.exceptions import ConfigError

RUNS_FILE = "runs.json"
UNTIMED = ("wall_time_s", "rrd")  # what differs between two runs of the same bits: time, and the recording's bytes
FIGURES = ("rms_position_error_m", "max_position_error_m", "rms_heading_error_rad")


def read_data(folder: Path, name: str) -> str:
    """A data file's text; ConfigError naming it when it is missing or cannot be read."""
    path = folder / name
    if not path.is_file():
        raise ConfigError(str(path), "missing: the data folder holds no such file")
    try:
        return path.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(str(path), f"cannot read: {err}") from None


def read_json(folder: Path, name: str) -> dict:
    """A data file's JSON; ConfigError naming it when it is not what a sweep writes."""
    text = read_data(folder, name)
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as err:
        raise ConfigError(str(folder / name), f"not valid JSON: {err}") from None
    if not isinstance(data, dict):
        raise ConfigError(str(folder / name), "expected a JSON object")
    return data


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
    relative difference of a kept figure, and the runs whose outcome changed."""

    name: str
    command: str
    checked: int = 0
    identical: int = 0
    worst: float = 0.0  # max |new - kept| / |kept| over every figure kept of the runs that differ
    worst_run: str = ""
    flipped: list[str] = field(default_factory=list)  # outcome or status changed
    skipped: str = ""  # why the dataset was not verified

    def line(self) -> str:
        if self.skipped:
            return f"{self.name}: not verified: {self.skipped}"
        if self.identical == self.checked:
            return f"{self.name}: {self.checked} of {self.checked} runs bit-identical"
        out = (
            f"{self.name}: {self.identical} of {self.checked} runs bit-identical; "
            f"largest difference {self.worst:.3g} (relative, {self.worst_run})"
        )
        return out + (f"; outcome changed: {', '.join(self.flipped)}" if self.flipped else "")

    @property
    def differs(self) -> bool:
        return not self.skipped and self.identical != self.checked


def _parser():
    """The command lines of ``mlpfac sweep`` and ``mlpfac compare``, as the command reads them."""
    import argparse

    from mlpfac.sweeps.cli import add_compare_arguments, add_sweep_arguments

    parser = argparse.ArgumentParser(prog="mlpfac")
    sub = parser.add_subparsers(dest="command", required=True)
    add_sweep_arguments(sub.add_parser("sweep"))
    add_compare_arguments(sub.add_parser("compare"))
    return parser


def _plan(command: str, root: Path):
    """The jobs of a recorded ``[NAME=VALUE ...] [cd DIR &&] mlpfac sweep|compare ...`` command (its
    ``--robot``/``--robots`` too), and the folder it runs in; ConfigError for any other command."""
    words = shlex.split(command)
    while words and "=" in words[0] and words[0].partition("=")[0].isidentifier():  # MENAGERIE_ROOT=... the reader sets
        words = words[1:]
    where = root
    if len(words) > 3 and words[0] == "cd" and words[2] == "&&":
        where, words = root / words[1], words[3:]
    if words[:1] != ["mlpfac"] or words[1:2] not in (["sweep"], ["compare"]):
        raise ConfigError(command, "a script's table: run its command again to check it")
    from mlpfac.sweeps.cli import scenarios_of
    from mlpfac.sweeps.plan import parse_controllers, parse_seeds, plan
    from mlpfac.sweeps.vary import parse_vary

    try:
        args = _parser().parse_args(words[1:])
    except SystemExit:
        raise ConfigError(command, "not a command mlpfac reads") from None
    with contextlib.chdir(where):
        jobs = plan(
            scenarios_of(args),
            parse_controllers(args.controllers),
            parse_seeds(args.seeds),
            args.duration,
            parse_vary(args.vary),  # the grid points and draws: each point's runs are its own scenario
        )
    return jobs, where


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


def verify_dataset(folder: Path, n: int, root: Path) -> Verdict:
    """Run ``n`` of the dataset's runs again (a sample fixed by the dataset's name) and compare."""
    from mlpfac.sweeps.worker import run_task

    command = read_json(folder, "meta.json").get("command", "")
    v = Verdict(folder.name, command)
    if not (folder / RUNS_FILE).is_file():
        v.skipped = "a script's table: run its command again to check it" if (folder / "table.md").is_file() else ""
        v.skipped = v.skipped or f"no per-seed results ({RUNS_FILE}): collect it again from its command"
        return v
    kept = {(r["scenario"], r["controller"], r["seed"]): r for r in read_json(folder, RUNS_FILE)["runs"]}
    try:
        jobs, where = _plan(command, root)
    except ConfigError as err:
        v.skipped = f"its command cannot be planned again ({err})"
        return v
    jobs = [j for j in jobs if j.key in kept]
    if not jobs:
        v.skipped = f"none of its {len(kept)} runs is in its command's plan: collect it again from its command"
        return v
    for job in random.Random(folder.name).sample(jobs, min(n, len(jobs))):
        with contextlib.chdir(where):
            (res,) = run_task([job])
        name = f"{job.scenario} / {job.controller} / seed {job.seed}"
        v.checked += 1
        if res["error"] is not None:
            v.flipped.append(f"{name} raised")
            v.worst, v.worst_run = float("inf"), name
            continue
        new, old = run_row(res["metrics"]), kept[job.key]
        if new["digest"] == old["digest"]:
            v.identical += 1
            continue
        if (new["status"], new["outcome"]) != (old["status"], old["outcome"]):
            v.flipped.append(f"{name} {old['outcome'] or old['status']} -> {new['outcome'] or new['status']}")
        d, which = differ(old, new)
        if d >= v.worst:
            v.worst, v.worst_run = d, f"{name}, {which or 'another figure'}"
    return v


def verify(docs: Path, n: int) -> Iterator[Verdict]:
    """Every dataset of ``docs/data`` checked by :func:`verify_dataset`, one after the other, from
    the repository root (the folder above ``docs``, where the recorded commands run). Bad input
    raises ConfigError before the first run."""
    if n < 1:
        raise ConfigError("--verify", f"must be a number of runs >= 1, got {n}")
    data = docs / "data"
    if not data.is_dir():
        raise ConfigError(str(data), "no data folder: nothing to verify")
    root = docs.resolve().parent
    folders = [f for f in sorted(data.iterdir()) if (f / "meta.json").is_file()]
    return (verify_dataset(f, n, root) for f in folders)
