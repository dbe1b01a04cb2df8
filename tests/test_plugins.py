"""A user's own controller, without editing mlpfac: every form of naming it, what its runs get,
its bad input, its bugs, the entry-point group and the Python API (mlpfac.control.plugins, mlpfac.api)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import mlpfac
from mlpfac.cli import main

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "pure_pursuit.py"

LAW = '''
import numpy as np


class Law:
    """Kanayama's law, written against the contract: step(e, r) -> (v, omega) for one run."""

    labels = {"gain": ["kx", "ky"]}

    def __init__(self, T, kx=10.0, ky=64.0, kt=16.0, fail_at=None, bad=None):
        self.T, self.kx, self.ky, self.kt = T, kx, ky, kt
        self.fail_at, self.bad, self.k = fail_at, bad, 0

    def reset(self, rng):
        self.k = 0
        self.draw = float(rng.random())

    def step(self, e, r):
        self.k += 1
        if self.fail_at is not None and self.k == self.fail_at:
            raise ZeroDivisionError("the law's own bug")
        if self.bad == "nan" and self.k == 5:
            return float("nan"), 0.0
        if self.bad == "shape" and self.k == 5:
            return np.zeros(3)
        v = r[3] * np.cos(e[2]) + self.kx * e[0]
        return v, r[4] + r[3] * (self.ky * e[1] + self.kt * np.sin(e[2]))

    def telemetry(self):
        return {"steps": float(self.k), "gain": np.array([self.kx, self.ky])}
'''

BATCHED = '''
import numpy as np


class BatchLaw:
    """The same law in the batch form: reset(list of generators), step((B, 3), r) -> (B, 2)."""

    batched = True
    name = "batch-law"

    def __init__(self, T):
        self.T = T

    def reset(self, rngs):
        self.B = len(rngs) if isinstance(rngs, list) else 1

    def step(self, e, r):
        e = np.atleast_2d(e)
        v = r[3] * np.cos(e[:, 2]) + 10.0 * e[:, 0]
        w = r[4] + r[3] * (64.0 * e[:, 1] + 16.0 * np.sin(e[:, 2]))
        return np.stack([v, w], axis=1)
