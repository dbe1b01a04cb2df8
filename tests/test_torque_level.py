"""Controllers of the wheels' torques (mlpfac.control.torque, mlpfac.control.dynamic): a user's class
written from the contract alone in run, sweep, compare and check; what it is given; its error rules;
its refusal on a robot without torque motors; the shipped fierro-lewis and oracle-dynamic."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mlpfac
from mlpfac.cli import main
from mlpfac.exceptions import PluginError
from mlpfac.scenario.parse import load

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "torque_law.py"
TUG = REPO / "models" / "tug.xml"
SCENE = REPO / "models" / "scene.xml"

PROBE = '''
import numpy as np


class Probe:
    """Zero torque; keeps what it was given, and misbehaves on request."""

    level = "torque"
    seen = []

    def __init__(self, T, robot, bad=None):
        self.T, self.robot, self.bad, self.k = T, robot, bad, 0

    def reset(self, rng):
        self.k = 0

    def step(self, obs):
        self.k += 1
        Probe.seen.append(obs)
        if self.bad == "raise" and self.k == 3:
            raise ZeroDivisionError("the law's own bug")
        if self.bad == "nan" and self.k == 3:
            return float("nan"), 0.0
        if self.bad == "shape" and self.k == 3:
            return np.zeros(3)
        return 0.01, -0.01
'''

TORQUE = f'duration = 0.5\n[plant]\nkind = "mujoco"\nmodel = "{SCENE}"\nactuator = "torque"\n'


def cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mlpfac.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=900)  # fmt: skip


def before_mm(rec) -> float:
    return mlpfac.metrics(rec)["phases"]["before"]["rms_position_error_m"] * 1e3


@pytest.fixture
def probe(tmp_path: Path) -> Path:
    (tmp_path / "probe.py").write_text(PROBE)
    (tmp_path / "t.toml").write_text(TORQUE)
    return tmp_path


def test_the_example_tracks_on_our_torque_robot_and_on_a_robot_of_ones_own():
    """examples/torque_law.py, written from the contract alone: within 10 mm on eight-torque and on
    a 24 kg robot with its load ahead of the axle, from its MJCF alone, before the wheel radius changes."""
    rec = mlpfac.run("eight-torque", controller=f"{EXAMPLE}:TorqueLaw", seed=0)
    assert rec.status == "ok" and before_mm(rec) < 10.0
    scn = load("eight-wheel-radius", robot=str(TUG)).with_overrides(f"{EXAMPLE}:TorqueLaw", 0)
    rec = mlpfac.run(scn)
    assert rec.status == "ok" and before_mm(rec) < 10.0


def test_what_the_controller_is_given(probe, monkeypatch):
    """robot: the nominal model; obs: e, r, r_dot, the measured pose, twist and wheel speeds, t; the
    twist and the wheel speeds delayed as the pose is, and noisy with their keys."""
    monkeypatch.chdir(probe)
    text = TORQUE + "pose_noise_std = 0.0\n" + '[[events]]\ntime = 0.2\nkind = "sensor_delay"\nsteps = 3\n'
    (probe / "d.toml").write_text(text)
    rec = mlpfac.run(str(probe / "d.toml"), controller="probe.py:Probe")
    mod = next(m for n, m in sys.modules.items() if n.startswith("mlpfac_plugin_") and n.endswith("_probe"))
    seen = mod.Probe.seen
    assert len(seen) == rec.n == 50
    first = seen[0]
    assert first.e.shape == (3,) and first.r.shape == (5,) and first.r_dot.shape == (2,)
    assert first.pose.shape == (3,) and first.twist.shape == (2,) and first.wheel_speeds.shape == (2,)
    assert first["t"] == 0.0 and seen[7].t == pytest.approx(0.07)
    assert np.allclose(first.twist, rec.ref[0, 3:5], atol=1e-3)  # a flying start: the reference's twist
    r = rec.ref
    assert np.allclose(seen[10].r_dot, (r[11, 3:5] - r[9, 3:5]) / 0.02)
    assert np.array_equal(seen[10].pose, rec.pose_meas[10])
    # after the delay of 3 steps: the twist of 3 steps before, as the plant recorded it (u_true)
    k = 40
    assert np.allclose(seen[k].twist, rec.plant["u_true"][k - 1 - 3], rtol=0, atol=1e-12)
    assert np.allclose(seen[k].wheel_speeds, rec.plant["wheel_meas"][k - 1 - 3], rtol=0, atol=1e-12)
    assert np.array_equal(seen[k].pose, rec.pose_meas[k]) and np.array_equal(rec.pose_meas[k], rec.pose[k - 3])
    assert np.isnan(rec.plant["wheel_cmd"]).all()  # no wheel-speed command: the torques are in u and "torque"
    assert np.allclose(rec.u[:-1], [0.01, -0.01]) and np.allclose(rec.plant["torque"][5], [0.01, -0.01])
    # noise on the twist and the wheel speeds, from their own stream: the pose's is the same
    mod.Probe.seen.clear()
    (probe / "n.toml").write_text(
        TORQUE.replace(
            'actuator = "torque"\n', 'actuator = "torque"\ntwist_noise_std = [0.1, 0.2]\nwheel_speed_noise_std = 0.3\n'
        )
    )
    noisy = mlpfac.run(str(probe / "n.toml"), controller="probe.py:Probe")
    tw = np.array([o.twist for o in seen[1:]]) - noisy.plant["u_true"][: noisy.n - 1]
    ws = np.array([o.wheel_speeds for o in seen[1:]]) - noisy.plant["wheel_meas"][: noisy.n - 1]
    assert 0.05 < tw[:, 0].std() < 0.2 and 0.1 < tw[:, 1].std() < 0.4 and 0.15 < ws.std() < 0.6
    mod.Probe.seen.clear()
    (probe / "p.toml").write_text(TORQUE)
    plain = mlpfac.run(str(probe / "p.toml"), controller="probe.py:Probe")
    noisy_pose = mlpfac.run(str(probe / "n.toml"), controller="probe.py:Probe")
    assert np.array_equal(plain.pose_meas - plain.pose, noisy_pose.pose_meas - noisy_pose.pose)


@pytest.mark.parametrize(("bad", "reason"), [("nan", "non-finite command"), ("shape", "(tau_left, tau_right)")])
def test_a_bad_torque_ends_the_run_as_diverged(probe, monkeypatch, bad, reason):
    monkeypatch.chdir(probe)
    (probe / "b.toml").write_text(
        TORQUE + f'[controller]\nname = "probe.py:Probe"\n[controller.params]\nbad = "{bad}"\n'
    )
    rec = mlpfac.run(str(probe / "b.toml"))
    assert rec.status == "diverged" and reason in rec.reason and rec.n == 3


def test_a_torque_controller_that_raises_is_its_failure(probe, monkeypatch):
    monkeypatch.chdir(probe)
    (probe / "r.toml").write_text(
        TORQUE + '[controller]\nname = "probe.py:Probe"\n[controller.params]\nbad = "raise"\n'
    )
    with pytest.raises(PluginError, match="the law's own bug"):
        mlpfac.run(str(probe / "r.toml"))


VELOCITY = TORQUE.replace('actuator = "torque"', 'actuator = "velocity"')
NO_ROBOT = 'class Law:\n    level = "torque"\n    def __init__(self, T):\n        pass\n    def step(self, obs):\n        return 0.0, 0.0\n'
BAD_LEVEL = 'class Law:\n    level = "force"\n    def __init__(self, T):\n        pass\n    def step(self, e, r):\n        return 0.0, 0.0\n'
BUDGET = 'scenarios = ["eight-torque"]\ncontrollers = ["probe.py:Probe"]\nseeds = "0"\nduration = 0.5\n{robots}[[budget]]\nlost = 0\n'
# name: (files, argv, what the one line holds)
BAD_TORQUE = {
    "on velocity servos": ({"v.toml": VELOCITY}, ["run", "v.toml", "--controller", "probe.py:Probe"], 'set actuator = "torque" in [plant]'),
    "shipped on velocity servos": ({"v.toml": VELOCITY}, ["run", "v.toml", "--controller", "fierro-lewis"], 'set actuator = "torque" in [plant]'),
    "on the kinematic plant": ({"k.toml": "duration = 0.5\n"}, ["run", "k.toml", "--controller", "probe.py:Probe"], 'actuator = "torque" in [plant]'),
    "a robot unset that has servos": ({"s.toml": f'duration = 0.5\n[plant]\nkind = "mujoco"\nmodel = "{SCENE}"\n'}, ["run", "s.toml", "--controller", "oracle-dynamic"], 'actuator = "torque"'),
    "sweep on velocity servos": ({"v.toml": VELOCITY}, ["sweep", "v.toml", "--controllers", "kanayama,probe.py:Probe"], 'set actuator = "torque"'),
    "no robot argument": ({"n.py": NO_ROBOT}, ["run", "t.toml", "--controller", "n.py:Law"], "must take robot"),
    "a level of its own": ({"l.py": BAD_LEVEL}, ["run", "t.toml", "--controller", "l.py:Law"], "level is 'force'"),
    "robot in params": ({"p.toml": TORQUE + '[controller]\nname = "probe.py:Probe"\n[controller.params]\nrobot = 1\n'}, ["run", "p.toml"], "[controller.params] robot"),
    "noise of the twist": ({"w.toml": TORQUE + "twist_noise_std = [0.1, -1.0]\n"}, ["run", "w.toml", "--controller", "fierro-lewis"], "twist_noise_std"),
    "noise of the wheels": ({"w.toml": TORQUE + 'wheel_speed_noise_std = "a"\n'}, ["run", "w.toml", "--controller", "fierro-lewis"], "wheel_speed_noise_std"),
    # on a robot a flag or key brought: that robot is named, under its flag or key, not the file's [plant]
    "--robot with velocity servos": ({}, ["run", "eight-torque", "--robot", "cart", "--controller", "probe.py:Probe"], "mlpfac: error: --robot cart: Probe is a torque-level"),
    "--robot, a shipped one": ({}, ["run", "eight-torque", "--robot", "diffdrive", "--controller", "fierro-lewis"], "mlpfac: error: --robot diffdrive: fierro-lewis is"),
    "--robot, its file says velocity": ({"r.toml": f'[plant]\nmodel = "{SCENE}"\nactuator = "velocity"\n'}, ["run", "eight-torque", "--robot", "r.toml", "--controller", "fierro-lewis"], "mlpfac: error: --robot r.toml: fierro-lewis is"),
    "--robots, one with velocity servos": ({}, ["sweep", "eight-torque", "--robots", "tug,diffdrive", "--controllers", "probe.py:Probe"], "mlpfac: error: --robots diffdrive: Probe is"),
    "compare --robot": ({}, ["compare", "eight-torque", "--robot", "cart", "--controllers", "fierro-lewis"], "mlpfac: error: --robot cart: fierro-lewis is"),
    "a budget's robots": ({"b.toml": BUDGET.format(robots='robots = ["tug", "cart"]\n')}, ["check", "b.toml"], "b.toml robots cart: Probe is a torque-level"),
    "check --robot": ({"b.toml": BUDGET.format(robots="")}, ["check", "b.toml", "--robot", "cart"], "mlpfac: error: --robot cart: Probe is"),
}  # fmt: skip


@pytest.mark.parametrize("case", BAD_TORQUE)
def test_bad_torque_level_input_is_one_line_and_nothing_written(probe, monkeypatch, capsys, case):
    files, argv, text = BAD_TORQUE[case]
    for name, body in files.items():
        (probe / name).write_text(body)
    monkeypatch.chdir(probe)
    before = sorted(os.listdir(probe))
    assert main([*argv, "--out", "out"]) == 2
    err = capsys.readouterr().err
    said = [line for line in err.strip().splitlines() if not line.startswith("mlpfac: planning")]
    assert len(said) == 1 and text in err, err
    assert "Traceback" not in err and sorted(os.listdir(probe)) == before


def test_a_users_torque_class_in_run_sweep_compare_and_check(tmp_path):
    """The example as a user names it (file.py:Class) in each command; the batched sweep gives the
    seed-by-seed runs' figures."""
    shutil.copy(EXAMPLE, tmp_path / "torque_law.py")
    (tmp_path / "t.toml").write_text(TORQUE.replace("duration = 0.5", "duration = 3.0"))
    name = "torque_law.py:TorqueLaw"
    run = cli(["run", "t.toml", "--controller", name, "--out", "r", "--no-log", "--no-plot"], tmp_path)
    assert run.returncode == 0, run.stderr
    m = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert m["controller"] == "torque-law" and m["outcome"] == "tracking"
    again = cli(["run", str(tmp_path / "r" / "config.toml"), "--out", "r2", "--no-log", "--no-plot"], tmp_path)
    assert again.returncode == 0, again.stderr
    m2 = json.loads((tmp_path / "r2" / "metrics.json").read_text())
    assert m2["rms_position_error_m"] == m["rms_position_error_m"]
    args = ["t.toml", "--controllers", f"{name},fierro-lewis,kanayama", "--seeds", "0-1", "--workers", "1"]
    for cmd, extra in (("sweep", ["--out", "s"]), ("sweep", ["--out", "b", "--batched"]), ("compare", ["--out", "c"])):
        p = cli([cmd, *args, *extra], tmp_path)
        assert p.returncode == 0, p.stderr
    for seed in (0, 1):
        f = f"t/torque-law/seed-{seed:04d}/metrics.json"
        a, b = (json.loads((tmp_path / d / f).read_text()) for d in ("s", "b"))
        assert a["rms_position_error_m"] == b["rms_position_error_m"]
    (tmp_path / "budget.toml").write_text(
        f'scenarios = ["t.toml"]\ncontrollers = ["{name}", "fierro-lewis"]\nseeds = "0-1"\n\n'
        '[[budget]]\nname = "within 10 mm"\nphase = "before"\nmedian_position_rms_mm = 10.0\ndiverged = 0\n'
    )
    chk = cli(["check", "budget.toml", "--out", "k"], tmp_path)
    assert chk.returncode == 0, chk.stdout + chk.stderr


