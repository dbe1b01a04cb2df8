"""Builds mlpfac's kernels ahead of time (mlpfac/jit.py says how they are used); everything else
about the package is in pyproject.toml."""

import os
import subprocess
import sys
import time

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

HERE = os.path.dirname(os.path.abspath(__file__))
BUILD = "import sys; from mlpfac.jit import build; build(sys.argv[1], sys.argv[2])"


def say(line: str) -> None:
    """A line of progress where the user sees it: pip shows a build's output only with -v, so it
    also goes to the terminal pip runs in, when there is one."""
    print(line, file=sys.stderr, flush=True)
    if not sys.stderr.isatty():
        try:
            with open("/dev/tty", "w") as tty:
                tty.write(line + "\n")
        except OSError:
            pass


class BuildKernels(build_ext):
    """Each extension module is compiled by numba's AOT compiler from the kernels' Python source,
    the two at once in two processes (each compiles for about half a minute of CPU). They are
    built together or not at all: where one cannot be built, neither is installed (with a warning),
    and numba compiles the kernels on first use, as in a checkout never built."""

    def build_extensions(self) -> None:
        self.check_extensions_list(self.extensions)
        sys.path.insert(0, HERE)
        from mlpfac.jit import EXTENSIONS

        names = {v: k for k, v in EXTENSIONS.items()}
        paths = {ext.name: self.get_ext_fullpath(ext.name) for ext in self.extensions}
        env = os.environ | {
            "MLPFAC_KERNELS": "build",
            "PYTHONPATH": os.pathsep.join(filter(None, (HERE, os.environ.get("PYTHONPATH")))),
        }
        say(f"mlpfac: compiling the kernels for this processor ({len(paths)} modules at once, about a minute)...")
        t0 = time.monotonic()
        procs = {}
        for name, path in paths.items():
            os.makedirs(os.path.dirname(path), exist_ok=True)
            procs[name] = subprocess.Popen([sys.executable, "-c", BUILD, names[name], path], env=env)
        failed = []
        while procs:
            for name, proc in list(procs.items()):
                if proc.poll() is not None:
                    del procs[name]
                    if proc.returncode:
                        failed.append(name)
                    else:
                        say(f"mlpfac: {name} compiled ({time.monotonic() - t0:.0f} s)")
            time.sleep(0.2)
        if failed:
            print(
                f"warning: {', '.join(failed)} could not be built; numba will compile the kernels on first use",
                file=sys.stderr,
            )
            for path in paths.values():  # both or neither
                if os.path.exists(path):
                    os.remove(path)


setup(
    ext_modules=[
        Extension("mlpfac._kernels", sources=[], optional=True),
        Extension("mlpfac.plants._kernels", sources=[], optional=True),
    ],
    cmdclass={"build_ext": BuildKernels},
)
