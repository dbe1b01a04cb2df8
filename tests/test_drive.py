"""What a wheel drive gives the torque-level laws (mlpfac.control.drive, mlpfac.control.torque.Drive):
known answers of the rated speed and of the traction guard, the compiled kernel against its Python
form to the bit, and in closed loop: the wheels within the rated speed, a wet floor that threw the
cart under the laws that command its torques, the oracle equal to fierro-lewis before its event."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import mlpfac
from mlpfac.control import drive
from mlpfac.control.torque import Drive, Observation
from mlpfac.dynamics import RobotModel
from mlpfac.plants import make_plant
from mlpfac.scenario.parse import load

SCENE = Path(__file__).resolve().parents[1] / "models" / "scene.xml"
R, TRACK, WMAX, TMAX = 0.1, 0.4, 5.0, 4.0
ROBOT = RobotModel(mass_kg=20.0, yaw_inertia_kg_m2=1.0, com_offset_m=0.0, wheel_radius_m=R, track_m=TRACK,
                   wheel_inertia_kg_m2=0.01, torque_limit_Nm=TMAX, wheel_speed_limit_rad_s=WMAX)  # fmt: skip
P = ROBOT.packed()
FREE = RobotModel(**(ROBOT.as_dict() | {"wheel_speed_limit_rad_s": math.inf}))  # no wheel-speed limit


def py(kernel):
    """A kernel's Python form (numba's ``py_func``; a kernel only kernels call is plain Python once built)."""
    return getattr(kernel, "py_func", kernel)


def wheels(v: float, w: float) -> tuple[float, float]:
    return (v - w * TRACK / 2) / R, (v + w * TRACK / 2) / R


def obs_of(twist, wheel_speeds) -> Observation:
    z = np.zeros(3)
    return Observation(z, np.zeros(5), np.zeros(2), z, np.asarray(twist, float), np.asarray(wheel_speeds, float), 0.0)


def test_a_command_past_the_rated_speed_is_scaled_to_it_with_its_curvature():
    """(1 m/s, 2 rad/s) asks 6 and 14 rad/s of the wheels: both scaled by 5/14, the faster wheel at
    5 rad/s, omega / v kept; a command within the limit comes back to the bit."""
    v, w = Drive(ROBOT).rated(1.0, 2.0)
    assert max(abs(x) for x in wheels(v, w)) == pytest.approx(WMAX, rel=1e-15)
    assert w / v == pytest.approx(2.0, rel=1e-15) and v == pytest.approx(5 / 14, rel=1e-15)
    assert Drive(ROBOT).rated(0.3, -0.5) == (0.3, -0.5)
    cmd = np.array([[1.0, 2.0], [-1.0, 2.0], [0.2, 0.1]])
    out = Drive(ROBOT).rated(cmd[:, 0], cmd[:, 1])  # a batch
    assert out[0][2] == 0.2 and out[1][2] == 0.1 and out[0][1] == pytest.approx(-5 / 14, rel=1e-15)


def test_the_scaled_commands_rate_is_its_derivative():
    """Along a command that passes the rated speed and changes, the rate returned is the derivative of
    the command returned (central differences, h = 1e-6 s)."""
    d = Drive(ROBOT)

    def path(t: float) -> tuple[float, float, float, float]:
        return 0.8 + 0.5 * t, 1.5 - 2.0 * t * t, 0.5, -4.0 * t  # v, omega and their rates

    for t in (0.1, 0.4, 0.7):
        v, w, dv, dw = d.rated(*path(t))
        assert max(abs(x) for x in wheels(v, w)) == pytest.approx(WMAX)
        h = 1e-6
        ahead, back = d.rated(*path(t + h))[:2], d.rated(*path(t - h))[:2]
        fd = [(a - b) / (2 * h) for a, b in zip(ahead, back, strict=True)]
        assert (dv, dw) == pytest.approx(fd, rel=1e-6, abs=1e-8)


def test_the_traction_guard_cuts_a_spinning_wheel_and_leaves_a_rolling_one():
    """At 0.5 m/s straight on (5 rad/s of ground under each wheel): the left wheel at 5 rad/s keeps
    its torque to the bit, the right one spinning at 20 rad/s loses all the torque that drives it on
    and keeps the torque that brakes it; a wheel locked under a braking torque keeps it (a skid is
    not a spin); one spun backwards loses the torque that spins it on and keeps the one that brings
    it back, going forwards or backwards; within the rolling slip (0.05 m/s / r + 0.6 min(|w|, |g|))
    nothing is cut, at twice that everything."""
    d = Drive(FREE)
    g = 0.5 / R
    assert d.torques(obs_of([0.5, 0.0], [g, 4 * g]), [1.234, 2.0]).tolist() == [1.234, 0.0]
    assert d.torques(obs_of([0.5, 0.0], [g, 4 * g]), [1.234, -2.0]).tolist() == [1.234, -2.0]
    assert d.torques(obs_of([0.5, 0.0], [0.0, g]), [-3.0, 1.0]).tolist() == [-3.0, 1.0]  # locked, braked
    assert d.torques(obs_of([0.5, 0.0], [-4 * g, g]), [-3.0, 3.0]).tolist() == [0.0, 3.0]  # spun backwards
    assert d.torques(obs_of([0.5, 0.0], [-4 * g, g]), [3.0, 3.0]).tolist() == [3.0, 3.0]
    assert d.torques(obs_of([-0.5, 0.0], [-4 * g, -g]), [-3.0, 3.0]).tolist() == [0.0, 3.0]  # reversing
    rolls = 0.05 / R + drive.SLIP_RATIO * g
    edge = d.torques(obs_of([0.5, 0.0], [g + rolls, g + 2 * rolls + 1e-9]), [1.0, 1.0])
    assert edge[0] == 1.0 and edge[1] == 0.0
    half = d.torques(obs_of([0.5, 0.0], [g + 1.5 * rolls, g]), [2.0, 2.0])
    assert half[0] == pytest.approx(1.0, rel=1e-12) and half[1] == 2.0


def test_no_torque_drives_a_wheel_past_its_rated_speed():
    """Rolling (the ground under it as fast): full torque up to w_max, none from 2 % past it, linear
    between; the torque that slows the wheel is kept; the torque limit holds."""
    d = Drive(ROBOT)

    def kept(w: float, tau: float) -> float:
        return float(d.torques(obs_of([w * R, 0.0], [w, w]), [tau, tau])[0])

    assert kept(5.0, 3.0) == 3.0 and kept(5.05, 3.0) == pytest.approx(1.5, rel=1e-9)
    assert kept(5.11, 3.0) == 0.0 and kept(6.0, 3.0) == 0.0 and kept(6.0, -3.0) == -3.0
    assert kept(1.0, 9.0) == TMAX and kept(-5.2, -3.0) == 0.0


def test_the_compiled_drive_is_its_python_form_to_the_bit():
    """drive_step and rated_step (compiled) against their Python forms over random twists, wheel
    speeds and torques, some spinning, some past the rated speed: the same bits."""
    rng = np.random.default_rng(7)
    n = 4000
    twist = rng.normal(0, 0.6, (n, 2))
    g = np.stack(wheels(twist[:, 0], twist[:, 1]), axis=1)
    spin = g * rng.choice([1.0, 1.0, 1.3, 2.5, 0.2], (n, 2)) + rng.normal(0, 0.5, (n, 2))
    tau = rng.normal(0, 3.0, (n, 2))
    out = tau.copy()
    drive.drive_step(P, twist, spin, out)
    guard = py(drive.guard)
    ref = np.array([guard(P, *twist[i], *spin[i], *tau[i]) for i in range(n)])
    assert np.array_equal(out, ref) and (out != np.clip(tau, -TMAX, TMAX)).sum() > n // 10  # the guard acted
    cmd, rate = rng.normal(0, 1.0, (n, 2)), rng.normal(0, 1.0, (n, 2))
    c2, r2 = cmd.copy(), rate.copy()
    drive.rated_step(P, c2, r2)
    rated = py(drive.rated)
    ref = np.array([rated(P, *cmd[i], *rate[i]) for i in range(n)])
    assert np.array_equal(np.hstack([c2, r2]), ref)
    assert (c2 != cmd).any() and (c2 == cmd).any()


def test_a_torque_law_keeps_the_wheels_within_their_rated_speed(tmp_path):
    """Our robot with torque motors, its wheels rated at 15 rad/s (the eight asks 23): fierro-lewis's
    velocity command never asks more of a wheel, and from 1 s on (the run starts rolling at the
    reference's speed, past it) the wheels reach it and stay within 2 % of it, as the IK keeps
    Kanayama's law's."""
    (tmp_path / "w.toml").write_text(
        f'duration = 12.0\n[plant]\nkind = "mujoco"\nmodel = "{SCENE}"\nactuator = "torque"\nmax_wheel_speed = 15.0\n'
    )
    for name in ("fierro-lewis", "adaptive-dynamic", "kanayama"):
        rec = mlpfac.run(str(tmp_path / "w.toml"), controller=name, seed=0)
        assert rec.status == "ok", rec.reason
        top = np.abs(rec.plant["wheel_meas"][int(1.0 / rec.T) : rec.n]).max()
        assert 14.0 < top < 15.0 * 1.02, (name, top)
        if name != "kanayama":
            vc = rec.ctrl["vc"][: rec.n]
            rm = make_plant(load(str(tmp_path / "w.toml")), rec.ref[:2]).dynamics()
            asked = np.abs(np.stack([vc[:, 0] - vc[:, 1] * rm.b, vc[:, 0] + vc[:, 1] * rm.b]) / rm.wheel_radius_m)
            assert asked.max() <= 15.0 * (1 + 1e-12)


@pytest.mark.parametrize(("controller", "seed"), [("fierro-lewis", 1), ("adaptive-dynamic", 0)])
def test_the_cart_keeps_the_wet_floor(controller, seed):
    """The cart with torque motors on a floor of friction 0.2 from 12.5 s: without the traction guard
    these seeds spun a wheel past 200 rad/s and left the floor (fierro-lewis at 23 s,
    adaptive-dynamic at 23.7 s); now they track, no wheel faster than three times the ground under it."""
    rec = mlpfac.run("eight-friction", controller=controller, seed=seed, robot="cart-torque")
    assert rec.status == "ok" and mlpfac.metrics(rec)["outcome"] == "tracking", rec.reason
    assert np.abs(rec.plant["wheel_meas"][: rec.n]).max() < 3 * 1.2 / 0.08  # 1.2 m/s at most, r = 0.08 m


def test_the_oracle_is_fierro_lewis_before_its_event_where_the_drive_acts(tmp_path):
    """Wheels rated at 15 rad/s (the drive scales the command and cuts the torque) and a payload at
    6 s: oracle-dynamic's torques are fierro-lewis's to the bit until then, not after."""
    (tmp_path / "p.toml").write_text(
        f'duration = 9.0\n[plant]\nkind = "mujoco"\nmodel = "{SCENE}"\nactuator = "torque"\nmax_wheel_speed = 15.0\n'
        '[[events]]\ntime = 6.0\nkind = "payload"\nmass_kg = 2.0\n'
    )
    fl, od = (mlpfac.run(str(tmp_path / "p.toml"), controller=c, seed=0) for c in ("fierro-lewis", "oracle-dynamic"))
    k = int(round(6.0 / fl.T))
    assert np.array_equal(fl.u[:k], od.u[:k]) and not np.array_equal(fl.u[k : fl.n], od.u[k : od.n])
    assert np.abs(fl.plant["wheel_meas"][:k]).max() > 14.0  # the rated speed reached before the event


def test_no_wheel_speed_limit_is_infinite():
    """A robot without a wheel-speed limit: the model says inf, the command and the torque pass."""
    d = Drive(FREE)
    assert d.rated(10.0, 3.0) == (10.0, 3.0)
    assert d.torques(obs_of([10.0, 0.0], [100.0, 100.0]), [1.0, 1.0]).tolist() == [1.0, 1.0]
