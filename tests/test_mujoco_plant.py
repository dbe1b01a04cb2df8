"""The MuJoCo robot as a plant: models, steady-state accuracy, events, determinism, bad input."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import mujoco
import numpy as np
import pytest

from mlpfac.exceptions import ConfigError
from mlpfac.plants.events import make_event, parse_event
from mlpfac.plants.mujoco.plant import MujocoConfig, MujocoPlant

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "models" / "scene.xml"
T = 0.01
DRIVES = ("velocity", "torque")


def make(actuator: str = "velocity", q0=(0.0, 0.0, 0.0), seed: int = 0, **kw) -> MujocoPlant:
    plant = MujocoPlant(MujocoConfig(actuator=actuator, **kw), T)
    plant.reset(np.array(q0, dtype=float), np.random.default_rng(seed))
    return plant


def hold(plant: MujocoPlant, u, steps: int) -> dict[str, np.ndarray]:
    """Apply u for ``steps`` control steps; the telemetry and true poses, stacked."""
    out: dict[str, list] = {"pose": []}
    for _ in range(steps):
        plant.step(np.asarray(u, dtype=float))
        for key, val in plant.telemetry().items():
            out.setdefault(key, []).append(np.array(val))
        out["pose"].append(plant.true_pose().copy())
    return {k: np.array(v) for k, v in out.items()}


def site_velocity(plant: MujocoPlant) -> tuple[float, float]:
    """Forward speed and yaw rate from the model's own sensors at the axle midpoint."""
    return float(plant.data.sensor("axle_vel").data[0]), float(plant.data.sensor("axle_gyro").data[2])


# --- models ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("path", sorted((ROOT / "models").glob("*.xml")), ids=lambda p: p.name)
def test_every_model_compiles_and_runs_a_second_without_warning(path):
    m = mujoco.MjSpec.from_file(str(path)).compile()
    d = mujoco.MjData(m)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    d.ctrl[:] = 10.0
    mujoco.mj_step(m, d, nstep=int(round(1.0 / m.opt.timestep)))
    assert [w.number for w in d.warning] == [0] * len(d.warning)


@pytest.mark.parametrize("actuator", DRIVES)
def test_plant_runs_a_second_without_warning(actuator):
    plant = make(actuator)
    assert plant.n_substeps * plant.model.opt.timestep == pytest.approx(T)
    hold(plant, (0.8, 1.0), 100)
    assert plant.mujoco_warnings() == {}
    assert plant.diverged() is None
    assert plant.sim_time == pytest.approx(1.0)


def test_model_geometry_is_what_the_readme_says():
    plant = make()
    assert plant.real_radius == plant.ik_radius == pytest.approx(0.05)
    assert plant.ik_track == pytest.approx(0.28, abs=1e-12)
    m = plant.model
    assert m.body("chassis").mass[0] == pytest.approx(5.0)
    assert m.body_subtreemass[m.body("chassis").id] == pytest.approx(5.5)
    np.testing.assert_allclose(m.actuator_gainprm[:, 0], 2.0)
    np.testing.assert_allclose(m.actuator_forcerange, [[-0.6, 0.6], [-0.6, 0.6]])


# --- steady state -----------------------------------------------------------------------------------


@pytest.mark.parametrize("actuator", DRIVES)
@pytest.mark.parametrize("u", [(0.5, 0.5), (1.0, 0.0), (0.3, -1.5), (1.2, 1.0)])
def test_constant_command_is_achieved_within_2_percent(actuator, u):
    plant = make(actuator)
    hold(plant, u, 200)  # 2 s: servo and PI transients gone
    meas = []
    for _ in range(50):
        plant.step(np.array(u))
        meas.append(site_velocity(plant))
    v, omega = np.mean(meas, axis=0)
    assert v == pytest.approx(u[0], rel=0.02)
    assert omega == pytest.approx(u[1], rel=0.02, abs=0.002)


# --- events -----------------------------------------------------------------------------------------


