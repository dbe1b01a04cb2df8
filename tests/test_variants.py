"""The adaptive controller's options beyond the paper: the defaults are the paper's scheme to the last bit,
adaptation that does not switch off, the nominal prior, the named VARIANTS, scenario-file keys."""

import dataclasses

import numpy as np
import pytest

from mlpfac.control.adaptive.controller import VARIANTS, Adaptive, AdaptiveConfig
from mlpfac.control.adaptive.estimators import EKF, UKF
from mlpfac.control.adaptive.networks import Networks
from mlpfac.control.baselines import CONTROLLERS, Corradini
from mlpfac.control.law import Law
from mlpfac.exceptions import ConfigError
from mlpfac.loop.factory import make_controller
from mlpfac.loop.metrics import metrics
from mlpfac.loop.runner import run
from mlpfac.normal import normal
from mlpfac.scenario.parse import load, parse
from mlpfac.scenario.reference import Eight, sample
from mlpfac.tables import covariance

T = 0.01


class PaperStep:
    """The adaptive step exactly as written before the options existed (reference implementation)."""

    def __init__(self, law, c, T):
        self.law, self.c, self.nets, self.T = law, c, c.networks, T

    def reset(self, rng):
        c, a = self.c, self.nets.alpha
        self.ekf = EKF(normal(rng, 0.0, c.weight_std, a), c.P0 * np.eye(a), covariance(c.R, 3, "R"),
                       c.Q * np.eye(a) if c.Q > 0 else None, c.forgetting, c.P_max)  # fmt: skip
        self.prev = None

    def step(self, e, r):
        nets = self.nets
        if self.prev is not None:
            x_f, x_G, e_prev, u_prev = self.prev
            self.ekf.update(e, lambda z: nets.h_and_jacobian(z, x_f, x_G, e_prev, u_prev))
        x_f, x_G = nets.inputs(e, r[3], r[4], self.prev[3] if self.prev is not None else np.zeros(2))
        f_hat, G_hat = nets.forward(self.ekf.z, x_f, x_G, e)
        h_hat = np.array([G_hat[0, 1], f_hat[0] - e[0], f_hat[2] - e[2]])
        u = self.law.control(e, h_hat, r[3], self.T)
        self.prev = (x_f, x_G, e, u)
        return u


def drive(ctrl, steps=300, seed=23):
    """Feed a controller a fixed synthetic error sequence (open loop, so any difference shows)."""
    ctrl.reset(np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 1)
    ref = sample(Eight(), np.arange(steps) * T)
    out = []
    for k in range(steps):
        e = np.array([0.05, -0.03, 0.1]) * np.cos(0.02 * k + np.arange(3)) + rng.normal(0.0, 1e-3, 3)
        out.append(ctrl.step(e, ref[k]))
    return np.array(out)


@pytest.mark.parametrize(
    "base",
    [
        AdaptiveConfig(output_weight_std=None),  # the paper's draw: every weight ~ N(0, weight_std^2)
        AdaptiveConfig(
            networks=Networks(error_scale=20.0), P0=1.0, R=1e-4, forgetting=0.999, P_max=2.0, output_weight_std=None
        ),
        AdaptiveConfig(networks=Networks(velocity_inputs=True), output_weight_std=None),  # x_f ends with u_{k-1}
    ],
)
def test_default_options_are_the_paper_scheme(base):
    """The compiled step equals the paper's equations written in numpy (to round-off: the kernel sums
    in another order), and the explicit default options are the same kernel to the last bit."""
    law = Law(v_max=2.0, omega_max=5.0)
    explicit = dataclasses.replace(
        base, estimator="ekf", cautious=0.0, prior=False, learned_gains=False, output_weight_std=None
    )
    ref = drive(PaperStep(law, base, T))
    got = drive(Adaptive(law, base, T))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(drive(Adaptive(law, explicit, T)), got)
    # output_weight_std equal to weight_std rescales nothing
    np.testing.assert_array_equal(
        drive(Adaptive(law, dataclasses.replace(base, output_weight_std=base.weight_std), T)), got
    )


