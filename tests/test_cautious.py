"""The cautious law: certainty equivalence at zero variance, the expected-cost optimum otherwise,
and the covariance of (h1, h2, h5, b_v, b_omega) it is fed from P_k."""

import numpy as np
import pytest

from mlpfac.control.adaptive.controller import Adaptive, AdaptiveConfig
from mlpfac.control.adaptive.networks import Networks
from mlpfac.control.law import Law

T = 0.01


def random_case(rng, n=None):
    shape = () if n is None else (n,)
    e = rng.normal(0.0, 0.1, (*shape, 3))
    v_r = rng.uniform(0.3, 1.2, shape)
    h = np.stack([T * e[..., 1], T * v_r * np.cos(e[..., 2]), T * rng.uniform(-1, 1, shape)], -1)
    h = h + rng.normal(0.0, 2e-3, h.shape)  # estimates, not the true functions
    return e, h, v_r


def random_covariance(rng, scale):
    A = rng.normal(size=(5, 5)) * scale
    return A @ A.T


@pytest.mark.parametrize(
    "law", [Law((0.8, 0.85, 0.9), v_max=None, omega_max=None), Law((0.7, 0.8, 0.8), v_max=0.8, omega_max=1.0)]
)
def test_zero_covariance_is_the_certainty_equivalence_law(law):
    rng = np.random.default_rng(11)
    for _ in range(500):
        e, h, v_r = random_case(rng)
        theta = np.r_[h, T, T]
        ce = law.control(e, h, v_r, T)
        for Sigma, weight in ((np.zeros((5, 5)), 1.0), (random_covariance(rng, 1e-3), 0.0), (None, 3.0)):
            np.testing.assert_allclose(law.cautious_control(e, theta, Sigma, v_r, T, weight), ce, rtol=0, atol=1e-12)
    # batched: the same, row by row
    e, h, v_r = random_case(rng, 7)
    theta = np.concatenate([h, np.full((7, 2), T)], -1)
    np.testing.assert_allclose(
        law.cautious_control(e, theta, np.zeros((7, 5, 5)), v_r, T), law.control(e, h, v_r, T), rtol=0, atol=1e-12
    )


def expected_cost(u, e, theta, Sigma, v_r, law):
    """E[r1^2] + E[r3^2] for theta ~ N(theta, Sigma); r1, r3 are affine in theta (see the law's docstring)."""
    v, omega = u
    k1, k2, k3 = law.gains(T, v_r)
    a1, c1 = np.array([omega, 1.0, 0.0, -v, 0.0]), k1 * e[0]  # r1 = a1' theta + c1
    a3, c3 = np.array([0.0, 0.0, 1.0, 0.0, -omega]), k2 * e[1] + k3 * e[2]  # r3 = a3' theta + c3
    return (a1 @ theta + c1) ** 2 + a1 @ Sigma @ a1 + (a3 @ theta + c3) ** 2 + a3 @ Sigma @ a3


def test_cautious_law_minimises_the_expected_one_step_cost():
    """The closed form is the minimiser: zero gradient, and no nearby input does better."""
    law, rng = Law((0.8, 0.85, 0.9), v_max=None, omega_max=None), np.random.default_rng(12)
    for _ in range(50):
        e, h, v_r = random_case(rng)
        theta = np.r_[h, T * rng.uniform(0.7, 1.5), T * rng.uniform(0.7, 1.5)]
        Sigma = random_covariance(rng, 3e-3)
        u = law.cautious_control(e, theta, Sigma, v_r, T, 1.0)
        J0 = expected_cost(u, e, theta, Sigma, v_r, law)
        for du in rng.normal(size=(20, 2)) * 1e-3:
            assert expected_cost(u + du, e, theta, Sigma, v_r, law) >= J0 - 1e-15
        # the weight scales the covariance
        np.testing.assert_allclose(
            law.cautious_control(e, theta, Sigma, v_r, T, 2.5),
            law.cautious_control(e, theta, 2.5 * Sigma, v_r, T),
            rtol=1e-12,
        )


