"""Every dataset of the docs made again from the command on record: ``mlpfac report docs --remake``.

Each data folder's ``meta.json`` keeps the command that made it. ``--remake`` runs it again from
the repository's root (the folder above ``docs``), as a reader would with the venv active, and
collects what it wrote (:func:`mlpfac.report.results.collect`): a sweep's or comparison's results
folder (its ``--out``, which must not exist yet: a sweep would resume the runs already there, made
by other code), or what a script printed (``table.md``, ``output.txt``). Sweeps run first, since a
script may read a sweep's folder (``python -m mlpfac.sweeps.bound runs/NAME``). A ``bench-*``
dataset (a benchmark's timings) or a ``history-*`` one (figures of earlier code) is a record of what
was measured once: it is made again only when named. ``NAME=VALUE`` words before the command (``MENAGERIE_ROOT=/path/to/...``) say
what the reader sets; the environment's own value is used.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from mlpfac.exceptions import ConfigError
from mlpfac.report.data import OUTPUT, read_data, read_json, record
from mlpfac.report.verify import Planned, Verdict, _words

ASSIGNMENTS = re.compile(r"\s*(?:[A-Za-z_]\w*=\S+\s+)*")  # MENAGERIE_ROOT=... before a command


def datasets(docs: Path, names: str) -> list[Path]:
    """The data folders named (``a,b``), or every one that is not a record of timings; sweeps first."""
    data = docs / "data"
    every = sorted(f for f in data.iterdir() if (f / "meta.json").is_file()) if data.is_dir() else []
    if names:
        wanted = names.split(",")
        unknown = [n for n in wanted if not (data / n / "meta.json").is_file()]
        if unknown:
            raise ConfigError(f"--remake {names}", f"no such dataset: {', '.join(unknown)} (in {data})")
        chosen = [data / n for n in wanted]
    else:
        chosen = [f for f in every if not record(f)]
    return sorted(chosen, key=lambda f: (_results(f, docs) is None, f.name))


def _results(folder: Path, docs: Path) -> Path | None:
    """The results folder a sweep's or comparison's command writes (its ``--out``), else None."""
    words, cd = _words(read_json(folder, "meta.json").get("command"), str(folder / "meta.json command"))
    if words[:1] != ["mlpfac"] or words[1:2] not in (["sweep"], ["compare"]) or "--out" not in words[:-1]:
        return None
    out = Path(words[words.index("--out") + 1])
    return out if out.is_absolute() else docs.resolve().parent / (cd or ".") / out


def _env() -> dict[str, str]:
    """The environment of a shell with this venv active: its ``bin`` first on PATH."""
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    return env


def printed(folder: Path, docs: Path) -> subprocess.CompletedProcess:
    """A script's recorded command run again by bash from the repository's root, as written but for
    the ``NAME=VALUE`` words before it (what the reader sets: the environment's own is used): what
    it printed."""
    command = read_json(folder, "meta.json")["command"]
    _words(command, str(folder / "meta.json command"))  # a command line, or bad input
    line = command[ASSIGNMENTS.match(command).end() :]
    return subprocess.run(["bash", "-c", line], cwd=docs.resolve().parent, env=_env(), capture_output=True, text=True)


def remake(folder: Path, docs: Path) -> Path:
    """Run a dataset's command again and collect it into its folder; ConfigError when it fails."""
    from mlpfac.report.results import collect

    command = read_json(folder, "meta.json")["command"]
    words, cd = _words(command, str(folder / "meta.json command"))
    root = docs.resolve().parent
    out = _results(folder, docs)
    if out is not None and out.exists():
        raise ConfigError(
            str(out), f"exists: {folder.name}'s sweep would resume the runs there; move it away to make it again"
        )
    print(f"{folder.name}: {command}", flush=True)
    if out is not None:
        mlpfac = Path(sys.executable).parent / "mlpfac"  # this venv's, as its PATH would find it
        where = root / (cd or ".")
        done = subprocess.run([str(mlpfac) if mlpfac.is_file() else "mlpfac", *words[1:]], cwd=where, env=_env())
        if done.returncode != 0:
            raise ConfigError(folder.name, f"its command exited with {done.returncode}")
        return collect(folder, out)
    done = printed(folder, docs)
    if done.returncode != 0:
        tail = " / ".join(done.stderr.strip().splitlines()[-2:])
        raise ConfigError(folder.name, f"its command exited with {done.returncode}: {tail}")
    name = "table.md" if (folder / "table.md").is_file() else "output.txt"
    text = root / "runs" / "remade" / folder.name / name
    text.parent.mkdir(parents=True, exist_ok=True)
    text.write_text(done.stdout)
    return collect(folder, text)


def verify_output(p: Planned, folder: Path) -> Verdict:
    """Run a command's printed output again (the whole command) and compare it, line by line."""
    v = p.verdict
    done = printed(folder, folder.parent.parent)
    if "is not available here" in done.stderr:  # a robot it needs (a loop of commands may go on without it)
        v.skipped = f"not available here: {done.stderr.strip().splitlines()[-1]}"
        return v
    v.checked, v.printed, kept = 1, True, read_data(folder, OUTPUT).splitlines()
    new = done.stdout.splitlines() if done.returncode == 0 else [f"(exit {done.returncode}) {done.stderr.strip()}"]
    if new == kept:
        v.identical = 1
        return v
    i = next((i for i, (a, b) in enumerate(zip(kept, new, strict=False)) if a != b), min(len(kept), len(new)))
    v.worst, v.worst_run = float("inf"), f"line {i + 1}: {(new[i] if i < len(new) else '(none)')[:120]}"
    return v


def run_cli(docs: Path, names: str) -> int:
    """``mlpfac report DOCS --remake [NAMES]``: each dataset made again, one after the other; exit 1
    if one failed (the others are made), then the tables written."""
    failed = []
    for folder in datasets(docs, names):
        try:
            remake(folder, docs)
        except ConfigError as err:
            print(f"mlpfac: {err}", file=sys.stderr)
            failed.append(folder.name)
    if failed:
        print(f"mlpfac: not made again: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0
