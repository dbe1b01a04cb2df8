"""The oracles told how a robot's wheels answer a command (mlpfac/control/oracle.py): the measurement
(:func:`mlpfac.plants.mjcf.settle.wheels_answer`) against servos whose answer is known in closed form,
the command that undoes it, the predictor exact over such wheels, and on a light robot with weak
servos (tests/data/weak_servo.xml) each told law no worse than itself told nothing."""

from __future__ import annotations

import math
import statistics
from pathlib import Path

import numpy as np
import pytest

from mlpfac.control.law import Law
from mlpfac.control.oracle import Oracle
from mlpfac.loop.factory import make_controller
from mlpfac.loop.metrics import metrics
from mlpfac.loop.runner import run
from mlpfac.plants import make_plant
from mlpfac.plants.ik import body_velocity, wheel_speeds
from mlpfac.plants.mjcf.settle import wheels_answer
from mlpfac.scenario.on_robot import peak_wheel_speed
from mlpfac.scenario.parse import load
from mlpfac.scenario.reference import sample

WEAK = Path(__file__).parent / "data" / "weak_servo.xml"
LAW = Law((0.9, 0.85, 0.8), v_max=2.0, omega_max=5.0)
GAINS = (10.0, 64.0, 16.0)
T, IK = 0.01, (0.05, 0.3)
E = np.array([0.004, -0.003, 0.02])
R = np.array([0.3, -0.2, 0.7, 0.9, 0.4])


def answer_of(model: Path) -> tuple[float, float]:
    scn = load("eight-nominal", robot=str(model))
    probe = make_plant(scn, sample(scn.reference, np.arange(2) * scn.T))
    return wheels_answer(probe, peak_wheel_speed(scn.reference, scn.duration, probe.robot))


def test_a_weak_servo_against_joint_friction_answers_friction_over_kv_slower():
    """Known answer: a velocity servo kv (w_asked - w) holds a joint's friction torque F at
    w = w_asked - F / kv, whatever is asked: 0.1 N m / 0.1 N m s/rad = 1 rad/s slower, gain 1."""
    gain, offset = answer_of(WEAK)
    assert gain == pytest.approx(1.0, abs=0.002) and offset == pytest.approx(0.1 / 0.1, rel=0.01)


def test_a_servo_against_joint_damping_answers_kv_over_kv_plus_damping(tmp_path):
    """Known answer: against a joint's damping D instead, kv (w_asked - w) = D w: w = kv / (kv + D)
    of what is asked, no offset."""
    xml = WEAK.read_text().replace('frictionloss="0.1"', 'damping="0.05"')
    (tmp_path / "damped.xml").write_text(xml)
    gain, offset = answer_of(tmp_path / "damped.xml")
    assert gain == pytest.approx(0.1 / (0.1 + 0.05), abs=0.003) and offset == pytest.approx(0.0, abs=0.005)


def test_wheels_that_answer_as_asked_tell_the_oracle_nothing_more():
    """Our robot's stiff servos answer as asked (to 3 digits): the oracle's changes are only the event's."""
    assert answer_of(Path(__file__).parents[1] / "models" / "scene.xml") == (1.0, 0.0)
    ctrl = make_controller(load("eight-sensor-delay").with_overrides(controller="oracle"))
    assert ctrl.changes == [(12.5, "sensor_delay", 3.0)]


def test_the_factory_tells_the_oracle_the_weak_servos_answer_with_the_change():
    told = make_controller(load("eight-wheel-radius", robot=str(WEAK)).with_overrides(controller="oracle-kanayama"))
    (t0, kind0, _), (t1, kind1, gain), (t2, kind2, offset) = told.changes
    assert (t0, t1, t2) == (12.5, 12.5, 12.5)
    assert (kind0, kind1, kind2) == ("wheel_radius", "wheel_gain", "wheel_offset")
    assert gain == pytest.approx(1.0, abs=0.002) and offset == pytest.approx(1.0, rel=0.01)
    assert told.ik == (pytest.approx(0.033), pytest.approx(0.16))
    nothing = make_controller(load("eight-payload", robot=str(WEAK)).with_overrides(controller="oracle"))
    assert nothing.changes == [(12.5, "payload", 1.0)]  # told nothing of the payload: nor of the wheels


