"""The results tables of the docs, written from the data kept beside them: ``mlpfac report``.

A table in a Markdown page sits between two markers, and everything between them is generated::

    <!-- table: data/ablation view=summary controllers=oracle,corradini -->
    | controller | eight-nominal | ... |
    <!-- /table -->

The path is a data folder relative to the page's own folder. It holds what a documented command
wrote (``sweep.json`` or ``compare.json``, ``paired.json``; or ``table.md``, the Markdown table a
script printed) and ``meta.json``: the command, the code version that ran it and the date; a sweep's data also
keeps every run's figures (``runs.json``, :mod:`mlpfac.report.verify`: ``mlpfac report --verify N``). Views,
each drawn by the table code the sweep itself uses (:mod:`mlpfac.sweeps.tables`,
:mod:`mlpfac.sweeps.paired`):

- ``sweep``: the full per-phase table (``sweep.json``), ``compare``: the shorter one (``compare.json``);
- ``paired``: per seed against Corradini's law and the oracle (``paired.json``);
- ``summary``: controllers x scenarios, median position RMS and x oracle (``paired.json``); with
  ``bound=NAME`` the ratio to that controller on the same seed (from ``runs.json``), ``bound=none``
  no ratio (where no law of the table is a bound);
- ``untold``: each law told the change against itself told nothing, per scenario (``paired.json``);
- ``robustness``: each controller's breaking points along a ``--vary`` axis (``robustness.json``,
  :mod:`mlpfac.sweeps.robustness`);
- ``limit``: per scenario the physical limit, ``mpc`` and the bound against it, and the controllers
  listed (``controllers=``), each x limit on the same seed (``runs.json``: :mod:`mlpfac.report.limit`);
- ``text``: ``table.md`` as it is.

Options (shell words after the view): ``scenarios=a,b`` and ``controllers=a,b`` keep those, in
that order; ``labels=a,b`` renames the scenarios kept (column heads of a summary).

``collect`` copies a finished results folder into a data folder and stamps ``meta.json``, so that
re-running the documented command, then ``mlpfac report --collect NAME=RESULTS``, updates both
the data and the tables.
"""

from __future__ import annotations

import json
import re
import shlex
import subprocess
from datetime import UTC, datetime
from pathlib import Path

from mlpfac.exceptions import ConfigError
from mlpfac.io.files import write_atomic
from mlpfac.report.data import read_data, read_json

MARKER = re.compile(r"^<!-- table: (?P<spec>.+?) -->\n(?P<body>.*?)^<!-- /table -->$", re.M | re.S)
VIEWS = ("sweep", "compare", "paired", "summary", "untold", "robustness", "limit", "text")
DATA_FILES = ("sweep.json", "compare.json", "paired.json", "robustness.json")
OPTIONS = ("view", "scenarios", "controllers", "labels", "bound")
ROW_TEXTS: dict[str, tuple[type, ...]] = {  # the fields of a sweep's rows that are no number
    "scenario": (str,), "controller": (str,), "phase": (str,), "worst_status": (str,), "no_event_twin": (str, type(None)),
    "vary": (dict,), "draws": (list,),
}  # fmt: skip
DATA_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")  # a data folder's name (--collect NAME=...)


def parse_spec(spec: str, where: str) -> tuple[str, dict[str, str]]:
    """``data/NAME key=value ...`` -> (the data path, its options); ConfigError naming the page."""
    try:
        words = shlex.split(spec)
    except ValueError as err:
        raise ConfigError(where, f"table marker {spec!r}: {err}") from None
    opts = dict(w.split("=", 1) for w in words[1:] if "=" in w)
    bad = [w for w in words[1:] if "=" not in w or w.split("=", 1)[0] not in OPTIONS]
    if not words or bad:
        raise ConfigError(where, f"table marker {spec!r}: expected 'PATH key=value ...' with keys {OPTIONS}")
    if opts.get("view", "summary") not in VIEWS:
        raise ConfigError(where, f"table marker {spec!r}: view must be one of {VIEWS}")
    return words[0], opts


