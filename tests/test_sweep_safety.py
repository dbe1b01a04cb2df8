"""A sweep never loses or mixes a result and meets every fault with one line: killed sweeps leave no
worker and no temporary file, a full disk is a failed run or one line, resume trusts only whole
folders of the same run, one sweep per folder, and plans or flags that cannot work are refused."""

import contextlib
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mlpfac.cli import main
from mlpfac.scenario.parse import load, to_toml
from mlpfac.sweeps import engine as sweep
from mlpfac.sweeps import execute

psutil = pytest.importorskip("psutil")


def sweep_cmd(out, *extra, seeds="0-200", duration="25"):
    """A sweep of ``paper``; by default one that runs for minutes on any machine (a test signals or
    kills it mid-way, after a sign: a finished folder)."""
    return [sys.executable, "-m", "mlpfac.cli", "sweep", "paper", "--seeds", seeds, "--duration", duration,
            "--out", str(out), *extra]  # fmt: skip


def wait_for(cond, timeout=60.0):
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError("timed out")
        time.sleep(0.05)


def pool_workers(pid: int) -> list:
    """The pool's worker processes of the sweep ``pid``: spawned, or forked by its fork server (not
    multiprocessing's resource tracker, nor the fork server itself)."""
    seen = {}
    for c in psutil.Process(pid).children(recursive=True):
        with contextlib.suppress(psutil.Error):  # a short-lived child may be gone by now
            seen[c] = (c.ppid(), " ".join(c.cmdline()))
    servers = {c.pid for c, (ppid, cmd) in seen.items() if ppid == pid and "forkserver" in cmd}
    return [c for c, (ppid, cmd) in seen.items() if "spawn_main" in cmd or ppid in servers]


def gone(pids, timeout=60.0) -> list[int]:
    """The pids still alive (not zombies) after ``timeout`` seconds (it returns as soon as none is:
    the timeout only bounds a hang)."""
    deadline = time.monotonic() + timeout
    while True:
        alive = []
        for pid in pids:
            try:
                if psutil.Process(pid).status() != psutil.STATUS_ZOMBIE:
                    alive.append(pid)
            except psutil.NoSuchProcess:
                pass
        if not alive or time.monotonic() > deadline:
            return alive
        time.sleep(0.1)


