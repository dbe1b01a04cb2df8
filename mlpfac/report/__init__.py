"""``mlpfac report``: the results pages' tables written from the data kept beside them
(:mod:`~mlpfac.report.results`), every other figure of the pages checked against its sources
(:mod:`~mlpfac.report.figures`, ``--check``), that data run again bit for bit
(:mod:`~mlpfac.report.verify`, ``--verify N``) and made again from its recorded commands
(:mod:`~mlpfac.report.remake`, ``--remake``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mlpfac.exceptions import ConfigError
from mlpfac.flags import needs, not_with
from mlpfac.io.targets import cli_path


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of ``mlpfac report`` (here, so that the command line's parser imports none of
    the report's code)."""
    p.description = (
        "Write every marked table of DOCS/*.md from the data folder it names (mlpfac/report/results.py); "
        "--check also checks every figure of the pages against its sources (mlpfac/report/figures.py)."
    )
    p.add_argument("docs", nargs="?", type=cli_path, default=Path("docs"), help="the folder of pages (default docs)")
    p.add_argument("--check", action="store_true", help="write nothing; exit 1 if a table differs from its data")
    p.add_argument(
        "--collect",
        action="append",
        default=[],
        metavar="NAME=RESULTS",
        help="first copy a finished results folder (or a script's printed table) into DOCS/data/NAME",
    )
    p.add_argument(
        "--command",
        dest="made_by",
        metavar="COMMAND",
        help="with one --collect: the command that made it (default: the one on record)",
    )
    p.add_argument("--code-version", metavar="SHA", help="with --collect: the code that ran it (default: HEAD)")
    p.add_argument(
        "--verify",
        type=int,
        nargs="?",
        const=3,
        metavar="N",
        help="run N (default 3) sampled runs of every dataset again from its recorded command; exit 1 if one differs",
    )
    p.add_argument(
        "--strict", action="store_true", help="with --verify: a dataset that cannot run here (its robot) is an error"
    )
    p.add_argument(
        "--remake",
        nargs="?",
        const="",
        metavar="NAMES",
        help="make the datasets named (a,b; default every one but the bench-* timings) again from their "
        "recorded commands, then write the tables",
    )
    p.add_argument(
        "--sources", action="store_true", help="list every page's parts, their sources and their count of figures"
    )
    needs(p, "--strict", "--verify")
    needs(p, "--command", "--collect")
    needs(p, "--code-version", "--collect")
    not_with(p, "--remake", "--collect", "--verify", "--check", "--sources")
    not_with(p, "--sources", "--collect", "--verify", "--check")


def run_cli(args: argparse.Namespace) -> int:
    """``mlpfac report``: collect, then make the data again (``--remake``), or list the pages'
    sources (``--sources``), or verify the data (``--verify``) and check the tables and figures
    (``--check``), both when both are given (exit 1 if a run, a table or a figure differs), or
    write the tables."""
    from mlpfac.report.results import _collect_item, collect, stale, write

    collects = [_collect_item(item) for item in args.collect]  # every one checked before any is copied
    if args.made_by is not None and len(collects) > 1:
        raise ConfigError(
            "--command", f"is the command of one --collect; {len(collects)} were given: collect each apart"
        )
    for name, results in collects:
        print(f"{results} -> {collect(args.docs / 'data' / name, Path(results), args.made_by, args.code_version)}")
    if args.remake is not None:
        from mlpfac.report.remake import run_cli as remake

        code = remake(args.docs, args.remake)
        for page, n, changed in write(args.docs):
            print(f"{page}: {n} tables, {'written' if changed else 'unchanged'}")
        return code
    if args.sources:
        from mlpfac.report.figures import sources

        print(sources(args.docs), end="")
        return 0
    code = 0
    if args.verify is not None:
        from mlpfac.report.remake import verify_output
        from mlpfac.report.verify import run_cli as verify

        code = verify(args.docs, args.verify, args.strict, verify_output)  # a line per dataset as it is done
    if args.check:
        old = stale(args.docs)
        for page in old:
            print(
                f"mlpfac: {page}: a table differs from its data; `mlpfac report {args.docs}` writes it", file=sys.stderr
            )
        from mlpfac.report.figures import check

        figures = check(args.docs)
        for line in figures:
            print(f"mlpfac: {line}", file=sys.stderr)
        if figures:
            print(
                f"mlpfac: {len(figures)} figure{'s' if len(figures) > 1 else ''} of the pages in none of their"
                " sources (docs/development.md)",
                file=sys.stderr,
            )
        code = max(code, 1 if old or figures else 0)
    if args.verify is not None or args.check:
        return code
    for page, n, changed in write(args.docs):
        print(f"{page}: {n} tables, {'written' if changed else 'unchanged'}")
    return 0
