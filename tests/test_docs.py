"""The docs: every results table is what its data gives, and every relative link and image resolves."""

from __future__ import annotations

import json
import re
import shutil
from decimal import ROUND_HALF_EVEN, ROUND_HALF_UP, Decimal
from pathlib import Path

import pytest

from mlpfac.cli import main
from mlpfac.exceptions import ConfigError
from mlpfac.report import results as report

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", ROOT / "models" / "README.md", *sorted(DOCS.glob("*.md"))]
# Pages written by other work, linked from here before they land. Each is allowed to be missing;
# once it exists it is checked like any other, and its name must leave this set.
AWAITED: set[str] = set()

LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HTML = re.compile(r"<(?:img|a)\b[^>]*?\b(?:src|href)=\"([^\"]+)\"", re.I)
FENCE = re.compile(r"^(```|~~~).*?^\1\s*$", re.M | re.S)
CODE = re.compile(r"`[^`\n]*`")
DATE = r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ"


def _prose(text: str) -> str:
    """The text without fenced code blocks (links there are not links)."""
    return FENCE.sub("", text)


def links(page: Path) -> list[str]:
    text = CODE.sub("code", _prose(page.read_text()))  # nor in code spans
    return LINK.findall(text) + HTML.findall(text)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: markup dropped, lower case, punctuation out, spaces to hyphens."""
    h = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", re.sub(r"<[^>]+>", "", heading))
    return re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for m in re.finditer(r"^#{1,6}\s+(.+?)\s*#*\s*$", _prose(page.read_text()), re.M):
        s = slug(m[1])
        out.add(f"{s}-{seen[s]}" if s in seen else s)
        seen[s] = seen.get(s, 0) + 1
    return out


def broken(page: Path) -> list[str]:
    bad = []
    for target in dict.fromkeys(links(page)):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):  # https:, mailto: ...
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        rel = dest.relative_to(ROOT).as_posix() if dest.is_relative_to(ROOT) else str(dest)
        if not dest.exists():
            if rel not in AWAITED:
                bad.append(f"{target} (no {rel})")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target} (no heading #{anchor} in {rel})")
    return bad


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_and_image_resolves(page: Path):
    assert not broken(page), f"{page.relative_to(ROOT)}: {broken(page)}"


def test_awaited_pages_are_still_awaited():
    landed = sorted(p for p in AWAITED if (ROOT / p).exists())
    assert not landed, f"{landed} exist now: remove them from AWAITED in tests/test_docs.py"


def test_the_link_check_finds_a_broken_link_and_anchor(tmp_path: Path):
    (tmp_path / "b.md").write_text("# A heading, (with) `code`\n\n## Twice\n\n## Twice\n")
    page = tmp_path / "a.md"
    page.write_text(
        "[ok](b.md#a-heading-with-code) [ok](b.md#twice-1) ![ok](b.md) `[not a link](x.md)`\n"
        '```\n[not a link](y.md)\n```\n[gone](c.md) [bad](b.md#nowhere) <img src="d.png"> [web](https://x.org/e)\n'
    )
    assert broken(page) == [
        f"c.md (no {tmp_path / 'c.md'})",
        f"b.md#nowhere (no heading #nowhere in {tmp_path / 'b.md'})",
        f"d.png (no {tmp_path / 'd.png'})",
    ]


def test_every_table_in_the_docs_is_what_its_data_gives():
    tables = sum(report.rewrite(p)[1] for p in report.pages(DOCS))
    assert tables >= 8, f"only {tables} marked tables in docs/"
    assert [p.name for p in report.stale(DOCS)] == []
    assert main(["report", str(DOCS), "--check"]) == 0


def test_every_data_folder_says_how_it_was_made_and_is_shown():
    """meta.json holds the command, the code version and the date; the command is written in a page
    (above its table) and a table shows the folder."""
    prose = " ".join(" ".join(p.read_text().replace("\\\n", " ") for p in report.pages(DOCS)).split())
    shown = {
        report.parse_spec(m["spec"], p.name)[0]
        for p in report.pages(DOCS)
        for m in report.MARKER.finditer(p.read_text())
    }
    folders = sorted(p for p in (DOCS / "data").iterdir() if p.is_dir())
    assert len(folders) >= 6
    for folder in folders:
        meta = json.loads((folder / "meta.json").read_text())
        assert re.fullmatch(r"[0-9a-f]{40}", meta["code_version"]), folder.name
        assert re.fullmatch(DATE, meta["date"]), folder.name
        assert " ".join(meta["command"].split()) in prose, f"{folder.name}: its command is in no page"
        assert f"data/{folder.name}" in shown, f"{folder.name}: no table shows it"


NUMBER = re.compile(r"(?<![\w.])\d+\.\d+(?![\w.])")
# The phrases of these pages' prose whose numbers are no figure of their data, each with its number
# in its context (the same number elsewhere on the page is checked): the robot's settings, single
# runs' figures from their series, and figures measured elsewhere that the prose quotes.
NOT_DATA = {
    "results-beyond.md": (
        "1200 runs: 394.5 s of wall time",  # the command's wall time
        "(23.64 against 23.22 mm)",  # seeds 2 and 7 after the delay, in runs.json but in no table
        "23.05 and 23.64 mm, is that of Corradini's law, 23.21 and 23.22",
    ),
    "results-paper.md": (
        "at 12.5 s of 25 s",  # the paper's experiment: its event's time and its duration
        "0.05 s (2 to 5 control steps)",  # paper-faithful's diverged runs: 2-5 steps (paper-table runs.json)
        "by T = 0.01 s",  # the sampling period
        "with λ = 0.8 the closed-loop poles",  # the eigenvalues set, the paper's and the defaults'
        "move from 0.8 to",
        "takes λ1..3 = 0.8,",
        "| P0 | 0.1 I |",  # the defaults' settings (sims/paper.toml)
        "| eigenvalues | 0.8 |",
    ),
    "results-torque.md": (
        "16.6 kg), PAL TIAGo",  # the robots' and the events' settings
        "at 12.5 s that changes",
        "(3 kg, 0.05 m ahead of the axle and 0.08 m to its left)",
        "the nominal model's 2.52)",  # what a run says under its outcome (the nominal dynamic model)
        "of 2.52 between them",
        "(a run says 0.0885 N m of them at 1x)",
    ),
    "results-tiago.md": (
        "±5 rad/s (0.49 m/s)",  # the wheels' limit and the eight's speeds
        "0.11-0.36 m/s, at most 3.6 rad/s per wheel",
        "kv ×0.25 with the torque limit",  # the event's setting
        "480 runs: 285.9 s of wall time",  # the command's wall time
        "(seed 7, 0.21 m RMS after the",  # adaptive's lost run (runs.json, in m)
        "tracks to 0.30 mm",  # `mlpfac run` of a copy of tiago-nominal.toml without pose noise
    ),
}


def _printed(page: Path) -> set[str]:
    """Every number that any view of the data folders shown on the page prints."""
    out: set[str] = set()
    for m in report.MARKER.finditer(page.read_text()):
        folder = page.parent / report.parse_spec(m["spec"], page.name)[0]
        files = {"sweep": "sweep.json", "compare": "compare.json", "paired": "paired.json", "text": "table.md"}
        views = [v for v, f in files.items() if (folder / f).is_file()]
        for view in views + (["summary"] if "paired" in views else []):
            out |= set(NUMBER.findall(report.render(folder, {"view": view})))
    return out


def unsupported(page: Path, text: str, allowed: tuple[str, ...]) -> list[str]:
    """The numbers of the prose (not its tables, code or link targets) that are neither a number the
    page's data print, rounded to the prose's digits, nor in an allowed phrase."""
    prose = re.sub(r"\]\([^)]*\)", "]", CODE.sub(" ", report.MARKER.sub(" ", _prose(text))))
    for phrase in allowed:
        prose = prose.replace(phrase, " ")
    printed = _printed(page)

    def shown(x: str) -> bool:  # a printed figure rounded to the prose's digits, either way at a tie
        digits = len(x.split(".")[1])
        q = Decimal(1).scaleb(-digits)
        return any(
            len(f.split(".")[1]) >= digits
            and x in (str(Decimal(f).quantize(q, h)) for h in (ROUND_HALF_UP, ROUND_HALF_EVEN))
            for f in printed
        )

    return [x for x in NUMBER.findall(prose) if not shown(x)]


@pytest.mark.parametrize("name", sorted(NOT_DATA))
def test_every_number_in_the_results_prose_is_its_data(name: str):
    page = DOCS / name
    assert unsupported(page, page.read_text(), NOT_DATA[name]) == []
    assert [p for p in NOT_DATA[name] if p not in page.read_text()] == [], "allowed phrases the page no longer has"


def test_a_stale_number_in_the_prose_fails():
    """15.02 mm: the sensor delay's median of adaptive-input-delay on another machine's data."""
    page = DOCS / "results-beyond.md"
    text = page.read_text() + "\nAfter the sensor delay: 15.02 mm, and 0.83 mm nominal.\n"
    assert unsupported(page, text, NOT_DATA[page.name]) == ["15.02"]


def _copy(tmp_path: Path) -> Path:
    docs = tmp_path / "docs"
    (docs / "data").mkdir(parents=True)
    shutil.copytree(DOCS / "data" / "compare", docs / "data" / "compare")
    shutil.copy(DOCS / "results-dynamics.md", docs)
    return docs


def test_a_table_that_differs_from_its_data_fails_and_report_writes_it_again(tmp_path: Path, capsys):
    docs = _copy(tmp_path)
    page = docs / "results-dynamics.md"
    good = page.read_text()
    row = next(line for line in good.splitlines() if line.startswith("| eight-nominal | corradini |"))
    page.write_text(good.replace(row, row.replace(" | 10 / 0 / 0 |", " | 9 / 1 / 0 |")))
    assert report.stale(docs) == [page]
    assert main(["report", str(docs), "--check"]) == 1
    assert main(["report", str(docs)]) == 0
    assert page.read_text() == good and report.stale(docs) == []
    assert "1 tables, written" in capsys.readouterr().out


def test_views_and_options(tmp_path: Path):
    folder = _copy(tmp_path) / "data" / "compare"
    rows = report.render(folder, {"view": "compare", "scenarios": "eight-payload,paper", "controllers": "kanayama"})
    assert [line.split(" | ")[:3] for line in rows.splitlines()[2:]] == [
        ["| eight-payload", "kanayama", "before"],
        ["| eight-payload", "kanayama", "after"],
        ["| paper", "kanayama", "before"],
        ["| paper", "kanayama", "after"],
    ]
    head = report.render(folder, {"scenarios": "eight-payload,paper", "labels": "payload ×3,kinematic"})
    assert head.splitlines()[0] == "| controller | payload ×3 | kinematic |"
    with pytest.raises(ConfigError, match="labels: 1 given for 2 scenarios"):
        report.render(folder, {"scenarios": "eight-payload,paper", "labels": "one"})
    with pytest.raises(ConfigError, match="view must be one of"):
        report.parse_spec("data/compare view=plot", "page.md")
    with pytest.raises(ConfigError, match="missing"):
        report.render(folder, {"view": "sweep"})


def test_a_summary_divides_by_the_bound_it_names_or_by_none():
    """``bound=none``: the medians alone (no law of the table is a bound); ``bound=NAME``: the median
    ratio to that law on the same seed, from runs.json (with the oracle, the same as x oracle)."""
    from mlpfac.sweeps.paired import bound_ratios

    folder = DOCS / "data" / "world-torque"
    plain = report.render(folder, {"bound": "none", "scenarios": "eight-ramp+tug"})
    assert "x)" not in plain and "| `oracle` | 1.50 |" in plain, plain
    told = report.render(folder, {"bound": "oracle-dynamic", "scenarios": "eight-ramp+tug"})
    assert "| `oracle-dynamic` | 1.10 |" in told and "| `corradini` | 1.50 (1.3x) |" in told, told
    runs = json.loads((folder / "runs.json").read_text())["runs"]
    rows = json.loads((folder / "paired.json").read_text())["rows"]
    ratios = bound_ratios(runs, "oracle")
    assert all(ratios[(r["scenario"], r["controller"])] == r["x_oracle_median"] for r in rows)
    with pytest.raises(ConfigError, match="bound=nosuch: no run of nosuch"):
        report.render(folder, {"bound": "nosuch"})


def test_collect_keeps_the_command_and_stamps_the_version_and_date(tmp_path: Path):
    docs = _copy(tmp_path)
    results = tmp_path / "runs" / "compare"
    results.mkdir(parents=True)
    for name in ("compare.json", "paired.json"):
        shutil.copy(docs / "data" / "compare" / name, results)
    target = docs / "data" / "compare"
    before = json.loads((target / "meta.json").read_text())
    report.collect(target, results, version="abc123")
    meta = json.loads((target / "meta.json").read_text())
    assert meta["command"] == before["command"] and meta["code_version"] == "abc123"
    assert re.fullmatch(DATE, meta["date"])
    with pytest.raises(ConfigError, match="--command"):
        report.collect(docs / "data" / "new", results)
    with pytest.raises(ConfigError, match="not a finished results folder"):
        report.collect(target, tmp_path, command="x")
    script = tmp_path / "table.out"
    script.write_text("| a |\n|---|\n| 1 |\n")
    report.collect(docs / "data" / "script", script, command="python script.py")
    assert report.render(docs / "data" / "script", {"view": "text"}) == script.read_text()


# name: (what to break in a copy of the docs, text the one line holds)
BAD_DATA = {
    "meta.json not JSON": (lambda d: (d / "data" / "compare" / "meta.json").write_text("{"), "not valid JSON"),
    "compare.json not JSON": (lambda d: (d / "data" / "compare" / "compare.json").write_text("[1,"), "not valid JSON"),
    "compare.json no rows": (lambda d: (d / "data" / "compare" / "compare.json").write_text("{}"), "expected the rows"),
    "marker with an open quote": (
        lambda d: (d / "results-dynamics.md").write_text(
            '<!-- table: data/compare view="compare -->\n<!-- /table -->\n'
        ),
        "No closing quotation",
    ),
    "marker naming no such controller": (
        lambda d: (d / "results-dynamics.md").write_text(
            "<!-- table: data/compare view=compare controllers=nosuch -->\n<!-- /table -->\n"
        ),
        "nosuch not in the data",
    ),
}


@pytest.mark.parametrize("case", BAD_DATA)
def test_bad_data_or_markers_are_one_line_and_exit_2(tmp_path: Path, capsys, case):
    docs = _copy(tmp_path)
    breaks, text = BAD_DATA[case]
    breaks(docs)
    argv = ["report", str(docs)]
    if case.startswith("meta.json"):
        argv += ["--collect", f"compare={docs / 'data' / 'compare'}"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and text in err and "Traceback" not in err, err


# The pages' commands and snippets, run as written. A command block fenced as ```sh cheap``` runs
# in a shell where the venv is active (its bin first on PATH, as `. .venv/bin/activate` leaves it)
# from a copy of the repository's top folder; every ```python``` block runs there too, after the
# files the pages define (a block whose first line is `# NAME.py`) are written beside it. A snippet
# runs as a notebook cell does (the code given to a fresh interpreter), each page's in order.
FENCED = re.compile(r"^```(\w*)([^\n]*)\n(.*?)^```\s*$", re.M | re.S)
DEFINES = re.compile(r"\A# (\w+\.py)\n")


def fenced(page: Path, lang: str) -> list[tuple[str, str]]:
    """(info, body) of the page's fenced blocks in ``lang`` (``sh cheap``: info "cheap")."""
    return [(info.strip(), body) for tag, info, body in FENCED.findall(page.read_text()) if tag == lang]


