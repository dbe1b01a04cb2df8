"""The command line: outputs of a run, and one clear line with exit code 2 for bad input."""

import json
import os
import subprocess
import sys

import pytest

from mlpfac.cli import _outcome, main


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
    first = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("paper / "))
    assert first.startswith(f"paper / adaptive / seed 3: ok, {m['outcome']} (") and "position RMS" in first, first


def test_a_runs_outcome_says_its_threshold_the_right_way_round():
    assert _outcome({"outcome": "tracking", "lost_threshold_m": 0.2}) == (
        ", tracking (every phase's position RMS within 0.2 m)"
    )
    assert (
        _outcome({"outcome": "lost", "lost_threshold_m": 0.0313}) == ", lost (a phase's position RMS beyond 0.0313 m)"
    )


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
