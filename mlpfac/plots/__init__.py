"""Pictures made with matplotlib: Figure 1 of the paper redrawn from one run (:mod:`.figure1`), the
sweep and comparison plots written next to ``sweep.md`` (:mod:`.sweeps`), and one colour per
controller shared with the viewer (:mod:`.colors`). matplotlib is imported only when drawing."""

from mlpfac.plots.colors import controller_colors
from mlpfac.plots.figure1 import figure1
from mlpfac.plots.sweeps import sweep_plots

__all__ = ["controller_colors", "figure1", "sweep_plots"]