'''

KINEMATIC = 'duration = 1.0\n[plant]\nkind = "kinematic"\n'


@pytest.fixture
def law(tmp_path: Path) -> Path:
    (tmp_path / "law.py").write_text(LAW)
    return tmp_path / "law.py"


def cli(args: list[str], cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", *args], cwd=cwd, capture_output=True, text=True, env=env, timeout=600
    )


def test_run_a_file_plugin_from_the_command_line(law, tmp_path, rrd_contents):
    """`--controller law.py:Law` relative to the current folder: every output a shipped controller's run gets."""
    p = cli(["run", "eight-nominal", "--controller", "law.py:Law", "--duration", "2", "--out", "out"], tmp_path)
    assert p.returncode == 0, p.stderr
    out = tmp_path / "out"
    assert sorted(os.listdir(out)) == ["config.toml", "figure1.png", "metrics.json", "run.rrd"]
    m = json.loads((out / "metrics.json").read_text())
    assert m["controller"] == "Law" and m["outcome"] == "tracking"
    assert m["ctrl_final"] == {"steps": m["steps"], "gain": [10.0, 64.0]}  # its telemetry, where it fits
    config = tomllib.loads((out / "config.toml").read_text())
    assert config["controller"]["name"] == f"{law}:Law"
    prov = config["provenance"]["controller"]
    assert prov["origin"] == "file" and len(prov["sha256"]) == 64
    entities = rrd_contents(out / "run.rrd")
    assert any(path.startswith("/ctrl") and "steps" in path for path in entities), sorted(entities)
    # the config re-runs it, to the bit; a changed file is refused with one line
    again = cli(["run", str(out / "config.toml"), "--out", "again", "--no-plot", "--no-log"], tmp_path)
    assert again.returncode == 0, again.stderr
    m2 = json.loads((tmp_path / "again" / "metrics.json").read_text())
    assert {k: v for k, v in m2.items() if k != "wall_time_s"} == {k: v for k, v in m.items() if k != "wall_time_s"}
    law.write_text(LAW + "\n# edited\n")
    changed = cli(["run", str(out / "config.toml"), "--out", "third", "--no-log"], tmp_path)
    assert changed.returncode == 2 and "[provenance] controller" in changed.stderr
    assert len(changed.stderr.strip().splitlines()) == 1 and not (tmp_path / "third").exists()


def test_run_a_module_plugin(tmp_path):
    pkg = tmp_path / "mylaws"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "kan.py").write_text(LAW)
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    scn = tmp_path / "k.toml"
    scn.write_text(KINEMATIC)
    p = cli(["run", str(scn), "--controller", "mylaws.kan:Law", "--out", "o", "--no-plot", "--no-log"], tmp_path, env)
    assert p.returncode == 0, p.stderr
    config = tomllib.loads((tmp_path / "o" / "config.toml").read_text())
    assert config["provenance"]["controller"]["target"] == "mylaws.kan:Law"


def test_a_scenario_file_names_its_plugin_relative_to_itself(tmp_path):
    """[controller] name = "file.py:Class" from the scenario's folder, [controller.params] as keyword arguments."""
    (tmp_path / "scn").mkdir()
    (tmp_path / "scn" / "laws").mkdir()
    (tmp_path / "scn" / "laws" / "pp.py").write_text(EXAMPLE.read_text())
    (tmp_path / "scn" / "mine.toml").write_text(
        KINEMATIC + '[controller]\nname = "laws/pp.py:PurePursuit"\n[controller.params]\nlookahead = 0.2\n'
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    p = cli(["run", "../scn/mine.toml", "--out", "o", "--no-plot", "--no-log"], elsewhere)
    assert p.returncode == 0, p.stderr
    assert "pure-pursuit" in p.stdout
    config = tomllib.loads((elsewhere / "o" / "config.toml").read_text())
    assert config["controller"]["params"] == {"lookahead": 0.2}
    rec = mlpfac.run(tmp_path / "scn" / "mine.toml")
    assert rec.controller == "pure-pursuit" and np.isfinite(rec.ctrl["curvature"][: rec.n]).all()


def test_the_example_tracks_on_the_robot():
    m = mlpfac.metrics(mlpfac.run("eight-nominal", controller=f"{EXAMPLE}:PurePursuit", duration=6.0))
    assert m["status"] == "ok" and m["phases"]["before"]["rms_position_error_m"] < 0.04, m["phases"]


def test_the_python_api_runs_a_class_or_an_object(law):
    sys.path.insert(0, str(law.parent))
    try:
        import law as law_module  # noqa: PLC0415
    finally:
        sys.path.remove(str(law.parent))
    scn = mlpfac.parse(
        {"duration": 1.0, "plant": {"kind": "kinematic"}, "initial": {"error": [0.05, 0.02, 0.0]}}, "api"
    )
    by_class = mlpfac.run(scn, controller=law_module.Law)
    obj = law_module.Law(T=scn.T, kx=5.0)
    by_object = mlpfac.run(scn, controller=obj)
    assert obj.k == by_object.n  # the object given is the one stepped
    assert by_class.controller == by_object.controller == "Law"
    assert not np.array_equal(by_class.u, by_object.u)  # kx = 5 is not the default
    by_file = mlpfac.run(scn, controller=f"{law}:Law")
    np.testing.assert_array_equal(by_file.u, by_class.u)


def test_the_python_sweep_with_a_local_class(tmp_path):
    class Local:
        def __init__(self, T):
            self.T = T

        def step(self, e, r):
            return r[3] * np.cos(e[2]) + 10.0 * e[0], r[4] + r[3] * (64.0 * e[1] + 16.0 * np.sin(e[2]))

    scn = tmp_path / "k.toml"
    scn.write_text(KINEMATIC)
    with pytest.warns(UserWarning, match="in this process"):
        rows = mlpfac.sweep([scn], [Local, "kanayama"], seeds="0-1", out=tmp_path / "sw", workers=2)
    got = {(r["controller"], r["phase"]): r for r in rows}
    assert got[("Local", "before")]["tracking"] == 2 and not rows.errors
    # the same law as Kanayama's: the same figures
    assert got[("Local", "before")]["pos_rms_m_median"] == pytest.approx(
        got[("kanayama", "before")]["pos_rms_m_median"]
    )
    assert json.loads((tmp_path / "sw" / "sweep.json").read_text())["rows"] == json.loads(json.dumps(list(rows)))


def test_a_two_worker_sweep_mixed_with_shipped_names_and_resumed(law, tmp_path):
    scn = tmp_path / "k.toml"
    scn.write_text(KINEMATIC + '[[events]]\ntime = 0.5\nkind = "control_period"\nfactor = 1.5\n')
    args = ["sweep", "k.toml", "--controllers", "law.py:Law,corradini,oracle", "--seeds", "0-2", "--out", "sw"]
    p = cli([*args, "--workers", "2"], tmp_path)
    assert p.returncode == 0, p.stderr
    assert sorted(os.listdir(tmp_path / "sw" / "k")) == ["Law", "corradini", "oracle"]
    paired = json.loads((tmp_path / "sw" / "paired.json").read_text())
    law_rows = [r for r in paired["rows"] if r["controller"] == "Law"]
    assert law_rows and all(r["pairs_vs_corradini"] == 3 for r in law_rows if r["phase"] == "after")
    assert (tmp_path / "sw" / "sweep.png").exists()
    again = cli(args, tmp_path)
    assert "9 already done" in again.stdout
    law.write_text(LAW + "\n# edited\n")  # a changed plug-in is run again on resume
    third = cli(args, tmp_path)
    assert third.returncode == 0 and "6 already done, 3 run now" in third.stdout, third.stdout


@pytest.mark.parametrize("batched", [False, True])
def test_a_plugin_that_raises_mid_sweep_is_one_failed_run(law, tmp_path, batched):
    (tmp_path / "k.toml").write_text(KINEMATIC)
    (tmp_path / "failing.py").write_text(
        LAW + "\n\nclass Failing(Law):\n    def __init__(self, T):\n        super().__init__(T, fail_at=50)\n"
    )
    args = ["sweep", "k.toml", "--controllers", "failing.py:Failing,law.py:Law", "--seeds", "0-1", "--out", "sw"]
    p = cli([*args, "--workers", "1"] + (["--batched"] if batched else []), tmp_path)
    assert p.returncode == 1
    assert "ZeroDivisionError: the law's own bug" in p.stderr
    err = (tmp_path / "sw" / "k" / "Failing" / "seed-0000" / "error.txt").read_text()
    assert "failing.py" in err and "the law's own bug" in err and "mlpfac/loop/runner.py" not in err
    assert (tmp_path / "sw" / "k" / "Law" / "seed-0001" / "metrics.json").exists()


def test_a_batch_form_plugin_runs_batched(tmp_path):
    (tmp_path / "b.py").write_text(BATCHED)
    (tmp_path / "k.toml").write_text(KINEMATIC)
    args = ["sweep", "k.toml", "--controllers", "b.py:BatchLaw,kanayama", "--seeds", "0-3", "--workers", "1"]
    one = cli([*args, "--out", "a"], tmp_path)
    batch = cli([*args, "--out", "b", "--batched"], tmp_path)
    assert one.returncode == batch.returncode == 0, batch.stderr
    for seed in range(4):
        f = f"k/batch-law/seed-{seed:04d}/metrics.json"
        ma, mb = (json.loads((tmp_path / d / f).read_text()) for d in ("a", "b"))
        assert ma["rms_position_error_m"] == mb["rms_position_error_m"]
        mk = json.loads((tmp_path / "a" / f.replace("batch-law", "kanayama")).read_text())
        assert ma["rms_position_error_m"] == pytest.approx(mk["rms_position_error_m"], rel=1e-9)


def test_a_plugin_that_raises_fails_its_run_and_keeps_the_earlier_one(law, tmp_path):
    (tmp_path / "k.toml").write_text(KINEMATIC + '[controller]\nname = "law.py:Law"\n')
    ok = cli(["run", "k.toml", "--out", "o", "--no-plot"], tmp_path)
    assert ok.returncode == 0, ok.stderr
    before = (tmp_path / "o" / "metrics.json").read_text()
    (tmp_path / "f.toml").write_text(
        KINEMATIC + '[controller]\nname = "law.py:Law"\n[controller.params]\nfail_at = 10\n'
    )
    bad = cli(["run", "f.toml", "--out", "o", "--no-plot"], tmp_path)
    assert bad.returncode == 1
    assert "law.py" in bad.stderr and "ZeroDivisionError" in bad.stderr and "mlpfac/loop/runner.py" not in bad.stderr
    assert (tmp_path / "o" / "metrics.json").read_text() == before  # the earlier run is whole
    fresh = cli(["run", "f.toml", "--out", "new", "--no-plot"], tmp_path)
    assert fresh.returncode == 1
    assert "the law's own bug" in (tmp_path / "new" / "error.txt").read_text()


@pytest.mark.parametrize(("bad", "reason"), [("nan", "non-finite command"), ("shape", "shape (3,)")])
def test_a_bad_command_ends_the_run_as_diverged(law, tmp_path, bad, reason):
    (tmp_path / "k.toml").write_text(
        KINEMATIC + f'[controller]\nname = "law.py:Law"\n[controller.params]\nbad = "{bad}"\n'
    )
    p = cli(["run", "k.toml", "--out", "o", "--no-plot", "--no-log"], tmp_path)
    assert p.returncode == 1
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["status"] == "diverged" and reason in m["reason"], m["reason"]
    assert m["steps"] == 5  # the step whose command was bad is recorded, as every divergence


NO_STEP = "class Law:\n    def __init__(self, T):\n        pass\n"
RAISES = "raise RuntimeError('broken at import')\n"

# name: (files {name: text}, argv (run or sweep), text the one line holds)
BAD_PLUGINS = {
    "missing file": ({}, ["run", "k.toml", "--controller", "nope.py:Law"], "nope.py: no such file"),
    "missing module": ({}, ["run", "k.toml", "--controller", "nomod.sub:Law"], "no module named 'nomod'"),
    "missing class": ({"law.py": LAW}, ["run", "k.toml", "--controller", "law.py:Nope"], "has no class 'Nope'"),
    "no step": ({"law.py": NO_STEP}, ["run", "k.toml", "--controller", "law.py:Law"], "no step(e, r)"),
    "not a class": ({"law.py": "Law = 3\n"}, ["run", "k.toml", "--controller", "law.py:Law"], "not a class"),
    "import raises": ({"law.py": RAISES}, ["run", "k.toml", "--controller", "law.py:Law"], "broken at import"),
    "syntax error": ({"law.py": "def (:\n"}, ["run", "k.toml", "--controller", "law.py:Law"], "SyntaxError"),
    "unknown name": ({}, ["run", "k.toml", "--controller", "pid"], "unknown controller 'pid'"),
    "shipped name": (
        {"law.py": LAW + "\nLaw.name = 'kanayama'\n"},
        ["run", "k.toml", "--controller", "law.py:Law"],
        "is a shipped controller's",
    ),
    "params not accepted": (
        {"law.py": LAW, "p.toml": KINEMATIC + '[controller]\nname = "law.py:Law"\n[controller.params]\ngain = 2\n'},
        ["run", "p.toml"],
        "[controller.params] gain",
    ),
    "params with a shipped controller": (
        {"p.toml": KINEMATIC + '[controller]\nname = "kanayama"\n[controller.params]\nKx = 2\n'},
        ["run", "p.toml"],
        "[controller] params",
    ),
    "params not a table": (
        {"law.py": LAW, "p.toml": KINEMATIC + '[controller]\nname = "law.py:Law"\nparams = 3\n'},
        ["run", "p.toml"],
        "[controller] params",
    ),
    "sweep missing class": (
        {"law.py": LAW},
        ["sweep", "k.toml", "--controllers", "corradini,law.py:X"],
        "--controllers",
    ),
    "sweep names collide": (
        {"law.py": LAW, "law2.py": LAW},
        ["sweep", "k.toml", "--controllers", "law.py:Law,law2.py:Law"],
        "both named 'Law'",
    ),
}


@pytest.mark.parametrize("case", BAD_PLUGINS)
def test_bad_plugin_input_is_one_line_and_nothing_written(tmp_path, monkeypatch, capsys, case):
    files, argv, text = BAD_PLUGINS[case]
    (tmp_path / "k.toml").write_text(KINEMATIC)
    for name, body in files.items():
        (tmp_path / name).write_text(body)
    monkeypatch.chdir(tmp_path)
    before = sorted(os.listdir(tmp_path))
    assert main([*argv, "--out", "out"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and text in err, err
    assert "Traceback" not in err
    assert sorted(os.listdir(tmp_path)) == before


def test_an_installed_package_registers_controllers(tmp_path):
    """The entry-point group mlpfac.control.baselines: a tiny installed package found by name."""
    site = tmp_path / "site"  # what `pip install --target site` leaves: the package and its dist-info
    (site / "tinylaws").mkdir(parents=True)
    (site / "tinylaws" / "__init__.py").write_text(LAW)
    info = site / "tinylaws-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: tinylaws\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[mlpfac.control.baselines]\ntiny-kanayama = tinylaws:Law\n")
    (info / "RECORD").write_text("")
    env = {**os.environ, "PYTHONPATH": str(site)}
    listed = cli(["list"], tmp_path, env)
    assert "tiny-kanayama  tinylaws:Law  (from tinylaws)" in listed.stdout, listed.stdout
    (tmp_path / "k.toml").write_text(KINEMATIC)
    p = cli(["run", "k.toml", "--controller", "tiny-kanayama", "--out", "o", "--no-plot", "--no-log"], tmp_path, env)
    assert p.returncode == 0, p.stderr
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["controller"] == "tiny-kanayama"
    prov = tomllib.loads((tmp_path / "o" / "config.toml").read_text())["provenance"]["controller"]
    assert prov["origin"] == "entry point (tinylaws)" and prov["target"] == "tinylaws:Law"


def test_a_plugin_on_a_dask_cluster_gives_the_local_rows(law, tmp_path):
    """Dask workers load the plug-in from the same absolute path (here: the same machine)."""
    distributed = pytest.importorskip("distributed")
    (tmp_path / "k.toml").write_text(KINEMATIC)
    args = ([tmp_path / "k.toml"], [f"{law}:Law", "corradini"])
    local = mlpfac.sweep(*args, seeds="0-1", workers=1)
    with distributed.LocalCluster(
        host="127.0.0.1", n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        remote = mlpfac.sweep(*args, seeds="0-1", scheduler=cluster.scheduler_address, out=tmp_path / "dask")
    assert list(remote) == list(local) and not remote.errors
    assert (tmp_path / "dask" / "k" / "Law" / "seed-0001" / "metrics.json").exists()


def test_the_python_api_runs_into_a_folder_as_the_command_does(law, tmp_path):
    (tmp_path / "k.toml").write_text(KINEMATIC)
    rec = mlpfac.run(tmp_path / "k.toml", controller=f"{law}:Law", out=tmp_path / "api")
    assert sorted(os.listdir(tmp_path / "api")) == ["config.toml", "figure1.png", "metrics.json", "run.rrd"]
    m = json.loads((tmp_path / "api" / "metrics.json").read_text())
    assert m["steps"] == rec.n and m["controller"] == "Law"
    p = cli(["run", "k.toml", "--controller", "law.py:Law", "--out", "cli"], tmp_path)
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "cli" / "config.toml").read_text() == (tmp_path / "api" / "config.toml").read_text()
    mlpfac.run(tmp_path / "k.toml", controller="kanayama", out=tmp_path / "bare", figure=None, record=False)
    assert sorted(os.listdir(tmp_path / "bare")) == ["config.toml", "metrics.json"]
    with pytest.raises(mlpfac.ConfigError, match="figure"):
        mlpfac.run(tmp_path / "k.toml", out=tmp_path / "x", figure="pid")


def test_the_readmes_controller_runs_as_written(tmp_path):
    """The class on the README's front page, copied to my_law.py, is Kanayama's law to the bit."""
    import re

    text = (REPO / "README.md").read_text()
    code = re.search(
        r"```python\n((?:# my_law.py\n)?from mlpfac.elementary import cos, sin[^\n]*\n\s*class MyLaw.*?)```", text, re.S
    )
    assert code, "README: the my_law.py block"
    (tmp_path / "my_law.py").write_text(code.group(1))
    scn = mlpfac.parse({"duration": 1.0, "plant": {"kind": "kinematic"}, "initial": {"error": [0.05, 0.02, 0.1]}})
    mine, theirs = mlpfac.run(scn, controller=f"{tmp_path}/my_law.py:MyLaw"), mlpfac.run(scn, controller="kanayama")
    np.testing.assert_array_equal(mine.u, theirs.u)


def test_a_config_of_a_class_no_file_names_is_refused_in_one_line(tmp_path, capsys):
    class Local:
        def __init__(self, T):
            pass

        def step(self, e, r):
            return r[3], r[4]

    scn = mlpfac.parse({"duration": 0.5, "plant": {"kind": "kinematic"}})
    mlpfac.run(scn, controller=Local, out=tmp_path / "o", figure=None, record=False)
    config = tomllib.loads((tmp_path / "o" / "config.toml").read_text())
    assert config["controller"]["name"].startswith("<local>:") and "Local#" in config["controller"]["name"]
    config["controller"]["name"] = config["controller"]["name"].replace("#", "#0")  # another process's
    from mlpfac.scenario.parse import to_toml

    (tmp_path / "again.toml").write_text(to_toml(config))
    assert main(["run", str(tmp_path / "again.toml"), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "put it in a file" in err


def test_a_seed_that_stopped_is_not_asked_for_telemetry_again(tmp_path):
    """In a batch without the batch form, a diverged seed's controller (which may be in a bad state)
    is neither stepped nor asked for telemetry again; the other seeds go on."""
    from mlpfac.loop.closed_loop import seeded_generators
    from mlpfac.loop.runner import run_batch

    (tmp_path / "fragile.py").write_text(
        LAW + "\n\nclass Fragile(Law):\n"
        "    def reset(self, rng):\n        super().reset(rng)\n"
        "        self.bad, self.asked = ('nan' if self.draw < 0.5 else None), 0\n"
        "    def telemetry(self):\n        self.asked += 1\n"
        "        if self.bad and self.asked > self.k:\n            raise RuntimeError('asked after it stopped')\n"
        "        return super().telemetry()\n"
    )
    draws = [seeded_generators(s)[0].random() for s in range(8)]
    assert any(d < 0.5 for d in draws) and any(d >= 0.5 for d in draws)
    spec = f"{tmp_path}/fragile.py:Fragile"
    scns = [mlpfac.parse({**tomllib.loads(KINEMATIC), "seed": s, "controller": {"name": spec}}) for s in range(8)]
    for rec, d in zip(run_batch(scns), draws, strict=True):
        assert rec.status == ("diverged" if d < 0.5 else "ok"), (d, rec.reason)


def test_sweep_workers_see_the_environment_of_the_sweep_that_uses_them(tmp_path, monkeypatch):
    """The warm fork server outlives a sweep; its workers take the sweep's environment, not the one
    it was started with."""
    (tmp_path / "envlaw.py").write_text(
        LAW + "\n\nclass EnvLaw(Law):\n    def __init__(self, T):\n"
        "        import os\n        super().__init__(T, kx=float(os.environ['MLPFAC_TEST_KX']))\n"
    )
    (tmp_path / "k.toml").write_text(
        'duration = 3.0\n[plant]\nkind = "kinematic"\n[initial]\nerror = [0.05, 0.0, 0.0]\n'
    )
    got = []
    for kx in ("2.0", "20.0"):
        monkeypatch.setenv("MLPFAC_TEST_KX", kx)
        rows = mlpfac.sweep([tmp_path / "k.toml"], [f"{tmp_path}/envlaw.py:EnvLaw"], seeds="0-1", workers=2)
        assert not rows.errors, rows.errors
        got.append(rows[0]["pos_rms_m_median"])
    assert got[0] != got[1]


SCRIBBLER = '''