def test_payload_mass_is_in_the_model_and_its_dynamics_match_a_compiled_model():
    plant = make()
    hold(plant, (0.6, 0.4), 30)
    b = plant.model.body("chassis").id
    inertia0 = plant.model.body_inertia[b].copy()
    text = plant.apply(make_event("payload", 0.3, mass_scale=3.0))
    assert "5 -> 15 kg" in text
    assert plant.model.body_mass[b] == pytest.approx(15.0)
    np.testing.assert_allclose(plant.model.body_inertia[b], 3.0 * inertia0)

    # The same robot compiled from scratch with the new mass, started from the plant's state.
    spec = mujoco.MjSpec.from_file(str(SCENE))
    spec.body("chassis").mass = 15.0
    spec.body("chassis").inertia = 3.0 * inertia0
    nominal = mujoco.MjSpec.from_file(str(SCENE)).compile()
    state = mujoco.mjtState.mjSTATE_INTEGRATION
    x = np.empty(mujoco.mj_stateSize(plant.model, state))
    mujoco.mj_getState(plant.model, plant.data, x, state)
    finals = []
    for m in (plant.model, spec.compile(), nominal):
        d = mujoco.MjData(m)
        mujoco.mj_setState(m, d, x, state)
        d.ctrl[:] = [15.0, 5.0]  # a hard turn: the mass matters
        mujoco.mj_step(m, d, nstep=200)
        finals.append(d.qpos.copy())
    assert np.max(np.abs(finals[0] - finals[1])) < 1e-9  # the event's model is the compiled one
    assert np.max(np.abs(finals[0] - finals[2])) > 1e-3  # and the mass does change the motion


def test_payload_adds_mass_to_a_named_body():
    plant = make()
    w = plant.model.body("left_wheel").id
    plant.apply(make_event("payload", 0.0, mass_kg=0.25, body="left_wheel"))
    assert plant.model.body_mass[w] == pytest.approx(0.5)
    plant.apply(make_event("payload", 0.0, mass_kg=2.0))
    assert plant.model.body("chassis").mass[0] == pytest.approx(7.0)
    plant.reset(np.zeros(3), np.random.default_rng(0))  # a new run starts from the nominal robot
    assert plant.model.body("chassis").mass[0] == pytest.approx(5.0)
    assert plant.model.body_mass[w] == pytest.approx(0.25)


def test_a_load_placed_off_centre_moves_the_centre_of_mass_by_the_lever_rule():
    """mass_kg at (offset, lateral) of the pose frame: the robot's mass grows by it and its centre of
    mass, seen in the pose frame, moves to the mass-weighted mean of the two (a known answer)."""
    plant = make()
    hold(plant, (0.5, 0.8), 40)  # mid-run, turned: the placement is in the robot's frame, not the world's

    def com_in_pose_frame() -> tuple[float, np.ndarray]:
        m, d, r, s = plant.model, plant.data, plant.robot.root, plant.robot.site
        mujoco.mj_forward(m, d)
        R = d.site_xmat[s].reshape(3, 3)
        return float(m.body_subtreemass[r]), R.T @ (d.subtree_com[r] - d.site_xpos[s])

    M, c = com_in_pose_frame()
    z = plant.model.body_ipos[plant.robot.root][2]
    text = plant.apply(make_event("payload", 0.4, mass_kg=3.0, offset=0.12, lateral=-0.05))
    mass2, c2 = com_in_pose_frame()
    assert mass2 == pytest.approx(M + 3.0)
    assert "0.12 m ahead" in text
    np.testing.assert_allclose(c2[:2], (M * c[:2] + 3.0 * np.array([0.12, -0.05])) / (M + 3.0), atol=1e-9)
    assert plant.model.body_ipos[plant.robot.root][2] == pytest.approx(z)  # at the body's own height
    I = plant.model.body_inertia[plant.robot.root]
    assert np.all(I > 0) and I.sum() >= 2 * I.max() - 1e-12  # a physical inertia (triangle inequality)
    hold(plant, (0.5, 0.8), 100)
    assert plant.diverged() is None and plant.mujoco_warnings() == {}


def test_friction_changes_the_slip_in_a_hard_start():
    slips = {}
    for mu in (None, 0.1):
        plant = make()
        if mu is not None:
            assert "1 -> 0.1" in plant.apply(make_event("friction", 0.0, mu=mu))
            tyres = [plant.model.geom(n).id for n in ("left_tyre", "right_tyre")]
            np.testing.assert_allclose(plant.model.geom_friction[tyres, 0], mu)
        rec = hold(plant, (1.5, 0.0), 30)  # from rest to 1.5 m/s: full torque
        d = plant.data
        tyre_contacts = [i for i in range(d.ncon) if plant.model.geom(int(d.contact.geom[i][1])).name.endswith("tyre")]
        assert len(tyre_contacts) == 2
        np.testing.assert_allclose(
            d.contact.friction[tyre_contacts, 0], 1.0 if mu is None else mu
        )  # what the contact uses
        slips[mu] = np.mean(rec["u_meas"][:, 0] - rec["u_true"][:, 0])  # wheel odometry minus true speed
    assert slips[None] < 0.03
    assert slips[0.1] > 0.3


