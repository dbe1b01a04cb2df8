"""``mpc`` and ``limit`` (mlpfac.control.mpc) and the robot as their model (mlpfac.plants.mujoco.predict):
the model predicts the run to the bit, its Jacobians agree with MuJoCo's and with finite
differences, the estimator's and the planner's algebra with numpy's, the controllers track better
than the laws on a short run, give the same bits twice, and refuse what cannot work in one line."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import mlpfac
from mlpfac.control.mpc.config import MpcConfig
from mlpfac.control.mpc.kernels import covariance_predict, gauss_newton, kalman_update, plan_cost, residual_jacobian
from mlpfac.exceptions import ConfigError
from mlpfac.loop.factory import make_controller
from mlpfac.loop.metrics import metrics
from mlpfac.loop.runner import build, run
from mlpfac.plants.mujoco import compiled as K  # noqa: N812
from mlpfac.plants.mujoco.predict import STATE, Predictor


def _scenario(name: str, controller: str, duration: float, **kw):
    return mlpfac.load(name, **kw).with_overrides(controller=controller, seed=0, duration=duration)


def _model(scn) -> tuple[Predictor, object]:
    """A model of the scenario's robot, and a run's plant of it, both reset where the run starts."""
    b = build(scn)
    ctrl = b.ctrl
    ctrl.reset(np.random.default_rng(np.random.SeedSequence(0)))
    return ctrl.seeds[0].model, b


def test_the_model_predicts_the_run_to_the_bit():
    """From the run's state at a step, a rollout of the commands the run sent gives the poses the
    run's robot reached, bit for bit (the same compiled step, no noise): on velocity servos and on
    torque motors, across an event the model is told."""
    for name, law in (("eight-wheel-radius", "kanayama"), ("eight-torque", "fierro-lewis")):  # (v, omega); torques
        scn = mlpfac.load(name, values={"events.0.time": 0.2} if name == "eight-wheel-radius" else None)
        scn = scn.with_overrides(controller=law, seed=0, duration=0.4)
        rec = run(scn)
        model, b = _model(scn.with_overrides(controller="limit"))
        plant = b.plant
        q0, u0 = scn.initial_state(b.ref)
        plant.reset(q0, np.random.default_rng(1), u0)
        x, st = model.capture(plant)
        k0 = 0
        if scn.events:  # from the event on: the model told it, the state the run's after it
            k0 = 20
            for k in range(k0):
                plant.step(rec.u[k])
            plant.apply(scn.events[0])
            model.apply(scn.events[0], *model.capture(plant))
            x, st = model.capture(plant)
        H = 10
        U = np.ascontiguousarray(rec.u[None, k0 : k0 + H])
        E = np.empty((1, H, 3))
        model.rollouts(x, st, k0, U, b.ref, E)
        np.testing.assert_array_equal(E[0], rec.e_true[k0 + 1 : k0 + H + 1])


@pytest.mark.parametrize(
    "name, robot",
    [("eight-nominal", None), ("eight-push", "diffdrive-torque"), ("eight-bumps", "diffdrive-torque"),
     ("eight-nominal", "examples/sensing/diffdrive-fused.toml")],
)  # fmt: skip
def test_rollouts_that_share_their_first_commands_give_the_bits_of_each_alone(name, robot):
    """A row whose commands equal the first row's up to a step starts from the first row's state
    there: its errors are, bit for bit, those it gives rolled out alone from the start (a velocity
    robot, a force's schedule under way, rough ground, a sensed pose)."""
    scn = _scenario(name, "limit", 0.5, robot=robot)
    model, b = _model(scn)
    x, st = model.capture()
    k = 0
    if scn.events:  # told the event, a few steps before it
        x, st = model.apply(scn.events[0], x, st)
        k = int(round(scn.events[0].time / scn.T)) - 3
    H, rng = 25, np.random.default_rng(3)
    scale = 0.2 if b.plant.ints[K.I_TAU] else 0.3  # torques (N m); (v, omega)
    U0 = scale * (0.5 + rng.random((H, 2)))
    U = np.repeat(U0[None], 6, axis=0)
    for i, f in enumerate((1, 7, 15, 24, H), start=1):  # parted at step f (H: never)
        U[i, f:] += 0.05 * rng.standard_normal((H - f, 2))
    U = np.ascontiguousarray(U)
    E, again = np.empty((6, H, 3)), np.empty((6, H, 3))
    model.rollouts(x, st, k, U, b.ref, E)
    steps = model.control_steps
    model.rollouts(x, st, k, U, b.ref, again)  # the first row not run again: its errors and states kept
    np.testing.assert_array_equal(again, E)
    assert model.control_steps - steps == 5 * H - (1 + 7 + 15 + 24 + H)
    for i in range(6):
        alone = np.empty((1, H, 3))
        model.rollouts(x, st, k, np.ascontiguousarray(U[i : i + 1]), b.ref, alone)
        np.testing.assert_array_equal(E[i], alone[0])
    assert np.all(np.abs(E) < 1.0)  # no row diverged: the states were used


def test_the_step_jacobian_agrees_with_mujocos_transition_fd():
    """On velocity servos (the command held over the physics steps of a control step), the control
    step's Jacobian in the tangent space is the product of MuJoCo's own ``mjd_transitionFD`` over
    those physics steps, to the forward difference's accuracy, among the directions the estimator
    estimates (the chassis' height, roll and pitch left to the model: their stiffest entry, a wheel's
    speed on the axle's height through the contact, -237 /s, is 0.17 off at the estimator's step of
    1e-6 and 0.0017 at 1e-8)."""
    scn = _scenario("eight-nominal", "mpc", 0.2)
    model, _ = _model(scn)
    x, st = model.capture()
    n, nv = model.n, model.nv
    u = np.array([0.8, 0.3])
    A = np.zeros((n, n))
    model.transition(x, st, 0, u, 1e-8, A)
    p = model.plant
    m, d = p.model, mujoco.MjData(p.model)
    mujoco.mj_setState(m, d, x, STATE)
    mujoco.mj_forward(m, d)
    al, ar = p.robot.acts
    from mlpfac.plants.ik import wheel_speeds

    wl, wr = wheel_speeds(u[0], u[1], p.ik_radius, p.ik_track)
    d.ctrl[al], d.ctrl[ar] = p.fl[0] * wl, p.fl[1] * wr
    chain = np.eye(2 * nv)
    for _ in range(p.n_substeps):
        Ai = np.zeros((2 * nv, 2 * nv))
        mujoco.mjd_transitionFD(m, d, 1e-7, True, Ai, None, None, None)
        chain = Ai @ chain
        mujoco.mj_step(m, d)
    chain = chain[np.ix_(model.S, model.S)]  # the estimated directions: all but the chassis' height, roll and pitch
    assert n == 2 * nv - 6 and p._droot + 2 not in model.S
    assert (np.abs(A - chain) / (np.abs(chain) + 1.0)).max() < 1e-4
    assert nv == m.nv and np.abs(chain).max() > 10.0


def test_the_pose_jacobian_agrees_with_finite_differences():
    scn = _scenario("eight-nominal", "mpc", 0.2)
    model, _ = _model(scn)
    x, st = model.capture()
    Hx = model.pose_jacobian(x, st, 0)
    eps = 1e-6
    for j in range(model.n):
        dx = np.zeros(model.n)
        dx[j] = eps
        _, st1 = model.correct(x, st, 0, dx)
        np.testing.assert_allclose((st1[4:7] - st[4:7]) / eps, Hx[:, j], atol=1e-5)


def test_the_kalman_update_and_the_covariance_agree_with_numpy():
    rng = np.random.default_rng(3)
    n = 8
    L = rng.normal(size=(n, n))
    P = L @ L.T + n * np.eye(n)
    Hx = rng.normal(size=(3, n))
    r = np.array([1e-2, 2e-2, 3e-2])
    nu = rng.normal(size=3)
    S = Hx @ P @ Hx.T + np.diag(r)
    K = P @ Hx.T @ np.linalg.inv(S)
    want_P = P - K @ S @ K.T
    got_P, dx = P.copy(), np.zeros(n)
    kalman_update(got_P, Hx, r, nu, dx)
    np.testing.assert_allclose(dx, K @ nu, rtol=1e-10)
    np.testing.assert_allclose(got_P, want_P, rtol=1e-9, atol=1e-12)
    assert np.array_equal(got_P, got_P.T)
    A, q = rng.normal(size=(n, n)), rng.uniform(size=n)
    want = A @ P @ A.T + np.diag(q)
    covariance_predict(P, A, q)
    np.testing.assert_allclose(P, want, rtol=1e-10)


def test_a_slipping_wheel_resets_its_own_speed_not_the_chassis():
    """The encoders' innovation within ``slip_gate`` standard deviations leaves the covariance as it
    is (the same bits as no gate); a wheel's speed 2 rad/s from the model's (a slip) grows that
    wheel's variance by its square, and the update moves the chassis' velocities a hundredth as far
    or less than the grip's covariance would."""
    scn = _scenario("eight-torque", "mpc", 0.3)
    b = build(scn)
    run(scn, built=b)
    ctrl = b.ctrl
    s = ctrl.seeds[0]
    Hw, _ = s.model.wheel_rows(s.x_a)
    r = ctrl.wheel_noise * ctrl.wheel_noise
    j = int(np.flatnonzero(Hw[0])[0])
    half = s.model.half
    for nu, slips in ((np.array([2.0 * np.sqrt(s.P[j, j] + r), 0.0]), False), (np.array([2.0, 0.0]), True)):
        P = s.P.copy()
        ctrl._slip(P, Hw, nu, r)
        if not slips:
            assert np.array_equal(P, s.P)
            continue
        assert P[j, j] == s.P[j, j] + 4.0 and np.count_nonzero(P != s.P) == 1
        moved = {}
        for name, Q in (("gated", P), ("grip", s.P.copy())):
            dx = np.zeros(s.model.n)
            kalman_update(Q, Hw, np.full(2, r), nu, dx)
            moved[name] = (np.abs(dx[half : half + 3]).max(), dx[j])
        assert moved["grip"][0] > 0.05  # the grip's covariance: a wheel's speed is the chassis'
        assert moved["gated"][0] < 0.01 * moved["grip"][0]
        assert abs(moved["gated"][1] - 2.0 * Hw[0, j]) < 1e-3  # the wheel takes the encoder's speed


def test_the_gauss_newton_step_solves_the_damped_normal_equations():
    rng = np.random.default_rng(4)
    M, H = 6, 7
    J = rng.normal(size=(M, H * 3))
    r0 = rng.normal(size=H * 3)
    w = rng.uniform(0.1, 1.0, size=M)
    E = np.empty((1 + M, H, 3))
    E[0] = r0.reshape(H, 3)
    for p in range(M):
        E[1 + p] = (r0 + w[p] * J[p]).reshape(H, 3)
    delta = np.zeros(M)
    mu = 0.1
    Jk = np.empty((M, 3 * H))
    residual_jacobian(E, w, Jk)
    np.testing.assert_allclose(Jk, J, rtol=1e-8, atol=1e-12)
    gauss_newton(Jk, np.ascontiguousarray(E[0]), mu, 0.0, delta)
    A = J @ J.T
    A += mu * np.diag(np.diag(A))
    np.testing.assert_allclose(delta, np.linalg.solve(A, -J @ r0), rtol=1e-8)
    assert plan_cost(E[0]) == pytest.approx(float(r0 @ r0))


@pytest.mark.parametrize("name", ["eight-nominal", "eight-torque"])
def test_mpc_and_limit_track_better_than_the_laws_and_give_the_same_bits_twice(name):
    """On a short run (after a 0.5 s warm-up) both model-predictive controllers track well within
    the best law's error, and a run again gives the same record to the bit."""
    law = "corradini"
    scn = mlpfac.load(name, values={"warmup": 0.5})
    rms = {}
    for c in (law, "mpc", "limit"):
        rec = run(scn.with_overrides(controller=c, duration=1.5))
        m = metrics(rec)
        assert m["outcome"] == "tracking", (c, m["reason"])
        rms[c] = m["phases"]["before"]["rms_position_error_m"]
        if c == "mpc":
            again = run(scn.with_overrides(controller=c, duration=1.5))
            np.testing.assert_array_equal(rec.pose, again.pose)
            np.testing.assert_array_equal(rec.u, again.u)
    assert rms["mpc"] < 0.5 * rms[law], rms
    assert rms["limit"] < 0.5 * rms[law], rms


def test_the_mpc_commands_the_drive_the_robot_has():
    assert _scenario("eight-nominal", "mpc", 0.2).level == "velocity"
    assert _scenario("eight-torque", "mpc", 0.2).level == "torque"
    assert _scenario("eight-torque", "limit", 0.2).level == "torque"
    ctrl = make_controller(_scenario("eight-torque", "mpc", 0.2))
    assert ctrl.level == "torque" and ctrl.name == "mpc"


@pytest.mark.parametrize(
    "key, value",
    [("horizon_s", 0.0), ("horizon_s", 1e9), ("knots", 0), ("knots", 2.5), ("iterations", 99),
     ("heading_m", -1.0), ("accel_std", float("nan")), ("fd_step", 0.0), ("damping", "x"), ("reuse", -1),
     ("slip_gate", 0.5)],
)  # fmt: skip
def test_bad_settings_are_refused_naming_their_key(key, value):
    with pytest.raises(ConfigError) as err:
        MpcConfig(**{key: value})
    assert key in str(err.value)


def test_mpc_on_the_kinematic_model_is_refused():
    with pytest.raises(ConfigError) as err:
        mlpfac.load("paper").with_overrides(controller="mpc")
    assert "MuJoCo" in str(err.value)


def test_a_sweep_with_limit_pairs_every_run_with_it_and_computes_each_limit_once(tmp_path, capsys):
    """--limit adds ``limit`` on every scenario and seed; the paired rows and the summary say x limit;
    a second sweep into another folder takes every limit from the cache (the same metrics, nothing
    run), and a cache folder changed by hand is run again."""
    from mlpfac.cli import main

    cache = tmp_path / "limits"
    args = ["compare", "eight-nominal", "--controllers", "kanayama", "--seeds", "0-1", "--duration", "0.3",
            "--workers", "1", "--limit", "--limit-cache", str(cache)]  # fmt: skip
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    first = capsys.readouterr().out
    assert "limit" in first and "x limit" in (tmp_path / "a" / "paired.md").read_text()
    assert "limit" in (tmp_path / "a" / "summary.md").read_text()
    kept = sorted(cache.glob("*/*/metrics.json"))
    assert len(kept) == 2
    assert main([*args, "--out", str(tmp_path / "b")]) == 0
    second = capsys.readouterr().out
    assert "2 limits from the cache, 2 run now" in second, second
    for seed in ("seed-0000", "seed-0001"):
        a = (tmp_path / "a" / "eight-nominal" / "limit" / seed / "metrics.json").read_text()
        b = (tmp_path / "b" / "eight-nominal" / "limit" / seed / "metrics.json").read_text()
        assert a == b
    kept[0].parent.joinpath("simulated.toml").write_text("seed = 99\n")
    assert main([*args, "--out", str(tmp_path / "c")]) == 0
    assert "1 limits from the cache, 3 run now" in capsys.readouterr().out


def test_its_settings_vary_as_any_number_of_the_file():
    """``--vary controller.mpc.horizon_s=...`` on a file that sets no [controller.mpc]: each point
    a scenario whose planner has that horizon."""
    from mlpfac.sweeps.plan import plan
    from mlpfac.sweeps.vary import parse_vary

    jobs = plan(["eight-nominal"], ["mpc"], [0], 0.2, parse_vary(["controller.mpc.horizon_s=0.2,0.4"]))
    got = sorted(mlpfac.parse(j.table, "x").mpc.horizon_s for j in jobs)
    assert got == [0.2, 0.4]


@pytest.mark.parametrize("robot", ["tests/data/weak_servo.xml", "tests/data/skid_short.xml", "tug", "SENSED"])
def test_it_runs_on_a_users_mjcf_a_skid_steer_and_a_torque_driven_robot(robot):
    """From the MJCF alone (a light robot with weak servos; four wheels that skid; the tug's torque
    motors) or a robot file that senses its pose (odometry fused with late fixes): both controllers
    run to the end, at the level the robot's drive takes."""
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    if robot == "SENSED":  # a robot that senses its pose (encoders, a gyro, late fixes): its model senses nothing
        robot = "examples/sensing/diffdrive-fused.toml"
    path = str(root / robot) if robot.endswith((".xml", ".toml")) else robot
    for c in ("mpc", "limit"):
        scn = mlpfac.load("eight-nominal", robot=path).with_overrides(controller=c, duration=0.3)
        rec = run(scn)
        assert rec.status == "ok" and rec.n == scn.steps, (robot, c, rec.reason)


def test_the_limit_view_sets_every_controller_against_the_limit_seed_by_seed():
    """A known answer: per seed ratios to limit, their median; the bound the least of the laws of
    the bound on each seed; a run lost counted as a seed not tracked; a diverged one infinite."""
    from mlpfac.report.limit import limit_table

    def run_(ctrl, seed, rms, outcome="tracking", status="ok"):
        return {"scenario": "s", "controller": ctrl, "seed": seed, "status": status, "outcome": outcome,
                "phases": {"before": {"rms_position_error_m": 1.0}, "after": {"rms_position_error_m": rms}}}  # fmt: skip

    runs = [run_("limit", 0, 1e-4), run_("limit", 1, 2e-4), run_("limit", 2, 1e-4)]
    runs += [run_("mpc", 0, 2e-4), run_("mpc", 1, 6e-4), run_("mpc", 2, 3e-4)]
    runs += [run_("oracle", 0, 1e-3), run_("oracle", 1, 4e-4), run_("oracle", 2, 2e-3)]
    runs += [run_("kanayama", 0, 2e-3), run_("kanayama", 1, 2e-3), run_("kanayama", 2, 1e-3)]
    runs += [run_("corradini", 0, 5e-3, "lost"), run_("corradini", 1, 1.0, "diverged", "diverged"),
             run_("corradini", 2, 4e-3)]  # fmt: skip
    table = limit_table(runs, ["s"], ["kanayama", "corradini"])
    row = table.splitlines()[2]
    # limit median 0.1 mm; mpc ratios 2, 3, 3 -> 3x; bound per seed 1, 0.4, 1 mm (oracle, oracle, kanayama)
    # -> median 1 mm, ratios 10, 2, 10 -> 10x; kanayama ratios 20, 10, 10 -> 10x; corradini 50, inf, 40
    assert row == "| s | 0.1 | 0.3 (3x) | 1 (oracle; 10x) | 2 (10x) | 5 (50x) 1/3 |", row


def test_robustness_names_a_law_that_holds_beyond_the_limits_breaking_point():
    """Where a law holds past limit's breaking point, robustness.md says the planner let go there,
    not the physics; where none does, it says nothing of the kind."""
    from mlpfac.sweeps.robustness import markdown

    def point(ctrl, holds_to, fails_at):
        side = {"whole_axis": False, "holds_to": holds_to, "fails_at": fails_at}
        return {
            "scenario": "s",
            "controller": ctrl,
            "axis": "a",
            "at": {},
            "nominal": 5.0,
            "below": None,
            "above": side,
        }

    beyond = markdown([point("limit", 20.0, 22.5), point("kanayama", 22.5, 25.0), point("corradini", 10.0, 20.0)], None)
    assert "kanayama (up to 22.5) hold beyond limit's breaking point (20 (fails at 22.5))" in beyond
    assert "corradini (up to" not in beyond
    within = markdown([point("limit", 20.0, 22.5), point("kanayama", 10.0, 20.0)], None)
    assert "beyond limit's breaking point" not in within and "lets go and no controller holds" in within
