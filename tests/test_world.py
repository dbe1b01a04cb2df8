"""The world around the robot: slopes, forces, ramps, rough ground and floor patches (issue 46).

Known answers (a robot held on a slope by the force that cancels gravity's pull; the force applied
is its schedule; a ramp's height along the path; the patch's friction under a tyre), the rough
ground drawn per seed, the compiled loop against the step-by-step one to the bit, config.toml
re-runs to the bit, the oracle told the world's load, and the recording's terrain and arrows.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

import mlpfac
from mlpfac.loop.runner import build, run
from mlpfac.plants import make_plant
from mlpfac.plants.events import Force, Slope
from mlpfac.plants.world.forces import event_step, force_schedule, in_newtons_all
from mlpfac.scenario.parse import load, parse
from mlpfac.scenario.reference import sample


def _scenario(name: str, duration: float, controller: str = "kanayama", **values):
    return load(name, values=values or None).with_overrides(controller=controller, duration=duration)


def _same(a, b) -> bool:
    arrays = [("pose", a.pose, b.pose), ("u", a.u, b.u), ("e_true", a.e_true, b.e_true)]
    arrays += [(k, a.plant[k], b.plant[k]) for k in a.plant]
    return all(np.array_equal(x, y, equal_nan=True) for _, x, y in arrays) and a.n == b.n


def test_a_robot_held_on_a_slope_by_the_force_that_cancels_gravity_stays_put():
    """On torque motors at zero torque (free wheels) the robot rolls down a 10 deg slope; pushed
    uphill at its root body's centre of mass with m g sin(10 deg) it stays where it is."""
    table = copy.deepcopy(load("eight-torque", build=False).table)
    table["controller"] = {"name": "fierro-lewis"}
    scn = parse(table, "held")
    plant = make_plant(scn, sample(scn.reference, np.arange(2) * scn.T))
    mass = float(plant.robot.model.body_subtreemass[plant._root])
    g = float(np.sqrt(np.sum(plant.robot.model.opt.gravity**2)))
    slope = Slope(time=0.0, angle_deg=10.0, heading_deg=0.0)
    pull = mass * math.sqrt(slope.gravity(g)[0] ** 2 + slope.gravity(g)[1] ** 2)
    moved = {}
    for force in (0.0, pull):
        events = (slope, Force(time=0.0, fx=force, frame="world"))
        plant.set_world(None, events, 400)
        plant.reset(np.zeros(3), np.random.default_rng(0))
        for ev in events:
            plant.apply(ev)
        for _ in range(200):  # 2 s at zero torque
            plant.step(np.zeros(2))
        moved[force] = float(np.hypot(*plant.true_pose()[:2]))
    assert moved[0.0] > 0.5  # it rolls downhill
    assert moved[pull] < 1e-3  # held


