"""The pictures: Figure 1's panels per controller, the sweep
plots beside the tables (made by `mlpfac sweep` and again by `mlpfac plot`), and the colours."""

from __future__ import annotations

import json

import pytest

from mlpfac.cli import main
from mlpfac.loop.metrics import RunMetrics
from mlpfac.loop.runner import run
from mlpfac.plots import controller_colors, figure1
from mlpfac.scenario.parse import load


@pytest.fixture(scope="module")
def short_runs():
    """The paper's scenario for 3 s with its event at 1.5 s, per controller."""
    import copy

    from mlpfac.scenario.parse import parse

    table = copy.deepcopy(load("paper").table)
    table["duration"] = 3.0
    table["events"][0]["time"] = 1.5
    scn = parse(table, "sims/paper.toml")
    return {c: run(scn.with_overrides(controller=c)) for c in ("adaptive", "corradini", "kanayama")}


def test_figure1_leaves_out_the_panels_that_do_not_apply(tmp_path, short_runs):
    adaptive, corradini, kanayama = (short_runs[c] for c in ("adaptive", "corradini", "kanayama"))
    assert figure1(adaptive, corradini, tmp_path / "a.png") == list("abcdefgh")
    assert figure1(kanayama, corradini, tmp_path / "k.png") == list("abcefh")  # no weights, no P
    assert figure1(corradini, corradini, tmp_path / "c.png") == list("abcef")  # (h) would be itself
    assert figure1(adaptive, None, tmp_path / "n.png") == list("abcdefg")
    assert all((tmp_path / f).stat().st_size > 20_000 for f in ("a.png", "k.png", "c.png", "n.png"))


def _pixels(path):
    import numpy as np
    from PIL import Image

    return np.asarray(Image.open(path))


def test_figure1_drawn_before_its_panel_h_is_the_figure_drawn_whole(tmp_path, short_runs):
    """The painter draws every panel but (h) while the baseline runs, then (h) over its blank
    place: the same pixels as the figure drawn at once."""
    import numpy as np

    from mlpfac.plots.figure1 import Draft

    adaptive, corradini = short_runs["adaptive"], short_runs["corradini"]
    draft = Draft(adaptive, True)
    draft.draw()
    assert draft.finish(corradini, tmp_path / "two.png") == list("abcdefgh")
    whole = Draft(adaptive, True).complete(corradini)
    whole.axes["h"].set_visible(True)
    whole.fig.canvas.draw()
    pixels = np.asarray(whole.fig.canvas.buffer_rgba())
    two = _pixels(tmp_path / "two.png")
    assert two.shape == pixels.shape and np.array_equal(two, pixels)
    h = whole.axes["h"].get_window_extent()  # and panel (h) is on it, not blank
    rows = slice(int(pixels.shape[0] - h.y1), int(pixels.shape[0] - h.y0))
    assert (pixels[rows, int(h.x0) : int(h.x1), :3] < 200).any(axis=2).mean() > 0.01


def test_a_draft_made_for_the_other_panel_h_is_made_again(tmp_path, short_runs):
    """The painter makes the figure before the baseline has run, expecting a panel (h); a baseline
    that turns out to be the run's own law (or ran no step) gets the figure without it."""
    from mlpfac.plots.figure1 import Draft

    adaptive, corradini = short_runs["adaptive"], short_runs["corradini"]
    assert Draft(adaptive, True).finish(adaptive, tmp_path / "a.png") == list("abcdefg")
    assert Draft(adaptive, False).finish(corradini, tmp_path / "b.png") == list("abcdefgh")
    assert Draft(adaptive, True, 1, title=False).finish(adaptive, tmp_path / "c.png", lambda: None) == list("abcdefg")
    assert (_pixels(tmp_path / "c.png") == _pixels(tmp_path / "a.png")).all()  # drawn whole: no column's pixels asked


@pytest.mark.parametrize("case", ["h on the right", "h on the left", "no h", "no weights"])
def test_figure1_drawn_in_two_columns_is_the_figure_drawn_whole(tmp_path, short_runs, case):
    """The painter draws the column of panel (h), a process forked from it the other with the
    title; put together, the pixels of the figure drawn whole, wherever (h) falls."""
    import dataclasses

    from mlpfac.plots.figure1 import Draft, h_column

    rec, baseline = short_runs["adaptive"], short_runs["corradini"]
    if case == "h on the left":  # a, b, c, d, h: (h) fifth, in the left column
        rec = dataclasses.replace(rec, ctrl={k: v for k, v in rec.ctrl.items() if k != "mean_diag_P"})
    elif case == "no h":
        baseline = rec
    elif case == "no weights":
        rec = short_runs["kanayama"]
    h = baseline.controller != rec.controller
    column = h_column(rec, h)
    assert column == (0 if case == "h on the left" else 1)
    letters = Draft(rec, h).finish(baseline, tmp_path / "whole.png")
    mine, rest = Draft(rec, h, column, title=False), Draft(rec, h, 1 - column)
    mine.draw()
    rest.draw()
    assert mine.finish(baseline, tmp_path / "two.png", rest.pixels) == letters
    assert "h" in letters if h else "h" not in letters
    whole, two = _pixels(tmp_path / "whole.png"), _pixels(tmp_path / "two.png")
    assert two.shape == whole.shape and (two == whole).all()
    assert Draft(rec, h, column, title=False).finish(baseline, tmp_path / "alone.png") == letters  # no pixels given
    assert (_pixels(tmp_path / "alone.png") == whole).all()


