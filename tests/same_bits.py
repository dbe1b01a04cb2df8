"""Runs whose bits must not depend on the processor: what tests/test_same_bits.py runs in subprocesses.

``python tests/same_bits.py [--menagerie | --only-menagerie] [--trap]`` prints one JSON object, a digest per run (of
every array of its record and of its metrics.json): the same object under every SIMD dispatch
numpy and OpenBLAS can be told to take. With ``--trap`` every call of numpy's processor-dispatched
maths (:data:`TRAPPED`) and of ``np.linalg`` raises while a run is built and stepped, and, in a
process started with ``LD_PRELOAD`` set to :func:`build_shim`'s library, so does every call into
BLAS or LAPACK (``@``, ``np.dot``, ``np.linalg``, numba's ``np.dot``) and into the C library's
maths functions that round (``sin``, ``exp``, ``pow``, ...; from anywhere but MuJoCo's library):
the process aborts, naming the function, and faulthandler prints where Python was.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

# numpy's functions whose float loops are chosen by the processor (SIMD versions of their own, or
# OpenBLAS's kernels): correctly rounded arithmetic (+ - * / sqrt, min, max, abs) is not among them
TRAPPED = [
    "exp",
    "exp2",
    "expm1",
    "log",
    "log2",
    "log10",
    "log1p",
    "sin",
    "cos",
    "tan",
    "arcsin",
    "arccos",
    "arctan",
    "arctan2",
    "sinh",
    "cosh",
    "tanh",
    "arcsinh",
    "arccosh",
    "arctanh",
    "hypot",
    "power",
    "float_power",
    "cbrt",
    "logaddexp",
    "logaddexp2",
    "dot",
    "vdot",
    "inner",
    "matmul",
    "tensordot",
]
ARMED = [False]
SURVEY: set[str] = set()
HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

# (scenario, controllers, duration, --vary): short runs that reach every controller (None: every
# shipped one, on FALLBACK those the kinematic model cannot run), our robot, the
# cart, torque motors, an event (moved early by a --vary point), a drawn plant, paths, a pose
# from odometry and from odometry fused with delayed fixes, rough ground, and a tow of a share of the
# weight with a gust of noise
RUNS = [
    ("paper", None, 3.0, ["events.0.time=2.5"]),
    ("eight-payload", ("corradini", "kanayama", "adaptive", "adaptive-ukf", "oracle"), 1.0, ["events.0.time=0.6"]),
    ("eight-payload", ("adaptive-real",), 1.0, ["events.0.time=0.6", "events.0.mass_scale=normal:3:0.5"]),
    ("eight-torque", ("corradini", "adaptive-input-delay"), 0.6, []),
    ("eight-sensor-delay", ("oracle", "oracle-kanayama"), 1.0, ["events.0.time=0.5"]),
    ("cart-sensor-delay", ("kanayama", "adaptive-real-fast"), 1.0, ["events.0.time=0.5"]),
    ("route", ("kanayama", "adaptive"), 1.0, ["reference.points.1.0=5.5"]),  # a path, a waypoint moved
    ("lane-change", ("corradini",), 1.0, []),  # a path from a CSV file
    ("route@diffdrive-torque", ("fierro-lewis",), 0.6, []),  # a path's own rates, to a torque-level law
    ("eight-wheel-radius-odometry", ("kanayama", "adaptive"), 1.0, ["events.0.time=0.5"]),
    ("eight-wheel-radius-fused", ("kanayama", "adaptive"), 1.0, ["events.0.time=0.5", "plant.fix_latency_s=0.05"]),
    ("eight-bumps", ("kanayama",), 1.0, []),  # rough ground drawn per seed, carried by contact tiles
    ("tests/data/eight-gust.toml", ("corradini",), 1.0, []),  # a tow of a share of the weight, and a gust
]
FALLBACK = "eight-torque"  # where a shipped controller runs that the kinematic model cannot (torque level)
MENAGERIE = [("tiago-friction", ("corradini", "adaptive"), 1.0, ["events.0.time=0.5"])]


def _trapping(name: str, fn):
    def trapped(*args, **kwargs):
        if ARMED[0] and os.environ.get("SAME_BITS_SURVEY"):
            f = sys._getframe(1)
            SURVEY.add(f"np.{name} {f.f_code.co_filename.split('/mlpfac/')[-1]}:{f.f_lineno}")
        elif ARMED[0]:
            raise AssertionError(f"np.{name} called in the simulated path: its bits depend on the processor")
        return fn(*args, **kwargs)

    return trapped


def install_trap() -> None:
    """Wrap numpy's processor-dispatched functions and np.linalg's to raise while armed."""
    for name in TRAPPED:
        setattr(np, name, _trapping(name, getattr(np, name)))
    for name in np.linalg.__all__:
        fn = getattr(np.linalg, name)
        if callable(fn) and not isinstance(fn, type):
            setattr(np.linalg, name, _trapping(f"linalg.{name}", fn))


def _shim():
    """The preloaded trap library (:func:`build_shim`), or None."""
    shim = os.environ.get("LD_PRELOAD", "")
    return ctypes.CDLL(shim) if shim.endswith("blas_trap.so") else None


@contextlib.contextmanager
def armed():
    """The trap armed (numpy's functions and, when preloaded, the shim's BLAS and LAPACK)."""
    lib = _shim()
    ARMED[0] = True
    if lib is not None:
        lib.blas_trap_arm(1)
    try:
        yield
    finally:
        ARMED[0] = False
        if lib is not None:
            lib.blas_trap_arm(0)


def record_digest(rec, metrics: dict) -> str:
    """Every array of the record and its metrics (but the wall-clock time), as one hash."""
    from mlpfac.report.verify import digest

    h = hashlib.sha256(digest(metrics).encode())
    for key in sorted(vars(rec)):
        value = getattr(rec, key)
        if isinstance(value, np.ndarray) and value.dtype.kind in "fiub":
            h.update(key.encode() + np.ascontiguousarray(value).tobytes())
    return h.hexdigest()[:24]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--menagerie", action="store_true")
    parser.add_argument("--only-menagerie", action="store_true")
    parser.add_argument("--trap", action="store_true")
    args = parser.parse_args()
    from mlpfac.control.variants import CONTROLLERS
    from mlpfac.exceptions import ConfigError
    from mlpfac.loop.metrics import metrics
    from mlpfac.loop.runner import run
    from mlpfac.scenario.parse import parse
    from mlpfac.sweeps.plan import plan
    from mlpfac.sweeps.vary import parse_vary

    if args.trap:
        import scipy.interpolate  # noqa: F401  (a path's spline: importing scipy computes constants with np.log)

        install_trap()
    out = {}
    os.chdir(ROOT)
    for scenario, controllers, duration, vary in (
        MENAGERIE if args.only_menagerie else RUNS + (MENAGERIE if args.menagerie else [])
    ):
        jobs = []
        for c in controllers or CONTROLLERS:
            with armed():  # the robot is read and its reference fitted here
                try:
                    jobs += plan([scenario], [c], [3], duration, parse_vary(vary))
                except ConfigError:  # a controller the kinematic model cannot run (one acting on torques)
                    if controllers is not None:
                        raise
                    jobs += plan([FALLBACK], [c], [3], 1.0, parse_vary([]))
        for job in jobs:
            with armed():
                rec = run(parse(job.table, job.source))
                m = metrics(rec)
            out[f"{job.scenario} {job.controller} {job.seed}"] = record_digest(rec, m)
    print(json.dumps(out, indent=1, sort_keys=True))
    if SURVEY:
        print("\n".join(sorted(SURVEY)), file=sys.stderr)


SHIM = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <link.h>
#include <stdio.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#define HIDDEN __attribute__((visibility("hidden"), used))
HIDDEN volatile int blas_trap_armed = 0;
void blas_trap_arm(int on) { blas_trap_armed = on; }
HIDDEN void blas_trap_hit(const char *name) {
    fprintf(stderr, "BLAS/LAPACK called in the simulated path: %s (its bits depend on the processor)\n", name);
    fflush(stderr);
    abort();
}
extern const char *blas_trap_names[];
HIDDEN void *blas_trap_reals[NAMES];
static const char *wanted;
static void *found;
static int look(struct dl_phdr_info *info, size_t size, void *self) {
    const char *path = info->dlpi_name;
    if (!path || !*path || strstr(path, "blas_trap") || !(strstr(path, "blas") || strstr(path, "lapack"))) return 0;
    void *h = dlopen(path, RTLD_NOLOAD | RTLD_LAZY);
    if (h) found = dlsym(h, wanted);
    return found != NULL;
}
HIDDEN void *blas_trap_resolve(long i) {  /* the real function, in the BLAS or LAPACK library loaded */
    wanted = blas_trap_names[i];
    found = NULL;
    dl_iterate_phdr(look, NULL);
    if (!found) { fprintf(stderr, "blas_trap: %s not found\n", wanted); abort(); }
    return blas_trap_reals[i] = found;
}
__asm__(".globl blas_trap_slow\n.hidden blas_trap_slow\nblas_trap_slow:\n"
        "pushq %rdi\npushq %rsi\npushq %rdx\npushq %rcx\npushq %r8\npushq %r9\nsubq $136, %rsp\n"
        "movdqu %xmm0, 0(%rsp)\nmovdqu %xmm1, 16(%rsp)\nmovdqu %xmm2, 32(%rsp)\nmovdqu %xmm3, 48(%rsp)\n"
        "movdqu %xmm4, 64(%rsp)\nmovdqu %xmm5, 80(%rsp)\nmovdqu %xmm6, 96(%rsp)\nmovdqu %xmm7, 112(%rsp)\n"
        "movq %r11, %rdi\ncall blas_trap_resolve\nmovq %rax, %r11\n"
        "movdqu 0(%rsp), %xmm0\nmovdqu 16(%rsp), %xmm1\nmovdqu 32(%rsp), %xmm2\nmovdqu 48(%rsp), %xmm3\n"
        "movdqu 64(%rsp), %xmm4\nmovdqu 80(%rsp), %xmm5\nmovdqu 96(%rsp), %xmm6\nmovdqu 112(%rsp), %xmm7\n"
        "addq $136, %rsp\npopq %r9\npopq %r8\npopq %rcx\npopq %rdx\npopq %rsi\npopq %rdi\njmp *%r11\n");
/* The C library's maths, whose last bits differ between libraries and processors: armed, a call
   from anywhere but MuJoCo's own library aborts, naming the function and its caller's library. */
static uintptr_t libm_allowed[16][2];
static int libm_nallowed;
static int libm_note(struct dl_phdr_info *info, size_t size, void *data) {
    if (!info->dlpi_name || !strstr(info->dlpi_name, "libmujoco")) return 0;
    for (int j = 0; j < info->dlpi_phnum && libm_nallowed < 16; j++, libm_nallowed++) {
        libm_allowed[libm_nallowed][0] = info->dlpi_addr + info->dlpi_phdr[j].p_vaddr;
        libm_allowed[libm_nallowed][1] = libm_allowed[libm_nallowed][0] + info->dlpi_phdr[j].p_memsz;
    }
    return 0;
}
HIDDEN void libm_check(const char *name, void *caller) {
    if (!blas_trap_armed) return;
    if (!libm_nallowed) dl_iterate_phdr(libm_note, NULL);
    for (int i = 0; i < libm_nallowed; i++)
        if ((uintptr_t)caller >= libm_allowed[i][0] && (uintptr_t)caller < libm_allowed[i][1]) return;
    Dl_info info;
    fprintf(stderr, "the C library's %s called in the simulated path from %s (its bits depend on the maths library)\n",
            name, dladdr(caller, &info) && info.dli_fname ? info.dli_fname : "?");
    fflush(stderr);
    abort();
}
#define LIBM1(f) double f(double x) { static double (*real)(double); \
    libm_check(#f, __builtin_return_address(0)); if (!real) real = dlsym(RTLD_NEXT, #f); return real(x); }
#define LIBM2(f) double f(double x, double y) { static double (*real)(double, double); \
    libm_check(#f, __builtin_return_address(0)); if (!real) real = dlsym(RTLD_NEXT, #f); return real(x, y); }
void sincos(double x, double *s, double *c) {
    static void (*real)(double, double *, double *);
    libm_check("sincos", __builtin_return_address(0));
    if (!real) real = dlsym(RTLD_NEXT, "sincos");
    real(x, s, c);
}
"""
LIBM = {  # the C library's functions of doubles that round (not sqrt, fmod, floor, frexp, ldexp: exact)
    1: "sin cos tan asin acos atan sinh cosh tanh asinh acosh atanh exp exp2 exp10 expm1 log log2 log10 log1p cbrt erf erfc lgamma tgamma",
    2: "atan2 pow hypot",
}
STUB = (
    '__asm__(".globl {name}\\n.type {name},@function\\n{name}:\\n'
    "cmpl $0, blas_trap_armed(%rip)\\njne 1f\\nmovq blas_trap_reals+{off}(%rip), %r11\\n"
    "testq %r11, %r11\\nje 2f\\njmp *%r11\\n"
    "1: leaq blas_trap_str_{i}(%rip), %rdi\\njmp blas_trap_hit\\n"
    '2: movq ${i}, %r11\\njmp blas_trap_slow\\n");'
)


