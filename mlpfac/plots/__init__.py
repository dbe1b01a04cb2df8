"""Pictures made with matplotlib: Figure 1 of the paper redrawn from one run (:mod:`.figure1`), the
sweep and comparison plots written next to ``sweep.md`` (:mod:`.sweeps`), and one colour per
controller shared with the viewer (:mod:`.colors`). matplotlib is imported only when drawing, and
the sweep plots' module when first named (the painter's process, forked before a run, needs none)."""

from __future__ import annotations

import importlib

from mlpfac.plots.figure1 import figure1

__all__ = ["controller_colors", "figure1", "sweep_plots"]
_LATER = {"controller_colors": "colors", "sweep_plots": "sweeps"}


def __getattr__(name: str):
    if name in _LATER:
        return getattr(importlib.import_module(f"mlpfac.plots.{_LATER[name]}"), name)
    raise AttributeError(f"module 'mlpfac.plots' has no attribute {name!r}")
