"""mlpfac/Track-v0: the environment is the run (a plug-in stepped through it records the same bits
as `mlpfac run --controller`), its vector form is its single form, randomized numbers are drawn
per episode seed, bad arguments are one line naming them; gymnasium's own checker passes."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import mlpfac
import mlpfac.envs  # noqa: F401 (registers mlpfac/Track-v0)
from mlpfac.envs.track import TrackEnv
from mlpfac.exceptions import ConfigError

ROOT = Path(__file__).resolve().parents[1]
ID = "mlpfac/Track-v0"


def _example(name: str, cls: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return getattr(module, cls)


def _through_env(env, ctrl, seed: int, level: str = "velocity") -> dict:
    """Step ``ctrl`` (a plug-in object) through ``env`` from reset(seed) to the end: the final info."""
    _, info = env.reset(seed=seed)
    ctrl.reset(np.random.default_rng(0))
    while True:
        u = ctrl.step(info["obs"]) if level == "torque" else ctrl.step(info["e"], info["r"])
        _, _, terminated, truncated, info = env.step(np.asarray(u, dtype=float))
        if terminated or truncated:
            return info


@pytest.mark.parametrize(
    ("scenario", "duration"),
    [("eight-slope", 13.0), ("eight-bumps", 2.0), ("eight-wheel-radius-fused", 13.0), ("eight-push", 3.0)],
)
def test_a_plugin_through_the_env_is_the_run_bit_for_bit(scenario, duration):
    """The world (a slope at 12.5 s, rough ground, a push) and the fused pose: the same phases, the
    same record, as `mlpfac run --controller pure_pursuit.py:PurePursuit`."""
    spec = f"{ROOT / 'examples' / 'pure_pursuit.py'}:PurePursuit"
    rec = mlpfac.run(scenario, controller=spec, seed=2, duration=duration)
    env = gymnasium.make(ID, scenario=scenario, duration=duration)
    info = _through_env(env, _example("pure_pursuit", "PurePursuit")(T=0.01), seed=2)
    assert info["metrics"]["phases"] == mlpfac.metrics(rec)["phases"]
    mine = info["record"]
    assert mine.n == rec.n and np.array_equal(mine.e_true[: rec.n], rec.e_true[: rec.n])
    assert np.array_equal(mine.u[: rec.n], rec.u[: rec.n])


def test_a_torque_level_plugin_through_the_env_is_the_run():
    spec = f"{ROOT / 'examples' / 'torque_law.py'}:TorqueLaw"
    rec = mlpfac.run("eight-torque", controller=spec, seed=1, duration=1.5)
    env = gymnasium.make(ID, scenario="eight-torque", level="torque", duration=1.5)
    env.reset(seed=1)
    robot = env.unwrapped.episode.plant.plants[0].dynamics()
    info = _through_env(env, _example("torque_law", "TorqueLaw")(T=0.01, robot=robot), seed=1, level="torque")
    assert info["metrics"]["phases"] == mlpfac.metrics(rec)["phases"]


def test_reset_starts_the_run_of_that_seed():
    """The first observation is the run's first measured error and reference; a diverging command
    terminates the episode with the run's reason."""
    rec = mlpfac.run("eight-payload", controller="kanayama", seed=7, duration=0.05)
    env = gymnasium.make(ID, scenario="eight-payload", duration=1.0)
    obs, info = env.reset(seed=7)
    assert np.array_equal(info["e"], rec.e[0]) and np.array_equal(info["r"], rec.ref[0])
    assert np.array_equal(obs[:3], rec.e[0]) and info["seed"] == 7
    _, _, terminated, truncated, info = env.step(np.array([np.nan, 0.0]))
    assert terminated and not truncated and "non-finite" in info["metrics"]["reason"]
    with pytest.raises(gymnasium.error.ResetNeeded):
        env.step(np.zeros(2))


def test_gymnasium_env_checker_passes():
    check_env(TrackEnv("eight-nominal", duration=0.5, render_mode="rgb_array"))
    check_env(TrackEnv("eight-torque", level="torque", duration=0.3, rescale_actions=True), skip_render_check=True)


def test_the_vector_env_is_the_single_env_with_the_same_seed():
    """Four robots on one kernel call a step, an event moved early by a draw, the next episodes
    started by the vector env itself: every observation, reward and end as four single envs'."""
    kw = {"scenario": "eight-wheel-radius", "duration": 0.6, "randomize": {"events.0.time": "uniform:0.1:0.5"}}
    venv = gymnasium.make_vec(ID, num_envs=4, vectorization_mode="vector_entry_point", **kw)
    envs = [gymnasium.make(ID, **kw) for _ in range(4)]
    obs, _ = venv.reset(seed=5)
    assert np.array_equal(obs, np.array([e.reset(seed=5 + i)[0] for i, e in enumerate(envs)]))
    rng = np.random.default_rng(0)
    done = np.zeros(4, dtype=bool)
    ended = 0
    for _ in range(130):
        a = obs[:, 6:8] + rng.uniform(-0.2, 0.2, (4, 2))
        obs, reward, term, trunc, info = venv.step(a)
        for i, env in enumerate(envs):
            if done[i]:  # the vector env started the next episode (seeded as the single env's reset())
                o, r, te, tr = *env.reset()[:1], 0.0, False, False
            else:
                o, r, te, tr, one = env.step(a[i])
                if te or tr:
                    ended += 1
                    assert info["_metrics"][i] and info["metrics"][i]["phases"] == one["metrics"]["phases"]
            assert np.array_equal(o, obs[i]) and r == reward[i] and (te, tr) == (term[i], trunc[i])
        done = term | trunc
    assert ended >= 4