def test_uncertain_gains_shrink_the_commands():
    """The classic cautious effect: more variance on the input gain (or on h1 for omega), a smaller input."""
    law = Law((0.8, 0.8, 0.8), v_max=None, omega_max=None)
    e, v_r = np.array([0.05, 0.03, 0.1]), 0.8
    theta = np.array([T * 0.03, T * v_r, T * 0.2, T, T])
    last = np.inf
    for var in (0.0, 1e-5, 1e-4, 1e-3):
        Sigma = np.diag([0.0, 0.0, 0.0, 0.0, var])
        omega = law.cautious_control(e, theta, Sigma, v_r, T)[1]
        assert 0 < omega < last
        np.testing.assert_allclose(omega, T * law.control(e, theta[:3], v_r, T)[1] * T / (T**2 + var), rtol=1e-12)
        last = omega
    last = np.inf
    for var in (0.0, 1e-5, 1e-4, 1e-3):  # Var(h1): omega also leaks into e1 through G_12
        omega = law.cautious_control(e, theta, np.diag([var, 0.0, 0.0, 0.0, 0.0]), v_r, T)[1]
        assert 0 < omega < last
        last = omega


def test_network_jacobians_match_central_differences():
    """d f / d z and d G / d z, which give the covariance of the estimates, against finite differences."""
    nets = Networks(L_f=6, L_G=2, error_scale=20.0)
    rng = np.random.default_rng(13)
    z, e = rng.normal(0.0, 1.0, nets.alpha), rng.normal(0.0, 0.05, 3)
    x_f, x_G = nets.inputs(e, 0.9, -0.3)
    f, G, df, dG = nets.jacobians(z, x_f, x_G, e)
    f0, G0 = nets.forward(z, x_f, x_G, e)
    np.testing.assert_array_equal(f, f0)
    np.testing.assert_array_equal(G, G0)
    for i in range(nets.alpha):
        d = 1e-6 * max(1.0, abs(z[i]))
        zp, zm = z.copy(), z.copy()
        zp[i] += d
        zm[i] -= d
        (fp, Gp), (fm, Gm) = nets.forward(zp, x_f, x_G, e), nets.forward(zm, x_f, x_G, e)
        np.testing.assert_allclose(df[:, i], (fp - fm) / (zp[i] - zm[i]), rtol=0, atol=1e-8)
        np.testing.assert_allclose(dG[:, :, i], (Gp - Gm) / (zp[i] - zm[i]), rtol=0, atol=1e-8)


def test_the_controller_feeds_the_law_the_first_order_covariance_of_its_estimates():
    """Sigma = J P J' with J the Jacobian of (h1, h2, h5, b_v, b_omega); checked by sampling the weights."""
    nets = Networks(L_f=4, L_G=1, error_scale=20.0)
    cfg = AdaptiveConfig(networks=nets, P0=1e-6, weight_std=0.5, cautious=1.0, learned_gains=True, prior=True)
    ctrl = Adaptive(Law(), cfg, T)
    ctrl.reset(np.random.default_rng(14))
    e, r = np.array([0.02, -0.01, 0.05]), np.array([0.0, 0.0, 0.0, 0.8, 0.3])
    seen = {}
    ctrl.law = type("Spy", (), {"cautious_control": lambda self, *a: seen.setdefault("args", a) and np.zeros(2)})()
    ctrl.step(e, r)
    _, theta, Sigma, *_ = seen["args"]
    x_f, x_G = nets.inputs(e, r[3], r[4])
    rng = np.random.default_rng(15)
    Z = ctrl.est.z + rng.normal(0.0, 1e-3, (20000, nets.alpha))  # P = 1e-6 I
    f, G = nets.forward(Z, x_f, x_G, e)
    samples = np.stack([G[:, 0, 1], f[:, 0], f[:, 2], -G[:, 0, 0], -G[:, 2, 1]], -1)
    C = np.cov(samples.T)
    scale = np.sqrt(np.outer(np.diag(Sigma), np.diag(Sigma)))
    assert np.all(np.abs(C - Sigma) <= 0.05 * scale), np.abs(C - Sigma) / scale  # sampling error ~ 1 %
    assert np.all(np.diag(Sigma) > 0)
    assert theta.shape == (5,)
