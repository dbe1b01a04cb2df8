"""Builds mlpfac's kernels ahead of time (mlpfac/jit.py says how they are used); everything else
about the package is in pyproject.toml."""

import os
import sys
import traceback

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


class BuildKernels(build_ext):
    """Each extension module is compiled by numba's AOT compiler from the kernels' Python source.
    One that cannot be built is left out with a warning: numba then compiles the kernels on first
    use, as in a checkout that was never built."""

    def build_extension(self, ext: Extension) -> None:
        os.environ["MLPFAC_KERNELS"] = "build"  # numba compiles the kernels from source, uncached
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        try:
            from mlpfac.jit import EXTENSIONS, build

            path = self.get_ext_fullpath(ext.name)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            build(next(k for k, v in EXTENSIONS.items() if v == ext.name), path)
        except Exception:
            traceback.print_exc()
            print(f"warning: {ext.name} was not built; numba will compile its kernels on first use", file=sys.stderr)


setup(
    ext_modules=[Extension("mlpfac._kernels", sources=[]), Extension("mlpfac.plants._kernels", sources=[])],
    cmdclass={"build_ext": BuildKernels},
)
