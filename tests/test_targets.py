"""What is not ours is never damaged: a report file that is a device, a FIFO, a link or our own
stdout is written through; a user's own tables in a results folder are refused, an empty path too;
view --save, report on a full disk, a broken recording leave the earlier file as it was. Each test
fails without its fix (mlpfac.io.targets, mlpfac.log.compare, mlpfac.report.results)."""

from __future__ import annotations

import json
import os
import socket
import stat
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from mlpfac.cli import main

KIN = 'name = "kin"\nduration = 1.0\nwarmup = 0.2\n[plant]\nkind = "kinematic"\n'
BUDGET = 'scenarios = ["kin.toml"]\ncontrollers = ["corradini"]\nseeds = "0"\n[[budget]]\nlost = 0\n'


@pytest.fixture
def here(tmp_path, monkeypatch) -> Path:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "kin.toml").write_text(KIN)
    (tmp_path / "b.toml").write_text(BUDGET)
    return tmp_path


def _cli(*argv: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mlpfac.cli", *argv], capture_output=True, text=True, **kw)


def _one_line(err: str) -> str:
    lines = [x for x in err.splitlines() if not x.startswith("mlpfac: planning")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# --- what is not ours ---------------------------------------------------------------------------


def test_check_reports_are_written_through_fifos_links_and_devices(here, capsys):
    """--junit and --summary: a FIFO and a character device stay what they are (written through), a
    link stays a link and its file gets the report; a regular file is replaced."""
    fifo, link = here / "fifo", here / "link.md"
    os.mkfifo(fifo)
    link.symlink_to("real.md")
    (here / "real.md").write_text("old\n")
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()), daemon=True)
    reader.start()
    assert main(["check", "b.toml", "--out", "runs", "--workers", "1", "--junit", "fifo", "--summary", "link.md"]) == 0
    reader.join(5)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and got and got[0].startswith(b"<?xml")
    assert link.is_symlink() and (here / "real.md").read_text().startswith("## mlpfac check: pass")
    if os.geteuid() == 0:  # a device of our own (the null device's numbers), in the test's folder
        dev = here / "null"
        os.mknod(dev, stat.S_IFCHR | 0o666, os.makedev(1, 3))
        assert main(["check", "b.toml", "--out", "runs", "--workers", "1", "--junit", str(dev)]) == 0
        assert stat.S_ISCHR(os.lstat(dev).st_mode)
    capsys.readouterr()


def test_a_fifo_without_reader_is_one_line_not_a_wait(here, capsys):
    os.mkfifo(here / "fifo")
    assert main(["check", "b.toml", "--out", "runs", "--workers", "1", "--summary", "fifo"]) == 2
    assert "fifo" in _one_line(capsys.readouterr().err)
    assert stat.S_ISFIFO(os.lstat(here / "fifo").st_mode)


# (argv, a file of the user's in the folder --out names)
USERS_TABLES = {
    "sweep: summary.md": (["sweep", "kin.toml", "--seeds", "0", "--workers", "1", "--out", "P"], "summary.md"),
    "sweep: sweep.csv": (["sweep", "kin.toml", "--seeds", "0", "--workers", "1", "--out", "P"], "sweep.csv"),
    "compare: compare.md": (["compare", "kin.toml", "--seeds", "0", "--workers", "1", "--out", "P"], "compare.md"),
    "check: sweep.json": (["check", "b.toml", "--workers", "1", "--out", "P"], "sweep.json"),
    "check: a folder named paired.md": (["check", "b.toml", "--workers", "1", "--out", "P"], "paired.md/"),
}


@pytest.mark.parametrize("case", sorted(USERS_TABLES))
def test_a_users_own_table_in_the_results_folder_is_never_replaced(here, capsys, case):
    argv, name = USERS_TABLES[case]
    (here / "P").mkdir()
    mine = here / "P" / name.rstrip("/")
    mine.mkdir() if name.endswith("/") else mine.write_text("my own notes\n")
    assert main(argv) == 2
    line = _one_line(capsys.readouterr().err)
    assert "--out P" in line and repr(name.rstrip("/")) in line, line
    assert sorted(p.name for p in (here / "P").iterdir()) == [name.rstrip("/")]
    assert name.endswith("/") or mine.read_text() == "my own notes\n"


def test_a_sweeps_own_tables_are_replaced_on_the_next_sweep(here, capsys):
    argv = ["sweep", "kin.toml", "--seeds", "0", "--workers", "1", "--out", "P"]
    assert main(argv) == 0 and main([*argv[:3], "0-1", *argv[4:]]) == 0
    assert json.loads((here / "P" / "sweep.json").read_text())["meta"]["seeds"] == "0-1"
    capsys.readouterr()


EMPTY_PATHS = {
    "run --out": ["run", "kin.toml", "--out", ""],
    "run --save": ["run", "kin.toml", "--save", " "],
    "sweep --out": ["sweep", "kin.toml", "--out", ""],
    "compare --out": ["compare", "kin.toml", "--out", ""],
    "check --out": ["check", "b.toml", "--out", ""],
    "check --junit": ["check", "b.toml", "--junit", ""],
    "check budget": ["check", ""],
    "view --save": ["view", "D", "--save", ""],
    "plot": ["plot", ""],
}


