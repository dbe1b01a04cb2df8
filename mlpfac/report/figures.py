"""Every figure of the docs traced to where it comes from: ``mlpfac report docs --check``.

A page's figures are the numbers of its prose, of its hand-written tables and of the printed
output it shows (a fenced block with no language, or ``text``): every decimal, every whole number
with a unit (``66 mm``, ``73x``, ``16%``, ``1200 runs``) and every count (``8 of 12``). Not its
commands, code, scenario files or link targets (what a reader types), nor the tables written from
data (:mod:`mlpfac.report.results`). Each figure, rounded to the digits the page gives it, is

- printed by the data a marked table on the page shows (``<!-- table: data/NAME ... -->``), or
- printed by a source named for its part of the page, from a marker to the next one (a marker
  naming nothing, ``<!-- figures: -->``, ends a part)::

      <!-- figures: data/route-robots ../sims/*.toml "2.9° slopes" -->

  a data folder (every view of its tables, the limit view where it ran ``limit``, its count of runs, the text a command printed:
  ``table.md``, ``output.txt``) or a file (a dataset's ``runs.json``: every run's figures; a
  scenario, a robot's model, a module: its settings as written), each path from the page's folder,
  ``*`` for any name; a number printed in m or s counts in mm or ms too, a percentage may be a
  fraction; a phrase in quotes is given as it is (a setting of a model outside the repository, a
  quotation, a figure derived in words), and must stay on its part of the page; or
- shown as the output of a ``sh cheap`` command block right above it, which ``tests/test_docs.py``
  runs and compares (:func:`matches`), in the same part of the page.

A figure that is none of these fails the check, naming the page, the line and the figure. A page
written from the code (:mod:`mlpfac.pages`) is checked against the code instead.
"""

from __future__ import annotations

import bisect
import functools
import operator
import re
from dataclasses import dataclass, field
from decimal import ROUND_HALF_EVEN, ROUND_HALF_UP, Decimal
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
    r"(?<![\w.,])(?P<t>\d{1,3}(?:[ ,]\d{3})+)(?![\w.]|,\d)"  # a whole number in groups of three: 100 000, 2,000
    r"|(?<![\w.])(?P<a>\d+) of (?P<b>\d+)(?![\w.])"  # a count
    r"|(?<![\w.])(?P<d>\d+\.\d+(?:e[-+]?\d+)?|\d+e[-+]?\d+)(?!\w|\.\d)"  # a decimal
    rf"|(?<![\w.])(?P<u>\d+)(?=\s?(?:{UNITS})(?!\w))"  # a whole number with its unit
)
NUMBER = re.compile(r"\d+(?:_\d{3})*(?:\.\d+)?(?:e[-+]?\d+)?")  # in a source: any number (100_000 in code)
PERCENT = re.compile(r"\s?%")
GROUPED = re.compile(r"(?<![\w.,])\d{1,3}(?:[ ,]\d{3})+(?![\w.]|,\d)")  # in a source: 2,000
SCALE = 3  # a number printed in m or s counts in mm or ms (x 10^3)
WRITTEN = "<!-- Written by `python -m mlpfac.pages"  # a page written from the code (mlpfac.pages)


@dataclass(frozen=True)
class Figure:
    """A figure of a page: its line (from 1), the numbers as written and the line's text; a
    percentage is a source's fraction too (5 % of 0.05)."""

    line: int
    numbers: tuple[str, ...]
    text: str
    percent: bool = False
    written: str = ""  # the figure as the page writes it (8 of 12, 2,000)


@dataclass
class Part:
    """A part of a page, from a ``figures:`` marker (or the page's start) to the next one."""

    start: int  # offset in the page's text
    end: int
    line: int
    sources: list[str] = field(default_factory=list)
    given: list[str] = field(default_factory=list)


def parts(text: str, where: str) -> list[Part]:
    """The page cut at its ``figures:`` markers (not those quoted in code), each part with its
    sources and given phrases."""
    out = [Part(0, len(text), 1)]
    uncoded = text
    for pattern in (FENCE, CODE):
        for m in pattern.finditer(uncoded):
            uncoded = _blank(uncoded, m.start(), m.end())
    for m in MARK.finditer(uncoded):
        out[-1].end = m.start()
        part = Part(m.end(), len(text), text.count("\n", 0, m.start()) + 1)
        for w in WORD.finditer(text[m.start("spec") : m.end("spec")]):
            (part.given if w["phrase"] is not None else part.sources).append(w["phrase"] or w["path"])
        out.append(part)  # (naming nothing: from here, the page's tables alone)
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
        numbers = (m["a"], m["b"]) if m["a"] else (m["d"] or m["u"] or re.sub("[ ,]", "", m["t"]),)
        line = plain.count("\n", 0, m.start()) + 1
        percent = PERCENT.match(plain, m.end()) is not None
        out.append((m.start(), Figure(line, numbers, lines[line - 1].strip(), percent, m[0])))
    return out


