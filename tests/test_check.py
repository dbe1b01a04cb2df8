"""``mlpfac check``: a budget that holds (exit 0) and one that does not (exit 1, one line per miss
with the command that re-runs its worst seed), the JUnit XML and the summary, every bad budget
(exit 2, one line naming the file and key, nothing run), and regressions against a baseline."""

from __future__ import annotations

import json
import math
import shlex
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

import mlpfac
from mlpfac.cli import main
from mlpfac.loop.metrics import RunMetrics

# A short kinematic figure of eight with its event at 3 s: "before", "after" and "whole" all exist.
SCENARIO = """name = "kin-event"
duration = 5.0
warmup = 1.0
[reference]
kind = "eight"
[plant]
kind = "kinematic"
noise_cov = 1e-6
[controller]
name = "corradini"
[[events]]
time = 3.0
kind = "control_period"
factor = 1.5
"""
RUNS = 'scenarios = ["kin.toml"]\ncontrollers = ["corradini", "kanayama"]\nseeds = "0-1"\n'
HOLDS = RUNS + "[[budget]]\nmedian_position_rms_mm = 50\nmax_error_mm = 100\nlost = 0\ndiverged = 0\n"
HOLDS += '[[budget]]\nname = "after the event"\nphase = "after"\nmedian_heading_rms_mrad = 500\n'
MISSES = RUNS + '[[budget]]\ncontroller = "kanayama"\nphase = "before"\nmedian_position_rms_mm = 0.001\nlost = 0\n'
MISSES += "[[budget]]\nmax_error_mm = 1000\n"


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A folder with the scenario; its runs (runs/) are shared by the tests: a check resumes them."""
    d = tmp_path_factory.mktemp("check")
    (d / "kin.toml").write_text(SCENARIO)
    return d


def _check(folder: Path, budget: str, *flags: str, name: str = "budget.toml") -> int:
    (folder / name).write_text(budget)
    return main(["check", str(folder / name), "--out", str(folder / "runs"), "--workers", "1", *flags])


def _junit(path: Path) -> tuple[ET.Element, list[ET.Element]]:
    root = ET.parse(path).getroot()
    assert root.tag == "testsuites" and [s.tag for s in root] == ["testsuite"]
    return root[0], list(root[0].iter("testcase"))


def test_a_budget_that_holds_exits_0_with_its_junit_and_summary(folder, capsys):
    assert _check(folder, HOLDS, "--junit", str(folder / "j.xml"), "--summary", str(folder / "s.md")) == 0
    out = capsys.readouterr().out
    assert "miss:" not in out and "4 of 4 budget cases hold" in out, out
    suite, cases = _junit(folder / "j.xml")
    assert suite.get("tests") == "4" and suite.get("failures") == "0" and len(cases) == 4
    assert not list(suite.iter("failure"))
    names = {(c.get("classname"), c.get("name")) for c in cases}
    assert ("budget.kin-event", "kanayama / after: after the event") in names, names
    assert all(float(c.get("time")) > 0 for c in cases)
    md = (folder / "s.md").read_text()
    assert "## mlpfac check: pass" in md and "MISS" not in md
    assert md.count("| pass |") == 2 * 4 + 2  # one row per figure of each case
    assert "![sweep](runs/sweep.png)" in md and (folder / "runs" / "sweep.png").is_file()


def test_a_missed_budget_exits_1_naming_the_worst_seed_and_how_to_rerun_it(folder, capsys, tmp_path):
    assert _check(folder, MISSES, "--junit", str(folder / "j.xml"), "--summary", str(folder / "s.md")) == 1
    out = capsys.readouterr().out
    misses = [line for line in out.splitlines() if line.startswith("miss:")]
    assert len(misses) == 1, out
    line = misses[0]
    assert line.startswith("miss: kin-event / kanayama / before: median_position_rms_mm ")
    assert "limit <= 0.00" in line and "worst seed " in line
    seed = int(line.split("worst seed ")[1].split(":")[0])
    cmd = shlex.split(line.split(f"worst seed {seed}: ")[1])
    assert cmd[:2] == ["mlpfac", "run"] and cmd[cmd.index("--seed") + 1] == str(seed)
    # the command re-runs that seed alone: its RMS before the event is the largest of the group
    assert main([*cmd[1:], "--no-log", "--no-plot", "--out", str(tmp_path / "again")]) == 0
    again = json.loads((tmp_path / "again" / "metrics.json").read_text())
    rms = {
        s: json.loads((folder / "runs" / "kin-event" / "kanayama" / f"seed-{s:04d}" / "metrics.json").read_text())
        for s in (0, 1)
    }
    assert again["phases"] == rms[seed]["phases"]
    assert max(rms, key=lambda s: rms[s]["phases"]["before"]["rms_position_error_m"]) == seed
    suite, cases = _junit(folder / "j.xml")
    assert (suite.get("tests"), suite.get("failures")) == ("3", "1")
    (failure,) = suite.iter("failure")
    assert "median_position_rms_mm" in failure.get("message") and "<= 0.00" in failure.get("message")
    assert f"--seed {seed}" in failure.text
    md = (folder / "s.md").read_text()
    assert "## mlpfac check: MISS" in md and md.count("| **MISS** |") == 1


def test_the_api_returns_the_verdicts(folder):
    (folder / "api.toml").write_text(MISSES)
    res = mlpfac.check(folder / "api.toml", out=folder / "runs", workers=1)
    assert res.code == 1 and not res.passed and "check" in dir(mlpfac)
    (miss,) = [v for c in res.cases for v in c.misses]
    assert miss.figure == "median_position_rms_mm" and miss.value > miss.limit
    assert len(res.lines()) == 1


def test_whole_is_the_run_after_the_warm_up_its_phases_joined():
    m = {
        "phases": {
            "before": {"start_s": 1.0, "end_s": 3.0, "rms_position_error_m": 1.0, "max_position_error_m": 2.0, "rms_heading_error_rad": 0.0},
            "after": {"start_s": 3.0, "end_s": 5.0, "rms_position_error_m": 3.0, "max_position_error_m": 4.0, "rms_heading_error_rad": 2.0},
        }
    }  # fmt: skip
    m |= {"status": "ok", "scenario": "paper", "controller": "corradini", "seed": 0, "T": 0.01, "steps": 500}
    pos, mx, head = RunMetrics.from_json(m).figures("whole")
    assert math.isclose(pos, math.sqrt(5.0)) and mx == 4.0 and math.isclose(head, math.sqrt(2.0))
    assert RunMetrics.from_json(m).figures("after") == (3.0, 4.0, 2.0)
    del m["phases"]["after"]
    run = RunMetrics.from_json(m)
    assert run.figures("whole") == run.figures("before") == (1.0, 2.0, 0.0)


def test_the_minimal_form_of_the_issue_works_as_written(tmp_path, capsys):
    budget = tmp_path / "BUDGET.toml"
    budget.write_text(
        'scenarios = ["eight-nominal", "eight-wheel-radius"]   # names or paths, like mlpfac sweep\n'
        'controllers = ["corradini"]                          # names, file.py:Class, module:Class\n'
        'seeds = "0-3"\n'
        "duration = 15.0                                      # optional override\n\n"
        "[[budget]]                         # each budget applies to every run group it matches\n"
        'scenario = "eight-nominal"         # optional filter; absent = every scenario\n'
        'controller = "corradini"           # optional filter; absent = every controller\n'
        'phase = "whole"                    # "before" | "after" | "whole" (the run after the warm-up)\n'
        "median_position_rms_mm = 5.0       # at most\n"
        "lost = 0                           # at most, runs\n"
        "diverged = 0                       # at most, runs\n"
    )
    assert main(["check", str(budget), "--out", str(tmp_path / "runs")]) == 0, capsys.readouterr()
    assert len(list((tmp_path / "runs").glob("*/corradini/seed-*/metrics.json"))) == 8


# name: (budget text, the key the one-line message names); "kin.toml" is the scenario beside it
BAD_BUDGETS: dict[str, tuple[str, str]] = {
    "not toml": ("scenarios = = 1\n", "not valid TOML"),
    "unknown key": ("workers = 2\n" + HOLDS, "budget.toml workers: unknown key"),
    "unknown budget key": (RUNS + "[[budget]]\nmedian_rms = 1.0\n", "budget #1 median_rms: unknown key"),
    "scenarios a string": ('scenarios = "kin.toml"\n[[budget]]\nlost = 0\n', "budget.toml scenarios"),
    "no scenarios": ("[[budget]]\nlost = 0\n", "budget.toml scenarios"),
    "scenario missing": ('scenarios = ["nope.toml"]\n[[budget]]\nlost = 0\n', "budget.toml scenarios"),
    "scenario unknown": ('scenarios = ["eight-nowhere"]\n[[budget]]\nlost = 0\n', "budget.toml scenarios"),
    "controller unknown": ('scenarios = ["kin.toml"]\ncontrollers = ["pid"]\n[[budget]]\nlost = 0\n', "budget.toml controllers"),
    "seeds bad": ('scenarios = ["kin.toml"]\nseeds = "3-1"\n[[budget]]\nlost = 0\n', "budget.toml seeds"),
    "seeds a float": ('scenarios = ["kin.toml"]\nseeds = 1.5\n[[budget]]\nlost = 0\n', "budget.toml seeds"),
    "duration negative": ('scenarios = ["kin.toml"]\nduration = -1.0\n[[budget]]\nlost = 0\n', "budget.toml duration"),
    "no budget": (RUNS, "budget.toml budget"),
    "budget a table": (RUNS + "[budget]\nlost = 0\n", "budget.toml budget"),
    "no figure": (RUNS + '[[budget]]\nphase = "whole"\n', "budget #1"),
    "phase unknown": (RUNS + '[[budget]]\nphase = "during"\nlost = 0\n', "budget #1 phase"),
    "figure negative": (RUNS + "[[budget]]\nmax_error_mm = -1.0\n", "budget #1 max_error_mm"),
    "figure a string": (RUNS + '[[budget]]\nmax_error_mm = "5"\n', "budget #1 max_error_mm"),
    "lost a float": (RUNS + "[[budget]]\nlost = 0.5\n", "budget #1 lost"),
    "p above 1": (RUNS + "[[budget]]\np = 2.0\n", "budget #1 p"),
    "scenario filter matches nothing": (RUNS + '[[budget]]\nscenario = "eight-nominal"\nlost = 0\n', "budget #1 scenario"),
    "controller filter matches nothing": (RUNS + '[[budget]]\ncontroller = "adaptive"\nlost = 0\n', "budget #1 controller"),
    "after without an event": (RUNS + 'duration = 2.0\n[[budget]]\nphase = "after"\nlost = 0\n', "budget #1 phase"),
    "baseline figure without --baseline": (RUNS + "[[budget]]\nno_worse_than_baseline = 1.1\n", "--baseline"),
    "p without --baseline": (RUNS + "[[budget]]\np = 0.01\n", "--baseline"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_BUDGETS))
def test_a_bad_budget_is_one_line_and_runs_nothing(tmp_path, capsys, case):
    text, needle = BAD_BUDGETS[case]
    (tmp_path / "kin.toml").write_text(SCENARIO)
    assert _check(tmp_path, text) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and needle in err and "budget.toml" in err, err
    assert not (tmp_path / "runs").exists() and not captured.out


def _baseline(folder: Path, tmp_path: Path, scale: float, drop: int | None = None) -> Path:
    """A copy of the check's runs as a baseline, every position RMS times ``scale``."""
    base = tmp_path / "base"
    shutil.copytree(folder / "runs", base)
    for f in base.glob("*/*/seed-*/metrics.json"):
        m = json.loads(f.read_text())
        for ph in m["phases"].values():
            ph["rms_position_error_m"] *= scale
        f.write_text(json.dumps(m))
    if drop is not None:
        for d in base.glob(f"*/*/seed-{drop:04d}"):
            shutil.rmtree(d)
    return base


