"""Every bad input we know of: one line on stderr naming the file, key or flag, exit code 2, no
traceback, and nothing written. Add a row for each new case found."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from mlpfac.cli import main
from mlpfac.scenario.parse import scenario_names, shipped_dir

MINIMAL = 'duration = 0.5\n[plant]\nkind = "kinematic"\n'
EVENT = '[[events]]\ntime = 0.2\nkind = "control_period"\nfactor = 1.5\n'
ROBOT = '[plant]\nkind = "mujoco"\n'
EV = '[[events]]\ntime = 0.2\nkind = "{}"\n{}\n'  # an event of a kind, with its parameters

# name: (file content, text the message must hold). The file's path must appear in the message too.
BAD_FILES: dict[str, tuple[str | bytes, str]] = {
    "binary": (b"\x00\x01\x02\xff\xfe" * 10, "not a text file"),
    "latin-1": ('name = "caf\xe9"\n'.encode("latin-1"), "not a text file"),
    "not toml": ("duration = = 3\n", "not valid TOML"),
    "unknown top key": ("durations = 3\n", "durations"),
    "duration string": ('duration = "long"\n', "duration"),
    "duration inf": ("duration = inf\n", "duration"),
    "T zero": ("T = 0.0\n", "T"),
    "T nan": ("T = nan\n", "T"),
    "duration below T": ("duration = 0.001\n", "shorter than one control period"),
    "duration huge": ("duration = 1e9\n", "GiB"),
    "T tiny": ("T = 1e-12\n", "GiB"),
    "seed negative": ("seed = -1\n", "seed"),
    "seed float": ("seed = 1.5\n", "seed"),
    "name with a slash": ('name = "../../etc"\n', "name"),
    "name empty": ('name = ""\n', "name"),
    "description table": ("[description]\nx = 1\n", "description"),
    "reference a string": ('reference = "eight"\n', "reference"),
    "reference kind": ('[reference]\nkind = "spiral"\n', "spiral"),
    "reference bool param": ('[reference]\nkind = "eight"\na = true\n', "[reference] a"),
    "initial error short": ("[initial]\nerror = [0.1]\n", "error"),
    "initial error text": ('[initial]\nerror = ["a", 0.0, 0.0]\n', "error"),
    "initial moving": ('[initial]\nmoving = "yes"\n', "moving"),
    "plant a list": ("plant = [1, 2]\n", "plant"),
    "plant kind": ('[plant]\nkind = "hovercraft"\n', "hovercraft"),
    "noise negative": ('[plant]\nkind = "kinematic"\nnoise_cov = -1e-6\n', "noise_cov"),
    "controller name": ('[controller]\nname = "pid"\n', "pid"),
    "lambda outside": ("[controller]\nlambdas = [0.8, 1.1, 0.8]\n", "lambdas"),
    "lambda text": ('[controller]\nlambdas = [0.8, "x", 0.8]\n', "lambdas"),
    "v_max negative": ("[controller]\nv_max = -1.0\n", "v_max"),
    "v_max nan": ("[controller]\nv_max = nan\n", "v_max"),
    "L_f float": ("[controller.adaptive]\nL_f = 18.5\n", "L_f"),
    "L_f zero": ("[controller.adaptive]\nL_f = 0\n", "L_f"),
    "L_f huge": ("[controller.adaptive]\nL_f = 100000\n", "GiB"),
    "P0 inf": ("[controller.adaptive]\nP0 = inf\n", "P0"),
    "R negative": ("[controller.adaptive]\nR = -1.0\n", "R"),
    "mpc horizon zero": (ROBOT + '[controller]\nname = "mpc"\n[controller.mpc]\nhorizon_s = 0.0\n', "horizon_s"),
    "mpc knots float": (ROBOT + '[controller]\nname = "mpc"\n[controller.mpc]\nknots = 2.5\n', "knots"),
    "mpc unknown key": (ROBOT + '[controller]\nname = "mpc"\n[controller.mpc]\nhorizon = 0.3\n', "horizon"),
    "mpc a string": (ROBOT + '[controller]\nname = "mpc"\n[controller.mpc]\naccel_std = "x"\n', "accel_std"),
    "mpc on the kinematic plant": ('[controller]\nname = "limit"\n', "MuJoCo robot as its model"),
    "estimator": ('[controller.adaptive]\nestimator = "pf"\n', "estimator"),
    "prior text": ('[controller.adaptive]\nprior = "yes"\n', "prior"),
    "velocity_inputs text": ('[controller.adaptive]\nvelocity_inputs = 1\n', "velocity_inputs"),
    "input_gains text": ('[controller.adaptive]\ninput_gains = "yes"\n', "input_gains"),
    "input_delay negative": ("[controller.adaptive]\ninput_delay = -1\n", "input_delay"),
    "input_delay float": ("[controller.adaptive]\ninput_delay = 2.5\n", "input_delay"),
    "input_delay huge": ("[controller.adaptive]\ninput_delay = 1000\n", "input_delay"),
    "input_P0 zero": ("[controller.adaptive]\ninput_P0 = 0.0\n", "input_P0"),
    "input_forgetting above 1": ("[controller.adaptive]\ninput_forgetting = 1.5\n", "input_forgetting"),
    "detect negative": ("[controller.adaptive]\ndetect = -1.0\n", "detect"),
    "law_form": ('[controller.adaptive]\nlaw_form = "pid"\n', "law_form"),
    "law_form number": ("[controller.adaptive]\nlaw_form = 35\n", "law_form"),
    "law_form kanayama with ukf": ('[controller.adaptive]\nlaw_form = "kanayama"\nestimator = "ukf"\n', "law_form"),
    "delay_finder": ('[controller.adaptive]\ndelay_finder = "guess"\n', "delay_finder"),
    "law_gains short": ("[controller.adaptive]\nlaw_gains = [10.0, 150.0]\n", "law_gains"),
    "law_gains negative": ("[controller.adaptive]\nlaw_gains = [10.0, -1.0, 12.0]\n", "law_gains"),
    "detect nan": ("[controller.adaptive]\ndetect = nan\n", "detect"),
    "detect_mean negative": ("[controller.adaptive]\ndetect_mean = -1.0\n", "detect_mean"),
    "detect_mean nan": ("[controller.adaptive]\ndetect_mean = nan\n", "detect_mean"),
    "input_P_alarm negative": ("[controller.adaptive]\ninput_P_alarm = -0.1\n", "input_P_alarm"),
    "input_P_alarm text": ('[controller.adaptive]\ninput_P_alarm = "wide"\n', "input_P_alarm"),
    "detect_mean without detect": ("[controller.adaptive]\ndetect_mean = 20.0\n", "detect_mean"),
    "input_P_alarm without detect_mean": ("[controller.adaptive]\ndetect = 50.0\ninput_P_alarm = 0.02\n", "input_P_alarm"),
    "kanayama gain": ("[controller.kanayama]\nKx = -1.0\n", "Kx"),
    "events not tables": ("events = [1, 2]\n", "events"),
    "events a table": ("[events]\ntime = 1\n", "events"),
    "event time negative": ('[[events]]\ntime = -1.0\nkind = "control_period"\nfactor = 1.5\n', "time"),
    "event time inf": ('[[events]]\ntime = inf\nkind = "control_period"\nfactor = 1.5\n', "time"),
    "event beyond the run": ('duration = 1.0\n[[events]]\ntime = 5.0\nkind = "control_period"\nfactor = 1.5\n', "never happen"),
    "event kind": ('[[events]]\ntime = 1.0\nkind = "teleport"\n', "teleport"),
    "event stray param on kinematic": (MINIMAL + EVENT + "colour = 1\n", "colour"),
    "event factor negative": (MINIMAL + '[[events]]\ntime = 0.2\nkind = "control_period"\nfactor = -1.0\n', "factor"),
    "event steps float": (MINIMAL + '[[events]]\ntime = 0.2\nkind = "sensor_delay"\nsteps = 1.5\n', "steps"),
    "event missing param": (MINIMAL + '[[events]]\ntime = 0.2\nkind = "control_period"\n', "factor"),
    "event not on kinematic": (MINIMAL + '[[events]]\ntime = 0.2\nkind = "friction"\nmu = 0.2\n', "kinematic plant cannot"),
    "friction negative": (ROBOT + '[[events]]\ntime = 0.2\nkind = "friction"\nmu = -1.0\n', "mu"),
    "payload body": (ROBOT + '[[events]]\ntime = 0.2\nkind = "payload"\nmass_scale = 2.0\nbody = "trailer"\n', "trailer"),
    "control period not whole steps": (ROBOT + 'timestep = 0.002\n[[events]]\ntime = 0.2\nkind = "control_period"\nfactor = 1.3\n', "whole number"),
    "model missing": ('[plant]\nkind = "mujoco"\nmodel = "nope.xml"\n', "not found"),
    "model not mjcf": ('[plant]\nkind = "mujoco"\nmodel = "scenario.toml"\n', "MuJoCo cannot load"),
    "actuator name": ('[plant]\nkind = "mujoco"\nleft_actuator = "nosuch"\n', "[plant] left_actuator"),
    "site name": ('[plant]\nkind = "mujoco"\nsite = "nosuch"\n', "[plant] site"),
    "T not whole physics steps": ('T = 0.011\n[plant]\nkind = "mujoco"\ntimestep = 0.002\n', "[plant] T"),
    "pose noise negative": ('[plant]\nkind = "mujoco"\npose_noise_std = -0.001\n', "pose_noise_std"),
    "provenance of another model": ('[plant]\nkind = "mujoco"\n[provenance]\nmodel_sha256 = "0"\n', "model_sha256"),
    "provenance a string": ('provenance = "x"\n', "provenance"),
    "pose body name": (ROBOT + 'site = "axle_mid"\nbody = "chassis"\n', "[plant] body"),
    "pose body missing": (ROBOT + 'body = "nosuch"\n', "[plant] body"),
    "frame offset short": (ROBOT + "frame_offset = [0.0, 0.1]\n", "frame_offset"),
    "keyframe missing": (ROBOT + 'keyframe = "home"\n', "[plant] keyframe"),
    "other actuators": (ROBOT + 'other_actuators = "drop"\n', "other_actuators"),
    "tyre shape": (ROBOT + 'tyre = "tank"\n', "[plant] tyre"),
    "timestep negative": (ROBOT + "timestep = -0.002\n", "[plant] timestep"),
    "timestep not dividing T": (ROBOT + "timestep = 0.003\n", "[plant] T"),
    "max wheel speed zero": (ROBOT + "max_wheel_speed = 0.0\n", "max_wheel_speed"),
    "turning track zero": (ROBOT + "turning_track = 0.0\n", "turning_track"),
    "turning track a string": (ROBOT + 'turning_track = "wide"\n', "turning_track"),
    "menagerie no robot": ('[plant]\nkind = "mujoco"\nmodel = "menagerie:"\n', "menagerie:ROBOT/ENTRY"),
    "menagerie robot unknown": ('[plant]\nkind = "mujoco"\nmodel = "menagerie:pal_tiagoo/scene"\n', "pal_tiago"),
    "menagerie entry unknown": ('[plant]\nkind = "mujoco"\nmodel = "menagerie:pal_tiago/scene_fast"\n', "scene_velocity"),
    "payload on every body of the kinematic": (MINIMAL + '[[events]]\ntime = 0.2\nkind = "payload"\nmass_kg = 2.0\nbody = "*"\n', "kinematic plant cannot"),
    "casters choice": (ROBOT + 'casters = "wheels"\n', "[plant] casters"),
    "servo_limit choice": (ROBOT + 'servo_limit = "joint"\n', "[plant] servo_limit"),
    "armature negative": (ROBOT + "armature = -0.1\n", "[plant] armature"),
    "armature absurd": (ROBOT + "armature = 1e9\n", "[plant] armature"),
    "armature nan": (ROBOT + "armature = nan\n", "[plant] armature"),
    "armature a word": (ROBOT + 'armature = "heavy"\n', "[plant] armature"),
    "tendon actuators one": (ROBOT + 'tendon_actuators = ["forward"]\n', "tendon_actuators"),
    "tendon and wheel actuators": (ROBOT + 'tendon_actuators = ["a", "b"]\nleft_actuator = "c"\n', "not both"),
    "second wheel missing": (ROBOT + 'left_actuator_2 = "nosuch"\n', "[plant] left_actuator_2"),
    "payload mass and scale": (ROBOT + '[[events]]\ntime = 0.2\nkind = "payload"\nmass_kg = 2.0\nmass_scale = 2.0\n', "either"),
    "reference kind a list": ('[reference]\nkind = ["eight"]\n', "unknown reference kind ['eight']"),
    "reference wx huge": ("[reference]\nwx = 1e308\n", "[reference] wx: must lie within"),
    "reference size huge": ('[reference]\nkind = "circle"\nradius = 1e300\n', "[reference] radius"),
    "reference speed zero": ("[reference]\nspeed = 0.0\n", "[reference] speed: must be > 0"),
    "reference speed negative": ("[reference]\nspeed = -1.0\n", "[reference] speed: must be > 0"),
    "reference speed huge": ("[reference]\nspeed = 1e9\n", "[reference] speed: must lie within"),
    "reference speed beyond a robot": ("[reference]\nspeed = 50.0\n", "beyond a wheeled robot's"),
    "line speed is a factor, v its m/s": ('[reference]\nkind = "line"\nv = 30.0\n', "[reference] v: must lie within"),
    "reference faster than a robot": ('[reference]\nkind = "circle"\nradius = 1000.0\nrate = 1.0\n', "beyond a wheeled robot's"),
    "reference speed 1e-300": ("[reference]\nspeed = 1e-300\n", "[reference]: the reference speed v_r must stay above zero"),
    "reference of radius 0": ('[reference]\nkind = "circle"\nradius = 0.0\n', "[reference]: the reference speed v_r must stay above zero"),
    "arrays nested 3000 deep": ("x = " + "[" * 3000 + "]" * 3000 + "\n", "nested too deep"),
    "timestep 1e-7": (ROBOT + "timestep = 1e-7\n", "[plant] timestep: 1e-07 s is outside"),
    "timestep 1e-9": (ROBOT + "timestep = 1e-9\n", "[plant] timestep"),
    "timestep a second": (ROBOT + "timestep = 1.0\n", "[plant] timestep"),
    "control period factor 1e15": (MINIMAL + EV.format("control_period", "factor = 1e15"), "factor: must be <= 100"),
    "control period beyond the physics limit": (ROBOT + "timestep = 1e-5\n" + EV.format("control_period", "factor = 20.0"), "limit is 10000 per control period"),
    "physics steps of the run beyond the limit": ('duration = 11000.0\nT = 0.1\n[controller]\nname = "corradini"\n' + ROBOT + "timestep = 1e-5\n", "physics steps; the limit is 1e+09 per run"),
    "payload mass_scale 1e300": (MINIMAL + EV.format("payload", "mass_scale = 1e300"), "mass_scale: must be <="),
    "payload mass_scale 1e-300": (MINIMAL + EV.format("payload", "mass_scale = 1e-300"), "mass_scale: must be >="),
    "payload mass_kg 1e300": (MINIMAL + EV.format("payload", "mass_kg = 1e300"), "mass_kg: must be <="),
    "friction 1e300": (MINIMAL + EV.format("friction", "mu = 1e300"), "mu: must be <="),
    "friction 1e-300": (MINIMAL + EV.format("friction", "mu = 1e-300"), "mu: must be >="),
    "wheel radius 1e300": (MINIMAL + EV.format("wheel_radius", "scale = 1e300"), "scale: must be <="),
    "wheel radius 1e-300": (MINIMAL + EV.format("wheel_radius", "scale = 1e-300"), "scale: must be >="),
    "actuator kv 1e300": (MINIMAL + EV.format("actuator", "kv_scale = 1e300"), "kv_scale: must be <="),
    "actuator force 1e-300": (MINIMAL + EV.format("actuator", "force_scale = 1e-300"), "force_scale: must be >="),
    "initial error huge": ("[initial]\nerror = [1e308, 0.0, 0.0]\n", "[initial] error"),
    "pose noise huge": (ROBOT + "pose_noise_std = 1e300\n", "[plant] pose_noise_std"),
    "sensor delay 1e15 steps": (MINIMAL + EV.format("sensor_delay", "steps = 1000000000000000"), "steps: must be <= 10000"),
    "uniform reversed": (MINIMAL + EVENT.replace("1.5", "{ uniform = [2.0, 1.0] }"), "events.0.factor: uniform needs low < high"),
    "uniform of text": (MINIMAL + EVENT.replace("1.5", '{ uniform = ["a", 2.0] }'), "events.0.factor: uniform takes two"),
    "normal sd zero": (MINIMAL + EVENT.replace("1.5", "{ normal = [1.5, 0.0] }"), "standard deviation > 0"),
    "distribution unknown": (MINIMAL + EVENT.replace("1.5", "{ lognormal = [1.5, 0.1] }"), "factor"),
    "lost_threshold_m zero": ("lost_threshold_m = 0.0\n", "lost_threshold_m: must be a number of metres above 0"),
    "lost_threshold_m a word": ('lost_threshold_m = "far"\n', "lost_threshold_m: expected a number of metres"),
    "drawn without a distribution": (MINIMAL + "[drawn]\nduration = 0.5\n", "[drawn] duration: no distribution"),
    "a distribution's low end out of range": (ROBOT + "[world]\npatches = [{ x = 1.0, y = 1.73, radius = 0.4, mu = { uniform = [-1.0, 0.5] } }]\n", "world.patches.0.mu = uniform(-1, 0.5) (its end -1): must be positive"),
    "a distribution's ends out of range": (ROBOT + 'pose_source = "odometry"\ngyro = true\ngyro_bias = { uniform = [-20, 20] }\n', "plant.gyro_bias = uniform(-20, 20) (its end -20)"),
    "a normal's end out of range": (MINIMAL + EVENT.replace("1.5", "{ normal = [1.5, 1.0] }"), "events.0.factor = normal(1.5, 1) (its end -1.5)"),
    "drawn a string": (MINIMAL + 'drawn = "x"\n', "drawn"),
    "torque-level controller on the kinematic plant": (MINIMAL + '[controller]\nname = "fierro-lewis"\n', '[plant] kind: fierro-lewis is a torque-level controller'),
    "torque-level controller on velocity servos": ('duration = 0.5\n[controller]\nname = "adaptive-dynamic"\n' + ROBOT + 'actuator = "velocity"\n', '[plant] actuator: adaptive-dynamic is a torque-level controller'),
    "twist noise huge": (ROBOT + "twist_noise_std = 1e300\n", "[plant] twist_noise_std"),
    "twist noise three numbers": (ROBOT + "twist_noise_std = [0.1, 0.1, 0.1]\n", "[plant] twist_noise_std"),
    "wheel speed noise negative": (ROBOT + "wheel_speed_noise_std = -0.1\n", "[plant] wheel_speed_noise_std"),
    "PI gain zero": (ROBOT + 'actuator = "torque"\npi_kp = 0.0\n', "[plant] pi_kp"),
    "path without waypoints": ('[reference]\nkind = "path"\n', "[reference]: a path takes its waypoints from points"),
    "path points and file": ('[reference]\nkind = "path"\npoints = [[0, 0], [1, 0]]\nfile = "r.csv"\n', "give one"),
    "path one waypoint": ('[reference]\nkind = "path"\npoints = [[0, 0]]\n', "[reference] points: an open path needs at least 2 waypoints"),
    "path closed of two": ('[reference]\nkind = "path"\nclosed = true\npoints = [[0, 0], [1, 0]]\n', "a closed path needs at least 3"),
    "path repeated waypoint": ('[reference]\nkind = "path"\npoints = [[0, 0], [1, 0], [1, 0], [1, 1]]\n', "waypoint 3 repeats the waypoint before it"),
    "path waypoint nan": ('[reference]\nkind = "path"\npoints = [[0, 0], [1, nan]]\n', "waypoint 2: (1, nan) must be finite"),
    "path waypoint far": ('[reference]\nkind = "path"\npoints = [[0, 0], [1e6, 0]]\n', "within +-10000 m"),
    "path waypoint of three": ('[reference]\nkind = "path"\npoints = [[0, 0], [1, 0, 0]]\n', "waypoint 2: expected [x, y]"),
    "path waypoint text": ('[reference]\nkind = "path"\npoints = [[0, 0], ["a", 0]]\n', "waypoint 2: expected [x, y]"),
    "path points a number": ('[reference]\nkind = "path"\npoints = 3\n', "[reference] points: expected a list"),
    "path turning back": ('[reference]\nkind = "path"\npoints = [[0, 0], [2, 0], [0, 0.1]]\n', "waypoint 2 turns the route back on itself"),
    "path closed a word": ('[reference]\nkind = "path"\nclosed = "yes"\npoints = [[0, 0], [1, 0]]\n', "[reference] closed"),
    "path v_max zero": ('[reference]\nkind = "path"\nv_max = 0.0\npoints = [[0, 0], [1, 0]]\n', "[reference] v_max: must be > 0"),
    "path a_max nan": ('[reference]\nkind = "path"\na_max = nan\npoints = [[0, 0], [1, 0]]\n', "[reference] a_max: expected a finite number"),
    "path track negative": ('[reference]\nkind = "path"\ntrack = -0.3\npoints = [[0, 0], [1, 0]]\n', "[reference] track: must be >= 0"),
    "path radius huge": ('[reference]\nkind = "path"\nradius = 1e9\npoints = [[0, 0], [1, 0]]\n', "[reference] radius"),
    "path a curve's key": ('[reference]\nkind = "path"\nwx = 0.2\npoints = [[0, 0], [1, 0]]\n', "not a parameter of 'path'"),
    "path too long to time": ('[reference]\nkind = "path"\nclosed = true\npoints = [[0, 0], [9999, 0], [9999, 9999], [0, 9999]]\n', "grid points to be timed"),
    "path too many waypoints": ('[reference]\nkind = "path"\npoints = [' + ", ".join(f"[{i}, {i % 2}]" for i in range(1001)) + "]\n", "at most 1000"),
    "path file missing": ('[reference]\nkind = "path"\nfile = "nope.csv"\n', "[reference] file: "),
    "path file a number": ('[reference]\nkind = "path"\nfile = 3\n', "[reference] file: expected the path of a CSV file"),
    "path file a folder": ('[reference]\nkind = "path"\nfile = "."\n', "is a folder"),
    "own reference file missing": ('[reference]\nkind = "nope.py:Route"\n', "[reference] kind: "),
    "own reference module missing": ('[reference]\nkind = "no_such_pkg.routes:Route"\n', "no module named 'no_such_pkg'"),
    "own reference a curve's key": ('[reference]\nkind = "nope.py:Route"\nwx = 1.0\n', "not a key of your own reference"),
    "own reference params a number": ('[reference]\nkind = "nope.py:Route"\nparams = 3\n', "[reference] params: expected a table"),
    "own reference speed zero": ('[reference]\nkind = "nope.py:Route"\nspeed = 0\n', "[reference] speed"),
    "drawn not the seed's draw": (MINIMAL + EVENT.replace("1.5", "{ uniform = [1.0, 2.0] }") + '[drawn]\n"events.0.factor" = 1.0\n', "is not what seed 0 draws"),
    # the pose source ([plant] pose_source, mlpfac.plants.sensors.sensing)
    "pose source unknown": (ROBOT + 'pose_source = "gps"\n', "[plant] pose_source: choose"),
    "pose source a number": (ROBOT + "pose_source = 1\n", "[plant] pose_source"),
    "pose source on the kinematic plant": (MINIMAL + 'pose_source = "odometry"\n', "[plant] pose_source: 'odometry': the kinematic plant"),
    "gyro on the kinematic plant": (MINIMAL + "gyro = true\n", "[plant] gyro: the kinematic plant"),
    "gyro a word": (ROBOT + 'pose_source = "odometry"\ngyro = "yes"\n', "[plant] gyro"),
    "gyro with the truth": (ROBOT + "gyro = true\n", '[plant] gyro: senses nothing with pose_source = "truth"'),
    "encoder cpr with the truth": (ROBOT + "encoder_cpr = 1024\n", "[plant] encoder_cpr: senses nothing"),
    "encoder cpr zero": (ROBOT + 'pose_source = "odometry"\nencoder_cpr = 0\n', "[plant] encoder_cpr"),
    "encoder cpr a fraction": (ROBOT + 'pose_source = "odometry"\nencoder_cpr = 1024.5\n', "[plant] encoder_cpr"),
    "encoder cpr huge": (ROBOT + 'pose_source = "odometry"\nencoder_cpr = 10000000000\n', "[plant] encoder_cpr"),
    "gyro noise without a gyro": (ROBOT + 'pose_source = "odometry"\ngyro_noise = 0.01\n', "[plant] gyro_noise: needs a gyro"),
    "gyro noise negative": (ROBOT + 'pose_source = "odometry"\ngyro = true\ngyro_noise = -0.01\n', "[plant] gyro_noise"),
    "gyro bias huge": (ROBOT + 'pose_source = "odometry"\ngyro = true\ngyro_bias = 1e300\n', "[plant] gyro_bias"),
    "pose noise with odometry": (ROBOT + 'pose_source = "odometry"\npose_noise_std = 0.001\n', '[plant] pose_noise_std: is the noise of what pose_source = "truth" gives'),
    "twist noise with fused": (ROBOT + 'pose_source = "fused"\ntwist_noise_std = 0.01\n', "[plant] twist_noise_std"),
    "fix rate with odometry": (ROBOT + 'pose_source = "odometry"\nfix_rate_hz = 10.0\n', '[plant] fix_rate_hz: takes fixes, which pose_source = "odometry" has none of'),
    "fix noise with the truth": (ROBOT + "fix_noise_m = 0.02\n", "[plant] fix_noise_m: senses nothing"),
    "fix rate zero": (ROBOT + 'pose_source = "fused"\nfix_rate_hz = 0.0\n', "[plant] fix_rate_hz: must be positive"),
    "fix rate negative": (ROBOT + 'pose_source = "fused"\nfix_rate_hz = -5.0\n', "[plant] fix_rate_hz: must be positive"),
    "fix rate inf": (ROBOT + 'pose_source = "fused"\nfix_rate_hz = inf\n', "[plant] fix_rate_hz"),
    "fix rate above the control rate": (ROBOT + 'pose_source = "fused"\nfix_rate_hz = 1000.0\n', "[plant] fix_rate_hz: 1000 Hz is more than one fix a control step"),
    "fix latency negative": (ROBOT + 'pose_source = "fused"\nfix_latency_s = -0.1\n', "[plant] fix_latency_s: must be >= 0"),
    "fix latency longer than the run": ("duration = 1.0\n" + ROBOT + 'pose_source = "fused"\nfix_latency_s = 2.0\n', "[plant] fix_latency_s: 2 s is not shorter than the run"),
    "fix noise negative": (ROBOT + 'pose_source = "fused"\nfix_noise_m = -0.02\n', "[plant] fix_noise_m"),
    "fix heading noise huge": (ROBOT + 'pose_source = "fused"\nfix_noise_rad = 1e300\n', "[plant] fix_noise_rad"),
    "fix noise a word": (ROBOT + 'pose_source = "fused"\nfix_noise_m = "small"\n', "[plant] fix_noise_m"),
    # the world around the robot: slopes, forces, [world] (docs/scenarios.md)
    "slope past the limit": (ROBOT + EV.format("slope", "angle_deg = 31.0"), "angle_deg: must be <= 30"),
    "slope negative": (ROBOT + EV.format("slope", "angle_deg = -1.0"), "angle_deg: must be >= 0"),
    "slope heading a word": (ROBOT + EV.format("slope", 'angle_deg = 5.0\nheading_deg = "north"'), "heading_deg: expected a finite number"),
    "slope on the kinematic plant": (MINIMAL + EV.format("slope", "angle_deg = 5.0"), "kinematic plant cannot apply a 'slope'"),
    "force of nothing": (ROBOT + EV.format("force", 'frame = "world"'), "needs 'fx', 'fy', 'torque_z' or 'std'"),
    "force frame": (ROBOT + EV.format("force", 'fx = 1.0\nframe = "chassis"'), "frame: choose 'world' or 'robot'"),
    "force periodic and noise": (ROBOT + EV.format("force", "fx = 1.0\nperiod = 1.0\nstd = 1.0"), "period: not with 'std': a force is periodic or noise"),
    "force in newtons and a share": (ROBOT + EV.format("force", "fx = 1.0\nfx_mg = 0.1"), "fx: not with 'fx_mg': one way of giving the force along x"),
    "force share and push": (ROBOT + EV.format("force", "fy_mg = 0.1\ndv_y = 1.0\nduration = 0.2"), "fy_mg: not with 'dv_y'"),
    "force push of no duration": (ROBOT + EV.format("force", "dv_y = 1.0"), "dv_y: needs 'duration': the push's impulse m dv"),
    "force push periodic": (ROBOT + EV.format("force", "dv_x = 1.0\nduration = 0.2\nperiod = 1.0"), "period: not with 'dv_x'"),
    "force noise twice": (ROBOT + EV.format("force", "std = 1.0\nstd_mg = 0.1"), "std: not with 'std_mg'"),
    "force gust of no noise": (ROBOT + EV.format("force", "fx = 1.0\ntau_s = 1.0"), "tau_s: needs 'std' or 'std_mg'"),
    "force gust of no time": (ROBOT + EV.format("force", "std = 1.0\ntau_s = 0.0"), "tau_s: must be positive"),
    "force share huge": (ROBOT + EV.format("force", "fx_mg = 1e3"), "fx_mg: must be <= 10"),
    "force push beyond a force": (ROBOT + EV.format("force", "dv_x = 100.0\nduration = 0.01"), "[[events]] #1 dv_x: 100 is 5.5e+04 N on this robot (5.5 kg)"),
    "force huge": (ROBOT + EV.format("force", "fx = 1e300"), "fx: must be <="),
    "force push of no time": (ROBOT + EV.format("force", "fx = 1.0\nduration = 0.0"), "duration: must be positive"),
    "force stray key": (ROBOT + EV.format("force", "fx = 1.0\nfz = 3.0"), "fz: not a parameter of a 'force' event"),
    "force on the kinematic plant": (MINIMAL + EV.format("force", "fx = 1.0"), "kinematic plant cannot apply a 'force'"),
    "world a string": ('world = "rough"\n' + ROBOT, "[world]: expected a table"),
    "world unknown key": (ROBOT + "[world]\nhills = 1\n", "[world] hills: unknown key"),
    "world laid out over no time": (ROBOT + "[world]\nover = 0.0\npatches = []\n", "[world] over: expected seconds of the reference"),
    "world on the kinematic plant": (MINIMAL + "[world]\nbumps = { height = 0.01, wavelength = 0.3 }\n", "[world]: the kinematic model drives on no ground"),
    "ramps a table": (ROBOT + "[world]\nramps = { at = 0.5, height = 0.01, length = 1.0 }\n", "[world] ramps: expected a list of tables"),
    "ramp at the start": (ROBOT + "[world]\nramps = [{ at = 0.0, height = 0.01, length = 1.0 }]\n", "[world] ramps #1 at: a share of the path's length"),
    "ramp unknown key": (ROBOT + "[world]\nramps = [{ at = 0.5, height = 0.01, length = 1.0, slope = 3.0 }]\n", "[world] ramps #1 slope: unknown key"),
    "ramp height huge": (ROBOT + "[world]\nramps = [{ at = 0.5, height = 1e300, length = 1.0 }]\n", "[world] ramps #1 height: must be <="),
    "ramp height 1e-300": (ROBOT + "[world]\nramps = [{ at = 0.5, height = 1e-300, length = 1.0 }]\n", "[world] ramps #1 height: must be >= 0.001"),
    "ramp height 1e-20": (ROBOT + "[world]\nramps = [{ at = 0.5, height = 1e-20, length = 1.0 }]\n", "[world] ramps #1 height: must be >= 0.001"),
    "ramp height 1e-9": (ROBOT + "[world]\nramps = [{ at = 0.5, height = 1e-9, length = 1.0 }]\n", "[world] ramps #1 height: must be >= 0.001"),
    "ramp width 1e-9": (ROBOT + "[world]\nramps = [{ at = 0.5, height = 0.01, length = 1.0, width = 1e-9 }]\n", "[world] ramps #1 width: must be >= 0.001"),
    "ramp at and placed": (ROBOT + "[world]\nramps = [{ at = 0.5, x = 1.0, y = 0.0, height = 0.01, length = 1.0 }]\n", "[world] ramps #1 x: not with 'at'"),
    "ramp placed without y": (ROBOT + "[world]\nramps = [{ x = 1.0, height = 0.01, length = 1.0 }]\n", "[world] ramps #1 y: give 'at'"),
    "ramp placed nowhere": (ROBOT + "[world]\nramps = [{ height = 0.01, length = 1.0 }]\n", "[world] ramps #1 at: give 'at' (a share of the path's length) or 'x' and 'y'"),
    "ramp placed outside the arena": (ROBOT + "[world]\nramps = [{ x = 50.0, y = 0.0, height = 0.01, length = 1.0 }]\n", "[world] ramps #1: (50, 0) lies outside the arena"),
    "ramps too many": (ROBOT + "[world]\nramps = [" + ", ".join(["{ at = 0.5, height = 0.01, length = 1.0 }"] * 101) + "]\n", "[world] ramps: 101 of them; the limit is 100"),
    "patches too many": (ROBOT + "[world]\npatches = [" + ", ".join(["{ x = 1.0, y = 0.5, radius = 0.1, mu = 0.5 }"] * 101) + "]\n", "[world] patches: 101 of them; the limit is 100"),
    "world over beyond memory": ("T = 1e-4\n" + ROBOT + "[world]\nover = 1e5\nkerbs = [{ at = 0.5, height = 0.005, length = 0.3 }]\n", "[world] over: the world is laid out along 1000000001 samples of the reference"),
    "kerb as high as the caster's axle": (ROBOT + "[world]\nkerbs = [{ at = 0.3, height = 0.019, length = 0.3 }]\n", "[world] kerbs #1 height: 0.019 m is more than 0.900 of the radius of the robot's caster (0.02 m)"),
    "kerb under the robot at its start": (ROBOT + "[world]\nkerbs = [{ x = 2.0, y = 0.0, height = 0.005, length = 0.3 }]\n", "[world] kerbs #1 x: the kerb lies under the robot's wheels or casters at its start"),
    "kerb height 1e-300": (ROBOT + "[world]\nkerbs = [{ at = 0.3, height = 1e-300, length = 0.3 }]\n", "[world] kerbs #1 height: must be >= 0.001"),
    "kerbs too many": (ROBOT + "[world]\nkerbs = [" + ", ".join(["{ at = 0.3, height = 0.005, length = 0.3 }"] * 101) + "]\n", "[world] kerbs: 101 of them; the limit is 100"),
    "ramp the wheels cannot climb": (ROBOT + "[world]\nramps = [{ at = 0.5, height = 0.3, length = 0.9 }]\n", "[world] ramps #1: the wheels cannot climb it"),
    "ramp under the robot at its start": (ROBOT + "[world]\nramps = [{ at = 0.002, height = 0.01, length = 1.0 }]\n", "[world] ramps #1 at: the ramp lies under the robot"),
    "bumps a number": (ROBOT + "[world]\nbumps = 0.01\n", "[world] bumps: expected a table"),
    "bumps unknown key": (ROBOT + "[world]\nbumps = { height = 0.01, wavelength = 0.3, seed = 2 }\n", "[world] bumps seed: unknown key"),
    "bumps without a wavelength": (ROBOT + "[world]\nbumps = { height = 0.01 }\n", "wavelength"),
    "bumps too fine for the tyre": (ROBOT + "[world]\nbumps = { height = 0.05, wavelength = 0.1 }\n", "[world] bumps wavelength: a heightfield too fine for the tyre"),
    "bumps too fine for the arena": (ROBOT + "[world]\nbumps = { height = 1e-4, wavelength = 0.01 }\n", "[world] bumps wavelength: 0.01 m over an arena"),
    "bumps height huge": (ROBOT + "[world]\nbumps = { height = 1e300, wavelength = 0.3 }\n", "[world] bumps height: must be <="),
    "patch outside the arena": (ROBOT + "[world]\npatches = [{ x = 50.0, y = 0.0, radius = 0.4, mu = 0.2 }]\n", "[world] patches #1: (50, 0) lies outside the arena"),
    "patch mu negative": (ROBOT + "[world]\npatches = [{ x = 1.0, y = 0.5, radius = 0.4, mu = -0.2 }]\n", "[world] patches #1 mu"),
    "patch of no size": (ROBOT + "[world]\npatches = [{ x = 1.0, y = 0.5, radius = 0.0, mu = 0.2 }]\n", "[world] patches #1 radius: must be positive"),
    "drawn bumps not the seed's": (ROBOT + '[world]\nbumps = { height = 0.01, wavelength = 0.3 }\n[drawn]\n"world.bumps" = "sha256:0"\n', "[drawn] world.bumps: 'sha256:0' is not the rough ground seed 0 draws"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_scenario_file(tmp_path, capsys, case):
    text, needle = BAD_FILES[case]
    path = tmp_path / "scenario.toml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    out = tmp_path / "out"
    assert main(["run", str(path), "--no-log", "--no-plot", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("mlpfac: error: "), err
    assert needle in err and str(path) in err, err
    assert not out.exists()


ROUTE = '[reference]\nkind = "path"\nfile = "route.csv"\n'
OWN = '[reference]\nkind = "route.py:{}"\n'
GOOD = "class R:\n    def __init__(self, k=1.0):\n        self.k = k\n\n    def sample(self, t):\n        return {}\n"
# name: (scenario file, {a file beside it: its content}, text the message must hold)
BAD_BESIDE: dict[str, tuple[str, dict[str, str | bytes], str]] = {
    "csv line not a number": (ROUTE, {"route.csv": "x,y\n0,0\n1,abc\n"}, "route.csv line 3: expected numbers"),
    "csv header without y": (ROUTE, {"route.csv": "x,z\n0,0\n1,0\n"}, "line 1: a header line must name the columns x and y"),
    "csv a yaw column": (ROUTE, {"route.csv": "x,y,yaw\n0,0,0\n1,0,0\n"}, "route.csv line 1: column 'yaw': a path takes no heading at its waypoints"),
    "csv a time column": (ROUTE, {"route.csv": "t,x,y\n0,0,0\n1,1,0\n"}, "route.csv line 1: column 't': a path is timed within its limits"),
    "csv a decimal comma": (ROUTE, {"route.csv": "x,y\n0,0\n2,5,0\n"}, "route.csv line 3: 3 values where the header on line 1 names 2 columns ('x,y'), got '2,5,0' (a decimal comma?"),
    "csv a row short of the header": (ROUTE, {"route.csv": "x,y,id\n0,0,a\n1,0\n"}, "route.csv line 3: 2 values where the header on line 1 names 3 columns"),
    "csv /dev/zero": ('[reference]\nkind = "path"\nfile = "/dev/zero"\n', {}, "[reference] file: /dev/zero: is a character device, not a regular file"),
    "csv three columns bare": (ROUTE, {"route.csv": "0,0,0\n1,0,0\n"}, "more columns: name them in a header line"),
    "csv binary": (ROUTE, {"route.csv": b"\xff\xfe\x00\x01"}, "route.csv: not a text file"),
    "csv empty": (ROUTE, {"route.csv": "x,y\n"}, "[reference] file: an open path needs at least 2 waypoints, got 0"),
    "csv repeated point": (ROUTE, {"route.csv": "0,0\n1,0\n1,0\n"}, "route.csv line 3 repeats the waypoint before it"),
    "csv value inf": (ROUTE, {"route.csv": "0,0\n1,inf\n"}, "route.csv line 2: (1, inf) must be finite"),
    "own reference class missing": (OWN.format("Nope"), {"route.py": GOOD.format("(0.0,) * 7")}, "has no class 'Nope'"),
    "own reference not a class": (OWN.format("f"), {"route.py": "def f():\n    pass\n"}, "is not a class"),
    "own reference without sample": (OWN.format("R"), {"route.py": "class R:\n    pass\n"}, "has no sample(t) method"),
    "own reference import raises": (OWN.format("R"), {"route.py": "1 / 0\n"}, "importing it raised ZeroDivisionError"),
    "own reference params refused": (OWN.format("R") + "[reference.params]\nq = 2.0\n", {"route.py": GOOD.format("(0.0,) * 7")}, "[reference.params] q: R(**[reference.params])"),
    "own reference constructor raises": (OWN.format("R") + "[reference.params]\nk = -1.0\n", {"route.py": GOOD.format("(0.0,) * 7").replace("self.k = k", "assert k > 0, 'k > 0'")}, "[reference] params: R(**[reference.params]) raised AssertionError: k > 0"),
    "own reference six numbers": (OWN.format("R"), {"route.py": GOOD.format("(0.0,) * 6")}, "sample(0) returned 6 numbers, not 7"),
    "own reference nan at 0": (OWN.format("R"), {"route.py": GOOD.format("(float('nan'),) * 7")}, "sample(0) returned a value that is not finite"),
    "own reference a word": (OWN.format("R"), {"route.py": GOOD.format("'seven'")}, "sample(0) returned 'seven', not seven numbers"),
    "own reference standing still": (OWN.format("R"), {"route.py": GOOD.format("(1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0)")}, "[reference] kind: R stands still over the run"),
    "own reference sample raises": (OWN.format("R"), {"route.py": GOOD.format("1 / t")}, "sample(0) raised ZeroDivisionError"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_BESIDE))
def test_bad_path_or_reference_class_beside_the_file(tmp_path, capsys, case):
    text, files, needle = BAD_BESIDE[case]
    for name, content in files.items():
        (tmp_path / name).write_bytes(content if isinstance(content, bytes) else content.encode())
    path = tmp_path / "scenario.toml"
    path.write_text(MINIMAL + text)
    out = tmp_path / "out"
    assert main(["run", str(path), "--no-log", "--no-plot", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("mlpfac: error: "), err
    assert needle in err and str(path) in err, err
    assert not out.exists()


def wheeled(wheels: str, robots: int = 1, servo: str = 'velocity kv="1"') -> str:
    """An MJCF of ``robots`` free boxes, each with the wheels "NAME X Y, ..." (a hinge across x driven
    by the actuator NAME, numbered by robot when there are several)."""
    bodies, servos = "", ""
    for r in range(robots):
        inner = ""
        for name, x, y in (w.split() for w in wheels.split(",")):
            name += str(r) if robots > 1 else ""
            inner += f'<body name="{name}" pos="{x} {y} 0"><joint name="{name}_hinge" axis="0 1 0"/>'
            inner += '<geom type="cylinder" size="0.05 0.01" zaxis="0 1 0"/></body>'
            servos += f'<{servo} name="{name}" joint="{name}_hinge"/>'
        bodies += (
            f'<body name="base{r}" pos="{r} 0 0.1"><freejoint/><geom type="box" size="0.1 0.1 0.02"/>{inner}</body>'
        )
    return f"<mujoco><worldbody>{bodies}</worldbody><actuator>{servos}</actuator></mujoco>"


# robots named by their model alone (robot.xml): (MJCF, texts the message must hold)
BAD_ROBOTS = {
    "three wheel servos": (wheeled("a 0 0.2, b 0 -0.2, c -0.2 0.2"), ["3 wheel servos found (a (joint a_hinge), b (joint b_hinge), c (joint c_hinge)", "left_actuator and right_actuator"]),
    "two free bodies": (wheeled("a 0 0.2, b 0 -0.2", robots=2), ["2 free bodies", "body base0: a0 (joint a0_hinge), b0", "body base1: a1", "left_actuator and right_actuator"]),
    "wheels on different axles": (wheeled("a 0.1 0.2, b -0.1 -0.2"), ["not on one axle", "a (joint a_hinge), b", "left_actuator and right_actuator"]),
    "wheels on one side": (wheeled("a 0 0.2, b 0 0.4"), ["not on either side", "a (joint a_hinge), b", "left_actuator and right_actuator", "site or body"]),
    "no wheel servo": (wheeled("a 0 0.2, b 0 -0.2", servo='position kp="1"'), ["two wheel servos needed, found none", "it has: 'a', 'b'", "left_actuator and right_actuator"]),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_ROBOTS))
def test_bad_robot(tmp_path, capsys, case):
    xml, needles = BAD_ROBOTS[case]
    (tmp_path / "robot.xml").write_text(xml)
    path = tmp_path / "scenario.toml"
    path.write_text(ROBOT + 'model = "robot.xml"\n')
    out = tmp_path / "out"
    assert main(["run", str(path), "--no-log", "--no-plot", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"mlpfac: error: {path} [plant] left_actuator: "), err
    assert all(needle in err for needle in needles), err
    assert not out.exists()


# "loop" is a symbolic link to itself: (argv, text the message must hold)
SYMLINK_LOOPS = {
    "run --out": (["run", "paper", "--out", "loop"], "--out loop: "),
    "run --out inside": (["run", "paper", "--out", "loop/run"], "--out loop/run: "),
    "run --save": (["run", "paper", "--out", "out", "--save", "loop"], "--save loop: "),
    "sweep --out": (["sweep", "paper", "--seeds", "0", "--out", "loop"], "--out loop: "),
    "compare --out": (["compare", "paper", "--seeds", "0", "--out", "loop/cmp"], "--out loop/cmp: "),
}


@pytest.mark.parametrize("case", sorted(SYMLINK_LOOPS))
def test_a_symlink_loop(tmp_path, capsys, monkeypatch, case):
    argv, needle = SYMLINK_LOOPS[case]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "loop").symlink_to("loop")
    assert main([*argv, "--duration", "0.5"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if not line.startswith("mlpfac: planning")]
    assert len(err) == 1 and needle in err[0] and "symlink loop" in err[0], err
    assert [p.name for p in tmp_path.iterdir()] == ["loop"]


def code_of(argv: list[str]) -> int:
    """The exit code of the command line ``argv``: main's, or a usage error's (argparse's, and a flag
    that means nothing without another: mlpfac.flags), which exits at once."""
    try:
        return main(argv)
    except SystemExit as err:
        return err.code


# flags: (argv after "run", text the message must hold)
BAD_FLAGS = {
    "duration zero": (["paper", "--duration", "0"], "--duration"),
    "duration tiny": (["paper", "--duration", "1e-9"], "--duration"),
    "duration nan": (["paper", "--duration", "nan"], "--duration"),
    "duration inf": (["paper", "--duration", "inf"], "--duration"),
    "duration huge": (["paper", "--duration", "1e9"], "--duration"),
    "seed negative": (["paper", "--seed", "-3"], "--seed"),
    "controller": (["paper", "--controller", "pid"], "--controller"),
    "baseline": (["paper", "--baseline", "nosuch"], "--baseline"),
    "no such scenario": (["no-such-scenario"], "no such scenario"),
    "scenario file missing": (["missing.toml"], "not found"),
    "scenario is a folder": (["sims.toml"], "folder"),
    "robot unknown": (["paper", "--robot", "nosuch"], "--robot"),
    "robot file missing": (["paper", "--robot", "missing.xml"], "not found"),
    "robot file a folder": (["paper", "--robot", "sims.toml"], "folder"),
    "robot file not a robot": (["paper", "--robot", "robot.toml"], "one [plant] table"),
    "robot file of the kinematic plant": (["paper", "--robot", "kin-robot.toml"], "--robot kin-robot.toml [plant] kind: must be"),
    "robot file missing (toml)": (["paper", "--robot", "missing.toml"], "--robot missing.toml: robot file not found"),
    "robot file with an unknown key": (["paper", "--robot", "bogus-robot.toml"], "--robot bogus-robot.toml [plant] bogus: unknown key"),
    "--port without --serve": (["paper", "--port", "9100"], "--port means nothing without --serve"),
    "--grpc-port without --serve": (["paper", "--grpc-port", "9100"], "--grpc-port means nothing without --serve"),
    "--bind without a viewer": (["paper", "--bind", "0.0.0.0"], "--bind means nothing without --serve or --spawn"),
    "--baseline with --no-plot": (["paper", "--baseline", "kanayama", "--no-plot"], "not allowed with argument --baseline"),
    "lost threshold zero": (["paper", "--lost-threshold", "0"], "--lost-threshold: must be a number of metres above 0"),
    "lost threshold huge": (["paper", "--lost-threshold", "1e308"], "--lost-threshold: must be a number of metres above 0 and at most 10000"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_FLAGS))
def test_bad_flag(tmp_path, capsys, monkeypatch, case):
    argv, needle = BAD_FLAGS[case]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sims.toml").mkdir()
    (tmp_path / "robot.toml").write_text('duration = 3.0\n[plant]\nmodel = "x.xml"\n')
    (tmp_path / "kin-robot.toml").write_text('[plant]\nkind = "kinematic"\nmodel = "x.xml"\n')
    (tmp_path / "bogus-robot.toml").write_text('[plant]\nmodel = "x.xml"\nbogus = 1\n')
    assert code_of(["run", *argv, "--no-log", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err, err
    assert not (tmp_path / "out").exists()


def _policy(**change) -> dict:
    """A policy file's arrays (mlpfac.control.policy), one layer, with ``change`` (None: left out)."""
    import numpy as np

    arrays = {"format": np.array("mlpfac-policy-1"), "features": np.array("tracking-1"), "obs_scale": np.ones(8),
              "obs_clip": np.array(5.0), "act_scale": np.ones(2), "feedforward": np.array(1.0),
              "W0": np.zeros((2, 8)), "b0": np.zeros(2)}  # fmt: skip
    return {k: v for k, v in (arrays | change).items() if v is not None}


