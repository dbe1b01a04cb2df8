"""Run folders: writing a result, and telling a whole folder of the same run from anything else."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import TYPE_CHECKING

from mlpfac.exceptions import OutputError
from mlpfac.io.files import write_folder_whole

if TYPE_CHECKING:
    from mlpfac.sweeps.plan import Job

PHASES = ("before", "after")


def write_result(out: Path, job: Job, result: dict) -> None:
    """The folder of one run, config.toml, run.rrd and metrics.json (or config.toml and error.txt),
    put in place whole in one rename: a killed sweep leaves each folder as it was or whole.

    With a recording, metrics.json also holds its size and sha256 ("rrd"), checked on resume.
    An OSError (a full disk) leaves the folder as it was: run again on resume if not done.
    """
    d = job.folder(out)
    try:
        _write_result(d, job, result)
    except OSError as err:  # a write names no file (EFBIG, ENOSPC from write()): name the folder
        raise _oserror(err, f"into {d}") from None


def _write_result(d: Path, job: Job, result: dict) -> None:
    if result["error"] is not None:
        write_folder_whole(d, {"config.toml": job.config, "error.txt": result["error"]})
        return
    m, rrd = result["metrics"], result.get("rrd")
    files: dict[str, str | bytes] = {"config.toml": job.config}
    if rrd is not None:
        m = m | {"rrd": {"bytes": len(rrd), "sha256": hashlib.sha256(rrd).hexdigest()}}
        files["run.rrd"] = rrd
    files["metrics.json"] = json.dumps(m, indent=2) + "\n"
    write_folder_whole(d, files)


def _number(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _number_or_none(x) -> bool:
    return x is None or _number(x)


PHASE_KEYS = ("rms_position_error_m", "max_position_error_m", "rms_heading_error_rad")


def metrics_problem(m, job: Job) -> str | None:
    """Why ``m`` (a parsed metrics.json) is not the metrics of ``job`` as ``runner.metrics`` writes them; None if it is."""
    if not isinstance(m, dict):
        return "not valid"
    if m.get("status") not in ("ok", "diverged"):
        return "not valid"
    if not (_number(m.get("T")) and isinstance(m.get("steps"), int) and not isinstance(m.get("steps"), bool)):
        return "not valid"
    if not all(_number_or_none(m.get(k, 0)) and k in m for k in PHASE_KEYS):
        return "not valid"
    for k in ("max_abs_weight", "mean_diag_P_final"):
        if k not in m or not _number_or_none(m[k]):
            return "not valid"
    if not (_number(m.get("sim_time_s")) and _number(m.get("wall_time_s"))):
        return "not valid"
    if not isinstance(m.get("events"), list) or not (m.get("reason") is None or isinstance(m.get("reason"), str)):
        return "not valid"
    phases = m.get("phases")
    if not isinstance(phases, dict) or "before" not in phases or not set(phases) <= set(PHASES):
        return "not valid"
    for ph in phases.values():
        if not isinstance(ph, dict) or not (_number(ph.get("start_s")) and _number(ph.get("end_s"))):
            return "not valid"
        if not all(k in ph and _number_or_none(ph[k]) for k in PHASE_KEYS):
            return "not valid"
    if (m.get("scenario"), m.get("controller"), m.get("seed")) != job.key or isinstance(m.get("seed"), bool):
        return "of another run"
    return None


def check_done(out: Path, job: Job, save_rrd: bool = False) -> tuple[dict | None, str | None]:
    """(metrics, None) if ``job``'s folder is whole and was run with the same configuration; else
    (None, why it must run again), why being None for a run never finished (no metrics.json).

    Whole: config.toml equals the job's, metrics.json is a metrics dict of this scenario, controller
    and seed, and with ``save_rrd`` run.rrd has the size and sha256 metrics.json recorded.
    """
    d = job.folder(out)
    try:
        text = (d / "metrics.json").read_text()
    except FileNotFoundError:
        return None, None
    except (OSError, ValueError):
        return None, "metrics.json unreadable"
    try:
        if (d / "config.toml").read_text() != job.config:
            return None, "configuration changed"
    except (OSError, ValueError):
        return None, "config.toml missing"
    try:
        m = json.loads(text)
    except ValueError:
        return None, "metrics.json not valid"
    problem = metrics_problem(m, job)
    if problem is not None:
        return None, f"metrics.json {problem}"
    if save_rrd:
        rec = m.get("rrd")
        if not (isinstance(rec, dict) and isinstance(rec.get("bytes"), int) and isinstance(rec.get("sha256"), str)):
            return None, "run.rrd not recorded"
        try:
            if (d / "run.rrd").stat().st_size != rec["bytes"] or _sha256(d / "run.rrd") != rec["sha256"]:
                return None, "run.rrd changed or cut"
        except OSError:
            return None, "run.rrd missing"
    return m, None


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _oserror(err: OSError, what: str) -> OutputError:
    path = err.filename or what
    return OutputError(f"cannot write {path} ({err.strerror or err})")
