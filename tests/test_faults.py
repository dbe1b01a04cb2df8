"""Faults of the unlucky user, each said in one line or ending the run as what it is: MuJoCo's
warnings end a run as diverged (nothing written outside it), a model MuJoCo cannot simulate, stdout
on a full disk, a corrupt metrics.json, report's bad pages, a controller's sys.exit, metrics that
blew up, a read-only HOME, a scheduler that never answers, the Python API's wrong types. Each test
fails without its fix."""

from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import test_targets
from test_targets import _cli, _one_line

import mlpfac
from mlpfac.cli import main
from mlpfac.exceptions import ConfigError, MlpfacError

here = test_targets.here  # the fixture: a folder with kin.toml and b.toml, the current one

# --- MuJoCo's warnings --------------------------------------------------------------------------

HUGE = """
class Huge:
    def __init__(self, T):
        self.k = 0

    def reset(self, rng):
        self.k = 0

    def step(self, e, r):
        self.k += 1
        return (1e200, 0.0) if self.k > 20 else (0.1, 0.0)
"""


def test_a_mujoco_warning_ends_the_run_as_diverged_and_writes_nothing_outside(here):
    """An absurd command: MuJoCo warns (a huge value in CTRL) and zeroes it; the run ends there as
    diverged with MuJoCo's words, and no MUJOCO_LOG.TXT appears in the current folder."""
    (here / "huge.py").write_text(HUGE)
    (here / "w.toml").write_text('duration = 1.0\n[plant]\nkind = "mujoco"\nmax_wheel_speed = inf\n')
    proc = _cli("run", "w.toml", "--controller", "huge.py:Huge", "--no-log", "--no-plot", "--out", "o", cwd=here)
    assert proc.returncode == 1, proc.stderr
    m = json.loads((here / "o" / "metrics.json").read_text())
    assert m["status"] == "diverged" and m["reason"].startswith("MuJoCo warned: Nan, Inf or huge value in CTRL")
    assert m["steps"] == 21
    assert not list(here.rglob("MUJOCO_LOG.TXT")) and "MuJoCo" not in proc.stdout.split("\n", 2)[-1]


def test_a_warning_marks_the_robot_stepping_and_ends_a_compiled_segment():
    """The handler marks the robot whose step warned; its divergence test (compiled, in every step
    of a segment too) then says so."""
    from mlpfac.loop.runner import build
    from mlpfac.plants.mujoco import compiled
    from mlpfac.scenario.parse import load

    scn = load("eight-nominal").with_overrides("kanayama", duration=0.5)
    built = build(scn)
    plant = built.plant
    plant.reset(np.zeros(3), np.random.default_rng(0))
    plant.kernel_args()  # as the compiled loop names the robot before its segment
    assert plant.diverged() is None
    compiled._warning(b"Nan, Inf or huge value in QACC at DOF 0. The simulation is unstable. Time = 0.1.")
    assert plant.diverged().startswith("MuJoCo warned: Nan, Inf or huge value in QACC")
    rec = mlpfac.run(scn)  # a new reset clears the mark
    assert rec.status == "ok"


def test_a_model_mujoco_cannot_simulate_is_one_line(here, capsys):
    """A model whose arena is too small (<size memory="4K"/>): MuJoCo's fatal error is one line, exit 2."""
    from mlpfac.scenario.parse import shipped_dir

    models = shipped_dir().parent / "models"
    for f in models.glob("*.xml"):
        (here / f.name).write_text(f.read_text())
    scene = here / "scene.xml"
    scene.write_text(
        scene.read_text().replace(
            '<include file="diffdrive.xml"/>', '<include file="diffdrive.xml"/><size memory="4K"/>'
        )
    )
    (here / "m.toml").write_text('[plant]\nkind = "mujoco"\nmodel = "scene.xml"\n')
    assert main(["run", "m.toml", "--no-log", "--no-plot", "--out", "o"]) == 2
    assert "MuJoCo cannot simulate the model: mj_stackAlloc: out of memory" in _one_line(capsys.readouterr().err)
    assert not (here / "o").exists()


# --- one line instead of a traceback; no silent or wrong answer ---------------------------------


SYS_EXIT = """
import sys


class Quits:
    def __init__(self, T):
        pass

    def reset(self, rng):
        pass

    def step(self, e, r):
        sys.exit(5)
"""


def test_a_controller_that_calls_sys_exit_is_its_failure(here):
    (here / "quits.py").write_text(SYS_EXIT)
    proc = _cli("run", "kin.toml", "--controller", "quits.py:Quits", "--no-log", "--no-plot", "--out", "o", cwd=here)
    assert proc.returncode == 1, proc.stderr
    assert "controller 'Quits' raised in step: SystemExit: 5" in proc.stderr


