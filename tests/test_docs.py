"""The docs: every results table is what its data gives, and every relative link and image resolves."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from mlpfac.cli import main
from mlpfac.exceptions import ConfigError
from mlpfac.report import figures
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
    (above its table), and a table shows the folder or a page names it as the source of its figures
    (the folder, or a file in it)."""
    pages = figures.pages(DOCS)
    prose = " ".join(" ".join(p.read_text().replace("\\\n", " ") for p in pages).split())
    shown = {report.parse_spec(m["spec"], p.name)[0] for p in pages for m in report.MARKER.finditer(p.read_text())}
    named = {
        "/".join(Path(source).parts[-2:] if (p.parent / source).is_dir() else Path(source).parts[-3:-1])
        for p in pages
        for part in figures.parts(p.read_text(), p.name)
        for source in part.sources
    }
    folders = sorted(p for p in (DOCS / "data").iterdir() if p.is_dir())
    assert len(folders) >= 6
    for folder in folders:
        meta = json.loads((folder / "meta.json").read_text())
        assert re.fullmatch(r"[0-9a-f]{40}", meta["code_version"]), folder.name
        assert re.fullmatch(DATE, meta["date"]), folder.name
        if not folder.name.startswith(("bench-", "history-")):  # a record: its page as written (development.md)
            assert " ".join(meta["command"].split()) in prose, f"{folder.name}: its command is in no page"
        assert f"data/{folder.name}" in shown | named, f"{folder.name}: no table shows it, no page names it"


def test_every_figure_of_the_docs_is_in_its_sources():
    """Every number of every page (README.md and docs/*.md) is printed by its sources, rounded to
    its digits: the data of the page's tables, the sources its ``figures:`` markers name, or the
    output of a ``sh cheap`` block shown below it (mlpfac/report/figures.py)."""
    assert figures.check(DOCS) == []
    pages = [p.name for p in figures.pages(DOCS)]
    assert "README.md" in pages and "scenarios.md" in pages and "robots.md" in pages


# (page, a figure as the page writes it, the same figure drifted): each page's figure from its own
# source; the drifted ones are the figures these pages gave before the code moved them.
DRIFTS = [
    ("scenarios.md", "by 49 mm, as it lags", "by 66 mm, as it lags", ["66"]),  # data/route
    ("robots.md", "12.99 mm with `servo_limit", "18.93 mm with `servo_limit", ["18.93"]),  # data/servo-limit
    ("robots.md", "| 3.31, 3.38, 3.51 mm |", "| 4.46, 3.38, 3.51 mm |", ["4.46"]),  # data/dual-payload/runs.json
    ("README.md", "(3.53 mm median after the change)", "(3.55 mm median after the change)", ["3.55"]),
    ("results-beyond.md", "", "\nAfter the sensor delay: 15.02 mm, and 0.83 mm nominal.\n", ["15.02"]),
]


@pytest.mark.parametrize(("name", "figure", "drifted", "failing"), DRIFTS)
def test_a_figure_that_drifts_from_its_source_fails(name: str, figure: str, drifted: str, failing: list[str]):
    """The check fails on a copy of the page with one figure changed, naming its line and the figure."""
    page = ROOT / name if name == "README.md" else DOCS / name
    text = page.read_text()
    assert figure in text and figures.unsupported(page) == []
    bad = figures.unsupported(page, text.replace(figure, drifted, 1) if figure else text + drifted)
    assert [n for f, _ in bad for n in f.numbers] == failing
    assert bad[0][0].line == (text[: text.index(figure)].count("\n") + 1 if figure else text.count("\n") + 2)