@pytest.mark.parametrize(
    "force",
    [
        {"fx": 7.0, "frame": "world", "duration": 0.3},
        {"fy": 4.0, "torque_z": 0.5, "frame": "robot"},
        {"fx": 3.0, "fy": -2.0, "period": 0.5},
        {"fy": 1.0, "std": 6.0, "frame": "robot"},
        {"fx_mg": 0.1, "frame": "robot"},
        {"dv_y": 0.5, "fx": 1.0, "duration": 0.3, "frame": "robot"},
        {"std_mg": 0.05, "tau_s": 0.5},
    ],
)
def test_the_force_applied_is_the_schedule(force):
    """What the plant applies is the schedule of the force in newtons: a share of the weight times
    m g (m the mass config.toml records, g 9.81), a push's velocity change times m over its duration."""
    scn = _scenario("eight-push", 2.0)
    scn = mlpfac.parse({**scn.table, "events": [{"time": 0.5, "kind": "force", **force}]}, "f")
    rec = run(scn)
    m, g = scn.table["provenance"]["mass_kg"], 9.81
    newtons = {
        "fx": force.get("fx", force.get("fx_mg", 0.0) * m * g),
        "fy": force.get("fy", force.get("dv_y", 0.0) * m / 0.3),
        "std": force.get("std", force.get("std_mg", 0.0) * m * g),
    }
    (told,) = in_newtons_all(scn.events, m, g, scn.T)
    assert [told.fx or 0.0, told.fy or 0.0, told.std or 0.0] == [pytest.approx(v, rel=1e-15) for v in newtons.values()]
    sched = force_schedule((told,), scn.T, scn.steps, scn.seed)
    c, s = np.cos(rec.pose[:, 2]), np.sin(rec.pose[:, 2])
    want = np.c_[
        sched[:, 0] + c * sched[:, 2] - s * sched[:, 3], sched[:, 1] + s * sched[:, 2] + c * sched[:, 3], sched[:, 4]
    ]
    np.testing.assert_allclose(rec.plant["force"], want, rtol=0, atol=1e-12)
    k0 = event_step(0.5, scn.T)
    assert not np.any(rec.plant["force"][:k0]) and np.any(rec.plant["force"][k0 : k0 + 2])  # (a sine starts at 0)
    if "duration" in force:  # a push ends
        assert not np.any(rec.plant["force"][k0 + 30 :]) and np.all(rec.plant["force"][k0 : k0 + 30, 0] != 0.0)
    if "std" in force:  # noise of its own stream: the seed's, the same again
        assert np.std(sched[k0:, 3]) == pytest.approx(6.0, rel=0.15)
        np.testing.assert_array_equal(sched, force_schedule(scn.events, scn.T, scn.steps, scn.seed))
        assert not np.array_equal(sched, force_schedule(scn.events, scn.T, scn.steps, scn.seed + 1))


def test_a_gust_is_a_gauss_markov_process_of_the_white_noises_draws():
    """With tau_s, the same standard normals (the force's own stream) drive x' = a x + std sqrt(1 - a^2) w
    from x_0 = std w_0: its first step is the white noise's, each next one that recursion; its lag-j
    autocorrelation is a^j and its standard deviation std (10 000 s of it)."""
    T, n, std, tau = 0.01, 1_000_000, 3.0, 0.5
    white = force_schedule((Force(time=0.0, std=std),), T, n, 7)[:, :2]
    gust = force_schedule((Force(time=0.0, std=std, tau_s=tau),), T, n, 7)[:, :2]
    a = math.exp(-T / tau)
    assert np.array_equal(gust[0], white[0])
    np.testing.assert_allclose(gust[1:50], a * gust[:49] + math.sqrt(1 - a * a) * white[1:50], rtol=0, atol=1e-13)
    assert np.std(gust) == pytest.approx(std, rel=0.03)
    for j in (1, 10, 50):
        r = np.mean(gust[j:] * gust[:-j]) / np.mean(gust * gust)
        assert r == pytest.approx(a**j, abs=0.02)
    assert abs(np.mean(white[1:] * white[:-1])) / np.mean(white * white) < 0.01  # white: no memory


def test_the_rough_ground_is_drawn_per_seed():
    a, b, c = (load("eight-bumps", build=False).with_overrides(seed=s) for s in (0, 0, 1))
    assert a.terrain.digest == b.terrain.digest and a.terrain.digest != c.terrain.digest
    np.testing.assert_array_equal(a.terrain.grid, b.terrain.grid)
    assert a.table["drawn"]["world.bumps"] == f"sha256:{a.terrain.digest}"
    grid = a.terrain.grid
    assert grid.min() == 0.0 and 0.8 * 0.01 < grid.max() < 0.01  # heights in [0, height)
    shorter = load("eight-bumps", build=False, values={"world.over": 8.0})  # a smaller arena, the same ground
    assert shorter.terrain.digest == a.terrain.digest and shorter.terrain.grid.shape != grid.shape
    p = np.array(shorter.terrain.arena[:2]) + 0.7
    assert shorter.terrain.height(*p) == a.terrain.height(*p)
    assert a.terrain.height(*a.terrain.start) == 0.0  # the robot starts on the flat pad
    # the surface between the grid's points is the heightfield's to within the bilinear's error
    x0, y0 = a.terrain.arena[:2]
    dx, dy = a.terrain.cell
    i, j = 40, 57
    assert a.terrain.height(x0 + j * dx, y0 + i * dy) == grid[i, j]