# --------------------------------------------------------------------------------------------
# 1. workers die with the sweep; 2. temporary files


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_workers_die_with_the_sweep(tmp_path, sig):
    out, systmp = tmp_path / "o", tmp_path / "systmp"
    systmp.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")} | {"TMPDIR": str(systmp)}
    p = subprocess.Popen(
        sweep_cmd(out, "--workers", "2", "--save-rrd"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE if sig == signal.SIGTERM else subprocess.DEVNULL,
        text=True,
        env=env,
    )
    try:
        wait_for(lambda: len(pool_workers(p.pid)) == 2 and list(out.glob("*/*/seed-*/metrics.json")))
        workers = psutil.Process(p.pid).children(recursive=True)  # and the resource tracker
        for w in pool_workers(p.pid):  # they were started with one BLAS thread
            assert w.environ().get("OPENBLAS_NUM_THREADS") == "1"
        p.send_signal(sig)
        if sig == signal.SIGTERM:
            _, err = p.communicate(timeout=60)
            assert p.returncode == 143, err
            assert "Traceback" not in err and "terminated;" in err and "Resume with the same command" in err
            assert not (out / ".tmp").exists()
        else:
            p.wait(timeout=60)
        assert gone([w.pid for w in workers]) == []
    finally:
        if p.poll() is None:
            p.kill()
    assert list(systmp.iterdir()) == []  # nothing in the system's temporary folder
    for d in out.glob("*/*/seed-*"):  # whole folders only
        assert (d / "metrics.json").exists() and (d / "run.rrd").exists()
    if sig == signal.SIGKILL:  # the next sweep into the folder removes what the killed one left
        (out / ".tmp").mkdir(exist_ok=True)
        (out / ".tmp" / "mlpfac-stale.rrd").write_bytes(b"RRF2")
        staged = out / "paper" / "adaptive" / ".seed-0150.tmp-killed"  # a folder killed half written
        staged.mkdir(parents=True)
        (staged / "config.toml").write_text("")
        jobs = sweep.plan(["paper"], ["adaptive"], [0], 1.0)
        sweep.execute(jobs, out, save_rrd=True)
        assert not (out / ".tmp").exists() and not staged.exists()


def test_a_folder_is_replaced_whole_or_not_at_all(tmp_path, monkeypatch):
    """A write that fails (or a process killed) half way through a run folder leaves the folder it
    replaces as it was, and nothing beside it."""
    out = tmp_path / "o"
    jobs = sweep.plan(["paper"], ["adaptive"], [0], 0.5)
    sweep.execute(jobs, out, save_rrd=True)
    d = jobs[0].folder(out)
    before = {f.name: f.read_bytes() for f in d.iterdir()}
    assert set(before) == {"config.toml", "run.rrd", "metrics.json"}
    real = Path.write_bytes

    def fail_on_the_recording(path, data):
        if path.name == "run.rrd":
            raise OSError(28, "No space left on device", str(path))
        return real(path, data)

    monkeypatch.setattr(Path, "write_bytes", fail_on_the_recording)
    with pytest.raises(sweep.OutputError, match=r"seed-0000/run.rrd"):
        sweep.write_result(out, jobs[0], {"error": None, "metrics": {"status": "ok"}, "rrd": b"RRF2"})
    assert {f.name: f.read_bytes() for f in d.iterdir()} == before
    assert sorted(p.name for p in d.parent.iterdir()) == ["seed-0000"]


def test_where_two_folders_cannot_be_exchanged_a_failed_swap_keeps_the_old_folder(tmp_path, monkeypatch):
    """Without renameat2's exchange the old folder is renamed aside first: if the new one then
    cannot take its place, the old one goes back; a sweep killed in between finds it aside and the
    next sweep puts it back (not removed as a temporary)."""
    from mlpfac.io import files as outputs

    target = tmp_path / "paper" / "adaptive" / "seed-0000"
    outputs.write_folder_whole(target, {"metrics.json": "old"})
    monkeypatch.setattr(outputs, "_exchange", lambda a, b: False)
    real_rename = os.rename

    def second_rename_fails(src, dst):
        if str(dst) == str(target) and ".tmp-" in str(src) and not str(src).endswith("-old"):
            raise OSError(5, "Input/output error", str(src))
        return real_rename(src, dst)

    monkeypatch.setattr(os, "rename", second_rename_fails)
    with pytest.raises(OSError) as err:
        outputs.write_folder_whole(target, {"metrics.json": "new"})
    assert err.value.filename == str(target)  # named as it would be, not its temporary
    assert (target / "metrics.json").read_text() == "old" and os.listdir(target.parent) == ["seed-0000"]
    monkeypatch.setattr(os, "rename", real_rename)
    aside = target.parent / ".seed-0000.tmp-killed01-old"  # killed between the two renames
    real_rename(target, aside)
    (target.parent / ".seed-0001.tmp-killed02").mkdir()  # killed while writing
    outputs.remove_staged([target.parent])
    assert (target / "metrics.json").read_text() == "old" and os.listdir(target.parent) == ["seed-0000"]


def test_a_folder_that_cannot_be_made_is_named_as_the_run_folder(tmp_path, monkeypatch):
    from mlpfac.io import files as outputs

    def full(dir, prefix):
        raise OSError(28, "No space left on device", str(Path(dir) / f"{prefix}abcd1234"))

    monkeypatch.setattr(outputs.tempfile, "mkdtemp", full)
    target = tmp_path / "s" / "c" / "seed-0003"
    with pytest.raises(OSError) as err:
        outputs.write_folder_whole(target, {"metrics.json": "{}"})
    assert err.value.filename == str(target) and err.value.errno == 28


def test_a_run_folder_to_be_replaced_that_holds_other_files_is_refused(tmp_path):
    """A run run again replaces its whole folder: a file of someone else's in it is one line naming
    it, before anything runs, and stays."""
    from mlpfac.exceptions import ConfigError

    out = tmp_path / "o"
    jobs = sweep.plan(["paper"], ["adaptive"], [0], 0.5)
    sweep.execute(jobs, out)
    d = jobs[0].folder(out)
    (d / "metrics.json").write_text("{}")  # not whole: to be run again
    (d / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match="notes.txt"):
        sweep.execute(jobs, out)
    assert (d / "notes.txt").read_text() == "mine" and (d / "metrics.json").read_text() == "{}"


# A signal that lands while cf.wait takes its futures' locks one by one (a window a loaded machine
# widens): the pool's thread would wait for the lock left taken, and the stopped sweep with it.
SIGNAL_INSIDE_THE_POOLS_LOCKS = """
import signal, sys
from pathlib import Path
import concurrent.futures._base as base
from mlpfac.sweeps import engine as sweep
from mlpfac.sweeps import execute

enter = base._AcquireFutures.__enter__
def enter_and_signal(self):
    for i, f in enumerate(sorted(self.futures, key=id)):
        f._condition.acquire()
        if i == 0 and not getattr(base, "signalled", False):
            base.signalled = True
            signal.raise_signal(signal.SIGINT)  # Ctrl-C, one lock taken and the others not
base._AcquireFutures.__enter__ = enter_and_signal

jobs = sweep.plan(["paper"], ["corradini"], [0, 1, 2, 3], 1.0)
oc = sweep.execute(jobs, Path(sys.argv[1]), workers=2)
print("interrupted" if oc.interrupted else "not interrupted", oc.ran)
"""


def test_a_signal_inside_the_pools_locks_still_stops_the_sweep(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-c", SIGNAL_INSIDE_THE_POOLS_LOCKS, str(tmp_path / "o")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0 and proc.stdout.startswith("interrupted"), proc.stdout + proc.stderr


def test_an_interrupted_save_rrd_sweep_leaves_no_temporary_file(tmp_path, monkeypatch):
    jobs = sweep.plan(["paper"], ["corradini"], [0, 1, 2], 0.5)
    monkeypatch.setenv("TMPDIR", str(tmp_path / "systmp"))
    (tmp_path / "systmp").mkdir()

    def stop(res):
        raise KeyboardInterrupt

    oc = sweep.execute(jobs, tmp_path / "o", save_rrd=True, on_result=stop)
    assert oc.interrupted and oc.ran == 1
    assert not (tmp_path / "o" / ".tmp").exists() and list((tmp_path / "systmp").iterdir()) == []


# --------------------------------------------------------------------------------------------
# 3. full disk


def _file_size_limit(limit):
    def pre():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return pre


def test_a_cut_recording_is_a_failed_run(tmp_path):
    out = tmp_path / "o"
    res = subprocess.run(
        sweep_cmd(out, "--workers", "1", "--save-rrd", seeds="0-1", duration="0.5"),
        preexec_fn=_file_size_limit(150_000),  # a recording is ~400 kB
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 1, res.stderr
    assert "Traceback" not in res.stderr.split("mlpfac: error:")[-1]
    assert "the recording is not whole" in res.stderr
    for seed in (0, 1):
        d = out / "paper" / "adaptive" / f"seed-{seed:04d}"
        assert not (d / "metrics.json").exists() and not (d / "run.rrd").exists() and (d / "error.txt").exists()
    assert not (out / ".tmp").exists()


def test_a_failed_write_is_one_line(tmp_path):
    done = tmp_path / "sizes"  # the sizes of a run's files, measured: the limit goes between them
    assert (
        subprocess.run(sweep_cmd(done, "--workers", "1", seeds="0", duration="0.5"), capture_output=True).returncode
        == 0
    )
    d = done / "paper" / "adaptive" / "seed-0000"
    small, large = sorted((d / name).stat().st_size for name in ("config.toml", "metrics.json"))
    assert small < large
    out = tmp_path / "o"
    res = subprocess.run(
        sweep_cmd(out, "--workers", "1", seeds="0-1", duration="0.5"),
        preexec_fn=_file_size_limit((small + large) // 2),  # the smaller file fits, the larger one does not
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 2, res.stderr
    last = res.stderr.strip().splitlines()
    assert "Traceback" not in res.stderr and len(last) == 2 and last[0].startswith("mlpfac: planning")
    assert (
        last[1].startswith(f"mlpfac: error: cannot write {out}/paper/adaptive/seed-0000")
        and "(File too large)" in last[1]
    )
    assert "resume with: mlpfac sweep paper" in last[1]
    assert list(out.rglob("metrics.json")) == []  # no folder counts as done


def test_a_full_disk_keeps_every_written_folder_whole(tmp_path):
    """A 1 MB tmpfs (needs root and mount): recordings cut, then a write fails with ENOSPC."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(disk)]).returncode:
        pytest.skip("cannot mount a tmpfs here")
    try:
        out = disk / "o"
        res = subprocess.run(
            sweep_cmd(out, "--workers", "2", "--save-rrd", seeds="0-9", duration="0.5"),
            capture_output=True,
            text=True,
            timeout=120,
        )
        # Which comes first depends on timing: a recording cut by the full disk (that run fails, exit 1)
        # or a run folder that cannot be written (one line, exit 2). Either way no folder lies.
        assert res.returncode in (1, 2), res.stderr
        assert "Traceback" not in res.stderr
        if res.returncode == 2:
            # multiprocessing's resource tracker, a process of Python's own, may warn after the sweep
            # has ended of a semaphore it could not unlink (a race of its own at exit): not mlpfac's lines
            ours = [line for line in res.stderr.strip().splitlines() if "resource_tracker" not in line]
            last = ours[-1]
            assert last.startswith(f"mlpfac: error: cannot write {out}/") and "No space left on device" in last
        else:
            assert "the recording is not whole" in res.stderr or "the recording could not be closed" in res.stderr
        jobs = {j.folder(out): j for j in sweep.plan(["paper"], ["adaptive"], list(range(10)), 0.5)}
        written = [d for d in jobs if (d / "metrics.json").exists()]
        assert all(sweep.check_done(out, jobs[d], save_rrd=True)[0] is not None for d in written)
        assert not (out / ".tmp").exists()
    finally:
        subprocess.run(["umount", str(disk)])


def test_a_failed_table_write_is_one_line(tmp_path, monkeypatch, capsys):
    import errno

    def full(*a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp_path / "o" / "sweep.csv"))

    monkeypatch.setattr(sweep, "write_tables", full)
    code = main(["sweep", "paper", "--seeds", "0", "--duration", "0.5", "--workers", "1", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "No space left on device" in err[-1] and "sweep.csv" in err[-1] and len(err) == 2
    assert (tmp_path / "o" / "paper" / "adaptive" / "seed-0000" / "metrics.json").exists()


# --------------------------------------------------------------------------------------------
# 4. resume trusts only whole folders of the same run


def _seed0(out):
    return out / "paper" / "adaptive" / "seed-0000"


CORRUPTIONS = {
    "run.rrd deleted": (lambda d: (d / "run.rrd").unlink(), "run.rrd missing"),
    "run.rrd truncated": (
        lambda d: (d / "run.rrd").write_bytes((d / "run.rrd").read_bytes()[:1000]),
        "run.rrd changed or cut",
    ),
    "run.rrd same size, other bytes": (
        lambda d: (d / "run.rrd").write_bytes(bytes(len((d / "run.rrd").read_bytes()))),
        "run.rrd changed or cut",
    ),
    "metrics.json of another seed": (
        lambda d: shutil.copy(d.parent / "seed-0001" / "metrics.json", d / "metrics.json"),
        "metrics.json of another run",
    ),
    "metrics.json {}": (lambda d: (d / "metrics.json").write_text("{}"), "metrics.json not valid"),
    "metrics.json []": (lambda d: (d / "metrics.json").write_text("[]"), "metrics.json not valid"),
    "metrics.json status only": (
        lambda d: (d / "metrics.json").write_text('{"status": "ok"}'),
        "metrics.json not valid",
    ),
    "metrics.json cut": (
        lambda d: (d / "metrics.json").write_text((d / "metrics.json").read_text()[:50]),
        "metrics.json not valid",
    ),
    "metrics.json interrupted": (
        lambda d: (d / "metrics.json").write_text(
            json.dumps(json.loads((d / "metrics.json").read_text()) | {"status": "interrupted"})
        ),
        "metrics.json not valid",
    ),
    "metrics.json phases wrong": (
        lambda d: (d / "metrics.json").write_text(
            json.dumps(json.loads((d / "metrics.json").read_text()) | {"phases": {"before": 1}})
        ),
        "metrics.json not valid",
    ),
    "config.toml deleted": (lambda d: (d / "config.toml").unlink(), "config.toml missing"),
}


@pytest.fixture(scope="module")
def whole_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("whole") / "o"
    jobs = sweep.plan(["paper"], ["adaptive"], [0, 1], 0.5)
    oc = sweep.execute(jobs, out, save_rrd=True)
    assert oc.ran == 2 and not oc.errors
    return jobs, out, sweep.aggregate(jobs, oc.metrics)


@pytest.mark.parametrize("case", list(CORRUPTIONS))
def test_resume_runs_a_damaged_folder_again(tmp_path, whole_sweep, case):
    jobs, whole, rows = whole_sweep
    out = tmp_path / "o"
    shutil.copytree(whole, out)
    damage, why = CORRUPTIONS[case]
    damage(_seed0(out))
    ran = []
    oc = sweep.execute(jobs, out, save_rrd=True, on_result=lambda r: ran.append(r["key"]))
    assert ran == [("paper", "adaptive", 0)] and oc.skipped == 1 and oc.redo == {why: 1}
    assert sweep.aggregate(jobs, oc.metrics) == rows
    assert sweep.check_done(out, jobs[0], save_rrd=True)[0] is not None  # whole again


def test_resume_reports_how_many_were_run_again(tmp_path, capsys):
    argv = ["sweep", "paper", "--seeds", "0-1", "--duration", "0.5", "--workers", "1", "--out", str(tmp_path)]
    assert main(argv) == 0
    (_seed0(tmp_path) / "metrics.json").write_text("[]")
    capsys.readouterr()
    assert main(argv) == 0
    assert "1 already done, 1 run now in" in (o := capsys.readouterr().out)
    assert "of which 1 were found but run again: metrics.json not valid 1)" in o


# --------------------------------------------------------------------------------------------
# 5. one sweep per folder


def test_a_second_sweep_into_the_same_folder_refuses(tmp_path):
    out = tmp_path / "o"
    first = subprocess.Popen(
        sweep_cmd(out, "--workers", "1"), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    try:
        wait_for(lambda: list(out.glob("*/*/seed-*/metrics.json")))
        second = subprocess.run(sweep_cmd(out, "--workers", "1"), capture_output=True, text=True, timeout=60)
        assert second.returncode == 2
        err = second.stderr.strip().splitlines()
        assert err[-1].startswith(f"mlpfac: error: --out {out}") and "another mlpfac process" in err[-1]
        assert first.poll() is None  # the first goes on
    finally:
        first.send_signal(signal.SIGTERM)
        first.communicate(timeout=60)
    assert first.returncode == 143


# --------------------------------------------------------------------------------------------
# 6. sizes and flags


def test_a_huge_plan_is_refused_at_once(tmp_path, capsys):
    """Refused from the count, before a list of its seeds or runs is made: the refusal's peak memory
    is far below what 10^7 seeds would take (over 500 MB), on a machine of any speed."""
    import tracemalloc

    tracemalloc.start()
    try:
        assert main(["sweep", "paper", "--seeds", "0-10000000", "--out", str(tmp_path / "o")]) == 2
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100e6, f"{peak / 1e6:.0f} MB"
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--seeds" in err and "10000001 seeds" in err and "100000" in err
    argv = ["sweep", "paper", "eight-nominal", "--controllers", "adaptive,corradini", "--seeds", "0-30000"]
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    assert "120004 runs" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("flag", "value"),
    [
        ("--workers", "0"),
        ("--workers", "-1"),
        ("--workers", "100000"),
        ("--batch-size", "0"),
        ("--scheduler-timeout", "0"),
        ("--scheduler-timeout", "-1"),
        ("--scheduler-timeout", "nan"),
    ],
)
def test_bad_execution_flags_are_one_line(tmp_path, capsys, flag, value):
    beside = {
        "--batch-size": ["--batched"],
        "--scheduler-timeout": ["--scheduler", "tcp://127.0.0.1:9"],
    }  # what it needs
    argv = ["sweep", "paper", "--seeds", "0", flag, value, *beside.get(flag, []), "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"mlpfac: error: {flag}:")
    assert not (tmp_path / "o").exists()


def test_planning_says_how_many_runs_at_once(tmp_path, capsys):
    main(["sweep", "paper", "--seeds", "0-2", "--duration", "0.2", "--workers", "1", "--out", str(tmp_path)])
    assert capsys.readouterr().err.splitlines()[0] == "mlpfac: planning 3 runs ..."


def test_planned_tables_equal_with_overrides():
    """Planning parses each scenario and controller once; each seed's table is what with_overrides gives."""
    seeds = [0, 5, 123, 10**6]
    for src in ("paper", "eight-nominal"):
        for ctrl in (None, "corradini"):
            jobs = sweep.plan([src], [ctrl], seeds, 1.0)
            assert [j.seed for j in jobs] == seeds
            for j in jobs:
                ref = load(src).with_overrides(controller=ctrl, seed=j.seed, duration=1.0)
                assert j.table == ref.table and j.config == to_toml(ref.table)
                assert (j.scenario, j.controller, j.source) == (ref.name, ref.controller, ref.source)


def test_planning_100000_runs_is_quick():
    t0 = time.perf_counter()
    jobs = sweep.plan(["paper"], ["adaptive"], sweep.parse_seeds("0-99999"), 1.0)
    assert len(jobs) == 100_000 and jobs[-1].config.count("seed = 99999\n") == 1
    assert time.perf_counter() - t0 < 10.0


# --------------------------------------------------------------------------------------------
# 7. BLAS threads


def test_worker_environment_leaves_the_users_choice(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    with sweep.worker_environment():
        assert os.environ["OPENBLAS_NUM_THREADS"] == "1" and os.environ["OMP_NUM_THREADS"] == "3"
    assert "OPENBLAS_NUM_THREADS" not in os.environ and os.environ["OMP_NUM_THREADS"] == "3"


def test_a_pool_found_broken_when_a_run_is_submitted_is_a_lost_worker(monkeypatch):
    """A killed worker breaks the pool: the next result or the next submit, whichever comes first,
    raises BrokenProcessPool; both are the same lost worker (seen in CI: the submit came first)."""
    import concurrent.futures as cf
    from concurrent.futures.process import BrokenProcessPool

    from mlpfac.sweeps import execute

    class KilledAfterOne:
        def __init__(self, *a, **k):
            self.submitted = 0

        def submit(self, *a, **k):
            self.submitted += 1
            if self.submitted > 1:
                raise BrokenProcessPool("A child process terminated abruptly")
            f = cf.Future()
            f.set_result([])
            return f

        def shutdown(self, *a, **k):
            pass

    monkeypatch.setattr(cf, "ProcessPoolExecutor", KilledAfterOne)
    jobs = sweep.plan(["paper"], ["adaptive"], [0, 1, 2], 0.5)
    with pytest.raises(sweep.WorkerLostError, match="a worker process died"):
        list(execute._pool_results([[j] for j in jobs], 1, False, False))


def test_a_worker_killed_from_outside_is_one_line(tmp_path):
    out = tmp_path / "o"
    p = subprocess.Popen(sweep_cmd(out, "--workers", "2"), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(lambda: len(pool_workers(p.pid)) == 2 and list(out.glob("*/*/seed-*/metrics.json")))
        workers = psutil.Process(p.pid).children(recursive=True)
        pool_workers(p.pid)[0].kill()  # as the kernel's out-of-memory killer would
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 1, err
    assert "Traceback" not in err and err.strip().splitlines()[-1].startswith("mlpfac: error: a worker process died")
    assert gone([w.pid for w in workers]) == []
    for d in out.glob("*/*/seed-*"):
        assert (d / "metrics.json").exists()


def test_a_pool_ends_its_thread_when_stopped_or_done(monkeypatch):
    """When the pool's results end (stopped, as by a signal, or done) the pool's own thread has
    ended, and raised nothing. A thread still ending as the interpreter exits races Python's own
    wake-up of it at exit: now and then, after a stopped sweep's one line, "Exception ignored in:
    <module 'threading'> ... OSError: [Errno 9] Bad file descriptor"; and a future cancelled as the
    thread fails the broken pool's futures made it raise InvalidStateError (Python 3.11)."""
    import threading

    raised = []
    monkeypatch.setattr(threading, "excepthook", raised.append)

    def pool_threads() -> list:
        return [t for t in threading.enumerate() if type(t).__name__ == "_ExecutorManagerThread"]

    jobs = sweep.plan(["paper"], ["corradini"], list(range(8)), 1.0)
    for _ in range(3):
        stopped = execute._pool_results([[j] for j in jobs], 2, False, False)
        next(stopped)
        stopped.close()  # what a Ctrl-C or a SIGTERM in the sweep does
        assert pool_threads() == []
    assert len(list(execute._pool_results([[j] for j in jobs[:3]], 2, False, False))) == 3
    assert pool_threads() == [] and raised == []


# A worker killed while it sends a result leaves half a message in the pool's result pipe: the
# pool's thread, reading it, must not wait forever for the rest (and the interpreter's exit with it).
HALF_A_RESULT = """
import concurrent.futures as cf, multiprocessing as mp, os, struct, sys, time
from mlpfac.sweeps.execute import _end_result_pipe

pool = cf.ProcessPoolExecutor(1, mp_context=mp.get_context("spawn"))
pool.submit(int, 1).result()  # the pool, its worker and its thread are up
thread = pool._executor_manager_thread
os.write(pool._result_queue._writer.fileno(), struct.pack("!i", 100) + b"abc")  # 3 bytes of 100


def reading_the_rest() -> bool:  # the sign: the pool's thread is in the read of the 100 bytes, its header read
    f = sys._current_frames().get(thread.ident)
    while f is not None and not (f.f_code.co_name == "_recv" and f.f_locals.get("size") == 100):
        f = f.f_back
    return f is not None


deadline = time.monotonic() + 120
while not reading_the_rest():
    assert time.monotonic() < deadline, "the pool's thread never read the message"
    time.sleep(0.01)
for p in list(pool._processes.values()):
    p.kill()
    p.join()
if sys.argv[1] == "end":
    _end_result_pipe(pool)
thread.join(5)
print("stuck" if thread.is_alive() else "ended", flush=True)
os._exit(0)  # a stuck thread would hold the interpreter's exit
"""


def test_a_half_sent_result_does_not_hold_the_pools_thread():
    run = lambda how: subprocess.run([sys.executable, "-c", HALF_A_RESULT, how], capture_output=True, text=True,  # noqa: E731
                                     timeout=60).stdout.strip()  # fmt: skip
    assert run("end") == "ended"
    assert run("keep") == "stuck"  # the mechanism: without the write end closed the read never ends


def test_the_workers_run_the_installed_mlpfac_not_a_folder_of_that_name_here(tmp_path):
    """A sweep started in a folder that holds another ``mlpfac`` (a checkout of another version)
    runs, in its workers, the package its own process runs: the fork server does not take the
    current folder, which the workers would otherwise import in its place (here a stub without the
    worker's module: every run failed)."""
    other = tmp_path / "mlpfac" / "sweeps"
    other.mkdir(parents=True)
    for f in ("mlpfac/__init__.py", "mlpfac/sweeps/__init__.py", "mlpfac/sweeps/warm.py"):
        (tmp_path / f).write_text("")
    cmd = [
        str(Path(sys.executable).parent / "mlpfac"),
        "compare",
        "paper",
        "--controllers",
        "kanayama",
        "--seeds",
        "0-1",
        "--duration",
        "1",
        "--workers",
        "2",
        "--out",
        "out",
    ]  # fmt: skip  (the command: no folder on its path)
    subprocess.run(cmd, cwd=tmp_path, check=True, capture_output=True, timeout=300)
    for seed in (0, 1):
        assert json.loads((tmp_path / f"out/paper/kanayama/seed-000{seed}/metrics.json").read_text())["status"] == "ok"