def test_wheel_radius_scale_makes_the_robot_faster_by_the_scale():
    speeds = []
    for scale in (1.0, 1.5):
        plant = make()
        if scale != 1.0:
            assert "0.05 -> 0.075 m" in plant.apply(make_event("wheel_radius", 0.0, scale=scale))
            assert plant.model.geom("left_tyre").size[0] == pytest.approx(0.075)
            assert plant.ik_radius == pytest.approx(0.05)  # the IK keeps believing the nominal radius
        hold(plant, (0.5, 0.5), 250)
        speeds.append(np.mean(hold(plant, (0.5, 0.5), 50)["u_true"], axis=0))
        assert plant.diverged() is None
    ratio = speeds[1] / speeds[0]
    np.testing.assert_allclose(ratio, [1.5, 1.5], rtol=0.02)


@pytest.mark.parametrize("actuator", DRIVES)
def test_weaker_force_limit_accelerates_slower(actuator):
    reached = []
    for force_scale in (1.0, 0.5):
        plant = make(actuator)
        if force_scale != 1.0:
            assert "torque limit 0.6 -> 0.3 N m" in plant.apply(make_event("actuator", 0.0, force_scale=force_scale))
        reached.append(hold(plant, (1.0, 0.0), 10)["u_true"][-1, 0])  # after 0.1 s at full torque
    assert reached[1] / reached[0] == pytest.approx(0.5, abs=0.05)


@pytest.mark.parametrize("actuator", DRIVES)
def test_lower_gain_follows_a_small_speed_step_slower(actuator):
    errors = []
    for kv_scale in (1.0, 0.25):
        plant = make(actuator)
        hold(plant, (0.5, 0.0), 100)
        if kv_scale != 1.0:
            plant.apply(make_event("actuator", 1.0, kv_scale=kv_scale))
            if actuator == "velocity":
                np.testing.assert_allclose(plant.model.actuator_gainprm[:, 0], 0.5)
                np.testing.assert_allclose(plant.model.actuator_biasprm[:, 2], -0.5)  # kv lives here too
        rec = hold(plant, (0.51, 0.0), 2)  # +0.2 rad/s per wheel: below the torque limit
        errors.append(np.abs(rec["wheel_cmd"][-1] - rec["wheel_meas"][-1]).max())
    assert errors[1] > 2.0 * errors[0]


def test_control_period_holds_each_command_longer():
    plant = make()
    rec = hold(plant, (1.0, 0.0), 150)
    dx_before = rec["pose"][-1, 0] - rec["pose"][-2, 0]
    text = plant.apply(make_event("control_period", 1.5, factor=1.5))
    assert "0.01 -> 0.015 s" in text
    t0, time0 = plant.sim_time, plant.data.time
    rec = hold(plant, (1.0, 0.0), 2)
    assert plant.sim_time - t0 == pytest.approx(0.03, abs=1e-12)
    assert plant.data.time - time0 == pytest.approx(0.03, abs=1e-12)
    dx_after = rec["pose"][-1, 0] - rec["pose"][-2, 0]
    assert dx_after / dx_before == pytest.approx(1.5, rel=0.01)


def test_sensor_delay_returns_the_pose_from_n_steps_ago():
    plant = make()
    hold(plant, (0.5, 0.2), 10)
    assert "0 -> 3 control steps" in plant.apply(make_event("sensor_delay", 0.1, steps=3))
    truth = [plant.true_pose().copy()]
    for k in range(12):
        plant.step(np.array([0.5 + 0.05 * k, math.sin(k)]))
        truth.append(plant.true_pose().copy())
        if k >= 2:
            np.testing.assert_array_equal(plant.measure(), truth[-4])


# --- poses, determinism, noise ---------------------------------------------------------------------


def test_reset_places_the_axle_midpoint_and_heading():
    plant = make(q0=(1.0, -2.0, 3.0))
    np.testing.assert_allclose(plant.true_pose(), [1.0, -2.0, 3.0], atol=1e-12)
    np.testing.assert_array_equal(plant.measure(), plant.true_pose())
    np.testing.assert_allclose(plant.data.site("axle_mid").xpos[:2], [1.0, -2.0], atol=1e-12)


def test_flying_start_rolls_at_u0():
    plant = MujocoPlant(MujocoConfig(), T)
    plant.reset(np.array([0.0, 0.0, 1.0]), np.random.default_rng(0), u0=np.array([1.0, 0.5]))
    assert site_velocity(plant) == pytest.approx((1.0, 0.5), abs=1e-5)  # the rest pose is pitched by ~1 mrad
    rec = hold(plant, (1.0, 0.5), 20)
    np.testing.assert_allclose(rec["u_true"], np.tile([1.0, 0.5], (20, 1)), rtol=0.02)


def test_heading_is_unwrapped():
    plant = make(q0=(0.0, 0.0, 3.0))
    rec = hold(plant, (0.0, 3.0), 300)  # spins more than one turn
    theta = rec["pose"][:, 2]
    assert theta[-1] > 3.0 + 2 * math.pi
    assert np.max(np.abs(np.diff(theta))) < 0.1


