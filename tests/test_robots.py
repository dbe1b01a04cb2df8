"""Every MuJoCo Menagerie wheeled base by its name alone, a test robot of nobody's (an arm, four
wheels, torque motors), and any scenario on any robot (--robot, --robots, a budget's robots)."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from mlpfac.cli import main
from mlpfac.exceptions import ConfigError
from mlpfac.plants.config import MujocoConfig
from mlpfac.plants.mjcf.wheels import skid_track
from mlpfac.plants.mujoco import MujocoPlant
from mlpfac.scenario.on_robot import SHARE, on_robot, robot_table, with_robots
from mlpfac.scenario.parse import shipped_dir
from mlpfac.scenario.reference import make_reference, sample
from mlpfac.tables import read_toml

SKID_ARM = Path(__file__).parent / "data" / "skid_arm.xml"
T = 0.01

# Each base from its model alone: what must have been found or chosen (docs/robots.md).
BASES = {
    "pal_tiago": {"keyframe": "home", "other_actuators": "lock", "tyre": "sphere", "actuator": "velocity"},
    "pal_tiago_dual": {"left_actuator_2": "wheel_rear_left_joint_velocity", "tyre": "sphere", "armature": 0.133,
                       "timestep": 0.002 / 15},
    "hello_robot_stretch": {"tendon_actuators": ["forward", "turn"], "actuator": "torque", "other_actuators": "lock"},
    "hello_robot_stretch_3": {"keyframe": "home", "timestep": 0.01 / 45, "actuator": "velocity", "other_actuators": "lock"},
}  # fmt: skip


@pytest.mark.menagerie
@pytest.mark.parametrize("name", sorted(BASES))
def test_a_menagerie_base_from_its_name_alone(name):
    plant = MujocoPlant(MujocoConfig(model=f"menagerie:{name}"), T, (T,))
    found = plant.found()
    assert {k: pytest.approx(found.get(k)) for k in BASES[name]} == BASES[name]
    assert plant.robot.locked and plant.model.nu == (4 if name == "pal_tiago_dual" else 2)  # only the drive is left
    assert plant.n_substeps == {"hello_robot_stretch_3": 45, "pal_tiago_dual": 75}.get(name, 5)  # else the model's 2 ms
    if name == "hello_robot_stretch_3":  # what hangs from the locked arm and head (fingertips, a camera) too
        assert {"rubber_left_x", "joint_head_nav_cam"} <= set(plant.robot.locked)


def _wheels(plant, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Wheel speed errors (rad/s) and wheel torques (N m) of ``steps`` control steps straight ahead."""
    plant.reset(np.zeros(3), np.random.default_rng(0))
    err, torque = [], []
    for _ in range(steps):
        plant.step(np.array([0.2, 0.0]))
        tele = plant.telemetry()
        err.append(tele["wheel_meas"] - tele["wheel_cmd"])
        torque.append(tele["torque"].copy())
    return np.array(err), np.array(torque)


@pytest.mark.menagerie
def test_stiff_servos_kept_within_their_force_limit_by_their_control_do_not_chatter():
    """TIAGo++'s wheel servos (kv 2000 on wheels of 0.0011 kg m^2, clamped at 400 N m) chatter at the
    model's 2 ms as MuJoCo clamps their force (a clamped servo is integrated explicitly): their
    speed swings by hundreds of rad/s. Kept within the limit through their control (servo_limit =
    "control", chosen where no timestep integrates them: here without the rotor inertia a skid-steer
    is given), MuJoCo integrates them implicitly: they hold the speed asked, within the limit."""
    clamped = MujocoPlant(MujocoConfig(model="menagerie:pal_tiago_dual", servo_limit="model", armature=0), T, (T,))
    kept = MujocoPlant(MujocoConfig(model="menagerie:pal_tiago_dual", armature=0), T, (T,))
    assert kept.config.servo_limit == "control" and kept.model.opt.timestep == clamped.model.opt.timestep
    err, _ = _wheels(clamped, 3)
    assert np.max(np.abs(err)) > 10.0
    err, torque = _wheels(kept, 100)
    assert np.max(np.abs(err[20:])) < 0.05 and np.max(np.abs(torque)) <= 400.0 * (1 + 1e-9)
    assert kept.provenance()["torque_limit_Nm"] == [400.0, 400.0]  # the limit the control keeps, said