REGRESSION = RUNS + '[[budget]]\ncontroller = "corradini"\nno_worse_than_baseline = 1.10\np = 0.3\n'


def test_a_regression_against_the_baseline_is_found(folder, tmp_path, capsys):
    assert _check(folder, HOLDS) == 0
    base = _baseline(folder, tmp_path, 0.5)  # the baseline tracked twice as well
    assert _check(folder, REGRESSION, "--baseline", str(base / "sweep.json"), "--summary", str(tmp_path / "s.md")) == 1
    out = capsys.readouterr().out
    assert "no_worse_than_baseline 2.00 (2 seeds paired), limit <= 1.10" in out, out
    assert "p 0.25 (2 seeds paired), limit >= 0.3;" in out, out  # 2 seeds, both worse: p = 1/4
    assert "| **MISS** |" in (tmp_path / "s.md").read_text()


def test_no_regression_is_found_where_there_is_none(folder, tmp_path, capsys):
    assert _check(folder, HOLDS) == 0
    base = _baseline(folder, tmp_path, 2.0, drop=1)  # worse baseline, and seed 1 missing from it
    assert _check(folder, REGRESSION + "median_position_rms_mm = 50\n", "--baseline", str(base)) == 0
    out = capsys.readouterr().out
    assert "miss:" not in out and "the baseline has no run of seeds 1; left out" in out, out
    res = mlpfac.check(folder / "budget.toml", baseline=base, out=folder / "runs", workers=1)
    (case,) = res.cases
    assert case.missing == [1]
    by = {v.figure: v for v in case.verdicts}
    assert by["no_worse_than_baseline"].value == 0.5 and by["no_worse_than_baseline"].note == "1 seeds paired"
    assert by["median_position_rms_mm"].baseline is not None  # the same figure over the baseline's runs


