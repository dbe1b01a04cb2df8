"""A scenario: a TOML file parsed into plain, validated data (:mod:`mlpfac.scenario.parse`), the reference it names, the provenance that makes a re-run exact.

``from mlpfac.scenario import load`` (and ``parse``, ``Scenario``, ``scenario_names``, ``to_toml``)
still works, as before the package had folders: the names are read from :mod:`mlpfac.scenario.parse`
on first use, so importing one module of this package does not import the parser.
"""

from __future__ import annotations

import importlib

_PARSE = ("Scenario", "load", "parse", "scenario_names", "to_toml")


def __getattr__(name: str):
    if name in _PARSE:
        return getattr(importlib.import_module("mlpfac.scenario.parse"), name)
    raise AttributeError(f"module 'mlpfac.scenario' has no attribute {name!r}")
