"""`mlpfac report --collect` keeps every run's figures (runs.json), and `mlpfac report --verify N`
runs N of them again from the recorded command: bit-identical, or by how much they differ."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from mlpfac.cli import main
from mlpfac.report.verify import RUNS_FILE, digest, verify

COMMAND = "mlpfac sweep paper --controllers kanayama,corradini --seeds 0-2 --duration 1 --out runs/tiny"


@pytest.fixture(scope="module")
def collected(tmp_path_factory) -> Path:
    """A docs folder whose one dataset is a small sweep, collected as the docs' are."""
    root = tmp_path_factory.mktemp("repo")
    out = root / "runs" / "tiny"
    assert main(["sweep", "paper", "--controllers", "kanayama,corradini", "--seeds", "0-2", "--duration", "1",
                 "--out", str(out), "--workers", "1"]) == 0  # fmt: skip
    docs = root / "docs"
    assert main(["report", str(docs), "--collect", f"tiny={out}", "--command", COMMAND]) == 0
    return docs


def _copy(docs: Path, tmp_path: Path) -> Path:
    shutil.copytree(docs, tmp_path / "docs")
    return tmp_path / "docs"


def test_collect_keeps_every_runs_figures_and_digest(collected):
    runs = json.loads((collected / "data" / "tiny" / RUNS_FILE).read_text())["runs"]
    assert sorted((r["controller"], r["seed"]) for r in runs) == [
        (c, s) for c in ("corradini", "kanayama") for s in range(3)
    ]
    folder = collected.parent / "runs" / "tiny" / "paper" / "kanayama" / "seed-0001"
    m = json.loads((folder / "metrics.json").read_text())
    (row,) = [r for r in runs if (r["controller"], r["seed"]) == ("kanayama", 1)]
    assert (
        row["digest"] == digest(m)
        and row["phases"]["before"]["rms_position_error_m"] == m["phases"]["before"]["rms_position_error_m"]
    )
    assert digest(m | {"wall_time_s": 123.0}) == digest(m)  # the time a run took is not its result
    assert digest(m | {"steps": m["steps"] - 1}) != digest(m)


def test_verify_says_bit_identical(collected, capsys):
    assert main(["report", str(collected), "--verify", "4"]) == 0
    assert capsys.readouterr().out == "tiny: 4 of 4 runs bit-identical\n"


def test_verify_says_by_how_much_a_run_differs(collected, tmp_path, capsys):
    docs = _copy(collected, tmp_path)
    path = docs / "data" / "tiny" / RUNS_FILE
    data = json.loads(path.read_text())
    for r in data["runs"]:  # the kept figures 1 % higher than what the code gives: a known answer
        r["digest"] = "0" * 32
        r["rms_position_error_m"] *= 1.01
    path.write_text(json.dumps(data))
    assert main(["report", str(docs), "--verify", "2"]) == 1
    out = capsys.readouterr().out
    assert out.startswith("tiny: 0 of 2 runs bit-identical; largest difference 0.0099 (relative, paper / ")
    assert out.rstrip().endswith(", rms_position_error_m)")


def test_verify_says_what_it_cannot_verify(collected, tmp_path, capsys):
    docs = _copy(collected, tmp_path)
    old = docs / "data" / "old"
    shutil.copytree(docs / "data" / "tiny", old)
    (old / RUNS_FILE).unlink()
    script = docs / "data" / "script"
    script.mkdir()
    (script / "table.md").write_text("| a |\n|---|\n| 1 |\n")
    (script / "meta.json").write_text(json.dumps({"command": "python sims/paper_choices.py --seeds 50"}))
    assert [v.line() for v in verify(docs, 1)] == [
        "old: not verified: no per-seed results (runs.json): collect it again from its command",
        "script: not verified: a script's table: run its command again to check it",
        "tiny: 1 of 1 runs bit-identical",
    ]


GRID = (
    "mlpfac sweep paper --controllers kanayama --vary events.0.factor=1,2 --vary plant.noise_cov=uniform:1e-07:1e-06 "
    "--seeds 0-1 --duration 13 --out runs/grid"
)


def test_a_vary_dataset_re_plans_its_grid_and_draws(tmp_path, capsys):
    """The recorded --vary of a dataset is planned again: the same grid points (the runs' keys) and
    the same draws (the same bits), so every run of a robustness dataset can be verified."""
    from mlpfac.report.verify import _plan

    root = tmp_path / "repo"
    out = root / "runs" / "grid"
    argv = GRID.split()[1:]
    assert main([*argv[: argv.index("--out")], "--out", str(out), "--workers", "1"]) == 0
    docs = root / "docs"
    assert main(["report", str(docs), "--collect", f"grid={out}", "--command", GRID]) == 0
    capsys.readouterr()
    runs = json.loads((docs / "data" / "grid" / RUNS_FILE).read_text())["runs"]
    jobs, _ = _plan(GRID, root)
    assert sorted(j.key for j in jobs) == sorted((r["scenario"], r["controller"], r["seed"]) for r in runs)
    assert {r["scenario"] for r in runs} == {"paper+events.0.factor+1.0", "paper+events.0.factor+2.0"}
    assert [v.line() for v in verify(docs, 4)] == ["grid: 4 of 4 runs bit-identical"]
    meta = docs / "data" / "grid" / "meta.json"  # recorded without its axes: none of its runs is planned
    meta.write_text(json.dumps({"command": GRID.replace(" --vary events.0.factor=1,2", "")}))
    (line,) = [v.line() for v in verify(docs, 4)]
    assert line == "grid: not verified: none of its 4 runs is in its command's plan: collect it again from its command"