def test_columns_whose_ink_meets_are_not_put_together():
    import numpy as np

    from mlpfac.plots.figure1 import together

    white = np.full((40, 60, 4), 255, np.uint8)
    left, right = white.copy(), white.copy()
    left[5:10, 5:30] = 0  # title and left column
    right[20:30, 35:55] = 0
    out = together(left, True, right)
    assert (out[5:10, 5:30] == 0).all() and (out[20:30, 35:55] == 0).all() and (out == 0).sum() == 4 * (125 + 200)
    left[25, 40] = 7  # the left column's ink on the right's side, below the right's top
    assert together(left, True, right) is None
    assert together(white, True, white) is None  # nothing drawn in the other column


def test_the_painter_draws_figure1_as_figure1_does(tmp_path, short_runs):
    """Through the painter's processes (the figure's child and the process it forks for a column)."""
    from mlpfac.plots.painter import painting

    adaptive, corradini = short_runs["adaptive"], short_runs["corradini"]
    letters = figure1(adaptive, corradini, tmp_path / "here.png")
    with painting(True) as painter:
        assert painter.pid is not None
        painter.begin(adaptive, tmp_path / "there.png", True)
        assert painter.finish(corradini) == letters
    assert (_pixels(tmp_path / "there.png") == _pixels(tmp_path / "here.png")).all()
    from functools import partial

    from mlpfac.io.interrupts import ForkedChild
    from mlpfac.plots.figure1 import Draft
    from mlpfac.plots.painter import _column

    pixels = ForkedChild(partial(_column, adaptive, True, 0)).answer()  # the other column, as the painter gets it
    here = Draft(adaptive, True, 0)
    here.draw()
    assert pixels is not None and (pixels == here.pixels()).all()


def outcome(m: dict) -> str:
    """The outcome RunMetrics reads from a metrics.json with the keys ``m`` adds to a minimal one."""
    least = {"scenario": "paper", "controller": "corradini", "seed": 0, "T": 0.01, "steps": 10, "phases": {}}
    return RunMetrics.from_json(least | m).outcome


def test_outcome_reads_the_newer_field_and_falls_back_to_status():
    assert outcome({"status": "ok"}) == "tracking" and outcome({"status": "diverged"}) == "diverged"
    assert outcome({"status": "ok", "outcome": "lost"}) == "lost"
    assert outcome({"status": "ok", "tracking_status": "lost"}) == "lost"


def test_every_controller_gets_its_own_colour_and_keeps_it():
    names = ["adaptive", "corradini", "kanayama", "oracle", "adaptive-best", "mine", "yours", "theirs"]
    colors = controller_colors(names)
    assert len(set(colors.values())) == len(names)
    assert controller_colors(["mine"])["mine"] == controller_colors(["kanayama", "mine"])["mine"]
    assert controller_colors(["corradini", "adaptive"]) == {k: colors[k] for k in ("corradini", "adaptive")}


def test_sweep_writes_its_plot_and_plot_draws_it_again(tmp_path, capsys):
    out = tmp_path / "s"
    argv = ["sweep", "paper", "paper-faithful", "--controllers", "adaptive,kanayama", "--seeds", "0-2"]
    assert main([*argv, "--duration", "3", "--workers", "1", "--out", str(out)]) == 0
    assert f"{out / 'sweep.png'}" in capsys.readouterr().out
    first = (out / "sweep.png").stat().st_size
    assert first > 30_000
    m = json.loads((out / "paper" / "adaptive" / "seed-0000" / "metrics.json").read_text())
    assert len(m["position_ms_bins"]["m2"]) == 30 and m["outcome"] == "tracking"
    (out / "sweep.png").unlink()
    assert main(["plot", str(out)]) == 0
    assert (out / "sweep.png").stat().st_size == first  # the same picture from the folders alone
    assert main(["compare", "paper", "--seeds", "0", "--duration", "2", "--workers", "1", "--out", str(out / "c")]) == 0
    assert (out / "c" / "compare.png").is_file()