@pytest.mark.parametrize("command", [["list"], ["run", "kin.toml", "--no-log", "--no-plot", "--out", "o"],
                                     ["sweep", "kin.toml", "--seeds", "0", "--workers", "1", "--out", "S"],
                                     ["check", "b.toml", "--workers", "1", "--out", "C"]])  # fmt: skip
def test_stdout_on_a_full_disk_is_one_line(here, command):
    with open("/dev/full", "w") as full:
        proc = subprocess.run(
            [sys.executable, "-m", "mlpfac.cli", *command], stdout=full, stderr=subprocess.PIPE, text=True, cwd=here
        )
    assert proc.returncode == 2, proc.stderr
    assert _one_line(proc.stderr) == "mlpfac: error: stdout: cannot write (No space left on device)"


def test_a_file_size_limit_in_a_run_without_log_or_plot_is_one_line(here):
    import resource

    def small() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (200, 200))

    proc = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", "run", "kin.toml", "--no-log", "--no-plot", "--out", "o"],
        capture_output=True, text=True, cwd=here, preexec_fn=small,
    )  # fmt: skip
    assert proc.returncode == 2 and "o/" in _one_line(proc.stderr), proc.stderr
    assert not (here / "o").exists()


@pytest.mark.parametrize("name", ["x" * 300, "x" * 250, "/".join(["x" * 200] * 25)])
def test_a_name_too_long_for_out_is_one_line_naming_out(here, capsys, name):
    """Too long for the file system: the name itself, the name it has while staged beside its
    place, or the whole path; found before the run."""
    assert main(["run", "kin.toml", "--no-log", "--no-plot", "--out", name]) == 2
    line = _one_line(capsys.readouterr().err)
    assert line.startswith(f"mlpfac: error: --out {name}: ") and "long" in line, line
    assert sorted(p.name for p in here.iterdir()) == ["b.toml", "kin.toml"]


def test_plot_of_a_corrupt_metrics_json_is_one_line(here, capsys):
    assert main(["sweep", "kin.toml", "--seeds", "0", "--workers", "1", "--out", "S"]) == 0
    (m,) = here.glob("S/*/*/seed-*/metrics.json")
    data = json.loads(m.read_text())
    data["phases"] = {"before": "not a table"}
    m.write_text(json.dumps(data))
    capsys.readouterr()
    assert main(["plot", "S"]) == 2
    assert "a metrics.json under it is not what a run writes" in _one_line(capsys.readouterr().err)


REPORT_PAGES = {
    "unclosed marker": ("# p\n<!-- table: data/x view=summary -->\n| a |\n", "page.md:2: a table marker without"),
    "wrong-typed rows": (
        "<!-- table: data/x view=sweep -->\n<!-- /table -->\n",
        "data/x/sweep.json rows[0].runs: expected a number or null, got 'many'",
    ),
    "a row without a field": (
        "<!-- table: data/x view=summary -->\n<!-- /table -->\n",
        "data/x/paired.json: a row has no field 'pos_rms_m_median'",
    ),
    "a robustness row of the wrong type": (
        "<!-- table: data/x view=robustness -->\n<!-- /table -->\n",
        "data/x/robustness.json curves[0].median_m: expected a number or null, got 'far'",
    ),
}


@pytest.mark.parametrize("case", sorted(REPORT_PAGES))
def test_report_of_a_bad_page_or_data_is_one_line(here, capsys, case):
    page, needle = REPORT_PAGES[case]
    docs = here / "docs"
    (docs / "data" / "x").mkdir(parents=True)
    (docs / "page.md").write_text(page)
    rows = [{"scenario": "s", "controller": "c", "phase": "before", "runs": "many", "pos_rms_m_mean": "x"}]
    (docs / "data" / "x" / "sweep.json").write_text(json.dumps({"meta": {}, "rows": rows}))
    paired = [{"scenario": "s", "controller": "c", "phase": "before", "runs": 1}]
    (docs / "data" / "x" / "paired.json").write_text(json.dumps({"meta": {}, "rows": paired}))
    curve = dict(CURVE, median_m="far")
    (docs / "data" / "x" / "robustness.json").write_text(
        json.dumps({"meta": {}, "curves": [curve], "breaking_points": []})
    )
    assert main(["report", "docs"]) == 2
    assert needle in _one_line(capsys.readouterr().err)
    assert (docs / "page.md").read_text() == page