@pytest.mark.parametrize("actuator", DRIVES)
def test_same_seed_gives_bit_identical_measurements(actuator):
    def run(seed: int) -> np.ndarray:
        plant = make(actuator, seed=seed, pose_noise_std=(0.01, 0.01, 0.02))
        out = []
        for k in range(100):
            out.append(plant.measure().copy())
            plant.step(np.array([0.8 + 0.3 * math.sin(0.1 * k), math.cos(0.05 * k)]))
        return np.array(out)

    a, b = run(5), run(5)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, run(6))


def test_zero_noise_is_deterministic_and_draws_nothing():
    rngs = [np.random.default_rng(1), np.random.default_rng(2)]
    states = [r.bit_generator.state for r in rngs]
    runs = []
    for rng in rngs:
        plant = MujocoPlant(MujocoConfig(), T)
        plant.reset(np.zeros(3), rng)
        rec = hold(plant, (0.7, -0.8), 100)
        np.testing.assert_array_equal(plant.measure(), plant.true_pose())
        runs.append(rec["pose"])
    np.testing.assert_array_equal(runs[0], runs[1])
    assert [r.bit_generator.state for r in rngs] == states


def test_noise_has_the_configured_spread():
    plant = make(pose_noise_std=(0.01, 0.02, 0.0))
    diffs = []
    for _ in range(400):
        plant.step(np.array([0.5, 0.3]))
        diffs.append(plant.measure() - plant.true_pose())
    std = np.std(diffs, axis=0)
    np.testing.assert_allclose(std[:2], [0.01, 0.02], rtol=0.15)
    assert std[2] == 0.0


# --- telemetry, divergence, geometry --------------------------------------------------------------


@pytest.mark.parametrize("actuator", DRIVES)
def test_telemetry_keys_shapes_and_meaning(actuator):
    plant = make(actuator, max_wheel_speed=20.0)
    rec = hold(plant, (1.5, 0.0), 100)  # asks 30 rad/s: scaled to the 20 rad/s limit
    assert set(rec) == {"pose", "u_meas", "u_true", "wheel_cmd", "wheel_meas", "torque"}
    for key in ("u_meas", "u_true", "wheel_cmd", "wheel_meas", "torque"):
        assert rec[key].shape == (100, 2)
    np.testing.assert_allclose(rec["wheel_cmd"][-1], [20.0, 20.0])
    np.testing.assert_allclose(rec["wheel_meas"][-1], [20.0, 20.0], rtol=0.01)
    np.testing.assert_allclose(rec["u_meas"][-1], [1.0, 0.0], atol=0.01)  # FK of the measured wheels
    assert np.max(np.abs(rec["torque"])) == pytest.approx(0.6)  # the start saturates the drive


def test_diverged_reports_flips_and_flights():
    plant = make()
    assert plant.diverged() is None
    d = plant.data
    d.qpos[2] += 0.1
    mujoco.mj_forward(plant.model, d)
    assert "left the floor" in plant.diverged()
    plant = make()
    plant.data.qpos[3:7] = [0.0, 1.0, 0.0, 0.0]  # upside down
    mujoco.mj_forward(plant.model, plant.data)
    assert "tipped over" in plant.diverged()


def test_geometry_is_the_robot_seen_from_the_axle_midpoint():
    shapes = {s["name"]: s for s in make().geometry()}
    assert set(shapes) == {"chassis", "caster", "left_wheel", "right_wheel"}
    assert [shapes[n]["type"] for n in ("chassis", "caster", "left_wheel")] == ["box", "sphere", "cylinder"]
    np.testing.assert_allclose(shapes["left_wheel"]["pos"], [0.0, 0.14, 0.0], atol=1e-6)
    np.testing.assert_allclose(shapes["right_wheel"]["pos"], [0.0, -0.14, 0.0], atol=1e-6)
    np.testing.assert_allclose(shapes["left_wheel"]["size"], [0.05, 0.0125])
    np.testing.assert_allclose(shapes["caster"]["pos"], [-0.17, 0.0, -0.03], atol=1e-6)
    for s in shapes.values():
        assert len(s["quat"]) == 4 and len(s["rgba"]) == 4
        assert np.linalg.norm(s["quat"]) == pytest.approx(1.0)


# --- both robots: ours and PAL TIAGo from MuJoCo Menagerie, as shipped ----------------------------