def test_what_an_oracle_is_told_is_measured_once_for_the_seeds_of_a_scenario(monkeypatch, tmp_path):
    """The wheels' answer is measured on a robot of the scenario's, not the run's: once a process for
    the seeds of one scenario (a sweep's grid point), again for another value of it or a ground drawn
    for each seed (mlpfac.loop.factory.MEASURED); every seed is told the same numbers."""
    from mlpfac.loop import factory
    from mlpfac.plants.mjcf import settle

    calls: list[tuple] = []
    monkeypatch.setattr(settle, "wheels_answer", lambda *a: calls.append(a) or wheels_answer(*a))
    monkeypatch.setattr(factory, "MEASURED", {})
    scn = load("eight-wheel-radius", robot=str(WEAK)).with_overrides(controller="oracle-kanayama")
    told = make_controller(scn).changes
    assert len(calls) == 1 and [kind for _, kind, _ in told] == ["wheel_radius", "wheel_gain", "wheel_offset"]
    assert make_controller(scn.with_overrides(seed=7)).changes == told and len(calls) == 1
    other = load("eight-wheel-radius", robot=str(WEAK), values={"events.0.scale": 1.3})
    assert make_controller(other.with_overrides(controller="oracle-kanayama")).changes != told and len(calls) == 2
    root = Path(__file__).parents[1]
    text = (root / "sims" / "eight-bumps.toml").read_text().replace("../models/", f"{root}/models/")
    (tmp_path / "bumps.toml").write_text(text + '\n[[events]]\ntime = 12.5\nkind = "wheel_radius"\nscale = 1.5\n')
    bumps = load(tmp_path / "bumps.toml").with_overrides(controller="oracle")
    for seed in (0, 1, 1):  # the rough ground is drawn for each seed: measured for each
        make_controller(bumps.with_overrides(seed=seed))
    assert len(calls) == 4


def signs(r) -> np.ndarray:
    """The signs of the reference's wheel speeds, left and right."""
    return np.sign(wheel_speeds(r[3], r[4], *IK))


@pytest.mark.parametrize("gains", [None, GAINS])
def test_the_oracle_asks_the_wheel_speeds_the_wheels_answer_with_the_ones_its_law_means(gains):
    """Known answer: told gain a and offset b, the IK of the command sent is (w + b s) / a, w the IK of
    the law's command and s the signs of the reference's wheel speeds."""
    a, b = 0.9, 0.5
    told = Oracle(LAW, T, [(0.0, "wheel_gain", a), (0.0, "wheel_offset", b)], False, gains, IK)
    plain = Oracle(LAW, T, [], False, gains, IK)
    for o in (told, plain):
        o.reset(np.random.default_rng(0))
    for r in (R, R * [1, 1, 1, 1, 12.0], R * [1, 1, 1, -1, 1]):  # the inner wheel forward, backward; reversing
        meant = wheel_speeds(*plain.step(E, r), *IK)
        np.testing.assert_allclose(wheel_speeds(*told.step(E, r), *IK), (meant + b * signs(r)) / a, rtol=1e-13)


def test_the_predictor_is_exact_over_wheels_that_answer_with_an_offset():
    """A unicycle whose wheels turn at a w_asked - b s, the pose seen 3 steps late: Kanayama's oracle
    told the delay and the wheels acts as the one told the wheels alone on the current pose."""
    a, b, d = 0.9, 0.5, 3
    wheels = [(0.0, "wheel_gain", a), (0.0, "wheel_offset", b)]
    o, free = (
        Oracle(LAW, T, [(0.0, "sensor_delay", float(d)), *wheels], False, GAINS, IK),
        Oracle(LAW, T, wheels, False, GAINS, IK),
    )
    for x in (o, free):
        x.reset(np.random.default_rng(0))
    q, poses = R[:3] - [0.001, 0.0005, 0.002], []  # near the reference: no command at its limit
    for k in range(8):
        poses.append(q)
        r = R + np.array([T * R[3] * k, 0.0, 0.0, 0.0, 0.0])
        u = o.step(error_of(poses[k - min(k, d)], r), r)
        assert np.all(np.abs(u) < [1.5, 2.5])  # no command at a limit
        np.testing.assert_allclose(u, free.step(error_of(q, r), r), rtol=1e-9, atol=1e-12)
        v, w = body_velocity(a * wheel_speeds(*u, *IK) - b * signs(r), *IK)
        q = arc(q, v, w, T)


def error_of(q, r) -> np.ndarray:
    c, s = math.cos(q[2]), math.sin(q[2])
    dx, dy = r[0] - q[0], r[1] - q[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, r[2] - q[2]])


def arc(q, v, w, dt) -> np.ndarray:
    """The unicycle moved at (v, w) for dt, exactly."""
    x, y, th = q
    return np.array([x + v / w * (math.sin(th + w * dt) - math.sin(th)),
                     y - v / w * (math.cos(th + w * dt) - math.cos(th)), th + w * dt])  # fmt: skip


