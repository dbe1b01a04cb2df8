"""Emulate a machine whose imports are slow: every module's own import (its ``exec_module`` and,
for an extension, ``create_module``, children excluded) takes ``SLOW_IMPORTS`` times as long.

    PYTHONPATH=benchmarks/slow_imports SLOW_IMPORTS=4 python ...        # extra time burnt on the CPU
    PYTHONPATH=benchmarks/slow_imports SLOW_IMPORTS=4:sleep python ...  # extra time waited (slow disk)

``cpu`` holds the interpreter (and the GIL) while it burns, as an import on a slower processor
does; ``sleep`` releases both, as an import waiting for a cold disk does. Processes forked or
started from this one inherit it (the environment). Not part of mlpfac: a benchmark's tool.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time


def _install(factor: float, mode: str) -> None:
    from importlib.abc import MetaPathFinder

    stack: list[float] = []  # per import in progress: the time its children took

    def slowed(fn):
        def run(*args, **kw):
            stack.append(0.0)
            t0 = time.perf_counter()
            try:
                return fn(*args, **kw)
            finally:
                took = time.perf_counter() - t0
                own = max(took - stack.pop(), 0.0)
                extra = (factor - 1.0) * own
                t1 = time.perf_counter()
                if mode == "sleep":
                    time.sleep(extra)
                else:
                    while time.perf_counter() - t1 < extra:
                        pass
                if stack:
                    stack[-1] += took + (time.perf_counter() - t1)

        return run

    class Finder(MetaPathFinder):
        def find_spec(self, name, path, target=None):
            for finder in sys.meta_path:
                if finder is self:
                    continue
                find = getattr(finder, "find_spec", None)
                spec = find(name, path, target) if find else None
                if spec is not None:
                    loader = spec.loader
                    if loader is not None and not getattr(loader, "_slowed", False):
                        for attr in ("exec_module", "create_module"):
                            fn = getattr(loader, attr, None)
                            if fn is not None:
                                with contextlib.suppress(AttributeError, TypeError):
                                    setattr(loader, attr, slowed(fn))
                        with contextlib.suppress(AttributeError, TypeError):
                            loader._slowed = True
                    return spec
            return None

    sys.meta_path.insert(0, Finder())


_text = os.environ.get("SLOW_IMPORTS")
if _text:
    _f, _, _m = _text.partition(":")
    _install(float(_f), _m or "cpu")