TIAGO = {
    "model": "menagerie:pal_tiago/scene_velocity",
    "left_actuator": "wheel_left_joint_vel",
    "right_actuator": "wheel_right_joint_vel",
    "body": "base_link",
    "keyframe": "home",
    "other_actuators": "lock",
    "tyre": "sphere",
    "timestep": 0.0025,
}
TIAGO_TORQUE = {"pi_kp": 10.0, "pi_ki": 200.0}
ROBOTS = {"diffdrive": {}, "tiago": TIAGO}
ROBOT_NAMES = ["diffdrive", pytest.param("tiago", marks=pytest.mark.menagerie)]
SPEEDS = {"diffdrive": [(0.5, 0.5), (0.3, -1.5)], "tiago": [(0.3, 0.3), (0.4, 0.0), (0.15, -0.8)]}


def robot(name: str, actuator: str = "velocity", **kw) -> MujocoPlant:
    if name == "tiago":
        pytest.importorskip("mujoco_menagerie")
        kw = TIAGO_TORQUE | kw if actuator == "torque" else kw
    plant = MujocoPlant(MujocoConfig(actuator=actuator, **(ROBOTS[name] | kw)), T)
    plant.reset(np.zeros(3), np.random.default_rng(0))
    return plant


@pytest.mark.parametrize("name", ROBOT_NAMES)
@pytest.mark.parametrize("actuator", DRIVES)
def test_each_robot_tracks_constant_commands_within_2_percent(name, actuator):
    plant = robot(name, actuator)
    for u in SPEEDS[name]:
        hold(plant, u, 200)
        v, omega = np.mean(hold(plant, u, 50)["u_true"], axis=0)
        assert v == pytest.approx(u[0], rel=0.02, abs=0.002)
        assert omega == pytest.approx(u[1], rel=0.02, abs=0.004)
    assert plant.mujoco_warnings() == {}
    assert plant.diverged() is None


@pytest.mark.parametrize("name", ROBOT_NAMES)
@pytest.mark.parametrize(
    "kind, params",
    [
        ("payload", {"mass_scale": 1.5}),
        ("payload", {"mass_kg": 10.0, "body": "*"}),
        ("friction", {"mu": 0.3}),
        ("wheel_radius", {"scale": 1.1}),
        ("actuator", {"kv_scale": 0.5, "force_scale": 0.5}),
        ("control_period", {"factor": 1.5}),
        ("sensor_delay", {"steps": 2}),
    ],
)
def test_every_event_applies_to_each_robot_and_it_stays_on_its_wheels(name, kind, params):
    plant = robot(name)
    u = SPEEDS[name][0]
    hold(plant, u, 100)
    m0 = plant.model
    mass, limit, radius = float(m0.body_subtreemass[plant.robot.root]), plant._torque_max[0], plant.real_radius
    event = make_event(kind, 1.0, **params)
    plant.check_event(event, "here")
    text = plant.apply(event)
    m = plant.model
    if kind == "payload" and "body" in params:
        assert float(m.body_subtreemass[plant.robot.root]) == pytest.approx(mass + 10.0)
        assert "the whole robot" in text
    elif kind == "payload":
        assert float(m.body_subtreemass[plant.robot.root]) > mass
    elif kind == "friction":
        np.testing.assert_allclose(m.geom_friction[list(plant._tyres), 0], 0.3)
    elif kind == "wheel_radius":
        assert plant.real_radius == pytest.approx(1.1 * radius) and plant.ik_radius == pytest.approx(radius)
    elif kind == "actuator":
        assert plant._torque_max[0] == pytest.approx(0.5 * limit)
    hold(plant, u, 150)
    assert plant.diverged() is None, text
    assert plant.mujoco_warnings() == {}


@pytest.mark.parametrize("name", ROBOT_NAMES)
def test_each_robot_is_bit_identical_for_a_seed(name):
    runs = []
    for _ in range(2):
        plant = robot(name, pose_noise_std=0.001)
        runs.append(np.array([plant.measure().copy() for _ in range(40) if plant.step(np.array([0.3, 0.2])) is None]))
    np.testing.assert_array_equal(runs[0], runs[1])


@pytest.mark.menagerie
def test_smaller_wheels_that_leave_the_robot_on_its_casters_are_refused():
    """Our robot's one caster tilts it onto smaller wheels; TIAGo's four rigid casters hold its base up."""
    robot("diffdrive").check_event(make_event("wheel_radius", 1.0, scale=0.9), "here")
    with pytest.raises(ConfigError, match="here scale: wheels of 0.088.* m no longer reach the floor"):
        robot("tiago").check_event(make_event("wheel_radius", 1.0, scale=0.9), "here")


