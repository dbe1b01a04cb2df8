"""Faults of the unlucky user: what is not ours is never damaged (devices, FIFOs, links, a user's own
tables), MuJoCo's warnings end a run, and what used to be a traceback or a silent answer is one
line. Each test fails without its fix (mlpfac.targets, mlpfac.plants.compiled's warning handler, ...)."""

from __future__ import annotations

import json
import os
import socket
import stat
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest

import mlpfac
from mlpfac.cli import main
from mlpfac.exceptions import ConfigError, MlpfacError

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
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
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
    from mlpfac.plants import compiled
    from mlpfac.runner import build
    from mlpfac.scenario import load

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
    from mlpfac.scenario import shipped_dir

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


def test_a_name_too_long_for_out_is_one_line(here, capsys):
    assert main(["run", "kin.toml", "--no-log", "--no-plot", "--out", "x" * 300]) == 2
    assert "File name too long" in _one_line(capsys.readouterr().err)


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
        "its data are not what a sweep writes",
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
    assert main(["report", "docs"]) == 2
    assert needle in _one_line(capsys.readouterr().err)
    assert (docs / "page.md").read_text() == page


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
                    "--scheduler-timeout", "1", cwd=here, timeout=30)  # fmt: skip
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
}


@pytest.mark.parametrize("case", sorted(API_CALLS))
def test_the_api_names_the_argument_of_a_wrong_type(here, case):
    call, name = API_CALLS[case]
    with pytest.raises(ConfigError) as exc:
        call()
    assert exc.value.where == name and isinstance(exc.value, MlpfacError), exc.value
    assert sorted(p.name for p in here.iterdir()) == ["b.toml", "kin.toml"]


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


def test_a_mujoco_compile_error_is_one_line(here, capsys):
    (here / "bad.xml").write_text('<mujoco><worldbody><body><geom type="sphere"/></body></worldbody></mujoco>')
    (here / "m.toml").write_text('[plant]\nkind = "mujoco"\nmodel = "bad.xml"\n')
    assert main(["run", "m.toml", "--no-log", "--no-plot", "--out", "o"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "MuJoCo cannot load the model: Error: size 0 must be positive in geom Element name" in line, line


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