def test_same_step_autoreset_gives_the_ended_episode_and_starts_the_next():
    from gymnasium.vector import AutoresetMode

    kw = {"scenario": "eight-nominal", "duration": 0.05}
    venv = gymnasium.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point",
                              autoreset_mode=AutoresetMode.SAME_STEP, **kw)  # fmt: skip
    env = gymnasium.make(ID, **kw)
    obs, _ = venv.reset(seed=3)
    env.reset(seed=3)
    for _ in range(5):
        o, _, _, truncated, one = env.step(obs[0, 6:8])
        obs, _, _, trunc, info = venv.step(obs[:, 6:8])
    assert truncated and trunc.all() and info["_final_obs"].all()
    assert np.array_equal(info["final_obs"][0], o)
    assert info["final_info"]["metrics"][0]["phases"] == one["metrics"]["phases"]
    assert np.array_equal(obs[0], env.reset()[0])  # the next episode, seeded as the single env's reset()


def test_randomized_numbers_are_drawn_per_episode_seed_and_named():
    key = "events.0.scale"
    env = gymnasium.make(ID, scenario="eight-wheel-radius", duration=13.0, randomize={key: "uniform:1.2:1.8"})
    drawn = [env.reset(seed=s)[1]["drawn"][key] for s in (0, 1, 0)]
    assert drawn[0] == drawn[2] != drawn[1] and all(1.2 <= d <= 1.8 for d in drawn)
    scn = mlpfac.load("eight-wheel-radius", values={key: {"uniform": [1.2, 1.8]}}).with_overrides(seed=1)
    assert scn.drawn[key] == drawn[1]  # what a sweep's --vary draws for the seed
    env = gymnasium.make(ID, scenario="eight-sensor-delay", duration=13.0, randomize={"events.0.steps": "choice:0:2:4"})
    assert {env.reset(seed=s)[1]["drawn"]["events.0.steps"] for s in range(12)} == {0, 2, 4}


BAD_ARGUMENTS = {
    "unknown scenario": ({"scenario": "nosuch"}, "nosuch"),
    "level": ({"level": "speed"}, "level"),
    "torque on velocity servos": ({"level": "torque"}, "level"),
    "robot not a name": ({"robot": 3}, "robot"),
    "duration": ({"duration": "long"}, "duration"),
    "randomize unknown key": ({"randomize": {"plant.nosuch": "uniform:0:1"}}, "randomize plant.nosuch"),
    "randomize an event left out": ({"randomize": {"events.0.scale": "uniform:1:2"}}, "left out by duration 0.2"),
    "randomize a list": ({"randomize": {"events.0.scale": "1.2,1.5"}}, "randomize events.0.scale"),
    "randomize a bad distribution": ({"randomize": {"events.0.scale": "uniform:2:1"}}, "randomize events.0.scale"),
    "randomize out of range": ({"randomize": {"events.0.scale": "uniform:1:100"}}, "randomize events.0.scale"),
    "randomize not a table": ({"randomize": ["events.0.scale"]}, "randomize"),
    "reward": ({"reward": 3}, "reward"),
    "render mode": ({"render_mode": "rgb"}, "render_mode"),
    "rescale": ({"rescale_actions": "yes"}, "rescale_actions"),
}


@pytest.mark.parametrize("case", sorted(BAD_ARGUMENTS))
def test_bad_arguments_are_one_line_naming_them(case):
    kwargs, needle = BAD_ARGUMENTS[case]
    kwargs = {"scenario": "eight-wheel-radius", "duration": 0.2} | kwargs
    if "events.0" in str(kwargs.get("randomize")) and "left out" not in needle:
        kwargs["duration"] = 13.0
    with pytest.raises(ConfigError) as err:
        gymnasium.make(ID, **kwargs)
    text = str(err.value)
    assert needle in text and len(text.splitlines()) == 1, text


def test_a_users_mjcf_robot_runs_to_the_end():
    env = gymnasium.make(ID, scenario="eight-nominal", robot=str(ROOT / "models" / "tug.xml"), duration=1.0)
    obs, info = env.reset(seed=0)
    steps, truncated = 0, False
    while not truncated:
        obs, _, terminated, truncated, info = env.step(obs[6:8])
        assert not terminated
        steps += 1
    assert steps == 100 and info["metrics"]["outcome"] == "tracking"


