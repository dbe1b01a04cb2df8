"""``--vary``: a number of the scenario as an axis (a grid point is the scenario with the value
written in, to the bit), distributions drawn per seed (the same robot for every controller,
re-run from config.toml), and where each controller breaks (robustness.*)."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from mlpfac.cli import main
from mlpfac.exceptions import ConfigError
from mlpfac.loop.runner import run
from mlpfac.scenario.draws import Distribution, leaves
from mlpfac.scenario.parse import load, parse, shipped_dir
from mlpfac.sweeps.plan import plan
from mlpfac.sweeps.robustness import breaking_points, median_interval
from mlpfac.sweeps.vary import parse_vary


def _same(a, b) -> None:
    for name in ("pose", "pose_meas", "u", "e"):
        assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name


@pytest.mark.parametrize(
    ("text", "values"),
    [
        ("1.0,1.25,1.5", (1.0, 1.25, 1.5)),
        ("1.0:2.0:5", (1.0, 1.25, 1.5, 1.75, 2.0)),
        ("1:1.5:6", (1.0, 1.1, 1.2, 1.3, 1.4, 1.5)),  # as written, not 1.2000000000000002
        ("0:10:11", tuple(range(11))),  # whole numbers: a delay in steps
        ("0:10:3", (0, 5, 10)),
        ("0:1:3", (0.0, 0.5, 1.0)),
    ],
)
def test_values_are_a_list_or_an_inclusive_range(text, values):
    (axis,) = parse_vary([f"events.0.scale={text}"]).axes
    assert axis.values == values and [type(v) for v in axis.values] == [type(v) for v in values]


def test_a_distribution_is_drawn_not_an_axis():
    v = parse_vary(["events.0.scale=uniform:0.9:1.1", "plant.noise_cov=normal:1e-6:1e-7", "reference.wx=1,2"])
    assert [a.key for a in v.axes] == ["reference.wx"] and v.size == 2
    assert v.draws == {
        "events.0.scale": Distribution("uniform", 0.9, 1.1),
        "plant.noise_cov": Distribution("normal", 1e-6, 1e-7),
    }
    assert parse_vary({"events.0.scale": {"uniform": [0.9, 1.1]}}).draws == {
        "events.0.scale": Distribution("uniform", 0.9, 1.1)
    }


@pytest.mark.parametrize("value", [1.5, 1.25])
def test_a_grid_point_is_the_scenario_with_the_value_written_in(tmp_path, value):
    """eight-wheel-radius at events.0.scale = 1.5 is the plain scenario; at 1.25 it is the file with 1.25."""
    jobs = plan(["eight-wheel-radius"], ["kanayama"], [3], 12.8, parse_vary(["events.0.scale=1.25,1.5"]))
    (job,) = [j for j in jobs if j.point == (("events.0.scale", value),)]
    assert job.scenario == f"eight-wheel-radius+events.0.scale+{value!r}" and job.family == "eight-wheel-radius"
    text = (shipped_dir() / "eight-wheel-radius.toml").read_text().replace("scale = 1.5", f"scale = {value}")
    text = text.replace('"../models/scene.xml"', json.dumps(job.table["plant"]["model"]))
    (tmp_path / "written.toml").write_text(text)
    written = load(tmp_path / "written.toml").with_overrides("kanayama", 3, 12.8)
    _same(run(parse(job.table, job.source)), run(written))
    point = tomllib.loads(job.config)  # config.toml holds the value, and re-runs the point
    assert point["events"][0]["scale"] == value
    _same(run(parse(point)), run(written))


def test_a_key_the_file_leaves_out_can_vary_and_the_values_take_the_files_type():
    jobs = plan(["paper"], ["corradini"], [0], 1.0, parse_vary(["controller.v_max=1,2", "warmup=0,1"]))
    assert [j.point for j in jobs] == [
        (("controller.v_max", 1.0), ("warmup", 0.0)),
        (("controller.v_max", 1.0), ("warmup", 1.0)),
        (("controller.v_max", 2.0), ("warmup", 0.0)),
        (("controller.v_max", 2.0), ("warmup", 1.0)),
    ]
    assert isinstance(jobs[0].table["controller"]["v_max"], float)


BAD_VARY = {  # --vary: the text the one line must hold
    "unknown key": (["no.such=1,2"], "--vary no.such: not a number of paper that can vary; it sets duration, T"),
    "a string key": (["plant.kind=1,2"], "it sets duration"),
    "the seed": (["seed=1,2"], "it sets duration"),
    "a reference class's parameter the file does not set": (
        ["reference.params.r=1,2", "OWN"],
        "own.toml sets no r in [reference.params] (your reference class's default is its own): write r = VALUE "
        "there to vary it",
    ),
    "a key of a file that sets no number": (
        ["plant.zz=1,2", "BARE"],
        "bare.toml that can vary; it sets no number; a key",
    ),
    "a point --duration makes wrong": (
        ["plant.fix_latency_s=0,5", "--duration", "2", "FUSED"],
        "--vary plant.fix_latency_s=5.0 with --duration 2: 5 s is not shorter than the run (2 s)",
    ),
    "a bad value": (["events.0.factor=1,-2"], "--vary events.0.factor=-2"),
    "not a number": (["events.0.factor=1,x"], "'x' is not a number"),
    "a range's count": (["events.0.factor=1:2:1"], "COUNT >= 2"),
    "no equals": (["events.0.factor"], "expected KEY=VALUES"),
    "twice": (["T=0.01", "T=0.02"], "given twice"),
    "a value twice": (["T=0.01,0.01"], "appears twice"),
    "an event never reached": (["events.0.time=1,30", "--duration", "25"], "--vary events.0.time=30: "),
    "a float steps": (["events.0.factor=1", "events.0.time=0.5"], None),  # fine: no error
    "uniform reversed": (["events.0.factor=uniform:2:1"], "low < high"),
    "normal sd 0": (["events.0.factor=normal:2:0"], "standard deviation > 0"),
    "a draw's end": (["events.0.factor=uniform:-1:2"], "its end -1"),
    "a whole number key": (["controller.adaptive.L_f=10.5"], "--vary controller.adaptive.L_f=10.5"),
    "threshold": (["T=0.01", "--threshold", "-1"], "--threshold"),
    "an event --duration leaves out": (["events.0.factor=2", "--duration", "1"], "left out by --duration 1: it would"),
    "an event time --duration leaves out": (["events.0.time=1,20"], "--vary events.0.time=20: the event would be left"),
    "a file's draw's end": (["FILE"], "drawn.toml events.0.factor = uniform(-1, 2) (its end -1): must be positive"),
    "duration beside --duration": (["duration=12,14"], "--vary duration: conflicts with --duration 13"),
    "a range of one value": (
        ["events.0.factor=1.5:1.5:3"],
        "--vary events.0.factor=1.5:1.5:3: the value 1.5 appears twice",
    ),
    "a range past the limit": (
        ["events.0.factor=1:2:1000000000"],
        "1000000000 values is more than the limit of 100000",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_VARY))
def test_bad_vary_is_one_line_and_nothing_runs(tmp_path, capsys, case):
    flags, needle = BAD_VARY[case]
    argv = ["sweep", "paper", "--seeds", "0", "--duration", "13", "--workers", "1", "--out", str(tmp_path / "o")]
    if flags == ["FILE"]:  # a distribution of the file whose support leaves the key's range
        (tmp_path / "drawn.toml").write_text(DRAWN.replace("[1.0, 2.0]", "[-1.0, 2.0]"))
        argv[1], flags = str(tmp_path / "drawn.toml"), []
    if flags[-1:] == ["FUSED"]:  # the fused pose's scenario, its fix latency an axis
        argv[1], flags = "eight-wheel-radius-fused", flags[:-1]
        argv = [a for i, a in enumerate(argv) if a != "--duration" and (i == 0 or argv[i - 1] != "--duration")]
    if flags[-1:] in (["OWN"], ["BARE"]):  # a file of a reference class that sets no [reference.params]
        (tmp_path / "c.py").write_text(OWN_CLASS)
        name = "own.toml" if flags[-1] == "OWN" else "bare.toml"
        kind = 'kind = "c.py:C"\n' if flags[-1] == "OWN" else ""
        (tmp_path / name).write_text(f'[plant]\nkind = "kinematic"\n[reference]\n{kind}')
        argv[1], flags = str(tmp_path / name), flags[:-1]
    for f in flags:
        argv += [f] if f.startswith("-") or argv[-1] in ("--threshold", "--duration") else ["--vary", f]
    if needle is None:
        assert main(argv) == 0
        return
    assert main(argv) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if not line.startswith("mlpfac: planning")]
    assert len(err) == 1 and needle in err[0], err
    assert not (tmp_path / "o").exists()


OWN_CLASS = """import math


