"""Builds mlpfac's kernels ahead of time (mlpfac/jit.py says how they are used); everything else
about the package is in pyproject.toml."""

import os
import sys
import traceback

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


class BuildKernels(build_ext):
    """Each extension module is compiled by numba's AOT compiler from the kernels' Python source.
    The two are built together or not at all: where one cannot be built, neither is installed (with
    a warning), and numba compiles the kernels on first use, as in a checkout never built."""

    failed = False

    def build_extension(self, ext: Extension) -> None:
        os.environ["MLPFAC_KERNELS"] = "build"  # numba compiles the kernels from source, uncached
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        path = self.get_ext_fullpath(ext.name)
        try:
            if BuildKernels.failed:
                raise RuntimeError("the other kernel module was not built")
            from mlpfac.jit import EXTENSIONS, build

            os.makedirs(os.path.dirname(path), exist_ok=True)
            build(next(k for k, v in EXTENSIONS.items() if v == ext.name), path)
        except Exception:
            traceback.print_exc()
            print(f"warning: {ext.name} was not built; numba will compile the kernels on first use", file=sys.stderr)
            BuildKernels.failed = True
            for other in self.extensions:  # both or neither
                with_path = self.get_ext_fullpath(other.name)
                if os.path.exists(with_path):
                    os.remove(with_path)


setup(
    ext_modules=[
        Extension("mlpfac._kernels", sources=[], optional=True),
        Extension("mlpfac.plants._kernels", sources=[], optional=True),
    ],
    cmdclass={"build_ext": BuildKernels},
)
