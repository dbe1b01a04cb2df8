"""What a budget limits: the figures a ``[[budget]]`` table can name, the run groups it is judged on
and its filters; read by :mod:`mlpfac.checks.budget`, judged by :mod:`mlpfac.checks.judge` and
:mod:`mlpfac.checks.breaking`."""

from __future__ import annotations

from dataclasses import dataclass, field

from mlpfac.scenario.on_robot import split_robot
from mlpfac.sweeps.plan import Job

PHASE_NAMES = ("before", "after", "whole")  # "whole": the run after the warm-up


@dataclass(frozen=True)
class Figure:
    """A figure a budget can limit: ``text`` and ``unit`` for reports; ``at_least``: the value must
    not fall below the limit (a p-value), else it must not exceed it."""

    text: str
    unit: str = ""
    count: bool = False  # a number of runs: the limit is a whole number
    baseline: bool = False  # needs --baseline
    at_least: bool = False
    axis: bool = False  # a breaking point along a --vary axis (mlpfac.checks.breaking)


FIGURES: dict[str, Figure] = {
    "median_position_rms_mm": Figure("median position RMS", "mm"),
    "mean_position_rms_mm": Figure("mean position RMS", "mm"),
    "max_position_rms_mm": Figure("largest position RMS of a run", "mm"),
    "max_error_mm": Figure("largest position error", "mm"),
    "median_heading_rms_mrad": Figure("median heading RMS", "mrad"),
    "mean_heading_rms_mrad": Figure("mean heading RMS", "mrad"),
    "max_heading_rms_mrad": Figure("largest heading RMS of a run", "mrad"),
    "lost": Figure("runs lost", "runs", count=True),
    "diverged": Figure("runs diverged", "runs", count=True),
    "no_worse_than_baseline": Figure("median per-seed ratio of position RMS to the baseline", "x", baseline=True),
    "p": Figure("one-sided Wilcoxon p that it is worse than the baseline", baseline=True, at_least=True),
    "holds_up_to": Figure("breaking point above the nominal value", at_least=True, axis=True),
    "holds_down_to": Figure("breaking point below the nominal value", axis=True),
}
AFTER_THE_CHANGE = "after the change"  # the phase of a breaking point: the last one (mlpfac.sweeps.robustness)


@dataclass
class Group:
    """The runs of one scenario and controller, with the names the budget gave them."""

    scenario: str  # the scenario's name (its folder)
    controller: str
    source: str  # the scenario as the budget wrote it (a name, or a path made absolute)
    spec: str | None  # the controller as the budget wrote it (None: the scenario's own)
    jobs: list[Job] = field(default_factory=list)
    family: str = ""  # the scenario's own name (a grid point's scenario is SCENARIO+KEY+VALUE)

    @property
    def has_event(self) -> bool:
        return bool(self.jobs and self.jobs[0].table.get("events"))


@dataclass
class Limit:
    """One ``[[budget]]`` table: its filters and the figures it limits."""

    index: int  # 1 for the first [[budget]]
    name: str | None
    scenario: str | None
    controller: str | None
    phase: str
    figures: dict[str, float]
    axis: str | None = None  # the --vary axis of a breaking point (None: the only one)

    @property
    def breaking(self) -> bool:
        return any(FIGURES[f].axis for f in self.figures)

    @property
    def where(self) -> str:
        return f"budget #{self.index}"

    def matches(self, g: Group) -> bool:
        scenario = self.scenario in (
            None,
            g.scenario,
            g.source,
            g.family,
            split_robot(g.source)[0],
        )  # on every robot, or on one
        return scenario and self.controller in (None, g.controller, g.spec)
