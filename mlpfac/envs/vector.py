"""N robots of one scenario as a Gymnasium vector environment, stepped by one compiled call a step.

    envs = gymnasium.make_vec("mlpfac/Track-v0", num_envs=16, vectorization_mode="vector_entry_point",
                              scenario="eight-nominal")

Sub-environment i is the single environment (:class:`~mlpfac.envs.track.TrackEnv`) with the same
seed, to the bit: its episodes are :class:`~mlpfac.envs.episode.Episode`\\ s, seeded as the single
environment seeds them (``reset(seed=s)`` gives sub-environment i the seed s + i, and each draws its
next episode's seed from its own generator). On a MuJoCo robot every sub-environment's step (the
closed loop's divergence test, the robot's compiled step, its record, the next step's errors) runs in
one kernel call for all of them (:func:`mlpfac.loop.compiled.across`), each robot at its own step;
Python steps in only where an episode starts or ends, an event is applied, and, at the torque level,
where the motion's noise is drawn. The kinematic model's episodes are stepped one by one.

Autoreset: ``autoreset_mode`` (gymnasium's :class:`~gymnasium.vector.AutoresetMode`): NEXT_STEP (the
default: the step after an episode's end starts the next one, its action ignored) or SAME_STEP (the
next episode starts within the step that ended one; the ended episode's observation and info are in
``infos["final_obs"]`` and ``infos["final_info"]``). ``infos`` holds arrays: ``e``, ``r``, ``e_true``,
``k``, ``t`` (at the torque level also ``r_dot``, ``pose``, ``twist``, ``wheel_speeds``: the
:class:`~mlpfac.control.torque.Observation`'s), and, where an episode ended, ``metrics`` and ``record``
(with the ``_metrics`` mask), where one started ``seed`` and ``drawn``.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from mlpfac.envs.episode import Episode
from mlpfac.envs.spaces import Reward, fill
from mlpfac.envs.track import RENDER_MODES, SEED_MAX, configure
from mlpfac.exceptions import ConfigError
from mlpfac.loop import compiled as A  # noqa: N812 - the kernel stepping many robots, and its row's layout
from mlpfac.loop.closed_loop import FLUSH_EVERY
from mlpfac.plants.mujoco import compiled as K  # noqa: N812 - the MuJoCo plant's compiled step
from mlpfac.plants.mujoco.compiled import ROW, robot_row

CHUNK = 256  # noise draws taken from a robot's stream at once (never past its next event)


def _put(row: np.ndarray, j: int, a: np.ndarray) -> None:
    """An array's (address, rows, columns) at j of a kernel's row (kept alive by its episode)."""
    assert a.flags.c_contiguous and a.dtype == np.float64
    row[j : j + 3] = a.ctypes.data, a.shape[0], a.shape[1] if a.ndim == 2 else 1


class TrackVectorEnv(VectorEnv):
    """``num_envs`` sub-environments of :class:`~mlpfac.envs.track.TrackEnv`'s arguments."""

    def __init__(
        self, num_envs: int = 1, scenario="eight-nominal", autoreset_mode=AutoresetMode.NEXT_STEP, **kwargs: Any
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or not 1 <= num_envs <= 4096:
            raise ConfigError("num_envs", f"expected a whole number from 1 to 4096, got {num_envs!r}")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            mode = None
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ConfigError("autoreset_mode", f"expected NEXT_STEP or SAME_STEP, got {autoreset_mode!r}")
        self.setup = s = configure(scenario, **kwargs)
        self.num_envs, self.mode = num_envs, mode
        self.metadata = {"autoreset_mode": mode, "render_modes": list(RENDER_MODES), "render_fps": 100}
        self.render_mode = s.render_mode
        lay = s.layout
        self.names = lay.names
        self.single_observation_space = gym.spaces.Box(lay.low, lay.high, dtype=np.float64)
        one = np.ones(2)
        low, high = (-one, one) if s.rescale else (-lay.act_high, lay.act_high)
        self.single_action_space = gym.spaces.Box(low, high, dtype=np.float64)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        n = num_envs
        self.torque = s.level == "torque"
        self.fast = s.source.plant_kind == "mujoco"  # a compiled robot step: one kernel call for all
        self.eps: list[Episode | None] = [None] * n
        self.rngs: list[np.random.Generator | None] = [None] * n
        self.episodes = 0
        self._obs = np.zeros((n, len(self.names)))
        self._E, self._ET, self._R, self._P = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 5)), np.zeros((n, 2))
        self._RD, self._PM, self._TW, self._WS = np.zeros((n, 2)), np.zeros((n, 3)), np.zeros((n, 2)), np.zeros((n, 2))
        self._ks, self._steps, self._due = (np.zeros(n, dtype=np.int64) for _ in range(3))
        self._limit = np.zeros(n)
        self._table = np.zeros((n, A.WIDTH), dtype=np.int64)
        self._drawn, self._codes = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        self._draws: list[np.ndarray] = [np.zeros((0, 3))] * n
        self._args: list = [None] * n
        self._sts: list = [np.zeros(K.N_ST)] * n
        self._autoreset = np.zeros(n, dtype=np.bool_)

    # -- episodes

    def reset(self, *, seed: int | list | None = None, options: dict | None = None):
        super().reset(seed=seed if isinstance(seed, int) else None)
        n = self.num_envs
        if seed is None:
            seeds = [None] * n
        elif isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0:
            seeds = [seed + i for i in range(n)]
        elif isinstance(seed, list | tuple) and len(seed) == n:
            seeds = list(seed)
        else:
            raise ConfigError("seed", f"expected a whole number >= 0 or a list of {n} of them, got {seed!r}")
        info: dict = {}
        for i, s in enumerate(seeds):
            if s is not None and (isinstance(s, bool) or not isinstance(s, int) or s < 0):
                raise ConfigError("seed", f"expected whole numbers >= 0, got {s!r}")
            if s is not None:
                self.rngs[i] = seeding.np_random(s)[0]
            self._start(i, s, info)
        self._autoreset[:] = False
        self._observe()
        return self._obs.copy(), self._infos() | info

    def _start(self, i: int, seed: int | None, info: dict) -> None:
        """Sub-environment i's next episode (the single environment's ``reset(seed=seed)``)."""
        if seed is None:
            if self.rngs[i] is None:
                self.rngs[i] = seeding.np_random()[0]
            seed = int(self.rngs[i].integers(SEED_MAX))
        if self.eps[i] is not None:
            self.eps[i].finish()
        scn = self.setup.scenario(seed)
        self.episodes += 1
        ep = self.eps[i] = Episode(scn, self.setup.level, self.setup.sink(scn, self.episodes))
        self._steps[i], self._limit[i], self._P[i] = ep.N, scn.divergence_m, 0.0
        if self.fast:
            ep.ptele = ep.loop.plant_rows()[0]
            self._draws[i], self._drawn[i] = np.zeros((0, 3)), 0
        self._sync(i)
        _mark(info, "seed", i, self.num_envs, seed, int)
        _mark(info, "drawn", i, self.num_envs, scn.drawn)

    def _sync(self, i: int) -> None:
        """Sub-environment i's rows from its episode, after Python stepped it (a start, an event, an
        end); on a MuJoCo robot its kernel row again (an event may have replaced the robot's arrays)."""
        ep = self.eps[i]
        k = min(ep.k, ep.N)
        self._ks[i] = ep.k
        self._E[i], self._ET[i], self._R[i] = ep.loop._e[0], ep.e_true[0], ep.ref[k]
        if self.torque:
            o = ep.inputs[0]
            self._RD[i], self._PM[i], self._TW[i], self._WS[i] = o.r_dot, o.pose[0], o.twist[0], o.wheel_speeds[0]
        if self.fast and not ep.done:
            self._due[i] = _due(ep)
            self._row(i)

    def _row(self, i: int) -> None:
        ep, row = self.eps[i], self._table[i]
        loop = ep.loop
        p = loop.plant.plants[0]
        self._args[i] = args = p.kernel_args()
        self._sts[i] = p.st
        robot_row(args, row[:ROW])
        arrays = ((A.TELE_AT, p.tele), (A.REF_AT, ep.ref), (A.POSE_AT, loop.pose[0]),
                  (A.POSE_MEAS_AT, loop.pose_meas[0]), (A.E_AT, loop.e[0]), (A.E_TRUE_AT, loop.e_true[0]),
                  (A.U_AT, loop.u[0]), (A.PTELE_AT, ep.ptele), (A.Q_AT, loop.plant._q), (A.Q_MEAS_AT, loop.plant._m),
                  (A.E_STEP_AT, loop._e), (A.ET_STEP_AT, loop._et), (A.ET_NEXT_AT, ep.e_true),
                  (A.DRAWS_AT, self._draws[i]))  # fmt: skip
        for j, a in arrays:
            _put(row, j, a)

    # -- a step

    def step(self, actions):
        U_ = np.array(actions, dtype=np.float64).reshape(self.num_envs, 2)
        if self.setup.rescale:
            U_ *= self.setup.layout.act_high
        n = self.num_envs
        info: dict = {}
        rewards = np.zeros(n)
        terminated, truncated = np.zeros(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_)
        if self.mode == AutoresetMode.NEXT_STEP:
            for i in np.flatnonzero(self._autoreset):
                self._start(int(i), None, info)
        active = ~self._autoreset
        for i in np.flatnonzero(active):
            if self.eps[i] is None or self.eps[i].done:
                raise gym.error.ResetNeeded("call reset() before step()")
        if self.fast:
            self._step_compiled(U_, active)
        else:
            for i in np.flatnonzero(active):
                self.eps[i].act(U_[i])
                self._sync(int(i))
        self._P[active] = U_[active]
        self._observe()
        for i in np.flatnonzero(active):
            ep = self.eps[i]
            if ep.done:
                terminated[i], truncated[i] = ep.terminated, not ep.terminated
                _mark(info, "metrics", i, n, ep.metrics())
                _mark(info, "record", i, n, ep.rec)
        reward = self.setup.reward
        if isinstance(reward, Reward):
            rewards[active] = reward.batch(self._ET[active], U_[active], self.setup.layout.act_high)
        else:
            for i in np.flatnonzero(active):
                one = {"e": self._E[i].copy(), "r": self._R[i].copy(), "k": int(self._ks[i])}
                rewards[i] = float(reward(self._ET[i].copy(), U_[i].copy(), one))
        infos = self._infos() | info
        obs = self._obs.copy()
        done = terminated | truncated
        if self.mode == AutoresetMode.SAME_STEP and done.any():
            infos["final_obs"] = np.array([obs[i] if done[i] else None for i in range(n)], dtype=object)
            infos["_final_obs"] = done.copy()
            infos["final_info"], infos["_final_info"] = (
                {k: v for k, v in infos.items() if not k.startswith("final")},
                done,
            )
            new: dict = {}
            for i in np.flatnonzero(done):
                self._start(int(i), None, new)
            self._observe()
            obs = self._obs.copy()
            infos |= {k: v for k, v in self._infos().items()} | new
        else:
            self._autoreset = done
        return obs, rewards, terminated, truncated, infos

    def _step_compiled(self, U_: np.ndarray, active: np.ndarray) -> None:
        """One kernel call steps every active robot; Python then ends the episodes that ended, applies
        the events due, and draws the motion's noise at the torque level."""
        live = np.flatnonzero(active)
        for i in live:
            ep, p = self.eps[i], self.eps[i].loop.plant.plants[0]
            if p._args is not self._args[i]:  # an event replaced the robot's arrays
                self._row(int(i))
            if self._drawn[i] == len(self._draws[i]):  # the next draws, never past the next event
                self._draws[i] = p.draws(max(1, min(CHUNK, int(self._due[i]) - ep.k)))
                self._drawn[i] = 0
                _put(self._table[i], A.DRAWS_AT, self._draws[i])
        observe = (self._ks + 1 < self._steps) & (self._ks + 1 != self._due)
        K.watch_many(self._sts)
        A.across(self._ks, active, U_, observe, self._limit, self._table, self._drawn, K.STEPPING, self._codes,
               self._E, self._ET, self._R)  # fmt: skip
        K.watch(None)
        for i in live:
            ep, code, k = self.eps[i], int(self._codes[i]), int(self._ks[i])
            loop = ep.loop
            if code == A.BAD:  # the runner's test: the loop's own step stops it, saying why
                loop.command(k, U_[i : i + 1])
            else:
                loop.recs[0].n = k + 1
                p = loop.plant.plants[0]
                p.stepped()
                if code:
                    loop.stop(0, p.why(code), k, k + 1)
            if ep.sink is not None and (k + 1) % FLUSH_EVERY == 0:
                ep.sink.flush(ep.rec, k + 1)
            if code or not observe[i]:
                ep.advance(k + 1)
                self._sync(int(i))
            else:
                ep.k = k + 1
                self._ks[i] = k + 1
                if self.torque:
                    w = p.motion()
                    self._RD[i], self._PM[i], self._TW[i], self._WS[i] = (
                        loop.r_dot[k + 1],
                        loop.plant._m[0],
                        w[:2],
                        w[2:],
                    )

    # -- what the agent is given

    def _observe(self) -> None:
        lay = self.setup.layout
        extra = (self._RD, self._PM, self._TW, self._WS) if self.torque else None
        fill(self._obs, self._E, self._R, self._P, lay.low, lay.high, extra)

    def _infos(self) -> dict:
        T = self.setup.source.T
        out = {"k": self._ks.copy(), "t": self._ks * T, "e": self._E.copy(), "r": self._R.copy(),
               "e_true": self._ET.copy()}  # fmt: skip
        if self.torque:
            out |= {"r_dot": self._RD.copy(), "pose": self._PM.copy(), "twist": self._TW.copy(),
                    "wheel_speeds": self._WS.copy()}  # fmt: skip
        return out

    def close_extras(self, **kwargs) -> None:
        for ep in self.eps:
            if ep is not None:
                ep.finish()


def _due(ep: Episode) -> int:
    """The next step at which Python must step in before the episode's observation: its next event
    is applied there, or its reference stops being finite (the run's end otherwise)."""
    loop, T = ep.loop, ep.scn.T
    due = ep.N
    if loop.pending:
        t = loop.pending[0].time
        j = max(0, math.floor((t - 1e-9) / T))
        while j * T + 1e-9 < t:  # the step _apply_due applies it at: the first with t <= j T + 1e-9
            j += 1
        due = min(due, j)
    if loop.end is not None:
        due = min(due, loop.end[0])
    return max(due, ep.k + 1)


def _mark(info: dict, key: str, i: int, n: int, value, dtype=object) -> None:
    """``info[key][i] = value`` and its mask ``info["_" + key][i]``, as gymnasium's vector infos hold them."""
    if key not in info:
        info[key] = np.zeros(n, dtype=dtype) if dtype is not object else np.array([None] * n, dtype=object)
        info["_" + key] = np.zeros(n, dtype=np.bool_)
    info[key][i] = value
    info["_" + key][i] = True