def test_report_check_fails_on_a_drifted_figure_and_names_it(tmp_path: Path, capsys):
    """`mlpfac report DOCS --check` on a copy of a results page whose prose says 83.9 mm where its data say 73.9."""
    docs = _copy(tmp_path)
    page = docs / "results-dynamics.md"
    assert main(["report", str(docs), "--check"]) == 0
    text = page.read_text()
    page.write_text(text.replace("73.9 mm median on the nominal", "83.9 mm median on the nominal"))
    assert main(["report", str(docs), "--check"]) == 1
    line = text[: text.index("73.9 mm median")].count("\n") + 1
    err = capsys.readouterr().err
    assert f"results-dynamics.md:{line}: 83.9 is in none of its sources" in err, err


# What counts as a figure, and where: known answers.
FIGURE_CASES = {
    "a decimal, a whole number with its unit, a count": (
        "RMS 1.34 mm of 66 mm, in 8 of 12 runs.",
        ["1.34", "66", "8", "12"],
    ),
    "a sentence's end, a ratio, a percent": ("It is 4.86. Then 73x, and 16% or 5 %.", ["4.86", "73", "16", "5"]),
    "not a bare integer, a version, a year, a seed": ("seeds 0-4, numpy 2.4.6, in 2004, Results 7", []),
    "a number in groups of three": ("at most 100 000 runs, a 2,000-run map, (1, 2)", ["100000", "2000"]),
    "not in code or links": ('`T = 0.01` and [x](a-1.5.md) <img src="b-2.5.png">', []),
    "not in a command, but in printed output": ("```sh\nrun --duration 2.5\n```\n\n```\nrms 0.25 m\n```\n", ["0.25"]),
    "not in a given phrase": ('<!-- figures: "at 12.5 s" -->\nat 12.5 s, then 12.5 s', ["12.5"]),
}


@pytest.mark.parametrize("case", FIGURE_CASES)
def test_what_a_figure_is(case: str):
    text, numbers = FIGURE_CASES[case]
    assert [n for _, f in figures.figures(text) for n in f.numbers] == numbers


def test_a_figure_matches_its_source_rounded_to_its_digits():
    keys = figures.printed("| 1.345 | 0.0013421 | 121.84 | 2.5 | 0.05 |")
    assert all(keys.shows(x) for x in ("1.34", "1.35", "1.3", "1", "1.3421", "1.342", "122", "121.8", "2.5"))
    assert not any(keys.shows(x) for x in ("1.36", "1.3450", "2.50", "1.4", "121.9", "0.00135", "5"))
    assert keys.shows("5", percent=True) and not keys.shows("6", percent=True)


def test_a_given_phrase_no_longer_on_its_part_fails_and_a_bad_marker_is_bad_input(tmp_path: Path):
    page = tmp_path / "p.md"
    page.write_text('<!-- figures: "at 12.5 s" -->\nnothing here\n')
    assert [why for _, why in figures.unsupported(page)] == ["a given phrase no longer on its part of the page"]
    page.write_text("<!-- figures: data/nosuch -->\n1.5 mm\n")
    with pytest.raises(ConfigError, match="neither a data folder nor a file"):
        figures.unsupported(page)


