"""The results pages' tables written from the data kept beside them (:mod:`~mlpfac.report.results`,
``mlpfac report``), and that data run again bit for bit (:mod:`~mlpfac.report.verify`,
``mlpfac report --verify N``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from mlpfac.flags import needs, not_with
from mlpfac.targets import cli_path


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
