"""Forces and kerbs that fit any robot: a force given as a share of the robot's weight or a push as
the velocity change it gives (the same newtons as before where the share is today's force, to the
bit; the plant and the oracle told it given the same newtons), the run's warning under its outcome
when a force exceeds what the wheels hold, a gust with a correlation time, kerbs (the standard geometry of a wheel
against a step, known answers; refused where no wheel of that radius climbs) and features placed at
(x, y), on our robot and on a maker's."""

from __future__ import annotations

import copy
import math
import re
from pathlib import Path

import numpy as np
import pytest

import mlpfac
from mlpfac.cli import main
from mlpfac.loop.runner import build, run
from mlpfac.plants.mujoco.holds import climb
from mlpfac.scenario.parse import load, parse
from mlpfac.tables import to_toml

DOCS = Path(__file__).resolve().parents[1] / "docs"
# A TurtleBot3-class robot: 0.9 kg, wheels of 33 mm on velocity servos of kv 0.1, a ball caster
SMALL = """<mujoco model="small">
  <worldbody>
    <geom name="floor" type="plane" size="0 0 0.05"/>
    <body name="base" pos="0 0 0.033">
      <freejoint/>
      <geom type="box" size="0.07 0.07 0.03" pos="-0.03 0 0.035" mass="0.8"/>
      <geom type="sphere" size="0.01" pos="-0.08 0 -0.023" condim="1" priority="1" mass="0.01"/>
      <body name="left" pos="0 0.08 0">
        <joint name="left_hinge" axis="0 1 0"/>
        <geom type="cylinder" size="0.033 0.009" zaxis="0 1 0" mass="0.05" priority="1" friction="1"/>
      </body>
      <body name="right" pos="0 -0.08 0">
        <joint name="right_hinge" axis="0 1 0"/>
        <geom type="cylinder" size="0.033 0.009" zaxis="0 1 0" mass="0.05" priority="1" friction="1"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <velocity name="left" joint="left_hinge" kv="0.1" ctrlrange="-6.5 6.5" forcerange="-1.5 1.5"/>
    <velocity name="right" joint="right_hinge" kv="0.1" ctrlrange="-6.5 6.5" forcerange="-1.5 1.5"/>
  </actuator>
</mujoco>
"""
IN_NEWTONS = {"eight-tow": {"fx": -5.0}, "eight-push": {"fy": 30.0}}  # the shipped forces of a round ago


def _with_event(name: str, event: dict, robot: str | None = None, **over):
    """The shipped scenario ``name`` with its force event's size given by ``event`` instead."""
    table = copy.deepcopy(load(name, build=False, robot=robot).table)
    ev = {k: v for k, v in table["events"][0].items() if k not in ("fx_mg", "dv_y")}
    table["events"] = [ev | event]
    table.pop("provenance", None)
    return parse(table, name).with_overrides(**over)


def _same(a, b) -> bool:
    arrays = [(a.pose, b.pose), (a.u, b.u), (a.e_true, b.e_true)] + [(a.plant[k], b.plant[k]) for k in a.plant]
    return a.n == b.n and all(np.array_equal(x, y, equal_nan=True) for x, y in arrays)


def test_a_share_of_the_weight_equal_to_the_old_force_gives_the_same_bits():
    """On the shipped robot (5.5 kg, g 9.81): fx_mg = -5 / (m g) is -5 N to the bit, and a push of
    dv_y = 30 N x 0.2 s / m is 30 N: each run is the newtons' run, bit for bit."""
    m, g = 5.5, 9.81
    for name, event in (("eight-tow", {"fx_mg": -5.0 / (m * g)}), ("eight-push", {"dv_y": 30.0 * 0.2 / m})):
        over = {"controller": "kanayama", "duration": 14.0}
        relative, newtons = (run(_with_event(name, e, **over)) for e in (event, IN_NEWTONS[name]))
        assert relative.status == "ok" and _same(relative, newtons), name
        assert mlpfac.metrics(relative)["rms_position_error_m"] == mlpfac.metrics(newtons)["rms_position_error_m"]