@pytest.mark.parametrize("case", sorted(EMPTY_PATHS))
def test_an_empty_path_is_refused(here, capsys, case):
    with pytest.raises(SystemExit) as exc:
        main(EMPTY_PATHS[case])
    assert exc.value.code == 2
    assert "an empty path" in _one_line(capsys.readouterr().err)
    assert sorted(p.name for p in here.iterdir()) == ["b.toml", "kin.toml"]


def _recorded_run(here: Path, name: str, duration: str = "0.5") -> Path:
    assert main(["run", "kin.toml", "--duration", duration, "--no-plot", "--out", name]) == 0
    return here / name


def test_view_save_is_atomic_and_reads_what_it_is_given(here, capsys):
    """A garbage or cut run.rrd is one line naming it, and the earlier cmp.rrd stays as it was; runs
    shorter than their warm-up (no figure after it) are compared."""
    a = _recorded_run(here, "a", "0.1")  # shorter than the warm-up of 0.2 s
    b = _recorded_run(here, "b")
    assert main(["view", "a", "b", "--save", "cmp.rrd"]) == 0
    before = (here / "cmp.rrd").read_bytes()
    (here / "bad").mkdir()
    (here / "bad" / "run.rrd").write_bytes(b"garbage" * 100)
    (here / "cut").mkdir()
    (here / "cut" / "run.rrd").write_bytes((b / "run.rrd").read_bytes()[:5000])
    for broken in ("bad", "cut"):
        capsys.readouterr()
        assert main(["view", str(a), broken, "--save", "cmp.rrd"]) == 2
        assert f"{broken}/run.rrd" in _one_line(capsys.readouterr().err)
        assert (here / "cmp.rrd").read_bytes() == before
        assert not [p for p in here.iterdir() if p.name.startswith(".cmp.rrd")]


def test_connect_to_a_viewer_that_never_answers_is_refused_before_the_run(here, capsys):
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    url = f"rerun+http://127.0.0.1:{server.getsockname()[1]}/proxy"
    try:
        assert main(["run", "kin.toml", "--no-plot", "--out", "o", "--connect", url]) == 2
    finally:
        server.close()
    assert "accepts connections there but does not answer" in _one_line(capsys.readouterr().err)
    assert not (here / "o").exists()


def _limited(size: int):
    """A preexec_fn: files of at most ``size`` bytes (a full disk, as far as a writer can tell)."""
    import resource

    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))


def test_view_save_on_a_full_disk_keeps_the_earlier_file(here, capsys):
    _recorded_run(here, "a")
    _recorded_run(here, "b")
    assert main(["view", "a", "b", "--save", "cmp.rrd"]) == 0
    before = (here / "cmp.rrd").read_bytes()
    proc = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", "view", "a", "b", "--save", "cmp.rrd"],
        capture_output=True, text=True, cwd=here, preexec_fn=_limited(len(before) // 2),
    )  # fmt: skip
    assert proc.returncode == 2 and "cmp.rrd" in _one_line(proc.stderr), proc.stderr
    assert (here / "cmp.rrd").read_bytes() == before
    assert not [p for p in here.iterdir() if p.name.startswith(".cmp.rrd")]
    capsys.readouterr()


def test_report_on_a_full_disk_keeps_the_page(here):
    docs = here / "docs"
    (docs / "data" / "x").mkdir(parents=True)
    rows = [{"scenario": "s", "controller": "c", "phase": "before", "runs": 1}]
    (docs / "data" / "x" / "table.md").write_text("| a |\n| --- |\n" + "| 1 |\n" * 2000)
    (docs / "data" / "x" / "sweep.json").write_text(json.dumps({"meta": {}, "rows": rows}))
    page = "# p\n<!-- table: data/x view=text -->\n<!-- /table -->\n"
    (docs / "page.md").write_text(page)
    proc = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", "report", "docs"],
        capture_output=True, text=True, cwd=here, preexec_fn=_limited(4096),
    )  # fmt: skip
    assert proc.returncode == 2 and "docs/page.md: cannot write" in _one_line(proc.stderr), proc.stderr
    assert (docs / "page.md").read_text() == page


def test_a_report_to_dev_stdout_redirected_to_a_file_joins_what_is_printed(here):
    """`mlpfac check ... --junit /dev/stdout > out.txt`: the file gets the printed lines and the whole
    XML in turn (not replaced, not written over)."""
    with open(here / "out.txt", "w") as out:
        proc = subprocess.run(
            [sys.executable, "-m", "mlpfac.cli", "check", "b.toml", "--workers", "1", "--out", "C", "--junit", "/dev/stdout"],
            stdout=out, stderr=subprocess.PIPE, text=True, cwd=here,
        )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    text = (here / "out.txt").read_text()
    xml = text[text.index("<?xml") : text.index("</testsuites>") + len("</testsuites>")]
    import xml.etree.ElementTree as ET

    assert ET.fromstring(xml.split("?>", 1)[1]).tag == "testsuites"
    assert text.startswith("1 runs (") and text.rstrip().endswith("/dev/stdout")