def _turn_rate(plant, omega: float, seconds: float = 3.0) -> float:
    """The base's mean yaw rate (rad/s) over the last seconds - 1 of ``seconds`` turning in place at ``omega``."""
    plant.reset(np.zeros(3), np.random.default_rng(0))
    poses = []
    for _ in range(int(round(seconds / T))):
        plant.step(np.array([0.0, omega]))
        poses.append(plant.true_pose()[2])
    return (poses[-1] - poses[int(round(1 / T)) - 1]) / (seconds - 1)


@pytest.mark.menagerie
def test_a_skid_steer_turns_as_its_ik_asks_with_a_rotor_on_each_wheel():
    """TIAGo++ as modelled, four plain wheels: MuJoCo softens each friction direction of a contact in
    proportion to the inverse mass it moves, so a 1 kg wheel with no rotor grips along its rim far
    more softly than the robot's mass holds it across, and the skid-steer, which must scrub its
    wheels sideways to turn, turns at a few per cent of the rate asked. With the rotor inertia
    chosen (M r^2 / 4 on each wheel) and the track it turns as measured as it settles (1.09 m), it
    turns in place at 0.87 of the rate asked (with the rule W + L^2 / W, 0.98 m: 0.82)."""
    plant = MujocoPlant(MujocoConfig(model="menagerie:pal_tiago_dual"), T, (T,))
    width, base = 2 * 0.223175, 2 * 0.244
    assert plant.ik_track == plant.config.turning_track == pytest.approx(1.09)  # measured
    assert plant.ik_track > width + base**2 / width > width  # wider than the rule's 0.98 m, the wheels' 0.446 m
    assert plant.config.armature == pytest.approx(
        plant.model.body_subtreemass[plant.robot.root] * 0.0762**2 / 4, rel=5e-3
    )
    assert abs(_turn_rate(plant, 0.5) / 0.5 - 1) < 0.15  # 0.87 (0.82 with the rule)
    bare = MujocoPlant(MujocoConfig(model="menagerie:pal_tiago_dual", armature=0), T, (T,))
    assert bare.config.turning_track > 5  # 7.13 m: it barely turns, and asked more its wheels reach their limit
    assert _turn_rate(bare, 0.5) / 0.5 < 0.15


def test_the_track_a_skid_steer_turns_with():
    """Known answer: wheels 0.4 m across and 0.3 m front to rear turn as a track of 0.4 + 0.09 / 0.4 m."""
    anchors = [np.array(a, dtype=float) for a in ([0.15, 0.2, 0], [0.15, -0.2, 0], [-0.15, 0.2, 0], [-0.15, -0.2, 0])]
    assert skid_track(anchors) == pytest.approx((0.625, 0.3))


@pytest.mark.menagerie
def test_rby1a_is_refused_in_one_line_with_its_numbers_and_the_keys_that_make_it_drive():
    with pytest.raises(ConfigError) as err:
        MujocoPlant(MujocoConfig(model="menagerie:rainbow_robotics_rby1"), T)
    text = str(err.value)
    assert "\n" not in text and "kv 1" in text and "3.14 N m" in text and "damping 5" in text
    assert 'actuator = "torque"' in text
    drag = MujocoPlant  # as shipped, its base's collision mesh drags too: named when the skids are kept
    with pytest.raises(ConfigError, match=r'base drag \d+ N.*casters = "frictionless"'):
        drag(MujocoConfig(model="menagerie:rainbow_robotics_rby1", casters="model"), T)


# before-phase position RMS (m) kanayama must keep on eight-wheel-radius, each base from its name
# (rby1a: the shipped robot file with the torque drive); measured 0.2-0.5 mm, Stretch 3 1.2 mm,
# TIAGo++ (a skid-steer, its slip the controller's to close) 0.94 mm.
TRACKS = {"pal_tiago": 0.002, "hello_robot_stretch": 0.002, "rby1a": 0.002, "hello_robot_stretch_3": 0.003,
          "pal_tiago_dual": 0.003}  # fmt: skip


