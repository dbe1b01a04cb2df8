"""A check's reports: one line per miss, JUnit XML for a CI page, a Markdown summary."""

from __future__ import annotations

import os
import shlex
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from mlpfac.checks.judge import Case, Verdict
from mlpfac.checks.limits import FIGURES


def rerun(case: Case, seed: int, duration: float | None) -> str:
    """The command that runs one seed of the case's group again, alone."""
    g = case.group
    argv = ["mlpfac", "run", g.source, "--controller", g.spec or g.controller, "--seed", str(seed)]
    if duration is not None:
        argv += ["--duration", f"{duration:g}"]
    return shlex.join(argv)


def _num(x: float | None, figure: str) -> str:
    if x is None:
        return "-"
    if FIGURES[figure].count:
        return f"{int(x)}"
    return f"{x:.3g}" if figure == "p" else f"{x:.2f}" if abs(x) < 1e4 else f"{x:.3g}"


def limit_text(v: Verdict) -> str:
    return f"{'>=' if FIGURES[v.figure].at_least else '<='} {_num(v.limit, v.figure)}"


def title(case: Case) -> str:
    """The group and phase: ``scenario / controller / phase``."""
    return f"{case.group.scenario} / {case.group.controller} / {case.limit.phase}"


def miss_lines(case: Case, duration: float | None) -> list[str]:
    """One line per miss: where, the figure, its value and limit, the worst seed and how to re-run it."""
    lines = []
    for v in case.misses:
        value = _num(v.value, v.figure) + (f" ({v.note})" if v.note else "")
        line = f"miss: {title(case)}: {v.figure} {value}, limit {limit_text(v)}"
        if v.worst_seed is not None:
            line += f"; worst seed {v.worst_seed}: {rerun(case, v.worst_seed, duration)}"
        lines.append(line)
    if case.missing:
        lines.append(f"note: {title(case)}: the baseline has no run of seeds {_seeds(case.missing)}; left out")
    for seed in case.errors:
        lines.append(
            f"miss: {title(case)}: the run of seed {seed} raised (see its error.txt): {rerun(case, seed, duration)}"
        )
    return lines


def _seeds(seeds: list[int]) -> str:
    return ", ".join(map(str, seeds))


def junit(cases: list[Case], suite: str, duration: float | None) -> bytes:
    """JUnit XML: one testsuite, one testcase per limit and run group, one ``failure`` per failing
    case listing each miss (the schema GitHub, GitLab and Jenkins read)."""
    failures = sum(not c.passed for c in cases)
    total = sum(c.time_s for c in cases)
    root = ET.Element("testsuites", name="mlpfac check", tests=str(len(cases)), failures=str(failures), errors="0")
    root.set("time", f"{total:.3f}")
    ts = ET.SubElement(root, "testsuite", name=suite, tests=str(len(cases)), failures=str(failures))
    ts.set("errors", "0")
    ts.set("skipped", "0")
    ts.set("time", f"{total:.3f}")
    ts.set("timestamp", time.strftime("%Y-%m-%dT%H:%M:%S"))
    for c in cases:
        name = f"{c.group.controller} / {c.limit.phase}: " + (c.limit.name or f"budget #{c.limit.index}")
        tc = ET.SubElement(ts, "testcase", classname=f"{suite}.{c.group.scenario}", name=name, time=f"{c.time_s:.3f}")
        lines = miss_lines(c, duration)
        if not c.passed:
            message = "; ".join(
                [f"{v.figure} {_num(v.value, v.figure)}, limit {limit_text(v)}" for v in c.misses]
                + [f"seed {s} raised" for s in c.errors]
            )
            failure = ET.SubElement(tc, "failure", message=message, type="BudgetMiss")
            failure.text = "\n".join(lines) + "\n"
        out = ET.SubElement(tc, "system-out")
        out.text = (
            "\n".join(_verdict_text(v) for v in c.verdicts)
            + "\n"
            + "".join(f"{x}\n" for x in lines if x.startswith("note"))
        )
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"


def _verdict_text(v: Verdict) -> str:
    state = "pass" if v.passed else "MISS"
    base = f", baseline {_num(v.baseline, v.figure)}" if v.baseline is not None else ""
    return f"{state} {v.figure} {_num(v.value, v.figure)} (limit {limit_text(v)}{base})" + (
        f" [{v.note}]" if v.note else ""
    )


def _vs(v: Verdict) -> str:
    if FIGURES[v.figure].baseline:
        return v.note or "-"
    if v.baseline is None:
        return "-"
    ratio = (
        f" (x{v.value / v.baseline:.2f})" if v.value is not None and v.baseline and not FIGURES[v.figure].count else ""
    )
    return _num(v.baseline, v.figure) + ratio


def summary(cases: list[Case], budget: Path, plots: list[Path], where: Path, baseline: Path | None) -> str:
    """The Markdown summary: the verdict, one table row per figure of each case, the misses, the plots
    (linked from ``where``, the summary's folder)."""
    misses = sum(len(c.misses) + len(c.errors) for c in cases)
    held = sum(c.passed for c in cases)
    head = f"## mlpfac check: {'pass' if held == len(cases) else 'MISS'}\n\n"
    head += (
        f"`{budget}`: {held} of {len(cases)} budget cases (budget x scenario x controller) hold"
        + (f", {misses} misses" if misses else "")
        + "."
    )
    head += f" Baseline: `{baseline}`.\n\n" if baseline is not None else "\n\n"
    rows = ["| | scenario | controller | phase | figure | limit | value | vs baseline | worst seed |", "|---" * 9 + "|"]
    for c in cases:
        for v in c.verdicts:
            mark = "pass" if v.passed else "**MISS**"
            worst = "-" if v.worst_seed is None else str(v.worst_seed)
            rows.append(
                f"| {mark} | {c.group.scenario} | {c.group.controller} | {c.limit.phase} | {v.figure} "
                f"| {limit_text(v)} | {_num(v.value, v.figure)} | {_vs(v)} | {worst} |"
            )
        if c.errors:
            rows.append(
                f"| **MISS** | {c.group.scenario} | {c.group.controller} | {c.limit.phase} | runs that raised | 0 | {len(c.errors)} | - | {c.errors[0]} |"
            )
    notes = [f"- {line}" for c in cases for line in miss_lines(c, None) if line.startswith("note")]
    text = head + "\n".join(rows) + "\n" + ("\n" + "\n".join(notes) + "\n" if notes else "")
    text += (
        "\nFigures over the runs after the warm-up in the phase named (whole: the run after the warm-up), "
        "position and heading over the runs that finished; limits are at most, p at least.\n"
    )
    for p in plots:
        text += f"\n![{p.stem}]({Path(os.path.relpath(p, where)).as_posix()})\n"
    return text
