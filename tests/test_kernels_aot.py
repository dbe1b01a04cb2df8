"""The kernels built at install (mlpfac.jit): used when current, the same bits as numba's, and
called only with the types their signatures name."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from mlpfac import jit
from mlpfac.control.variants import CONTROLLERS, TORQUE_LEVEL
from mlpfac.exceptions import ConfigError

# Short runs that call every exported kernel between them: every shipped controller (the adaptive
# step and its EKF, the estimators' ekf_update, the input model and the delay bank, the baselines'
# compiled closed loop, a delay line of integers: the oracle's; a policy's MLP), the torque-driven
# wheels, the kinematic plant, batches of seeds (B > 1) on both plants, and the vector environment.
RUNS = (
    *(("eight-nominal", c) for c in CONTROLLERS if c not in TORQUE_LEVEL),
    *(("eight-torque", c) for c in TORQUE_LEVEL),  # the wheels' torques: a robot with torque motors
    ("eight-sensor-delay", "oracle"),
    ("eight-torque", "kanayama"),
    ("paper", "adaptive-prior"),
    ("paper", "kanayama"),
)
BATCHES = (
    ("paper", "adaptive"),
    ("paper", "adaptive-cautious"),
    ("paper", "corradini"),
    ("eight-nominal", "adaptive"),
    ("eight-torque", "adaptive-dynamic"),
)

SCRIPT = textwrap.dedent(
    """
    import hashlib, json, sys
    import numpy as np
    import mlpfac
    from mlpfac.control.adaptive.kernels import networks_h_jacobian

    from mlpfac.loop.runner import run_batch
    from mlpfac.scenario.parse import load

    def digest(r):
        return hashlib.sha256(b"".join(a.tobytes() for a in (r.pose, r.e, r.u))).hexdigest()

    out = {}
    runs, batches = json.loads(sys.argv[1])
    for scenario, controller in runs:
        out[f"{scenario} {controller}"] = digest(mlpfac.run(scenario, controller, duration=2.0, figure=None))
    for scenario, controller in batches:
        s = load(scenario).with_overrides(controller=controller, duration=2.0)
        recs = run_batch([s.with_overrides(seed=k) for k in range(3)])
        out[f"{scenario} {controller} batch"] = [digest(r) for r in recs]
    rng = np.random.default_rng(0)
    z, xf, xG, e, u = (rng.normal(size=s) for s in ((2, 162), (2, 6), (2, 3), (2, 3), (2, 2)))
    h, H = np.empty((2, 3)), np.empty((2, 3, 162))
    networks_h_jacobian(z, xf, xG, e, u, 9, 9, True, h, H)
    out["jacobian"] = hashlib.sha256(h.tobytes() + H.tobytes()).hexdigest()
    import gymnasium, mlpfac.envs  # the vector environment's kernel (many robots a call), and a policy's inputs
    from mlpfac.control.policy import features
    v = gymnasium.make_vec("mlpfac/Track-v0", num_envs=2, vectorization_mode="vector_entry_point", duration=0.3)
    obs, _ = v.reset(seed=0)
    for _ in range(40):
        obs = v.step(obs[:, 6:8])[0]
    X = np.empty((2, 8))
    features(np.ascontiguousarray(obs[:, :3]), np.ascontiguousarray(obs[:, 6:8]), np.ascontiguousarray(obs[:, 8:10]),
             2.0, 5.0, np.full(8, 0.1), 5.0, X)
    out["vector env"] = hashlib.sha256(obs.tobytes() + X.tobytes()).hexdigest()
    print(json.dumps({"runs": out, "numba": "numba" in sys.modules}))
    """
)


def _hashes(mode: str) -> dict:
    env = dict(os.environ, MLPFAC_KERNELS=mode)
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, json.dumps([RUNS, BATCHES])],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(os.environ.get(jit.ENV) == "jit", reason="MLPFAC_KERNELS=jit: numba compiles them")
def test_the_installed_kernels_are_current_and_used():
    """An install (editable or not) builds them: a run imports neither numba nor its compiler."""
    import mlpfac.plants.mujoco.compiled  # noqa: F401  (loads MuJoCo's library, which the second module calls)

    for ext, name in jit.EXTENSIONS.items():
        assert jit.built(ext) is not None, f"{name} is missing or stale: reinstall (pip install -e .)"
    got = _hashes("aot")
    assert got["numba"] is False


def test_built_and_numba_compiled_kernels_give_the_same_bits():
    """Under MLPFAC_KERNELS=jit numba compiles the same functions with the same signatures (so a
    call of another type is refused there, where the built module would not check it)."""
    built, compiled = _hashes("aot"), _hashes("jit")
    assert compiled["numba"] is True
    assert built["runs"] == compiled["runs"]


def test_stale_or_missing_kernels_are_compiled_or_refused(monkeypatch, capsys):
    """A module built from other sources is not used: numba compiles instead, and a note says so
    once, or, with MLPFAC_KERNELS=aot, one line refuses."""
    jit.built.cache_clear()
    monkeypatch.setattr(jit, "stamp", lambda salt="": 12345)
    try:
        monkeypatch.setenv("MLPFAC_KERNELS", "")
        assert jit.built("core") is None and jit.built("core") is None
        note = capsys.readouterr().err.splitlines()
        assert len(note) == 1 and note[0].startswith("mlpfac: note: mlpfac._kernels was built from other sources")
        jit.built.cache_clear()
        monkeypatch.setenv("MLPFAC_KERNELS", "aot")
        with pytest.raises(ConfigError, match="built from other sources"):
            jit.built("core")
        jit.built.cache_clear()
        monkeypatch.setenv("MLPFAC_KERNELS", "fast")
        with pytest.raises(ConfigError, match="MLPFAC_KERNELS: 'fast' is neither"):
            jit.built("core")
    finally:
        jit.built.cache_clear()


def test_the_stamp_covers_every_kernel_file_and_the_processor():
    files = {f.removesuffix(".py").replace("/", ".") for f in jit.FILES}
    for modules in jit.MODULES.values():
        assert {m.removeprefix("mlpfac.") for m in modules} <= files
    for m in (sys.modules[m] for ms in jit.MODULES.values() for m in ms if m in sys.modules):
        assert any(m.__file__.endswith(f) for f in jit.FILES)
    h = hashlib.sha256(jit._cpu())
    for name in jit.FILES:
        h.update((jit.HERE / name).read_bytes())
    for salt in ("", "4.0.0"):  # the salt (MuJoCo's version for the MuJoCo kernels) over the files' hash
        expected = hashlib.sha256(h.digest() + salt.encode()).digest()[:8]
        assert jit.stamp(salt) == int.from_bytes(expected, "little", signed=True)
    assert jit.stamp("4.0.0") != jit.stamp("4.0.1")


def test_a_delay_line_of_integers_or_strided_rows_pushes_what_it_was_given():
    from mlpfac.plants.events import DelayLine

    line = DelayLine(np.int32(3))
    assert line.hist.dtype == np.int64
    line.push(np.int16(4))
    assert line.read() == 4
    rows = DelayLine(np.zeros(3))
    x = np.arange(6.0)[::2]  # not contiguous: copied before the kernel reads it
    rows.push(x)
    assert np.array_equal(rows.read(), [0.0, 2.0, 4.0])


@pytest.mark.skipif(os.environ.get(jit.ENV) == "jit", reason="MLPFAC_KERNELS=jit: numba compiles them")
def test_a_mujoco_other_than_the_built_ones_asks_for_a_reinstall():
    """The MuJoCo kernels were built against one MuJoCo's functions and enums; the core kernels
    built, they cannot be compiled by numba instead (they call the built ones): one line."""
    script = "import mujoco; mujoco.__version__ = '0.0.0'; import mlpfac.plants.mujoco.compiled"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert out.returncode != 0
    assert "mlpfac.plants._kernels was built from other sources, for another processor or another MuJoCo" in out.stderr
    assert "pip install --force-reinstall --no-deps mlpfac" in out.stderr


def test_a_numba_cache_of_moved_code_is_compiled_afresh(monkeypatch):
    """A checkout whose numba cache names a module that has moved since (numba's index unpickles it:
    ModuleNotFoundError) compiles the kernel again without the cache, never fails to import."""
    import numba

    from mlpfac import jit

    real, calls = numba.njit, []

    def njit(*args, **opts):
        calls.append(opts.get("cache"))
        if opts.get("cache"):

            def stale(fn):
                raise ModuleNotFoundError("No module named 'mlpfac.plants.compiled'")

            return stale
        return real(*args, **opts)

    monkeypatch.setenv(jit.ENV, "jit")
    monkeypatch.setattr(numba, "njit", njit)
    monkeypatch.setitem(jit.EXPORTS, "core", [])

    def plus_one(x):
        return x + 1.0

    jit.built.cache_clear()  # built() is read once a process: asked again under MLPFAC_KERNELS=jit
    try:
        assert jit.kernel("f8(f8)")(plus_one)(1.0) == 2.0 and calls[:2] == [True, False]  # cached, then not
    finally:
        jit.built.cache_clear()  # and again for the tests after this one