@pytest.mark.menagerie
@pytest.mark.parametrize("robot", sorted(TRACKS))
def test_eight_wheel_radius_tracks_on_each_base(tmp_path, monkeypatch, capsys, robot):
    monkeypatch.chdir(tmp_path)  # outside the repository
    argv = ["run", "eight-wheel-radius", "--robot", robot, "--controller", "kanayama", "--duration", "8"]
    assert main([*argv, "--no-log", "--no-plot", "--out", "run"]) == 0
    lines = capsys.readouterr().out.splitlines()  # what happened, then what was found and chosen
    assert lines[0].startswith(f"eight-wheel-radius+{robot} / kanayama / seed 0: tracking: ") and lines[1].startswith(
        "  robot: "
    )
    slowed = next(line for line in lines if line.startswith("  reference: reference x"))  # what --robot did to it
    k = float(slowed.split("reference x", 1)[1].split()[0])
    assert k == 1 or "what the file's 25 s drive of it now takes " in slowed, slowed
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["phases"]["before"]["rms_position_error_m"] < TRACKS[robot]


@pytest.mark.menagerie
def test_a_run_on_another_robot_reruns_from_its_config_toml(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = ["--controller", "kanayama", "--duration", "3", "--no-log", "--no-plot"]
    assert main(["run", "eight-payload", "--robot", "hello_robot_stretch", *argv, "--out", "a"]) == 0
    config = tomllib.loads((tmp_path / "a" / "config.toml").read_text())
    assert (
        config["plant"]["tendon_actuators"] == ["forward", "turn"]
        and config["name"] == "eight-payload+hello_robot_stretch"
    )
    assert main(["run", "a/config.toml", *argv, "--out", "b"]) == 0
    a, b = (json.loads((tmp_path / d / "metrics.json").read_text()) for d in "ab")
    assert a["phases"] == b["phases"]


def test_a_test_robot_with_an_arm_four_wheels_and_torque_motors_from_its_model_alone():
    plant = MujocoPlant(MujocoConfig(model=str(SKID_ARM)), T, (T,))
    found = plant.found()
    assert (found["left_actuator"], found["right_actuator"]) == ("m_fl", "m_fr")
    assert (found["left_actuator_2"], found["right_actuator_2"]) == ("m_rl", "m_rr")
    assert found["actuator"] == "torque" and found["keyframe"] == "home" and found["other_actuators"] == "lock"
    assert found["timestep"] == 0.0025 and plant.n_substeps == 4  # its 3 ms does not divide 10 ms
    assert set(plant.robot.locked) == {"shoulder", "elbow"} and plant.model.nu == 4
    assert "tyre" not in found  # cylinders above the floor's priority roll as they are
    # the pose is measured at its kinematic centre, measured as it settled: ahead of the middle of its
    # four wheels (its arm is forward), on the axles' height
    assert 0.05 < found["frame_offset"][0] < 0.15 and found["frame_offset"][1:] == [0.0, 0.0]
    assert plant.robot.site_rest[0][:2] == pytest.approx([found["frame_offset"][0], 0.0], abs=1e-3)


def test_keys_a_user_sets_still_win():
    cfg = MujocoConfig(model=str(SKID_ARM), timestep=0.001, other_actuators="hold", keyframe="home")
    plant = MujocoPlant(cfg, T, (T,))
    assert "timestep" not in plant.found() and "other_actuators" not in plant.found() and not plant.robot.locked
    assert plant.model.opt.timestep == 0.001 and plant.model.nu == 6


def test_any_scenario_on_the_test_robot_tracks(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = ["--controller", "kanayama", "--duration", "6", "--no-log", "--no-plot", "--out", "run"]
    assert main(["run", "eight-nominal", "--robot", str(SKID_ARM), *argv]) == 0
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["phases"]["before"]["rms_position_error_m"] < 0.005  # measured 2.7 mm (25 s run)


def test_the_reference_rule_on_a_robot_of_known_limits(tmp_path):
    """The wheel-speed limit of a drive without servos: its torque limit over its wheels' damping
    (4 N m / 1 N m s/rad = 4 rad/s); the reference slowed until its peak wheel speed is SHARE of it."""
    table = read_toml(shipped_dir() / "eight-nominal.toml", "scenario file")
    table["reference"] = {"kind": "eight", "wx": 4.0, "wy": 8.0}  # 16x the shipped eight's speed, far beyond this robot
    out = on_robot(table, str(SKID_ARM))
    plant = MujocoPlant(MujocoConfig(model=str(SKID_ARM)), T, (T,))
    r, b = plant.real_radius, plant._real_track
    assert out["controller"]["v_max"] == pytest.approx(r * 4, rel=1e-5)
    assert out["controller"]["omega_max"] == pytest.approx(2 * r * 4 / b, rel=1e-5)
    ref = out["reference"]
    assert ref["wy"] == pytest.approx(2 * ref["wx"], rel=1e-5) and ref["wx"] < 4.0
    rows = sample(make_reference("eight", {k: v for k, v in ref.items() if k != "kind"}), np.linspace(0, 100, 20001))
    peak = np.max((np.abs(rows[:, 3]) + np.abs(rows[:, 4]) * b / 2) / r)
    assert peak == pytest.approx(SHARE * 4, rel=1e-3)
    assert out["plant"] == {"kind": "mujoco", "model": str(SKID_ARM), "pose_noise_std": 0.001}


def test_events_mean_the_same_physical_change():
    table = {"name": "x", "events": [{"time": 1.0, "kind": "payload", "mass_kg": 2.0, "body": "chassis_top"}]}
    table["events"].append({"time": 2.0, "kind": "wheel_radius", "scale": 1.5})
    out = on_robot(table, str(SKID_ARM))
    assert out["events"] == [
        {"time": 1.0, "kind": "payload", "mass_kg": 2.0},  # on this robot's base: its body is not there
        {"time": 2.0, "kind": "wheel_radius", "scale": 1.5},  # x1.5 of this robot's wheel
    ]


def test_robots_are_an_axis_of_a_sweep(tmp_path, monkeypatch, capsys):
    assert with_robots(["a", "b"], ["diffdrive", "cart"]) == ["a@diffdrive", "a@cart", "b@diffdrive", "b@cart"]
    monkeypatch.chdir(tmp_path)
    argv = ["compare", "eight-nominal", "--robots", f"diffdrive,{SKID_ARM}", "--controllers", "kanayama"]
    assert main([*argv, "--seeds", "0", "--duration", "3", "--out", "c", "--workers", "1"]) == 0
    rows = json.loads((tmp_path / "c" / "compare.json").read_text())["rows"]
    assert {r["scenario"] for r in rows} == {"eight-nominal+diffdrive", "eight-nominal+skid_arm"}


def test_a_budget_runs_each_scenario_on_its_robots(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "skid.xml").write_text(SKID_ARM.read_text())
    budget = tmp_path / "budget.toml"
    budget.write_text(
        'scenarios = ["eight-nominal"]\nrobots = ["diffdrive", "skid.xml"]\ncontrollers = ["kanayama"]\n'
        'seeds = "0"\nduration = 3.0\n[[budget]]\nscenario = "eight-nominal"\nmax_position_rms_mm = 50.0\n'
    )
    assert main(["check", str(budget), "--out", "c", "--workers", "1"]) == 0
    assert "2 of 2 budget cases hold" in capsys.readouterr().out  # one case a robot, the limit on both
    assert main(["check", str(budget), "--out", "d", "--workers", "1", "--robot", "nosuch"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--robot" in err and not (tmp_path / "d").exists()


@pytest.mark.menagerie
def test_list_says_what_each_menagerie_base_does_as_shipped(tmp_path, monkeypatch, capsys):
    """What `mlpfac list` says of a base as shipped is what it does: RB-Y1A refused (above), TIAGo++ a
    skid-steer that tracks."""
    assert main(["list"]) == 0
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line.startswith("  ")}
    assert "refused as shipped" in lines["rainbow_robotics_rby1"] and "skid-steer" in lines["pal_tiago_dual"]
    assert "MENAGERIE_ROOT=" in lines["pal_tiago"] and ";" not in lines["pal_tiago"]
    monkeypatch.chdir(tmp_path)
    argv = ["run", "eight-nominal", "--robot", "pal_tiago_dual", "--controller", "kanayama", "--duration", "4"]
    main([*argv, "--no-log", "--no-plot", "--out", "run"])
    assert json.loads((tmp_path / "run" / "metrics.json").read_text())["outcome"] == "tracking"


# A scenario file that names its robot and nothing of the reference's speed: the [plant] keys of
# each base (rby1a: the shipped robot file's, rainbow_robotics_rby1 being refused as shipped).
FILE_PLANTS = {name: {"model": f"menagerie:{name}"} for name in BASES} | {"rby1a": robot_table("rby1a")}


def bare_file(tmp_path: Path, robot: str, reference: str = "", duration: float = 8.0) -> Path:
    plant = {"kind": "mujoco"} | FILE_PLANTS[robot]
    keys = "".join(f"{k} = {json.dumps(v)}\n" for k, v in plant.items())
    path = tmp_path / f"bare-{robot}.toml"
    path.write_text(f'name = "bare-{robot}"\nduration = {duration}\n{reference}\n[plant]\n{keys}')
    return path


@pytest.mark.menagerie
@pytest.mark.parametrize("robot", sorted(FILE_PLANTS))
def test_a_file_naming_its_robot_gets_the_reference_fitted_by_the_rule_of_robot(tmp_path, monkeypatch, capsys, robot):
    """Before, the default eight on TIAGo from its model alone was lost at 1.61 m RMS (Stretch 3: 2.88 m)."""
    monkeypatch.chdir(tmp_path)
    argv = ["--controller", "kanayama", "--no-log", "--no-plot"]
    assert main(["run", str(bare_file(tmp_path, robot)), *argv, "--out", "a"]) == 0
    lines = capsys.readouterr().out.splitlines()  # what happened; what was found; what was done to the reference
    first = lines[2]
    assert lines[1].startswith("  robot: ") and first.startswith("  reference: reference x")
    assert "(the rule of --robot)" in first
    config = tomllib.loads((tmp_path / "a" / "config.toml").read_text())
    table = read_toml(shipped_dir() / "eight-nominal.toml", "scenario") | {"duration": 8.0}  # the file's
    same = on_robot(table, robot)  # the one rule: the same reference and controller limits as --robot
    assert config["reference"] == same["reference"] and config["reference"]["wx"] < 0.25
    assert {k: config["controller"][k] for k in ("v_max", "omega_max")} == {
        k: same["controller"][k] for k in ("v_max", "omega_max")
    }
    assert config["provenance"]["reference_fit"] in first
    a = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert a["phases"]["before"]["rms_position_error_m"] < TRACKS.get(robot, 0.003)
    assert main(["run", "a/config.toml", *argv, "--out", "b"]) == 0  # config.toml runs the same, not fitted again
    assert "reference_fit" not in tomllib.loads((tmp_path / "b" / "config.toml").read_text())["provenance"]
    assert json.loads((tmp_path / "b" / "metrics.json").read_text())["phases"] == a["phases"]


@pytest.mark.menagerie
@pytest.mark.parametrize("robot", sorted(FILE_PLANTS))
def test_a_reference_the_robot_cannot_drive_is_said_in_numbers(tmp_path, robot):
    """Warned, not refused: a reference beyond the wheels is an experiment of its own (a --vary
    reference.speed axis past the limit); the run goes on, told the peak asked against the limit."""
    from mlpfac.plants.mjcf.robot import read_robot
    from mlpfac.plants.mjcf.wheels import wheel_speed_limit
    from mlpfac.scenario.on_robot import peak_wheel_speed
    from mlpfac.scenario.parse import load

    eight = '[reference]\nkind = "eight"\nspeed = {}\n'  # over a whole eight even slowed 20x (the peak's window: 4 x duration)
    fast = load(bare_file(tmp_path, robot, eight.format(1.0), duration=200.0))
    r = read_robot(fast.plant_config, (T,))
    peak, w_max = peak_wheel_speed(fast.reference, fast.duration, r), wheel_speed_limit(r)
    said = fast.table["provenance"]["reference_warning"]
    assert peak > w_max and f"peak wheel speed of {peak:.3g} rad/s of wheels that give {w_max:.3g} rad/s" in said
    assert fast.reference.speed == 1.0 and "reference_fit" not in fast.table["provenance"]  # run as written
    speed = float(said.rsplit("speed = ", 1)[1].split()[0])  # what it suggests drives it at SHARE of the limit
    slow = load(bare_file(tmp_path, robot, eight.format(speed), duration=200.0))
    assert "reference_warning" not in slow.table["provenance"]
    assert peak_wheel_speed(slow.reference, slow.duration, r) == pytest.approx(SHARE * w_max, rel=5e-3)


@pytest.mark.menagerie
def test_the_warning_follows_the_outcome_first_of_what_a_run_says(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    path = bare_file(tmp_path, "pal_tiago", '[reference]\nkind = "eight"\nwx = 0.25\nwy = 0.5\n')
    assert main(["run", str(path), "--controller", "kanayama", "--duration", "1", "--no-log", "--no-plot"]) == 0
    lines = capsys.readouterr().out.splitlines()  # what happened, then the warning first of what was read and done
    assert lines[0].startswith(f"{path.stem} / kanayama / seed 0: ")
    assert lines[1].startswith("  warning: the reference asks a peak wheel speed of 11.4 rad/s of wheels that give 5")
    assert lines[2].startswith("  robot: ") and not any(line.startswith("  reference:") for line in lines)
