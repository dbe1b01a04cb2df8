"""The sweep / compare engine: seeds, validation before any run, resume, pool, Dask, batched, tables."""

import argparse
import json
import os
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from mlpfac.exceptions import ConfigError
from mlpfac.loop.metrics import RunMetrics
from mlpfac.scenario.parse import load, to_toml
from mlpfac.sweeps import cli as sweep_cli
from mlpfac.sweeps import engine as sweep

DUR = 3.0  # seconds per run (2 s of warm-up excluded): the table is what is tested, not the controller


def plan(seeds="0-3", controllers="adaptive,corradini", scenarios=("paper",)):
    return sweep.plan(list(scenarios), sweep.parse_controllers(controllers), sweep.parse_seeds(seeds), DUR)


def table(jobs, oc):
    return sweep.aggregate(jobs, oc.metrics)


def strip(metrics: RunMetrics) -> dict:
    """A run's metrics.json as read, but its wall-clock time."""
    return {k: v for k, v in metrics.data.items() if k != "wall_time_s"}


def cli_args(out, *extra, command="sweep"):
    p = argparse.ArgumentParser()
    (sweep_cli.add_sweep_arguments if command == "sweep" else sweep_cli.add_compare_arguments)(p)
    return p.parse_args([*extra, "--out", str(out)])


@pytest.mark.parametrize(
    ("text", "seeds"),
    [
        ("0-4", [0, 1, 2, 3, 4]),
        ("3", [3]),
        ("0,2,5", [0, 2, 5]),
        ("0-4,10", [0, 1, 2, 3, 4, 10]),
        (" 2-3, 1 ", [1, 2, 3]),
    ],
)
def test_parse_seeds(text, seeds):
    assert sweep.parse_seeds(text) == seeds


@pytest.mark.parametrize("text", ["5-2", "a", "1-", "-3", "", "1,,2"])
def test_bad_seeds(text):
    with pytest.raises(ConfigError, match="--seeds"):
        sweep.parse_seeds(text)


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["paper", "--seeds", "5-2"], "empty range"),
        (["no-such-scenario", "--seeds", "0"], "no such scenario"),
        (["paper", "--controllers", "adaptive,pid"], "unknown controller"),
        (["paper", "--duration", "-1"], "--duration"),
        (["paper", "--workers", "0"], "--workers"),
        (["paper", "--scheduler", "tcp://127.0.0.1:1", "--scheduler-timeout", "1"], "cannot reach a Dask scheduler"),
    ],
)
def test_bad_input_fails_before_any_run(tmp_path, argv, match):
    out = tmp_path / "out"
    with pytest.raises(ConfigError, match=match) as err:
        sweep_cli.run_sweep_cli(cli_args(out, *argv))
    assert "\n" not in str(err.value)
    assert not out.exists()  # nothing created, not even the results folder


