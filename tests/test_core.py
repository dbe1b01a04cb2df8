"""Known-answer and finite-difference checks of the controller core."""

import numpy as np
import pytest

from mlpfac.control.adaptive.estimators import EKF
from mlpfac.control.adaptive.networks import Networks
from mlpfac.control.law import Law
from mlpfac.exceptions import ConfigError
from mlpfac.model import G_true, f_true, h_true, pose_from_error, tracking_error, wrap
from mlpfac.scenario.reference import Circle, Eight, Lemniscate, Line, make_reference, sample

NETS = [Networks(), Networks(L_f=5, L_G=3, error_scale=20.0), Networks(residual=True), Networks(velocity_inputs=True)]


@pytest.mark.parametrize("nets", NETS)
def test_jacobian_matches_central_differences(nets):
    rng = np.random.default_rng(1)
    z = rng.normal(0, 1.0, nets.alpha)
    e = rng.normal(0, 0.1, 3)
    u = np.array([0.8, -0.6])
    x_f, x_G = nets.inputs(e, 0.9, 0.3, np.array([0.7, -0.4]))
    h, H = nets.h_and_jacobian(z, x_f, x_G, e, u)
    assert H.shape == (3, nets.alpha)
    np.testing.assert_allclose(h, nets.h(z, x_f, x_G, e, u), rtol=1e-14, atol=1e-15)
    H_fd = np.empty_like(H)
    for i in range(nets.alpha):
        d = 1e-6 * max(1.0, abs(z[i]))
        zp, zm = z.copy(), z.copy()
        zp[i] += d
        zm[i] -= d
        H_fd[:, i] = (nets.h(zp, x_f, x_G, e, u) - nets.h(zm, x_f, x_G, e, u)) / (zp[i] - zm[i])
    assert np.max(np.abs(H - H_fd)) / np.max(np.abs(H)) <= 1e-6


def test_weight_count_and_layout():
    nets = Networks()
    assert nets.alpha == 171  # 3*18 + 18*6 + 6*1 + 1*3
    z = np.arange(nets.alpha, dtype=float)
    W_f, S_f, W_G, S_G = nets.split(z)
    assert W_f[1, 0] == 18  # w_2 starts after w_1 (16)
    assert S_f[0, 0] == 54  # s_f1 after the output weights
    assert W_G[0, 1, 0] == 163 and S_G[0, 0] == 168  # w_12, then s_G1 (17)
    assert len(set(nets.labels())) == nets.alpha
    vel = Networks(velocity_inputs=True)
    assert vel.n_f == 8 and vel.alpha == 207  # 3*18 + 18*8 + 6*1 + 1*3
    assert len(set(vel.labels())) == vel.alpha
    x_f, _ = vel.inputs(np.array([0.01, 0.02, 0.03]), 0.9, 0.3, np.array([0.7, -0.4]))
    np.testing.assert_array_equal(x_f, [0.2, 0.4, 0.6, 0.9, 0.3, 1.0, 0.7, -0.4])
    X_f, _ = vel.inputs(np.full((2, 3), 0.01), 0.9, 0.3, np.array([[0.7, -0.4], [0.1, 0.2]]))
    np.testing.assert_array_equal(X_f[:, 6:], [[0.7, -0.4], [0.1, 0.2]])


def test_batched_networks_equal_single():
    nets = Networks(error_scale=10.0)
    rng = np.random.default_rng(2)
    Z, E, U = rng.normal(size=(5, nets.alpha)), rng.normal(0, 0.1, (5, 3)), rng.normal(size=(5, 2))
    x_f, x_G = nets.inputs(E, 0.7, 0.2)
    h, H = nets.h_and_jacobian(Z, x_f, x_G, E, U)
    for b in range(5):
        hb, Hb = nets.h_and_jacobian(Z[b], x_f[b], x_G[b], E[b], U[b])
        np.testing.assert_array_equal(h[b], hb)
        np.testing.assert_array_equal(H[b], Hb)


