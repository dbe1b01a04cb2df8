"""What the robot believed, drawn beside the truth, for a run whose pose is estimated (``[plant]
pose_source`` "odometry" or "fused"): the believed path (the pose the controller was given) in the
3D world and the top view, and the fixes of a ``"fused"`` source as they arrived, each labelled
with the time it was taken. The estimate's error and the sensors' series are the schema's rows
(``errors/estimate``, ``sensors``)."""

from __future__ import annotations

import numpy as np
import rerun as rr

from mlpfac.log.scene import PATH_STRIDE, POSE_STRIDE, driven_path, strided
from mlpfac.log.series import time_index
from mlpfac.loop.record import RunRecord

BELIEF_COLOR = (60, 220, 200)  # the believed path: teal, narrower than the true path's blue under it
FIX_TRAIL = 50  # the fixes shown at once: the newest, labelled, and those before it (5 s at 10 Hz)
FIX_COLOR = (140, 210, 30)  # the fixes: lime dots (the top view is light, the floor dark)


def estimated(record: RunRecord) -> bool:
    return record.pose_source != "truth"


def send_belief_static(rec: rr.RecordingStream, record: RunRecord) -> None:
    """The styles of the believed path, the believed pose and the fixes."""
    if not estimated(record):
        return
    rec.log("world/belief", rr.LineStrips3D.from_fields(colors=[BELIEF_COLOR], radii=[0.004]), static=True)
    rec.log("top/plane/belief", rr.LineStrips2D.from_fields(colors=[BELIEF_COLOR], radii=[0.005]), static=True)
    rec.log("top/plane/belief_now", rr.Arrows2D.from_fields(colors=[BELIEF_COLOR], radii=[0.03]), static=True)
    if "fix" in record.plant and record.pose_source == "fused":
        rec.log("world/fixes", rr.Points3D.from_fields(colors=[FIX_COLOR], radii=[0.015]), static=True)
        rec.log("top/plane/fixes", rr.Points2D.from_fields(colors=[FIX_COLOR], radii=[0.015]), static=True)
        rec.log("top/plane/fix_now", rr.Points2D.from_fields(colors=[FIX_COLOR], radii=[0.03]), static=True)


def send_belief(rec: rr.RecordingStream, record: RunRecord, a: int, b: int, last: bool = False) -> None:
    """Steps a .. b - 1: the believed path and pose (at the strides of the true ones; ``last``: step
    b - 1 too), and at each step a fix arrived, the fix (``top/plane/fix_now``, its label: when it
    was taken) and the trail of the FIX_TRAIL fixes up to it (``world/fixes``, ``top/plane/fixes``)."""
    if not estimated(record) or b <= a:
        return
    meas = record.pose_meas
    rows = strided(a, b, POSE_STRIDE)
    path_rows = strided(a, b, PATH_STRIDE)
    if last:
        rows, path_rows = np.union1d(rows, [b - 1]), np.union1d(path_rows, [b - 1])
    rows = rows[np.all(np.isfinite(meas[rows]), axis=1)]
    if len(rows):
        x, y, th = meas[rows].T
        rec.send_columns(
            "top/plane/belief_now",
            indexes=time_index(record, rows),
            columns=rr.Arrows2D.columns(origins=np.c_[x, y], vectors=0.35 * np.c_[np.cos(th), np.sin(th)]),
        )
    if len(path_rows):
        strips = [driven_path(meas, k) for k in path_rows]
        idx = time_index(record, path_rows)
        rec.send_columns(
            "world/belief",
            indexes=idx,
            columns=rr.LineStrips3D.columns(strips=[np.c_[p, np.full(len(p), 0.006)] for p in strips]),
        )
        rec.send_columns("top/plane/belief", indexes=idx, columns=rr.LineStrips2D.columns(strips=strips))
    fix = record.plant.get("fix")
    if fix is None or record.pose_source != "fused":
        return
    arrived = a + np.flatnonzero(np.all(np.isfinite(fix[a:b]), axis=1))
    if not len(arrived):
        return
    before = np.flatnonzero(np.all(np.isfinite(fix[:b]), axis=1))  # every fix so far, for the trail
    trails = [before[max(0, j - FIX_TRAIL + 1) : j + 1] for j in np.searchsorted(before, arrived)]
    f, lengths = np.concatenate([fix[t] for t in trails]), [len(t) for t in trails]
    idx = time_index(record, arrived)
    trail = rr.Points3D.columns(positions=np.c_[f[:, :2], np.full(len(f), 0.01)]).partition(lengths)
    rec.send_columns("world/fixes", indexes=idx, columns=trail)
    rec.send_columns("top/plane/fixes", indexes=idx, columns=rr.Points2D.columns(positions=f[:, :2]).partition(lengths))
    now = fix[arrived]
    labels = [f"fix taken at {t:.2f} s" for t in now[:, 3]]
    rec.send_columns("top/plane/fix_now", indexes=idx, columns=rr.Points2D.columns(positions=now[:, :2], labels=labels))