def test_default_variant_in_closed_loop_is_bit_identical_to_explicit_options():
    scn = load("paper").with_overrides(duration=3.0, seed=3)
    explicit = dataclasses.replace(scn.adaptive, estimator="ekf", cautious=0.0, prior=False, learned_gains=False)
    a, b = run(scn), run(dataclasses.replace(scn, adaptive=explicit))
    np.testing.assert_array_equal(a.u, b.u)
    np.testing.assert_array_equal(a.ctrl["z"], b.ctrl["z"])


def linear_tracking(make, n=6, steps_before=3000, steps_after=300, seed=31):
    """Identify z_true, let P shrink, then change z_true: the error left after ``steps_after`` steps."""
    rng = np.random.default_rng(seed)
    R = 1e-4 * np.eye(3)
    z1 = rng.normal(size=n)
    z2 = z1 + rng.normal(size=n)
    est = make(np.zeros(n), np.eye(n), R)
    for k in range(steps_before + steps_after):
        z_true = z1 if k < steps_before else z2
        H = rng.normal(size=(3, n))
        y = H @ z_true + rng.multivariate_normal(np.zeros(3), R)
        est.update(y, lambda zz, H=H: (H @ zz, H), lambda Z, H=H: Z @ H.T)
        if k == steps_before - 1:
            assert np.max(np.abs(est.z - z1)) < 0.01  # learned, and P has shrunk
            p_shrunk = est.diag_P().max()
    return np.max(np.abs(est.z - z2)), p_shrunk


@pytest.mark.parametrize("cls", [EKF, UKF])
def test_process_noise_or_forgetting_keeps_the_estimator_adapting(cls):
    stuck, p_paper = linear_tracking(lambda z, P, R: cls(z, P, R))
    with_q, p_q = linear_tracking(lambda z, P, R: cls(z, P, R, Q=1e-4 * np.eye(len(z)), P_max=1.0))
    forget, _ = linear_tracking(lambda z, P, R: cls(z, P, R, forgetting=0.98, P_max=1.0))
    assert p_paper < 1e-4  # P collapsed: without Q the gain has all but switched off
    assert stuck > 0.1, stuck  # ... so 300 steps after the change it is still far off
    assert with_q < 0.01 and forget < 0.01, (with_q, forget)  # with Q or forgetting it has re-learned