def test_oracle_dynamic_is_told_the_newtons_the_plant_applies():
    scn = load("eight-tow", robot="diffdrive-torque").with_overrides(controller="oracle-dynamic", duration=14.0)
    b = build(scn)
    m, g = b.plant.weight()
    assert (m, g) == (scn.table["provenance"]["mass_kg"], 9.81)
    (told,) = b.ctrl.world.events
    assert told is b.plant.forces[0] and told.fx == -0.1 * m * g and told.fx_mg is None  # newtons, the plant's own
    rng = np.random.default_rng(np.random.SeedSequence(scn.seed))
    b.ctrl.world.reset([rng], scn.T)
    b.plant.reset(np.zeros(3), np.random.default_rng(np.random.SeedSequence(scn.seed)))
    np.testing.assert_array_equal(b.ctrl.world.schedules[0], b.plant._push)


def test_the_run_warns_when_a_force_exceeds_what_the_wheels_hold(tmp_path, capsys):
    """On a 0.9 kg robot the 30 N push of a round ago is beyond its tyres' traction (mu x the weight on
    its wheels), said right under the run's outcome; the shipped push, 1 m/s of velocity change, is not."""
    (tmp_path / "small.xml").write_text(SMALL)
    robot = str(tmp_path / "small.xml")
    table = copy.deepcopy(load("eight-push", build=False).table)
    table["events"][0] = {k: v for k, v in table["events"][0].items() if k != "dv_y"} | {"fy": 30.0}
    table["plant"]["model"] = str(Path(mlpfac.__file__).parents[1] / "models" / "scene.xml")
    path = tmp_path / "push-30N.toml"
    path.write_text(to_toml(table))
    common = ["--robot", robot, "--controller", "kanayama", "--duration", "13", "--no-log", "--no-plot"]
    assert main(["run", str(path), *common, "--out", str(tmp_path / "a")]) in (0, 1)
    first = capsys.readouterr().out.splitlines()[1]  # the outcome, then what was built and warned
    assert re.fullmatch(
        r"  warning: the force at 12\.5 s \(30 N, 3\.4 m g\) exceeds what the tyres' traction \(1 x \d+% of the 8\.9\d+ N "
        r"weight on the driven wheels: [\d.]+ N\) can hold: the wheels slide",
        first,
    ), first
    assert main(["run", "eight-push", *common, "--out", str(tmp_path / "b")]) == 0
    assert "warning:" not in capsys.readouterr().out


@pytest.mark.parametrize("name", ["eight-tow", "eight-push"])
def test_the_shipped_forces_fit_a_small_robot_where_newtons_did_not(tmp_path, name):
    """The tow of a round ago (5 N) and its push (30 N for 0.2 s) on the 0.9 kg robot: it diverges;
    the shipped ones, a tenth of its weight and 1 m/s, it holds."""
    (tmp_path / "small.xml").write_text(SMALL)
    robot = str(tmp_path / "small.xml")
    over = {"controller": "kanayama", "duration": 16.0}
    old = mlpfac.metrics(run(_with_event(name, IN_NEWTONS[name], robot=robot, **over)))
    new = mlpfac.metrics(run(load(name, robot=robot).with_overrides(**over)))
    assert old["status"] == "diverged"
    assert new["status"] == "ok" and new["outcome"] == "tracking" and new["max_position_error_m"] < 0.01


def _gust_runs(std: float, tau: float | None) -> float:
    """kanayama on the eight (the shipped robot, seed 0): how far a gust of ``std`` N from 2 s moves
    the robot's path from the run without it (RMS, m)."""
    table = copy.deepcopy(load("eight-tow", build=False).table)
    table["controller"]["name"] = "kanayama"
    quiet = copy.deepcopy(table) | {"events": []}
    table["events"] = [{"time": 2.0, "kind": "force", "std": std} | ({"tau_s": tau} if tau else {})]
    a, b = run(parse(table, "gust")), run(parse(quiet, "quiet"))
    d = np.hypot(*(a.pose[: a.n, :2] - b.pose[: b.n, :2]).T)
    return float(np.sqrt(np.mean(d * d)))


def test_a_gust_with_a_correlation_time_moves_the_run_where_white_noise_barely_does():
    """3 N of noise, white (drawn afresh each 10 ms step) against the same draws as a gust of 1 s
    correlation time: the gust moves the path about three times as far, and docs/scenarios.md says
    by how much."""
    white, gust = _gust_runs(3.0, None), _gust_runs(3.0, 1.0)
    assert gust > 2.5 * white
    text = (DOCS / "scenarios.md").read_text()
    said = f"{white * 1e3:.2f} mm RMS from the run without it; as a gust of `tau_s = 1.0`, {gust * 1e3:.2f} mm"
    assert said in text, said


