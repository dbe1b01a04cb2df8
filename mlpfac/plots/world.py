"""What a run in a world, or on an estimated pose, adds to Figure 1 (:mod:`mlpfac.plots.figure1`):
the ramps' and kerbs' footprints and the patches on the paths' panels, the path the robot believed it drove
(``[plant] pose_source`` other than the truth), where each event happened and where a force acted
along the driven path, and, on the panels against time, when the robot was on a ramp, a kerb or a
patch.
The record carries all of it as plain data (``record.world``, :meth:`mlpfac.plants.world.layout.Terrain.as_dict`;
the events as applied): nothing here reads the plant.

Every mark gets one entry in the figure's legend, drawn above the panels (:func:`legend_entries`),
so that no legend lies over the data.
"""

from __future__ import annotations

import numpy as np

from mlpfac.loop.record import RunRecord, force_windows

EVENT_COLOR = "firebrick"
FORCE_SPAN = "mediumvioletred"  # the windows in which a force acts on the robot
RUN_COLOR = "tab:blue"
BELIEF_COLOR = "darkcyan"  # the believed path (the viewer's teal, darker on white)
RAMP_COLOR = "#968060"  # a ramp's footprint (the viewer's ramp colour)
KERB_COLOR = "#8c8c87"  # a kerb's footprint (the viewer's concrete grey, darker on white)
PATCH_COLOR = "#3278e6"  # a patch of its own friction (the viewer's, half see-through)
WARM_COLOR = "0.88"  # the warm-up, left out of the figures


def on_ground(rec: RunRecord) -> dict[str, np.ndarray]:
    """Per step (n,): whether the robot's true (x, y) is on a ramp's or a kerb's footprint, or in a
    patch, by what it is on ("ramp", "kerb", "patch"; absent where the world has none)."""
    n, world = rec.n, rec.world or {}
    xy = rec.pose[:n, :2]
    ok = np.all(np.isfinite(xy), axis=1)
    out = {}
    for key in ("ramps", "kerbs"):
        prints = [footprint(c) for c in world.get(key, [])]
        if prints:
            from matplotlib.path import Path

            on = np.zeros(n, dtype=bool)
            for corners in prints:
                on[ok] |= Path(corners).contains_points(xy[ok])
            out[key[:-1]] = on
    patches = world.get("patches", [])
    if patches:
        on = np.zeros(n, dtype=bool)
        for p in patches:
            d = xy[ok] - np.array([p["x"], p["y"]])
            on[ok] |= (d * d).sum(axis=1) <= p["radius"] * p["radius"]
        out["patch"] = on
    return out


def footprint(corners) -> np.ndarray:
    """A ramp's (or a kerb's) footprint on the floor, (4, 2): its foot's two sides, then its end's (the prism's
    corners 0, 1, 7, 6 of :meth:`mlpfac.plants.world.layout.PlacedRamp.corners`)."""
    c = np.asarray(corners, dtype=float)
    return c[[0, 1, 7, 6], :2]


def spans(mask: np.ndarray, t: np.ndarray, T: float) -> list[tuple[float, float]]:
    """The (start, end) times of each run of True in ``mask`` (steps at times ``t``)."""
    edges = np.flatnonzero(np.diff(np.r_[False, mask, False].astype(np.int8)))
    return [(float(t[a]), float(t[b - 1]) + T) for a, b in zip(edges[::2], edges[1::2], strict=True)]


GROUND = {"ramp": (RAMP_COLOR, "on a ramp"), "kerb": (KERB_COLOR, "on a kerb"), "patch": (PATCH_COLOR, "on a patch")}


