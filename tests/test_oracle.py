"""The oracle (the law told the change), the run's outcome, and the paired comparisons of sweeps."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import wilcoxon as scipy_wilcoxon

from mlpfac.control.law import Law
from mlpfac.control.oracle import Oracle, told
from mlpfac.loop.factory import make_controller
from mlpfac.loop.metrics import LOST_FRACTION, RunMetrics, metrics, outcome
from mlpfac.loop.record import RunRecord
from mlpfac.loop.runner import run
from mlpfac.model import G_true, f_true
from mlpfac.plants.events import make_event
from mlpfac.scenario.parse import load
from mlpfac.sweeps.paired import compare, paired_rows, twins, wilcoxon
from mlpfac.sweeps.plan import plan

LAW = Law((0.9, 0.85, 0.8), v_max=2.0, omega_max=5.0)
T = 0.01


def oracle(changes, kinematic=False, B=None) -> Oracle:
    o = Oracle(LAW, T, changes, kinematic)
    o.reset(np.random.default_rng(0) if B is None else [np.random.default_rng(b) for b in range(B)])
    return o


def corradini_u(e, r, T_law=T, limits=(2.0, 5.0)) -> np.ndarray:
    law = Law(LAW.lambdas, v_max=limits[0], omega_max=limits[1])
    return law.control(e, np.array([T_law * e[1], T_law * r[3] * math.cos(e[2]), T_law * r[4]]), r[3], T_law)


E = np.array([0.004, -0.003, 0.02])
R = np.array([0.3, -0.2, 0.7, 0.9, 0.4])


def test_told_reads_the_number_each_kind_needs():
    assert told(make_event("wheel_radius", 12.5, scale=1.5)) == (12.5, "wheel_radius", 1.5)
    assert told(make_event("sensor_delay", 1.0, steps=3)) == (1.0, "sensor_delay", 3.0)
    assert told(make_event("payload", 2.0, mass_scale=3.0)) == (2.0, "payload", 1.0)


def test_wheel_radius_oracle_sends_the_nominal_command_divided_by_the_scale():
    o = oracle([(0.0, "wheel_radius", 1.5)])
    np.testing.assert_allclose(o.step(E, R), corradini_u(E, R) / 1.5, rtol=1e-15)


def test_control_period_oracle_places_the_eigenvalues_of_the_true_one_step_map():
    """The robot holds each command c T, the reference moves T: e_{k+1} = f(e; T) + G(e; c T) u.
    The oracle's command gives e1 -> lambda_1 e1 exactly and e3 -> (1 - k3) e3 - k2 e2 (the law (35)
    redesigned); the nominal command does not."""
    c = 1.5
    u = oracle([(0.0, "control_period", c)]).step(E, R)
    nxt = f_true(E, R[3], R[4], T) + G_true(E, c * T) @ u
    k1, k2, k3 = LAW.gains(T, R[3])
    assert nxt[0] == pytest.approx((1 - k1) * E[0], abs=1e-15)
    assert nxt[2] == pytest.approx((1 - k3) * E[2] - k2 * E[1], abs=1e-15)
    nominal = f_true(E, R[3], R[4], T) + G_true(E, c * T) @ corradini_u(E, R)
    assert abs(nominal[0] - (1 - k1) * E[0]) > 1e-5


def test_control_period_limits_bound_the_velocity_sent():
    big = np.array([0.0, 0.5, 0.0])  # omega beyond 5 rad/s before the limit
    u = oracle([(0.0, "control_period", 1.5)]).step(big, R)
    assert u[1] == pytest.approx(5.0) and u[1] == pytest.approx(corradini_u(big, R, limits=(3.0, 7.5))[1] / 1.5)


def test_kinematic_control_period_is_the_law_at_c_T():
    u = oracle([(0.0, "control_period", 1.5)], kinematic=True).step(E, R)
    np.testing.assert_array_equal(u, corradini_u(E, R, T_law=1.5 * T))


def unicycle(q, u, dt, n=2000):
    """Reference integration: n Euler substeps."""
    x, y, th = q
    h = dt / n
    for _ in range(n):
        x, y, th = x + u[0] * h * math.cos(th), y + u[0] * h * math.sin(th), th + u[1] * h
    return np.array([x, y, th])


def error_of(q, r) -> np.ndarray:
    c, s = math.cos(q[2]), math.sin(q[2])
    dx, dy = r[0] - q[0], r[1] - q[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, r[2] - q[2]])


def test_sensor_delay_predictor_is_the_unicycle_through_the_commands_sent():
    """3 steps of delay from step 0: the oracle sees the pose of step k - min(k, 3) (the plant's delay
    line) and acts on the error of the pose the commands it sent reach: as the oracle without delay
    acting on the current pose."""
    d, steps = 3, 8
    o, free = oracle([(0.0, "sensor_delay", float(d))]), oracle([])
    q, poses = np.array([0.1, -0.05, 0.3]), []
    for k in range(steps):
        poses.append(q)
        r = R + np.array([0.01 * k, 0.0, 0.0, 0.0, 0.0])
        seen = poses[k - min(k, d)]
        u = o.step(error_of(seen, r), r)
        np.testing.assert_allclose(u, free.step(error_of(q, r), r), atol=1e-9)
        q = unicycle(q, u, T)


def test_the_oracle_is_corradini_to_the_last_bit_where_it_is_told_nothing():
    """Payload: nothing to tell the law (35); before any event: no change yet."""
    for name in ("eight-payload", "eight-wheel-radius"):
        scn = load(name).with_overrides(duration=12.7)
        a, b = run(scn.with_overrides(controller="oracle")), run(scn.with_overrides(controller="corradini"))
        n = a.n if name == "eight-payload" else int(round(12.5 / T))
        np.testing.assert_array_equal(a.u[:n], b.u[:n])
        if name == "eight-wheel-radius":
            assert not np.array_equal(a.u[n:], b.u[n:])


GAINS = (10.0, 64.0, 16.0)


def kanayama_u(e, r, limits=(2.0, 5.0)) -> np.ndarray:
    v = r[3] * math.cos(e[2]) + GAINS[0] * e[0]
    w = r[4] + r[3] * (GAINS[1] * e[1] + GAINS[2] * math.sin(e[2]))
    return np.array([np.clip(v, -limits[0], limits[0]), np.clip(w, -limits[1], limits[1])])


@pytest.mark.parametrize(
    ("changes", "kinematic", "gain"),
    [
        ([], False, 1.0),
        ([(0.0, "wheel_radius", 1.5)], False, 1.5),
        ([(0.0, "control_period", 2.0)], False, 2.0),
        ([(0.0, "control_period", 2.0)], True, 1.0),  # (7): f and G scale alike, the velocity law needs no change
        ([(0.0, "wheel_radius", 1.1), (0.0, "control_period", 1.5)], False, 1.65),
    ],
)
def test_oracle_kanayama_sends_kanayamas_command_divided_by_what_it_is_told(changes, kinematic, gain):
    o = Oracle(LAW, T, changes, kinematic, GAINS)
    o.reset(np.random.default_rng(0))
    assert o.name == "oracle-kanayama" and o.telemetry() == {}
    c = dict((kind, v) for _, kind, v in changes).get("control_period", 1.0) if not kinematic else 1.0
    limits = (2.0 * c, 5.0 * c)
    np.testing.assert_allclose(o.step(E, R), kanayama_u(E, R, limits) / gain, rtol=1e-14)


@pytest.mark.parametrize("kanayama", [True, False])
def test_a_skid_steers_oracle_told_its_turning_leads_the_heading_and_scales_omega(kanayama):
    """Known answer: told the track ratio t and the kinematic centre a ahead, the law acts on e3 +
    phi, sin phi = a omega_r / v_r, and sends omega x t; told (1, 0), the law as it was, to the bit."""
    gains = GAINS if kanayama else None
    t, a = 1.25, 0.02
    told_ = Oracle(LAW, T, [(0.0, "turning_track", t), (0.0, "kinematic_centre", a)], False, gains)
    plain = Oracle(LAW, T, [(0.0, "turning_track", 1.0), (0.0, "kinematic_centre", 0.0)], False, gains)
    for o in (told_, plain):
        o.reset(np.random.default_rng(0))
    led = E + [0.0, 0.0, math.asin(a * R[4] / R[3])]
    want = kanayama_u(led, R) if kanayama else corradini_u(led, R)
    np.testing.assert_allclose(told_.step(E, R), want * [1.0, t], rtol=1e-14)
    np.testing.assert_array_equal(plain.step(E, R), kanayama_u(E, R) if kanayama else corradini_u(E, R))


def test_the_factory_tells_a_skid_steers_oracle_what_the_payload_does_to_its_turning():
    """Measured on a robot of the scenario's with the payload (tests/data/skid_short.xml: the track
    0.879 -> 1.355 m, the centre 48.9 mm back, docs/robots.md); a differential drive is told nothing,
    and so is a skid-steer of a floor."""
    skid = str(Path(__file__).parent / "data" / "skid_short.xml")
    ctrl = make_controller(load("eight-payload", robot=skid).with_overrides(controller="oracle-kanayama"))
    (_, _, ratio), (_, _, ahead) = [c for c in ctrl.changes if c[1] in ("turning_track", "kinematic_centre")]
    assert ratio == pytest.approx(1.355 / 0.879, rel=0.03) and ahead == pytest.approx(-0.0489, abs=0.003)
    plain = make_controller(load("eight-payload").with_overrides(controller="oracle-kanayama"))
    assert plain.changes == [(12.5, "payload", 1.0)]
    floor = make_controller(load("eight-friction", robot=skid).with_overrides(controller="oracle"))
    assert floor.changes == [(12.5, "friction", 1.0)]  # a floor's turning is not told (docs/robots.md)


def test_oracle_kanayama_is_kanayama_to_the_last_bit_before_the_event():
    scn = load("eight-wheel-radius").with_overrides(duration=12.7)
    a, b = run(scn.with_overrides(controller="oracle-kanayama")), run(scn.with_overrides(controller="kanayama"))
    n = int(round(12.5 / T))
    np.testing.assert_array_equal(a.u[:n], b.u[:n])
    assert not np.array_equal(a.u[n:], b.u[n:])


def test_factory_builds_the_oracle_told_the_events():
    ctrl = make_controller(load("eight-sensor-delay").with_overrides(controller="oracle"))
    assert isinstance(ctrl, Oracle) and ctrl.changes == [(12.5, "sensor_delay", 3.0)] and not ctrl.kinematic
    assert make_controller(load("paper").with_overrides(controller="oracle")).kinematic


def test_oracle_on_wheel_radius_tracks_like_corradini_on_the_nominal_robot():
    """Known answer: told the true radius, the law is back on the robot it was designed for."""
    lo, hi = 14.0, 16.0
    got = {}
    for name, ctrl in (
        ("eight-wheel-radius", "oracle"),
        ("eight-wheel-radius", "corradini"),
        ("eight-nominal", "corradini"),
    ):
        m = metrics(run(load(name).with_overrides(controller=ctrl, duration=hi)))
        got[name, ctrl] = RunMetrics.from_json(m).window_rms(lo, hi)
    nominal = got["eight-nominal", "corradini"]
    assert got["eight-wheel-radius", "oracle"] < 1.6 * nominal
    assert got["eight-wheel-radius", "corradini"] > 10 * nominal


def record(e_true: np.ndarray, status="ok", split=1.0) -> RunRecord:
    N = len(e_true)
    t = np.arange(N) * T
    ref = np.stack([2 * np.cos(t), 2 * np.sin(t), t, np.ones(N), np.ones(N)], axis=1)  # 4 m across
    rec = RunRecord(
        "s", "c", 0, T, t, ref, *(np.zeros((N, 3)) for _ in range(2)), np.zeros((N, 3)), e_true, np.zeros((N, 2))
    )
    rec.n, rec.status, rec.warmup_s, rec.split_s = N, status, 0.0, split
    return rec


@pytest.mark.parametrize(
    ("after_m", "status", "expected"),
    [
        (0.05, "ok", "tracking"),
        (0.19, "ok", "tracking"),
        (0.25, "ok", "lost"),
        (3.0, "ok", "lost"),
        (0.01, "diverged", "diverged"),
    ],
)
def test_outcome_separates_tracking_lost_and_diverged(after_m, status, expected):
    N = 629  # a whole circle of radius 2: the path is 4 m across
    e = np.zeros((N, 3))
    e[100:, 0] = after_m
    m = metrics(record(e, status))
    assert m["outcome"] == expected
    assert m["lost_threshold_m"] == pytest.approx(LOST_FRACTION * 4.0, rel=1e-3) and LOST_FRACTION == 0.05
    assert outcome(record(e, status), m["phases"])["outcome"] == expected


def test_window_rms_from_the_bins_is_the_phase_rms():
    m = metrics(run(load("paper").with_overrides(controller="corradini", duration=3.0, seed=2)))
    # the split at 12.5 s is beyond 3 s: one phase, [2, 3)
    ph = m["phases"]["before"]
    read = RunMetrics.from_json(m)
    assert read.window_rms(ph["start_s"], ph["end_s"]) == pytest.approx(ph["rms_position_error_m"], rel=1e-12)
    assert RunMetrics.from_json(m | {"status": "diverged"}).window_rms(2.0, 3.0) is None


FIXED_X = [1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30, 0.9, 2.2, 1.1]
FIXED_Y = [0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29, 1.4, 1.7, 1.0]


def test_wilcoxon_is_scipys_and_an_all_wins_pair_has_its_exact_p():
    assert wilcoxon(FIXED_X, FIXED_Y) == pytest.approx(scipy_wilcoxon(FIXED_X, FIXED_Y).pvalue, rel=1e-12)
    x = [1.0 + 0.01 * i for i in range(20)]
    assert wilcoxon(x, [2.0] * 20) == pytest.approx(2.0 / 2**20, rel=1e-9)  # every seed better: 2 / 2^n
    assert wilcoxon([1.0, 2.0], [1.0, 2.0]) is None


def test_compare_counts_a_diverged_run_as_a_loss_with_the_largest_rank():
    wins, n, p = compare([1.0, 2.0, math.inf, None], [2.0, 3.0, 1.0, 1.0])
    assert (wins, n) == (2, 3)  # the missing pair is left out
    assert p == pytest.approx(scipy_wilcoxon([1.0, 2.0, 7.0], [2.0, 3.0, 1.0]).pvalue)


def test_paired_rows_on_a_sweep_plan():
    jobs = plan(["eight-nominal", "eight-wheel-radius", "eight-torque"], ["corradini", "oracle", "adaptive"], [0, 1])
    assert twins(jobs) == {"eight-wheel-radius": "eight-nominal"}

    def fake(scn, ctrl, seed):
        after = {"corradini": 0.026, "oracle": 0.0013, "adaptive": 0.02 + 0.001 * seed}[ctrl]
        base = {"corradini": 0.0008, "oracle": 0.0008, "adaptive": 0.07}[ctrl]
        nominal = scn != "eight-wheel-radius"
        phases = {"before": {"start_s": 2.0, "end_s": 25.0 if nominal else 12.5, "rms_position_error_m": base}}
        if not nominal:
            phases["after"] = {"start_s": 12.5, "end_s": 25.0, "rms_position_error_m": after}
        return {"status": "ok", "outcome": "tracking", "T": 0.01, "steps": 2500, "phases": phases,
                "scenario": scn, "controller": ctrl, "seed": seed,
                "position_ms_bins": {"bin_steps": 10, "m2": [base**2] * 250}}  # fmt: skip

    ms = {j.key: RunMetrics.from_json(fake(*j.key)) for j in jobs}
    rows = {(r["scenario"], r["controller"]): r for r in paired_rows(jobs, ms)}
    a = rows["eight-wheel-radius", "adaptive"]
    assert a["x_oracle_median"] == pytest.approx(0.0205 / 0.0013)
    assert a["event_cost_median"] == pytest.approx(0.0205 / 0.07)
    assert (a["wins_vs_corradini"], a["pairs_vs_corradini"], a["wins_vs_oracle"]) == (2, 2, 0)
    assert a["wins_cost_vs_corradini"] == 2  # 0.29x against corradini's 32x
    assert rows["eight-torque", "adaptive"]["event_cost_median"] is None


@pytest.mark.parametrize("limit", [None, 30.0, 5.0])
def test_dividing_by_the_radius_scale_is_the_ik_given_the_true_radius(limit):
    """The nominal IK on u / s gives the wheel speeds of the IK told the true radius s r, limit included."""
    from mlpfac.plants.ik import wheel_speeds

    u, s, r, track = np.array([0.9, 1.7]), 1.5, 0.05, 0.3
    np.testing.assert_allclose(
        wheel_speeds(*(u / s), r, track, limit), wheel_speeds(*u, s * r, track, limit), rtol=1e-15
    )


def test_a_ci_of_an_rms_never_reaches_below_zero():
    """Two spread seeds: Student's t interval of the mean reaches below 0, which no RMS can; its lower
    end is clipped at 0 (the same coverage: the mean it estimates is positive), in the tables of
    data made before too."""
    from mlpfac.sweeps.tables import _ci, _ci95

    lo, hi = _ci95([0.1e-3, 1.0e-3])
    assert lo == 0.0 and hi > 1.0e-3
    assert _ci95([1.0, 1.1])[0] > 0.0  # a tight interval is as it was
    assert _ci(-0.39e-3, 1.54e-3, 1e3) == "[0.00, 1.54]"


def test_a_grid_points_summary_column_is_named_by_its_values_and_paired_md_by_words():
    from mlpfac.sweeps.paired import column_name, note, summary

    point = {"events.0.angle_deg": 12.0, "events.1.fy": 6.0}
    assert column_name("aisle-slope-gust+events.0.angle_deg+12.0+events.1.fy+6.0", point) == (
        "aisle-slope-gust: angle_deg 12, fy 6"
    )
    same = {"events.0.scale": 1.5, "events.1.scale": 2}
    assert column_name("s+events.0.scale+1.5+events.1.scale+2", same) == "s: events.0.scale 1.5, events.1.scale 2"
    row = {"scenario": "s+events.0.scale+1.5+events.1.scale+2", "controller": "kanayama", "runs": 1, "tracking": 1,
           "pos_rms_m_median": 0.001, "x_oracle_median": None, "vary": same}  # fmt: skip
    assert summary([row]).splitlines()[0] == "| controller | s: events.0.scale 1.5, events.1.scale 2 |"
    text = note()
    assert "TOLD_AT_MOST" not in text and "UNTOLD_MARK" not in text and "``" not in text
    assert "at most 1.1 times itself untold" in text and "marks (‡)" in text