@pytest.mark.parametrize("told, untold", [("oracle", "corradini"), ("oracle-kanayama", "kanayama")])
def test_the_oracle_on_the_weak_servos_is_corradini_to_the_bit_before_the_event(told, untold):
    scn = load("eight-control-period", robot=str(WEAK)).with_overrides(duration=13.0)
    a, b = run(scn.with_overrides(controller=told)), run(scn.with_overrides(controller=untold))
    n = int(round(12.5 / T))
    np.testing.assert_array_equal(a.u[:n], b.u[:n])
    assert not np.array_equal(a.u[n:], b.u[n:])


@pytest.mark.parametrize("scenario", ["eight-wheel-radius", "eight-sensor-delay", "eight-control-period"])
@pytest.mark.parametrize("told, untold", [("oracle", "corradini"), ("oracle-kanayama", "kanayama")])
def test_on_the_weak_servos_each_told_law_is_no_worse_than_itself_told_nothing(scenario, told, untold):
    """Per seed, position RMS after the event, median of 4 seeds: told / untold at most 1.1 (told only
    the event, 1.7-4.1: tests/data/weak_servo.xml, docs/controllers.md)."""
    scn = load(scenario, robot=str(WEAK))  # the whole run: the told law's transient after the radius is longer

    def after(ctrl: str, seed: int) -> float:
        return metrics(run(scn.with_overrides(controller=ctrl, seed=seed)))["phases"]["after"]["rms_position_error_m"]

    assert statistics.median(after(told, s) / after(untold, s) for s in range(4)) <= 1.1


def test_the_summary_marks_a_told_law_worse_than_itself_told_nothing():
    """x untold: per seed the told law's RMS / the untold one's, median; marked past 1.1 (oracle 1.2x
    corradini here), not at or below it (oracle-kanayama 0.5x kanayama), nor on an untold law."""
    from mlpfac.loop.metrics import RunMetrics
    from mlpfac.sweeps.paired import UNTOLD_MARK, paired_rows, summary
    from mlpfac.sweeps.plan import plan

    after = {"oracle": 0.0024, "corradini": 0.002, "oracle-kanayama": 0.001, "kanayama": 0.002}
    jobs = plan(["eight-wheel-radius"], list(after), [0, 1, 2])

    def fake(scn, ctrl, seed):
        rms = after[ctrl] * (1 + 0.01 * seed)
        phases = {"before": {"start_s": 2.0, "end_s": 12.5, "rms_position_error_m": 0.001},
                  "after": {"start_s": 12.5, "end_s": 25.0, "rms_position_error_m": rms}}  # fmt: skip
        return {"status": "ok", "outcome": "tracking", "T": 0.01, "steps": 2500, "phases": phases,
                "scenario": scn, "controller": ctrl, "seed": seed,
                "position_ms_bins": {"bin_steps": 10, "m2": [rms**2] * 250}}  # fmt: skip

    rows = paired_rows(jobs, {j.key: RunMetrics.from_json(fake(*j.key)) for j in jobs})
    x = {r["controller"]: r["x_untold_median"] for r in rows}
    assert x == {
        "oracle": pytest.approx(1.2),
        "corradini": None,
        "oracle-kanayama": pytest.approx(0.5),
        "kanayama": None,
    }
    marked = [line.split("|")[1].strip() for line in summary(rows).splitlines() if UNTOLD_MARK in line]
    assert marked == ["`oracle`"]


def test_the_dynamic_oracle_moves_the_delayed_twist_through_the_torques_sent():
    """Known answer: without damping or an offset centre of mass the model's accelerations are B tau / M,
    (tau_l + tau_r) / (r m') and b (tau_r - tau_l) / (r I'): the twist moves by their sum times each
    torque's seconds."""
    from mlpfac.control.dynamic import twist_ahead
    from mlpfac.dynamics import RobotModel

    robot = RobotModel(5.0, 0.2, 0.0, 0.05, 0.3, 1e-3, 2.0)
    p = robot.packed()
    m, i = 5.0 + 2 * 1e-3 / 0.05**2, 0.2 + 2 * 0.15**2 * 1e-3 / 0.05**2  # M's diagonal, the wheels' inertia in it
    sent = [(np.array([[0.2, 0.3]]), 0.01), (np.array([[-0.1, 0.4]]), 0.015)]
    got = twist_ahead(p, np.array([[0.5, -0.2]]), sent)
    dv = sum(dt * (t[0, 0] + t[0, 1]) / (0.05 * m) for t, dt in sent)
    dw = sum(dt * 0.15 * (t[0, 1] - t[0, 0]) / (0.05 * i) for t, dt in sent)
    np.testing.assert_allclose(got, [[0.5 + dv, -0.2 + dw]], rtol=1e-14)
