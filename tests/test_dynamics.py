"""The dynamic model (mlpfac.dynamics) read from MuJoCo robots (mlpfac.plants.mjcf.dynamics): its
parameters where the MJCF gives them by hand, its accelerations against MuJoCo's, its inverse."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from mlpfac.dynamics import RobotModel
from mlpfac.exceptions import ConfigError
from mlpfac.plants.config import MujocoConfig
from mlpfac.plants.mujoco import MujocoPlant

ROOT = Path(__file__).resolve().parents[1]
TUG = ROOT / "models" / "tug.xml"
ROBOTS = {"ours": ROOT / "models" / "scene.xml", "cart": ROOT / "models" / "cart-scene.xml", "tug": TUG}
# MuJoCo's tyres are soft contacts that slip a little sideways in a turn (about 4 % of v omega on
# our 5.5 kg robot): the rigid rolling model matches its accelerations to within this share of the
# larger of the two's size, plus a floor for an acceleration near zero
REL_TOL, ABS_TOL = 0.06, 0.03  # -, m/s^2 or rad/s^2


def plant(path: Path) -> MujocoPlant:
    p = MujocoPlant(MujocoConfig(model=str(path), actuator="torque"), 0.01)
    p.torque_commands()
    p.reset(np.zeros(3), np.random.default_rng(0))
    return p


def test_parameters_of_the_tug_by_hand():
    """24 kg: a 14 kg chassis on the axle, an 8 kg load 0.2 m ahead, two 1 kg wheels 0.25 m aside (read
    at rest, settled on its casters: tilted by a fraction of a degree, hence 1e-3)."""
    rm = plant(TUG).dynamics()
    assert rm.mass_kg == pytest.approx(24.0)
    assert rm.com_offset_m == pytest.approx(8 * 0.2 / 24, rel=1e-3)
    assert abs(rm.com_lateral_m) < 1e-12
    izz = 0.6 + (0.05 + 8 * 0.2**2) + 2 * (0.0027 + 1 * 0.25**2)  # chassis, load, wheels about the axle
    assert rm.yaw_inertia_kg_m2 == pytest.approx(izz, rel=1e-3)
    assert rm.wheel_inertia_kg_m2 == pytest.approx(0.005 + 0.02, rel=1e-3)  # the wheel about its axle + armature
    assert (rm.wheel_radius_m, rm.track_m) == pytest.approx((0.1, 0.5))
    assert rm.torque_limit_Nm == pytest.approx(4.0)
    assert rm.wheel_damping_Nm_s == pytest.approx(0.05)


def test_the_rated_wheel_speed_is_the_plants():
    """The model a torque-level law is given holds the wheel-speed limit the IK keeps: none on the
    tug (inf), [plant] max_wheel_speed where the file sets one, and the true model the same."""
    assert plant(TUG).dynamics().wheel_speed_limit_rad_s == float("inf")
    p = MujocoPlant(MujocoConfig(model=str(TUG), actuator="torque", max_wheel_speed=12.0), 0.01)
    assert p.dynamics().wheel_speed_limit_rad_s == 12.0
    p.reset(np.zeros(3), np.random.default_rng(0))
    assert p.true_dynamics().wheel_speed_limit_rad_s == 12.0


def test_our_robot_by_hand():
    rm = plant(ROBOTS["ours"]).dynamics()
    assert rm.mass_kg == pytest.approx(5.5)
    assert rm.com_offset_m == pytest.approx(5 * -0.05 / 5.5, rel=1e-3)  # its battery behind the axle
    assert rm.wheel_inertia_kg_m2 == pytest.approx(0.0003125 + 0.001, rel=1e-3)
    assert rm.torque_limit_Nm == pytest.approx(0.6)


@pytest.mark.parametrize("name", list(ROBOTS))
def test_accelerations_match_mujoco(name):
    """Driven from rest for 0.2 s (the tyres' contacts settled into rolling), then for three pairs of
    wheel torques: the model's (vdot, omegadot) against MuJoCo's at the axle midpoint (mj_forward)."""
    p = plant(ROBOTS[name])
    rm = p.dynamics()
    lim = rm.torque_limit_Nm
    for _ in range(20):  # a turn under way: v and omega both well away from zero
        p.step(np.array([0.3 * lim, 0.6 * lim]))
    m, d = p.model, p.data
    for tau in ([0.5, 0.5], [-0.4, 0.6], [0.7, -0.2]):
        tau = np.array(tau) * lim
        for a, c, t in zip(p._acts, p._act_per_wheel, tau, strict=True):
            d.ctrl[a] = t / c
        mujoco.mj_forward(m, d)
        mujoco.mj_rnePostConstraint(m, d)
        acc, vel = np.zeros(6), np.zeros(6)
        mujoco.mj_objectAcceleration(m, d, mujoco.mjtObj.mjOBJ_SITE, p._site, acc, 1)  # (angular, linear), local
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, p._site, vel, 1)
        twist = np.array([vel[3], vel[2]])
        assert twist[0] > 0.1 and abs(twist[1]) > 0.2
        got, want = rm.accelerations(twist, tau), np.array([acc[3], acc[2]])
        scale = np.max(np.abs(want))
        assert np.all(np.abs(got - want) <= REL_TOL * scale + ABS_TOL), (name, tau, got, want)


def test_torques_invert_accelerations():
    rm = plant(TUG).dynamics()
    rng = np.random.default_rng(3)
    twist, tau = rng.normal(size=(16, 2)), rng.normal(size=(16, 2))
    acc = rm.accelerations(twist, tau)
    assert np.allclose(rm.torques(twist, acc), tau, rtol=0, atol=1e-12)
    # the centre of mass off the axle couples the two, the wheels' damping drags: no torque, v = omega = 1
    a = rm.accelerations(np.array([1.0, 1.0]), np.zeros(2))
    md, c, r, b = rm.mass_kg * rm.com_offset_m, rm.wheel_damping_Nm_s, rm.wheel_radius_m, rm.b
    assert a[0] == pytest.approx((md - 2 * c / r**2) / rm.packed()[0], rel=1e-12)
    assert a[1] == pytest.approx((-md - 2 * c * b * b / r**2) / rm.packed()[1], rel=1e-12)


def test_bad_model_is_refused():
    good = plant(TUG).dynamics().as_dict()
    for key, bad in (("mass_kg", 0.0), ("track_m", -1.0), ("torque_limit_Nm", float("nan")), ("wheel_radius_m", True),
                     ("wheel_speed_limit_rad_s", 0.0)):  # fmt: skip
        with pytest.raises(ConfigError, match=key):
            RobotModel(**(good | {key: bad}))
