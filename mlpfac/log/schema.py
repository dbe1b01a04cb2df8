"""What a recording holds for each array of a run record: one row per record array or telemetry key.

A row names its source (``store``: a top-level array of the record, or a key of ``record.plant`` or
``record.ctrl``), how it is sent, its entity path, its component names, the name of each plotted
line, its unit and its colours. A key may have several rows (the reference is a path, a pose and
two speeds). A telemetry key without a row is still logged, under ``plant/<key>`` or
``ctrl/<key>`` (:func:`generic`); ``tests/test_log.py`` checks that every key of a real run has one.

How a row is sent (``send``):

- ``LINES``: scalar series, one entity per component (``{name}`` in the path), or one entity for a
  1-D array; one row per control step.
- ``LAYERS``: one entity per layer, several lines each: the components are grouped by their label
  up to the last ``/`` (``NN_f/hidden/w3`` is line ``w3`` of ``weights/NN_f/hidden``). A chunk per
  component made saving a run three times as slow and its file three times as big.
- ``CHANGE``: one entity per layer (grouped as for ``LAYERS``), one line: the RMS of the layer's
  change since the first step, what a person reads from 171 weights at a glance.
- ``SCENE``: drawn in the 3D world and the top view by :mod:`mlpfac.log.scene`; ``path`` lists its
  entities.
- ``UNSENT``: kept in the record (and its metrics), not in the recording.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

RGB = tuple[int, int, int]
LINES, LAYERS, CHANGE, SCENE, UNSENT = "lines", "layers", "change", "scene", "unsent"

# Colours: the reference is orange, the robot's own path blue, e1/e2/e3 red/green/blue; the robot's
# heading arrow purple (it reads on the viewer's light and dark backgrounds); events dark red.
REF_COLOR: RGB = (255, 160, 40)
PATH_COLOR: RGB = (60, 140, 255)
ROBOT_COLOR: RGB = (160, 40, 200)
EVENT_COLOR: RGB = (200, 20, 40)
ERROR_COLORS: tuple[RGB, ...] = ((230, 70, 70), (80, 200, 90), (80, 140, 255), (240, 220, 80))
CMD_COLOR: RGB = (80, 160, 255)
MEAS_COLOR: RGB = (255, 130, 60)
WHEEL_CMD_COLORS: tuple[RGB, ...] = ((30, 80, 200), (200, 60, 20))  # left blue, right red-orange ...
WHEEL_MEAS_COLORS: tuple[RGB, ...] = ((120, 180, 255), (255, 170, 90))  # ... paler when measured
REFSPEED_COLOR: RGB = (150, 150, 150)
TRUE_COLOR: RGB = (150, 150, 150)
P_COLOR: RGB = (240, 200, 80)
FORCE_COLORS: tuple[RGB, ...] = ((235, 60, 170), (150, 60, 235), (90, 90, 90))  # fx, fy, torque_z
OTHER_COLOR: RGB = (200, 200, 200)
ESTIMATE_COLORS: tuple[RGB, ...] = ((60, 220, 200), (40, 150, 140))  # the estimate's error: teal, as its path
WEIGHT_COLORS: dict[str, RGB] = {  # one hue per network and layer
    "NN_f/output": (90, 160, 255),
    "NN_f/hidden": (120, 220, 160),
    "NN_G/output": (255, 150, 80),
    "NN_G/hidden": (240, 110, 200),
}


def position_error(e: np.ndarray) -> np.ndarray:
    """|(e1, e2)| of tracking errors (rows, 3): the distance from the reference point."""
    return np.hypot(e[:, 0], e[:, 1])


def log10(x: np.ndarray) -> np.ndarray:
    """log10 of a positive series (NaN where it is not): trace(P) spans decades."""
    x = np.asarray(x, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(x > 0, np.log10(np.where(x > 0, x, 1.0)), np.nan)


def log10_norm(x: np.ndarray) -> np.ndarray:
    """log10 of each row's Euclidean norm: the innovation's size, which spans decades."""
    return log10(np.sqrt(np.sum(np.asarray(x, dtype=float) ** 2, axis=1)))


@dataclass(frozen=True)
class Row:
    """One way one record array or telemetry key goes into the recording (see the module docstring).

    ``names`` are the components' names, () for a 1-D array; ``labels`` names a ``record.labels``
    entry that replaces them when it has one name per component; when neither fits, components
    are named ``prefix`` + index. ``cols`` picks components (default: all). ``line`` is a plotted
    line's name, ``{name}`` standing for the component's (a 1-D array's one line: as written).
    ``colors`` go to the components in turn (a mapping: by layer, for ``LAYERS``). ``derive`` turns
    the array's rows into one value per row. ``unit``: one for all components, or one each
    ("m/s, rad/s").
    """

    key: str
    store: str  # "record" (a top-level array), "plant" or "ctrl" (telemetry)
    send: str
    path: str
    unit: str = ""
    names: tuple[str, ...] = ()
    line: str = "{name}"
    colors: tuple[RGB, ...] | Mapping[str, RGB] = (OTHER_COLOR,)
    width: float = 1.5
    cols: tuple[int, ...] | None = None
    labels: str | None = None
    prefix: str = ""
    derive: Callable[[np.ndarray], np.ndarray] | None = None


_VW, _LR, _H = ("v", "omega"), ("left", "right"), ("h1", "h2", "h5")

# fmt: off
SCHEMA: tuple[Row, ...] = (
    # The record's own arrays.
    Row("t", "record", UNSENT, "", "s"),  # the sim_time timeline itself
    Row("e_true", "record", LINES, "errors/{name}", "m, m, rad", ("e1", "e2", "e3"), colors=ERROR_COLORS[:3]),
    Row("e_true", "record", LINES, "errors/position", "m", line="|(e1, e2)|", colors=ERROR_COLORS[3:],
        derive=position_error),
    Row("e", "record", UNSENT, "", "m, m, rad"),  # what the controller saw: e_true through the measurement
    Row("pose_meas", "record", UNSENT, "", "m, m, rad"),
    Row("u", "record", LINES, "controls/{name}/cmd", "m/s, rad/s", _VW, "{name} commanded", (CMD_COLOR,)),
    Row("ref", "record", LINES, "controls/{name}/ref", "m/s, rad/s", _VW, "{name}_r", (REFSPEED_COLOR,), 1.0, (3, 4)),
    Row("ref", "record", SCENE, "world/reference_path top/plane/reference_path", "m", colors=(REF_COLOR,)),
    Row("ref", "record", SCENE, "world/reference_now top/plane/reference_now", "m, m, rad", colors=(REF_COLOR,)),
    Row("pose", "record", SCENE, "world/robot top/plane/robot", "m, m, rad", colors=(ROBOT_COLOR,)),
    Row("pose", "record", SCENE, "world/path top/plane/path", "m", colors=(PATH_COLOR,)),
    # Plant telemetry.
    Row("u_meas", "plant", LINES, "controls/{name}/meas", "m/s, rad/s", _VW, "{name} measured", (MEAS_COLOR,)),
    Row("wheel_cmd", "plant", LINES, "wheels/{name}/cmd", "rad/s", _LR, "{name} commanded", WHEEL_CMD_COLORS),
    Row("wheel_meas", "plant", LINES, "wheels/{name}/meas", "rad/s", _LR, "{name} measured", WHEEL_MEAS_COLORS),
    Row("h_true", "plant", LINES, "h/{name}/true", "", _H, "{name} true", (TRUE_COLOR,), labels="h_hat", prefix="h"),
    # (v, omega) of the axle midpoint and the (left, right) wheel torques: named by index, as always.
    Row("u_true", "plant", LINES, "plant/u_true/{name}", "m/s, rad/s", ("0", "1"), labels="u_true"),
    Row("torque", "plant", LINES, "plant/torque/{name}", "N m", ("0", "1"), labels="torque"),
    # A pose that was estimated ([plant] pose_source; mlpfac.log.belief draws the believed path and the fixes).
    Row("estimate_error", "record", LINES, "errors/estimate/{name}", "m, rad", ("position", "heading"),
        "{name}: believed - true", ESTIMATE_COLORS),
    Row("fix", "plant", SCENE, "world/fixes top/plane/fixes", "m, m, rad, s"),
    Row("sensed", "plant", LINES, "sensors/{name}", "m/s, rad/s, rad/s, rad/s", ("v", "omega", "left", "right"),
        "{name} sensed", (MEAS_COLOR, MEAS_COLOR, *WHEEL_MEAS_COLORS)),
    Row("estimate_std", "plant", LINES, "sensors/estimate_std/{name}", "m, m, rad", ("x", "y", "theta"),
        "{name} std", ERROR_COLORS[:3]),
    Row("odometry_scale", "plant", LINES, "sensors/wheel_scale/{name}", "", _LR, "{name} wheel's scale",
        WHEEL_MEAS_COLORS),
    # The force of a force event on the robot, the world's axes: its lines, and its arrow (mlpfac.log.terrain).
    Row("force", "plant", LINES, "forces/{name}", "N, N, N m", ("fx", "fy", "torque_z"), "{name} applied",
        FORCE_COLORS),
    Row("force", "plant", SCENE, "world/force", "N", colors=(FORCE_COLORS[0],)),
    # Controller telemetry.
    Row("z", "ctrl", LAYERS, "weights/{layer}", colors=WEIGHT_COLORS, width=1.0, labels="z", prefix="w"),
    Row("z", "ctrl", CHANGE, "weight_change/{layer}", colors=WEIGHT_COLORS, width=2.0, labels="z", prefix="w"),
    Row("trace_P", "ctrl", LINES, "ekf/trace_P", line="trace(P)", colors=(P_COLOR,)),
    Row("trace_P", "ctrl", LINES, "ekf/log10_trace_P", line="log10 trace(P)", colors=(P_COLOR,), derive=log10),
    Row("mean_diag_P", "ctrl", LINES, "ekf/mean_diag_P", line="mean diag(P)", colors=(P_COLOR,)),
    Row("innovation", "ctrl", LINES, "ekf/innovation/{name}", "m, m, rad", ("e1", "e2", "e3"), colors=ERROR_COLORS[:3],
        labels="innovation", prefix="e"),
    Row("innovation", "ctrl", LINES, "ekf/log10_innovation", line="log10 |innovation|", colors=(P_COLOR,),
        derive=log10_norm),
    Row("h_hat", "ctrl", LINES, "h/{name}/estimate", "", _H, "{name} estimate", (CMD_COLOR,), labels="h_hat",
        prefix="h"),
)
# fmt: on


def rows_for(store: str, key: str) -> list[Row]:
    """The schema's rows for one key (empty for a key it does not know)."""
    return [r for r in SCHEMA if r.store == store and r.key == key]


def generic(store: str, key: str, arr: np.ndarray) -> Row:
    """The row of a telemetry key the schema does not know: ``<store>/<key>``, one entity per component."""
    if arr.ndim == 1:
        return Row(key, store, LINES, f"{store}/{entity_part(key)}", line=key)
    return Row(key, store, LINES, f"{store}/{entity_part(key)}/{{name}}", names=(), labels=key)


def component_names(row: Row, arr: np.ndarray, labels: Mapping[str, list[str]]) -> list[str]:
    """One entity-path-safe name per component of ``arr`` (rows, ...) as ``row`` sends it: the
    record's labels, else the row's names, else ``prefix`` + index."""
    width = len(row.cols) if row.cols is not None else int(np.prod(arr.shape[1:]))
    names = labels.get(row.labels) if row.labels else None
    if names is None or len(names) != width:
        names = row.names if len(row.names) == width else [f"{row.prefix}{i}" for i in range(width)]
    return ["/".join(entity_part(p) for p in str(name).split("/")) for name in names]


def fill(template: str, **parts: str) -> str:
    """``template`` with ``{name}`` / ``{layer}`` replaced; no other brace is special."""
    for k, v in parts.items():
        template = template.replace("{" + k + "}", v)
    return template


def entity_part(name: str) -> str:
    """One entity-path part: letters, digits, '_', '-', '.' kept; anything else becomes '_'."""
    return re.sub(r"[^A-Za-z0-9_.\-]", "_", name) or "_"


def unit(key: str, j: int = 0) -> str:
    """The unit of component j of a key (its first row's; "m/s, rad/s" lists one per component)."""
    units = next(r.unit for r in SCHEMA if r.key == key).split(", ")
    return units[j] if len(units) > 1 else units[0]
