"""``mlpfac check``: run a budget's sweep, then judge it against the budget's limits.

A budget file (TOML) names the sweep (``scenarios``, ``controllers``, ``seeds``, ``duration``) and
one or more ``[[budget]]`` tables, each limiting figures of every run group (scenario and
controller) it matches in one phase; see :mod:`mlpfac.checks.budget` and docs/ci.md. The sweep is
:func:`mlpfac.sweeps.engine.sweep_into`: the same engine, folders and resume as ``mlpfac sweep``.

Exit codes: 0 every budget holds, 1 at least one does not (or a run raised), 2 bad input (nothing
run) or a failed write, 130 / 143 interrupted by Ctrl-C / SIGTERM.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path

from mlpfac.checks.budget import Budget, read_budget
from mlpfac.checks.judge import Case, baseline_folder, baseline_runs, judge
from mlpfac.checks.reports import junit as junit_xml
from mlpfac.checks.reports import miss_lines
from mlpfac.checks.reports import summary as summary_md
from mlpfac.exceptions import ConfigError
from mlpfac.loop.metrics import RunMetrics

DEFAULT_OUT = Path("runs/check")
DEFAULT_WORKERS = 2
EXIT_OK, EXIT_MISS = 0, 1


@dataclass
class CheckResult:
    """What :func:`check` found: ``code`` is the command's exit code; ``cases`` one per limit and run
    group (empty when the sweep was interrupted); ``files`` every table, plot and report written."""

    budget: Path
    out: Path
    code: int
    cases: list[Case] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    duration: float | None = None

    @property
    def passed(self) -> bool:
        return self.code == EXIT_OK

    def lines(self) -> list[str]:
        """One line per miss (scenario, controller, phase, figure, limit, worst seed, re-run command) and note."""
        return [line for c in self.cases for line in miss_lines(c, self.duration)]


def check(
    budget: str | Path,
    junit: str | Path | None = None,
    summary: str | Path | None = None,
    baseline: str | Path | None = None,
    out: str | Path | None = None,
    workers: int | None = None,
    robot: str | None = None,
    vary: list[str] | dict | None = None,
    lost_threshold: float | None = None,
) -> CheckResult:
    """Run the sweep of the budget file ``budget`` into ``out`` (default runs/check; runs already
    done there are skipped) with ``workers`` local processes (default 2), then judge it, against
    the runs of the sweep folder (or its sweep.json) ``baseline`` per seed where the budget asks.
    Writes JUnit XML to ``junit`` and a Markdown summary to ``summary`` when given. ``vary`` adds
    axes and draws to the budget's ``vary`` (``--vary``, :mod:`mlpfac.sweeps.vary`); ``lost_threshold``
    (``--lost-threshold``) sets every run's ``lost_threshold_m`` over the budget's.

    ``robot`` (``--robot``) runs every scenario of the budget on that robot instead of the
    budget's ``robots``. Bad input (the budget, a flag) is a ConfigError naming the file and key
    before anything runs.
    """
    from mlpfac.exceptions import OutputError
    from mlpfac.io.targets import check_report_file, check_results_folder, user_path, write_report_file
    from mlpfac.sweeps.engine import SWEEP_COLUMNS, check_execution_flags, report, sweep_into, sweep_meta
    from mlpfac.sweeps.folders import _oserror
    from mlpfac.sweeps.plan import check_writable
    from mlpfac.sweeps.tables import table_files
    from mlpfac.sweeps.worker import not_in_a_worker

    not_in_a_worker("check")

    path = user_path(budget, "budget")
    out = DEFAULT_OUT if out is None else user_path(out, "out")
    n_workers = check_execution_flags(DEFAULT_WORKERS if workers is None else workers)
    from mlpfac.sweeps.vary import parse_vary

    b = read_budget(path, robot, parse_vary(vary), lost_threshold)
    needs = b.needs_baseline()
    if needs is not None and baseline is None:
        figure = next(f for f in needs.figures if f in ("no_worse_than_baseline", "p"))
        raise ConfigError(
            f"{path} {needs.where} {figure}", "compares with a baseline: give --baseline DIR_OR_SWEEP_JSON"
        )
    base_dir = baseline_folder(baseline) if baseline is not None else None
    reports = [(user_path(p, flag), flag) for p, flag in ((junit, "--junit"), (summary, "--summary")) if p is not None]
    for p, flag in reports:
        check_report_file(p, flag)
    jobs, groups = b.plan()
    check_writable(out)
    check_results_folder(out, table_files("sweep"))
    argv = ["mlpfac", "check", str(budget), "--out", str(out), "--workers", str(n_workers)]
    argv += ["--baseline", str(baseline)] if baseline is not None else []
    argv += [f"--vary={v}" for v in (vary if isinstance(vary, list) else parse_vary(vary).texts())]
    argv += ["--lost-threshold", f"{lost_threshold!r}"] if lost_threshold is not None else []
    meta = sweep_meta("check", b.scenarios, b.seeds_text, b.duration, jobs) | {"budget": str(path)}
    meta |= {"vary": b.vary.texts(), "threshold_m": b.threshold} if b.vary else {}
    meta |= {"lost_threshold_m": b.lost_threshold} if b.lost_threshold is not None else {}
    done = sweep_into(jobs, out, "sweep", SWEEP_COLUMNS, meta, shlex.join(argv), workers=n_workers)
    result = CheckResult(path, out, EXIT_MISS, files=list(done.paths), duration=b.duration)
    if done.code is not None:
        result.code = done.code
        return result
    report(done)
    result.cases = _judge(b, groups, done.outcome.metrics, base_dir)
    result.code = EXIT_OK if all(c.passed for c in result.cases) else EXIT_MISS
    plots = [p for p in done.paths if p.suffix == ".png"]
    for p, flag in reports:
        try:
            if flag == "--junit":
                write_report_file(p, junit_xml(result.cases, path.stem, b.duration))
            else:
                write_report_file(p, summary_md(result.cases, path, plots, p.absolute().parent, base_dir))
        except OSError as err:
            raise OutputError(f"{_oserror(err, str(p))}; the runs in {out} are whole, run the check again") from None
        result.files.append(p)
    return result


def _judge(b: Budget, groups, metrics: dict[tuple, RunMetrics], base_dir: Path | None) -> list[Case]:
    from mlpfac.checks.breaking import judge_breaking

    cases = []
    for limit in b.limits:
        if limit.breaking:  # one case per scenario and controller, over the grid
            cases += judge_breaking(limit, groups, metrics, b.threshold)
            continue
        for g in groups:
            if limit.matches(g) and (limit.phase != "after" or g.has_event):
                base = baseline_runs(base_dir, g) if base_dir is not None else None
                cases.append(judge(limit, g, metrics, base))
    return cases