def test_the_standard_geometry_of_a_wheel_against_a_step():
    """The edge of a step of h under a wheel of radius r: sqrt(2 r h - h^2) ahead of the axle, r - h
    below it (a 5 cm wheel, a 1 cm step: 3 cm and 4 cm, tan a = 0.75); at 0.9 r, tan a is 10."""
    d, tan = climb(0.05, 0.01)
    assert d == pytest.approx(0.03, rel=1e-15) and tan == pytest.approx(0.75, rel=1e-15)
    from mlpfac.plants.mujoco.holds import STEP_SHARE

    assert climb(1.0, STEP_SHARE)[1] == pytest.approx(10.0, rel=1e-12)


def test_a_kerb_is_a_step_up_and_down_on_the_ground_the_robot_climbs():
    scn = load("eight-kerb").with_overrides(controller="kanayama")
    t = scn.terrain
    kerb, placed = t.kerbs
    along = np.array([kerb.c, kerb.s])
    foot = np.array([kerb.x, kerb.y])
    h = t.height
    assert h(*(foot - 1e-3 * along)) == 0.0 and h(*(foot + 1e-3 * along)) == 0.005  # the step up
    assert h(*(foot + (0.3 - 1e-3) * along)) == 0.005 and h(*(foot + (0.3 + 1e-3) * along)) == 0.0  # down
    centre = np.array([placed.x, placed.y]) + 0.2 * np.array([placed.c, placed.s])
    assert centre == pytest.approx([1.75, 1.7], abs=1e-12) and h(*centre) == 0.008
    assert math.degrees(math.atan2(placed.s, placed.c)) == pytest.approx(115.0, abs=1e-12)
    b = build(scn)
    p = b.plant
    m, g = p.weight()
    need, tan, _ = p.kerb_need(0.005)
    wheel_load = max(load for geom, _, load in p._footing if geom in p._tyres)
    r = float(p.robot.real_radius)
    assert need == pytest.approx(wheel_load * math.sqrt(0.005 * (2 * r - 0.005)), rel=0.01)  # the wheel's climb
    need = scn.table["provenance"]["world_need"]  # the run's world: line
    assert need.startswith("kerb #1 (5 mm) asks 0.43 N m a driven wheel from rest to climb it")
    # driven over the placed kerb, the robot's axle rises by its height, and comes down again
    rise = []
    p.reset(np.array([*(centre - 0.6 * np.array([placed.c, placed.s])), math.radians(115.0)]), np.random.default_rng(0))
    z0 = float(p.data.site_xpos[p._site][2])
    for _ in range(500):
        p.step(np.array([0.25, 0.0]))
        assert p.diverged() is None
        rise.append(float(p.data.site_xpos[p._site][2]) - z0)
    assert max(rise) == pytest.approx(0.008, abs=0.001) and abs(rise[-1]) < 0.001
    rec = run(scn)
    assert rec.status == "ok" and mlpfac.metrics(rec)["outcome"] == "tracking"


@pytest.mark.menagerie
def test_a_kerb_on_makers_robots_says_what_their_motors_lack(tmp_path, capsys):
    """PAL TIAGo's 100 N m motors climb both kerbs; Stretch's forward motor (3 N m for both wheels)
    cannot push its caster up either from rest: the run says so under its outcome, and it stalls at
    the second with its caster against the step: lost."""
    common = ["--controller", "kanayama", "--duration", "25", "--no-log", "--no-plot"]
    assert main(["run", "eight-kerb", "--robot", "pal_tiago", *common, "--out", str(tmp_path / "t")]) == 0
    out = capsys.readouterr().out
    assert "warning:" not in out and ": tracking" in out.splitlines()[0], out
    main(["run", "eight-kerb", "--robot", "hello_robot_stretch", *common, "--out", str(tmp_path / "s")])
    out = capsys.readouterr().out
    outcome, first = out.splitlines()[:2]
    assert ": lost" in outcome, outcome
    assert first.startswith("  warning: kerb #1 (5 mm) asks 1.57 N m a driven wheel from rest to push its caster up it, "
                            "of motors that give 1.5 N m")  # fmt: skip
    assert "kerb #2 (8 mm) asks 2.38 N m" in first


def test_the_recording_holds_the_kerbs(tmp_path, rrd_contents):
    from mlpfac import log

    scn = load("eight-kerb").with_overrides(controller="kanayama", duration=1.0)
    run(scn, sink=log.make_sink(save=tmp_path / "kerb.rrd", recording_id="kerb"))
    ents = rrd_contents(tmp_path / "kerb.rrd")
    for i, kerb in enumerate(scn.terrain.kerbs):
        v = np.array(ents[f"/world/terrain/kerb_{i}"].static["Mesh3D:vertex_positions"].to_pylist()[0])
        np.testing.assert_allclose(v, kerb.corners(), atol=1e-6)
        assert v[:, 2].max() == pytest.approx(kerb.height, abs=1e-7)