@pytest.mark.parametrize("cls", [EKF, UKF])
def test_covariance_stays_bounded_by_p_max_over_a_long_run(cls):
    """Forgetting inflates P in directions the data do not excite; P_max caps it at every step."""
    rng = np.random.default_rng(41)
    n, P_max = 8, 0.5
    est = cls(np.zeros(n), 0.1 * np.eye(n), 1e-4 * np.eye(3), Q=1e-5 * np.eye(n), forgetting=0.97, P_max=P_max)
    peak = 0.0
    for k in range(5000):
        H = rng.normal(size=(3, n))
        H[:, : n // 2] *= k % 1000 < 500  # half the weights go unexcited for long spells
        est.update(rng.normal(size=3), lambda zz, H=H: (H @ zz, H), lambda Z, H=H: Z @ H.T)
        peak = max(peak, est.diag_P().max())
    assert peak <= P_max * (1 + 1e-12)
    assert peak > 0.9 * P_max  # the cap was reached, so it was tested
    assert np.linalg.eigvalsh(est.P).min() > 0


def test_forgetting_variant_keeps_p_bounded_in_closed_loop():
    rec = run(load("paper").with_overrides(controller="adaptive-forget", duration=8.0, seed=2))
    P_max = dataclasses.replace(load("paper").adaptive, **VARIANTS["adaptive-forget"]).P_max
    assert rec.status == "ok"
    assert np.nanmax(rec.ctrl["mean_diag_P"]) <= P_max


@pytest.mark.parametrize("opts", [{}, {"learned_gains": True}, {"learned_gains": True, "cautious": 1.0}])
def test_prior_with_zero_output_weights_starts_as_corradinis_law(opts):
    """f = f_nominal + NN_f, G = G_nominal + NN_G with NN = 0: the first command is Corradini's."""
    law = Law(v_max=2.0, omega_max=5.0)
    cfg = AdaptiveConfig(prior=True, output_weight_std=0.0, P0=1e-2, **opts)
    ctrl, corr = Adaptive(law, cfg, T), Corradini(law, T)
    ctrl.reset(np.random.default_rng(5))
    corr.reset(np.random.default_rng(5))
    r = sample(Eight(), np.array([1.0]))[0]
    e = np.array([0.03, -0.02, 0.05])
    u = ctrl.step(e, r)
    if opts.get("cautious"):  # P0 > 0: the cautious law is not CE even at zero weights
        assert not np.allclose(u, corr.step(e, r), rtol=0, atol=1e-12)
    else:
        np.testing.assert_allclose(u, corr.step(e, r), rtol=0, atol=1e-12)
        np.testing.assert_allclose(ctrl.h_hat, corr.h_hat, rtol=0, atol=1e-15)


def test_prior_without_learning_is_corradinis_law_in_closed_loop():
    """With P0 -> 0 nothing is learned, so the prior variant must fly Corradini's run, event included."""
    scn = load("paper").with_overrides(duration=14.0, seed=4)
    frozen = dataclasses.replace(scn.adaptive, prior=True, output_weight_std=0.0, P0=1e-30)
    a = run(dataclasses.replace(scn, adaptive=frozen))
    b = run(scn.with_overrides(controller="corradini"))
    assert a.status == b.status == "ok"
    np.testing.assert_allclose(a.u, b.u, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.ctrl["h_hat"], b.ctrl["h_hat"], rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_every_variant_runs_the_paper_scenario_bounded(name):
    assert name in CONTROLLERS
    rec = run(load("paper").with_overrides(controller=name, duration=4.0, seed=1))
    m = metrics(rec)
    assert m["status"] == "ok", m["reason"]
    assert rec.controller == name
    assert m["max_abs_weight"] < 50
    assert np.all(np.isfinite(rec.u[: rec.n]))
    assert m["phases"]["before"]["rms_position_error_m"] < 0.5


def test_options_are_scenario_file_keys():
    table = {
        "duration": 0.5,
        "controller": {
            "name": "adaptive",
            "adaptive": {
                "estimator": "ukf",
                "ukf_alpha": 0.2,
                "cautious": 0.5,
                "prior": True,
                "learned_gains": True,
                "output_weight_std": 0.0,
                "forgetting": 0.999,
                "P_max": 1.0,
                "Q": 1e-7,
            },
        },
    }
    scn = parse(table)
    ctrl = make_controller(scn)
    c = ctrl.config
    assert (c.estimator, c.ukf_alpha, c.cautious, c.prior, c.learned_gains) == ("ukf", 0.2, 0.5, True, True)
    assert isinstance(ctrl, Adaptive) and not ctrl.compiled  # the UKF and the cautious law: numpy parts
    rec = run(scn)
    assert rec.status == "ok" and rec.n == scn.steps
    # the options reach the run: without them the commands differ
    plain = run(parse({"duration": 0.5, "controller": {"name": "adaptive"}}))
    assert plain.status == "ok" and not np.allclose(rec.u[: rec.n], plain.u[: plain.n])


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"estimator": "pf"}, "ekf"),
        ({"cautious": -1.0}, "cautious"),
        ({"forgetting": 0.0}, "forgetting"),
        ({"P_max": 0.0}, "P_max"),
        ({"output_weight_std": -0.1}, "output_weight_std"),
        ({"prior": True, "residual": True}, "residual"),
        ({"ukf_alpha": 0.0}, "ukf_alpha"),
    ],
)
def test_bad_options_are_refused_with_the_key_named(bad, match):
    with pytest.raises(ConfigError, match=match):
        parse({"controller": {"name": "adaptive", "adaptive": bad}})
