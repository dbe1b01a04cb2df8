"""Every figure of the docs traced to where it comes from: ``mlpfac report docs --check``.

A page's figures are the numbers of its prose, of its hand-written tables and of the printed
output it shows (a fenced block with no language, or ``text``): every decimal, every whole number
with a unit (``66 mm``, ``73x``, ``16%``, ``1200 runs``) and every count (``8 of 12``). Not its
commands, code, scenario files or link targets (what a reader types), nor the tables written from
data (:mod:`mlpfac.report.results`). Each figure, rounded to the digits the page gives it, is

- printed by the data a marked table on the page shows (``<!-- table: data/NAME ... -->``), or
- printed by a source named for its part of the page, from a marker to the next one::

      <!-- figures: data/route-robots ../sims/route.toml "2.9° slopes" -->

  a data folder (every view of its tables, the text a command printed: ``table.md``,
  ``output.txt``) or a file (a dataset's ``runs.json``: every run's figures; a scenario, a robot's
  model, a module: its settings as written), each path from the page's folder (``*`` for any
  name: ``../sims/*.toml``); a number printed in m or s counts in mm
  or ms too; a phrase in quotes is given as it is (a setting, a quotation, a figure derived in
  words), and must stay on its part of the page; or
- shown as the output of a ``sh cheap`` command block right above it, which ``tests/test_docs.py``
  runs and compares (:func:`matches`), in the same part of the page.

A page whose figure is none of these fails the check, naming the page, the line and the figure.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from decimal import ROUND_HALF_EVEN, ROUND_HALF_UP, Decimal
from functools import cache
from pathlib import Path

from mlpfac.exceptions import ConfigError

MARK = re.compile(r"<!-- figures:(?P<spec>.*?)-->", re.S)
WORD = re.compile(r'"(?P<phrase>[^"]*)"|(?P<path>[^\s"]+)')
COMMENT = re.compile(r"<!--.*?-->", re.S)
FENCE = re.compile(r"^```(?P<info>[^\n`]*)\n(?P<body>.*?)^```[ \t]*$", re.M | re.S)
OUTPUT = ("", "text")  # a fenced block of printed output; any other language is what a reader types
CODE = re.compile(r"`[^`\n]*`")
TARGET = re.compile(r"\]\([^)]*\)|<[^>\n]*>")  # a link's target, an HTML tag
UNITS = r"mm|cm|m|km|ms|µs|us|ns|s|min|h|x|×|%|Hz|kHz|N|kg|mrad|rad|GiB|MiB|KiB|GB|MB|kB|runs"
FIGURE = re.compile(
    r"(?<![\w.])(?P<a>\d+) of (?P<b>\d+)(?![\w.])"  # a count
    r"|(?<![\w.])(?P<d>\d+\.\d+(?:e[-+]?\d+)?|\d+e[-+]?\d+)(?!\w|\.\d)"  # a decimal
    rf"|(?<![\w.])(?P<u>\d+)(?=\s?(?:{UNITS})(?!\w))"  # a whole number with its unit
)
NUMBER = re.compile(r"\d+(?:\.\d+)?(?:e[-+]?\d+)?")  # in a source: any number
SCALE = 3  # a number printed in m or s counts in mm or ms (x 10^3)
WRITTEN = "<!-- Written by `python -m mlpfac.pages"  # a page written from the code (mlpfac.pages)


@dataclass(frozen=True)
class Figure:
    """A figure of a page: its line (from 1), the numbers as written and the line's text."""

    line: int
    numbers: tuple[str, ...]
    text: str


@dataclass
class Part:
    """A part of a page, from a ``figures:`` marker (or the page's start) to the next one."""

    start: int  # offset in the page's text
    end: int
    line: int
    sources: list[str] = field(default_factory=list)
    given: list[str] = field(default_factory=list)


def parts(text: str, where: str) -> list[Part]:
    """The page cut at its ``figures:`` markers, each part with its sources and given phrases."""
    out = [Part(0, len(text), 1)]
    for m in MARK.finditer(text):
        out[-1].end = m.start()
        part = Part(m.end(), len(text), text.count("\n", 0, m.start()) + 1)
        for w in WORD.finditer(m["spec"]):
            (part.given if w["phrase"] is not None else part.sources).append(w["phrase"] or w["path"])
        if not part.sources and not part.given:
            raise ConfigError(f"{where}:{part.line}", "a figures marker names no source")
        out.append(part)
    return out


def _blank(text: str, start: int, end: int) -> str:
    """``text`` with [start, end) blanked, its line breaks kept (so lines keep their numbers)."""
    return text[:start] + re.sub(r"[^\n]", " ", text[start:end]) + text[end:]


