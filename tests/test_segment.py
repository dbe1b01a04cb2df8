"""The compiled closed loop (mlpfac.loop.compiled) and the compiled plant step (mlpfac.plants.mujoco.compiled):
the same records, to the bit, as the step-by-step loop; divergence stops at the same step for the
same reason; MuJoCo's fatal errors end the process with one line."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from mlpfac.loop.factory import make_plant
from mlpfac.loop.runner import run, run_batch
from mlpfac.plants.events import DelayLine
from mlpfac.plants.mujoco import compiled
from mlpfac.scenario.parse import load
from mlpfac.scenario.reference import sample


def _arrays(rec) -> dict[str, np.ndarray]:
    out = {name: getattr(rec, name) for name in ("pose", "pose_meas", "e", "e_true", "u")}
    out |= {f"ctrl.{k}": v for k, v in rec.ctrl.items()} | {f"plant.{k}": v for k, v in rec.plant.items()}
    return out


def _same(a, b) -> None:
    assert (a.status, a.reason, a.n) == (b.status, b.reason, b.n)
    assert [e["text"] for e in a.events] == [e["text"] for e in b.events]
    A, B = _arrays(a), _arrays(b)
    assert A.keys() == B.keys()
    for key in A:
        np.testing.assert_array_equal(A[key], B[key], err_msg=key)


def _short(name: str, controller: str, duration: float = 4.0):
    scn = load(name).with_overrides(controller=controller)
    t = scn.events[0].time if scn.events else 0.0
    return scn.with_overrides(duration=min(scn.duration, t + duration))


@pytest.mark.parametrize(
    "name", ["eight-payload", "eight-torque", "eight-sensor-delay", "eight-control-period", "eight-wheel-radius"]
)
@pytest.mark.parametrize(
    "controller",
    ["kanayama", "corradini", "adaptive", "adaptive-velocity", "adaptive-best", "oracle", "oracle-kanayama"],
)
def test_compiled_loop_is_the_step_by_step_loop(name, controller):
    scn = _short(name, controller)
    compiled_rec = run(scn)
    stepwise = run(scn, on_step=lambda k: None)  # on_step: the loop goes step by step in Python
    _same(compiled_rec, stepwise)
    assert compiled_rec.n == scn.steps and compiled_rec.status == "ok"
    assert np.isfinite(compiled_rec.plant["u_true"]).all()


def test_a_seed_stopped_by_the_runner_stops_at_the_same_step():
    scn = dataclasses.replace(_short("eight-nominal", "kanayama"), divergence_m=0.002)
    a, b = run(scn), run(scn, on_step=lambda k: None)
    assert a.status == "diverged" and "position error" in a.reason
    _same(a, b)
    assert np.isnan(a.pose[a.n :]).all() and np.isnan(a.plant["torque"][a.n - 1 :]).all()


def test_which_controllers_run_compiled():
    """Known answer: the laws and the adaptive scheme's one-kernel forms; not the numpy parts, the
    input model, a torque-level law or a user's controller."""
    from mlpfac.control.variants import CONTROLLERS
    from mlpfac.loop.closed_loop import ClosedLoop
    from mlpfac.loop.runner import build

    compiled = set()
    for name in CONTROLLERS:
        torque = name in ("fierro-lewis", "adaptive-dynamic", "oracle-dynamic")
        s = _short("eight-torque" if torque else "eight-nominal", name, 0.1)
        b = build(s)
        if ClosedLoop([s], b.ref, b.plant, b.ctrl, True, compiled=True).compiled:
            compiled.add(name)
    one_kernel = {"adaptive", "adaptive-forget", "adaptive-q", "adaptive-prior", "adaptive-best", "adaptive-velocity"}
    assert compiled == {"kanayama", "corradini", "oracle", "oracle-kanayama"} | one_kernel
    s = _short("eight-sensor-delay", "oracle", 0.1)  # told a delay: its predictor runs in Python
    b = build(s)
    assert not ClosedLoop([s], b.ref, b.plant, b.ctrl, True, compiled=True).compiled


