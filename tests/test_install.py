"""A regular (non-editable) install is the whole tool: the wheel carries the shipped scenarios and
robot, and a fresh environment with only the wheel lists and runs every shipped scenario from a
folder far from the source."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    build = tmp_path_factory.mktemp("build")  # setuptools' build/ folder, away from the checkout
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(out), str(ROOT)],
        capture_output=True,
        text=True,
        cwd=build,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    (whl,) = out.glob("mlpfac-*.whl")
    return whl


def test_the_wheel_holds_every_shipped_scenario_and_robot_file(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for folder, package in (("sims", "mlpfac/sims"), ("models", "mlpfac/models")):
        for f in (ROOT / folder).iterdir():
            if f.suffix in (".toml", ".xml", ".md", ".csv"):  # sims/lane-change.csv: a path's waypoints
                assert f"{package}/{f.name}" in names, f.name
    for f in (ROOT / "mlpfac").rglob("*.py"):  # every module, in every subpackage
        assert f.relative_to(ROOT).as_posix() in names, f
    import mlpfac

    assert wheel.name.startswith(f"mlpfac-{mlpfac.__version__}-")  # the version is written once, in mlpfac
    assert any(n.endswith(("/LICENSE", "/licenses/LICENSE")) and ".dist-info/" in n for n in names)
    for module in ("mlpfac/_kernels", "mlpfac/plants/_kernels"):  # the kernels built at install (mlpfac.jit)
        assert any(n.startswith(module + ".") and n.endswith((".so", ".pyd")) for n in names), module


@pytest.mark.slow
def test_a_fresh_install_lists_and_runs_every_shipped_scenario(wheel, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    py = venv / "bin" / "python"
    proc = subprocess.run(
        [str(py), "-m", "pip", "install", "-q", str(wheel)], capture_output=True, text=True, timeout=1200
    )
    assert proc.returncode == 0, proc.stderr
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}

    def mlpfac(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [str(venv / "bin" / "mlpfac"), *args], capture_output=True, text=True, cwd=work, env=env, timeout=600
        )

    where = subprocess.run(
        [str(py), "-c", "import mlpfac; print(mlpfac.__file__)"], capture_output=True, text=True, cwd=work, env=env
    )
    assert where.stdout.startswith(str(venv)), where.stdout  # not the checkout
    built = subprocess.run(  # the wheel's built kernels are used: a run imports no numba
        [
            str(py),
            "-c",
            "import sys, mlpfac; mlpfac.run('eight-nominal', duration=0.3, figure=None); print('numba' in sys.modules)",
        ],
        capture_output=True,
        text=True,
        cwd=work,
        env={**env, "MLPFAC_KERNELS": "aot"},
    )
    assert built.returncode == 0 and built.stdout.strip() == "False", built.stderr
    listed = mlpfac("list")
    assert listed.returncode == 0, listed.stderr
    shipped = sorted(p.stem for p in (ROOT / "sims").glob("*.toml"))
    assert [line.split()[0] for line in listed.stdout.splitlines()[: len(shipped)]] == shipped
    for name in shipped:
        res = mlpfac("run", name, "--duration", "0.3", "--no-plot", "--out", f"runs/{name}")
        if name.startswith("tiago-"):  # a Menagerie robot: the wheel alone lacks the package, and says so
            assert res.returncode == 2 and "pip install 'mlpfac[menagerie]'" in res.stderr, (name, res.stderr)
            continue
        assert res.returncode == (1 if name == "paper-faithful" else 0), (name, res.stderr)
        assert (work / "runs" / name / "metrics.json").is_file() and (work / "runs" / name / "run.rrd").is_file()