def cheap_outputs(text: str) -> list[tuple[str, str, int, int]]:
    """(command, output, start, end) of every ``sh cheap`` block followed (blank lines between) by
    a block of printed output: the output the command prints, compared by ``tests/test_docs.py``."""
    blocks = list(FENCE.finditer(text))
    out = []
    for a, b in zip(blocks, blocks[1:], strict=False):
        if (
            a["info"].split() == ["sh", "cheap"]
            and b["info"].strip() in OUTPUT
            and not text[a.end() : b.start()].strip()
        ):
            out.append((a["body"], b["body"], b.start(), b.end()))
    return out


def masked(text: str, pairs: list[Part]) -> str:
    """The page with everything that holds no figure blanked: the tables written from data, HTML
    comments, code blocks, code spans, link targets and tags, checked outputs, given phrases."""
    from mlpfac.report.results import MARKER

    for m in [*MARKER.finditer(text), *COMMENT.finditer(text)]:
        text = _blank(text, m.start(), m.end())
    checked = {start for _, _, start, _ in cheap_outputs(text)}
    for m in FENCE.finditer(text):
        if m["info"].strip() in OUTPUT and m.start() not in checked:
            text = _blank(text, m.start(), m.start("body"))  # the fences, not the output
            text = _blank(text, m.end("body"), m.end())
        else:
            text = _blank(text, m.start(), m.end())
    for pattern in (CODE, TARGET):
        for m in pattern.finditer(text):
            text = _blank(text, m.start(), m.end())
    for part in pairs:
        for phrase in part.given:
            at = text.find(phrase, part.start, part.end)
            while at >= 0:
                text = _blank(text, at, at + len(phrase))
                at = text.find(phrase, at + len(phrase), part.end)
    return text


def figures(text: str, pairs: list[Part] | None = None) -> list[tuple[int, Figure]]:
    """The figures of a page, in order, each with its offset in the text."""
    plain = masked(text, parts(text, "page") if pairs is None else pairs)
    lines = text.splitlines()
    out = []
    for m in FIGURE.finditer(plain):
        numbers = (m["a"], m["b"]) if m["a"] else (m["d"] or m["u"],)
        line = plain.count("\n", 0, m.start()) + 1
        out.append((m.start(), Figure(line, numbers, lines[line - 1].strip())))
    return out


def _keys(number: str) -> set[tuple[int, Decimal]]:
    """Every way a page may write ``number`` (as it is, or x 10^3): (exponent, value) rounded to
    each exponent from its own up to 0, half up or half even."""
    try:
        exact = Decimal(number)
        both = (exact, exact.scaleb(SCALE))
    except ArithmeticError:  # (InvalidOperation, Overflow)
        return set()
    out = set()
    for value in both:
        low = value.as_tuple().exponent
        if not isinstance(low, int):
            continue
        for e in range(low, max(low, 0) + 1):
            q = Decimal(1).scaleb(e)
            out |= {(e, value.quantize(q, mode)) for mode in (ROUND_HALF_UP, ROUND_HALF_EVEN)}
    return out


def printed(text: str) -> frozenset[tuple[int, Decimal]]:
    """What a page may quote of a source's text: every number in it, as :func:`_keys` writes it."""
    return frozenset(k for n in NUMBER.findall(text) for k in _keys(n))


def shown(number: str, keys: frozenset[tuple[int, Decimal]]) -> bool:
    """``number`` (as a page writes it) is a number of the source rounded to its digits."""
    value = Decimal(number)
    return (value.as_tuple().exponent, value) in keys


@cache
def _folder_text(folder: Path, stamp: tuple) -> str:
    """Every view of a data folder's tables, and the text kept in it, as one text."""
    from mlpfac.report.results import render

    files = {
        "sweep": "sweep.json",
        "compare": "compare.json",
        "paired": "paired.json",
        "robustness": "robustness.json",
        "text": "table.md",
    }
    views = [v for v, f in files.items() if (folder / f).is_file()]
    texts = [render(folder, {"view": v}) for v in views + (["summary"] if "paired" in views else [])]
    if (folder / "output.txt").is_file():
        texts.append((folder / "output.txt").read_text())
    return "\n".join(texts)


@cache
def _file_text(path: Path, stamp: tuple) -> str:
    return path.read_text()