@pytest.mark.parametrize("controller", ["oracle", "oracle-kanayama"])
@pytest.mark.parametrize(
    ("name", "robot"),
    [("eight-payload", "skid_short.xml"), ("eight-wheel-radius", "weak_servo.xml"), ("eight-control-period", None)],
)
def test_an_oracle_compiled_is_the_oracle_step_by_step(name, robot, controller):
    """Told what a skid-steer's payload does to its turning (its track and kinematic centre), weak
    servos' answer with a wheel radius, a control period: the same records, to the bit."""
    from pathlib import Path

    scn = load(name, robot=str(Path(__file__).parent / "data" / robot) if robot else None)
    scn = scn.with_overrides(controller=controller, duration=scn.events[0].time + 2.0)
    _same(run(scn), run(scn, on_step=lambda k: None))
    seeds = [scn.with_overrides(seed=s) for s in range(2)]
    for a, b in zip(run_batch(seeds), [run(s, on_step=lambda k: None) for s in seeds], strict=True):
        _same(a, b)


def test_adaptive_batch_compiled_records_max_weight_as_the_step_by_step_loop():
    """A batch records max |z| per step (full=False), computed in the kernel as np.max does; a seed
    stopped by the runner stops at the same step."""
    from mlpfac.loop.factory import make_controller
    from mlpfac.loop.runner import _loop

    scn = _short("eight-payload", "adaptive", 2.0)
    scns = [dataclasses.replace(scn.with_overrides(seed=s), divergence_m=0.125) for s in range(4)]  # stops 2 and 3
    ref = sample(scn.reference, np.arange(scn.steps + 1) * scn.T)

    def batch(on_step):
        plants = [make_plant(s, ref) for s in scns]
        return _loop(scns, ref, plants, make_controller(scn, None, plants[0]), None, on_step, full=False)

    compiled_recs, stepwise = batch(None), batch(lambda k: None)
    assert {r.status for r in compiled_recs} == {"ok", "diverged"}
    for a, b in zip(compiled_recs, stepwise, strict=True):
        _same(a, b)
        assert a.ctrl["z"].shape[1] == 1


def test_an_adaptive_run_that_blows_up_stops_compiled_where_and_why_the_step_by_step_loop_stops():
    """An EKF that overflows (P_0 = 1e300) stops the compiled run at the step, and for the reason,
    the step-by-step loop gives (the weights are handed to the reason's test, as there)."""
    import copy

    from mlpfac.scenario.parse import parse

    t = copy.deepcopy(_short("eight-nominal", "adaptive", 1.0).table)
    t["controller"]["adaptive"] = {**t["controller"].get("adaptive", {}), "P0": 1e300}  # P H' overflows
    scn = parse(t, "nan")
    a, b = run(scn), run(scn, on_step=lambda k: None)
    assert a.status == "diverged" and a.reason.startswith("non-finite"), a.reason
    _same(a, b)


def test_batch_with_a_stopped_seed_equals_each_seed_alone():
    scn = _short("eight-payload", "corradini")
    scns = [dataclasses.replace(scn.with_overrides(seed=s), divergence_m=0.0022) for s in range(4)]
    recs = run_batch(scns)
    assert {r.status for r in recs} == {"ok", "diverged"}  # the limit stops some seeds, not all
    for r, s in zip(recs, scns, strict=True):
        alone = run(s)
        assert (r.status, r.reason, r.n) == (alone.status, alone.reason, alone.n)
        np.testing.assert_array_equal(r.e_true, alone.e_true)
        np.testing.assert_array_equal(r.plant["wheel_meas"], alone.plant["wheel_meas"])