@pytest.mark.menagerie
def test_what_the_pages_say_of_forces_and_kerbs_is_what_the_code_gives():
    """docs/scenarios.md's and the shipped files' numbers of the relative forces and the kerbs, each
    from the code: the newtons each robot is given, what each kerb asks of its driven wheels."""
    page = (DOCS / "scenarios.md").read_text()
    said = {}
    for robot in (None, "pal_tiago", "hello_robot_stretch"):
        p = build(load("eight-kerb", robot=robot).with_overrides(controller="kanayama")).plant
        said[robot] = [f"{p.kerb_need(k.height)[0]:.3g}" for k in p.terrain.kerbs] + [f"{p.each_wheel():.3g}"]
        push = build(load("eight-push", robot=robot).with_overrides(controller="kanayama")).plant.forces[0]
        said[robot] += [f"{push.fy:.3g}"]
    ours, tiago, stretch = said[None], said["pal_tiago"], said["hello_robot_stretch"]
    assert f"each kerb asks {ours[0]} and {ours[1]} N m of the {ours[2]} its servos give" in page
    assert f"on PAL TIAGo, {tiago[0]} and {tiago[1]} of {tiago[2]};" in page
    assert f"3 N m together, {stretch[0]} and {stretch[1]}\n  N m of the {stretch[2]} each" in page
    assert f"1 m/s ({ours[3]} N on this robot, {tiago[3]} N on PAL TIAGo)" in page
    tow = build(load("eight-tow").with_overrides(controller="kanayama")).plant
    text = tow._force_text(load("eight-tow", build=False).events[0])
    assert text.startswith(f"force fx {tow.forces[0].fx:.4g} N (fx_mg -0.1 m g)") and text[:35] in page
    assert f"in its own axes: {-tow.forces[0].fx:.2g} N on this robot)" in page
    for name, newtons in (("eight-tow", f"{-tow.forces[0].fx:.2g} N"), ("eight-push", f"{ours[3]} N")):
        assert f"{newtons} on the shipped {tow.weight()[0]:g} kg robot" in load(name, build=False).description
    given = {}  # the newtons of Results 9's robots on velocity servos
    for robot in ("cart", "pal_tiago"):
        push, pull = (
            build(load(n, robot=robot).with_overrides(controller="kanayama")).plant.forces[0]
            for n in ("eight-push", "eight-tow")
        )
        given[robot] = (f"{push.fy:.3g}", f"{-pull.fx:.2g}")
    results = " ".join((DOCS / "results-world.md").read_text().split())
    assert (
        f"(`eight-push`: {ours[3]} N on our robot, {given['cart'][0]} N on the cart, {given['pal_tiago'][0]} N on TIAGo)"
        in results
    )
    assert (
        f"(`eight-tow`: {-tow.forces[0].fx:.2g} N on ours, {given['cart'][1]} N on the cart, {given['pal_tiago'][1]} N "
        "on TIAGo)" in results
    )


def test_figure_1_draws_the_kerbs_and_the_time_on_them():
    from matplotlib.patches import Polygon

    from mlpfac.plots.figure1 import Draft
    from mlpfac.plots.world import footprint, legend_entries, on_ground

    rec = run(load("eight-kerb").with_overrides(controller="kanayama", duration=8.0))
    prints = [p for p in Draft(rec, False).paths["e"].patches if isinstance(p, Polygon)]
    assert len(prints) == 2  # each kerb's footprint
    on = on_ground(rec)["kerb"]
    centres = [footprint(c).mean(axis=0) for c in rec.world["kerbs"]]
    assert np.allclose(centres[1], [1.75, 1.7])  # the kerb placed at (x, y), met first (at 2 s)
    for kerb, after in ((1, 0.0), (0, 4.0)):  # then the one across the path at 20 % of it
        k = int(np.argmax(on & (rec.t[: rec.n] >= after)))
        assert on[k] and math.hypot(*(rec.pose[k, :2] - centres[kerb])) < 0.7, (kerb, rec.t[k])
    assert "kerb (and the time on it)" in [e.get_label() for e in legend_entries(rec, True)]