def test_a_ramp_lies_where_the_path_has_gone_its_share():
    scn = load("eight-ramp", build=False)
    ref = sample(scn.reference, np.arange(scn.steps + 1) * scn.T)
    d = np.diff(ref[:, :2], axis=0)
    s = np.concatenate([[0.0], np.cumsum(np.sqrt(np.sum(d * d, axis=1)))])
    for ramp, placed in zip(scn.world.ramps, scn.terrain.ramps, strict=True):
        k = int(np.argmin(np.abs(s - ramp.at * s[-1])))
        assert np.hypot(placed.x - ref[k, 0], placed.y - ref[k, 1]) < 0.01  # its foot on the path, at its share
        along = np.array([placed.c, placed.s])
        foot = np.array([placed.x, placed.y])
        h = scn.terrain.height
        assert h(*(foot - 0.01 * along)) == 0.0
        assert h(*(foot + 0.5 * placed.up * along)) == pytest.approx(0.5 * ramp.height, rel=1e-9)
        assert h(*(foot + (placed.up + 0.5 * placed.top) * along)) == ramp.height
        assert h(*(foot + (placed.up + placed.top + 0.5 * placed.down) * along)) == pytest.approx(0.5 * ramp.height)


def test_a_tyre_on_a_patch_slides_on_its_friction():
    scn = _scenario("eight-wet-patch", 1.0)
    b = build(scn)
    p, patch = b.plant, scn.world.patches[0]
    p.reset(np.array([patch.x, patch.y, 0.0]), np.random.default_rng(0))
    p.step(np.zeros(2))
    assert [float(p.model.geom_friction[g, 0]) for g in p._tyres] == [patch.mu] * 2
    p.reset(np.array([2.0, 0.0, np.pi / 2]), np.random.default_rng(0))
    p.step(np.zeros(2))
    assert [float(p.model.geom_friction[g, 0]) for g in p._tyres] == [1.0, 1.0]


@pytest.mark.parametrize("name", ["eight-bumps", "eight-ramp", "eight-push", "eight-slope", "eight-wet-patch"])
def test_compiled_loop_and_step_by_step_give_the_same_bits(name):
    scn = _scenario(name, 14.0)
    compiled, stepped = run(scn), run(scn, on_step=lambda k: None)
    assert compiled.status == "ok" and _same(compiled, stepped)


def test_config_toml_runs_again_to_the_bit(tmp_path):
    out = tmp_path / "first"
    mlpfac.run("eight-bumps", controller="kanayama", seed=2, duration=3.0, out=out)
    again = mlpfac.run(str(out / "config.toml"))
    first = mlpfac.run("eight-bumps", controller="kanayama", seed=2, duration=3.0)
    assert _same(first, again)
    assert "world.bumps" in (out / "config.toml").read_text()


def test_on_rough_ground_the_robot_stands_on_it_and_is_not_lifted():
    """Reset off the start's pad, the robot is put on the ground (not in it) and rests there."""
    scn = _scenario("eight-bumps", 3.0)
    p = build(scn).plant
    p.reset(np.array([0.0, 1.2, 0.3]), np.random.default_rng(0))
    for _ in range(100):
        p.step(np.zeros(2))
        assert p.diverged() is None
    site = p.data.site_xpos[p._site]
    rest = p.robot.site_rest[0][2]
    assert abs(site[2] - p.ground(site[0], site[1]) - rest) < 0.003


