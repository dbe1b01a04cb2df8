"""The physical limit of a run, computed once: ``limit`` runs kept across sweeps, keyed by what was simulated.

``limit`` (:mod:`mlpfac.control.mpc`: the run's own robot as the model, given the true state) costs
a hundred times a law's run, and its figure depends only on the run, not on who asks: a sweep with
``--limit`` takes each (scenario, robot, seed, duration) from the cache folder (``--limit-cache``,
default ``runs/limits``) when it is there and runs it into the cache when it is not. One folder a
run, named by the sha256 of

- the scenario as resolved for the run, but for its name and description: what was simulated (the
  robot as read, its ``[provenance]``, the world, the events, the seed, the duration, the
  controller's settings), and
- the code a run computes with: mlpfac's version and the sources of the simulated path (the
  controllers, the plants, the scenario, the loop and the maths under them; not the tables,
  pictures or command line).

Each holds ``simulated.toml`` (what the key was made of) and ``metrics.json``; a hit is checked as
a resumed sweep checks a run folder (the same text, a whole metrics.json of that controller and
seed) and is written into the sweep's folder under the sweep's scenario name. A folder that is not
whole is run again and replaced.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

from mlpfac.io.files import write_folder_whole
from mlpfac.sweeps.folders import metrics_problem
from mlpfac.sweeps.plan import Job

LIMIT = "limit"
DEFAULT_CACHE = Path("runs") / "limits"
UNSIMULATED = ("name", "description")  # keys of a resolved scenario that change no bit of its run
SIMULATED_CODE = ("elementary.py", "normal.py", "model.py", "dynamics.py", "jit.py", "tables.py", "control",
                  "plants", "scenario", "loop")  # fmt: skip


def with_limit(names: list, limit: bool) -> list:
    """The controllers of a sweep (``parse_controllers``'s), ``limit`` added with ``--limit``."""
    return names + [LIMIT] if limit and LIMIT not in names else names


@functools.cache
def fingerprint() -> str:
    """mlpfac's version and a hash of the sources a run computes with."""
    from mlpfac.version import __version__

    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256(__version__.encode())
    for part in SIMULATED_CODE:
        p = root / part
        for f in sorted(p.rglob("*.py")) if p.is_dir() else [p]:
            h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


class LimitCache:
    """The cache folder ``root`` of ``limit`` runs (made when the first one is stored)."""

    controller = LIMIT

    def __init__(self, root: Path) -> None:
        self.root = Path(root)

    @staticmethod
    def simulated(job: Job) -> str:
        from mlpfac.tables import to_toml

        table = {k: v for k, v in job.table.items() if k not in UNSIMULATED}
        return f"# mlpfac code {fingerprint()}\n{to_toml(table)}"

    def folder(self, simulated: str) -> Path:
        """The folder of the run whose :meth:`simulated` text is ``simulated``."""
        key = hashlib.sha256(simulated.encode()).hexdigest()
        return self.root / key[:2] / key

    def lookup(self, job: Job) -> dict | None:
        """The metrics of ``job``'s run (under its scenario's name) if the cache holds it whole."""
        text = self.simulated(job)
        d = self.folder(text)
        try:
            if (d / "simulated.toml").read_text() != text:
                return None
            m = json.loads((d / "metrics.json").read_text())
        except (OSError, ValueError):
            return None
        if not isinstance(m, dict):
            return None
        m = m | {"scenario": job.scenario}
        return m if metrics_problem(m, job) is None else None

    def store(self, job: Job, metrics: dict) -> None:
        """Keep ``job``'s run (an OSError names the folder: a failed write is an error)."""
        text = self.simulated(job)
        write_folder_whole(
            self.folder(text), {"simulated.toml": text, "metrics.json": json.dumps(metrics, indent=2) + "\n"}
        )