# a policy file as --controller: (its arrays, or bytes; text the message must hold)
BAD_POLICIES = {
    "not an npz": (b"PK\x03\x04 not a zip", "not a policy file"),
    "text": (b"W0 = 1\n", "not a policy file"),
    "no weights": (_policy(W0=None, b0=None), "expected 1 to 8 layers"),
    "a missing array": (_policy(obs_scale=None), "no array 'obs_scale'"),
    "wrong format": (_policy(format="__np__:other"), "format must be 'mlpfac-policy-1'"),
    "wrong shape": (_policy(W0="__np__:zeros:2,7"), "W0 has shape (2, 7), expected (2, 8)"),
    "a bias of the wrong size": (_policy(b0="__np__:zeros:3"), "b0 has shape (3,), expected (2,)"),
    "three outputs": (_policy(W0="__np__:zeros:3,8", b0="__np__:zeros:3"), "W0 has shape (3, 8), expected (2, 8)"),
    "a weight not finite": (_policy(W0="__np__:nan:2,8"), "W0 holds a value that is not finite"),
    "a scale of zero": (_policy(obs_scale="__np__:zeros:8"), "must be positive"),
    "text weights": (_policy(W0="__np__:text"), "W0 holds <U"),
}  # fmt: skip


def _array(v):
    import numpy as np

    if not (isinstance(v, str) and v.startswith("__np__:")):
        return v
    kind, _, shape = v[7:].partition(":")
    dims = tuple(int(x) for x in shape.split(",")) if shape else ()
    return {"other": np.array("other"), "text": np.array(["a", "b"]), "zeros": np.zeros(dims),
            "nan": np.full(dims, np.nan)}[kind]  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_POLICIES))