def test_oracle_dynamic_is_told_the_load():
    from mlpfac.control.dynamic import Told

    slope = Slope(time=1.0, angle_deg=10.0, heading_deg=90.0)
    gx, gy, _ = slope.gravity(9.81)
    told = Told([(1.0, gx, gy)], (Force(time=0.0, fx=2.0, frame="robot"),), 200)
    told.reset([np.random.default_rng(np.random.SeedSequence(0))], 0.01)
    model = type("M", (), {"mass_kg": 5.0, "com_offset_m": 0.1})()
    heading_uphill = np.array([[0.0, 0.0, np.pi / 2]])
    assert told.loads(0, heading_uphill, model) == [pytest.approx((2.0, 0.0))]  # the tow alone
    fv, fw = told.loads(100, heading_uphill, model)[0]  # gravity pulls it back down the slope
    assert fv == pytest.approx(2.0 - 5.0 * 9.81 * math.sin(math.radians(10.0)), rel=1e-12) and fw == pytest.approx(0.0)


def test_oracle_dynamic_told_the_slope_beats_fierro_lewis():
    """The bound covers the slope: told it, the same backstepping keeps its error (diffdrive-torque, 10 deg)."""
    after = {}
    for c in ("fierro-lewis", "oracle-dynamic"):
        scn = load("eight-slope", robot="diffdrive-torque", values={"events.0.angle_deg": 10.0, "events.0.time": 4.0})
        rec = run(scn.with_overrides(controller=c, duration=9.0))
        e = np.hypot(rec.e_true[500:, 0], rec.e_true[500:, 1])
        after[c] = float(np.sqrt(np.mean(e * e)))
    assert after["oracle-dynamic"] < 0.8 * after["fierro-lewis"]


def test_the_recording_holds_the_terrain_and_the_force(tmp_path, rrd_contents):
    from mlpfac import log

    scn = _scenario("eight-push", 13.0)
    run(scn, sink=log.make_sink(save=tmp_path / "push.rrd", recording_id="push"))
    ents = rrd_contents(tmp_path / "push.rrd")
    arrows = ents["/world/force"].temporal["Arrows3D:vectors"]
    counts = np.array([len(row) for row in arrows.values.to_pylist()])
    steps = np.asarray(arrows.times["step"])
    k0 = event_step(12.5, scn.T)
    assert np.all(counts[(steps >= k0) & (steps < k0 + 20)] == 1) and np.all(counts[steps < k0] == 0)
    assert np.all(counts[steps >= k0 + 20] == 0)  # the push ended
    assert "/forces/fy" in ents
    scn = _scenario("eight-bumps", 1.0)
    run(scn, sink=log.make_sink(save=tmp_path / "bumps.rrd", recording_id="bumps"))
    mesh = rrd_contents(tmp_path / "bumps.rrd")["/world/terrain/bumps"].static
    assert len(mesh["Mesh3D:vertex_positions"].to_pylist()[0]) == scn.terrain.grid.size


def test_a_shorter_run_drives_into_the_same_world():
    """--duration keeps the world laid out along the file's run (its config.toml says so)."""
    full = load("eight-ramp", build=False)
    short = full.with_overrides(duration=0.3)
    assert short.table["world"]["over"] == 25.0
    assert [vars(r) for r in short.terrain.ramps] == [vars(r) for r in full.terrain.ramps]
    assert short.terrain.arena == full.terrain.arena


@pytest.mark.parametrize(
    ("name", "axis"), [("eight-tow", "events.0.fx_mg=-0.8:0:3"), ("eight-slope", "events.0.angle_deg=0:30:3")]
)
def test_the_slope_and_the_force_are_axes_with_breaking_points(tmp_path, name, axis):
    import json

    mlpfac.sweep([name], ["kanayama"], seeds="0", duration=16.0, vary=[axis], out=tmp_path, workers=1)
    points = json.loads((tmp_path / "robustness.json").read_text())["breaking_points"]
    key, _ = axis.split("=")
    (point,) = [p for p in points if p["axis"] == key]
    assert point["below"]["fails_at"] == -0.8 if name == "eight-tow" else point["above"]["fails_at"] == 30.0
    assert (tmp_path / "robustness.png").is_file() and (tmp_path / "robustness.md").is_file()