class C:
    def __init__(self, r=1.0):
        self.r = r

    def sample(self, t):
        return (self.r * math.cos(t), self.r * math.sin(t), t + math.pi / 2, self.r, 1.0, 0.0, 0.0)
"""
DRAWN = """name = "drawn"
duration = 3.0
[plant]
kind = "kinematic"
noise_cov = { uniform = [1e-7, 1e-5] }
[controller]
lambdas = [0.8, { normal = [0.8, 0.02] }, 0.8]
[[events]]
time = 1.0
kind = "control_period"
factor = { uniform = [1.0, 2.0] }
"""


def test_a_draw_is_the_same_robot_for_every_controller_and_reruns_from_config_toml(tmp_path):
    (tmp_path / "drawn.toml").write_text(DRAWN)
    jobs = plan([str(tmp_path / "drawn.toml")], ["corradini", "kanayama"], [0, 1, 2], None)
    drawn = {(j.controller, j.seed): j.drawn for j in jobs}
    assert set(drawn[("corradini", 0)]) == {"plant.noise_cov", "controller.lambdas.1", "events.0.factor"}
    for seed in (0, 1, 2):
        assert drawn[("corradini", seed)] == drawn[("kanayama", seed)]
        assert 1.0 <= drawn[("corradini", seed)]["events.0.factor"] <= 2.0
    assert drawn[("corradini", 0)] != drawn[("corradini", 1)]
    job = jobs[1]
    scn = parse(job.table, job.source)
    assert (
        scn.events[0].factor == job.drawn["events.0.factor"] and scn.law.lambdas[1] == job.drawn["controller.lambdas.1"]
    )
    again = tomllib.loads(job.config)  # config.toml: the distributions, the seed and what they drew
    assert again["drawn"] == job.drawn and again["events"][0]["factor"] == {"uniform": [1.0, 2.0]}
    _same(run(parse(again)), run(scn))
    again["drawn"]["events.0.factor"] = 1.5  # edited: refused, not silently drawn again
    with pytest.raises(ConfigError, match=r"\[drawn\] events.0.factor: 1.5 is not what seed 1 draws"):
        parse(again)
    # the same draws given on the command line
    (tmp_path / "plain.toml").write_text(DRAWN.replace("{ uniform = [1.0, 2.0] }", "1.5"))
    flags = parse_vary(["events.0.factor=uniform:1:2"])
    (other,) = [j for j in plan([str(tmp_path / "plain.toml")], ["corradini"], [1], None, flags)]
    assert other.drawn["events.0.factor"] == job.drawn["events.0.factor"]


def test_draws_are_in_the_sweep_rows(tmp_path):
    (tmp_path / "drawn.toml").write_text(DRAWN)
    out = tmp_path / "out"
    assert main(["sweep", str(tmp_path / "drawn.toml"), "--controllers", "corradini", "--seeds", "0-2",
                 "--workers", "1", "--out", str(out)]) == 0  # fmt: skip
    rows = json.loads((out / "sweep.json").read_text())["rows"]
    draws = rows[-1]["draws"]
    assert [d["seed"] for d in draws] == [0, 1, 2]
    conf = tomllib.loads((out / "drawn/corradini/seed-0001/config.toml").read_text())
    assert draws[1]["events.0.factor"] == conf["drawn"]["events.0.factor"] and draws[1]["pos_rms_m"] > 0
    batched = tmp_path / "batched"  # each seed its own robot: batched, each runs alone, to the same table
    assert main(["sweep", str(tmp_path / "drawn.toml"), "--controllers", "corradini", "--seeds", "0-2",
                 "--workers", "1", "--batched", "--out", str(batched)]) == 0  # fmt: skip
    assert json.loads((batched / "sweep.json").read_text())["rows"] == rows


def test_leaves_are_every_number_by_its_dotted_key():
    keys = leaves(load("paper", build=False).table)
    assert {"T", "duration", "events.0.factor", "events.0.time", "controller.lambdas.2", "plant.noise_cov"} <= set(keys)
    assert "seed" not in keys


def test_the_median_interval_covers_95_percent():
    assert median_interval([1.0] * 5) == (None, None)
    lo, hi = median_interval([float(i) for i in range(1, 11)])  # n = 10: the 2nd and 9th values (97.9 %)
    assert (lo, hi) == (2.0, 9.0)


def test_breaking_points_go_away_from_the_nominal_value():
    holds = {0.5: False, 0.75: True, 1.0: True, 1.25: True, 1.5: False, 1.75: True, 2.0: False}
    rows = [{"scenario": "s", "controller": "c", "point": {"k": v}, "holds": h} for v, h in holds.items()]
    (b,) = breaking_points(rows, {("s", "k"): 1.0})
    assert b["below"] == {"holds_to": 0.75, "fails_at": 0.5, "whole_axis": False}
    assert b["above"] == {"holds_to": 1.25, "fails_at": 1.5, "whole_axis": False}  # 1.75 holds again: not counted
    (b,) = breaking_points(rows[1:4], {("s", "k"): 1.0})
    assert b["above"]["whole_axis"] and b["above"]["holds_to"] == 1.25


def test_a_law_breaks_where_its_speed_limit_falls_below_the_reference(tmp_path, capsys):
    """A known case: on the kinematic plant without noise Corradini's law tracks the figure of eight
    while v_max is above the reference's top speed, and loses it once v_max is below the speed it
    must keep on average (it falls behind by the difference every second)."""
    from mlpfac.scenario.reference import sample

    scn = load("paper", build=False)
    ref = sample(scn.reference, np.arange(2500) * scn.T)
    top, mean = float(ref[:, 3].max()), float(ref[:, 3].mean())
    values = [round(x, 4) for x in (0.5 * mean, 0.8 * mean, 1.05 * top, 1.5 * top, 2.0)]
    out = tmp_path / "out"
    argv = ["sweep", "paper", "--controllers", "corradini", "--seeds", "0-1", "--duration", "20", "--workers", "1",
            "--vary", "controller.v_max=" + ",".join(map(str, values)), "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    robust = json.loads((out / "robustness.json").read_text())
    (b,) = robust["breaking_points"]
    assert b["nominal"] == 2.0 and b["below"]["holds_to"] == values[2] and b["below"]["fails_at"] == values[1]
    assert (out / "robustness.png").stat().st_size > 10_000 and "holds down to" in (out / "robustness.md").read_text()
    rows = json.loads((out / "sweep.json").read_text())["rows"]
    assert [r["vary"]["controller.v_max"] for r in rows if r["phase"] == "before"] == values
    assert main(argv) == 0  # resumed: the grid is known, nothing runs again
    assert json.loads((out / "robustness.json").read_text())["breaking_points"] == robust["breaking_points"]
    (out / "robustness.png").unlink()
    assert main(["plot", str(out)]) == 0 and (out / "robustness.png").is_file() and not (out / "sweep.png").exists()
    from mlpfac.report.results import render

    assert (out / "robustness.md").read_text() == render(out, {"view": "robustness"})
    panels = tmp_path / "axes.png"  # the curves of several sweeps in one figure: this one's twice
    assert main(["plot", str(out), str(out), "--panels", str(panels)]) == 0 and panels.stat().st_size > 10_000
    edited = tmp_path / "edited"  # a robustness.json edited by hand: one line naming it, nothing written
    edited.mkdir()
    (edited / "robustness.json").write_text('{"curves": [{"scenario": "x", "point": {"k": 1}}]}')
    capsys.readouterr()
    assert main(["plot", str(out), str(edited), "--panels", str(tmp_path / "no.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"mlpfac: error: {edited / 'robustness.json'} curves[0].controller: missing"
    assert not (tmp_path / "no.png").exists()


V_MAX = [0.3, 0.6, 1.2, 1.6, 2.0]  # below the figure of eight's mean speed (0.77 m/s), above its top (1.12)
CHECKED = f'scenarios = ["paper"]\ncontrollers = ["corradini"]\nseeds = "0-1"\nduration = 20.0\nvary = ["controller.v_max={",".join(map(str, V_MAX))}"]\n'


@pytest.fixture(scope="module")
def budget_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("breaking")


def _check(d: Path, text: str, *flags: str) -> int:
    (d / "budget.toml").write_text(text)
    return main(["check", str(d / "budget.toml"), "--out", str(d / "runs"), "--workers", "1", *flags])


def test_an_axis_of_one_value_is_a_setting(tmp_path):
    """``--vary controller.v_max=1e9`` beside a real axis (the limits off while the speed varies): the
    breaking points and the curves are the speed's alone, the setting said in the curves' heading."""
    out = tmp_path / "out"
    argv = ["sweep", "paper", "--controllers", "kanayama", "--seeds", "0", "--duration", "3", "--workers", "1",
            "--vary", "reference.speed=1,1.5", "--vary", "controller.v_max=1e9", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    robust = json.loads((out / "robustness.json").read_text())
    assert [b["axis"] for b in robust["breaking_points"]] == ["reference.speed"]
    assert all(
        r["point"].keys() == {"reference.speed"} and r["set"] == {"controller.v_max": 1e9} for r in robust["curves"]
    )
    assert "| paper: `reference.speed`, controller.v_max = 1e+09 | 1 | 1.5 |" in (out / "robustness.md").read_text()


def test_check_holds_a_controller_to_its_breaking_point(budget_dir, capsys):
    from mlpfac.scenario.reference import sample

    ref = sample(load("paper", build=False).reference, np.arange(2000) * 0.01)
    assert V_MAX[1] < ref[:, 3].mean() < V_MAX[2] and ref[:, 3].max() < V_MAX[2]
    holds = CHECKED + '[[budget]]\nname = "slow wheels"\nholds_down_to = 1.2\n'
    junit = budget_dir / "check.xml"
    assert _check(budget_dir, holds, "--junit", str(junit), "--summary", str(budget_dir / "check.md")) == 0
    assert (
        "pass | paper | corradini | after the change | holds_down_to | <= 1.20 | 1.20"
        in (budget_dir / "check.md").read_text()
    )
    assert (budget_dir / "runs/robustness.json").is_file() and 'failures="0"' in junit.read_text()
    capsys.readouterr()
    misses = CHECKED + "[[budget]]\nholds_down_to = 0.6\n"
    assert _check(budget_dir, misses, "--junit", str(junit)) == 1
    out = capsys.readouterr().out
    assert "miss: paper / corradini / after the change: holds_down_to 1.20 (fails at 0.6), limit <= 0.60" in out
    assert "0 run now" in out  # the grid's runs were resumed
    assert 'failures="1"' in junit.read_text()


BAD_BUDGETS = {
    "no axis": ('scenarios = ["paper"]\n[[budget]]\nholds_up_to = 2\n', "budget.toml vary: holds_up_to"),
    "not an axis": (CHECKED + '[[budget]]\naxis = "T"\nholds_down_to = 0.3\n', "budget #1 axis: 'T' is not an axis"),
    "beyond the axis": (CHECKED + "[[budget]]\nholds_down_to = 0.2\n", "no grid point reaches it"),
    "with another figure": (CHECKED + "[[budget]]\nholds_down_to = 0.3\nlost = 0\n", "budget #1 lost"),
    "a phase": (CHECKED + '[[budget]]\nholds_down_to = 0.3\nphase = "after"\n', "budget #1 phase"),
    "vary not a list": ('scenarios = ["paper"]\nvary = "T=1"\n[[budget]]\nlost = 0\n', "budget.toml vary"),
    "a bad value": ('scenarios = ["paper"]\nvary = ["T=0.01,-1"]\n[[budget]]\nlost = 0\n', "vary: --vary T=-1"),
    "threshold": (CHECKED + "threshold_m = 0\n[[budget]]\nholds_down_to = 0.3\n", "threshold_m"),
    "a setting as its axis": (
        CHECKED.rstrip("]\n") + ', "T=0.01"]\n[[budget]]\naxis = "T"\nholds_down_to = 0.3\n',
        "budget #1 axis: 'T' is not an axis of vary of more than one value (controller.v_max)",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_BUDGETS))
def test_a_bad_breaking_budget_is_one_line(tmp_path, capsys, case):
    text, needle = BAD_BUDGETS[case]
    assert _check(tmp_path, text) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if not line.startswith("mlpfac: planning")]
    assert len(err) == 1 and needle in err[0], err
    assert not (tmp_path / "runs").exists()


def test_the_python_api_varies_as_the_command_line(tmp_path):
    import mlpfac

    vary = {"events.0.factor": [1.0, 2.0], "plant.noise_cov": {"uniform": [1e-7, 1e-6]}}
    rows = mlpfac.sweep("paper", ["corradini"], seeds="0-1", duration=13.0, workers=1, vary=vary, out=tmp_path / "o")
    assert [r["vary"] for r in rows if r["phase"] == "before"] == [{"events.0.factor": 1.0}, {"events.0.factor": 2.0}]
    assert rows.robustness["meta"]["vary"] == ["events.0.factor=1.0,2.0", "plant.noise_cov=uniform:1e-07:1e-06"]
    assert [d["seed"] for d in rows[0]["draws"]] == [0, 1]
    with pytest.raises(ConfigError, match=r"--vary events.0.factor=-1"):
        mlpfac.sweep("paper", ["corradini"], seeds="0", workers=1, vary={"events.0.factor": [-1]})


def test_a_grid_with_draws_on_dask_gives_the_local_table(tmp_path):
    distributed = pytest.importorskip("distributed")
    from mlpfac.sweeps import engine

    (tmp_path / "drawn.toml").write_text(DRAWN)
    jobs = plan([str(tmp_path / "drawn.toml")], ["corradini"], [0, 1], None, parse_vary(["controller.v_max=1,2"]))
    local = engine.execute(jobs, tmp_path / "local", workers=2)
    with distributed.LocalCluster(
        host="127.0.0.1", n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        client = engine.connect(cluster.scheduler_address, timeout=30)
        try:
            remote = engine.execute(jobs, tmp_path / "dask", client=client)
        finally:
            client.close()
    assert len(remote.metrics) == 4 and engine.aggregate(jobs, remote.metrics) == engine.aggregate(jobs, local.metrics)
    for j in jobs:
        assert (j.folder(tmp_path / "dask") / "config.toml").read_text() == j.config


def test_a_grid_of_two_axes_is_a_table_a_controller_and_a_controller_key_has_its_default_nominal(tmp_path):
    """``--vary reference.speed=1,1.5 --vary controller.kanayama.Kx=5,10,20``: the file leaves Kx out,
    so its nominal value is the table's default (10), not the axis's first; the curves are a table
    per controller, the speed across and Kx down."""
    out = tmp_path / "out"
    argv = ["sweep", "paper", "--controllers", "kanayama,corradini", "--seeds", "0", "--duration", "3",
            "--workers", "1", "--vary", "reference.speed=1,1.5", "--vary", "controller.kanayama.Kx=5,10,20",
            "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    robust = json.loads((out / "robustness.json").read_text())
    kx = [b for b in robust["breaking_points"] if b["axis"] == "controller.kanayama.Kx"]
    assert len(kx) == 4 and all(b["nominal"] == 10.0 for b in kx)  # 2 controllers x 2 speeds
    text = (out / "robustness.md").read_text()
    for ctrl in ("kanayama", "corradini"):
        head = f"| paper, {ctrl}: `controller.kanayama.Kx` \\ `reference.speed` | 1 | 1.5 |"
        rows = text.split(head)[1].splitlines()[2:5]
        assert [r.split(" | ")[0] for r in rows] == ["| 5", "| 10", "| 20"]
        assert all(len(r.split(" | ")) == 3 for r in rows)


def test_a_friction_axis_is_measured_from_the_robots_own_friction(tmp_path):
    """``eight-friction`` sets mu = 0.2; along ``events.0.mu`` the nominal value is the robot's own
    tyre friction (1, which the event changes), not the file's 0.2, so the axis goes down from 1."""
    out = tmp_path / "out"
    argv = ["sweep", "eight-friction", "--controllers", "kanayama", "--seeds", "0", "--duration", "13",
            "--workers", "1", "--vary", "events.0.mu=0.5,1", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    (b,) = json.loads((out / "robustness.json").read_text())["breaking_points"]
    assert b["nominal"] == 1.0 and b["below"] == {"holds_to": 0.5, "fails_at": None, "whole_axis": True}
    assert "above" not in b


@pytest.mark.menagerie
def test_on_a_robot_the_speed_axis_runs_the_fitted_path_faster_and_a_limit_asked_for_wins():
    """``--robot pal_tiago --vary reference.speed=...``: the path is fitted to TIAGo once (the same wx,
    wy at every speed) and run ``speed`` times as fast; a controller limit the axis sets is not replaced
    by the robot's."""
    one = load("eight-nominal", robot="pal_tiago", values={"reference.speed": 1.0})
    two = load("eight-nominal", robot="pal_tiago", values={"reference.speed": 2.0, "controller.v_max": 1e9})
    assert one.reference.wx < 0.1 and "reference x0.22" in one.table["description"]  # its 5 rad/s wheels slow it
    assert (two.reference.wx, two.reference.wy, two.reference.speed) == (one.reference.wx, one.reference.wy, 2.0)
    assert one.table["controller"]["v_max"] < 2.0 and two.table["controller"]["v_max"] == 1e9