@pytest.mark.menagerie
def test_a_menagerie_robot_by_name_runs_to_the_end():
    env = gymnasium.make(ID, scenario="eight-payload", robot="pal_tiago", duration=0.5)
    obs, info = env.reset(seed=0)
    truncated = False
    while not truncated:
        obs, _, terminated, truncated, info = env.step(obs[6:8])
        assert not terminated
    assert info["metrics"]["status"] == "ok"


def test_an_episode_is_recorded_for_the_viewer(tmp_path):
    from mlpfac.log import check_recording

    env = gymnasium.make(ID, scenario="eight-nominal", duration=0.3, record=tmp_path / "episodes")
    obs, _ = env.reset(seed=4)
    truncated = False
    while not truncated:
        obs, _, _, truncated, _ = env.step(obs[6:8])
    env.close()
    (rrd,) = (tmp_path / "episodes").glob("*.rrd")
    assert rrd.name == "episode-00001-seed-4.rrd"
    check_recording(rrd)


def test_policy_dr_runs_on_a_robot_it_was_not_trained_on():
    """The cart, with the limits the scenario gives it: a run to the end, its outcome said."""
    rec = mlpfac.run("cart-nominal", controller="policy-dr", seed=0, duration=3.0)
    m = mlpfac.metrics(rec)
    assert rec.status == "ok" and m["outcome"] in ("tracking", "lost")


def test_a_policy_runs_by_name_and_by_path_in_sweep_check_and_on_other_robots(tmp_path):
    """policy-dr by name, a copy of it by path (its folders named by its stem), on the cart and TIAGo's
    names beside our robot; a budget naming the file beside it."""
    import shutil

    from mlpfac.control.policy import policy_file

    mine = tmp_path / "mine.npz"
    shutil.copy(policy_file("policy-dr"), mine)
    rows = mlpfac.sweep(["eight-nominal"], ["policy-dr", str(mine)], seeds="0", duration=0.5, robots=["diffdrive", "cart"],
                        workers=1, out=tmp_path / "sweep")  # fmt: skip
    assert {(r["scenario"], r["controller"]) for r in rows} >= {
        ("eight-nominal+cart", "mine"),
        ("eight-nominal+diffdrive", "policy-dr"),
    }
    assert not rows.errors
    (tmp_path / "budget.toml").write_text(
        'scenarios = ["eight-nominal"]\ncontrollers = ["mine.npz", "policy-dr"]\nseeds = "0"\nduration = 0.5\n'
        '[[budget]]\nname = "finishes"\ndiverged = 0\n'
    )
    result = mlpfac.check(tmp_path / "budget.toml", out=tmp_path / "check", workers=1)
    assert result.code == 0


def test_a_policy_is_its_formula(tmp_path):
    """Known answer: a one-layer policy's command is ff + act_scale * clip(W x + b) * limits, with x
    the scaled, clipped inputs of mlpfac.control.policy; a zero policy is the feed-forward alone."""
    from mlpfac.control.policy import Policy, save
    from mlpfac.elementary import cos, sin

    W, b = np.arange(16.0).reshape(2, 8) / 40.0 - 0.2, np.array([0.05, -0.1])
    scale = np.array([0.05, 0.05, 0.1, 0.01, 0.5, 0.2, 0.5, 0.2])
    p = save(tmp_path / "one.npz", [(W, b)], scale, 5.0, [0.25, 0.5], True)
    law = mlpfac.load("eight-nominal").law
    ctrl = Policy(p, "one", 0.01, law)
    ctrl.reset(np.random.default_rng(0))
    e, r = np.array([0.01, -0.02, 0.3]), np.array([0.0, 0.0, 0.0, 0.8, 0.4])
    u1 = ctrl.step(e, r)
    u2 = ctrl.step(e, r)  # now with its last command as an input
    for u, prev in ((u1, np.zeros(2)), (u2, u1)):
        f = [e[0], e[1], sin(e[2]), 1.0 - cos(e[2]), r[3] / 2.0, r[4] / 5.0, prev[0] / 2.0, prev[1] / 5.0]
        x = np.clip(np.array(f) / scale, -5.0, 5.0)
        a = np.clip([sum(W[j, i] * x[i] for i in range(8)) + b[j] for j in range(2)], -1.0, 1.0)
        assert np.allclose(u, [r[3] + 0.25 * a[0] * 2.0, r[4] + 0.5 * a[1] * 5.0], rtol=0, atol=1e-12)
    zero = Policy(
        save(tmp_path / "zero.npz", [(np.zeros((2, 8)), np.zeros(2))], scale, 5.0, [1, 1], True), "z", 0.01, law
    )
    zero.reset(np.random.default_rng(0))
    assert np.array_equal(zero.step(e, r), r[3:5])