def build_shim(folder: Path) -> Path | None:
    """A library that, preloaded, stands in front of every BLAS and LAPACK function numpy, numpy's
    linalg and scipy's BLAS (numba's ``np.dot``) import, and of the C library's maths functions of
    :data:`LIBM`: armed, it aborts naming the function (a maths function called from MuJoCo's own
    library excepted); otherwise it jumps to the real one (found on its first call). None where no
    C compiler or ``nm`` is found."""
    import shutil

    cc, nm = shutil.which("cc") or shutil.which("gcc"), shutil.which("nm")
    if cc is None or nm is None:
        return None
    libs = list(Path(np.__file__).parent.glob("_core/_multiarray_umath*.so"))
    libs += list(Path(np.__file__).parent.glob("linalg/_umath_linalg*.so"))
    with contextlib.suppress(ImportError):
        import scipy.linalg

        libs += list(Path(scipy.linalg.__file__).parent.glob("cython_blas*.so"))
        libs += list(Path(scipy.linalg.__file__).parent.glob("cython_lapack*.so"))
    names = set()
    for lib in libs:
        undefined = subprocess.run([nm, "-D", "--undefined-only", str(lib)], capture_output=True, text=True, check=True)
        for line in undefined.stdout.splitlines():
            name = line.split()[-1].split("@")[0]
            if name.startswith("scipy_") or "blas" in name:
                names.add(name)
    names = sorted(names)
    src = [SHIM.replace("NAMES", str(len(names)))]
    src += [f'HIDDEN const char blas_trap_str_{i}[] = "{n}";' for i, n in enumerate(names)]
    src += ["const char *blas_trap_names[] = {" + ", ".join(f"blas_trap_str_{i}" for i in range(len(names))) + "};"]
    src += [STUB.format(name=n, i=i, off=8 * i) for i, n in enumerate(names)]
    src += [f"LIBM{k}({f})" for k, fs in LIBM.items() for f in fs.split()]
    (folder / "blas_trap.c").write_text("\n".join(src) + "\n")
    out = folder / "blas_trap.so"
    cmd = [cc, "-shared", "-fPIC", "-O1", "-fno-builtin", "-o", str(out), str(folder / "blas_trap.c"), "-ldl"]
    subprocess.run(cmd, check=True)
    return out


if __name__ == "__main__":
    sys.exit(main())
