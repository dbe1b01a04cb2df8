"""Figure 1 of the paper redrawn from a run record, each panel at a scale where its signal reads:
(a)-(c) e1, e2 [mm] and e3 [mrad], (d) the weights that moved most, (e) the reference and the
driven path, (f) a close-up where the error is largest, (g) mean diag(P_k), (h) e2 of the
non-adaptive law on the same scenario and seed. Panels that do not apply (no weights, no P, the
baseline being the run itself) are left out; the others keep the paper's letters.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from mlpfac.loop.record import RunRecord
from mlpfac.plots.world import EVENT_COLOR, RUN_COLOR, WARM_COLOR, legend_entries, mark_paths, mark_times, on_ground


def figure1(rec: RunRecord, baseline: RunRecord | None, path: Path) -> list[str]:
    """Write Figure 1 for ``rec`` (and ``baseline`` for panel h) to ``path`` (PNG); the letters of
    the panels drawn."""
    return Draft(rec, shows_h(rec, baseline)).finish(baseline, path)


def shows_h(rec: RunRecord, baseline: RunRecord | None) -> bool:
    """Whether panel (h) is drawn: a baseline that is not the run's own law and ran."""
    return baseline is not None and baseline.controller != rec.controller and baseline.n > 0


class Draft:
    """Figure 1 but panel (h), made and drawn (:meth:`draw`) before the baseline has run (the
    painter's process does it while the run's process runs the baseline); :meth:`finish` draws
    (h) over its place, left blank, and writes the figure: the same pixels as a figure drawn
    whole, since no panel overlaps another. ``h``: whether the figure has a panel (h);
    ``column``: only the panels of that column (0 the left, 1 the right; None both), laid out as in
    the whole figure; ``title``: with the figure's title."""

    def __init__(self, rec: RunRecord, h: bool, column: int | None = None, title: bool = True) -> None:
        from mlpfac.plots.mplconfig import quiet_config

        quiet_config()
        from matplotlib import rc_context
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        from matplotlib.ticker import LogFormatter

        self.rec, self.h, self.column = rec, h, column
        n = rec.n
        P = rec.ctrl.get("mean_diag_P")
        time_panels = _time_panels(rec, h)
        rows = -(-len(time_panels) // 2) + 1
        t = rec.t[:n]
        warm = min(rec.warmup_s, t[-1] if n else 0.0)
        entries = legend_entries(rec, warm > 0)
        lines = -(-len(entries) // LEGEND_COLUMNS)
        heading = _title(rec)  # the run and its outcome, a line each (the outcome wrapped where long)
        title_in = TITLE_LINE_IN * heading.count("\n") + TITLE_IN
        top = title_in + LEGEND_LINE_IN * lines + 0.3  # the title, the legend under it, the panels' titles
        height = 2.9 * rows + 0.2 + top
        self.fig = fig = Figure(figsize=(12, height), dpi=DPI)  # no pyplot: nothing global, nothing to close
        FigureCanvasAgg(fig)
        grid = fig.add_gridspec(rows, 2, **_layout(height, top))
        if title:  # the outcome metrics.json records, in its words; the legend of every panel under it
            fig.suptitle(heading, fontsize=11, y=1 - 0.06 / height, va="top")
            fig.legend(handles=entries, loc="upper center", ncol=min(len(entries), LEGEND_COLUMNS), fontsize=8,
                       bbox_to_anchor=(0.5, 1 - title_in / height), frameon=False)  # fmt: skip
        self.axes = axes = {}
        self.paths = paths = {}
        drawn = (0, 1) if column is None else (column,)
        with rc_context({"axes.titley": 1.0}):  # titles at a fixed height: no search for the room above the axes
            for i, tag in enumerate(time_panels):
                if i % 2 in drawn:
                    axes[tag] = fig.add_subplot(grid[i // 2 + (i >= 4), i % 2])  # the paths' row follows (c), (d)
            prow = min(2, rows - 1)
            for j, tag in enumerate("ef"):
                if j in drawn:
                    paths[tag] = fig.add_subplot(grid[prow, j])
        for i, (name, scale, unit, what) in enumerate(
            [("e1", 1e3, "mm", "along the path"), ("e2", 1e3, "mm", "across the path"), ("e3", 1e3, "mrad", "heading")]
        ):
            if (ax := axes.get("abc"[i])) is not None:
                _signal(ax, t, rec.e_true[:n, i] * scale, warm)
                ax.set(title=f"({'abc'[i]}) {name}: {what}", ylabel=f"{name} [{unit}]")
        if "d" in axes:
            _weights(axes["d"], rec, t)
        if (ax := axes.get("g")) is not None:
            ax.semilogy(t, P[:n], color=RUN_COLOR, lw=1.0)
            for minor in (False, True):  # plain "9e-02" labels: the same ticks, no mathtext to lay out
                (ax.yaxis.set_minor_formatter if minor else ax.yaxis.set_major_formatter)(LogFormatter())
            ax.set(title="(g) mean of diag(P_k): the EKF's uncertainty", ylabel="mean diag(P_k) [-]")
        ground = on_ground(rec)  # when the robot was on a ramp or a patch
        for tag, ax in axes.items():
            ax.set_xlabel("t [s]")
            ax.grid(alpha=0.3, which="both")
            ax.set_xlim(0, rec.t[-1] + rec.T)
            if tag != "h":  # (h): the baseline's own times, where it is drawn
                mark_times(ax, rec, ground)
        _paths(paths, rec, warm)
        if "h" in axes:
            axes["h"].set_visible(False)  # drawn by finish, over its blank place
        self.drawn = False

    def draw(self) -> None:
        """Draw every panel but (h) (once)."""
        if not self.drawn:
            self.fig.canvas.draw()
            self.drawn = True

    def pixels(self) -> np.ndarray:
        """The drawn figure, (height, width, 4) RGBA."""
        return np.asarray(self.fig.canvas.buffer_rgba())

    def finish(
        self, baseline: RunRecord | None, path: Path, other: Callable[[], np.ndarray | None] | None = None
    ) -> list[str]:
        """The figure completed with ``baseline`` (:meth:`complete`), drawn and written to
        ``path``; the letters of the panels drawn. A draft of one column gets the other's pixels
        from ``other`` (a :meth:`pixels` of the draft of the other column, with the title; None, or
        no ``other``: drawn here) and puts the two together (:func:`together`)."""
        done = self.complete(baseline)
        done.draw()
        if "h" in done.axes:
            ax = done.axes["h"]
            ax.set_visible(True)
            ax.draw(done.fig.canvas.get_renderer())
        pixels = done.pixels()
        letters = [*done.axes, *done.paths]
        if done.column is not None:
            theirs = other() if other is not None else None
            if theirs is None or theirs.shape != pixels.shape:
                rest = Draft(done.rec, done.h, 1 - done.column)
                rest.draw()
                theirs = rest.pixels()
            pixels = together(theirs, done.column == 1, pixels)
            if pixels is None:  # the columns' ink not apart: the figure drawn whole
                return Draft(done.rec, done.h).finish(baseline, path)
            letters = [*_time_panels(done.rec, done.h), "e", "f"]
        write_png(pixels, path)
        return sorted(letters)

    def complete(self, baseline: RunRecord | None) -> Draft:
        """This draft with panel (h) drawn from ``baseline``; a draft made for the other answer of
        :func:`shows_h` is made again, whole (and returned)."""
        if self.h != shows_h(self.rec, baseline):
            return Draft(self.rec, not self.h).complete(baseline)
        if "h" in self.axes:
            nb = baseline.n
            ax = self.axes["h"]
            _signal(ax, baseline.t[:nb], baseline.e_true[:nb, 1] * 1e3, min(baseline.warmup_s, baseline.t[nb - 1]))
            mark_times(ax, baseline, on_ground(baseline))
            how = _outcome(baseline)["outcome"]
            ax.set(title=f"(h) e2 under the {baseline.controller} law, same seed ({how})", ylabel="e2 [mm]")
        return self


def h_column(rec: RunRecord, h: bool) -> int:
    """The column of panel (h) (1 when there is none): the painter draws it, and a process forked
    from the painter the other column with the title."""
    panels = _time_panels(rec, h)
    return (len(panels) - 1) % 2 if h else 1


def together(titled: np.ndarray, left: bool, other: np.ndarray) -> np.ndarray | None:
    """Figure 1 from the pixels of its two columns drawn apart, each on the figure's white: the
    column with the title (``titled``, the left one if ``left``) above the other's topmost ink and
    on its side of a line between the columns, the ``other`` on the other side. The same pixels as
    the figure drawn whole when each column's ink stays on its side (every white an artist draws is
    framed by ink: axes, legends); None when it does not."""
    ink_t, ink_o = (np.ascontiguousarray(x).view(np.uint32)[..., 0] != 0xFFFFFFFF for x in (titled, other))
    rows, cols = np.flatnonzero(ink_o.any(axis=1)), np.flatnonzero(ink_o.any(axis=0))
    if not len(rows):
        return None
    top = rows[0]
    cols_t = np.flatnonzero(ink_t[top:].any(axis=0))
    split = cols[0] if left else cols[-1] + 1
    if len(cols_t) and (cols_t[-1] >= split if left else cols_t[0] < split):
        return None
    out = titled.copy()
    side = np.s_[top:, split:] if left else np.s_[top:, :split]
    out[side] = other[side]
    return out


def _time_panels(rec: RunRecord, h: bool) -> list[str]:
    """The panels against time, in the order they are laid out two by two."""
    z = rec.ctrl.get("z")
    adaptive = z is not None and z.ndim == 2 and z.shape[1] > 1
    panels = ["a", "b", "c"] + (["d"] if adaptive else []) + (["g"] if rec.ctrl.get("mean_diag_P") is not None else [])
    return panels + (["h"] if h else [])


DPI = 90
TITLE_IN, TITLE_LINE_IN = 0.35, 0.2  # inches above the panels: the title's first line, each line more
LEGEND_LINE_IN, LEGEND_COLUMNS = 0.22, 5  # ... a line of the legend, of this many entries
TITLE_WIDTH = 130  # characters of the outcome a line of the title holds


def _outcome(rec: RunRecord) -> dict:
    """The run's figures as metrics.json records them (its outcome among them)."""
    from mlpfac.loop.metrics import metrics

    return metrics(rec)


def _title(rec: RunRecord) -> str:
    """The figure's title: the run, and its outcome in the words of its first line."""
    import textwrap

    from mlpfac.loop.metrics import outcome_words

    words = textwrap.wrap(outcome_words(_outcome(rec)), TITLE_WIDTH)
    return "\n".join([f"{rec.scenario} / {rec.controller} / seed {rec.seed}", *words])


def write_png(pixels: np.ndarray, path: Path) -> None:
    """``pixels`` (height, width, 4) as a PNG at ``path``, compressed for speed (a few % larger)."""
    from PIL import Image

    Image.fromarray(pixels, "RGBA").save(path, format="png", compress_level=1, dpi=(DPI, DPI))


def warm_up() -> None:
    """Do ahead what the first figure of a process does once: matplotlib's figure, axes and
    projections imported (their docstrings processed), the font and its glyphs loaded, PIL's PNG
    writer registered. The painter's child does it while the run is computed."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import LogFormatter
    from PIL import Image

    Image.preinit()
    fig = Figure(figsize=(1, 1), dpi=10)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.semilogy([0.0, 1.0], [1e-2, 1.0], label="x")
    ax.yaxis.set_major_formatter(LogFormatter())
    ax.set(title="(x) 0.1", xlabel="t [s]")
    ax.legend(fontsize=7)
    ax.add_patch(_box(np.zeros(2), 0.1))
    fig.canvas.draw()


def _layout(height: float, top: float) -> dict[str, float]:
    """A fixed layout (what constrained layout found for this figure, without its solver's passes):
    margins in inches (``top``: the title and the legend above the panels), room on the right for
    the legend of (d)."""
    return {
        "left": 0.08,
        "right": 0.865,
        "top": 1 - top / height,
        "bottom": 0.5 / height,
        "wspace": 0.2,
        "hspace": 0.36,
    }


def _signal(ax, t: np.ndarray, y: np.ndarray, warm: float) -> None:
    """One signal, its y range set by what follows the warm-up (a larger start is clipped and said so)."""
    ax.plot(t, y, color=RUN_COLOR, lw=0.8)
    after = y[(t >= warm) & np.isfinite(y)]
    if warm > 0:
        ax.axvspan(0, warm, color=WARM_COLOR, lw=0, zorder=0)
    if len(after) < 2:
        return
    lo, hi = np.percentile(after, [0.2, 99.8])
    lo, hi = min(lo, 0.0), max(hi, 0.0)
    pad = 0.12 * (hi - lo or 1.0)
    lo, hi = lo - pad, hi + pad
    ax.set_ylim(lo, hi)
    early = y[(t < warm) & np.isfinite(y)]
    if len(early) and (early.max() > hi or early.min() < lo):
        peak = early[np.argmax(np.abs(early))]
        ax.annotate(
            f"warm-up, clipped\n(up to {peak:.3g})",
            (warm, 0.96),
            xycoords=("data", "axes fraction"),
            xytext=(3, 0),
            textcoords="offset points",
            va="top",
            fontsize=7,
            color="0.35",
        )


def _weights(ax, rec: RunRecord, t: np.ndarray) -> None:
    """(d): the six weights that moved most from their initial values, named."""
    z = rec.ctrl["z"][: rec.n]
    labels = rec.labels.get("z") or [f"z{j}" for j in range(z.shape[1])]
    moved = np.nan_to_num(np.nanmax(np.abs(z - z[0]), axis=0), nan=-1.0)
    for j in np.argsort(moved)[::-1][:6]:
        ax.plot(t, z[:, j], lw=0.9, label=labels[j] if j < len(labels) else f"z{j}")
    ax.legend(
        fontsize=7, loc="center left", bbox_to_anchor=(1.0, 0.5), frameon=False, title="moved most", title_fontsize=7
    )
    ax.set(title=f"(d) the 6 of {z.shape[1]} weights that moved most", ylabel="weight z_i [-]")


def _paths(axes: dict, rec: RunRecord, warm: float) -> None:
    """(e) the whole reference and driven paths; (f) a close-up around the largest error after the
    warm-up (each if in ``axes``)."""
    n = rec.n
    ref, pose = rec.ref[:n, :2], rec.pose[:n, :2]
    ok = np.all(np.isfinite(pose), axis=1)
    err = np.where(ok, np.hypot(*(pose - ref).T), -1.0)
    w = min(int(round(warm / rec.T)), max(n - 1, 0))
    k = w + int(np.argmax(err[w:])) if n else 0
    half = float(np.clip(3.0 * err[k], 0.03, 0.5)) if n else 0.5
    for ax in axes.values():
        ax.plot(rec.ref[: len(rec.t), 0], rec.ref[: len(rec.t), 1], color="black", lw=1.0)
        ax.plot(pose[ok, 0], pose[ok, 1], color=RUN_COLOR, lw=1.0)
        mark_paths(ax, rec)
        ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
        ax.grid(alpha=0.3)
    full, close = axes.get("e"), axes.get("f")
    if full is not None:
        rough = " (on rough ground)" if (rec.world or {}).get("grid") is not None else ""
        full.set_title(f"(e) reference and driven paths{rough}")
    if not n:
        return
    c = ref[k]
    if full is not None:
        full.add_patch(_box(c, half))
    if close is None:
        return
    stride = max(1, int(round(0.1 / rec.T)))
    near = np.arange(max(k - 60 * stride, 0), min(k + 60 * stride, n), stride)
    near = near[ok[near] & (np.abs(ref[near] - c).max(axis=1) < half)]
    for j in near:  # where the robot is (blue) against where it should be (black), every 0.1 s
        close.plot(*np.c_[pose[j], ref[j]], color="0.55", lw=0.7)
    close.plot(*np.c_[pose[k], ref[k]], color=EVENT_COLOR, lw=1.5)
    close.plot(*pose[k], "o", color=RUN_COLOR, ms=6)
    close.plot(*ref[k], "o", color="black", ms=6, mfc="white")
    close.set(xlim=(c[0] - half, c[0] + half), ylim=(c[1] - half, c[1] + half))
    close.set_title(f"(f) close-up: largest error after warm-up, {err[k] * 1e3:.1f} mm at t = {rec.t[k]:.1f} s")
    close.annotate(
        "robot (blue dot) to its reference point (white); grey: every 0.1 s",
        (0.02, 0.02),
        xycoords="axes fraction",
        fontsize=7,
        color="0.3",
    )


def _box(center: np.ndarray, half: float):
    from matplotlib.patches import Rectangle

    return Rectangle(tuple(center - half), 2 * half, 2 * half, fill=False, ec=EVENT_COLOR, lw=1.2)