def select(rows: list[dict], scenarios: str | None, controllers: str | None) -> list[dict]:
    """The rows of the listed scenarios and controllers (all if not listed), scenario by scenario,
    each in the listed order, else in the data's; the phases of one keep their order."""
    order = {}
    for key, wanted in (("scenario", scenarios), ("controller", controllers)):
        there = list(dict.fromkeys(r[key] for r in rows))
        names = wanted.split(",") if wanted else there
        unknown = [n for n in names if n not in there]
        if unknown:
            raise ConfigError(f"{key}s={wanted}", f"{', '.join(unknown)} not in the data ({', '.join(there)})")
        order[key] = {n: i for i, n in enumerate(names)}
    kept = [r for r in rows if r["scenario"] in order["scenario"] and r["controller"] in order["controller"]]
    return sorted(kept, key=lambda r: (order["scenario"][r["scenario"]], order["controller"][r["controller"]]))


def render(folder: Path, opts: dict[str, str]) -> str:
    """The Markdown table a data folder gives for one view and its options."""
    view = opts.get("view", "summary")
    if view == "text":
        return read_data(folder, "table.md")
    if view == "limit":
        return _limit(folder, opts)
    name = {"sweep": "sweep.json", "compare": "compare.json", "robustness": "robustness.json"}.get(view, "paired.json")
    if view == "robustness":
        from mlpfac.plots.robustness import read_robustness

        read_data(folder, name)  # a missing file named as the other views name it
        data = read_robustness(folder / name)
    else:
        data = read_json(folder, name)
    rows = data.get("breaking_points" if view == "robustness" else "rows")
    if not isinstance(rows, list) or not all(
        isinstance(r, dict) and "scenario" in r and "controller" in r for r in rows
    ):
        raise ConfigError(
            str(folder / name), "expected the rows a sweep writes (each with its scenario and controller)"
        )
    if view != "robustness":  # (robustness.json is checked as it is read)
        _check_rows(rows, folder / name)
    try:
        return _render(folder, view, opts, data, rows)
    except KeyError as err:
        raise ConfigError(str(folder / name), f"a row has no field {err}: not what a sweep writes") from None


def _check_rows(rows: list[dict], path: Path) -> None:
    """Each field of a sweep's rows of the type a sweep writes: ConfigError naming the file, the row and the field."""
    for i, r in enumerate(rows):
        for key, v in r.items():
            want = ROW_TEXTS.get(key, (int, float, type(None)))
            if not isinstance(v, want) or (isinstance(v, bool) and bool not in want):
                kind = (
                    "a text"
                    if str in want
                    else "a table"
                    if dict in want
                    else "a list"
                    if list in want
                    else "a number or null"
                )
                raise ConfigError(f"{path} rows[{i}].{key}", f"expected {kind}, got {v!r}")


def _render(folder: Path, view: str, opts: dict[str, str], data: dict, rows: list[dict]) -> str:
    from mlpfac.sweeps.paired import paired_columns, summary
    from mlpfac.sweeps.tables import COMPARE_COLUMNS, SWEEP_COLUMNS, markdown

    try:
        rows = select(rows, opts.get("scenarios"), opts.get("controllers"))
    except ConfigError as err:
        raise ConfigError(f"{folder} {err.where}", err.what) from None
    bound = opts.get("bound", "oracle")
    if view == "summary" and bound not in ("oracle", "none"):  # the ratios, by the data's own names
        rows = _bound(folder, bound, rows)
    if "labels" in opts:
        kept = list(dict.fromkeys(r["scenario"] for r in rows))
        labels = opts["labels"].split(",")
        if len(labels) != len(kept):
            raise ConfigError(str(folder), f"labels: {len(labels)} given for {len(kept)} scenarios {kept}")
        rows = [
            {k: v for k, v in r.items() if k != "vary"} | {"scenario": labels[kept.index(r["scenario"])]} for r in rows
        ]
    if view == "summary":
        return summary(rows, None if bound == "none" else bound)
    if view == "untold":
        return untold(rows)
    if view == "robustness":
        from mlpfac.sweeps.robustness import markdown as breaking_markdown

        return breaking_markdown(rows, (data.get("meta") or {}).get("threshold_m"), data.get("curves"))
    columns = {"sweep": SWEEP_COLUMNS, "compare": COMPARE_COLUMNS, "paired": paired_columns(rows)}[view]
    return markdown(rows, columns)