CURVE = {"scenario": "s", "controller": "c", "point": {"events.0.scale": 2.0}, "runs": 6, "finished": 6,
         "tracking": 0, "tracking_share": 0.0, "median_m": math.inf, "ci_lo_m": 0.5, "ci_hi_m": math.inf,
         "threshold_m": 0.2, "bound_m": 0.01, "holds": False}  # fmt: skip


def test_robustness_json_of_diverged_runs_is_json_and_reads_back_infinite(tmp_path):
    """A median over runs that diverged is infinite: null in the file (JSON has no Infinity), as in
    metrics.json, and infinite again when read (the file of an earlier version, with Infinity, too)."""
    from mlpfac.plots.robustness import read_robustness
    from mlpfac.sweeps.robustness import _finite

    data = {"meta": {"threshold_m": None}, "curves": [CURVE], "breaking_points": []}
    text = json.dumps(_finite(data), allow_nan=False)
    assert '"median_m": null' in text and '"ci_hi_m": null' in text and "Infinity" not in text
    for written in (text, json.dumps(data)):  # now, and as an earlier version wrote it
        (tmp_path / "robustness.json").write_text(written)
        (row,) = read_robustness(tmp_path / "robustness.json")["curves"]
        assert row == CURVE
    shipped = Path(__file__).resolve().parents[1] / "docs" / "data"
    for f in shipped.glob("*/robustness.json"):
        json.loads(f.read_text(), parse_constant=lambda name, f=f: pytest.fail(f"{f} holds {name}"))


def test_plot_panels_over_a_wrong_typed_robustness_json_is_one_line_and_keeps_the_png(here, capsys):
    (here / "S").mkdir()
    (here / "S" / "robustness.json").write_text(json.dumps({"meta": {}, "curves": [dict(CURVE, point=5)]}))
    (here / "out.png").write_bytes(b"earlier")
    assert main(["plot", "S", "--panels", "out.png"]) == 2
    assert _one_line(capsys.readouterr().err).endswith("robustness.json curves[0].point: expected a table, got 5")
    assert (here / "out.png").read_bytes() == b"earlier"
    (here / "S" / "robustness.json").write_text(json.dumps({"meta": {}, "curves": [dict(CURVE, tracking="all")]}))
    assert main(["plot", "S"]) == 2
    assert _one_line(capsys.readouterr().err).endswith("curves[0].tracking: expected a number, got 'all'")
    for meta, curve, where in (({"threshold_m": 1e308}, CURVE, "meta.threshold_m"),
                               ({}, dict(CURVE, threshold_m=1e308), "curves[0].threshold_m")):  # fmt: skip
        (here / "S" / "robustness.json").write_text(json.dumps({"meta": meta, "curves": [curve]}))
        assert main(["plot", "S", "--panels", "out.png"]) == 2  # a threshold drawn on a log scale: not absurd
        assert f"robustness.json {where}: must be a number of metres above 0" in _one_line(capsys.readouterr().err)
        assert (here / "out.png").read_bytes() == b"earlier"