def test_the_plant_divergence_codes_read_the_state():
    scn = load("eight-nominal")
    ref = sample(scn.reference, np.arange(scn.steps + 1) * scn.T)
    plant = make_plant(scn, ref)
    q0, u0 = scn.initial_state(ref)
    plant.reset(q0, np.random.default_rng(0), u0)
    robot = plant.kernel_args()
    st, site_xpos, qvel = robot.st, robot.site_xpos, robot.qvel

    def code() -> int:
        return compiled.diverged(robot)

    assert code() == 0 and plant.diverged() is None
    st[compiled.S_TIME] += 1.0  # MuJoCo's time no longer ours: it reset the data
    assert code() == compiled.RESET and "reset" in plant.why(code())
    st[compiled.S_TIME] -= 1.0
    site_xpos[2] += plant.real_radius  # the axle a wheel radius up
    assert code() == compiled.LIFTED and "left the floor" in plant.why(code())
    site_xpos[2] -= plant.real_radius
    qvel[0] = np.nan
    assert code() == compiled.NOT_FINITE and plant.why(code()) == "non-finite MuJoCo state"


def test_delay_line_keeps_the_newest_and_repeats_the_oldest():
    line = DelayLine(np.array([0.0, 0.0, 0.0]))
    for k in range(1, 4):
        line.push(np.full(3, float(k)))
    assert line.read()[0] == 3.0 and line.steps == 0
    line.delay(2)  # longer: keeps what it holds, the oldest repeated until it fills
    assert line.read()[0] == 3.0
    line.push(np.full(3, 4.0))
    line.push(np.full(3, 5.0))
    assert line.read()[0] == 3.0
    line.push(np.full(3, 6.0))
    assert line.read()[0] == 4.0
    line.delay(0)  # shorter: the newest
    assert line.read()[0] == 6.0
    ints = DelayLine(0)
    ints.delay(1)
    ints.push(1)
    ints.push(2)
    assert ints.read() == 1 and isinstance(ints.read(), int)


def test_a_delay_line_of_a_batch_holds_each_measurement_whole():
    """A batch's measurements (B, 3) are pushed as flat rows of the same memory: what comes out is
    what went in, steps late, seed by seed and coordinate by coordinate."""
    rng = np.random.default_rng(0)
    xs = rng.normal(size=(12, 4, 3))
    line = DelayLine(xs[0])
    line.delay(3)
    for k in range(1, len(xs)):
        line.push(xs[k])
        assert np.array_equal(line.read(), xs[max(k - 3, 0)])
    assert line.hist.shape == (4, 4, 3)
    with pytest.raises(ValueError, match="delay line"):
        line.push(xs[0][:3])  # a measurement of another size: refused, not cut


def test_a_fatal_mujoco_error_in_a_compiled_step_is_one_line_and_exit_1():
    script = textwrap.dedent(
        """
        import mujoco
        from numba import njit
        from mlpfac.plants.mujoco import compiled
        bodies = "".join(f'<body pos="0 0 {i * 0.01}"><freejoint/><geom size=".1"/></body>' for i in range(20))
        m = mujoco.MjModel.from_xml_string(f'<mujoco><size memory="20K"/><worldbody>{bodies}</worldbody></mujoco>')
        d = mujoco.MjData(m)
        try:
            mujoco.mj_step(m, mujoco.MjData(m))
            raise SystemExit(3)  # this MuJoCo fits the contacts in the arena: nothing to test
        except mujoco.FatalError:
            pass  # the bindings still raise (their own handler comes first)

        @njit
        def step(mp, dp):
            compiled.mj_step(mp, dp)

        step(m._address, d._address)
        print("returned")
        """
    )
    env = dict(os.environ, MLPFAC_KERNELS="jit")  # numba names mj_step for the test's own kernel
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300, env=env)
    if out.returncode == 3:
        pytest.skip("this MuJoCo does not overflow the arena of the test model")
    assert out.returncode == 1, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: MuJoCo: mj_stackAlloc"), out.stderr
    assert "returned" not in out.stdout