@pytest.mark.menagerie
def test_tiago_limits_are_read_where_its_makers_declared_them():
    """The wheels' speed limit is the servo's ctrlrange (5 rad/s), the torque limit the joints'
    actuatorfrcrange (100 N m): defaults, applied to (v, omega) keeping the curvature."""
    plant = robot("tiago")
    assert plant.max_wheel_speed == pytest.approx(5.0)
    assert plant._torque_max == pytest.approx((100.0, 100.0))
    rec = hold(plant, (1.0, 0.5), 5)  # asks (1.0 +- 0.1) / 0.098 rad/s: scaled down by one factor
    wl, wr = rec["wheel_cmd"][-1]
    assert max(abs(wl), abs(wr)) == pytest.approx(5.0)
    assert (wr - wl) / (wr + wl) == pytest.approx(0.5 * plant.ik_track / 2 / 1.0)  # omega / v kept
    plant.apply(make_event("actuator", 0.0, force_scale=0.2))
    assert plant._torque_max == pytest.approx((20.0, 20.0))
    rec = hold(plant, (0.45, -2.0), 30)
    assert np.max(np.abs(rec["torque"])) <= 20.0 + 1e-9  # as applied at the joint
    assert MujocoPlant(MujocoConfig(**TIAGO, max_wheel_speed=math.inf), T).max_wheel_speed is None


@pytest.mark.menagerie
def test_tiago_starts_from_its_keyframe_at_rest_with_the_arm_locked_or_held():
    locked, held = robot("tiago"), robot("tiago", other_actuators="hold")
    assert len(locked.robot.locked) == 12 and held.robot.locked == ()
    assert locked.model.nv == held.model.nv - 12
    for plant in (locked, held):
        assert plant.model.body_subtreemass[plant.robot.root] == pytest.approx(73.3, abs=0.1)
        z = plant.data.xpos[plant.robot.root, 2]
        assert z == pytest.approx(-0.99, abs=0.005)  # on its wheels on the floor at z = -0.99
        assert plant.real_radius == pytest.approx(0.0983, abs=2e-4)  # from the mesh
        assert plant.ik_track == pytest.approx(0.4044, abs=1e-4)
    torso = held.model.joint("torso_lift_joint")
    assert held.data.qpos[torso.qposadr[0]] == pytest.approx(0.15, abs=0.01)  # "home", not 0


@pytest.mark.menagerie
def test_tiago_geometry_is_its_meshes():
    shapes = robot("tiago").geometry()
    meshes = [s for s in shapes if s["type"] == "mesh"]
    assert len(meshes) > 20 and not any(s["name"].startswith("mlpfac") for s in shapes)
    for s in meshes:
        assert s["vertices"].ndim == 2 and s["vertices"].shape[1] == 3 and s["faces"].shape[1] == 3
        assert s["faces"].max() < len(s["vertices"])


# --- your own robot -------------------------------------------------------------------------------

OWN_ROBOT = """
<mujoco model="own_robot">
  <compiler autolimits="true"/>
  <option timestep="0.002" integrator="implicitfast"/>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 0.05"/>
    <body name="base" pos="0 0 0.08">
      <freejoint/>
      <inertial pos="-0.1 0 0" mass="8" diaginertia="0.05 0.08 0.1"/>
      <site name="base"/>
      <geom type="box" size="0.2 0.2 0.05" pos="-0.1 0 0.06" contype="0" conaffinity="0"/>
      <geom type="sphere" size="0.03" pos="-0.3 0 -0.05" priority="1" condim="1"/>
      <body name="wheel_a" pos="0 0.25 0">
        <joint name="wheel_a" axis="0 -1 0" armature="0.001"/>
        <inertial pos="0 0 0" mass="0.4" diaginertia="0.0007 0.0013 0.0007"/>
        <geom type="sphere" size="0.08" priority="1"/>
      </body>
      <body name="wheel_b" pos="0 -0.25 0">
        <joint name="wheel_b" axis="0 1 0" armature="0.001"/>
        <inertial pos="0 0 0" mass="0.4" diaginertia="0.0007 0.0013 0.0007"/>
        <geom type="sphere" size="0.08" priority="1"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <velocity name="lm" joint="wheel_a" kv="3" forcerange="-2 2"/>
    <velocity name="rm" joint="wheel_b" kv="1.5" gear="2" forcerange="-1 1"/>
  </actuator>
</mujoco>
"""


def write(tmp_path: Path, text: str, name: str = "robot.xml") -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("actuator", DRIVES)
def test_own_robot_geometry_read_from_the_model(tmp_path, actuator):
    cfg = MujocoConfig(
        model=write(tmp_path, OWN_ROBOT), actuator=actuator, left_actuator="lm", right_actuator="rm", site="base"
    )
    plant = MujocoPlant(cfg, 0.01)
    assert plant.n_substeps == 5
    assert plant.ik_radius == pytest.approx(0.08) and plant.ik_track == pytest.approx(0.5)
    plant.reset(np.zeros(3), np.random.default_rng(0))
    rec = hold(plant, (0.4, 0.4), 300)  # reversed left axis and a geared right motor: still (v, omega)
    np.testing.assert_allclose(np.mean(rec["u_true"][-50:], axis=0), [0.4, 0.4], rtol=0.03)
    assert plant.mujoco_warnings() == {}