def test_fierro_lewis_and_the_oracle_on_the_tug_before_and_after_the_radius_changes():
    scn = load("eight-wheel-radius", robot=str(TUG))
    fl = mlpfac.run(scn.with_overrides("fierro-lewis", 0))
    od = mlpfac.run(scn.with_overrides("oracle-dynamic", 0))
    mf, mo = mlpfac.metrics(fl)["phases"], mlpfac.metrics(od)["phases"]
    assert mf["before"]["rms_position_error_m"] < 0.01 and mo["before"] == mf["before"]  # told nothing yet
    assert mo["after"]["rms_position_error_m"] < 0.01


def test_the_shipped_torque_controllers_are_listed(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "fierro-lewis" in out and "oracle-dynamic" in out
    assert {"fierro-lewis", "oracle-dynamic"} <= set(mlpfac.CONTROLLERS)


def test_the_dynamic_oracle_is_told_the_payload(tmp_path):
    """oracle-dynamic's model after a payload is the robot's changed one; fierro-lewis keeps the nominal."""
    from mlpfac.loop.factory import make_controller

    (tmp_path / "p.toml").write_text(TORQUE + '[[events]]\ntime = 0.2\nkind = "payload"\nmass_kg = 5.0\n')
    scn = load(str(tmp_path / "p.toml")).with_overrides("oracle-dynamic")
    ctrl = make_controller(scn)
    (_, kind, _, model) = ctrl.changes[0]
    assert kind == "payload" and model.mass_kg == pytest.approx(ctrl.robot.mass_kg + 5.0)
    assert model.yaw_inertia_kg_m2 > ctrl.robot.yaw_inertia_kg_m2


def test_the_torque_loop_is_chosen_from_the_model():
    """Unset PI gains are scaled to the inertia a wheel drives: our robot gets the gains tuned on it
    (0.5, 10: the published eight-torque runs' bits), the 24 kg robot 17.7 times them, said on the
    robot's line and written into config.toml; gains the file sets are kept."""
    from mlpfac.plants.config import MujocoConfig
    from mlpfac.plants.mujoco import MujocoPlant

    ours = MujocoPlant(MujocoConfig(model=str(SCENE), actuator="torque"), 0.01)
    assert (ours.config.pi_kp, ours.config.pi_ki) == (0.5, 10.0)
    tug = MujocoPlant(MujocoConfig(model=str(TUG)), 0.01)
    j = 24 * 0.1**2 / 2 + 0.025  # m r^2 / 2 + I_w
    scale = j / (5.5 * 0.05**2 / 2 + 0.0013125)
    assert tug.config.pi_kp == float(f"{0.5 * scale:.3g}") and tug.config.pi_ki == float(f"{10 * scale:.3g}")
    assert {"pi_kp", "pi_ki"} <= set(tug.found()) and "wheel-speed PI gains kp 8.85" in tug.robot.description
    kept = MujocoPlant(MujocoConfig(model=str(TUG), pi_kp=2.0), 0.01)
    assert kept.config.pi_kp == 2.0 and kept.config.pi_ki == tug.config.pi_ki and "pi_kp" not in kept.found()
    servos = MujocoPlant(MujocoConfig(model=str(SCENE)), 0.01)
    assert servos.config.pi_kp is None and "pi_kp" not in servos.found()


@pytest.mark.parametrize("controller", ["kanayama", "fierro-lewis", "adaptive-dynamic"])
def test_the_tug_tracks_from_its_mjcf_alone(controller):
    """The 24 kg robot, its load ahead of the axle, 4 N m motors: within 10 mm before the wheel radius
    changes, with Kanayama's law through the torque loop chosen from the model, and at the torque level."""
    scn = load("eight-wheel-radius", robot=str(TUG)).with_overrides(controller, 0, duration=12.0)
    rec = mlpfac.run(scn)
    assert rec.status == "ok" and before_mm(rec) < 10.0


def test_adaptive_dynamic_learns_what_the_nominal_model_misses():
    """The 24 kg robot's base three times as heavy at 12.5 s: fierro-lewis's nominal model is wrong
    from there on; adaptive-dynamic's networks learn what it misses and track closer after it."""
    scn = load("eight-payload", robot=str(TUG))
    after = {}
    for name in ("fierro-lewis", "adaptive-dynamic"):
        rec = mlpfac.run(scn.with_overrides(name, 0))
        assert rec.status == "ok"
        after[name] = mlpfac.metrics(rec)["phases"]["after"]["rms_position_error_m"]
        if name == "adaptive-dynamic":
            z = rec.ctrl["z"]
            assert np.isfinite(z).all() and np.abs(z[rec.n - 1, :24]).max() > 1e-4  # its output weights moved
    assert after["adaptive-dynamic"] < 0.9 * after["fierro-lewis"]


BATCHED_TORQUE = '''
import numpy as np


class BatchTorque:
    """Kanayama's velocities, then torques through the robot's mass and inertia: the batch form."""

    level = "torque"
    batched = True
    name = "batch-torque"

    def __init__(self, T, robot):
        self.r, self.b, iw = robot.wheel_radius_m, robot.track_m / 2, robot.wheel_inertia_kg_m2
        self.m = robot.mass_kg + 2 * iw / self.r**2
        self.i = robot.yaw_inertia_kg_m2 + 2 * self.b**2 * iw / self.r**2
        self.rate = 0.5 / T

    def step(self, obs):
        e, tw = np.atleast_2d(obs.e), np.atleast_2d(obs.twist)
        v_c = obs.r[3] * np.cos(e[:, 2]) + 10.0 * e[:, 0]
        w_c = obs.r[4] + obs.r[3] * (150.0 * e[:, 1] + 16.0 * np.sin(e[:, 2]))
        f = self.m * (obs.r_dot[0] + self.rate * (v_c - tw[:, 0])) * self.r
        t = self.i * (obs.r_dot[1] + self.rate * (w_c - tw[:, 1])) * self.r / self.b
        out = np.stack([(f - t) / 2, (f + t) / 2], axis=1)
        return out if np.ndim(obs.e) == 2 else out[0]
'''


def test_a_batch_form_torque_class_gives_its_seeds_one_by_one_runs(tmp_path):
    """The batch form (obs arrays (B, ...), torques (B, 2)) in a --batched sweep, every seed's figures
    those of the sweep without it; fierro-lewis batched likewise."""
    (tmp_path / "bt.py").write_text(BATCHED_TORQUE)
    (tmp_path / "t.toml").write_text(TORQUE.replace("duration = 0.5", "duration = 3.0"))
    args = ["sweep", "t.toml", "--controllers", "bt.py:BatchTorque,fierro-lewis", "--seeds", "0-2", "--workers", "1"]
    one, batch = cli([*args, "--out", "a"], tmp_path), cli([*args, "--out", "b", "--batched"], tmp_path)
    assert one.returncode == batch.returncode == 0, batch.stderr
    for name in ("batch-torque", "fierro-lewis"):
        for seed in range(3):
            f = f"t/{name}/seed-{seed:04d}/metrics.json"
            a, b = (json.loads((tmp_path / d / f).read_text()) for d in ("a", "b"))
            assert a["rms_position_error_m"] == b["rms_position_error_m"] and a["outcome"] == "tracking"


SCRIBBLER = """

class Scribbler(BatchTorque):
    \"\"\"BatchTorque, then it writes into every array of the observation it was given.\"\"\"

    name = "scribbler"

    def step(self, obs):
        out = super().step(obs)
        for a in (obs.e, obs.r, obs.r_dot, obs.pose, obs.twist, obs.wheel_speeds):
            a[...] = 1e3
        return out
"""


def test_a_batch_form_torque_class_that_writes_into_its_observation_changes_nothing(tmp_path):
    """The batch form's observation is copies, batched or not: a law that writes into every array it
    was given runs to the bit as the same law that does not."""
    (tmp_path / "bt.py").write_text(BATCHED_TORQUE + SCRIBBLER)
    (tmp_path / "t.toml").write_text(TORQUE.replace("duration = 0.5", "duration = 1.0"))
    args = ["sweep", "t.toml", "--controllers", "bt.py:BatchTorque,bt.py:Scribbler", "--seeds", "0-2", "--workers", "1"]
    for out, flags in (("a", []), ("b", ["--batched"])):
        assert cli([*args, "--out", out, *flags], tmp_path).returncode == 0
        for seed in range(3):
            ma, mb = (
                json.loads((tmp_path / out / f"t/{name}/seed-{seed:04d}/metrics.json").read_text())
                for name in ("batch-torque", "scribbler")
            )
            assert mb["status"] == "ok" and mb["rms_position_error_m"] == ma["rms_position_error_m"], (out, seed)


@pytest.mark.parametrize(
    "event", ['kind = "sensor_delay"\nsteps = 3', 'kind = "control_period"\nfactor = 1.5'], ids=["delay", "period"]
)
def test_the_dynamic_oracle_told_the_period_and_the_delay(tmp_path, event):
    """After a sensor delay of 3 steps, or a control period x1.5, fierro-lewis loses the eight (beyond
    10 mm); told the change, oracle-dynamic tracks within 3 mm: the pose predicted over the delay, or
    the reference in the robot's time."""
    text = TORQUE.replace("duration = 0.5", "duration = 8.0") + "pose_noise_std = 0.001\n"
    (tmp_path / "e.toml").write_text(text + f"[[events]]\ntime = 3.0\n{event}\n")
    after = {}
    for name in ("fierro-lewis", "oracle-dynamic"):
        rec = mlpfac.run(str(tmp_path / "e.toml"), controller=name, seed=0)
        after[name] = mlpfac.metrics(rec)["phases"]["after"]["rms_position_error_m"]
    assert after["fierro-lewis"] > 0.01 and after["oracle-dynamic"] < 0.003, after


def test_what_the_reference_asks_of_the_motors(tmp_path):
    """The largest wheel torque the nominal model needs along the reference, against the motors' limit,
    said on the robot's line: on a circle (v, omega constant: the offset mass's coupling and the joints'
    damping alone, in closed form), and on the eight at the speed it names as the motors' last, where
    the need is the limit; beyond it a warning."""
    import re

    from mlpfac.plants import make_plant

    circle = TORQUE + '[reference]\nkind = "circle"\nradius = 1.0\nrate = 0.8\n'
    (tmp_path / "circle.toml").write_text(circle)
    scn = load(str(tmp_path / "circle.toml"))
    model = make_plant(scn, np.zeros((2, 5))).dynamics()
    m, d, c, r, b = model.mass_kg, model.com_offset_m, model.wheel_damping_Nm_s, model.wheel_radius_m, model.b

    def need(k: float) -> float:  # v = omega = 0.8 k on a circle of 1 m
        v = w = 0.8 * k
        total = r * (-m * d * w * w + 2 * c * v / r**2)  # tau_l + tau_r
        diff = r / b * (m * d * w * v + 2 * c * b * b * w / r**2)  # tau_r - tau_l
        return max(abs(total - diff), abs(total + diff)) / 2

    from scipy.optimize import brentq

    said = scn.table["provenance"]["reference_torque"]
    assert f"needs up to {need(1.0):.3g} N m a wheel of the motors' 0.6 N m" in said, said
    k = float(re.search(r"speed = ([0-9.]+)", said)[1])
    assert k == pytest.approx(brentq(lambda k: need(k) - 0.6, 0.1, 100.0), rel=2e-3)

    full = TORQUE.replace("duration = 0.5", "duration = 25.0")  # the whole eight: the need is over the run
    (tmp_path / "eight.toml").write_text(full + '[reference]\nkind = "eight"\n')
    said = load(str(tmp_path / "eight.toml")).table["provenance"]["reference_torque"]
    top = float(re.search(r"speed = ([0-9.]+)", said)[1])
    assert 2.0 < top < 3.0, said  # the prototype's motors saturated by 2.75
    (tmp_path / "top.toml").write_text(full + f'[reference]\nkind = "eight"\nspeed = {top}\n')
    share = load(str(tmp_path / "top.toml")).table["provenance"]["reference_torque"]
    assert re.search(r"\((99|100|101)%", share), share
    (tmp_path / "over.toml").write_text(full + f'[reference]\nkind = "eight"\nspeed = {1.1 * top:.3g}\n')
    warned = load(str(tmp_path / "over.toml")).table["provenance"]
    assert "the motors saturate" in warned["torque_warning"]
    short = load(str(tmp_path / "eight.toml")).with_overrides(duration=3.0).table["provenance"]  # --duration 3
    (tmp_path / "short.toml").write_text(
        TORQUE.replace("duration = 0.5", "duration = 3.0") + '[reference]\nkind = "eight"\n'
    )
    assert short["reference_torque"] == load(str(tmp_path / "short.toml")).table["provenance"]["reference_torque"]
    assert short["reference_torque"] != said  # over the path the run drives, not the file's
    servos = load("eight-nominal").table["provenance"]
    assert "reference_torque" not in servos and "torque_warning" not in servos
