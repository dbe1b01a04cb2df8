"""The default layout (a rerun blueprint), made to be read in ten seconds.

Left: what the run is and where to look (a text panel), the 3D world, the top view, the events.
Right, top to bottom: e1, e2, e3 and |(e1, e2)| each on its own axis; v, omega and the wheel speeds;
then the learning (the weights' change per layer, every weight one tab away) beside the EKF
(trace(P) and the innovation as log10, the raw values and h1, h2, h5 in tabs). A view is shown when
the record has a series under its origin. Titles say what is drawn and in which unit; the text
panel names the colours, so legends stay hidden and cover nothing; every time plot marks the
events (dark-red diamonds).

The same layout shows several runs (:func:`blueprint` with ``prefixes``, used by
:func:`mlpfac.log.compare.save_comparison`): each view then holds that view's series of every run,
each run in its controller's colour.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import rerun.blueprint as rrb
import rerun.blueprint.encodings as rbe

from mlpfac.log.scene import bounds
from mlpfac.log.series import Series, plan_series
from mlpfac.loop.record import RunRecord

# (place, title, origin, marked: the events are marked on its first series).
VIEWS = (
    ("errors", "e1 along path [m]", "/errors/e1", True),
    ("errors", "e2 sideways [m]", "/errors/e2", True),
    ("errors", "e3 heading [rad]", "/errors/e3", True),
    ("errors", "|(e1, e2)| [m]", "/errors/position", True),
    ("errors", "estimate's error: position [m], heading [rad]", "/errors/estimate", True),
    ("speeds", "v [m/s]", "/controls/v", True),
    ("speeds", "omega [rad/s]", "/controls/omega", True),
    ("speeds", "wheel speeds [rad/s]", "/wheels", True),
    ("speeds", "force on the robot [N, N m]", "/forces", True),
    ("learning", "weights: RMS change per layer", "/weight_change", True),
    ("learning", "all weights", "/weights", False),
    ("ekf", "log10 trace(P)", "/ekf/log10_trace_P", True),
    ("ekf", "log10 |innovation|", "/ekf/log10_innovation", True),
    ("ekf", "h1, h2, h5", "/h", False),
    ("ekf", "trace(P)", "/ekf/trace_P", False),
    ("ekf", "mean diag(P)", "/ekf/mean_diag_P", False),
    ("ekf", "innovation [m, m, rad]", "/ekf/innovation", False),
    ("ekf", "pose sensors: twist, wheel speeds, the estimate's std, wheel scales", "/sensors", False),
    ("ekf", "other plant telemetry", "/plant", False),
    ("ekf", "other ctrl telemetry", "/ctrl", False),
)
ABOUT = "about"  # the text panel's entity


def marked_origins(paths: Sequence[str]) -> list[str]:
    """Origins of the views that mark the events, among those the series ``paths`` fill."""
    return [o for _, _, o, marked in VIEWS if marked and any(_under(p, o) for p in paths)]


def _under(path: str, origin: str) -> bool:
    return path == origin or path.startswith(origin + "/")


def blueprint(record: RunRecord, ref_xy: np.ndarray | None = None, series: list[Series] | None = None) -> rrb.Blueprint:
    """The default layout for ``record`` (its series: ``series``, default :func:`plan_series`)."""
    ref_xy = record.ref[: max(record.n, 1), :2] if ref_xy is None else ref_xy
    paths = ["/" + s.path for s in (plan_series(record) if series is None else series)]
    return layout(ref_xy, paths)


def layout(
    ref_xy: np.ndarray | None, paths: Sequence[str], prefixes: Sequence[str] = ("",), one: bool = True
) -> rrb.Blueprint:
    """The layout for series ``paths`` (entity paths of one run) of the runs under ``prefixes``
    ("" for one run); the views frame ``ref_xy`` (the reference path) when given."""
    lo, hi = bounds(ref_xy if ref_xy is not None else np.zeros((0, 2)))
    center, size = (lo + hi) / 2, max(float(np.max(hi - lo)), 1.0)
    margin = 0.12 * size + 0.2

    def within(origin: str) -> dict:
        if one:
            return {"origin": origin}
        return {"origin": "/", "contents": [f"/{p}{origin.lstrip('/')}/**" for p in prefixes]}

    left = rrb.Vertical(
        rrb.TextDocumentView(name="about this run" if one else "about these runs", origin=f"/{ABOUT}"),
        rrb.Spatial3DView(
            name="world",
            **within("/world"),
            eye_controls=rrb.EyeControls3D(
                position=[center[0], center[1] - 1.0 * size, 0.75 * size],
                look_target=[center[0], center[1], 0.0],
                eye_up=[0.0, 0.0, 1.0],
            ),
        ),
        rrb.Spatial2DView(
            name="top view (x right, y up)",
            **within("/top"),
            background=(245, 245, 245),
            visual_bounds=rrb.VisualBounds2D(
                x_range=[lo[0] - margin, hi[0] + margin], y_range=[-hi[1] - margin, -lo[1] + margin]
            ),
        ),
        rrb.TextLogView(
            name="events and status",
            origin="/",
            contents=[f"/{p}{e}" for p in prefixes for e in ("events", "status")],
            columns=rrb.TextLogColumns(
                timeline_columns=[rbe.TimelineColumn("sim_time")],
                text_log_columns=[
                    rbe.TextLogColumn("LogLevel", visible=False),
                    rbe.TextLogColumn("EntityPath", visible=False),  # the texts name their run
                    rbe.TextLogColumn("Body"),
                ],
            ),
        ),
        row_shares=[3.2, 1.5, 2.6, 1.3] if one else [1.6, 1.8, 2.8, 0.8 + 0.4 * len(prefixes)],
    )
    views: dict[str, list] = {"errors": [], "speeds": [], "learning": [], "ekf": []}
    for place, title, origin, _ in VIEWS:
        if any(_under(p, origin) for p in paths):
            views[place].append(
                rrb.TimeSeriesView(name=title, **within(origin), plot_legend=rrb.PlotLegend(visible=False))
            )
    right = [rrb.Horizontal(*views[k]) for k in ("errors", "speeds") if views[k]]
    bottom = [rrb.Tabs(*views[k]) for k in ("learning", "ekf") if views[k]]
    if bottom:
        right.append(rrb.Horizontal(*bottom))
    return rrb.Blueprint(
        rrb.Horizontal(left, rrb.Vertical(*right), column_shares=[2, 3]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="sim_time", play_state="following"),  # open at the end
    )