DOCS = Path(__file__).resolve().parents[1] / "docs"
ROBUST = sorted(p.name for p in (DOCS / "data").glob("robust-*"))


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=[pytest.mark.menagerie] if "tiago" in n else []) for n in ROBUST]
)
def test_every_documented_robustness_dataset_re_plans_to_its_runs(name):
    """Each robustness dataset keeps every run's figures, and its recorded command (its --vary)
    plans exactly those runs again, so report --verify can check any of them."""
    from mlpfac.report.verify import _plan

    folder = DOCS / "data" / name
    runs = json.loads((folder / RUNS_FILE).read_text())["runs"]
    jobs, _ = _plan(json.loads((folder / "meta.json").read_text())["command"], DOCS.parent)
    assert sorted(j.key for j in jobs) == sorted((r["scenario"], r["controller"], r["seed"]) for r in runs)


def test_verify_plans_a_dataset_of_robots_from_its_command(tmp_path, capsys):
    """A dataset of --robots (each scenario as SCENARIO+ROBOT in runs.json) behind an environment the
    reader sets (MENAGERIE_ROOT=...): its runs planned again on their robots, bit-identical."""
    out = tmp_path / "runs" / "robots"
    argv = ["compare", "eight-nominal", "--robots", "diffdrive,cart", "--controllers", "kanayama", "--seeds", "0"]
    assert main([*argv, "--duration", "1", "--out", str(out), "--workers", "1"]) == 0
    command = f"MENAGERIE_ROOT=/path/to/mujoco_menagerie mlpfac {' '.join(argv)} --duration 1 --out runs/robots"
    assert main(["report", str(tmp_path / "docs"), "--collect", f"robots={out}", "--command", command]) == 0
    capsys.readouterr()
    assert main(["report", str(tmp_path / "docs"), "--verify", "2"]) == 0
    assert capsys.readouterr().out == "robots: 2 of 2 runs bit-identical\n"


# A dataset that is not what `report --collect` writes: which file is written, what it holds, and
# what the one line must say. The dataset sorts after `tiny`: nothing may run before the error.
RUNS_OK = {"command": COMMAND}
ROW = {"scenario": "paper", "controller": "kanayama", "seed": 0, "digest": "0", "status": "ok", "outcome": "tracking"}
BAD_DATASETS = {
    "meta.json not JSON": ({"meta.json": "{not json"}, "zz/meta.json: not valid JSON"),
    "command with an unclosed quote": (
        {"meta.json": {"command": "mlpfac sweep 'paper"}},
        "cannot be read as a command",
    ),
    "command a number": ({"meta.json": {"command": 5}}, "meta.json command: expected the command line as a string"),
    "command a list": ({"meta.json": {"command": ["mlpfac", "sweep"]}}, "expected the command line as a string"),
    "command with an unknown flag": (
        {"meta.json": {"command": "mlpfac sweep paper --frobnicate 3"}, RUNS_FILE: {"runs": [ROW]}},
        "meta.json command: not a command mlpfac reads (unrecognized arguments: --frobnicate 3)",
    ),
    "runs.json {}": ({"meta.json": RUNS_OK, RUNS_FILE: {}}, "zz/runs.json runs: expected a list of runs, got NoneType"),
    "runs.json runs 5": (
        {"meta.json": RUNS_OK, RUNS_FILE: {"runs": 5}},
        "runs.json runs: expected a list of runs, got int",
    ),
    "runs.json row without fields": (
        {"meta.json": RUNS_OK, RUNS_FILE: {"runs": [{"scenario": "paper", "seed": 0}]}},
        "runs.json runs[0]: expected a run's row with",
    ),
    "runs.json row a number": ({"meta.json": RUNS_OK, RUNS_FILE: {"runs": [3]}}, "runs.json runs[0]"),
    "meta.json without a command": (
        {"meta.json": {"code_version": "abc"}, RUNS_FILE: {"runs": [ROW]}},
        "zz/meta.json command: missing: a dataset's meta.json names the command that made it",
    ),
    "meta.json with an empty command": ({"meta.json": {"command": " "}, RUNS_FILE: {"runs": [ROW]}}, "zz/meta.json command: missing"),
    "a script's table without a command": ({"meta.json": {}, "table.md": "| a |\n"}, "zz/meta.json command: missing"),
    "command in a folder that is not there": (
        {"meta.json": {"command": f"cd no-such-folder && {COMMAND}"}, RUNS_FILE: {"runs": [ROW]}},
        "zz/meta.json command: cd no-such-folder: no such folder (",
    ),
    "command with a flag that needs another": (
        {"meta.json": {"command": f"{COMMAND} --threshold 0.1"}, RUNS_FILE: {"runs": [ROW]}},
        "meta.json command: not a command mlpfac reads (--threshold means nothing without --vary",
    ),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_DATASETS))
