"""`mlpfac run` never loses or mixes a result: signals, full disks, file-size limits, a second run
into the same folder, and the addresses its viewers listen on. Real subprocesses throughout."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from mlpfac.cli import main

RUN = [sys.executable, "-m", "mlpfac.cli", "run", "paper", "--no-plot"]


def earlier_run(out: Path) -> dict[str, bytes]:
    """A finished run in ``out`` (0.3 s, with its run.rrd); its files' bytes."""
    assert main(["run", "paper", "--duration", "0.3", "--no-plot", "--out", str(out)]) == 0
    return files(out)


def files(d: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(d.iterdir())}


def leftovers(parent: Path) -> list[str]:
    return [p.name for p in parent.iterdir() if ".tmp-" in p.name]


def start(out: Path, *flags: str, duration: str = "600") -> subprocess.Popen:
    """A long run into ``out``, returned once it is stepping (its recording in the stage grows)."""
    proc = subprocess.Popen(
        [*RUN, "--duration", duration, "--out", str(out), *flags],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        staged = list(out.parent.glob(f".{out.name}.tmp-*/run.rrd"))
        if staged and staged[0].stat().st_size > 100_000:
            return proc
        time.sleep(0.05)
    proc.kill()
    raise AssertionError(f"the run did not start stepping: {proc.communicate()}")


SIGNALS = {"SIGINT": (signal.SIGINT, 130, "interrupted at"), "SIGTERM": (signal.SIGTERM, 143, "terminated by SIGTERM")}


@pytest.mark.parametrize("name", sorted(SIGNALS))
def test_a_signal_keeps_the_earlier_run_whole(tmp_path, name):
    sig, code, reason = SIGNALS[name]
    out = tmp_path / "run"
    before = earlier_run(out)
    proc = start(out)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert len(err.strip().splitlines()) == 1 and reason in err and "earlier run" in err and "discarded" in err
    assert files(out) == before  # byte for byte
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("name", sorted(SIGNALS))
def test_a_signal_into_an_empty_target_keeps_the_partial_run(tmp_path, name, rrd_contents):
    sig, code, reason = SIGNALS[name]
    out = tmp_path / "run"
    proc = start(out)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert "Traceback" not in err
    m = json.loads((out / "metrics.json").read_text())
    assert m["status"] == "interrupted" and m["reason"].startswith(reason)
    status = rrd_contents(out / "run.rrd")["/status"].temporal["TextLog:text"].values.to_pylist()
    assert status[0][0].startswith("interrupted")  # the recording is whole and says how it ended
    assert sorted(files(out)) == ["config.toml", "metrics.json", "run.rrd"] and leftovers(tmp_path) == []


def test_a_second_run_into_the_same_folder_is_refused(tmp_path):
    out = tmp_path / "run"
    first = start(out)
    try:
        second = subprocess.run([*RUN, "--duration", "0.3", "--out", str(out)], capture_output=True, text=True)
        assert second.returncode == 2
        lines = second.stderr.strip().splitlines()
        assert len(lines) == 1 and f"--out {out}" in lines[0] and f"pid {first.pid}" in lines[0]
    finally:
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=60)
    assert first.returncode == 130 and json.loads((out / "metrics.json").read_text())["status"] == "interrupted"


def test_temporaries_of_a_killed_run_are_removed_by_the_next(tmp_path):
    out = tmp_path / "run"
    proc = start(out)
    proc.kill()  # SIGKILL: no cleanup
    proc.communicate()
    assert leftovers(tmp_path) and not out.exists()
    assert main(["run", "paper", "--duration", "0.3", "--no-plot", "--out", str(out)]) == 0
    assert leftovers(tmp_path) == [] and (out / "metrics.json").exists()


def test_a_new_run_replaces_the_whole_folder(tmp_path):
    out = tmp_path / "run"
    earlier_run(out)
    assert main(["run", "paper", "--duration", "0.3", "--no-plot", "--out", str(out), "--no-log"]) == 0
    assert sorted(files(out)) == ["config.toml", "metrics.json"]  # no run.rrd of the earlier run beside it


def test_save_elsewhere_is_replaced_only_when_whole(tmp_path):
    save = tmp_path / "rec" / "a.rrd"
    save.parent.mkdir()
    save.write_bytes(b"earlier")
    bad = tmp_path / "bad.toml"
    bad.write_text('[plant]\nkind = "mujoco"\nleft_actuator = "nosuch"\n')
    assert main(["run", str(bad), "--out", str(tmp_path / "run"), "--save", str(save)]) == 2
    assert save.read_bytes() == b"earlier" and not (tmp_path / "run").exists()
    assert (
        main(["run", "paper", "--duration", "0.3", "--no-plot", "--out", str(tmp_path / "run"), "--save", str(save)])
        == 0
    )
    assert save.stat().st_size > 10_000 and leftovers(save.parent) == [] and leftovers(tmp_path) == []


