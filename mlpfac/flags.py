"""Flags that mean something only beside another (``report --strict`` needs ``--verify``) or never
beside another (``view --bind`` with ``--save``, which starts no viewer): declared with a command's
arguments (:func:`needs`, :func:`not_with`) and checked once its command line is parsed
(:class:`Parser`). Such a flag is refused in one line, exit 2, before anything runs or is written,
never silently dropped (docs/errors.md).

Only the standard library: every command's parser imports this module.
"""

from __future__ import annotations

import argparse
import sys

from mlpfac.io.exits import EXIT_BAD_INPUT

_RULES = "_mlpfac_flag_rules"  # the parser's attribute holding its rules: (flag, others, needed)


def needs(p: argparse.ArgumentParser, flag: str, *others: str) -> None:
    """``flag`` of ``p`` means nothing unless one of ``others`` is given too."""
    p.__dict__.setdefault(_RULES, []).append((flag, others, True))


def not_with(p: argparse.ArgumentParser, flag: str, *others: str) -> None:
    """``flag`` of ``p`` means nothing beside any of ``others``."""
    p.__dict__.setdefault(_RULES, []).append((flag, others, False))


def _given(p: argparse.ArgumentParser, ns: argparse.Namespace, flag: str) -> bool:
    """Whether ``flag`` was given a value other than its default (``--port 9090``, the default, is not)."""
    action = p._option_string_actions[flag]
    return getattr(ns, action.dest, action.default) != action.default


def broken_rule(p: argparse.ArgumentParser, ns: argparse.Namespace) -> str | None:
    """The message of the first rule of ``p`` the parsed ``ns`` breaks, or None."""
    for flag, others, needed in p.__dict__.get(_RULES, ()):
        if not _given(p, ns, flag):
            continue
        beside = [o for o in others if _given(p, ns, o)]
        if needed and not beside:
            return (
                f"{flag} means nothing without {' or '.join(others)}: give it with {' or '.join(others)}, or not at all"
            )
        if not needed and beside:
            return f"{flag} means nothing with {beside[0]}: give one of them"
    return None


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (exit 2), and so is a flag that breaks its rule."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(EXIT_BAD_INPUT)

    def parse_known_args(self, args=None, namespace=None):  # a subcommand's parser is called here too
        ns, extra = super().parse_known_args(args, namespace)
        broken = broken_rule(self, ns)
        if broken is not None:
            self.error(broken)
        return ns, extra