def test_cli_exit_code_and_one_line(tmp_path, capsys):
    from mlpfac.cli import main

    assert main(["sweep", "paper", "--seeds", "5-2", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--seeds" in err


def test_sweep_layout_tables_and_resume(tmp_path):
    jobs = plan()
    out = tmp_path / "a"
    oc = sweep.execute(jobs, out)
    assert oc.ran == len(jobs) == 8 and not oc.errors and not oc.interrupted
    run_dir = out / "paper" / "corradini" / "seed-0003"
    m = json.loads((run_dir / "metrics.json").read_text())
    assert (m["controller"], m["seed"], m["sim_time_s"]) == ("corradini", 3, DUR)
    assert "seed = 3" in (run_dir / "config.toml").read_text()
    rows = table(jobs, oc)
    assert [(r["controller"], r["phase"]) for r in rows] == [
        ("adaptive", "before"),
        ("corradini", "before"),
    ]  # event at 12.5 s > 2 s
    assert (
        rows[1]["bounded"] == 4
        and rows[1]["pos_rms_m_ci_lo"] <= rows[1]["pos_rms_m_mean"] <= rows[1]["pos_rms_m_ci_hi"]
    )

    # resume after losing two runs: only those run again, the table is the same
    for seed in (1, 2):
        (out / "paper" / "adaptive" / f"seed-{seed:04d}" / "metrics.json").unlink()
    ran = []
    oc2 = sweep.execute(jobs, out, on_result=lambda r: ran.append(r["key"]))
    assert sorted(ran) == [("paper", "adaptive", 1), ("paper", "adaptive", 2)] and oc2.skipped == 6
    assert table(jobs, oc2) == rows

    # a folder of another configuration (another duration) is run again, not reused
    jobs3 = sweep.plan(["paper"], ["corradini"], [3], 1.0)
    oc3 = sweep.execute(jobs3, out)
    assert oc3.ran == 1 and json.loads((run_dir / "metrics.json").read_text())["sim_time_s"] == 1.0

    paths = sweep.write_tables(out, "sweep", rows, sweep.SWEEP_COLUMNS, {})
    assert [p.name for p in paths] == ["sweep.csv", "sweep.md", "sweep.json"]
    assert paths[0].read_text().count("\n") == 1 + len(rows)


def test_a_sweeps_duration_says_what_its_reference_asks_of_torque_motors_over_that_duration():
    """--duration on torque motors: each run's [provenance] says the need over the run it is (once
    a scenario, for every controller and seed), as `mlpfac run --duration` and a file of that
    duration do."""
    said = load("eight-torque").with_overrides(duration=2.0).table["provenance"]["reference_torque"]
    assert said != load("eight-torque").table["provenance"]["reference_torque"]
    jobs = sweep.plan(["eight-torque"], ["kanayama", "adaptive"], [0, 1], 2.0)
    assert len(jobs) == 4 and all(j.table["provenance"]["reference_torque"] == said for j in jobs)
    assert all(f"reference_torque = {json.dumps(said)}" in j.config for j in jobs)


def test_interrupted_sweep_resumes_to_the_same_table(tmp_path):
    jobs = plan(seeds="0-2")
    full = sweep.execute(jobs, tmp_path / "full")
    out = tmp_path / "cut"
    count = []

    def interrupt_after_three(res):
        count.append(res)
        if len(count) == 3:
            raise KeyboardInterrupt

    oc = sweep.execute(jobs, out, on_result=interrupt_after_three)
    assert oc.interrupted and len(oc.metrics) == 3
    folders = [p for p in out.glob("*/*/seed-*")]
    assert all((p / "metrics.json").exists() for p in folders)  # only whole runs were left
    oc2 = sweep.execute(jobs, out)
    assert oc2.skipped == 3 and oc2.ran == 3
    assert table(jobs, oc2) == table(jobs, full)


def test_ctrl_c_of_the_command_line(tmp_path):
    """SIGINT to `mlpfac sweep` with two workers: exit code 130, no traceback, how to resume, whole runs only."""
    import signal
    import time

    out = tmp_path / "o"
    cmd = [
        sys.executable,
        "-m",
        "mlpfac.cli",
        "sweep",
        "paper",
        "--seeds",
        "0-200",
        "--duration",
        "25",  # minutes in all on any machine: still running at the sign
        "--workers",
        "2",
        "--out",
        str(out),
    ]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120  # the sign: a finished run folder (the timeout only bounds a hang)
    while not list(out.glob("*/*/seed-*/metrics.json")):
        assert p.poll() is None and time.monotonic() < deadline, "no run finished"
        time.sleep(0.1)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert "Traceback" not in err and "Resume with the same command" in err
    for d in out.glob("*/*/seed-*"):
        assert (d / "metrics.json").exists()


def test_ctrl_c_while_a_folder_is_written_waits_for_the_folder(tmp_path):
    """The race the test above can hit: SIGINT between a run's config.toml and its metrics.json."""
    import signal

    from mlpfac.io.interrupts import sigint_deferred

    written = []
    with pytest.raises(KeyboardInterrupt), sigint_deferred():
        # its handler has run when raise_signal returns: without the deferral, KeyboardInterrupt is raised here
        signal.raise_signal(signal.SIGINT)
        written.append("metrics.json")
    assert written == ["metrics.json"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_pool_and_batched_give_the_serial_table(tmp_path):
    jobs = plan()
    serial = sweep.execute(jobs, tmp_path / "serial")
    pool = sweep.execute(jobs, tmp_path / "pool", workers=2)
    batched = sweep.execute(jobs, tmp_path / "batched", workers=2, batched=True, batch_size=3)
    for oc in (pool, batched):
        assert table(jobs, oc) == table(jobs, serial)
        assert {k: strip(m) for k, m in oc.metrics.items()} == {k: strip(m) for k, m in serial.metrics.items()}


def test_local_sweep_does_not_import_dask(tmp_path):
    code = textwrap.dedent(f"""
        import sys
        from mlpfac.cli import main
        out = {str(tmp_path)!r}
        assert main(["sweep", "paper", "--seeds", "0-1", "--duration", "0.5", "--workers", "2", "--out", out]) == 0
        print(sorted(m for m in sys.modules if m.split(".")[0] in ("dask", "distributed")))
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().splitlines()[-1] == "[]"


def test_dask_cluster_gives_the_local_table(tmp_path):
    distributed = pytest.importorskip("distributed")
    jobs = plan(seeds="0-2")
    local = sweep.execute(jobs, tmp_path / "local")
    with distributed.LocalCluster(
        host="127.0.0.1", n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        client = sweep.connect(cluster.scheduler_address, timeout=30)
        try:
            remote = sweep.execute(jobs, tmp_path / "dask", client=client)
            # the command-line path on the same cluster (connects by address, closes its client)
            args = cli_args(
                tmp_path / "cli",
                "paper",
                "--seeds",
                "0-2",
                "--controllers",
                "adaptive,corradini",
                "--duration",
                str(DUR),
                "--scheduler",
                cluster.scheduler_address,
            )
            assert sweep_cli.run_sweep_cli(args) == 0
        finally:
            client.close()
    assert table(jobs, remote) == table(jobs, local)
    assert {k: strip(m) for k, m in remote.metrics.items()} == {k: strip(m) for k, m in local.metrics.items()}
    assert (tmp_path / "cli" / "sweep.md").read_text() == (lambda p: p.read_text())(
        sweep.write_tables(tmp_path / "local", "sweep", table(jobs, local), sweep.SWEEP_COLUMNS, {})[1]
    )


def test_a_lost_dask_worker_costs_only_its_runs(tmp_path):
    """A worker process that dies mid-sweep: its runs go to another worker, the table is the local one."""
    distributed = pytest.importorskip("distributed")
    jobs = sweep.plan(["paper"], ["adaptive"], list(range(8)), 20.0)
    local = sweep.execute(jobs, tmp_path / "local")
    out = tmp_path / "dask"
    lost: list = []

    def kill_a_busy_worker(client) -> None:
        deadline = time.monotonic() + 60
        while not list(out.rglob("metrics.json")) and time.monotonic() < deadline:
            time.sleep(0.01)
        busy = [w for w, keys in client.processing().items() if keys]
        if busy:  # its running task dies with it

            async def die() -> None:
                os._exit(1)

            lost.append((busy[0], len(list(out.rglob("metrics.json"))), client.processing()[busy[0]]))
            client.run(die, workers=[busy[0]], wait=False)

    with distributed.LocalCluster(
        host="127.0.0.1", n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        client = sweep.connect(cluster.scheduler_address, timeout=30)
        killer = threading.Thread(target=kill_a_busy_worker, args=(client,))
        try:
            killer.start()
            remote = sweep.execute(jobs, out, client=client)
            killer.join()
            workers_after = set(client.scheduler_info()["workers"])
        finally:
            killer.join()
            client.close()
    dead, done_at_kill, running = lost[0]  # IndexError: no worker was busy, the test proved nothing
    assert done_at_kill < len(jobs) and running and dead not in workers_after
    assert table(jobs, remote) == table(jobs, local)
    assert {k: strip(m) for k, m in remote.metrics.items()} == {k: strip(m) for k, m in local.metrics.items()}


def test_compare_table(tmp_path, capsys):
    args = cli_args(tmp_path, "paper", "--seeds", "1-2", "--duration", "13", "--workers", "2", command="compare")
    assert args.controllers == "adaptive,corradini,kanayama"
    assert sweep_cli.run_compare_cli(args) == 0
    md = (tmp_path / "compare.md").read_text()
    assert "| paper | kanayama | after |" in md and "| 2 / 0 / 0 |" in md
    assert (tmp_path / "compare.csv").exists() and "max error [mm]" in capsys.readouterr().out


def test_worst_seed_is_the_first_to_diverge(tmp_path):
    from test_batch import DIVERGENCE_M

    t = load("paper").table | {"divergence_m": DIVERGENCE_M}  # seed 2 diverges, seed 1 does not
    (tmp_path / "tight.toml").write_text(to_toml(t))
    jobs = sweep.plan([str(tmp_path / "tight.toml")], ["adaptive"], [1, 2], 3.0)
    rows = table(jobs, sweep.execute(jobs, tmp_path / "out"))
    assert rows[0]["worst_seed"] == 2 and rows[0]["worst_status"] == "diverged" and rows[0]["bounded"] == 1
    assert rows[0]["pos_rms_m_ci_lo"] is None  # one bounded run: no interval


def test_run_that_raises_is_reported_and_rerun(tmp_path, monkeypatch):
    jobs = plan(seeds="0", controllers="corradini")
    broken = {"on": True}
    import mlpfac.loop.runner

    real = mlpfac.loop.runner.run

    def run(scn, sink=None, on_step=None):
        if broken["on"]:
            raise RuntimeError("boom")
        return real(scn, sink, on_step)

    monkeypatch.setattr(mlpfac.loop.runner, "run", run)
    oc = sweep.execute(jobs, tmp_path)
    assert list(oc.errors) == [jobs[0].key] and not oc.metrics
    assert "boom" in (jobs[0].folder(tmp_path) / "error.txt").read_text()
    broken["on"] = False
    oc = sweep.execute(jobs, tmp_path)
    assert oc.ran == 1 and not oc.errors and not (jobs[0].folder(tmp_path) / "error.txt").exists()