class Tidy(BatchLaw):
    """BatchLaw, also for one seed's arrays (an object given to the Python API runs one seed)."""

    name = "tidy"

    def step(self, e, r):
        out = super().step(e, r)
        return out if np.ndim(e) == 2 else out[0]


class Scribbler(Tidy):
    """Tidy, then it writes into every array it was given (in place, as a law's own scratch)."""

    name = "scribbler"

    def step(self, e, r):
        out = super().step(e, r)
        e[...] = 1e3
        r[...] = 0.0
        return out


class NanRows(BatchLaw):
    """BatchLaw whose commands are NaN at step 5 for the seeds whose controller stream draws below 0.5."""

    name = "nan-rows"

    def reset(self, rngs):
        self.bad = [g.random() < 0.5 for g in (rngs if isinstance(rngs, list) else [rngs])]
        self.k = 0

    def step(self, e, r):
        out = super().step(e, r)
        self.k += 1
        if self.k == 5:
            out[self.bad] = np.nan
        return out
'''


def test_a_batch_form_plugin_that_writes_into_its_arrays_changes_nothing(tmp_path):
    """The batch form is handed copies, batched or not, and so is an object given to the Python API:
    a law that writes into e and r after its step runs to the bit as the same law that does not
    (the runner's reference and errors intact)."""
    (tmp_path / "b.py").write_text(BATCHED + SCRIBBLER)
    (tmp_path / "k.toml").write_text(KINEMATIC)
    args = ["sweep", "k.toml", "--controllers", "b.py:BatchLaw,b.py:Scribbler", "--seeds", "0-3", "--workers", "1"]
    for out, flags in (("a", []), ("b", ["--batched"])):
        done = cli([*args, "--out", out, *flags], tmp_path)
        assert done.returncode == 0, done.stderr
        for seed in range(4):
            ma, mb = (
                json.loads((tmp_path / out / f"k/{name}/seed-{seed:04d}/metrics.json").read_text())
                for name in ("batch-law", "scribbler")
            )
            assert mb["status"] == "ok" and mb["rms_position_error_m"] == ma["rms_position_error_m"], (out, seed)
    module = {}
    exec(compile(BATCHED + SCRIBBLER, str(tmp_path / "b.py"), "exec"), module)
    recs = [mlpfac.run(str(tmp_path / "k.toml"), controller=module[c](T=0.01)) for c in ("Tidy", "Scribbler")]
    assert recs[1].status == "ok" and np.array_equal(recs[0].pose, recs[1].pose)  # an object given, one seed


def test_a_batch_whose_row_is_not_finite_stops_only_that_seed(tmp_path):
    """A batch-form command with a NaN row stops that seed alone, with the reason its run alone gives
    (its row, not the batch's); batched and one by one, every seed ends the same."""
    from mlpfac.loop.closed_loop import seeded_generators

    (tmp_path / "b.py").write_text(BATCHED + SCRIBBLER)
    (tmp_path / "k.toml").write_text(KINEMATIC)
    bad = [seeded_generators(s)[0].random() < 0.5 for s in range(6)]
    assert any(bad) and not all(bad)
    args = ["sweep", "k.toml", "--controllers", "b.py:NanRows", "--seeds", "0-5", "--workers", "1"]
    ends = {}
    for out, flags in (("a", []), ("b", ["--batched"])):
        assert cli([*args, "--out", out, *flags], tmp_path).returncode == 0
        ends[out] = [
            (m["status"], m["reason"], m["steps"])
            for m in (
                json.loads((tmp_path / out / f"k/nan-rows/seed-{s:04d}/metrics.json").read_text()) for s in range(6)
            )
        ]
    assert ends["a"] == ends["b"]
    for (status, reason, _), b in zip(ends["b"], bad, strict=True):
        assert status == ("diverged" if b else "ok")
        assert reason == ("step returned a non-finite command [nan nan] at t = 0.04 s" if b else ""), reason
