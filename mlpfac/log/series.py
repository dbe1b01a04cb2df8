"""A record's per-step values as rerun columns: the scalar series the schema plans, sent in batches.

Two timelines: ``sim_time`` (duration, the controller clock t[k] = k T) and ``step`` (k).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import rerun as rr

from mlpfac.log.schema import (
    CHANGE,
    LAYERS,
    LINES,
    OTHER_COLOR,
    RGB,
    SCHEMA,
    Row,
    component_names,
    fill,
    generic,
    rows_for,
)
from mlpfac.loop.record import RunRecord

SCALARS = rr.Scalars.descriptor_scalars()

Getter = Callable[[RunRecord, slice], np.ndarray]


@dataclass(frozen=True)
class Series:
    """A scalar time series entity: an entity path, where its values come from, and its style.

    ``name`` is one name for one line per step, or a tuple of names for several lines that share
    the entity (``get`` then gives (rows, lines)).
    """

    path: str
    get: Getter
    name: str | tuple[str, ...]
    color: RGB
    width: float = 1.5

    @property
    def names(self) -> list[str]:
        return list(self.name) if isinstance(self.name, tuple) else [self.name]


@dataclass(frozen=True)
class _Batch:
    """An arrow array of scalar values, as rr.ComponentColumn wants it."""

    array: pa.Array

    def as_arrow_array(self) -> pa.Array:
        return self.array


def plan_series(record: RunRecord) -> list[Series]:
    """Every scalar series of this record: the schema's rows in order, then each telemetry key the
    schema does not know, under ``plant/<key>`` or ``ctrl/<key>``."""
    labels: Mapping[str, list[str]] = getattr(record, "labels", None) or {}
    out: list[Series] = []
    for row in SCHEMA:
        if row.send in (LINES, LAYERS, CHANGE):
            arr = getattr(record, row.key) if row.store == "record" else getattr(record, row.store).get(row.key)
            if arr is not None:
                out += _expand(row, arr, labels)
    for store in ("plant", "ctrl"):
        for key, arr in getattr(record, store).items():
            if not rows_for(store, key):
                out += _expand(generic(store, key, arr), arr, labels)
    return out


def _expand(row: Row, arr: np.ndarray, labels: Mapping[str, list[str]]) -> list[Series]:
    """The series one schema row makes of one array."""
    colors = row.colors
    if row.send == CHANGE:
        return _changes(row, arr, labels) if arr.ndim == 2 else []  # a batch's max |z| has no layers
    if row.derive is not None or (arr.ndim == 1 and row.cols is None):
        return [Series(row.path, _getter(row, None), row.line, colors[0], row.width)]
    names = component_names(row, arr, labels)
    if row.send == LAYERS:  # one entity per layer, one line per component
        layers: dict[str, list[int]] = {}
        for i, label in enumerate(names):
            layers.setdefault(label.rpartition("/")[0], []).append(i)
        return [
            Series(
                fill(row.path, layer=layer).rstrip("/"),
                _getter(row, idx),
                tuple(fill(row.line, name=names[i].rpartition("/")[2]) for i in idx),
                colors.get(layer, OTHER_COLOR),
                row.width,
            )
            for layer, idx in layers.items()
        ]
    cols = row.cols if row.cols is not None else range(len(names))
    return [
        Series(
            fill(row.path, name=name), _getter(row, c), fill(row.line, name=name), colors[j % len(colors)], row.width
        )
        for j, (c, name) in enumerate(zip(cols, names, strict=True))
    ]


def _changes(row: Row, arr: np.ndarray, labels: Mapping[str, list[str]]) -> list[Series]:
    """One series per layer: the RMS over its weights of z_i(t) - z_i(0)."""
    layers: dict[str, list[int]] = {}
    for i, label in enumerate(component_names(row, arr, labels)):
        layers.setdefault(label.rpartition("/")[0] or "all", []).append(i)
    key, store = row.key, row.store

    def change(idx: list[int]) -> Getter:
        def get(record: RunRecord, s: slice) -> np.ndarray:
            z = getattr(record, store)[key]
            return np.sqrt(np.mean((z[s][:, idx] - z[0, idx]) ** 2, axis=1))

        return get

    return [
        Series(
            fill(row.path, layer=layer),
            change(idx),
            f"{layer} ({len(idx)})",
            row.colors.get(layer, OTHER_COLOR),
            row.width,
        )
        for layer, idx in layers.items()
    ]


def _getter(row: Row, j: int | list[int] | None) -> Getter:
    """Component(s) j of the row's array (its trailing axes flattened), the whole array for None,
    or the row's derived value."""
    key, store, derive = row.key, row.store, row.derive

    def get(record: RunRecord, s: slice) -> np.ndarray:
        arr = (getattr(record, key) if store == "record" else getattr(record, store)[key])[s]
        if derive is not None:
            return derive(arr)
        return arr if j is None else arr.reshape(len(arr), -1)[:, j]

    return get


def style_series(rec: rr.RecordingStream, series: list[Series], styled: set[str]) -> None:
    """Each series' line names, colours and widths, once per entity (static)."""
    for s in series:
        if s.path not in styled:
            styled.add(s.path)
            k = len(s.names)
            rec.log(s.path, rr.SeriesLines(colors=[s.color] * k, names=s.names, widths=[s.width] * k), static=True)


def send_series(rec: rr.RecordingStream, series: list[Series], record: RunRecord, a: int, b: int) -> None:
    """Rows [a, b) of every series, one chunk per series. ComponentColumn skips Scalars.columns'
    checks (2x faster)."""
    idx = time_index(record, np.arange(a, b))
    for s in series:
        values = np.ascontiguousarray(s.get(record, slice(a, b)), dtype=np.float64)
        column = rr.ComponentColumn(SCALARS, _Batch(pa.array(values.ravel())))
        if values.ndim == 2:  # several lines: each row holds one value per line
            column = column.partition(np.full(len(values), values.shape[1]))
        rec.send_columns(s.path, indexes=idx, columns=[column])


def ns(seconds: np.ndarray) -> np.ndarray:
    """Seconds as whole nanoseconds, rounded (not truncated: 0.07 s * 1e9 is 69999999.99...)."""
    return np.round(np.asarray(seconds, dtype=float) * 1e9).astype(np.int64).astype("timedelta64[ns]")


def time_index(record: RunRecord, rows: np.ndarray) -> list[rr.TimeColumn]:
    """The ``sim_time`` and ``step`` columns of the record's rows."""
    return [rr.TimeColumn("sim_time", duration=ns(record.t[rows])), rr.TimeColumn("step", sequence=rows)]
