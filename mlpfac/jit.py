"""The compiled kernels: built once when mlpfac is installed, or compiled by numba on first use.

Every kernel of the loop (the networks, the EKF, the laws, the error, the delay lines, the MuJoCo
plant's step, the compiled closed loop) is a plain Python function marked :func:`kernel`. Those that
Python calls are marked with their one signature; ``pip install`` compiles them ahead of time
(numba's AOT compiler, from ``setup.py``) into two extension modules: :data:`EXTENSIONS`, the second
holding the kernels that call MuJoCo's C functions, so that only the plants load it. A run then
imports neither numba nor its compiler, and the first run after an install is as fast as any other.

A built module is used only when it was built from these very files (:data:`FILES`) for this kind of
processor (``target_cpu="host"`` where the processor's flags tell kinds apart, as numba compiles on
the fly; a generic build elsewhere) and, for the MuJoCo kernels, this MuJoCo version: all are
hashed into it at build time (:func:`stamp`). The two modules are used together or not at all
(numba cannot compile a MuJoCo kernel that calls a built one). Otherwise, after an edit in a
checkout, say, numba compiles the same functions on their first call and caches them
(``cache=True``): the same code either way, and a one-line note says so. ``MLPFAC_KERNELS=jit`` asks for numba always (the test that both give the same bits);
``MLPFAC_KERNELS=aot`` refuses to start without current built modules; the build sets ``build``.

A kernel built ahead of time does not check the types of what it is given, as numba's dispatcher
does: its signature is the contract. Numba is given the same signature, so a call that would not
match it is refused under ``MLPFAC_KERNELS=jit`` (tests/test_kernels_aot.py runs the loop so), and
what Python hands a kernel from outside mlpfac goes through :func:`as_rows`.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import inspect
import os
import platform
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mlpfac.exceptions import ConfigError

ENV = "MLPFAC_KERNELS"
HERE = Path(__file__).resolve().parent
EXTENSIONS = {"core": "mlpfac._kernels", "mujoco": "mlpfac.plants._kernels"}
MODULES = {  # the modules whose kernels each extension holds
    "core": (
        "mlpfac.elementary",
        "mlpfac.normal",
        "mlpfac.model",
        "mlpfac.dynamics",
        "mlpfac.control.law",
        "mlpfac.control.policy",
        "mlpfac.control.oracle",
        "mlpfac.control.drive",
        "mlpfac.control.dynamic",
        "mlpfac.control.adaptive.kernels",
        "mlpfac.control.adaptive.dynamic_level",
        "mlpfac.loop.kernels",
        "mlpfac.control.adaptive.input_model",
        "mlpfac.control.adaptive.delay_bank",
        "mlpfac.control.mpc.kernels",
        "mlpfac.plants.events",
        "mlpfac.plants.ik",
        "mlpfac.plants.sensors.odometry",
        "mlpfac.plants.world.terrain",
    ),
    "mujoco": ("mlpfac.plants.mujoco.compiled", "mlpfac.loop.compiled", "mlpfac.plants.mujoco.predict"),
}
FILES = tuple(m.removeprefix("mlpfac.").replace(".", "/") + ".py" for ms in MODULES.values() for m in ms) + ("jit.py",)
JIT = {"cache": True, "error_model": "numpy", "nogil": True}  # numpy's inf or NaN for a division by zero
# No fastmath (so no fused multiply-add, no reassociation): numba's code rounds each operation, on any
# processor. And no Intel SVML, which numba uses for loops of transcendental functions when the
# icc_rt package is installed: its vectorised results differ from glibc's by processor.
os.environ["NUMBA_DISABLE_INTEL_SVML"] = "1"
EXPORTS: dict[str, list[tuple[str, object, Callable]]] = {ext: [] for ext in EXTENSIONS}  # symbol, signature, kernel
SALT: dict[str, str] = {}  # what else an extension's built code depends on (see built)
WHY: dict[str, str] = {}  # why an extension's built module is not used


CPU_FLAGS = (b"flags", b"Features")  # /proc/cpuinfo's line of instruction set extensions (x86, Arm)


def as_rows(x, width: int) -> np.ndarray:
    """``x``, one row (width,) or a batch (B, width) of any numbers, as the kernels take it: (B, width)
    float64 in C order (a built kernel reads memory as its signature says, whatever it is given)."""
    return np.ascontiguousarray(x, dtype=float).reshape(-1, width)


def seeds(rng) -> tuple[list[np.random.Generator], bool]:
    """The batch convention of ``reset(..., rng)``: one Generator is one run (arrays without a batch
    dimension, "single"), a sequence of B Generators is a batch (arrays (B, ...))."""
    if isinstance(rng, np.random.Generator):
        return [rng], True
    return list(rng), False


def _cpu() -> bytes:
    """What the code built for this processor needs of it: its instruction set extensions."""
    try:
        with open("/proc/cpuinfo", "rb") as f:
            for line in f:
                if line.startswith(CPU_FLAGS):
                    return line
    except OSError:
        pass
    return f"{platform.machine()} {platform.processor()}".encode()


@functools.cache
def _sources() -> bytes:
    """A hash of the processor and of the kernels' files, read once a process."""
    h = hashlib.sha256(_cpu())
    for name in FILES:
        h.update((HERE / name).read_bytes())
    return h.digest()


