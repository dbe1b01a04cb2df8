"""The default layout (a rerun blueprint): 3D world, top view and events on the left; the time
series on the right, each view shown when the record has a series under its origin."""

from __future__ import annotations

import numpy as np
import rerun.blueprint as rrb

from mlpfac.log.scene import bounds
from mlpfac.log.schema import unit
from mlpfac.log.series import Series, plan_series
from mlpfac.record import RunRecord

# (place, title, origin). Places, top to bottom: "errors", "speeds" (side by side), "weights", "tabs".
VIEWS = (
    ("errors", "tracking error (true)", "/errors"),
    ("speeds", f"v ({unit('u', 0)})", "/controls/v"),
    ("speeds", f"omega ({unit('u', 1)})", "/controls/omega"),
    ("speeds", f"wheel speeds ({unit('wheel_cmd')})", "/wheels"),
    ("weights", "network weights", "/weights"),
    ("tabs", "trace(P)", "/ekf/trace_P"),
    ("tabs", "mean diag(P)", "/ekf/mean_diag_P"),
    ("tabs", "innovation", "/ekf/innovation"),
    ("tabs", "h1, h2, h5", "/h"),
    ("tabs", "other plant telemetry", "/plant"),
    ("tabs", "other ctrl telemetry", "/ctrl"),
)


def blueprint(record: RunRecord, ref_xy: np.ndarray | None = None, series: list[Series] | None = None) -> rrb.Blueprint:
    """The default layout for ``record`` (its series: ``series``, default :func:`plan_series`)."""
    ref_xy = record.ref[: max(record.n, 1), :2] if ref_xy is None else ref_xy
    lo, hi = bounds(ref_xy)
    center, size = (lo + hi) / 2, max(float(np.max(hi - lo)), 1.0)
    margin = 0.15 * size + 0.3
    left = rrb.Vertical(
        rrb.Spatial3DView(
            name="world",
            origin="/world",
            eye_controls=rrb.EyeControls3D(
                position=[center[0], center[1] - 1.1 * size, 0.9 * size],
                look_target=[center[0], center[1], 0.0],
                eye_up=[0.0, 0.0, 1.0],
            ),
        ),
        rrb.Spatial2DView(
            name="top view (x right, y up)",
            origin="/top",
            visual_bounds=rrb.VisualBounds2D(
                x_range=[lo[0] - margin, hi[0] + margin], y_range=[-hi[1] - margin, -lo[1] + margin]
            ),
        ),
        rrb.TextLogView(name="events and status", origin="/", contents=["/events", "/status"]),
        row_shares=[4, 4, 1.5],
    )
    paths = ["/" + s.path for s in (plan_series(record) if series is None else series)]
    views: dict[str, list] = {"errors": [], "speeds": [], "weights": [], "tabs": []}
    for place, title, origin in VIEWS:
        if any(p == origin or p.startswith(origin + "/") for p in paths):
            legend = rrb.PlotLegend(visible=False) if place == "weights" else None
            views[place].append(rrb.TimeSeriesView(name=title, origin=origin, plot_legend=legend))
    right = views["errors"] + ([rrb.Horizontal(*views["speeds"])] if views["speeds"] else []) + views["weights"]
    if views["tabs"]:
        right.append(rrb.Tabs(*views["tabs"]))
    return rrb.Blueprint(
        rrb.Horizontal(left, rrb.Vertical(*right), column_shares=[2, 3]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="sim_time", play_state="following"),  # open at the end
    )