def test_own_robot_with_swapped_wheels_is_refused(tmp_path):
    cfg = MujocoConfig(model=write(tmp_path, OWN_ROBOT), left_actuator="rm", right_actuator="lm", site="base")
    with pytest.raises(ConfigError, match="left_actuator.*not on the left"):
        MujocoPlant(cfg, 0.01)


# --- bad input ------------------------------------------------------------------------------------


def test_missing_model_file():
    with pytest.raises(ConfigError, match="nope.xml"):
        MujocoConfig(model="models/nope.xml")


def test_unloadable_model_names_the_file(tmp_path):
    path = write(tmp_path, "<mujoco><worldbody><bad/></worldbody></mujoco>", "broken.xml")
    with pytest.raises(ConfigError, match="broken.xml.*cannot load"):
        MujocoPlant(MujocoConfig(model=path), T)


@pytest.mark.parametrize(
    ("kw", "key"),
    [
        ({"left_actuator": "left_motor"}, "left_actuator.*left_motor"),
        ({"right_actuator": "left_wheel"}, "right_actuator"),
        ({"site": "base_link"}, "site.*base_link"),
    ],
)
def test_names_not_in_the_model(kw, key):
    with pytest.raises(ConfigError, match=key):
        MujocoPlant(MujocoConfig(**kw), T)


@pytest.mark.parametrize(
    ("kw", "key"),
    [
        ({"actuator": "servo"}, "actuator"),
        ({"pose_noise_std": -0.1}, "pose_noise_std"),
        ({"pose_noise_std": (0.1, 0.1)}, "pose_noise_std"),
        ({"wheel_radius": 0.0}, "wheel_radius"),
        ({"max_wheel_speed": -3.0}, "max_wheel_speed"),
        ({"pi_ki": -1.0}, "pi_ki"),
    ],
)
def test_bad_config_values(kw, key):
    with pytest.raises(ConfigError, match=key):
        MujocoConfig(**kw)


def test_period_that_is_not_whole_physics_steps():
    """A timestep the scenario sets wins, and must divide T; left unset, one that does is chosen."""
    with pytest.raises(ConfigError, match="T: 0.011 s is not a whole number"):
        MujocoPlant(MujocoConfig(timestep=0.002), 0.011)
    plant = MujocoPlant(MujocoConfig(), 0.011, (0.011, 0.0165))
    assert plant.config.timestep == pytest.approx(0.011 / 6) and plant.found()["timestep"] == plant.config.timestep
    assert plant.n_substeps == 6 and plant._substeps(0.0165, "factor") == 9


def test_model_without_velocity_servo_or_freejoint(tmp_path):
    motor = OWN_ROBOT.replace('<velocity name="lm" joint="wheel_a" kv="3"', '<motor name="lm" joint="wheel_a"')
    cfg = MujocoConfig(
        model=write(tmp_path, motor), left_actuator="lm", right_actuator="rm", site="base", actuator="velocity"
    )
    with pytest.raises(ConfigError, match="left_actuator.*velocity servo"):
        MujocoPlant(cfg, 0.01)
    fixed = OWN_ROBOT.replace("<freejoint/>", "")
    cfg = MujocoConfig(model=write(tmp_path, fixed, "fixed.xml"), left_actuator="lm", right_actuator="rm", site="base")
    with pytest.raises(ConfigError, match="freejoint"):
        MujocoPlant(cfg, 0.01)


@pytest.mark.parametrize(
    ("kind", "params", "match"),
    [
        ("teleport", {}, "unknown event kind"),
        ("payload", {"mass_scale": 2.0, "colour": "red"}, "colour.*not a parameter"),
        ("payload", {"mass_scale": 2.0, "body": "trailer"}, "body.*trailer"),
        ("payload", {"mass_kg": -1.0}, "mass_kg.*positive"),
        ("payload", {"mass_scale": -2.0}, "mass_scale.*positive"),
        ("payload", {"mass_scale": 2.0, "mass_kg": 1.0}, "either"),
        ("payload", {"body": "chassis"}, "either"),
        ("payload", {"mass_scale": 2.0, "offset": 0.1}, "offset.*mass_kg"),
        ("payload", {"mass_kg": 2.0, "body": "chassis", "lateral": 0.1}, "lateral.*mass_kg"),
        ("payload", {"mass_kg": 2.0, "offset": 20.0}, "offset.*<= 10"),
        ("payload", {"mass_kg": 2.0, "offset": "ahead"}, "offset.*number"),
        ("friction", {"mu": 0.0}, "mu.*positive"),
        ("friction", {}, "needs 'mu'"),
        ("wheel_radius", {"scale": -1.5}, "scale.*positive"),
        ("actuator", {}, "kv_scale"),
        ("actuator", {"kv_scale": "weak"}, "kv_scale.*number"),
        ("control_period", {"factor": 1.3}, "factor.*whole number"),
        ("control_period", {"factor": -1.0}, "factor"),
        ("sensor_delay", {"steps": -1}, "steps"),
        ("sensor_delay", {"steps": 1.5}, "steps"),
    ],
)
def test_bad_events_are_refused(kind, params, match):
    """Parameters are checked when the scenario is parsed, what the robot can apply when it is built."""
    plant = make()
    with pytest.raises(ConfigError, match=match):
        where = "scenario.toml [[events]] #1"
        plant.check_event(parse_event({"time": 1.0, "kind": kind, **params}, 25.0, where), where)