def test_a_baseline_holding_nan_is_a_bad_baseline(here, capsys):
    assert main(["sweep", "kin.toml", "--seeds", "0-1", "--workers", "1", "--out", "B"]) == 0
    (m, *_) = sorted(here.glob("B/*/*/seed-*/metrics.json"))
    m.write_text(m.read_text().replace('"rms_position_error_m": ', '"rms_position_error_m": NaN, "x": ', 1))
    budget = 'scenarios = ["kin.toml"]\nseeds = "0-1"\n[[budget]]\nno_worse_than_baseline = 1.1\n'
    (here / "nan.toml").write_text(budget)
    capsys.readouterr()
    assert main(["check", "nan.toml", "--baseline", "B", "--workers", "1", "--out", "C"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert line.startswith(f"mlpfac: error: --baseline {m.relative_to(here)}: holds NaN"), line
    assert not (here / "C").exists()


def test_metrics_of_a_run_that_blew_up_are_json_without_warnings():
    rec = mlpfac.run("paper", controller="corradini", duration=0.5)
    rec.e_true[: rec.n] = 1e300  # squares overflow
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = mlpfac.metrics(rec)
    json.dumps(m, allow_nan=False)
    assert m["rms_position_error_m"] is None


def test_a_read_only_home_prints_no_matplotlib_warning(here):
    env = {k: v for k, v in os.environ.items() if k not in ("MPLCONFIGDIR", "XDG_CONFIG_HOME", "XDG_CACHE_HOME")}
    home = here / "home"
    home.mkdir(mode=0o555)
    proc = _cli("run", "kin.toml", "--no-log", "--out", "o", cwd=here, env=env | {"HOME": str(home)})
    if os.access(home, os.W_OK):  # root writes anywhere: point HOME at a path nobody can create
        proc = _cli("run", "kin.toml", "--no-log", "--out", "o", cwd=here, env=env | {"HOME": "/proc/none"})
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert (here / "o" / "figure1.png").is_file()


def test_a_scheduler_that_accepts_and_never_answers_times_out(here):
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    port = server.getsockname()[1]
    try:
        proc = _cli("sweep", "kin.toml", "--seeds", "0", "--out", "S", "--scheduler", f"tcp://127.0.0.1:{port}",
                    "--scheduler-timeout", "1", cwd=here, timeout=300)  # fmt: skip
    finally:
        server.close()
    assert proc.returncode == 2 and "--scheduler: cannot reach a Dask scheduler" in _one_line(proc.stderr)


# --- the Python API -----------------------------------------------------------------------------

API_CALLS = {
    "run(42)": (lambda: mlpfac.run(42), "scenario"),
    "run(out='')": (lambda: mlpfac.run("paper", out=""), "out"),
    "sweep(42)": (lambda: mlpfac.sweep(42), "scenarios"),
    "sweep(seeds=None)": (lambda: mlpfac.sweep("paper", seeds=None), "seeds"),
    "sweep(workers='2')": (lambda: mlpfac.sweep("paper", workers="2"), "workers"),
    "sweep(controllers=42)": (lambda: mlpfac.sweep("paper", 42), "controllers"),
    "sweep(out=3.5)": (lambda: mlpfac.sweep("paper", out=3.5), "out"),
    "sweep(scheduler=42)": (lambda: mlpfac.sweep("paper", scheduler=42), "scheduler"),
    "check(42)": (lambda: mlpfac.check(42), "budget"),
    "check(workers='2')": (lambda: mlpfac.check("b.toml", workers="2"), "--workers"),
    "sweep(vary=42)": (lambda: mlpfac.sweep("paper", ["kanayama"], vary=42), "vary"),
    "sweep(vary=a huge range)": (lambda: mlpfac.sweep("paper", ["kanayama"], vary={"T": "0.01:0.02:1000000000"}), "--vary T=0.01:0.02:1000000000"),
    "scenario.load(42)": (lambda: mlpfac.scenario.load(42), "scenario"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(API_CALLS))
def test_the_api_names_the_argument_of_a_wrong_type(here, case):
    call, name = API_CALLS[case]
    with pytest.raises(ConfigError) as exc:
        call()
    assert exc.value.where == name and isinstance(exc.value, MlpfacError), exc.value
    assert sorted(p.name for p in here.iterdir()) == ["b.toml", "kin.toml"]


def test_a_mujoco_compile_error_is_one_line(here, capsys):
    (here / "bad.xml").write_text('<mujoco><worldbody><body><geom type="sphere"/></body></worldbody></mujoco>')
    (here / "m.toml").write_text('[plant]\nkind = "mujoco"\nmodel = "bad.xml"\n')
    assert main(["run", "m.toml", "--no-log", "--no-plot", "--out", "o"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "MuJoCo cannot load the model: Error: size 0 must be positive in geom Element name" in line, line


# --- the recording written beside the run --------------------------------------------------------

ONLY_THE_CHILD = """
import sys
from mlpfac.cli import main
code = main(["run", "kin.toml", "--no-plot", "--out", "o"])
print(code, "rerun" in sys.modules)
"""


def test_a_short_runs_recording_is_written_by_a_child_and_a_lost_one_is_replaced(here, monkeypatch, capsys):
    """The command's process never imports rerun (a child forked before the run writes run.rrd and
    reads it back); a child that is gone before it writes leaves the recording to the command."""
    proc = subprocess.run([sys.executable, "-c", ONLY_THE_CHILD], capture_output=True, text=True, cwd=here)
    assert proc.stdout.splitlines()[-1] == "0 False", proc.stdout + proc.stderr
    assert (here / "o" / "run.rrd").stat().st_size > 10_000
    from mlpfac.runs import writer

    monkeypatch.setattr(writer, "_child", lambda *fds: os._exit(0))  # forked, then gone at once
    assert main(["run", "kin.toml", "--no-plot", "--out", "p"]) == 0
    assert capsys.readouterr().err == ""
    from mlpfac.log.sinks import check_recording

    check_recording(here / "p" / "run.rrd")  # whole
