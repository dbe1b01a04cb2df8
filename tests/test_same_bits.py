"""The same bits on every x86-64 processor (docs/reproducibility.md), tested two ways that do not
depend on the machine the tests run on:

- the runs of tests/same_bits.py (every shipped controller, our robot, the cart, torque motors, an
  event moved by a ``--vary`` point, a drawn plant; TIAGo with the ``menagerie`` marker) in
  subprocesses under every SIMD dispatch numpy and OpenBLAS can be told to take, each giving the
  bits of the default;
- the same runs with numpy's processor-dispatched maths wrapped to raise, and every BLAS and LAPACK
  function numpy, its linalg and scipy's BLAS (numba's ``np.dot``) call and every function of the
  C library's maths that rounds (sin, exp, pow, ...: from Python's math, a float's ``**``, a kernel,
  numpy's normal sampler; MuJoCo's own calls excepted) replaced by a trap (a preloaded library),
  armed while a run is planned, built and stepped: a new call in the simulated path fails here
  whatever the processor and maths library.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from conftest import menagerie_missing

HERE = Path(__file__).resolve().parent
HARNESS = HERE / "same_bits.py"
NUMPY_AVX512 = "X86_V4 AVX512_ICL AVX512_SPR"
DISPATCHES = {  # name: environment
    "default": {},
    "numpy-no-avx512": {"NPY_DISABLE_CPU_FEATURES": NUMPY_AVX512},
    "numpy-no-avx2-fma": {"NPY_DISABLE_CPU_FEATURES": f"X86_V3 {NUMPY_AVX512}"},
    "openblas-skylakex": {"OPENBLAS_CORETYPE": "SkylakeX"},
    "openblas-haswell": {"OPENBLAS_CORETYPE": "Haswell"},
    "openblas-sandybridge": {"OPENBLAS_CORETYPE": "Sandybridge"},
    "openblas-prescott": {"OPENBLAS_CORETYPE": "Prescott"},
}
PROBE = "import numpy as np; a = np.ones((64, 64)); a @ a"


def runs(env: dict, *args: str) -> dict:
    """The harness's digests in a fresh process with ``env`` set."""
    out = subprocess.run(
        [sys.executable, "-X", "faulthandler", str(HARNESS), *args],
        env=os.environ | env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0, f"{env}: exit {out.returncode}\n{out.stderr[-4000:]}"
    return json.loads(out.stdout)


def runs_here(env: dict) -> bool:
    """Whether this processor can take the dispatch (OpenBLAS's AVX-512 kernels need AVX-512)."""
    return subprocess.run([sys.executable, "-c", PROBE], env=os.environ | env, capture_output=True).returncode == 0


def under_every_dispatch(*args: str) -> dict[str, dict]:
    """The digests under each dispatch this processor can take, two processes at a time."""
    names = [n for n, env in DISPATCHES.items() if runs_here(env)]
    with ThreadPoolExecutor(2) as pool:
        found = pool.map(lambda n: runs(DISPATCHES[n], *args), names)
    return dict(zip(names, found, strict=True))


def assert_same(found: dict[str, dict], runs_at_least: int) -> None:
    base = found["default"]
    assert len(base) >= runs_at_least
    for name, digests in found.items():
        moved = sorted(k for k in base if digests.get(k) != base[k])
        assert not moved, f"under {name} ({DISPATCHES[name]}) these runs' bits moved: {moved}"


@pytest.fixture(scope="module")
def dispatched() -> dict[str, dict]:
    return under_every_dispatch()


def test_every_dispatch_gives_the_same_bits(dispatched):
    assert "openblas-prescott" in dispatched and "numpy-no-avx2-fma" in dispatched
    assert_same(dispatched, 30)


@pytest.mark.menagerie
def test_every_dispatch_gives_the_same_bits_on_tiago():
    found = under_every_dispatch("--only-menagerie")
    assert all(k.startswith("tiago") for k in found["default"])
    assert_same(found, 2)


@pytest.fixture(scope="module")
def shim(tmp_path_factory) -> Path:
    lib = HERE / "same_bits.py"
    sys.path.insert(0, str(lib.parent))
    from same_bits import build_shim

    built = build_shim(tmp_path_factory.mktemp("trap"))
    if built is None:
        pytest.skip("needs a C compiler and nm to build the BLAS trap")
    return built


def test_nothing_in_the_simulated_path_calls_dispatched_maths_or_blas(shim, dispatched):
    """The runs with the trap armed: the same digests (the trap changes nothing it does not stop)."""
    args = ("--trap",) + (() if menagerie_missing() else ("--menagerie",))
    found = runs({"LD_PRELOAD": str(shim)}, *args)
    assert {k: v for k, v in found.items() if k in dispatched["default"]} == dispatched["default"]


@pytest.mark.parametrize(
    "snippet, says",
    [
        ("np.ones(3) @ np.ones(3)", "scipy_cblas_ddot64_"),
        ("np.ones((4, 4)) @ np.ones((4, 4))", "scipy_cblas_dgemm64_"),
        ("np.linalg.cholesky(np.eye(3))", "np.linalg.cholesky called"),
        ("np.tanh(np.ones(3))", "np.tanh called"),
        ("np.arctan2(1.0, 2.0)", "np.arctan2 called"),
        ("math.sin(1.0)", "the C library's sin called"),
        ("x = 1.1; x ** 2.0", "the C library's pow called"),
        ("np.random.default_rng(0).standard_normal(10000)", "the C library's exp called"),
    ],
)
def test_the_trap_catches(shim, snippet, says):
    """The trap can fail: each kind of call it stands in front of, armed, ends the process naming it
    (numpy's ziggurat, ``Generator.standard_normal``, calls the C library's exp in its wedges)."""
    code = f"import math, sys; sys.path.insert(0, {str(HERE)!r}); import numpy as np, same_bits as sb\n"
    code += f"sb.install_trap()\n{snippet}\nwith sb.armed():\n    {snippet}\n"
    out = subprocess.run(
        [sys.executable, "-c", code], env=os.environ | {"LD_PRELOAD": str(shim)}, capture_output=True, text=True
    )
    assert out.returncode != 0 and says in out.stderr, out.stderr[-2000:]


BUDGET = """scenarios = ["paper"]
controllers = ["adaptive-ukf", "adaptive-cautious"]
seeds = "0-1"
duration = 3.0

[[budget]]
name = "as the baseline"
no_worse_than_baseline = 1.0
"""


def test_a_baseline_from_one_dispatch_judges_another_by_the_same_figures(tmp_path):
    """``mlpfac check --baseline``: the baseline made under the default dispatch, the check run with
    numpy's AVX2 and FMA off and OpenBLAS's oldest kernels: every run's metrics.json the same bits."""
    from mlpfac.report.verify import digest

    (tmp_path / "budget.toml").write_text(BUDGET)
    (tmp_path / "base.toml").write_text(BUDGET.replace("no_worse_than_baseline = 1.0", "diverged = 0"))
    cli = [str(Path(sys.executable).with_name("mlpfac")), "check", "--workers", "1"]
    other = {"NPY_DISABLE_CPU_FEATURES": f"X86_V3 {NUMPY_AVX512}", "OPENBLAS_CORETYPE": "Prescott"}
    for budget, out, env, extra in (
        ("base.toml", "base", {}, []),
        ("budget.toml", "other", other, ["--baseline", "base", "--summary", "check.md"]),
    ):
        done = subprocess.run(
            [*cli, budget, "--out", out, *extra], cwd=tmp_path, env=os.environ | env, capture_output=True, text=True
        )
        assert done.returncode == 0, done.stderr[-2000:]

    def figures(out: str) -> dict:
        return {
            f.relative_to(tmp_path / out).parent: digest(json.loads(f.read_text()))
            for f in (tmp_path / out).glob("*/*/seed-*/metrics.json")
        }

    assert len(figures("base")) == 4 and figures("other") == figures("base")
    assert "mlpfac check: pass" in (tmp_path / "check.md").read_text()


@pytest.mark.parametrize("n", [1, 2, 3, 6])
def test_the_linear_algebra_written_out_agrees_with_lapack(n):
    """mlpfac.model's Cholesky, solves and Jacobi eigenvalues (batched, as the UKF calls them)
    against numpy's LAPACK, to rounding; a semi-definite matrix's zero pivot gives a zero column."""
    import numpy as np

    from mlpfac.elementary import atan2, each
    from mlpfac.model import cholesky, eigh, solve_lower, solve_spd

    rng = np.random.default_rng(n)
    M = rng.standard_normal((5, n, n))
    P = M @ np.swapaxes(M, -1, -2) + 0.1 * np.eye(n)
    L = cholesky(P)
    np.testing.assert_allclose(L, np.linalg.cholesky(P), rtol=1e-10, atol=1e-12)
    B = rng.standard_normal((5, n, 2))
    np.testing.assert_allclose(solve_lower(L, B), np.linalg.solve(L, B), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(solve_spd(P, B), np.linalg.solve(P, B), rtol=1e-9, atol=1e-12)
    S = M + np.swapaxes(M, -1, -2)
    w, V = eigh(S)
    np.testing.assert_allclose(np.sort(w, axis=-1), np.linalg.eigvalsh(S), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose((V * w[..., None, :]) @ np.swapaxes(V, -1, -2), S, atol=1e-12)
    assert (cholesky(np.diag([4.0, 0.0, 9.0])) == np.diag([2.0, 0.0, 3.0])).all()
    x = np.linspace(-3.0, 3.0, 7).reshape(7, 1)
    assert each(atan2, x, 2.0).shape == (7, 1) and each(atan2, x, 2.0)[0, 0] == atan2(-3.0, 2.0)