def limited(limit: int):
    def preexec() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return preexec


@pytest.mark.parametrize(
    "limit,flags,file",
    [(200_000, ["--no-plot"], "run.rrd"), (20_000, ["--no-log", "--baseline", "corradini"], "figure1.png")],
)
def test_a_file_size_limit_is_a_failed_write(tmp_path, limit, flags, file):
    out = tmp_path / "run"
    before = earlier_run(out)
    argv = [a for a in RUN if a != "--no-plot"] + ["--duration", "5", "--out", str(out), *flags]
    proc = subprocess.run(argv, capture_output=True, text=True, preexec_fn=limited(limit))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and str(out / file) in lines[0], proc.stderr
    assert files(out) == before and leftovers(tmp_path) == []


@pytest.fixture
def tmpfs(tmp_path):
    """A 1 MiB tmpfs at tmp_path/fs (root and a kernel that allows the mount, else the test is skipped)."""
    d = tmp_path / "fs"
    d.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(d)], capture_output=True).returncode:
        pytest.skip("mounting a tmpfs is not permitted here")
    try:
        yield d
    finally:
        subprocess.run(["umount", "-l", str(d)], check=False)


def test_a_full_disk_is_a_failed_write(tmpfs):
    out = tmpfs / "run"
    before = earlier_run(out)
    proc = subprocess.run([*RUN, "--duration", "10", "--out", str(out)], capture_output=True, text=True)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and str(out) in lines[0] and "Traceback" not in proc.stderr, proc.stderr
    assert files(out) == before and leftovers(tmpfs) == []