def _limit(folder: Path, opts: dict[str, str]) -> str:
    """The ``limit`` view (:mod:`mlpfac.report.limit`) of the data's runs.json: its scenarios (or those
    listed) in their order, the controllers listed; a ConfigError naming what is not there."""
    from mlpfac.report.limit import LIMIT, limit_table

    runs = read_json(folder, "runs.json").get("runs")
    if not isinstance(runs, list) or not all(isinstance(r, dict) and "scenario" in r for r in runs):
        raise ConfigError(str(folder / "runs.json"), "expected the runs a dataset keeps")
    there = list(dict.fromkeys(r["scenario"] for r in runs))
    ctrls = {r.get("controller") for r in runs}
    if LIMIT not in ctrls:
        raise ConfigError(f"{folder} view=limit", "no run of limit in runs.json: make it with --limit")
    scenarios = opts["scenarios"].split(",") if "scenarios" in opts else there
    controllers = opts["controllers"].split(",") if "controllers" in opts else []
    missing = [s for s in scenarios if s not in there] + [c for c in controllers if c not in ctrls]
    if missing:
        raise ConfigError(f"{folder} view=limit", f"{', '.join(missing)} not in the data")
    table = limit_table(runs, scenarios, controllers)
    if "labels" in opts:
        labels = opts["labels"].split(",")
        if len(labels) != len(scenarios):
            raise ConfigError(str(folder), f"labels: {len(labels)} given for {len(scenarios)} scenarios {scenarios}")
        for scn, label in zip(scenarios, labels, strict=True):
            table = table.replace(f"| {scn} |", f"| {label} |", 1)
    return table


def _bound(folder: Path, bound: str, rows: list[dict]) -> list[dict]:
    """``rows`` with the median ratio to ``bound`` on the same seed (``x_bound_median``), from the
    data's runs.json; a ConfigError naming the option where no run of it is there."""
    from mlpfac.sweeps.paired import bound_ratios

    runs = read_json(folder, "runs.json").get("runs")
    there = {r.get("controller") for r in runs if isinstance(r, dict)} if isinstance(runs, list) else set()
    if bound not in there:
        raise ConfigError(f"{folder} bound={bound}", f"no run of {bound} in runs.json ({', '.join(sorted(there))})")
    ratios = bound_ratios(runs, bound)
    return [r | {"x_bound_median": ratios.get((r["scenario"], r["controller"]))} for r in rows]


def untold(rows: list[dict]) -> str:
    """Each law told the change against itself told nothing: the median over seeds of the per-seed
    ratio of their position RMS (``x_untold_median`` of paired.json), where both ran."""
    lines = ["| scenario | told | x itself untold |", "| --- | --- | ---: |"]
    lines += [
        f"| {r['scenario']} | {r['controller']} | {r['x_untold_median']:.2f} |"
        for r in rows
        if isinstance(r.get("x_untold_median"), float)
    ]
    return "\n".join(lines) + "\n"


def rewrite(page: Path) -> tuple[str, int]:
    """The page's text with every marked table written from its data, and the number of tables."""
    try:
        text = page.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(str(page), f"cannot read this page ({getattr(err, 'strerror', None) or err})") from None
    count = 0

    def table(m: re.Match) -> str:
        nonlocal count
        count += 1
        path, opts = parse_spec(m["spec"], str(page))
        try:
            body = render(page.parent / path, opts)
        except (TypeError, ValueError, KeyError, AttributeError, IndexError) as err:
            if isinstance(err, ConfigError):
                raise
            raise ConfigError(
                str(page.parent / path), f"its data are not what a sweep writes ({type(err).__name__}: {err})"
            ) from None
        return f"<!-- table: {m['spec']} -->\n\n{body}\n<!-- /table -->"  # blank lines: a table block

    new = MARKER.sub(table, text)
    matched = {text.count("\n", 0, m.start()) for m in MARKER.finditer(text)}
    for i, line in enumerate(text.splitlines()):
        if line.startswith("<!-- table:") and i not in matched:
            raise ConfigError(f"{page}:{i + 1}", "a table marker without its closing <!-- /table --> line")
    return new, count


def pages(docs: Path) -> list[Path]:
    """The Markdown pages of a docs folder (not the data folders)."""
    if not docs.is_dir():
        raise ConfigError(str(docs), "not a folder of Markdown pages")
    return sorted(docs.glob("*.md"))


def stale(docs: Path) -> list[Path]:
    """The pages whose tables differ from what their data gives."""
    return [p for p in pages(docs) if rewrite(p)[0] != p.read_text()]