def _workspace(tmp_path: Path) -> tuple[Path, dict]:
    """A folder like the repository's top (sims, models, examples, benchmarks linked; docs copied, so
    a command that writes there cannot touch the repository), and the environment of an active venv."""
    import os
    import sys

    work = tmp_path / "repo"
    work.mkdir()
    for name in ("sims", "models", "examples", "benchmarks", "mlpfac"):
        (work / name).symlink_to(ROOT / name)
    shutil.copytree(DOCS, work / "docs")
    shutil.copy(ROOT / "README.md", work)
    env = dict(os.environ)
    venv = Path(sys.executable).parent
    env["PATH"] = f"{venv}{os.pathsep}{env.get('PATH', '')}"
    env["VIRTUAL_ENV"] = str(venv.parent)
    env.pop("PYTHONPATH", None)
    return work, env


def _files() -> dict[str, str]:
    """NAME.py -> its text, for every python block of the pages that starts with ``# NAME.py``."""
    out: dict[str, str] = {}
    for page in PAGES:
        for _, body in fenced(page, "python"):
            m = DEFINES.match(body)
            if m:
                out.setdefault(m[1], body)
    return out


CHEAP = [(page, body) for page in PAGES for info, body in fenced(page, "sh") if info == "cheap"]
WRITTEN = "<!-- Written by `python -m mlpfac.pages"  # the reference pages: signatures, not snippets
SNIPPETS = [
    (page, body)
    for page in PAGES
    if WRITTEN not in page.read_text()
    for _, body in fenced(page, "python")
    if body.strip() and not DEFINES.match(body)
]