class Printed:
    """The numbers a source prints (each as written, and x 10^3), sorted: a page's figure is one of
    them rounded to its digits (:meth:`shows`), found by bisection."""

    def __init__(self, numbers: list[tuple[Decimal, int]]) -> None:
        self.numbers = sorted(numbers)
        self.values = [v for v, _ in self.numbers]

    @classmethod
    def of(cls, text: str) -> Printed:
        out = []
        grouped = [re.sub("[ ,]", "", g) for g in GROUPED.findall(text)]  # 2,000 and 100 000 as one number
        for n in NUMBER.findall(text) + grouped:
            try:
                exact = Decimal(n.replace("_", ""))
                for value in (exact, exact.scaleb(SCALE)):
                    if isinstance(value.as_tuple().exponent, int) and abs(value.adjusted()) <= 30:
                        out.append((value, value.as_tuple().exponent))
            except ArithmeticError:  # (InvalidOperation, Overflow): no number a page writes
                continue
        return cls(out)

    def __or__(self, other: Printed) -> Printed:
        return Sources([self, other])

    def shows(self, number: str, percent: bool = False) -> bool:
        """``number`` (as a page writes it) is a number printed here rounded to its digits, half up
        or half even, the printed one with at least as many (a percentage: or its fraction)."""
        for value in (Decimal(number), Decimal(number).scaleb(-2)) if percent else (Decimal(number),):
            e = value.as_tuple().exponent
            q = Decimal(1).scaleb(e)
            half = Decimal(5).scaleb(e - 1)
            lo = bisect.bisect_left(self.values, value - half)
            hi = bisect.bisect_right(self.values, value + half)
            for v, ev in self.numbers[lo:hi]:
                if ev <= e and value in (v.quantize(q, ROUND_HALF_UP), v.quantize(q, ROUND_HALF_EVEN)):
                    return True
        return False


class Sources(Printed):
    """Several sources: a figure is shown when one of them shows it (none copied or sorted again)."""

    def __init__(self, parts: list[Printed]) -> None:
        self.parts = [q for p in parts for q in (p.parts if isinstance(p, Sources) else [p])]

    def shows(self, number: str, percent: bool = False) -> bool:
        return any(p.shows(number, percent) for p in self.parts)


NOTHING = Printed([])


@functools.cache
def printed(text: str) -> Printed:
    """What a page may quote of a source's text: every number in it."""
    return Printed.of(text)


@functools.cache
def _folder_text(folder: Path, stamp: tuple) -> str:
    """Every view of a data folder's tables, and the text kept in it, as one text."""
    from mlpfac.report.data import read_json
    from mlpfac.report.limit import LIMIT, MPC
    from mlpfac.report.results import render

    files = {
        "sweep": "sweep.json",
        "compare": "compare.json",
        "paired": "paired.json",
        "robustness": "robustness.json",
        "text": "table.md",
    }
    views = [v for v, f in files.items() if (folder / f).is_file()]
    texts = [render(folder, {"view": v}) for v in views + (["summary", "untold"] if "paired" in views else [])]
    if (folder / "output.txt").is_file():
        texts.append((folder / "output.txt").read_text())
    if (folder / "runs.json").is_file():  # every controller against the limit, where the data has it
        runs = read_json(folder, "runs.json").get("runs") or []
        ctrls = list(dict.fromkeys(r.get("controller") for r in runs if isinstance(r, dict)))
        if LIMIT in ctrls:
            others = ",".join(c for c in ctrls if c not in (LIMIT, MPC))
            texts.append(render(folder, {"view": "limit"} | ({"controllers": others} if others else {})))
    for name in ("sweep.json", "compare.json"):  # how many runs the command made
        if (folder / name).is_file():
            runs = (read_json(folder, name).get("meta") or {}).get("runs")
            texts.append(f"{runs} runs" if isinstance(runs, int) else "")
    return "\n".join(texts)


@functools.cache
def _file_text(path: Path, stamp: tuple) -> str:
    return path.read_text()


def source_keys(page: Path, source: str, where: str) -> Printed:
    """The numbers a source, named from ``page``'s folder, prints."""
    path = page.parent / source
    if "*" in source:  # files by a pattern: the shipped scenarios, the robots
        found = sorted(f for f in page.parent.glob(source) if f.is_file())
        if not found:
            raise ConfigError(where, f"figures marker: {source} names no file")
        try:
            return printed("\n".join(_file_text(f.resolve(), (f.stat().st_mtime_ns,)) for f in found))
        except (OSError, UnicodeDecodeError) as err:
            raise ConfigError(
                f"{where} {source}", f"cannot read it ({getattr(err, 'strerror', None) or err})"
            ) from None
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
    tables = functools.reduce(
        operator.or_,
        (source_keys(page, parse_spec(m["spec"], str(page))[0], str(page)) for m in MARKER.finditer(text)),
        NOTHING,
    )
    outputs = cheap_outputs(text)
    found = figures(text, pairs)
    bad = []
    for part in pairs:
        where = f"{page}:{part.line}"
        keys = functools.reduce(operator.or_, (source_keys(page, s, where) for s in part.sources), tables)
        keys = functools.reduce(
            operator.or_, (printed(out) for _, out, start, _ in outputs if part.start <= start < part.end), keys
        )
        for phrase in part.given:
            if phrase not in text[part.start : part.end]:
                bad.append((Figure(part.line, (), phrase), "a given phrase no longer on its part of the page"))
        names = ", ".join(part.sources) or "none but the page's tables"
        for f in (f for at, f in found if part.start <= at < part.end):
            if any(not keys.shows(n, f.percent) for n in f.numbers):
                bad.append((f, f"{f.written} is in none of its sources ({names})"))
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