def test_a_read_only_folder_is_refused_before_the_run(tmpfs):
    out = tmpfs / "run"
    before = earlier_run(out)
    subprocess.run(["mount", "-o", "remount,ro", str(tmpfs)], check=True)
    proc = subprocess.run([*RUN, "--duration", "0.3", "--out", str(out)], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"mlpfac: error: --out {out}: cannot write here (Read-only file system)"
    assert files(out) == before


def listening_addresses(port: int) -> set[str]:
    """Local addresses with a socket listening on ``port``, from /proc/net/tcp and tcp6."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        if not os.path.exists(table):
            continue
        for row in Path(table).read_text().splitlines()[1:]:
            local, state = row.split()[1], row.split()[3]
            addr, p = local.split(":")
            if state == "0A" and int(p, 16) == port:  # 0A: LISTEN
                raw = bytes.fromhex(addr)
                found.add(".".join(str(b) for b in raw[::-1]) if len(raw) == 4 else raw.hex())
    return found


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_serve_listens_on_localhost_only(tmp_path):
    grpc, web = free_port(), free_port()
    code = (
        "import sys; from mlpfac.cli import main; "
        f"sys.exit(main(['run', 'paper', '--duration', '1', '--no-plot', '--serve', '--port', '{web}', "
        f"'--grpc-port', '{grpc}', '--out', {str(tmp_path / 'run')!r}]))"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        while not any("serving the recording" in ln for ln in lines):
            line = proc.stdout.readline()
            assert line, f"it stopped before serving: {proc.communicate()}"
            lines.append(line)
        assert any(f"http://127.0.0.1:{web}/" in ln for ln in lines)
        assert listening_addresses(grpc) == {"127.0.0.1"} and listening_addresses(web) == {"127.0.0.1"}
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    deadline = time.monotonic() + 120  # the viewer stops with it (the timeout only bounds a hang)
    while (listening_addresses(grpc) or listening_addresses(web)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert listening_addresses(grpc) == set() and listening_addresses(web) == set()


@pytest.mark.parametrize(
    "script,wait_s,needle",
    [  # a viewer that exits is seen whenever it does (the wait bounds a hang); one that never listens waits it out
        ("echo 'Error: no GPU' >&2; exit 3", 120.0, "exited at once (code 3: Error: no GPU)"),
        ("exec sleep 300", 1.0, "did not listen"),
    ],
)
def test_view_reports_a_viewer_that_does_not_start(tmp_path, monkeypatch, capsys, script, wait_s, needle):
    from mlpfac.log import sinks

    fake = tmp_path / "rerun"
    fake.write_text(f"#!/bin/sh\n{script}\n")
    fake.chmod(0o755)
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "run.rrd").write_bytes(b"")
    monkeypatch.setenv("DISPLAY", ":99")
    monkeypatch.setattr(sinks, "rerun_executable", lambda: str(fake))
    monkeypatch.setattr(sinks, "START_TIMEOUT_S", wait_s)
    assert main(["view", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err


def test_spawn_without_a_working_display_is_one_line(tmp_path, monkeypatch, capsys):
    from mlpfac.log import sinks

    monkeypatch.setenv("DISPLAY", ":97")  # no X server there: the viewer exits at once
    monkeypatch.setattr(sinks, "SPAWN_PORT", free_port())
    out = tmp_path / "run"
    assert main(["run", "paper", "--duration", "0.3", "--no-plot", "--out", str(out), "--spawn"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--spawn: the rerun viewer exited at once" in err
    assert not out.exists() and leftovers(tmp_path) == []


def test_a_symlinked_out_replaces_the_folder_it_names(tmp_path):
    real = tmp_path / "real"
    earlier_run(real)
    (tmp_path / "link").symlink_to(real)
    assert main(["run", "paper", "--duration", "0.5", "--no-plot", "--out", str(tmp_path / "link")]) == 0
    assert (tmp_path / "link").is_symlink() and json.loads((real / "metrics.json").read_text())["steps"] == 50


def test_connect_streams_to_a_running_viewer_and_keeps_no_file(tmp_path):
    from mlpfac.log.sinks import rerun_executable

    port = free_port()
    server = subprocess.Popen(
        [rerun_executable(), "--serve-grpc", "--bind", "127.0.0.1", "--port", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 120  # the sign: it listens (the timeout only bounds a hang)
        while not listening_addresses(port):
            assert server.poll() is None and time.monotonic() < deadline, "the viewer never listened"
            time.sleep(0.1)
        out = tmp_path / "run"
        url = f"rerun+http://127.0.0.1:{port}/proxy"
        assert main(["run", "paper", "--duration", "0.3", "--no-plot", "--out", str(out), "--connect", url]) == 0
        assert sorted(files(out)) == ["config.toml", "metrics.json"]
    finally:
        server.terminate()
        server.wait()


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "rename-aside"])
def test_a_stage_replaces_a_full_folder_whole(tmp_path, monkeypatch, exchange):
    from mlpfac.io import files as outputs

    if not exchange:
        monkeypatch.setattr(outputs, "_exchange", lambda a, b: False)
    target = tmp_path / "run"
    target.mkdir()
    (target / "metrics.json").write_text("old")
    (target / "run.rrd").write_text("old")
    with outputs.Stage(target, "--out") as stage:
        (stage.path / "metrics.json").write_text("new")
        stage.commit()
    assert files(target) == {"metrics.json": b"new"} and leftovers(tmp_path) == []
    with outputs.Stage(target, "--out") as stage:
        (stage.path / "metrics.json").write_text("discarded")
    assert files(target) == {"metrics.json": b"new"} and leftovers(tmp_path) == []


def test_a_recording_that_cannot_be_closed_is_a_failed_write(tmp_path):
    """rerun's file closed too late (a full disk can stall it): one line naming the file, exit 2."""
    out = tmp_path / "run"
    script = (  # rerun's close never returns, the recorder waits 0.2 s
        "import sys, threading; import rerun as rr; import mlpfac.log.recorder as r; r.CLOSE_TIMEOUT_S = 0.2; "
        "rr.RecordingStream.disconnect = lambda self: threading.Event().wait(); "
        "from mlpfac.cli import entry; "
        f"sys.argv = ['mlpfac', 'run', 'paper', '--no-plot', '--duration', '0.3', '--out', {str(out)!r}]; entry()"
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"mlpfac: error: {out / 'run.rrd'}: cannot write"), proc.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    "controller, k, stopped",
    [("adaptive-real", 100, "1.01 s"), ("adaptive", 250, "5.00 s")],  # step by step; compiled from 250 to 500
)
def test_a_ctrl_c_that_lands_in_a_del_still_stops_the_run(tmp_path, controller, k, stopped):
    """Python reports an exception raised in a ``__del__`` (rerun's streams flush in theirs) as
    ignored and goes on: a Ctrl-C delivered there stops the run at its next step (or compiled
    segment) all the same."""
    out = tmp_path / "run"
    script = textwrap.dedent(
        f"""
        import sys
        import mlpfac.loop.closed_loop as runner

        class Dropped:
            def __del__(self):
                raise KeyboardInterrupt  # as SIGINT's handler does, wherever Python is

        apply_due = runner._apply_due

        def step(pending, k, *args):
            if k == {k}:
                Dropped()
            return apply_due(pending, k, *args)

        runner._apply_due = step
        from mlpfac.cli import entry

        sys.argv = ["mlpfac", "run", "eight-nominal", "--no-plot", "--duration", "10", "--controller", {controller!r},
                    "--out", {str(out)!r}]
        entry()
        """
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 130, proc.stderr
    assert "ignored" not in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["status"] == "interrupted" and m["reason"] == f"interrupted at t = {stopped}", m["reason"]