def _ids(cases):
    return [f"{p.relative_to(ROOT).as_posix()}:{b.strip().splitlines()[0][:50]}" for p, b in cases]


def test_there_are_cheap_commands_and_snippets_to_run():
    assert len(CHEAP) >= 3 and len(SNIPPETS) >= 3 and "my_law.py" in _files()


@pytest.mark.parametrize(("page", "block"), CHEAP, ids=_ids(CHEAP))
def test_every_cheap_command_block_runs_as_written(tmp_path: Path, page: Path, block: str):
    import subprocess

    work, env = _workspace(tmp_path)
    for name, text in _files().items():
        (work / name).write_text(text)
    r = subprocess.run(
        ["bash", "-eo", "pipefail", "-c", block], cwd=work, env=env, capture_output=True, text=True, timeout=600
    )
    assert r.returncode == 0, f"{page.name}: {block}\nstdout: {r.stdout[-2000:]}\nstderr: {r.stderr[-2000:]}"


OUTPUT = re.compile(r"^<!-- output: (?P<cmd>.+?) -->\n```\n(?P<body>.*?)^```$", re.M | re.S)
OUTPUTS = [(page, m["cmd"], m["body"]) for page in PAGES for m in OUTPUT.finditer(page.read_text())]


def test_there_is_a_printed_output_to_compare():
    assert any(cmd.startswith("mlpfac run ") for _, cmd, _ in OUTPUTS)


