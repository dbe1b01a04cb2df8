"""``mlpfac/Track-v0``: any scenario as a Gymnasium environment (docs/envs.md).

    env = gymnasium.make("mlpfac/Track-v0", scenario="eight-wheel-radius", robot=None, level="velocity")
    obs, info = env.reset(seed=3)          # the run `mlpfac run eight-wheel-radius --seed 3` starts
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

An episode is a run: ``reset(seed=s)`` builds what ``mlpfac run SCENARIO --seed s`` builds (the plant
drawn for the seed, its noise streams, its events, its world) and each step is one control period
of the run's closed loop with the action as the command. Without a seed, an episode's seed is drawn
from the environment's generator (seeded by the last seed given). A divergence (MuJoCo's warning,
the error bound ``divergence_m``, the plant's own test) terminates the episode; the scenario's end
truncates it; either way ``info["metrics"]`` then holds the run's figures (metrics.json's, its
``phases`` against the true pose).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from mlpfac.envs.episode import Episode
from mlpfac.envs.spaces import Layout, Reward, fill, layout, torque_limits, velocity_limits
from mlpfac.exceptions import ConfigError
from mlpfac.scenario.parse import Scenario

LEVELS = ("velocity", "torque")
RENDER_MODES = ("human", "rgb_array")  # a rerun viewer started for the episode; a top view as an image
SEED_MAX = 2**31 - 1  # an episode's seed drawn by the environment: in [0, SEED_MAX)


@dataclass(frozen=True)
class Setup:
    """What every episode of an environment is made from: the scenario as loaded (its randomized
    numbers as distributions, drawn per episode seed), what a run of it overrides, the spaces."""

    source: Scenario
    level: str
    controller: str | None  # the controller the episode's scenario names (its level: the plant's command)
    duration: float | None
    layout: Layout
    reward: Reward | Callable
    rescale: bool
    randomized: tuple[str, ...]
    record: Path | None
    render_mode: str | None

    def scenario(self, seed: int) -> Scenario:
        """The episode's scenario for ``seed``: ``mlpfac run SCENARIO --seed seed`` (its draws for the seed)."""
        return self.source.with_overrides(self.controller, seed, self.duration)

    def command(self, action) -> np.ndarray:
        """The action as the plant's command, (2,) float: scaled from [-1, 1] with ``rescale_actions``."""
        try:
            a = np.asarray(action, dtype=np.float64).reshape(2)
        except (TypeError, ValueError):
            raise ConfigError("action", f"expected two numbers, got {action!r}") from None
        return a * self.layout.act_high if self.rescale else a

    def sink(self, scn: Scenario, count: int):
        """The episode's recording (:mod:`mlpfac.log`): a file in ``record``, a viewer for "human"; None: neither."""
        if self.record is None and self.render_mode != "human":
            return None
        from mlpfac.log import make_sink  # only mlpfac.log imports rerun

        save = None if self.record is None else self.record / f"episode-{count:05d}-seed-{scn.seed}.rrd"
        name = f"{scn.name} {self.level} episode {count} seed {scn.seed}"
        return make_sink(save=save, spawn=self.render_mode == "human", recording_name=name, description=scn.description)


def configure(
    scenario: str | Path = "eight-nominal",
    robot: str | None = None,
    level: str = "velocity",
    duration: float | None = None,
    randomize: dict | None = None,
    reward: Reward | Callable | None = None,
    rescale_actions: bool = False,
    render_mode: str | None = None,
    record: str | Path | None = None,
) -> Setup:
    """The environment's arguments checked, each bad one a ConfigError naming it (as the command's
    flags are named), and the first episode's scenario built to find the spaces."""
    from mlpfac.envs.randomize import randomized_source

    if not isinstance(scenario, str | Path) or isinstance(scenario, bool):
        raise ConfigError("scenario", f"expected a shipped scenario's name or a .toml path, got {scenario!r}")
    if robot is not None and not isinstance(robot, str):
        raise ConfigError("robot", f"expected a robot's name or an MJCF file, got {robot!r}")
    if level not in LEVELS:
        raise ConfigError("level", f"expected 'velocity' or 'torque', got {level!r}")
    if duration is not None and (isinstance(duration, bool) or not isinstance(duration, int | float)):
        raise ConfigError("duration", f"expected a number of seconds, got {duration!r}")
    if not isinstance(rescale_actions, bool):
        raise ConfigError("rescale_actions", f"expected true or false, got {rescale_actions!r}")
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ConfigError(
            "render_mode", f"expected None, 'human' (a rerun viewer) or 'rgb_array' (a top view), got {render_mode!r}"
        )
    reward = Reward() if reward is None else reward
    if not isinstance(reward, Reward) and not callable(reward):
        raise ConfigError("reward", f"expected a callable reward(e_true, u, info) -> float, got {reward!r}")
    folder = None
    if record is not None:
        from mlpfac.io.targets import user_path

        folder = Path(user_path(record, "record"))
        if folder.exists() and not folder.is_dir():
            raise ConfigError("record", f"{folder} is not a folder (each episode is written into it as an .rrd file)")
        folder.mkdir(parents=True, exist_ok=True)
    source, keys = randomized_source(str(scenario), robot, randomize, duration)
    torque_plant = getattr(source.plant_config, "actuator", None) == "torque"
    if level == "torque" and not torque_plant:
        raise ConfigError(
            "level",
            f"'torque' commands the wheels' torques, which {source.plant_from or source.source}'s "
            f"{getattr(source.plant_config, 'actuator', source.plant_kind)} drive does not take: choose a robot "
            'with torque motors (eight-torque, diffdrive-torque, cart-torque, tug, or actuator = "torque" in [plant])',
        )
    controller = None
    if source.level != level:  # what the plant is commanded: a controller of the level named
        controller = "fierro-lewis" if level == "torque" else "kanayama"
    try:
        first = source.with_overrides(controller, 0, duration, flag="level")
    except ConfigError as err:
        raise ConfigError(err.where.replace("--duration", "duration"), err.what) from None
    ep = Episode(first, level)
    high = velocity_limits(first.law) if level == "velocity" else torque_limits(ep.plant.plants[0].dynamics())
    robot_model = ep.plant.plants[0].dynamics() if level == "torque" else None
    lay = layout(level, ep.ref, ep.loop.r_dot if level == "torque" else ep.ref[:, 3:5], first.divergence_m, high,
                 robot_model)  # fmt: skip
    ep.finish()
    return Setup(source, level, controller, duration, lay, reward, rescale_actions, keys, folder, render_mode)


