"""The command line: outputs of a run, and one clear line with exit code 2 for bad input."""

import json
import os
import subprocess
import sys

import pytest

from mlpfac.cli import main
from mlpfac.loop.metrics import outcome_words


def test_run_writes_metrics_config_and_figure(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "paper", "--duration", "1", "--seed", "3", "--out", str(out), "--no-log"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    for key in (
        "status",
        "controller",
        "seed",
        "rms_position_error_m",
        "max_position_error_m",
        "rms_heading_error_rad",
        "phases",
        "excluded_s",
        "max_abs_weight",
        "mean_diag_P_final",
        "sim_time_s",
        "wall_time_s",
    ):
        assert key in m
    assert m["seed"] == 3 and m["controller"] == "adaptive" and m["status"] == "ok"
    assert "seed = 3" in (out / "config.toml").read_text()
    assert (out / "figure1.png").stat().st_size > 10_000
    first = capsys.readouterr().out.splitlines()[0]  # what happened, first
    assert first.startswith(f"paper / adaptive / seed 3: {m['outcome']}: ") and "position RMS" in first, first


PHASES = {"before": {"start_s": 2.0, "end_s": 12.5, "rms_position_error_m": 0.004},
          "after": {"start_s": 12.5, "end_s": 25.0, "rms_position_error_m": 0.25}}  # fmt: skip
WORDS = {  # a metrics.json's outcome, threshold, phases: the sentence the first line, the figure and the viewer say
    "tracking": ({"outcome": "tracking", "lost_threshold_m": 0.3, "path_size_m": 1.0, "phases": PHASES},
                 "tracking: every phase's position RMS (at most 250 mm) is within 0.3 m (lost_threshold_m)"),
    "lost after the event": ({"outcome": "lost", "lost_threshold_m": 0.2, "path_size_m": 4.0, "phases": PHASES},
                             "lost: the position RMS after the event (250 mm) is beyond 0.2 m (5 % of the path's 4 m size)"),
    "lost without an event": ({"outcome": "lost", "lost_threshold_m": 0.2, "path_size_m": 4.0, "excluded_s": [0, 2],
                               "phases": {"before": PHASES["after"]}},
                              "lost: the position RMS after the 2 s warm-up (250 mm) is beyond 0.2 m"),
    "within the warm-up": ({"outcome": "lost", "lost_threshold_m": 0.0839, "path_size_m": 1.678, "excluded_s": [0, 2],
                            "rms_position_error_m": 1.8, "phases": {"before": {"start_s": 2, "end_s": 2,
                                                                               "rms_position_error_m": None}}},
                           "lost: the whole run's position RMS 1.8 m is beyond 0.0839 m (5 % of the path's 1.68 m size); "
                           "the run ends within its warm-up, so the warm-up is judged too"),
    "diverged": ({"outcome": "diverged", "status": "diverged", "reason": "position error 5.01 m beyond 5 m"},
                 "diverged (position error 5.01 m beyond 5 m)"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(WORDS))
def test_a_runs_outcome_is_said_in_the_word_metrics_json_records_its_threshold_explained(case):
    m, words = WORDS[case]
    if m.get("lost_threshold_m") == 0.2 or m.get("path_size_m") == 1.678:
        m["lost_threshold_m"] = 0.05 * m["path_size_m"]  # the default: 5 % of the path's size
    assert outcome_words(m).startswith(words), outcome_words(m)
    assert "ok" not in outcome_words(m).split()


def test_a_run_within_its_warm_up_is_judged_on_what_it_has(tmp_path, capsys):
    """A 2 s run ends within the 2 s warm-up: no phase has a step, so the outcome is judged over the
    whole run (a robot left behind is lost, not "tracking" for want of a phase), the first line says
    so, and no empty phase is printed."""
    out = tmp_path / "run"
    table = 'duration = 2.0\n[plant]\nkind = "kinematic"\n[reference]\nkind = "eight"\nspeed = 4.0\n'
    (tmp_path / "fast.toml").write_text(table + '[controller]\nname = "corradini"\nv_max = 0.01\n')
    assert main(["run", str(tmp_path / "fast.toml"), "--no-log", "--no-plot", "--out", str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    lines = capsys.readouterr().out.splitlines()
    assert m["outcome"] == "lost" and m["phases"]["before"]["rms_position_error_m"] is None, m
    assert (
        lines[0].startswith("fast / corradini / seed 0: lost: the whole run's position RMS") and "warm-up" in lines[0]
    )
    assert not any("[2, 2)" in line for line in lines), lines


def test_the_lost_threshold_is_a_key_and_a_flag_and_is_said(tmp_path, capsys):
    """lost_threshold_m in the file, or --lost-threshold over it: the run judged against it, metrics.json
    and config.toml hold it, the first line says it; bad values named by the key or the flag."""
    (tmp_path / "s.toml").write_text('duration = 3.0\nlost_threshold_m = 1e-5\n[controller]\nname = "kanayama"\n')
    out = tmp_path / "a"
    assert main(["run", str(tmp_path / "s.toml"), "--no-log", "--no-plot", "--out", str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["outcome"] == "lost" and m["lost_threshold_m"] == 1e-5
    assert "beyond 1e-05 m (lost_threshold_m)" in capsys.readouterr().out.splitlines()[0]
    flag = ["--lost-threshold", "2.5", "--out", str(tmp_path / "b")]
    assert main(["run", str(tmp_path / "s.toml"), "--no-log", "--no-plot", *flag]) == 0
    assert json.loads((tmp_path / "b" / "metrics.json").read_text())["lost_threshold_m"] == 2.5
    assert "lost_threshold_m = 2.5" in (tmp_path / "b" / "config.toml").read_text()
    assert "within 2.5 m (lost_threshold_m)" in capsys.readouterr().out.splitlines()[0]


def test_config_toml_reproduces_the_run(tmp_path):
    out = tmp_path / "a"
    main(["run", "paper", "--duration", "1", "--seed", "5", "--out", str(out), "--no-log", "--no-plot"])
    again = tmp_path / "b"
    main(["run", str(out / "config.toml"), "--out", str(again), "--no-log", "--no-plot"])
    a, b = (json.loads((d / "metrics.json").read_text()) for d in (out, again))
    assert a["rms_position_error_m"] == b["rms_position_error_m"] and a["max_abs_weight"] == b["max_abs_weight"]


BAD_FILES = {
    "eigenvalue": ("[controller]\nlambdas = [0.8, 1.1, 0.8]\n", "lambdas"),
    "period": ("T = 0.0\n", "T"),
    "noise": ('[plant]\nkind = "kinematic"\nnoise_cov = -1e-6\n', "noise_cov"),
    "ekf_R": ("[controller.adaptive]\nR = -1.0\n", "R"),
    "unknown_key": ("durations = 3\n", "durations"),
    "unknown_controller": ('[controller]\nname = "pid"\n', "pid"),
    "toml": ("duration = = 3\n", "not valid TOML"),
    "event_time": ('[[events]]\ntime = -1.0\nkind = "control_period"\nfactor = 1.5\n', "time"),
    "event_kind": ('[[events]]\ntime = 1.0\nkind = "teleport"\n', "teleport"),
    "reference": ('[reference]\nkind = "spiral"\n', "spiral"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_scenario_file_is_one_line_and_exit_2(tmp_path, capsys, case):
    text, needle = BAD_FILES[case]
    path = tmp_path / f"{case}.toml"
    path.write_text(text)
    assert main(["run", str(path), "--no-log", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err and str(path) in err


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["run", "no-such-scenario"], "no such scenario"),
        (["run", "paper", "--controller", "pid"], "unknown controller"),
        (["run", "missing.toml"], "not found"),
        (["run", "paper", "--seed", "x"], "invalid int"),
    ],
)
def test_bad_command_line_is_one_line_and_exit_2(tmp_path, argv, needle):
    proc = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", *argv, "--no-log", "--out", str(tmp_path)], capture_output=True, text=True
    )
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and needle in proc.stderr and "Traceback" not in proc.stderr


def test_version_is_the_packages(capsys):
    import mlpfac

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out == f"mlpfac {mlpfac.__version__}\n"


def test_list_shows_every_scenario(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "paper " in out and "paper-faithful" in out and "controllers:" in out


EARLIER_RUN = {
    "config.toml": b"seed = 0\n",
    "metrics.json": b'{"status": "ok"}\n',
    "run.rrd": bytes(range(256)) * 4,
}

# Output paths and sinks that cannot work: (flags, what the one line names), checked before the
# first step. "{tmp}" is the test's folder; {tmp}/run holds an earlier run, {tmp}/a_file a file.
BAD_OUTPUTS = {
    "out_is_a_file": (["--out", "{tmp}/a_file"], "--out {tmp}/a_file: is a file"),
    "out_under_a_file": (["--out", "{tmp}/a_file/run"], "a_file is a file"),
    "out_in_proc": (["--out", "/proc/mlpfac-run"], "--out /proc/mlpfac-run: cannot write"),
    "out_in_sys": (["--out", "/sys/mlpfac-run"], "--out /sys/mlpfac-run: cannot write"),
    "out_holds_other_files": (["--out", "{tmp}"], "not a run's file"),
    "save_onto_a_folder": (["--out", "{tmp}/run", "--save", "{tmp}/run"], "--save {tmp}/run: is a folder"),
    "save_to_dev_full": (["--out", "{tmp}/run", "--save", "/dev/full"], "--save /dev/full: is not a regular file"),
    "save_in_proc": (["--out", "{tmp}/run", "--save", "/proc/mlpfac/run.rrd"], "--save /proc/mlpfac/run.rrd"),
    "save_under_a_file": (["--out", "{tmp}/run", "--save", "{tmp}/a_file/x.rrd"], "a_file is a file"),
    "save_inside_out": (["--out", "{tmp}/run", "--save", "{tmp}/run/other.rrd"], "is inside --out"),
    "connect_nobody": (["--out", "{tmp}/run", "--connect", "rerun+http://127.0.0.1:1/proxy"], "no rerun viewer"),
    "connect_bad_url": (["--out", "{tmp}/run", "--connect", "http://127.0.0.1:9876"], "a viewer URL looks like"),
    "missing_actuator": (["sims/bad.toml", "--out", "{tmp}/run"], "no actuator named 'nosuch'"),
}


def snapshot(root) -> dict:
    """Every file under ``root`` and its bytes, but the lock files (``.NAME.lock``) a run leaves beside --out."""
    return {p: p.read_bytes() for p in root.rglob("*") if p.is_file() and not p.name.endswith(".lock")}


@pytest.mark.parametrize("case", sorted(BAD_OUTPUTS))
def test_bad_output_is_one_line_exit_2_and_changes_nothing(tmp_path, case):
    flags, needle = BAD_OUTPUTS[case]
    (tmp_path / "run").mkdir()
    for name, data in EARLIER_RUN.items():
        (tmp_path / "run" / name).write_bytes(data)
    (tmp_path / "a_file").write_text("not a folder\n")
    (tmp_path / "sims").mkdir()
    (tmp_path / "sims" / "bad.toml").write_text('[plant]\nkind = "mujoco"\nleft_actuator = "nosuch"\n')
    before = snapshot(tmp_path)
    argv = [f.replace("{tmp}", str(tmp_path)) for f in flags]
    scenario = [] if argv[0].endswith(".toml") else ["paper"]
    proc = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", "run", *scenario, *argv, "--duration", "0.3", "--no-plot"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and needle.replace("{tmp}", str(tmp_path)) in lines[0], proc.stderr
    assert snapshot(tmp_path) == before
    assert not [p for p in tmp_path.rglob(".*tmp-*")], "a temporary file was left"


def test_view_of_a_folder_without_a_run(tmp_path, capsys):
    assert main(["view", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no run.rrd" in err


def test_a_duration_before_the_event_says_the_run_has_none(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "eight-payload", "--duration", "0.5", "--no-log", "--no-plot", "--out", str(out)]) == 0
    assert "ends before the event at 12.5 s" in capsys.readouterr().out
    config = (out / "config.toml").read_text()
    assert "duration = 0.5" in config and "[[events]]" not in config  # config.toml is the run as simulated


def test_a_reader_that_closes_early_is_no_traceback(tmp_path):
    """`mlpfac run ... | head -1`: the run's folder is whole, exit 141 as shell tools, nothing on stderr."""
    cmd = [sys.executable, "-m", "mlpfac.cli", "run", "paper", "--duration", "0.5", "--no-log", "--no-plot"]
    proc = subprocess.Popen([*cmd, "--out", str(tmp_path / "run")], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.readline()
    proc.stdout.close()
    assert proc.wait(timeout=120) in (0, 141)  # 0 if everything fitted in the pipe before it closed
    assert proc.stderr.read() == b""
    assert json.loads((tmp_path / "run" / "metrics.json").read_text())["status"] == "ok"


def test_the_summary_prints_the_learning_figures_it_has(tmp_path, capsys, monkeypatch):
    """A run that diverged before its first EKF update has weights but no P (null in metrics.json):
    the summary prints what there is, no traceback."""
    from mlpfac.cli import _print_summary

    monkeypatch.chdir(tmp_path)
    assert main(["run", "paper", "--duration", "0.5", "--no-log", "--no-plot", "--out", "a"]) == 0
    m = json.loads((tmp_path / "a" / "metrics.json").read_text())
    capsys.readouterr()
    _print_summary(m | {"mean_diag_P_final": None}, tmp_path / "a")
    out = capsys.readouterr().out
    assert f"max |weight| {m['max_abs_weight']:.3g}\n" in out and "diag P" not in out
    _print_summary(m | {"max_abs_weight": None, "mean_diag_P_final": None}, tmp_path / "a")
    assert "weight" not in capsys.readouterr().out


def test_mujoco_sets_up_no_gl_context_when_only_shipped_code_runs(tmp_path, monkeypatch):
    """glfw's import (and its subprocess) is skipped where nothing can render: MUJOCO_GL unset and
    only shipped controllers; a user's controller, or MUJOCO_GL set, gets MuJoCo as it comes."""
    from mlpfac.cli import _without_gl

    monkeypatch.delenv("MUJOCO_GL", raising=False)
    _without_gl("my_controller.py:Mine", "corradini")
    assert "MUJOCO_GL" not in os.environ
    monkeypatch.setenv("MUJOCO_GL", "egl")
    _without_gl("adaptive", "none")
    assert os.environ["MUJOCO_GL"] == "egl"
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    script = (
        "import sys; from mlpfac.cli import main; "
        f"code = main(['run', 'eight-nominal', '--duration', '0.5', '--no-log', '--no-plot', '--out', {str(tmp_path / 'r')!r}]); "
        "print(code, 'mujoco' in sys.modules, 'glfw' in sys.modules)"
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300)
    assert proc.stdout.splitlines()[-1] == "0 True False", proc.stdout + proc.stderr


def test_the_lost_threshold_flag_sets_every_run_of_a_sweep_and_a_check(tmp_path, capsys):
    import mlpfac

    rows = mlpfac.sweep(["paper"], ["kanayama"], seeds="0-1", duration=3.0, workers=1, lost_threshold=1e-9)
    assert rows[0]["lost"] == 2 and rows[0]["tracking"] == 0
    budget = tmp_path / "b.toml"
    budget.write_text('scenarios = ["paper"]\ncontrollers = ["kanayama"]\nduration = 3.0\n[[budget]]\nlost = 0\n')
    argv = ["check", str(budget), "--workers", "1"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    assert main([*argv, "--out", str(tmp_path / "b"), "--lost-threshold", "1e-9"]) == 1
    budget.write_text(budget.read_text().replace("duration = 3.0", "duration = 3.0\nlost_threshold_m = 1e-9"))
    assert main([*argv, "--out", str(tmp_path / "c")]) == 1
    meta = json.loads((tmp_path / "c" / "sweep.json").read_text())["meta"]
    assert meta["lost_threshold_m"] == 1e-9
