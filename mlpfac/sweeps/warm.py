"""Imported by the fork server of a local pool (:func:`mlpfac.sweeps.worker.pool_context`), once:
what a run needs, the compiled kernels (:mod:`mlpfac.jit`; numba started, where it compiles
them) and the shipped robot, so that every worker forked from it starts warm instead of importing
numpy, MuJoCo and the rest and reading the robot itself. Importing this module elsewhere does the
same work in that process.
"""

from __future__ import annotations

import atexit
import os
import shutil

# The folder of the fork server's socket goes when the fork server does: "PID:FOLDER", set by
# mlpfac.sweeps.worker.pool_context in the process PID, which started this one.
_owner, _, _folder = os.environ.get("MLPFAC_POOL_TMP", "").partition(":")
if _folder and _owner == str(os.getppid()):
    atexit.register(shutil.rmtree, _folder, True)

# The user's modules as the sweep's own process finds them (mlpfac.sweeps.worker.worker_environment):
# after the installed mlpfac, which the fork server imported without the current folder on its path.
if os.environ.get("MLPFAC_SYS_PATH"):
    import json
    import sys

    sys.path[:] = [*dict.fromkeys([*json.loads(os.environ["MLPFAC_SYS_PATH"]), *sys.path])]

try:
    import numpy as np

    from mlpfac.loop.metrics import metrics  # noqa: F401
    from mlpfac.loop.runner import run  # noqa: F401
    from mlpfac.model import tracking_errors
    from mlpfac.plants.mujoco import compiled  # noqa: F401
    from mlpfac.scenario.parse import load, parse  # noqa: F401
    from mlpfac.sweeps.worker import run_task  # noqa: F401

    tracking_errors(np.zeros((0, 3)), np.zeros(5), np.zeros((0, 3)))
    load("eight-nominal")  # the shipped robot read (and checked) once, for every worker of every sweep
except Exception:  # a worker imports (and reports) what failed here itself
    pass