def test_friction_event_needs_tyres_that_own_the_contact(tmp_path):
    text = OWN_ROBOT.replace('<geom type="sphere" size="0.08" priority="1"/>', '<geom type="sphere" size="0.08"/>')
    own = MujocoConfig(model=write(tmp_path, text), left_actuator="lm", right_actuator="rm", site="base", tyre="model")
    plant = MujocoPlant(own, 0.01)
    with pytest.raises(ConfigError, match="priority"):
        plant.check_event(make_event("friction", 1.0, mu=0.2), "here")


# --- shipped scenarios ----------------------------------------------------------------------------

SCENARIOS = sorted((ROOT / "sims").glob("eight-*.toml"))


def test_the_eight_scenarios_are_shipped():
    names = {p.stem for p in SCENARIOS}
    assert names == {
        "eight-nominal",
        "eight-payload",
        "eight-payload-offset",
        "eight-friction",
        "eight-wheel-radius",
        "eight-weak-actuator",
        "eight-control-period",
        "eight-sensor-delay",
        "eight-torque",
        "eight-wheel-radius-odometry",  # its pose from the encoders (mlpfac.plants.sensors.sensing)
        "eight-wheel-radius-fused",  # ... and a localizer's fixes
        "eight-slope",
        "eight-ramp",
        "eight-kerb",
        "eight-bumps",
        "eight-wet-patch",
        "eight-push",
        "eight-tow",
    }


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_scenario_builds_a_plant_and_its_events_pass(path):
    table = tomllib.loads(path.read_text())
    assert table["name"] == path.stem
    assert table["description"] and "\n" not in table["description"]
    assert table["reference"]["kind"] == "eight"
    plant_table = dict(table["plant"])
    assert plant_table.pop("kind") == "mujoco"
    plant_table["model"] = str((path.parent / plant_table["model"]).resolve())
    cfg = MujocoConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in plant_table.items()})
    plant = MujocoPlant(cfg, table["T"])
    plant.reset(np.zeros(3), np.random.default_rng(0))
    events = table.get("events", [])
    assert len(events) == (0 if path.stem in ("eight-nominal", "eight-torque") or "world" in table else 1)
    for i, ev in enumerate(events):
        ev = dict(ev)
        t = float(ev.pop("time"))
        event = make_event(ev.pop("kind"), t, **ev)
        plant.check_event(event, f"{path.name} [[events]] #{i + 1}")
        assert event.time < table["duration"]
        plant.apply(event)
    hold(plant, (1.0, 0.5), 20)
    assert plant.diverged() is None


def test_a_scenario_robot_is_read_once_by_its_load_and_its_run(monkeypatch):
    """``load`` writes the parts it found into the scenario ([plant] left_actuator, ...): the run's
    configuration then names them, and is the same robot, not read (and compiled) a second time."""
    from mlpfac.loop.runner import run
    from mlpfac.plants.mjcf import robot
    from mlpfac.scenario.parse import load

    reads = []
    real = robot._read_robot
    monkeypatch.setattr(robot, "_read_robot", lambda c, *a: reads.append(c) or real(c, *a))
    monkeypatch.setattr(robot, "_ROBOTS", {})
    scn = load("eight-nominal").with_overrides(duration=0.1)
    assert scn.plant_config.left_actuator is not None and reads[0].left_actuator is None  # found, written in
    run(scn)
    run(scn.with_overrides(controller="corradini"))
    assert len(reads) == 1
    again = robot.read_robot(scn.plant_config, (scn.T,))
    monkeypatch.setattr(robot, "_ROBOTS", {})
    fresh = robot.read_robot(scn.plant_config, (scn.T,))  # read from the file with every part named
    assert len(reads) == 2 and again.found == fresh.found == () and again.config == fresh.config
    assert again.description == fresh.description and again.sha256 == fresh.sha256