def _metrics(seed: int, rms_mm: float, how: str) -> RunMetrics:
    """A finished run's metrics.json, as much of it as the sweep plots read, read."""
    phase = {"start_s": 12.5, "end_s": 25.0, "rms_position_error_m": rms_mm / 1e3}
    return RunMetrics.from_json({
        "status": "ok", "outcome": how, "seed": seed, "T": 0.01, "excluded_s": [0.0, 2.0],
        "scenario": "s", "controller": "c", "steps": 2500,
        "phases": {"before": phase | {"start_s": 2.0, "end_s": 12.5}, "after": phase},
        "position_ms_bins": {"bin_steps": 10, "m2": [(rms_mm / 1e3) ** 2] * 250},
    })  # fmt: skip


def test_the_plots_median_is_the_tables_over_the_same_finished_runs():
    """A lost run is in the table's statistics (over the finished runs): the plot takes it too."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mlpfac.plots import sweeps
    from mlpfac.sweeps.paired import median

    rms = [1.0, 2.0, 3.0, 400.0, 500.0]  # mm; the last two lost
    runs = {("s", "c"): [_metrics(i, x, "lost" if x > 100 else "tracking") for i, x in enumerate(rms)]}
    fig, ax = plt.subplots()
    sweeps._distribution(ax, "s", ["c"], runs, {"c": "C0"})
    label = ax.get_yticklabels()[0].get_text()
    plt.close(fig)
    assert f"5/5  median {median(rms):.3g}" in label, label  # 3, not the tracking runs' 2


@pytest.mark.parametrize(("lo", "hi"), [(0.7, 30.0), (0.5, 2500.0), (20.0, 60.0), (12.0, 130.0)])
def test_log_axis_labels_do_not_overlap(lo: float, hi: float):
    """On a narrow axis matplotlib's own labels of 12-130 overlap (2x10^1, 3x10^1, ... beside 10^2)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mlpfac.plots.sweeps import log_ticks

    fig, ax = plt.subplots(figsize=(3.0, 3))
    ax.scatter([lo, hi], [0, 1])
    ax.set_xscale("log")
    log_ticks(ax.xaxis, lo, hi)
    fig.canvas.draw()
    r, (x0, x1) = fig.canvas.get_renderer(), ax.get_xlim()
    labels = [
        t
        for t in ax.get_xticklabels(which="both")
        if t.get_text() and t.get_visible() and x0 <= t.get_position()[0] <= x1
    ]
    boxes = sorted((t.get_window_extent(r) for t in labels), key=lambda b: b.x0)
    plt.close(fig)
    texts = [t.get_text() for t in labels]
    assert len(boxes) >= 2 and all("times" not in t for t in texts), texts  # plain numbers
    assert all(a.x1 < b.x0 for a, b in zip(boxes[:-1], boxes[1:], strict=True)), texts


def test_figure1_says_the_outcome_metrics_json_records_and_draws_the_world_and_the_belief():
    """The title and panel (h) say tracking / lost / diverged (never "ok"), as the run's first line
    does; a world's ramps and patches, the believed path of an odometry run, the events and a
    force's stretch are drawn on the paths' panels; every legend sits above the panels, none on them."""
    from matplotlib.patches import Circle, Polygon

    from mlpfac.loop.metrics import metrics, outcome_words
    from mlpfac.plots.figure1 import Draft

    lost = run(load("eight-wheel-radius-odometry").with_overrides(controller="kanayama", duration=16.0))
    base = run(load("eight-wheel-radius-odometry").with_overrides(controller="corradini", duration=16.0))
    draft = Draft(lost, True).complete(base)
    title = draft.fig._suptitle.get_text()
    assert metrics(lost)["outcome"] == "lost" and title.endswith(outcome_words(metrics(lost))), title
    assert draft.axes["h"].get_title().endswith(f"({metrics(base)['outcome']})")
    assert "ok" not in title.split() and "(ok)" not in draft.axes["h"].get_title()
    dashed = [ln for ln in draft.paths["e"].get_lines() if ln.get_linestyle() == "--"]
    assert len(dashed) == 1 and len(dashed[0].get_xdata()) > 1000  # the believed path
    labels = [t.get_text() for t in draft.fig.legends[0].get_texts()]
    assert "believed (odometry)" in labels and any(x.startswith("event: ") for x in labels), labels
    assert all(ax.get_legend() is None for ax in [*draft.paths.values(), draft.axes["a"]])
    world = {}
    for name in ("eight-ramp", "eight-wet-patch"):
        rec = run(load(name).with_overrides(controller="kanayama", duration=5.0))
        world[name] = Draft(rec, False).paths["e"].patches
    assert sum(isinstance(p, Polygon) for p in world["eight-ramp"]) == 2
    assert sum(isinstance(p, Circle) for p in world["eight-wet-patch"]) == 1
    push = run(load("eight-push").with_overrides(controller="kanayama", duration=13.5))
    thick = [ln for ln in Draft(push, False).paths["e"].get_lines() if ln.get_linewidth() == 3.0]
    assert len(thick) == 1 and 15 <= len(thick[0].get_xdata()) <= 25  # 0.2 s of push at T = 0.01 s