def test_a_figures_marker_naming_no_such_source_is_one_line_and_exit_2(tmp_path: Path, capsys):
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "page.md").write_text("# A page\n\n<!-- figures: data/nosuch -->\n\n1.5 mm\n")
    assert main(["report", str(docs), "--check"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "page.md:3: figures marker: data/nosuch is neither" in err, err


def test_a_part_takes_its_own_sources(tmp_path: Path):
    (tmp_path / "a.txt").write_text("rms 0.0252 m\n")
    page = tmp_path / "p.md"
    page.write_text(
        "25.2 mm\n\n<!-- figures: a.txt -->\n25.2 mm, 25 mm, 0.025 m\n\n<!-- figures: b.toml -->\n25.2 mm\n"
    )
    (tmp_path / "b.toml").write_text("x = 1\n")
    assert [(f.line, f.numbers) for f, _ in figures.unsupported(page)] == [(1, ("25.2",)), (7, ("25.2",))]


SHOWN = {
    "the same lines": ("tracking 0.0013421", "tracking 0.0013421\n", True),
    "an ellipsis for any text": ("tracking 0.00134...", "noise\ntracking 0.0013421 m\nend\n", True),
    "a figure that differs": ("tracking 0.00139...", "tracking 0.0013421\n", False),
    "lines out of order": ("b\na", "a\nb\n", False),
}


@pytest.mark.parametrize("case", SHOWN)
def test_a_shown_output_matches_what_the_command_printed(case: str):
    shown, printed, ok = SHOWN[case]
    assert figures.matches(shown, printed) is ok


def _copy(tmp_path: Path) -> Path:
    docs = tmp_path / "docs"
    (docs / "data").mkdir(parents=True)
    for name in ("compare", "ablation"):  # the data results-dynamics.md's tables and figures come from
        shutil.copytree(DOCS / "data" / name, docs / "data" / name)
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
    report.collect(target, results, version="a1" * 20)
    meta = json.loads((target / "meta.json").read_text())
    assert meta["command"] == before["command"] and meta["code_version"] == "a1" * 20
    assert re.fullmatch(DATE, meta["date"])
    with pytest.raises(ConfigError, match="--code-version: 'abc123' names no commit"):  # a short SHA of nothing
        report.collect(target, results, version="abc123")
    with pytest.raises(ConfigError, match="--command"):
        report.collect(docs / "data" / "new", results)
    with pytest.raises(ConfigError, match="not a finished results folder"):
        report.collect(target, tmp_path, command="x")
    script = tmp_path / "table.md"
    script.write_text("| a |\n|---|\n| 1 |\n")
    report.collect(docs / "data" / "script", script, command="python script.py")
    assert report.render(docs / "data" / "script", {"view": "text"}) == script.read_text()


def _dataset(docs: Path, name: str, command: str, **files: str) -> Path:
    folder = docs / "data" / name
    folder.mkdir(parents=True)
    meta = {"command": command, "code_version": "0" * 40, "date": "2026-01-01T00:00:00Z"}
    (folder / "meta.json").write_text(json.dumps(meta))
    for file, text in files.items():
        (folder / file.replace("_", ".")).write_text(text)
    return folder


def test_a_commands_printed_output_is_run_again_by_verify_and_a_record_is_not(tmp_path: Path, capsys):
    docs = tmp_path / "docs"
    _dataset(docs, "printed", "python -c 'print(1.5); print(2)'", output_txt="1.5\n2\n")
    _dataset(docs, "bench-timing", "python -c 'import sys; sys.exit(3)'", output_txt="3.2 s\n")
    _dataset(docs, "history-tried", "python -c 'import sys; sys.exit(3)'", output_txt="9 mm\n")
    assert main(["report", str(docs), "--verify", "2", "--strict"]) == 0
    out = capsys.readouterr().out
    assert "printed: its printed output as recorded" in out
    assert "bench-timing: not verified: a benchmark's timings, a record" in out
    assert "history-tried: not verified: figures of earlier code" in out
    (docs / "data" / "printed" / "output.txt").write_text("1.5\n3\n")
    assert main(["report", str(docs), "--verify", "2"]) == 1
    assert "printed: its printed output differs: line 2: 2" in capsys.readouterr().out


def test_collect_keeps_a_printed_output_beside_a_table_and_stamps_the_machine(tmp_path: Path):
    docs = tmp_path / "docs"
    printed = tmp_path / "out.txt"
    printed.write_text("robot: 1.09 m\n")
    folder = report.collect(docs / "data" / "lines", printed, command="mlpfac run x | head -1")
    assert (folder / "output.txt").read_text() == printed.read_text() and not (folder / "table.md").exists()
    assert json.loads((folder / "meta.json").read_text())["machine"].endswith("CPUs")
    table = tmp_path / "t.md"
    table.write_text("| a |\n|---|\n| 1 |\n")
    report.collect(folder, table)  # the same dataset, now a table: the output it held is gone
    assert (folder / "table.md").is_file() and not (folder / "output.txt").exists()


def test_remake_runs_each_recorded_command_again_and_refuses_to_resume_a_sweep(tmp_path: Path, capsys):
    docs = tmp_path / "docs"
    sweep = "mlpfac compare paper --controllers corradini --seeds 0 --duration 1 --workers 1 --out runs/tiny"
    _dataset(docs, "tiny", sweep)
    _dataset(docs, "lines", "python -c 'print(0.25)'", output_txt="0.5\n")
    _dataset(docs, "bench-timing", "python -c 'import sys; sys.exit(3)'", output_txt="3.2 s\n")
    assert main(["report", str(docs), "--remake"]) == 0
    assert (docs / "data" / "lines" / "output.txt").read_text() == "0.25\n"
    assert (docs / "data" / "tiny" / "runs.json").is_file()
    assert (docs / "data" / "bench-timing" / "output.txt").read_text() == "3.2 s\n"  # a record: not made
    assert main(["report", str(docs), "--remake", "tiny"]) == 1  # runs/tiny is there: a sweep would resume it
    assert "runs/tiny: exists" in capsys.readouterr().err
    assert main(["report", str(docs), "--remake", "nosuch"]) == 2


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
    for name in ("sims", "models", "examples", "benchmarks", "mlpfac", "tests"):
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


def _ids(cases):
    return [f"{p.relative_to(ROOT).as_posix()}:{b.strip().splitlines()[0][:50]}" for p, b in cases]


def _cheap(page: Path, body: str, shown: str | None):
    """A ``sh cheap`` block (and the output the page shows it printing), marked ``menagerie``
    where it names a MuJoCo Menagerie robot."""
    marks = [pytest.mark.menagerie] if MENAGERIE.search(body) else []
    return pytest.param(page, body, shown, marks=marks, id=_ids([(page, body)])[0])


MENAGERIE = re.compile(r"pal_tiago|hello_robot_stretch|rby1|tiago-")
CHEAP = [
    _cheap(page, body, {c: out for c, out, *_ in figures.cheap_outputs(page.read_text())}.get(body))
    for page in PAGES
    for info, body in fenced(page, "sh")
    if info == "cheap"
]
WRITTEN = "<!-- Written by `python -m mlpfac.pages"  # the reference pages: signatures, not snippets
SNIPPETS = [
    (page, body)
    for page in PAGES
    if WRITTEN not in page.read_text()
    for _, body in fenced(page, "python")
    if body.strip() and not DEFINES.match(body)
]


def test_there_are_cheap_commands_and_snippets_to_run():
    assert len(CHEAP) >= 3 and len(SNIPPETS) >= 3 and "my_law.py" in _files()


@pytest.mark.parametrize(("page", "block", "shown"), CHEAP)
def test_every_cheap_command_block_runs_as_written(tmp_path: Path, page: Path, block: str, shown: str | None):
    """Each runs, and prints what the page shows it printing (the block of output below it)."""
    import subprocess

    work, env = _workspace(tmp_path)
    for name, text in _files().items():
        (work / name).write_text(text)
    r = subprocess.run(
        ["bash", "-eo", "pipefail", "-c", block],
        cwd=work,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,  # as a terminal shows them
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, f"{page.name}: {block}\noutput: {r.stdout[-3000:]}"
    if shown is not None:
        assert figures.matches(shown, r.stdout), f"{page.name}: {block}\nshown:\n{shown}\nprinted:\n{r.stdout[-3000:]}"


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
        "`period`, `std`, `std_mg` (a force is periodic or noise, not both)",  # a rule between parameters
        "`tau_s` needs `std` or `std_mg`",
        "| `height` | number | required | [0.001, 0.5] | m, of its flat top |",
        "| `wavelength` | number | required | [0.01, 10] | m between crests |",
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