def source_keys(page: Path, source: str, where: str) -> frozenset[tuple[int, Decimal]]:
    """The numbers a source, named from ``page``'s folder, prints."""
    path = page.parent / source
    if "*" in source:  # files by a pattern: the shipped scenarios, the robots
        found = sorted(page.parent.glob(source))
        if not found:
            raise ConfigError(where, f"figures marker: {source} names no file")
        return frozenset().union(*(source_keys(page, str(f.relative_to(page.parent)), where) for f in found))
    try:
        stamp = tuple(sorted((f.name, f.stat().st_mtime_ns) for f in path.iterdir())) if path.is_dir() else ()
        if path.is_dir():
            return printed(_folder_text(path.resolve(), stamp))
        if path.is_file():
            return printed(_file_text(path.resolve(), (path.stat().st_mtime_ns,)))
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{where} {source}", f"cannot read it ({getattr(err, 'strerror', None) or err})") from None
    raise ConfigError(where, f"figures marker: {source} is neither a data folder nor a file ({path})")


def unsupported(page: Path, text: str | None = None) -> list[tuple[Figure, str]]:
    """Every figure of ``page`` (its text, or ``text`` in its place) that none of its sources
    prints, and every given phrase no longer on its part: (figure, why), in the page's order."""
    from mlpfac.report.results import MARKER, parse_spec

    text = page.read_text() if text is None else text
    if WRITTEN in text:  # written from the code, and checked against it (tests/test_docs.py)
        return []
    pairs = parts(text, str(page))
    tables = frozenset().union(
        *(source_keys(page, parse_spec(m["spec"], str(page))[0], str(page)) for m in MARKER.finditer(text))
    )
    outputs = cheap_outputs(text)
    found = figures(text, pairs)
    bad = []
    for part in pairs:
        where = f"{page}:{part.line}"
        keys = tables.union(*(source_keys(page, s, where) for s in part.sources))
        keys |= frozenset().union(*(printed(out) for _, out, start, _ in outputs if part.start <= start < part.end))
        for phrase in part.given:
            if phrase not in text[part.start : part.end]:
                bad.append((Figure(part.line, (), phrase), "a given phrase no longer on its part of the page"))
        names = ", ".join(part.sources) or "none but the page's tables"
        for f in (f for at, f in found if part.start <= at < part.end):
            missing = [n for n in f.numbers if not shown(n, keys)]
            if missing:
                bad.append((f, f"{' and '.join(missing)} is in none of its sources ({names})"))
    return bad


def pages(docs: Path) -> list[Path]:
    """The pages whose figures are checked: ``DOCS/*.md`` and the README above the folder."""
    from mlpfac.report.results import pages as docs_pages

    readme = docs.parent / "README.md"
    return docs_pages(docs) + ([readme] if readme.is_file() else [])


def check(docs: Path) -> list[str]:
    """One line per figure of the pages that its sources do not give."""
    return [f"{p}:{f.line}: {why}: {f.text[:160]}" for p in pages(docs) for f, why in unsupported(p)]


def sources(docs: Path) -> str:
    """Every page, each part of it with its sources and its count of figures: what
    ``mlpfac report docs --sources`` prints."""
    from mlpfac.report.results import MARKER, parse_spec

    out = []
    for page in pages(docs):
        text = page.read_text()
        if WRITTEN in text:
            out.append(f"{page}: written from the code (python -m mlpfac.pages docs --check)")
            continue
        tables = sorted({parse_spec(m["spec"], str(page))[0] for m in MARKER.finditer(text)})
        pairs = parts(text, str(page))
        found = figures(text, pairs)
        checked = sum(1 for _, out_, start, _ in cheap_outputs(text))
        out.append(
            f"{page}: {len(found)} figures; tables from {', '.join(tables) or 'no data'}"
            + (f"; {checked} outputs of sh cheap blocks, compared by tests/test_docs.py" if checked else "")
        )
        for part in pairs:
            n = sum(part.start <= at < part.end for at, _ in found)
            if part.sources or part.given:
                given = f", {len(part.given)} given phrases" if part.given else ""
                out.append(f"  line {part.line}: {n} figures from {', '.join(part.sources) or 'the tables'}{given}")
    return "\n".join(out) + "\n"


def matches(shown_text: str, output: str) -> bool:
    """The output a page shows is what the command printed: its lines in order among the printed
    ones, each in full, where ``...`` stands for any text."""
    want = [line.rstrip() for line in shown_text.strip("\n").splitlines()]
    got = iter(line.rstrip() for line in output.splitlines())
    for line in want:
        pattern = re.compile(".*".join(re.escape(p) for p in line.split("...")))
        if not any(pattern.fullmatch(g) for g in got):
            return False
    return True
