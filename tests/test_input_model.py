"""The input model (mlpfac.control.adaptive.input_model): input gains, change detection, delay and predictor, on
synthetic unicycles with a known gain and delay (batched on the MuJoCo robot: tests/test_batch.py)."""

import math

import numpy as np
import pytest

from mlpfac.control.adaptive.input_model import InputModel
from mlpfac.model import tracking_errors

T = 0.01
R0 = np.zeros(5)  # a reference fixed at the origin: e is the pose seen from it


def unicycle(q, v, om):
    """The exact step the predictor assumes (mid-heading chord)."""
    mid = q[2] + 0.5 * T * om
    return np.array([q[0] + T * v * math.cos(mid), q[1] + T * v * math.sin(mid), q[2] + T * om])


def drive(model, steps, gain, delay=0, noise=0.0, seed=0, gain_after=None, change_at=None):
    """Close a loop around ``model``: the law's command is a smooth path plus white dither, the model
    sends it divided by its gain, the robot realises gain * command, its pose is measured ``delay``
    steps late with noise. Returns the history of the model's (g_v, g_omega, delay, alarms)."""
    rng = np.random.default_rng(seed)
    q = np.array([0.3, -0.2, 0.1])
    poses = [q.copy()] * (delay + 1)
    out, e = [], np.zeros((1, 3))
    for k in range(steps):
        g = gain_after if change_at is not None and k >= change_at else gain
        meas = poses[0] + noise * rng.standard_normal(3)
        tracking_errors(meas[None], R0, e)
        model.observe(e, R0, k == 0)
        u = np.array([[0.8 + 0.3 * math.sin(0.5 * k * T) + 0.05 * rng.standard_normal(),
                       0.6 * math.sin(0.3 * k * T) + 0.3 * rng.standard_normal()]])  # fmt: skip
        sent = model.command(u)[0]
        q = unicycle(q, g * sent[0], g * sent[1])
        poses = [*poses[1:], q.copy()]
        out.append((*model.S[0, 4:6], model.S[0, 16], model.S[0, 14]))
    return np.array(out)


@pytest.mark.parametrize("gain", [1.0, 1.5, 0.9])
def test_input_gains_converge_to_the_true_gain(gain):
    m = InputModel(1, T, True, 0, P0=1e-4, forgetting=0.999, detect=0.0)
    hist = drive(m, 1500, gain, noise=1e-3)
    np.testing.assert_allclose(hist[-1, :2], gain, rtol=0.02)


def test_a_detected_change_reopens_the_covariance_and_is_learned_faster():
    """The gain jumps 1 -> 1.5 at step 1000: with the CUSUM the estimate is within 5 % in 50 steps
    (an alarm fired); forgetting alone is still far."""
    kw = {"steps": 1100, "gain": 1.0, "gain_after": 1.5, "change_at": 1000, "noise": 1e-3}
    fast = drive(InputModel(1, T, True, 0, P0=1e-4, forgetting=0.999, detect=20.0), **kw)
    slow = drive(InputModel(1, T, True, 0, P0=1e-4, forgetting=0.999, detect=0.0), **kw)
    assert fast[-1, 3] > fast[999, 3]  # an alarm after the change
    assert abs(fast[1050, 0] - 1.5) < 0.075
    assert abs(slow[1050, 0] - 1.5) > 0.15


def test_a_small_gain_change_is_seen_as_a_bias_and_relearnt_at_once_with_input_P_alarm():
    """A 10 % gain change (1 -> 1.1 at step 1500) under 1 mm of pose noise: nu^2 of one step hardly
    grows and the CUSUM at 50 stays quiet; the leaky sum of the innovations (detect_mean) shows the
    bias and raises the alarm, and with input_P_alarm the gain is within 3 % 50 steps later (and
    nearer after 20 steps than with P reopened to P0 only)."""
    kw = {"steps": 1600, "gain": 1.0, "gain_after": 1.1, "change_at": 1500, "noise": 1e-3}
    cusum = drive(InputModel(1, T, True, 0, P0=1e-4, forgetting=0.999, detect=50.0), **kw)
    bias = drive(InputModel(1, T, True, 0, P0=1e-4, forgetting=0.999, detect=50.0, detect_mean=20.0), **kw)
    wide = drive(
        InputModel(1, T, True, 0, P0=1e-4, forgetting=0.999, detect=50.0, detect_mean=20.0, P_alarm=2e-2), **kw
    )
    assert cusum[-1, 3] == cusum[1499, 3]  # the CUSUM alone: no alarm after the change
    assert bias[-1, 3] > bias[1499, 3] and wide[-1, 3] > wide[1499, 3]  # the bias test: an alarm
    assert abs(wide[1550, 0] - 1.1) < 0.033
    assert abs(wide[1520, 0] - 1.1) < abs(bias[1520, 0] - 1.1) < abs(cusum[1520, 0] - 1.1)  # wider: faster


@pytest.mark.parametrize("delay", [0, 3, 5])
def test_the_delay_is_found(delay):
    m = InputModel(1, T, True, 6, P0=1e-4, forgetting=0.999, detect=20.0)
    hist = drive(m, 800, 1.0, delay=delay, noise=1e-3)
    assert (hist[-200:, 2] == delay).all()


def test_the_predictor_gives_the_error_of_the_pose_now():
    """Noise-free, gain 1 and a delay of 3 steps found: e_hat is the error (2) of the true pose,
    the measured one moved over the last 3 commands sent."""
    m = InputModel(1, T, False, 6, P0=1e-4, forgetting=1.0, detect=0.0)
    drive(m, 300, 1.0, delay=3)
    m.S[0, 16], m.S[0, 4:6] = 3.0, 1.0  # the delay and the gains, as found
    q = np.array([0.5, 0.1, 0.2])
    hist = [np.array([0.7, 0.4]), np.array([0.9, -0.2]), np.array([1.1, 0.3])]  # u_{k-3}, u_{k-2}, u_{k-1}
    for u in hist:
        m.command(u[None])
    truth = q
    for u in hist:
        truth = unicycle(truth, *u)
    e, want = np.zeros((1, 3)), np.zeros((1, 3))
    tracking_errors(q[None], R0, e)
    tracking_errors(truth[None], R0, want)
    got = m.observe(e, R0, True)  # first: no update, the prediction alone
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_without_a_delay_the_error_is_passed_on_to_the_bit():
    m = InputModel(2, T, True, 6, P0=1e-4, forgetting=1.0, detect=0.0)
    e = np.array([[0.01, -0.02, 0.03], [0.0, 0.001, -0.3]])
    assert (m.observe(e, R0, True) == e).all()
