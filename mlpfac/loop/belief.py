"""What the robot believed, beside the truth: the error of its pose estimate (what the controller was
given against the true pose) and the outcome it would have reported of itself, for a run whose
pose source is not the truth (``[plant] pose_source``, :mod:`mlpfac.plants.sensors.sensing`). The headline
figures and the outcome stay the truth's (:mod:`mlpfac.loop.metrics`)."""

from __future__ import annotations

import math

import numpy as np

from mlpfac.elementary import each, hypot
from mlpfac.loop.record import RunRecord


def _figures(rec: RunRecord, lo: int, hi: int) -> dict:
    """The estimate's error over steps lo .. hi: position (|(x, y) believed - true|) and heading (wrapped)."""
    from mlpfac.model import wrap

    if hi <= lo:
        return {"rms_position_error_m": None, "max_position_error_m": None, "rms_heading_error_rad": None,
                "max_heading_error_rad": None}  # fmt: skip
    d = rec.pose_meas[lo:hi] - rec.pose[lo:hi]
    pos = each(hypot, d[:, 0], d[:, 1])
    head = np.abs(wrap(d[:, 2]))
    return {
        "rms_position_error_m": float(np.sqrt(np.mean(pos * pos))),
        "max_position_error_m": float(np.max(pos)),
        "rms_heading_error_rad": float(np.sqrt(np.mean(head * head))),
        "max_heading_error_rad": float(np.max(head)),
    }


def believed(rec: RunRecord, bounds: dict[str, tuple[int, int]], limit: float, outcome: str) -> dict:
    """metrics.json's ``estimate``: the estimate's error over the whole run and per phase, the position
    RMS of the tracking error the controller saw per phase, and the outcome that error would give
    (``believed_outcome``); ``said``: a line for a run whose truth is lost (or diverged) while its
    belief tracked."""
    n = rec.n
    out = {"pose_source": rec.pose_source} | _figures(rec, 0, n)
    phases, seen = {}, []
    for name, (lo, hi) in bounds.items():
        hi = min(hi, n)
        phases[name] = _figures(rec, lo, hi)
        if hi > lo:
            e = rec.e[lo:hi]
            dist = each(hypot, e[:, 0], e[:, 1])
            rms = float(np.sqrt(np.mean(dist * dist)))
            phases[name]["believed_rms_position_error_m"] = rms
            seen.append(rms)
    out["phases"] = phases
    out["believed_outcome"] = "lost" if any(not x <= limit for x in seen) else "tracking"
    out["said"] = ""
    if outcome in ("lost", "diverged") and out["believed_outcome"] == "tracking":
        worst = max(seen) if seen else math.nan
        out["said"] = (
            f"{outcome}: the truth {'is lost' if outcome == 'lost' else 'diverged'}, while the robot believed it tracked (the error it saw: position "
            f"RMS at most {worst * 1e3:.3g} mm a phase, within {limit:.3g} m); its {rec.pose_source} estimate "
            f"was off by {out['max_position_error_m'] * 1e3:.4g} mm at most"
        )
    return out