class TrackEnv(gym.Env):
    """Tracking the scenario's reference with the scenario's robot, world and pose source.

    - **action**: ``(v, omega)`` in m/s and rad/s at the velocity level (bounded by the controller's
      limits, which a robot's wheels set), the wheels' torques ``(tau_l, tau_r)`` in N m at the torque
      level (within the motors' range); with ``rescale_actions=True``, both in [-1, 1] instead. A
      command outside the Box is applied as given, as a plug-in's is (the IK keeps the wheels within
      their limit, the motors clamp their torque).
    - **observation**: :mod:`mlpfac.envs.spaces` (``env.unwrapped.names`` names each component).
    - **reward**: :class:`~mlpfac.envs.spaces.Reward`, or ``reward(e_true, u, info)`` of your own.
    - **info**: ``e`` and ``r`` exactly as a kinematic plug-in's ``step(e, r)`` receives them (and
      ``obs``, the :class:`~mlpfac.control.torque.Observation` of a torque-level plug-in), ``e_true``
      (the true error, which no controller sees), ``t``; after reset ``drawn`` (the randomized numbers
      and the scenario's own draws, by key) and ``seed``; at the episode's end ``metrics`` (metrics.json's
      figures) and ``record`` (the run's :class:`~mlpfac.loop.record.RunRecord`).
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 100}

    def __init__(self, scenario: str | Path = "eight-nominal", **kwargs: Any) -> None:
        self.setup = configure(scenario, **kwargs)
        lay = self.setup.layout
        self.names = lay.names
        self.render_mode = self.setup.render_mode
        self.observation_space = gym.spaces.Box(lay.low, lay.high, dtype=np.float64)
        one = np.ones(2)
        low, high = (-one, one) if self.setup.rescale else (-lay.act_high, lay.act_high)
        self.action_space = gym.spaces.Box(low, high, dtype=np.float64)
        self.episode: Episode | None = None
        self.episodes = 0
        self._obs = np.zeros((1, len(self.names)))

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
            raise ConfigError("seed", f"expected a whole number >= 0, got {seed!r}")
        super().reset(seed=seed)
        s = int(seed) if seed is not None else int(self.np_random.integers(SEED_MAX))
        if self.episode is not None:
            self.episode.finish()
        scn = self.setup.scenario(s)
        self.episodes += 1
        self.episode = Episode(scn, self.setup.level, self.setup.sink(scn, self.episodes))
        self._prev = np.zeros((1, 2))
        return self._observation(), self._info() | {"seed": s, "drawn": scn.drawn}

    def step(self, action):
        ep = self.episode
        if ep is None or ep.done:
            raise gym.error.ResetNeeded("call reset() before step(), and after the episode's end")
        u = self.setup.command(action)
        ep.act(u)
        self._prev[0] = u
        info = self._info()
        if ep.done:
            info |= {"metrics": ep.metrics(), "record": ep.rec, "drawn": ep.scn.drawn}
        if isinstance(self.setup.reward, Reward):
            reward = float(self.setup.reward.batch(ep.e_true, u[None], self.setup.layout.act_high)[0])
        else:
            reward = float(self.setup.reward(ep.e_true[0].copy(), u.copy(), info))
        return self._observation(), reward, ep.terminated, ep.done and not ep.terminated, info

    def _observation(self) -> np.ndarray:
        ep, lay, prev = self.episode, self.setup.layout, self._prev
        if self.setup.level == "velocity":
            e, r = ep.inputs
            fill(self._obs, e, r[None], prev, lay.low, lay.high)
        else:
            o = ep.inputs[0]
            fill(self._obs, o.e, o.r[None], prev, lay.low, lay.high, (o.r_dot[None], o.pose, o.twist, o.wheel_speeds))
        return self._obs[0].copy()

    def _info(self) -> dict:
        ep = self.episode
        k = min(ep.k, ep.N)
        out = {"k": k, "t": k * ep.scn.T, "e_true": ep.e_true[0].copy()}
        if self.setup.level == "velocity":
            e, r = ep.inputs
            return out | {"e": e[0].copy(), "r": r.copy()}
        o = ep.inputs[0].seed(0)
        return out | {"e": o.e, "r": o.r, "obs": o}

    def render(self) -> np.ndarray | None:
        """The episode's top view with ``render_mode="rgb_array"`` (:mod:`mlpfac.envs.picture`); "human"
        streams each episode to a rerun viewer as it runs (nothing to do here)."""
        if self.render_mode != "rgb_array" or self.episode is None:
            return None
        from mlpfac.envs.picture import top_view

        ep = self.episode
        n = ep.rec.n
        return top_view(ep.ref[:, :2], ep.loop.pose[0, :n, :2], ep.loop._q[0])

    def close(self) -> None:
        if self.episode is not None:
            self.episode.finish()
        super().close()
