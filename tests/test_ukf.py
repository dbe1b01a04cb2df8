"""The square-root UKF over the weights: exact on linear problems, consistent with the EKF, batched."""

import numpy as np
import pytest

from mlpfac.control.adaptive.estimators import EKF, UKF
from mlpfac.control.adaptive.networks import Networks

R3 = np.diag([1e-2, 2e-2, 5e-3])


def kalman_filter(z, P, H, y, R):
    """The textbook Kalman filter measurement update (identity state model)."""
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    return z + K @ (y - H @ z), (np.eye(len(z)) - K @ H) @ P


@pytest.mark.parametrize(
    "spread",
    [dict(alpha=0.01), dict(alpha=0.1), dict(alpha=1.0), dict(alpha=2.0, beta=0.0), dict(alpha=0.5, kappa=3.0)],
)
def test_ukf_on_a_linear_problem_is_the_exact_kalman_filter(spread):
    """h(z) = H z: whatever the sigma-point spread, the UKF must reproduce the Kalman filter."""
    rng = np.random.default_rng(5)
    n = 12
    z_true = rng.normal(size=n)
    ukf = UKF(np.zeros(n), 5.0 * np.eye(n), R3, **spread)
    z, P = np.zeros(n), 5.0 * np.eye(n)
    for _ in range(200):
        H = rng.normal(size=(3, n))
        y = H @ z_true + rng.multivariate_normal(np.zeros(3), R3)
        ukf.update(y, None, lambda Z, H=H: Z @ H.T)
        z, P = kalman_filter(z, P, H, y, R3)
        np.testing.assert_allclose(ukf.z, z, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ukf.P, P, rtol=0, atol=1e-9)
    assert np.linalg.eigvalsh(ukf.P).min() > 0
    np.testing.assert_allclose(ukf.diag_P(), np.diag(P), rtol=0, atol=1e-9)
    J = rng.normal(size=(5, n))
    np.testing.assert_allclose(ukf.project(J), J @ P @ J.T, rtol=1e-9, atol=1e-12)


def test_ukf_keep_adapting_options_match_the_ekf_on_a_linear_problem():
    """Forgetting, Q and the P_max cap act on P exactly as in the EKF (square-root form or not)."""
    rng = np.random.default_rng(6)
    n = 10
    z_true = rng.normal(size=n)
    opts = dict(Q=1e-3 * np.eye(n), forgetting=0.98, P_max=2.0)
    ekf = EKF(np.zeros(n), 5.0 * np.eye(n), R3, **opts)
    ukf = UKF(np.zeros(n), 5.0 * np.eye(n), R3, alpha=0.3, **opts)
    for k in range(300):
        H = rng.normal(size=(3, n)) * (1.0 if k % 50 < 40 else 0.0)  # spells without excitation
        y = H @ z_true + rng.multivariate_normal(np.zeros(3), R3)
        ekf.update(y, lambda zz, H=H: (H @ zz, H))
        ukf.update(y, None, lambda Z, H=H: Z @ H.T)
        np.testing.assert_allclose(ukf.z, ekf.z, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ukf.P, ekf.P, rtol=0, atol=1e-9)
        assert ukf.diag_P().max() <= 2.0 * (1 + 1e-12)


def network_problem(seed=7):
    nets = Networks(error_scale=20.0)
    rng = np.random.default_rng(seed)
    z = rng.normal(0.0, 0.3, nets.alpha)
    e = rng.normal(0.0, 0.05, 3)
    u = np.array([0.8, -0.4])
    x_f, x_G = nets.inputs(e, 0.9, 0.3)
    return nets, z, e, u, x_f, x_G, rng


def test_ukf_with_a_small_spread_approaches_the_ekf_gain_on_the_networks():
    """As the spread a -> 0 the sigma points become central differences: the UKF's gain tends to the
    EKF's P H' (H P H' + R)^-1 when beta = 0. (Its predicted mean keeps the second-order term
    1/2 sum_i s_i' d2h s_i for any spread, and beta adds beta/4 of its square to P_yy, so the gain is
    compared on the UKF's own innovation, with beta = 0.)"""
    nets, z, e, u, x_f, x_G, rng = network_problem()
    y = nets.h(z, x_f, x_G, e, u) + rng.normal(0.0, 0.05, 3)
    R = 1e-4 * np.eye(3)
    P0 = 0.05 * np.eye(nets.alpha)
    _, H = nets.h_and_jacobian(z, x_f, x_G, e, u)
    K = P0 @ H.T @ np.linalg.inv(H @ P0 @ H.T + R)
    gaps = []
    for a in (0.3, 0.03, 0.003):
        ukf = UKF(z, P0, R, alpha=a, beta=0.0)
        i = ukf.update(y, None, lambda Z: nets.h(Z, x_f, x_G, e, u))
        gaps.append(np.max(np.abs(ukf.z - (z + K @ i))) / np.max(np.abs(K @ i)))
    assert gaps[-1] < 1e-4, gaps
    assert gaps[0] > gaps[1] > gaps[2], gaps  # the gap closes as the spread shrinks


def test_ukf_sigma_points_are_one_batched_call_and_batches_equal_singles():
    nets, z, e, u, x_f, x_G, rng = network_problem(8)
    calls = []

    def h_of(Z):
        calls.append(Z.shape)
        return nets.h(Z, x_f, x_G, e, u)

    ukf = UKF(z, 0.1 * np.eye(nets.alpha), 1e-4 * np.eye(3), alpha=0.2)
    y = nets.h(z, x_f, x_G, e, u) + 0.01
    ukf.update(y, None, h_of)
    assert calls == [(2 * nets.alpha + 1, nets.alpha)]
    # a batch of 3 filters (same inputs, different weights) equals three single filters
    Zb = z + rng.normal(0.0, 0.1, (3, nets.alpha))
    batch = UKF(Zb, 0.1 * np.eye(nets.alpha), 1e-4 * np.eye(3), alpha=0.2)
    batch.update(np.broadcast_to(y, (3, 3)), None, lambda Z: nets.h(Z, x_f, x_G, e, u))
    for b in range(3):
        one = UKF(Zb[b], 0.1 * np.eye(nets.alpha), 1e-4 * np.eye(3), alpha=0.2)
        one.update(y, None, lambda Z: nets.h(Z, x_f, x_G, e, u))
        np.testing.assert_allclose(batch.z[b], one.z, rtol=0, atol=1e-13)
        np.testing.assert_allclose(batch.S[b], one.S, rtol=0, atol=1e-13)


def test_ukf_covariance_stays_positive_definite_over_a_long_nonlinear_run():
    """The square-root form: P = S S' keeps positive eigenvalues after thousands of nonlinear updates."""
    nets, z_true, e, u, x_f, x_G, rng = network_problem(9)
    ukf = UKF(np.zeros(nets.alpha), 1.0 * np.eye(nets.alpha), 1e-6 * np.eye(3), alpha=1.0)
    for _ in range(1500):
        e = rng.normal(0.0, 0.05, 3)
        u = rng.normal(0.5, 0.5, 2)
        x_f, x_G = nets.inputs(e, rng.uniform(0.3, 1.1), rng.uniform(-1, 1))
        y = nets.h(z_true, x_f, x_G, e, u) + rng.normal(0.0, 1e-3, 3)
        ukf.update(y, None, lambda Z, x_f=x_f, x_G=x_G, e=e, u=u: nets.h(Z, x_f, x_G, e, u))
    assert np.all(np.isfinite(ukf.z))
    w = np.linalg.eigvalsh(ukf.P)
    assert w.min() > 0, w.min()
