"""Differential-drive kinematics: known answers, IK then FK is the identity, the wheel-speed limit."""

from __future__ import annotations

import numpy as np
import pytest

from mlpfac.plants.ik import body_velocity, wheel_speeds

R, L = 0.05, 0.28


def test_known_answers():
    np.testing.assert_allclose(wheel_speeds(1.0, 0.0, R, L), [20.0, 20.0])  # straight: v / r
    np.testing.assert_allclose(wheel_speeds(0.0, 1.0, R, L), [-2.8, 2.8])  # on the spot: omega L / 2r
    np.testing.assert_allclose(wheel_speeds(0.5, 0.5, R, L), [8.6, 11.4])
    np.testing.assert_allclose(body_velocity(np.array([8.6, 11.4]), R, L), [0.5, 0.5])


def test_ik_then_fk_is_identity():
    rng = np.random.default_rng(1)
    for v, omega, r, track in zip(
        rng.uniform(-2, 2, 200),
        rng.uniform(-5, 5, 200),
        rng.uniform(0.02, 0.2, 200),
        rng.uniform(0.1, 0.6, 200),
        strict=True,
    ):
        u = body_velocity(wheel_speeds(v, omega, r, track), r, track)
        np.testing.assert_allclose(u, [v, omega], rtol=0, atol=1e-12)


def test_fk_then_ik_is_identity():
    rng = np.random.default_rng(2)
    for w in rng.uniform(-50, 50, (100, 2)):
        v, omega = body_velocity(w, R, L)
        np.testing.assert_allclose(wheel_speeds(v, omega, R, L), w, rtol=0, atol=1e-12)


def test_limit_keeps_curvature_and_is_respected():
    rng = np.random.default_rng(3)
    w_max = 30.0
    scaled = 0
    for v, omega in zip(rng.uniform(-2, 2, 300), rng.uniform(-5, 5, 300), strict=True):
        free = wheel_speeds(v, omega, R, L)
        w = wheel_speeds(v, omega, R, L, max_wheel_speed=w_max)
        assert np.max(np.abs(w)) <= w_max * (1 + 1e-12)
        v2, omega2 = body_velocity(w, R, L)
        if np.max(np.abs(free)) <= w_max:
            np.testing.assert_array_equal(w, free)  # under the limit: untouched
            continue
        scaled += 1
        assert np.max(np.abs(w)) == pytest.approx(w_max, rel=1e-12)  # the faster wheel sits on the limit
        s = v2 / v  # one factor for both: the curvature omega / v and the direction are kept
        assert 0 < s < 1
        assert omega2 == pytest.approx(s * omega, rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(w, s * free, rtol=1e-12)
    assert scaled > 50  # the test exercised the limit


def test_limit_on_the_spot_turn():
    w = wheel_speeds(0.0, 5.0, R, L, max_wheel_speed=10.0)
    np.testing.assert_allclose(w, [-10.0, 10.0])
    v, omega = body_velocity(w, R, L)
    assert v == 0.0 and omega == pytest.approx(10.0 * 2 * R / L)