def test_a_bad_dataset_is_one_line_before_any_run(collected, tmp_path, capsys, case):
    files, needle = BAD_DATASETS[case]
    docs = _copy(collected, tmp_path)
    bad = docs / "data" / "zz"
    bad.mkdir()
    for name, content in files.items():
        (bad / name).write_text(content if isinstance(content, str) else json.dumps(content))
    capsys.readouterr()
    assert main(["report", str(docs), "--verify", "1"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and needle in err and "usage" not in err, err


def test_check_and_verify_together_do_both(collected, tmp_path, capsys):
    """``--check --verify N``: the data run again and the tables checked; exit 1 if either differs."""
    docs = _copy(collected, tmp_path)
    page = docs / "page.md"
    page.write_text("<!-- table: data/tiny view=sweep -->\n<!-- /table -->\n")
    assert main(["report", str(docs)]) == 0  # the table, written from its data
    good = page.read_text()
    assert " | 3 / 0 / 0 |" in good
    page.write_text(good.replace(" | 3 / 0 / 0 |", " | 2 / 1 / 0 |", 1))
    capsys.readouterr()
    assert main(["report", str(docs), "--check", "--verify", "1"]) == 1
    out, err = capsys.readouterr()
    assert out == "tiny: 1 of 1 runs bit-identical\n" and "page.md: a table differs from its data" in err, err
    page.write_text(good)
    assert main(["report", str(docs), "--verify", "1", "--check"]) == 0
    assert capsys.readouterr().err == ""


SKIPPED = (
    "MENAGERIE_ROOT=/path/to/mujoco_menagerie mlpfac sweep tiago-nominal --controllers kanayama --seeds 0 --out runs/t"
)
OFFLINE = """import sys, mujoco_menagerie as mm
def get(*args, **kwargs):
    raise mm.MenagerieError("offline here")
mm.get = get
from mlpfac.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_a_dataset_whose_robot_is_not_here_is_skipped_and_only_strict_fails(collected, tmp_path):
    """Offline without MuJoCo Menagerie: the TIAGo dataset is listed as skipped, with the reason,
    exit 0 since every dataset that could run is bit-identical; --strict makes the skip an error."""
    docs = _copy(collected, tmp_path)
    t = docs / "data" / "t"
    t.mkdir()
    (t / "meta.json").write_text(json.dumps({"command": SKIPPED}))
    row = json.loads((docs / "data" / "tiny" / RUNS_FILE).read_text())["runs"][0] | {"scenario": "tiago-nominal"}
    (t / RUNS_FILE).write_text(json.dumps({"runs": [row]}))
    for strict, code in (([], 0), (["--strict"], 1)):
        cmd = [sys.executable, "-c", OFFLINE, "report", str(docs), "--verify", "1", *strict]
        done = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path)
        assert done.returncode == code, done.stderr
        lines = done.stdout.splitlines()
        assert lines[0].startswith("t: skipped: not available here: ") and "pal_tiago" in lines[0]
        assert "offline here" in lines[0] and lines[1] == "tiny: 1 of 1 runs bit-identical"
        assert done.stderr.startswith("mlpfac: 1 datasets skipped, not verified here: t (--strict")


def test_sigterm_during_verify_ends_it_as_terminated(collected, tmp_path):
    """SIGTERM while a dataset's run is re-run: exit 143 and one line, as everywhere else (not 130).
    The sign: the line of the dataset verified before it (``tiny``); the slow one's run lasts minutes
    of simulated time on any machine, so the signal lands inside it."""
    docs = _copy(collected, tmp_path)
    slow = docs / "data" / "z-slow"  # after tiny
    slow.mkdir()
    command = "mlpfac sweep paper --controllers adaptive-ukf --seeds 0 --duration 3000 --out runs/slow"
    (slow / "meta.json").write_text(json.dumps({"command": command}))
    row = json.loads((docs / "data" / "tiny" / RUNS_FILE).read_text())["runs"][0]
    (slow / RUNS_FILE).write_text(json.dumps({"runs": [row | {"controller": "adaptive-ukf", "seed": 0}]}))
    mlpfac = str(Path(sys.executable).with_name("mlpfac"))
    proc = subprocess.Popen([mlpfac, "report", str(docs), "--verify", "1"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path)  # fmt: skip
    try:
        first = proc.stdout.readline()  # tiny's verdict: z-slow's run starts now
        assert first == "tiny: 1 of 1 runs bit-identical\n", (first, proc.stderr.read() if not first else "")
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=300)  # only bounds a hang
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 143 and err.strip() == "mlpfac: terminated", err
    assert out == ""