@pytest.mark.parametrize(("page", "command", "shown"), OUTPUTS, ids=[f"{p.name}:{c[:60]}" for p, c, _ in OUTPUTS])
def test_every_printed_output_on_a_page_is_what_its_command_prints(tmp_path: Path, page: Path, command: str, shown):
    """A block marked ``<!-- output: COMMAND -->`` is what COMMAND prints, line for line (the wall
    time a run took aside)."""
    import subprocess

    work, env = _workspace(tmp_path)
    r = subprocess.run(["bash", "-c", command], cwd=work, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr

    def steady(text: str) -> list[str]:
        return [re.sub(r"in \d+\.\d+ s wall", "in - s wall", line) for line in text.splitlines()]

    assert steady(r.stdout) == steady(shown), f"{page.name}: {command}\n{r.stdout}"


@pytest.mark.slow
@pytest.mark.parametrize(("page", "snippet"), SNIPPETS, ids=_ids(SNIPPETS))
def test_every_python_snippet_runs_as_written(tmp_path: Path, page: Path, snippet: str):
    import subprocess
    import sys

    work, env = _workspace(tmp_path)
    for name, text in _files().items():
        (work / name).write_text(text)
    code = f"import sys; sys.path.insert(0, ''); exec(compile({snippet!r}, 'snippet', 'exec'))"
    r = subprocess.run([sys.executable, "-c", code], cwd=work, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, f"{page.name}:\n{snippet}\nstdout: {r.stdout[-2000:]}\nstderr: {r.stderr[-3000:]}"


def test_the_readmes_budget_is_the_shipped_example():
    shown = [body for _, body in fenced(ROOT / "README.md", "toml") if "[[budget]]" in body]
    text = (ROOT / "examples" / "budget.toml").read_text()
    assert shown and shown[0] == text[text.index("scenarios =") :]


def test_no_page_or_script_points_outside_the_repository():
    """A user's clone has only the repository: no page, benchmark or example names a folder beside it."""
    files = [*PAGES, *sorted((ROOT / "benchmarks").glob("*.py")), *sorted((ROOT / "examples").iterdir())]
    bad = [
        f.relative_to(ROOT).as_posix() for f in files if f.is_file() and re.search(r"\.\./shared|/work/", f.read_text())
    ]
    assert bad == []


def test_the_pages_written_from_the_code_are_what_the_code_gives(tmp_path: Path, capsys):
    from mlpfac.pages import doc_pages

    assert doc_pages.stale(DOCS) == [], "run: python -m mlpfac.pages docs"
    docs = tmp_path / "docs"
    docs.mkdir()
    assert doc_pages.main([str(docs), "--check"]) == 1  # missing: stale
    assert doc_pages.main([str(docs)]) == 0 and doc_pages.stale(docs) == []
    page = docs / "scenario-file.md"
    page.write_text(page.read_text().replace("| (0, 1] |", "| > 0 |", 1))
    assert doc_pages.main([str(docs), "--check"]) == 1 and "scenario-file.md" in capsys.readouterr().out


@pytest.mark.parametrize("foreign", ["a file of someone else's", "a folder"])
def test_the_page_writer_replaces_only_its_own_pages(tmp_path: Path, capsys, foreign: str):
    from mlpfac.pages import doc_pages

    docs = tmp_path / "docs"
    docs.mkdir()
    if foreign == "a folder":
        (docs / "api.md").mkdir()
    else:
        (docs / "api.md").write_text("# my own notes\n")
    assert doc_pages.main([str(docs)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "api.md" in err and "Traceback" not in err
    assert (docs / "api.md").is_dir() if foreign == "a folder" else (docs / "api.md").read_text() == "# my own notes\n"
    assert not (docs / "scenario-file.md").exists()  # nothing written


def test_the_scenario_reference_gives_the_validators_ranges():
    """Known answers, probed from the validators: a new or changed check shows on the page by itself."""
    text = (DOCS / "scenario-file.md").read_text()
    for row in (
        "| `forgetting` | number | 1 | (0, 1] |",
        "| `input_delay` | integer | 0 | 0-50 |",
        "| `lambdas` | 3 numbers | [0.9, 0.9, 0.9] | (-1, 1) |",
        "| `v_max` | number | 2 | > 0; `inf`: no limit |",
        "| `T` | s | 0.01 | > 0 |",
        "| `estimator` | string | \"ekf\" | choose 'ekf' or 'ukf' |",
        "| `sensor_delay` | `steps` (integer >= 0) |",
    ):
        assert row in text, row


def _fields(page: str, name: str) -> set[str]:
    block = re.search(rf"<!-- fields: {name} -->(.*?)<!-- /fields -->", (DOCS / page).read_text(), re.S)
    assert block, name
    return {f for cell in re.findall(r"^\| ([^|]+) \|", block[1], re.M) for f in re.findall(r"`(\w+)`", cell)}


@pytest.mark.slow
def test_the_outputs_page_names_every_field_the_code_writes():
    import mlpfac

    rows = mlpfac.sweep(["paper"], ["corradini", "oracle"], seeds="0-1", duration=13.0, workers=1)
    m = mlpfac.metrics(mlpfac.run("paper", controller="corradini", duration=13.0))
    # and the fields of a pose that was estimated (pose_source), only there
    est = mlpfac.metrics(mlpfac.run("eight-wheel-radius-fused", controller="kanayama", duration=3.0))
    est_rows = mlpfac.sweep(["eight-wheel-radius-fused"], ["kanayama"], seeds="0", duration=3.0, workers=1)
    assert _fields("outputs.md", "metrics") == set(m) | set(est) and "estimate" in est
    assert _fields("outputs.md", "sweep") == set(rows[0]) | set(est_rows[0]) and "est_rms_m_median" in est_rows[0]
    assert _fields("outputs.md", "paired") == set(rows.paired[0]) | set(est_rows.paired[0])