def mark_times(ax, rec: RunRecord, ground: dict[str, np.ndarray]) -> None:
    """On a panel against time: the events (dashed), the forces' windows and the times on a ramp,
    a kerb or a patch (shaded)."""
    end = rec.t[-1] + rec.T
    for ev in rec.events:
        ax.axvline(float(ev["time"]), color=EVENT_COLOR, lw=0.9, ls="--")
    for t0, t1 in force_windows(rec.events, end):
        ax.axvspan(t0, t1, color=FORCE_SPAN, alpha=0.18, lw=0, zorder=0)
    t = rec.t[: rec.n]
    for what, mask in ground.items():
        for t0, t1 in spans(mask, t, rec.T):
            ax.axvspan(t0, t1, color=GROUND[what][0], alpha=0.16, lw=0, zorder=0)


def mark_paths(ax, rec: RunRecord) -> None:
    """On a panel of the paths: the ramps' and kerbs' footprints, the patches, the believed path, where each
    event happened and where a force acted along the driven path."""
    from matplotlib.patches import Circle, Polygon

    world = rec.world or {}
    for key, color in (("ramps", RAMP_COLOR), ("kerbs", KERB_COLOR)):
        for corners in world.get(key, []):
            ax.add_patch(Polygon(footprint(corners), closed=True, fc=color, ec=color, alpha=0.35, lw=0.8))
    for p in world.get("patches", []):
        ax.add_patch(Circle((p["x"], p["y"]), p["radius"], fc=PATCH_COLOR, ec=PATCH_COLOR, alpha=0.3, lw=0.8))
    n = rec.n
    if rec.pose_source != "truth":
        meas = rec.pose_meas[:n, :2]
        ok = np.all(np.isfinite(meas), axis=1)
        ax.plot(meas[ok, 0], meas[ok, 1], color=BELIEF_COLOR, lw=1.0, ls="--")
    pose = rec.pose[:n, :2]
    for t0, t1 in force_windows(rec.events, rec.t[-1] + rec.T):
        a, b = int(round(t0 / rec.T)), min(int(round(t1 / rec.T)) + 1, n)
        if b > a:
            ax.plot(pose[a:b, 0], pose[a:b, 1], color=FORCE_SPAN, lw=3.0, alpha=0.6, solid_capstyle="butt")
    for ev in rec.events:
        k = int(round(float(ev["time"]) / rec.T))
        if k < n and np.all(np.isfinite(pose[k])):
            ax.plot(*pose[k], "D", color=EVENT_COLOR, ms=5)


def legend_entries(rec: RunRecord, warm: bool) -> list:
    """The figure's legend: one entry for each kind of mark the figure draws."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    out = [Line2D([], [], color="black", lw=1.0, label="reference"), Line2D([], [], color=RUN_COLOR, lw=1.0,
           label="robot (true pose)")]  # fmt: skip
    if rec.pose_source != "truth":
        out.append(Line2D([], [], color=BELIEF_COLOR, lw=1.0, ls="--", label=f"believed ({rec.pose_source})"))
    if warm:
        out.append(Patch(color=WARM_COLOR, label="warm-up (left out of the figures)"))
    if rec.events:
        texts = list(dict.fromkeys(str(ev.get("text") or ev.get("kind")).split(" (")[0] for ev in rec.events))
        label = f"event: {texts[0]}" if len(texts) == 1 else f"events ({len(rec.events)})"
        out.append(Line2D([], [], color=EVENT_COLOR, lw=0.9, ls="--", marker="D", ms=4, label=label))
    if force_windows(rec.events, rec.t[-1] + rec.T):
        out.append(Patch(color=FORCE_SPAN, alpha=0.35, label="a force acts"))
    world = rec.world or {}
    if world.get("ramps"):
        out.append(Patch(color=RAMP_COLOR, alpha=0.45, label="ramp (and the time on it)"))
    if world.get("kerbs"):
        out.append(Patch(color=KERB_COLOR, alpha=0.45, label="kerb (and the time on it)"))
    if world.get("patches"):
        out.append(Patch(color=PATCH_COLOR, alpha=0.4, label="patch (and the time on it)"))
    return out