def test_bad_policy_file(tmp_path, capsys, monkeypatch, case):
    import numpy as np

    content, needle = BAD_POLICIES[case]
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "mine.npz"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        with open(path, "wb") as fh:
            np.savez(fh, **{k: _array(v) for k, v in content.items()})
    assert (
        code_of(["run", "eight-nominal", "--controller", "mine.npz", "--no-log", "--out", str(tmp_path / "out")]) == 2
    )
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err and "--controller" in err and "mine.npz" in err, err
    assert not (tmp_path / "out").exists()


def test_a_missing_policy_file_is_named(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert code_of(["run", "eight-nominal", "--controller", "nosuch.npz", "--no-log", "--out", "out"]) == 2
    assert "nosuch.npz: no such policy file" in capsys.readouterr().err


# view, plot and check: (argv, text the message must hold); "D" is a folder holding no run
BAD_VIEW_PLOT = {
    "view: no run.rrd": (["view", "D"], "no run.rrd"),
    "view --save: folders without run.rrd": (["view", "D", "D", "--save", "x.rrd"], "no run.rrd"),
    "view --serve: a port out of range": (["view", "D", "--serve", "--port", "70000"], "--port: 70000 is not a port"),
    "view --serve: a gRPC port of 0": (["view", "D", "--serve", "--grpc-port", "0"], "--grpc-port: 0 is not a port"),
    "view --serve: one port twice": (["view", "D", "--serve", "--port", "9876"], "cannot share port 9876"),
    "report --verify 0": (["report", "D", "--verify", "0"], "--verify: must be a number of runs >= 1"),
    "report --verify: no data folder": (["report", "D", "--verify", "1"], "no data folder"),
    "plot: not a folder": (["plot", "missing"], "is not a folder"),
    "plot: no runs": (["plot", "D"], "holds no finished runs"),
    "plot --panels: not a .png": (["plot", "D", "--panels", "x.svg"], "--panels x.svg: must name a .png file"),
    "plot --panels: a folder": (["plot", "D", "--panels", "D/.png"], "--panels D/.png"),
    "plot --panels: no robustness.json": (["plot", "D", "--panels", "x.png"], "holds no robustness.json"),
    "check: no budget file": (["check", "missing.toml"], "budget file not found"),
    "check: a folder as the budget": (["check", "D"], "is a folder, not a budget file"),
    "check: --workers 0": (["check", "missing.toml", "--workers", "0"], "--workers"),
    "sweep: --robots with an empty name": (["sweep", "paper", "--robots", "diffdrive,,cart"], "--robots"),
    "compare: --robot unknown": (["compare", "paper", "--robot", "nosuch"], "--robot"),
    "sweep: --robots unknown": (["sweep", "paper", "--robots", "diffdrive,cartt"], "--robots cartt: neither a robot"),
    "view --serve: --bind not an address": (["view", "D", "--serve", "--bind", "not an address"], "--bind: 'not an address' is not an IP"),
    "view: --bind not an address": (["view", "D", "--bind", "localhost"], "--bind: 'localhost' is not an IP"),
    "report --collect ../x": (["report", "docs", "--collect", "../x=D", "--command", "c"], "--collect ../x=D: NAME is one"),
    "report --collect a/b": (["report", "docs", "--collect", "a/b=D", "--command", "c"], "--collect a/b=D: NAME is one"),
    "report --collect .": (["report", "docs", "--collect", ".=D", "--command", "c"], "--collect .=D: NAME is one"),
    "report --collect an absolute path": (["report", "docs", "--collect", "/tmp/x=D", "--command", "c"], "--collect /tmp/x=D"),
    # a flag that means nothing without another (mlpfac.flags): refused, nothing written
    "report --strict without --verify": (["report", "D", "--strict"], "--strict means nothing without --verify"),
    "report --command without --collect": (["report", "D", "--command", "c"], "--command means nothing without --collect"),
    "report --code-version without --collect": (["report", "D", "--code-version", "abc"], "--code-version means nothing without --collect"),
    "report --code-version no commit": (["report", "D", "--collect", "x=D", "--command", "c", "--code-version", "e6c5e10zz"],
                                        "--code-version: 'e6c5e10zz' names no commit"),
    "report --command of two --collect": (["report", "D", "--collect", "a=D", "--collect", "b=D", "--command", "c"], "--command: is the command of one --collect"),
    "report --remake with --check": (["report", "D", "--remake", "--check"], "--remake means nothing with --check"),
    "report --sources with --verify": (["report", "D", "--sources", "--verify", "1"], "--sources means nothing with --verify"),
    "report --remake: no such dataset": (["report", "D", "--remake", "nosuch"], "--remake nosuch: no such dataset: nosuch"),
    "sweep --threshold without --vary": (["sweep", "paper", "--threshold", "0.1"], "--threshold means nothing without --vary"),
    "sweep --threshold with a draw only": (["sweep", "paper", "--vary", "T=uniform:0.01:0.02", "--threshold", "0.1"], "--threshold: means nothing without an axis"),
    "sweep --lost-threshold -1": (["sweep", "paper", "--lost-threshold", "-1"], "--lost-threshold: must be a number of metres above 0"),
    "sweep --threshold 1e308": (["sweep", "paper", "--vary", "T=0.01,0.02", "--threshold", "1e308"], "--threshold: must be a number of metres above 0 and at most 10000"),
    "sweep --batch-size without --batched": (["sweep", "paper", "--batch-size", "8"], "--batch-size means nothing without --batched"),
    "sweep --limit-cache without --limit": (["sweep", "paper", "--limit-cache", "D"], "--limit-cache means nothing without --limit"),
    "compare --limit-cache a file": (["compare", "eight-nominal", "--limit", "--limit-cache", "/dev/null/limits"], "is a file, not a folder"),
    "compare --scheduler-timeout without --scheduler": (["compare", "paper", "--scheduler-timeout", "3"], "--scheduler-timeout means nothing without --scheduler"),
    "view --port without --serve": (["view", "D", "--port", "9100"], "--port means nothing without --serve"),
    "view --bind with --save": (["view", "D", "--save", "x.rrd", "--bind", "0.0.0.0"], "--bind means nothing with --save"),
    "sweep --robots a robot file missing": (["sweep", "paper", "--robots", "diffdrive,nope.toml"], "--robots nope.toml: robot file not found"),
    "sweep --robots an MJCF missing": (["sweep", "paper", "--robots", "diffdrive,nope.xml"], "--robots nope.xml: MJCF model file not found"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_VIEW_PLOT))
def test_bad_view_or_plot(tmp_path, capsys, monkeypatch, case):
    argv, needle = BAD_VIEW_PLOT[case]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "D").mkdir()
    assert code_of(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err, err
    assert [p.name for p in tmp_path.rglob("*")] == ["D"]


def test_a_bad_file_from_the_command_line_has_no_traceback(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_bytes(b"\xff\xfe\x00binary")
    proc = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", "run", str(path), "--no-log"], capture_output=True, text=True
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip() == f"mlpfac: error: {path}: not a text file (TOML is UTF-8 text)"


BAD_ENVIRONMENT = {  # a variable of ours with a value it does not take: one line, exit 2, nothing written
    "MLPFAC_KERNELS=fast": ({"MLPFAC_KERNELS": "fast"}, "mlpfac: error: MLPFAC_KERNELS: 'fast' is neither jit"),
}


@pytest.mark.parametrize("case", sorted(BAD_ENVIRONMENT))
def test_bad_environment(tmp_path, case):
    env, needle = BAD_ENVIRONMENT[case]
    proc = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", "run", "eight-nominal", "--out", str(tmp_path / "D")],
        capture_output=True,
        text=True,
        env={**os.environ, **env},
    )
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert proc.stderr.startswith(needle), proc.stderr
    assert not any(tmp_path.iterdir())


def test_a_minimal_mujoco_file_runs_bounded_on_the_default_robot(tmp_path):
    """The tuned configuration is the built-in default: [plant] kind = "mujoco" alone tracks the eight."""
    path = tmp_path / "minimal.toml"
    path.write_text(ROBOT)
    out = tmp_path / "out"
    assert main(["run", str(path), "--duration", "6", "--no-log", "--no-plot", "--out", str(out)]) == 0
    import json

    m = json.loads((out / "metrics.json").read_text())
    assert m["status"] == "ok" and m["phases"]["before"]["rms_position_error_m"] < 0.2


def test_a_custom_robot_reruns_from_its_config_toml(tmp_path, monkeypatch):
    """A relative model path is taken from the TOML's folder, whatever the working folder; config.toml
    records the resolved path and the compiled model's hash and re-runs to the same metrics; a changed
    model is refused, not silently simulated."""
    import json
    import shutil

    from mlpfac.scenario.parse import shipped_dir

    robot = tmp_path / "robots"
    shutil.copytree(shipped_dir().parent / "models", robot)
    (robot / "diffdrive.xml").write_text((robot / "diffdrive.xml").read_text().replace('size="0.05"', 'size="0.06"', 1))
    scen = tmp_path / "exp" / "mine.toml"
    scen.parent.mkdir()
    scen.write_text('duration = 1.0\n[plant]\nkind = "mujoco"\nmodel = "../robots/scene.xml"\npose_noise_std = 0.001\n')
    monkeypatch.chdir(tmp_path / "robots")  # somewhere else: the path is the file's, not the shell's
    first, again = tmp_path / "a", tmp_path / "b"
    assert main(["run", "../exp/mine.toml", "--no-log", "--no-plot", "--out", str(first)]) == 0
    config = (first / "config.toml").read_text()
    assert f'model = "{robot / "scene.xml"}"' in config and "model_sha256" in config
    assert main(["run", str(first / "config.toml"), "--no-log", "--no-plot", "--out", str(again)]) == 0
    a, b = (json.loads((d / "metrics.json").read_text()) for d in (first, again))
    for key in ("rms_position_error_m", "max_position_error_m", "rms_heading_error_rad", "max_abs_weight"):
        assert a[key] == b[key]
    (robot / "diffdrive.xml").write_text((robot / "diffdrive.xml").read_text().replace('size="0.06"', 'size="0.05"', 1))
    assert main(["run", str(first / "config.toml"), "--no-log", "--no-plot", "--out", str(tmp_path / "c")]) == 2


@pytest.mark.parametrize("name", scenario_names())
def test_config_toml_round_trips(name):
    """What config.toml says is the table that was run: every shipped scenario, read back, is equal."""
    import tomllib

    from mlpfac.scenario.parse import load, to_toml

    table = load(name).table
    assert tomllib.loads(to_toml(table)) == table, name


def test_shipped_scenarios_resolve_inside_the_package():
    from mlpfac.scenario.parse import load, shipped_dir

    scn = load("eight-nominal")
    assert Path(scn.plant_config.model).is_file() and Path(scn.plant_config.model).parent.name == "models"
    assert (shipped_dir() / "eight-nominal.toml").is_file()


def test_one_wheel_named_takes_the_other_or_says_which_to_name(tmp_path, capsys):
    """left_actuator named alone: with one other wheel servo that is the right one (whatever side the
    geometry puts it on); with two others, one line naming right_actuator and the candidates."""
    (tmp_path / "robot.xml").write_text(wheeled("a 0 0.2, b 0 -0.2, c -0.2 0.2"))
    path = tmp_path / "scenario.toml"
    path.write_text(ROBOT + 'model = "robot.xml"\nleft_actuator = "a"\n')
    assert main(["run", str(path), "--no-log", "--no-plot", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{path} [plant] right_actuator: left_actuator = 'a' is named" in err, err
    assert "b (joint b_hinge), c (joint c_hinge)" in err
    import mujoco

    from mlpfac.exceptions import ConfigError
    from mlpfac.plants.config import MujocoConfig
    from mlpfac.plants.mjcf.detect import resolve

    m = mujoco.MjModel.from_xml_string(wheeled("a 0 0.2, b 0 -0.2, c -0.2 0.2"))
    for named, found in ((dict(right_actuator="b"), "left_actuator"), (dict(left_actuator="b"), "right_actuator")):
        with pytest.raises(ConfigError, match=f"^{found}: "):
            resolve(MujocoConfig(**named), m, m.qpos0)
    m = mujoco.MjModel.from_xml_string(wheeled("a 0 0.2, b 0 -0.2"))
    got = resolve(MujocoConfig(right_actuator="b"), m, m.qpos0)
    assert (got.config.left_actuator, got.config.right_actuator, got.keys[0]) == ("a", "b", "left_actuator")


# A robot's errors name the robot under the flag or key that brought it (docs/errors.md): argv, the
# text the one line holds ({here}: the test's folder, where a budget's robot files are found)
BUDGET = 'scenarios = ["eight-nominal"]\ncontrollers = ["kanayama"]\nseeds = "0"\nduration = 0.5\n{robots}[[budget]]\nlost = 0\n'
ROBOT_NAMED = {
    "--robot, a robot file missing": (["run", "eight-nominal", "--robot", "nope.toml"], "mlpfac: error: --robot nope.toml: robot file not found"),
    "--robots, a robot file missing": (["sweep", "eight-nominal", "--robots", "diffdrive,nope.toml"], "mlpfac: error: --robots nope.toml: robot file not found"),
    "--robots, a robot file's unknown key": (["sweep", "eight-nominal", "--robots", "diffdrive,bogus.toml"], "mlpfac: error: --robots bogus.toml [plant] bogus: unknown key"),
    "--robots, a robot file that is no robot": (["compare", "eight-nominal", "--robots", "cart,norobot.toml"], "mlpfac: error: --robots norobot.toml: a robot file holds one [plant]"),
    "a budget's robot file missing": (["check", "missing.toml"], "mlpfac: error: missing.toml robots {here}/nope.toml: robot file not found"),
    "a budget's robot file's unknown key": (["check", "bogus-budget.toml"], "mlpfac: error: bogus-budget.toml robots {here}/bogus.toml [plant] bogus: unknown key"),
    "a budget's robot unknown": (["check", "unknown.toml"], "mlpfac: error: unknown.toml robots zzz: neither a robot"),
    "check --robot over a budget's robots": (["check", "missing.toml", "--robot", "nope.xml"], "mlpfac: error: --robot nope.xml: MJCF model file not found"),
    "a budget's robot file, from the budget's folder": (["check", "sub/b.toml"], "mlpfac: error: sub/b.toml robots {here}/sub/bogus.toml [plant] bogus"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(ROBOT_NAMED))
def test_a_robots_error_names_the_flag_or_key_that_brought_it(tmp_path, capsys, monkeypatch, case):
    argv, needle = ROBOT_NAMED[case]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    for folder in (tmp_path, tmp_path / "sub"):
        (folder / "bogus.toml").write_text(
            f'[plant]\nmodel = "{shipped_dir().parent / "models" / "cart.xml"}"\nbogus = 1\n'
        )
    (tmp_path / "norobot.toml").write_text("duration = 3.0\n")
    (tmp_path / "missing.toml").write_text(BUDGET.format(robots='robots = ["nope.toml"]\n'))
    (tmp_path / "bogus-budget.toml").write_text(BUDGET.format(robots='robots = ["cart", "bogus.toml"]\n'))
    (tmp_path / "unknown.toml").write_text(BUDGET.format(robots='robots = ["zzz"]\n'))
    (tmp_path / "sub" / "b.toml").write_text(BUDGET.format(robots='robots = ["bogus.toml"]\n'))
    before = sorted(p.name for p in tmp_path.rglob("*"))
    assert code_of([*argv, "--out", "out"]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("mlpfac: planning")]
    assert len(err) == 1 and err[0].startswith(needle.format(here=tmp_path)), err
    assert sorted(p.name for p in tmp_path.rglob("*")) == before


# Bad input whose extra lines came from outside the one line (a library's warning, a plot's
# traceback): the command run as a user runs it, its whole stderr read. (argv, the one line's start)
ONE_LINE_IN_A_PROCESS = {
    "[reference] speed = 1e-300": (["run", "s.toml"], "mlpfac: error: s.toml [reference]: the reference speed v_r must stay above zero"),
    "--vary reference.speed=1e-300": (["sweep", "eight-nominal", "--seeds", "0", "--vary", "reference.speed=1e-300"], "mlpfac: error: --vary reference.speed=1e-300: the reference speed v_r must stay above zero"),
    "--threshold 1e308": (["sweep", "paper", "--seeds", "0", "--vary", "T=0.01,0.02", "--threshold", "1e308"], "mlpfac: error: --threshold: must be"),
    "a budget's threshold_m = 1e308": (["check", "b.toml"], "mlpfac: error: b.toml threshold_m: must be"),
    "a budget's threshold_m without vary": (["check", "n.toml"], "mlpfac: error: n.toml threshold_m: means nothing without an axis"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(ONE_LINE_IN_A_PROCESS))
def test_bad_input_is_one_line_in_the_commands_own_process(tmp_path, case):
    argv, needle = ONE_LINE_IN_A_PROCESS[case]
    (tmp_path / "s.toml").write_text("duration = 1.0\n[reference]\nspeed = 1e-300\n")
    budget = 'scenarios = ["paper"]\ncontrollers = ["kanayama"]\nduration = 0.5\n{}[[budget]]\nlost = 0\n'
    (tmp_path / "b.toml").write_text(budget.format('vary = ["T=0.01,0.02"]\nthreshold_m = 1e308\n'))
    (tmp_path / "n.toml").write_text(budget.format("threshold_m = 0.1\n"))
    cmd = [sys.executable, "-m", "mlpfac.cli", *argv, "--out", "out"]
    proc = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    err = [ln for ln in proc.stderr.splitlines() if not ln.startswith("mlpfac: planning")]
    assert proc.returncode == 2 and len(err) == 1 and err[0].startswith(needle), proc.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("what", ["waypoints", "scenario", "policy"])
def test_a_fifo_without_a_writer_is_refused_in_one_line_not_waited_for(tmp_path, what):
    """A FIFO named as a path's CSV file, as the scenario file or as a policy file: one line, at
    once (never a read that waits for a writer), exit 2; a file larger than allowed is refused
    before it is read."""
    fifo = tmp_path / {"waypoints": "route.csv", "scenario": "fifo.toml", "policy": "policy.npz"}[what]
    os.mkfifo(fifo)
    scenario = tmp_path / "s.toml"
    scenario.write_text(MINIMAL + '[reference]\nkind = "path"\nfile = "route.csv"\n')
    target = {"waypoints": scenario, "scenario": fifo, "policy": "eight-nominal"}[what]
    policy = ["--controller", str(fifo)] if what == "policy" else []
    proc = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", "run", str(target), *policy, "--no-log", "--out", str(tmp_path / "o")],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert f"{fifo}: is a FIFO, not a regular file" in proc.stderr, proc.stderr
    from mlpfac.io.files import NotAFileError, read_regular

    big = tmp_path / "big.csv"
    big.write_bytes(b"0,0\n" * 1000)
    with pytest.raises(NotAFileError, match="MiB is more than"):
        read_regular(big, 100)
    assert read_regular(big, 4000) == b"0,0\n" * 1000


# A path's absurd limit: one line naming the key (no numpy warning, no 300-digit count), run as a user
# runs it, its whole stderr read. (the [reference] line, the one line's start after the file's name)
PATH_LIMITS = {
    "v_max = 1e-300": "[reference] v_max: the path cannot be timed within its limits",
    "omega_max = 1e-300": "[reference] omega_max: the path cannot be timed within its limits",
    "radius = 1e-300": "[reference] radius: must be 0 (from the limits) or at least 0.001 m",
    "speed = 1e-300": "[reference] speed: the path takes 1.44e+301 s to drive once",
    "alpha_max = 1e-300": "[reference] alpha_max: the path takes",
}


@pytest.mark.parametrize("line", sorted(PATH_LIMITS))
def test_a_paths_absurd_limit_is_one_line_naming_its_key(tmp_path, line):
    path = tmp_path / "p.toml"
    path.write_text(f'{MINIMAL.replace("duration = 0.5", "")}[reference]\nkind = "path"\nclosed = true\n'
                    f"points = [[0, 0], [3, 0], [3, 3], [0, 3]]\n{line}\n")  # fmt: skip
    proc = subprocess.run(
        [sys.executable, "-m", "mlpfac.cli", "run", str(path), "--no-log", "--out", str(tmp_path / "o")],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(err) == 1, proc.stderr
    assert err[0].startswith(f"mlpfac: error: {path} {PATH_LIMITS[line]}"), err[0]
    assert not any(len(w) > 40 for w in err[0].split() if "/" not in w), err[0]  # no count of hundreds of digits