def test_ekf_on_a_linear_problem_is_the_exact_kalman_filter():
    rng = np.random.default_rng(3)
    n, R = 12, np.diag([1e-2, 2e-2, 5e-3])
    z_true = rng.normal(size=n)
    ekf = EKF(np.zeros(n), 5.0 * np.eye(n), R)
    z, P = np.zeros(n), 5.0 * np.eye(n)
    for _ in range(200):
        H = rng.normal(size=(3, n))
        y = H @ z_true + rng.multivariate_normal(np.zeros(3), R)
        ekf.update(y, lambda zz, H=H: (H @ zz, H))
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)  # textbook KF
        z = z + K @ (y - H @ z)
        P = (np.eye(n) - K @ H) @ P
        np.testing.assert_allclose(ekf.z, z, rtol=0, atol=1e-10)
        np.testing.assert_allclose(ekf.P, P, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(ekf.P, ekf.P.T)
    assert np.linalg.eigvalsh(ekf.P).min() > 0


def closed_loop(e, law, v_r, omega_r, T):
    """One step of model (5)-(6) under the law (35) with the true h."""
    u = law.control(e, h_true(e, v_r, omega_r, T), v_r, T)
    return f_true(e, v_r, omega_r, T) + G_true(e, T) @ u


def test_e1_decays_exactly_as_lambda1():
    law, T = Law((0.7, 0.8, 0.9), v_max=None, omega_max=None), 0.01
    e = np.array([0.2, -0.1, 0.05])
    e1 = [e[0]]
    for k in range(50):
        e = closed_loop(e, law, 0.6 + 0.01 * k, 0.3, T)
        e1.append(e[0])
    np.testing.assert_allclose(e1, 0.2 * 0.7 ** np.arange(51), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("lambdas", [(0.8, 0.8, 0.8), (0.5, 0.7, 0.95), (0.9, 0.3, 0.6)])
def test_closed_loop_has_the_requested_eigenvalues(lambdas):
    law, T, v_r, omega_r = Law(lambdas, v_max=None, omega_max=None), 0.01, 0.9, 0.4
    J = np.empty((3, 3))
    for i in range(3):
        d = np.zeros(3)
        d[i] = 1e-7
        J[:, i] = (closed_loop(d, law, v_r, omega_r, T) - closed_loop(-d, law, v_r, omega_r, T)) / 2e-7
    got = np.sort(np.linalg.eigvals(J).real)
    np.testing.assert_allclose(got, np.sort(lambdas), atol=1e-6)


def test_printed_gain_assignment_would_not_place_them():
    """The erratum: with k2 and k3 swapped as printed in (36), 0.95 is not where the eigenvalues go."""
    T, v_r, lam = 0.01, 0.9, 0.95
    k2_printed, k3_printed = 2 - 2 * lam, (1 - lam) ** 2 / (T * v_r)
    A = np.array([[1.0, T * v_r], [-k2_printed, 1.0 - k3_printed]])
    assert not np.allclose(np.linalg.eigvals(A), lam, atol=1e-3)


def test_tracking_error_round_trip_and_wrap():
    rng = np.random.default_rng(4)
    for _ in range(100):
        q_r, e = rng.normal(size=3) * [3, 3, 10], rng.normal(size=3) * [0.5, 0.5, 1]
        e[2] = wrap(e[2])
        np.testing.assert_allclose(tracking_error(pose_from_error(e, q_r), q_r), e, atol=1e-12)
    assert wrap(np.pi) == np.pi and wrap(-np.pi) == np.pi and abs(wrap(3 * np.pi) - np.pi) < 1e-12


@pytest.mark.parametrize("curve", [Eight(), Circle(), Line(), Lemniscate(), Eight(speed=2.5), Lemniscate(speed=0.4)])
def test_references_are_consistent(curve):
    t = np.linspace(0.0, 30.0, 30001)
    r = sample(curve, t)
    h = t[1] - t[0]
    dx, dy = np.gradient(r[:, 0], h), np.gradient(r[:, 1], h)
    np.testing.assert_allclose(np.hypot(dx, dy)[2:-2], r[2:-2, 3], atol=1e-5)  # v_r = |p'|
    np.testing.assert_allclose(np.gradient(r[:, 2], h)[2:-2], r[2:-2, 4], atol=1e-4)  # omega_r = theta_r'
    np.testing.assert_allclose((np.cos(r[:, 2]) * r[:, 3])[2:-2], dx[2:-2], atol=1e-4)  # (1)
    assert np.max(np.abs(np.diff(r[:, 2]))) < 0.01  # continuous heading


@pytest.mark.parametrize("kind", ["eight", "circle", "line", "lemniscate"])
def test_speed_traverses_the_same_path_faster(kind):
    """reference.speed = k: the path of speed 1 at t is reached at t / k, with v_r and omega_r x k."""
    t = np.linspace(0.0, 30.0, 3001)
    slow = sample(make_reference(kind, {}), t)
    fast = sample(make_reference(kind, {"speed": 2.0}), t / 2.0)  # k t exact for k = 2
    np.testing.assert_array_equal(fast[:, :3], slow[:, :3])
    np.testing.assert_array_equal(fast[:, 3:], 2.0 * slow[:, 3:])
    assert np.array_equal(sample(make_reference(kind, {"speed": 1.0}), t), slow)  # speed 1: the same bits


def test_figure_of_eight_speed_range():
    r = sample(Eight(), np.linspace(0, 8 * np.pi, 10001))
    assert 0.34 < r[:, 3].min() < 0.36 and 1.11 < r[:, 3].max() < 1.12


def test_law_rejects_eigenvalues_outside_the_unit_circle():
    with pytest.raises(ConfigError, match="unit circle"):
        Law((0.8, 1.2, 0.8))


def test_config_error_survives_a_process_boundary():
    import pickle

    err = pickle.loads(pickle.dumps(ConfigError("sims/x.toml [plant] model", "file not found")))
    assert str(err) == "sims/x.toml [plant] model: file not found" and err.where == "sims/x.toml [plant] model"


def _plain_ekf_update(z, P, y, h, H, R, Q, forgetting, P_max):
    """The short-form update written plainly, one new array per operation: the reference."""
    PHt = P @ H.T
    K = np.linalg.solve(H @ PHt + R, PHt.T).T
    z = z + K @ (y - h)
    P = (P - K @ PHt.T) / forgetting + Q
    return z, P * min(1.0, P_max / np.max(np.diag(P)))


def test_compiled_ekf_update_equals_the_plain_formula():
    import copy

    rng = np.random.default_rng(5)
    n, R, Q = 20, np.diag([1e-3, 2e-3, 1e-3]), 1e-6 * np.eye(20)
    ekf = EKF(np.zeros(n), np.eye(n), R, Q=Q, forgetting=0.999, P_max=2.0)
    z, P = np.zeros(n), np.eye(n)
    twin = None
    for k in range(60):
        H, y = rng.normal(size=(3, n)), rng.normal(size=3)
        h = 0.1 * H @ ekf.z
        ekf.update(y, lambda zz, H=H, h=h: (h, H))
        z, P = _plain_ekf_update(z, P, y, h, H, R, Q, 0.999, 2.0)
        np.testing.assert_allclose(ekf.z, z, rtol=0, atol=1e-10)  # round-off only, as the exact-Kalman test
        np.testing.assert_allclose(ekf.P, P, rtol=0, atol=1e-10)
        np.testing.assert_array_equal(ekf.P, ekf.P.T)  # exactly symmetric, with no symmetrisation pass
        if k == 30:  # a copy shares no storage with the original, which updates P in place
            twin, P_at_copy = copy.copy(ekf), ekf.P.copy()
    np.testing.assert_array_equal(twin.P, P_at_copy)
    twin.update(y, lambda zz: (np.zeros(3), H))
    assert not np.array_equal(twin.P, P_at_copy)
    assert ekf.P.flags.c_contiguous


def test_ekf_covariance_stays_symmetric_positive_definite_over_a_long_run():
    """20000 updates on the networks' own Jacobians, the shipped R and P0: the short form keeps P
    exactly symmetric and positive definite (where the plain short form may drift in round-off)."""
    nets = Networks()
    rng = np.random.default_rng(6)
    ekf = EKF(rng.normal(0.0, 0.3, nets.alpha), 0.1 * np.eye(nets.alpha), 1e-3 * np.eye(3))
    for k in range(20000):
        e = rng.normal(0.0, 0.05, 3)
        x_f, x_G = nets.inputs(e, rng.uniform(0.3, 1.1), rng.uniform(-1.0, 1.0))
        u = rng.normal(0.0, 1.0, 2)
        ekf.update(
            rng.normal(0.0, 0.01, 3), lambda z, x_f=x_f, x_G=x_G, e=e, u=u: nets.h_and_jacobian(z, x_f, x_G, e, u)
        )
        if k % 5000 == 4999:
            np.testing.assert_array_equal(ekf.P, ekf.P.T)
            assert np.linalg.eigvalsh(ekf.P).min() > 0
    assert np.all(np.isfinite(ekf.z))


@pytest.mark.parametrize("nets", NETS)
def test_compiled_networks_equal_the_numpy_ones(nets):
    from mlpfac.control.adaptive.kernels import networks_h_jacobian

    rng = np.random.default_rng(7)
    B = 4
    z, e, u = rng.normal(0, 1.0, (B, nets.alpha)), rng.normal(0, 0.1, (B, 3)), rng.normal(size=(B, 2))
    x_f, x_G = nets.inputs(e, 0.9, 0.3, rng.normal(size=(B, 2)))
    h, H = np.empty((B, 3)), np.empty((B, 3, nets.alpha))
    networks_h_jacobian(z, x_f, x_G, e, u, nets.L_f, nets.L_G, nets.residual, h, H)
    h_ref, H_ref = nets.h_and_jacobian(z, x_f, x_G, e, u)
    np.testing.assert_allclose(h, h_ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(H, H_ref, rtol=0, atol=1e-14)