@functools.cache
def stamp(salt: str = "") -> int:
    """A hash of the kernels' files, of the processor and of ``salt`` (what else the built code
    depends on: the MuJoCo version for ``"mujoco"``), as a signed 64-bit number."""
    return int.from_bytes(hashlib.sha256(_sources() + salt.encode()).digest()[:8], "little", signed=True)


@functools.cache
def built(ext: str):
    """The built module of ``ext`` when it is current (``None``: numba compiles the kernels; why
    in :data:`WHY`). ``"mujoco"``'s calls MuJoCo's library by name and depends on its version:
    :mod:`mlpfac.plants.mujoco.compiled` loads the library and sets :data:`SALT` first."""
    mode = os.environ.get(ENV, "")
    if mode not in ("", "jit", "aot", "build"):
        raise ConfigError(ENV, f"{mode!r} is neither jit (numba compiles the kernels) nor aot (the built ones only)")
    if mode in ("jit", "build"):
        WHY[ext] = f"{ENV}={mode}"
        return None
    name = EXTENSIONS[ext]
    try:
        module = importlib.import_module(name)
        if module.stamp() == stamp(SALT.get(ext, "")):
            return module
        why = "was built from other sources, for another processor or another MuJoCo"
    except ImportError as exc:
        why = f"could not be imported ({exc})"
    except OSError as exc:
        why = f"cannot be checked against its sources ({exc})"
    WHY[ext] = f"{name} {why}"
    if mode == "aot":
        raise ConfigError(f"{ENV}=aot", f"{name} {why}: reinstall mlpfac (pip install .)")
    if ext == "core":  # said once a process: the first run will wait for numba
        sys.stderr.write(f"mlpfac: note: {name} {why}; numba compiles the kernels on first use\n")
    return None


def kernel(
    signature: str | Callable[[], object] | None = None, *, ext: str = "core", name: str | None = None, **options
):
    """Mark a kernel. ``signature`` (numba's, or a function giving it) for one that Python calls:
    it is built into ``ext``'s module (as ``name``, by default the function's); without one, it is
    called only by other kernels. ``options``: numba's, over :data:`JIT`."""

    def mark(fn: Callable) -> Callable:
        symbol = f"{fn.__module__.rsplit('.', 1)[-1]}__{name or fn.__name__}"
        module = built(ext)
        if module is not None:
            return getattr(module, symbol) if signature is not None else fn
        from numba import njit

        opts = {**JIT, **options}
        if os.environ.get(ENV) == "build":
            opts["cache"] = False  # a kernel loaded from numba's cache cannot be linked into a module
        if signature is None:
            return njit(**opts)(fn)
        sig = signature() if callable(signature) else signature
        try:
            compiled = njit(sig, **opts)(fn)
        except ImportError:  # numba's cache of code that has moved since (a module it names is gone)
            if not opts.get("cache"):
                raise
            compiled = njit(sig, **{**opts, "cache": False})(fn)
        EXPORTS[ext].append((symbol, sig, compiled))
        return compiled

    return mark


def build(ext: str, path: str) -> None:
    """Compile the kernels of ``ext`` into the extension module file ``path`` (``setup.py``).

    Each exported function is a call of the numba-compiled kernel, so it keeps the kernel's own
    options (``error_model="numpy"``) and releases the GIL; ``stamp()`` returns :func:`stamp` as it
    is at build time."""
    if os.environ.get(ENV) != "build":
        raise RuntimeError(f"set {ENV}=build before mlpfac's kernels are imported")
    from numba.pycc import CC, compiler

    class Flags(compiler.Flags):  # the exported functions release the GIL, as a kernel may (threads)
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            self.release_gil = True

    compiler.Flags = Flags
    for m in MODULES[ext]:
        importlib.import_module(m)
    cc = CC(EXTENSIONS[ext].rsplit(".", 1)[1])
    cc.output_dir, cc.output_file = os.path.dirname(path) or ".", os.path.basename(path)
    # this processor's instructions where the stamp can tell processors apart (their flags), else a
    # generic build that runs on any processor of the kind
    cc.target_cpu = "host" if _cpu().startswith(CPU_FLAGS) else ""
    for symbol, sig, compiled in EXPORTS[ext]:
        args = ", ".join(inspect.signature(compiled.py_func).parameters)
        ns = {"kernel": compiled}
        exec(f"def {symbol}({args}):\n    return kernel({args})", ns)
        cc.export(symbol, sig)(ns[symbol])
    ns = {}
    exec(f"def stamp():\n    return {stamp(SALT.get(ext, ''))}", ns)
    cc.export("stamp", "i8()")(ns["stamp"])
    cc.compile()
