"""Your own path and your own reference class (mlpfac.scenario.path, .timing, .waypoints,
.own_reference): known answers of the curve and its timing, the limits along the whole profile,
the rates against finite differences, CSV files, runs and sweeps, and a reference that stops being
finite mid-run."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path as FilePath

import numpy as np
import pytest

import mlpfac
from mlpfac.exceptions import ConfigError
from mlpfac.scenario.parse import load, parse
from mlpfac.scenario.path import CORNER_D, Path
from mlpfac.scenario.reference import make_reference, sample_rates
from mlpfac.scenario.waypoints import read_csv

REPO = FilePath(__file__).resolve().parents[1]
SQUARE = ((0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (0.0, 4.0))
WHEELS = {"v_max": 1.0, "omega_max": 2.5, "a_max": 1.0, "alpha_max": 7.0, "track": 0.28}
ROUTE_CSV = "x,y\n0,0\n5,0\n5,3\n2,3\n2,6\n7,6\n"  # right angles, an open route
OURS = 'T = 0.01\n[plant]\nkind = "mujoco"\nmodel = "{model}"\nactuator = "velocity"\npose_noise_std = 0.001\n'


def dense(p: Path, n: int = 200_001, laps: float = 1.0) -> np.ndarray:
    return p.rows(np.linspace(0.0, laps * p.duration, n))


def test_a_straight_path_is_driven_at_its_speed_limit_along_its_line():
    """Two waypoints: v = v_max all along, omega and the rates 0 (to the rounding of control points
    on a slanted line), theta the line's heading; after its end it goes on along the same line."""
    p = Path(((1.0, 2.0), (4.0, 6.0)), v_max=0.8)
    assert p.geometry.length == pytest.approx(5.0, rel=1e-12)
    assert p.duration == pytest.approx(5.0 / 0.8, rel=1e-12)
    r = p.rows(np.linspace(0.0, 2 * p.duration, 1001))
    assert np.all(r[:, 3] == 0.8) and np.abs(r[:, 4:7]).max() < 1e-12
    np.testing.assert_allclose(r[:, 2], math.atan2(4.0, 3.0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(r[:, 0], 1.0 + 0.6 * 0.8 * np.linspace(0.0, 2 * p.duration, 1001), atol=1e-9)


def test_a_right_angles_corner_has_the_radius_asked_and_the_legs_are_straight():
    p = Path(SQUARE, closed=True, radius=0.25, **WHEELS)
    g = p.geometry
    kappa = np.abs(g.kappa)
    assert kappa.max() == pytest.approx(1 / 0.25, rel=1e-9)  # at the middle of each corner, a grid point
    d = CORNER_D * 0.25  # the curve leaves each leg (K - 1) d / 2 = 2 d before its waypoint
    r = dense(p, 100_001)
    on_leg = (np.abs(r[:, 1]) < 1e-12) & (r[:, 0] > 2 * d + 1e-6) & (r[:, 0] < 6.0 - 2 * d - 1e-6)
    assert on_leg.sum() > 1000 and np.all(r[on_leg, 4] == 0.0) and np.all(np.abs(r[on_leg, 2]) < 1e-12)
    # the corner keeps within a third of d of its waypoint (the curve's closest point: its middle)
    near = np.min(np.hypot(r[:, 0] - 6.0, r[:, 1]))
    assert near == pytest.approx(0.2333333 * d * math.sqrt(2), rel=1e-5)


def test_a_short_leg_takes_a_tighter_corner():
    """A corner takes at most a quarter... of either leg (1 / (2 (K - 1)) of it): between waypoints 1 m
    apart, a right angle asked 0.3 m gets 1 / 8 / CORNER_D m."""
    p = Path(((0.0, 0.0), (3.0, 0.0), (3.0, 1.0), (6.0, 1.0)), radius=0.3, **WHEELS)
    assert np.abs(p.geometry.kappa).max() == pytest.approx(CORNER_D / (1.0 / 8.0), rel=1e-9)


@pytest.mark.parametrize("closed", [False, True])
def test_the_wheels_keep_their_limits_along_the_whole_profile(closed):
    """Each wheel's rim speed |v| + |omega| b / 2 and acceleration |dv| + |domega| b / 2, |omega| and
    |domega|, sampled 200001 times: within the limits (at every grid point exactly; between two by
    at most 0.2 %), and each reached."""
    pts = ((0.0, 0.0), (5.0, 0.0), (6.0, 2.0), (3.0, 4.0), (3.0, 1.5), (0.5, 3.0))
    p = Path(pts, closed=closed, **WHEELS)
    r = dense(p)
    h = WHEELS["track"] / 2
    rim, acc = r[:, 3] + np.abs(r[:, 4]) * h, np.abs(r[:, 5]) + np.abs(r[:, 6]) * h
    for value, limit in ((rim, 1.0), (np.abs(r[:, 4]), 2.5), (acc, 1.0), (np.abs(r[:, 6]), 7.0)):
        assert value.max() <= limit * 1.002 and value.max() >= limit * 0.99
    assert r[:, 3].min() > 0.1  # v_r > 0 throughout
    g = p.geometry
    at = p.rows(g.t[:-1])  # the grid points
    assert (at[:, 3] + np.abs(at[:, 4]) * h).max() <= 1.0 + 1e-12
    assert (np.abs(at[:, 5]) + np.abs(at[:, 6]) * h).max() <= 1.0 + 1e-9


def test_the_rates_are_the_derivatives_of_v_and_omega_and_the_pose_moves_as_v_and_omega_say():
    p = Path(SQUARE, closed=True, **WHEELS)
    t = np.linspace(0.3, p.duration - 0.3, 400)
    h = 1e-6
    r, ahead, back = p.rows(t), p.rows(t + h), p.rows(t - h)
    cells = np.searchsorted(p.geometry.t, t - h) == np.searchsorted(p.geometry.t, t + h)  # dv is constant in a cell
    assert cells.sum() > 390
    np.testing.assert_allclose((ahead[cells, 3] - back[cells, 3]) / (2 * h), r[cells, 5], atol=1e-6)
    np.testing.assert_allclose((ahead[cells, 4] - back[cells, 4]) / (2 * h), r[cells, 6], rtol=1e-5, atol=1e-5)
    speed = np.hypot(ahead[:, 0] - back[:, 0], ahead[:, 1] - back[:, 1]) / (2 * h)
    np.testing.assert_allclose(speed, r[:, 3], rtol=1e-6)  # the arc length is the curve's, to the quadrature
    np.testing.assert_allclose((ahead[:, 2] - back[:, 2]) / (2 * h), r[:, 4], rtol=1e-5, atol=1e-5)


def test_a_closed_route_loops_and_its_heading_goes_on_turning():
    p = Path(SQUARE, closed=True, **WHEELS)
    t = np.linspace(0.0, p.duration, 501)
    one, two = p.rows(t), p.rows(t + p.duration)
    np.testing.assert_allclose(two[:, [0, 1, 3, 4, 5, 6]], one[:, [0, 1, 3, 4, 5, 6]], atol=1e-9)
    np.testing.assert_allclose(two[:, 2], one[:, 2] + 2 * math.pi, atol=1e-9)
    far = p.rows(np.array([0.0, 0.5 * p.duration, 3.5 * p.duration]))  # few samples: theta continuous all the same
    assert far[2, 2] == pytest.approx(far[1, 2] + 3 * 2 * math.pi, abs=1e-9)


def test_speed_runs_the_same_path_faster():
    slow = make_reference("path", {"points": [list(q) for q in SQUARE], "closed": True})
    fast = make_reference("path", {"points": [list(q) for q in SQUARE], "closed": True, "speed": 2.0})
    t = np.linspace(0.0, 10.0, 101)
    a, b = slow.rows(t), fast.rows(t / 2.0)
    np.testing.assert_array_equal(b[:, :3], a[:, :3])
    np.testing.assert_array_equal(b[:, 3:5], 2.0 * a[:, 3:5])
    np.testing.assert_array_equal(b[:, 5:7], 4.0 * a[:, 5:7])


def test_unset_limits_are_a_share_of_the_controllers():
    p = make_reference("path", {"points": [[0, 0], [1, 0]]}, limits=(1.2, 3.0))
    assert (p.v_max, p.omega_max, p.a_max, p.alpha_max, p.track) == (0.6, 1.5, 0.6, 1.5, 0.0)


@pytest.mark.parametrize(
    "text",
    [
        "0,0\n2,0\n2,1\n",
        "x,y\n0,0\n2,0\n2,1\n",
        "# a route\n\nid, y, x\n0, 0, 0\n1, 0, 2\n2, 1, 2\n",
        "0 0\n2 0\n2 1\n",
        '\ufeff"x";"y"\n0;0\n2;0\n2;1\n',
    ],
    ids=["bare", "header", "comment and columns named", "spaces", "bom and quotes"],
)
def test_a_csv_file_with_or_without_a_header(tmp_path, text):
    f = tmp_path / "r.csv"
    f.write_text(text, encoding="utf-8")
    points, lines, sha = read_csv(f, "file")
    assert points == [(0.0, 0.0), (2.0, 0.0), (2.0, 1.0)] and len(sha) == 64
    assert all(f"{f} line " in line for line in lines)


def test_the_users_csv_route_of_right_angles_is_tracked_by_kanayama_within_10_mm(tmp_path):
    """The route given as a CSV file beside the scenario, on our robot: position RMS <= 10 mm;
    config.toml records the file's digest, re-runs it to the bit, and refuses it once changed."""
    (tmp_path / "route.csv").write_text(ROUTE_CSV)
    scn_file = tmp_path / "mine.toml"
    model = REPO / "models" / "scene.xml"
    scn_file.write_text(
        OURS.format(model=model) + '[reference]\nkind = "path"\nfile = "route.csv"\n[controller]\nname = "kanayama"\n'
    )
    out = tmp_path / "out"
    rec = mlpfac.run(str(scn_file), out=str(out))
    m = json.loads((out / "metrics.json").read_text())
    assert rec.status == "ok" and m["rms_position_error_m"] <= 0.010, m["rms_position_error_m"]
    config = tomllib.loads((out / "config.toml").read_text())
    assert config["provenance"]["reference"]["file"] == str(tmp_path / "route.csv")
    assert "duration" not in config  # the route once: its time, computed again from the file
    again = mlpfac.run(str(out / "config.toml"))
    assert np.array_equal(again.pose, rec.pose, equal_nan=True)
    (tmp_path / "route.csv").write_text(ROUTE_CSV + "7,9\n")
    with pytest.raises(ConfigError, match=r"\[provenance\] reference"):
        load(out / "config.toml")


def test_an_open_route_lasts_its_time_unless_the_file_says(tmp_path):
    table = {"reference": {"kind": "path", "points": [[0, 0], [3, 0], [3, 2]]}, "plant": {"kind": "kinematic"}}
    scn = parse(table)
    assert scn.duration == pytest.approx(scn.reference.duration, abs=0.01) and scn.duration >= scn.reference.duration
    assert parse(table | {"duration": 30.0}).duration == 30.0


def test_the_shipped_routes_run_on_every_kind_of_plant():
    for name in ("route", "lane-change"):
        scn = load(name).with_overrides(controller="kanayama", duration=3.0)
        assert "reference_fit" in scn.table["provenance"]
        rec = mlpfac.run(scn)
        assert rec.status == "ok" and np.nanmax(np.abs(rec.e[:, :2])) < 0.01
    torque = load("route", robot="diffdrive-torque").with_overrides(controller="fierro-lewis", duration=3.0)
    assert mlpfac.run(torque).status == "ok"


def test_a_torque_level_controller_is_given_the_paths_own_rates():
    from mlpfac.loop.closed_loop import ClosedLoop
    from mlpfac.loop.runner import build

    scn = load("route", robot="diffdrive-torque").with_overrides(controller="fierro-lewis", duration=2.0)
    b = build(scn)
    loop = ClosedLoop([scn], b.ref, b.plant, b.ctrl, True, False, b.rates, b.end)
    _, rates = sample_rates(scn.reference, np.arange(scn.steps + 1) * scn.T)
    assert np.array_equal(loop.r_dot, rates) and np.any(rates != 0.0)


@pytest.mark.menagerie
def test_the_route_on_tiago():
    scn = load("route", robot="pal_tiago").with_overrides(controller="kanayama", duration=10.0)
    rec = mlpfac.run(scn)
    assert rec.status == "ok" and mlpfac.metrics(rec)["rms_position_error_m"] < 0.005


ELLIPSE = REPO / "examples" / "my_route.py"
OWN = 'duration = 3.0\n[plant]\nkind = "kinematic"\n[reference]\nkind = "{kind}"\n[reference.params]\n{params}\n'
LATE = '''
class Late:
    """A straight line at 0.5 m/s, until ``when``: then NaN, or an exception."""

    def __init__(self, when=1.0, how="nan"):
        self.when, self.how = when, how

    def sample(self, t):
        if t >= self.when:
            if self.how == "raise":
                raise ValueError("off the map")
            return ("seven", "words") if self.how == "words" else (float("nan"),) * 7
        return (0.5 * t, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0)
'''


def _own(tmp_path: FilePath, kind: str = "my_route.py:Ellipse", params: str = "a = 2.0") -> FilePath:
    (tmp_path / "my_route.py").write_text(ELLIPSE.read_text())
    (tmp_path / "late.py").write_text(LATE)
    f = tmp_path / "own.toml"
    f.write_text(OWN.format(kind=kind, params=params))
    return f


def test_a_reference_class_runs_in_run_and_sweep_batched_or_not(tmp_path):
    f = _own(tmp_path)
    scn = load(f)
    assert scn.table["provenance"]["reference"]["origin"] == "file"
    ref, rates = sample_rates(scn.reference, np.arange(301) * 0.01)
    t = np.arange(301) * 0.01
    np.testing.assert_allclose(np.gradient(ref[:, 3], t)[1:-1], rates[1:-1, 0], atol=1e-4)
    np.testing.assert_allclose(np.gradient(ref[:, 4], t)[1:-1], rates[1:-1, 1], atol=1e-4)
    rec = mlpfac.run(scn.with_overrides(controller="kanayama"))
    assert rec.status == "ok" and mlpfac.metrics(rec)["rms_position_error_m"] < 0.02  # the kinematic model's noise
    args = ["sweep", str(f), "--controllers", "kanayama,corradini", "--seeds", "0-1", "--workers", "1"]
    args += ["--vary", "reference.params.b=0.5:1.5:2"]
    one = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", *args, "--out", "a"], cwd=tmp_path, capture_output=True, text=True
    )
    two = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", *args, "--out", "b", "--batched"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert one.returncode == 0 and two.returncode == 0, one.stderr + two.stderr
    rows = [json.loads((tmp_path / d / "sweep.json").read_text())["rows"] for d in ("a", "b")]
    assert len(rows[0]) == 4 and {r["vary"]["reference.params.b"] for r in rows[0]} == {0.5, 1.5}
    assert [r["pos_rms_m_mean"] for r in rows[0]] == [r["pos_rms_m_mean"] for r in rows[1]]  # batched: the same bits


@pytest.mark.parametrize(
    "how, says",
    [
        ("nan", "late.py:Late: sample(1) returned a value that is not finite"),
        ("raise", "late.py:Late: sample(1) raised ValueError: off the map (late.py, line"),
        ("words", "late.py:Late: sample(1) returned ('seven', 'words'), not seven numbers"),
    ],
)
def test_a_reference_that_stops_being_finite_ends_the_run_there(tmp_path, how, says):
    f = _own(tmp_path, "late.py:Late", f'how = "{how}"')
    for controller in ("kanayama", "corradini"):
        rec = mlpfac.run(load(f).with_overrides(controller=controller))
        assert rec.status == "diverged" and says in rec.reason and rec.reason.endswith("at t = 1.00 s")
        assert "own_reference.py" not in rec.reason and ("raised" in rec.reason) == (how == "raise")  # their file
        assert rec.n == 100 and np.all(np.isfinite(rec.pose[:100]))
    mlpfac.sweep([str(f)], ["kanayama"], seeds="0-1", batched=True, out=tmp_path / "sw")
    found = [json.loads(m.read_text()) for m in sorted((tmp_path / "sw").glob("own/kanayama/seed-*/metrics.json"))]
    assert [m["outcome"] for m in found] == ["diverged", "diverged"] and says in found[0]["reason"]


def test_the_route_on_a_users_own_diff_drive_mjcf(tmp_path):
    """``--robot cart.xml``: a robot of the user's, its parts found in its model; the path timed for it."""
    from test_own_robots import cart

    (tmp_path / "cart.xml").write_text(cart(("left", "right")))
    scn = load("route", robot=str(tmp_path / "cart.xml")).with_overrides(controller="kanayama", duration=12.0)
    assert scn.reference.track == pytest.approx(0.32) and "path timed within 0.5" in scn.description
    rec = mlpfac.run(scn)
    assert rec.status == "ok" and mlpfac.metrics(rec)["rms_position_error_m"] < 0.01


def test_mlpfac_list_names_the_routes(capsys):
    from mlpfac.cli import main

    assert main(["list"]) == 0
    names = [line.split()[0] for line in capsys.readouterr().out.splitlines() if line and not line.startswith(" ")]
    assert "route" in names and "lane-change" in names


def test_a_paths_numbers_vary_and_are_drawn_as_any_other(tmp_path):
    """``--vary reference.speed`` an axis (its breaking point in robustness.json), a waypoint moved by its
    dotted key, and ``reference.radius`` drawn per seed (recorded in [drawn])."""
    mlpfac.sweep(
        ["route"], ["kanayama"], seeds="0", duration=4.0, vary={"reference.speed": [1.0, 3.0]}, out=tmp_path / "a"
    )
    rob = json.loads((tmp_path / "a" / "robustness.json").read_text())
    assert "reference.speed" in json.dumps(rob) and (tmp_path / "a" / "robustness.png").exists()
    moved = load("route", values={"reference.points.1.0": 5.0})
    assert moved.reference.points[1] == (5.0, 0.0)
    drawn = [load("route", values={"reference.radius": {"uniform": [0.1, 0.4]}, "seed": s}) for s in (0, 1)]
    radii = [d.reference.radius for d in drawn]
    assert radii[0] != radii[1] and all(0.1 <= r <= 0.4 for r in radii)
    assert drawn[0].table["drawn"]["reference.radius"] == radii[0]


def test_a_path_put_on_a_robot_says_its_new_timing_after_the_files_words_with_their_stop(tmp_path, capsys):
    """--robot retimes a path: the run says so under its outcome (the path's time once along it, and as
    the file times it), and the description joins the robot's sentence to the file's with its stop."""
    from mlpfac.cli import main

    f = tmp_path / "mine.toml"
    f.write_text('description = "A corridor from 5 s"\nduration = 3.0\n[reference]\nkind = "path"\n'
                 "points = [[0, 0], [4, 0], [4, 3]]\n[plant]\nkind = \"kinematic\"\n")  # fmt: skip
    scn = load(f, robot="cart")
    assert scn.description.startswith("A corridor from 5 s. On cart: path timed within 0.5 of the wheels' limits")
    fit = scn.table["provenance"]["reference_fit"]
    assert ": once along it takes " in fit and " s as the file times it)" in fit
    assert main(["run", str(f), "--robot", "cart", "--controller", "kanayama", "--no-log", "--no-plot",
                 "--out", str(tmp_path / "o")]) == 0  # fmt: skip
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("mine+cart / kanayama / seed 0: ") and f"  reference: {fit}" in lines