DIVERGES = """name = "kin-diverges"
duration = 3.0
divergence_m = 0.05
[reference]
kind = "eight"
[plant]
kind = "kinematic"
[initial]
error = [0.3, 0.0, 0.0]
[controller]
name = "corradini"
"""


def test_runs_that_diverged_are_counted_and_have_no_position_figure(tmp_path, capsys):
    (tmp_path / "div.toml").write_text(DIVERGES)  # 0.3 m off, diverged beyond 0.05 m: every run
    budget = 'scenarios = ["div.toml"]\nseeds = "0-1"\n[[budget]]\ndiverged = 0\nmedian_position_rms_mm = 10\n'
    assert _check(tmp_path, budget) == 1
    misses = [line for line in capsys.readouterr().out.splitlines() if line.startswith("miss:")]
    assert len(misses) == 2, misses
    assert "median_position_rms_mm - (no run finished), limit <= 10.00; worst seed 0" in misses[0]
    assert "diverged 2, limit <= 0; worst seed 0: mlpfac run " in misses[1]


def test_a_budget_names_a_plugin_relative_to_its_own_folder(tmp_path, monkeypatch, capsys):
    """controllers = ["laws/my_law.py:MyLaw"] from the budget's folder, filtered by that spelling;
    a baseline swept from another folder pairs with it by the controller's name."""
    (tmp_path / "ci" / "laws").mkdir(parents=True)
    (tmp_path / "ci" / "laws" / "my_law.py").write_text(
        "import math\n\n\nclass MyLaw:\n    def __init__(self, T):\n        pass\n\n"
        "    def step(self, e, r):\n        return r[3] * math.cos(e[2]) + 10 * e[0], "
        "r[4] + r[3] * (64 * e[1] + 16 * math.sin(e[2]))\n"
    )
    (tmp_path / "ci" / "budget.toml").write_text(
        'scenarios = ["paper"]\ncontrollers = ["laws/my_law.py:MyLaw", "corradini"]\nseeds = "0-1"\n'
        'duration = 4.0\n\n[[budget]]\ncontroller = "laws/my_law.py:MyLaw"\nmedian_position_rms_mm = 50.0\n'
        "diverged = 0\nno_worse_than_baseline = 1.0\n"
    )
    monkeypatch.chdir(tmp_path)
    base = mlpfac.sweep(["paper"], [f"{tmp_path}/ci/laws/my_law.py:MyLaw"], seeds="0-1", duration=4.0, out="base")
    assert {r["controller"] for r in base} == {"MyLaw"}
    code = main(["check", "ci/budget.toml", "--out", "o", "--workers", "1", "--baseline", "base", "--junit", "j.xml"])
    out = capsys.readouterr()
    assert code == 0, out.out + out.err
    root, cases = _junit(tmp_path / "j.xml")
    assert len(cases) == 1 and "MyLaw" in cases[0].get("name") and root.get("failures") in ("0", None)