def write(docs: Path) -> list[tuple[Path, int, bool]]:
    """Rewrite every page's tables; (page, tables, changed) for each page that has tables."""
    done = []
    for p in pages(docs):
        text, n = rewrite(p)
        if n:
            changed = text != p.read_text()
            if changed:
                try:
                    write_atomic(p, text)
                except OSError as err:
                    raise ConfigError(str(p), f"cannot write ({err.strerror or err}); the page is as it was") from None
            done.append((p, n, changed))
    return done


def code_version(rev: str = "HEAD") -> str:
    """The commit ``rev`` names in the checkout in the current folder, its whole SHA: HEAD's, or
    "unknown" outside a checkout; a given one must name a commit here or be a whole SHA."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}"], capture_output=True, text=True, check=True
        )
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        pass
    if rev == "HEAD":
        return "unknown"
    if re.fullmatch(r"[0-9a-f]{40}", rev):
        return rev
    raise ConfigError("--code-version", f"{rev!r} names no commit of this checkout: give one, or its whole SHA")


def machine() -> str:
    """The machine collecting a dataset: its processor and cores (a benchmark's timings are this
    machine's; a run's bits depend on it only as docs/reproducibility.md says)."""
    import os
    import platform

    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        lines = []
    cpu = next((line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")), None)
    return f"{cpu or platform.processor() or platform.machine()}, {os.cpu_count()} CPUs"


def collect(folder: Path, results: Path, command: str | None = None, version: str | None = None) -> Path:
    """Copy a finished results folder (or a script's printed table, a file) into a data folder and
    write its meta.json: the command (kept from the earlier meta.json unless given), the code
    version and the date the results were written."""
    old = folder / "meta.json"
    meta = read_json(folder, "meta.json") if old.is_file() else {}
    command = command or meta.get("command")
    if not command:
        raise ConfigError("--command", f"{folder} has no meta.json yet: give the command that made {results}")
    version = code_version(version or "HEAD")
    runs = None
    if results.is_file():  # a printed Markdown table (a .md file), else a command's printed output
        sources = {"table.md" if results.suffix == ".md" else "output.txt": results}
    else:
        sources = {n: results / n for n in DATA_FILES if (results / n).is_file()}
        if "paired.json" not in sources:
            raise ConfigError(str(results), "not a finished results folder of `mlpfac sweep` or `mlpfac compare`")
        from mlpfac.report.verify import RUNS_FILE, per_seed

        runs = per_seed(results)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for name, src in sources.items():
            write_atomic(folder / name, src.read_bytes())
        if runs:  # every run's figures, one line each
            lines = ",\n".join(json.dumps(r, separators=(",", ":")) for r in runs)
            write_atomic(folder / RUNS_FILE, f'{{"runs": [\n{lines}\n]}}\n')
        elif runs is not None and (folder / RUNS_FILE).is_file():  # they were of other results
            (folder / RUNS_FILE).unlink()
        for name in {"table.md", "output.txt"} - set(sources):  # a script's text of another kind, before
            if results.is_file() and (folder / name).is_file():
                (folder / name).unlink()
        made = max(src.stat().st_mtime for src in sources.values())
    except OSError as err:
        raise ConfigError(str(err.filename or folder), f"cannot copy the results ({err.strerror or err})") from None
    meta = {
        "command": command,
        "code_version": version,
        "date": datetime.fromtimestamp(made, UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "machine": machine(),
    }
    try:
        write_atomic(old, json.dumps(meta, indent=2) + "\n")
    except OSError as err:
        raise ConfigError(str(old), f"cannot write ({err.strerror or err})") from None
    return folder


def _collect_item(item: str) -> tuple[str, str]:
    """(NAME, RESULTS) of ``--collect NAME=RESULTS``; NAME is one folder's name inside DOCS/data."""
    name, sep, results = item.partition("=")
    if not (sep and name and results):
        raise ConfigError("--collect", f"expected NAME=RESULTS, got {item!r}")
    if not DATA_NAME.fullmatch(name):  # not a path: ../x, a/b, . or /abs would write outside DOCS/data
        raise ConfigError(f"--collect {item}", f"NAME is one data folder's name (letters, digits, - _ .), got {name!r}")
    return name, results
