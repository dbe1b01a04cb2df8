"""Train a tracking policy over randomized robots with stable-baselines3's PPO, on mlpfac's vector
environment, and write it as a policy file that mlpfac runs as a controller (no learning library
needed to run it). This is how policies/policy-dr.npz was made:

    pip install 'mlpfac[learn]'    # stable-baselines3 and torch (a CPU build does)
    nice python examples/policy/train_policy.py --out policies/policy-dr

The training ground is ``train-dr.toml`` beside this file: our robot on the figure of eight, its
wheel radius, payload, floor friction, control period and sensor delay each changed at a time drawn
per episode. The policy is residual: it commands the reference's (v_r, omega_r) plus a correction
(mlpfac/control/policy.py), from the errors (2), the reference's speeds and its last command, each
scaled by the robot's limits. Writes OUT.npz (the weights and scaling), OUT.json (the command,
seed, versions and the training curve) and OUT.png (the curve). Stops at --timesteps, when the
process has used --cpu-minutes of CPU, or at SIGTERM, whichever comes first, and writes what it learnt.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # a shared machine: one thread for torch and BLAS

import argparse  # noqa: E402
import json  # noqa: E402
import shlex  # noqa: E402
import signal  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import mlpfac  # noqa: E402
import mlpfac.envs  # noqa: E402, F401 (registers mlpfac/Track-v0)
from mlpfac.control.policy import N_IN, features, policy_file, save  # noqa: E402

HERE = Path(__file__).resolve().parent
OBS_SCALE = np.array([0.05, 0.05, 0.1, 0.01, 0.5, 0.2, 0.5, 0.2])  # e1, e2 (m), sin e3, 1 - cos e3, speeds / limits
OBS_CLIP = 5.0
ACT_SCALE = np.array([0.25, 0.5])  # the correction: at most a quarter of v_max, half of omega_max


def tracking_reward(e_true: np.ndarray, u: np.ndarray, info: dict) -> float:
    """In (0, 1] while on the path, sharpest near it (exp(-distance / 5 cm)), less the heading error's
    square: positive, so that ending an episode early (a divergence) costs what it would have earned.
    (The environment's default, the negative squared error, rewards ending a hopeless episode.)"""
    d = float(np.hypot(e_true[0], e_true[1]))
    return float(np.exp(-d / 0.05)) - 0.1 * float(e_true[2]) ** 2


def learning_env(venv, limits: np.ndarray):
    """The vector environment as stable-baselines3 steps it (its own VecEnv: same-step autoreset,
    the ended episode's observation in ``terminal_observation``), with the policy's inputs and its
    residual command (the environment's action is the command itself)."""
    from stable_baselines3.common.vec_env import VecEnv

    class Residual(VecEnv):
        def __init__(self) -> None:
            box = gym.spaces.Box(-OBS_CLIP, OBS_CLIP, (N_IN,), dtype=np.float32)
            super().__init__(venv.num_envs, box, gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32))
            self.episodes: list[dict] = []  # each ended episode: return, steps, its run's figures
            self._ret = np.zeros(venv.num_envs)
            self._len = np.zeros(venv.num_envs, dtype=int)

        def _x(self, obs: np.ndarray) -> np.ndarray:
            X = np.zeros((len(obs), N_IN))
            E, R, P = (np.ascontiguousarray(obs[:, a:b]) for a, b in ((0, 3), (6, 8), (8, 10)))
            features(E, R, P, limits[0], limits[1], OBS_SCALE, OBS_CLIP, X)
            return X.astype(np.float32)

        def reset(self):
            seed = self._seeds[0] if self._seeds and self._seeds[0] is not None else None
            self._obs, _ = venv.reset(seed=seed)
            self._reset_seeds()
            return self._x(self._obs)

        def step_async(self, actions) -> None:
            self._actions = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)

        def step_wait(self):
            u = self._obs[:, 6:8] + ACT_SCALE * self._actions * limits  # (v_r, omega_r) + correction
            obs, reward, term, trunc, info = venv.step(u)
            self._ret += reward
            self._len += 1
            done = term | trunc
            infos = [{} for _ in range(self.num_envs)]
            for i in np.flatnonzero(done):
                final = info["final_obs"][i][None]
                infos[i] = {"terminal_observation": self._x(final)[0], "TimeLimit.truncated": bool(trunc[i])}
                m = info["final_info"]["metrics"][i]
                self.episodes.append({"return": float(self._ret[i]), "steps": int(self._len[i]),
                                      "rms_position_error_m": m["rms_position_error_m"], "outcome": m["outcome"]})  # fmt: skip
                self._ret[i], self._len[i] = 0.0, 0
            self._obs = obs
            return self._x(obs), reward.astype(np.float32), done, infos

        def close(self) -> None:
            venv.close()

        def get_attr(self, attr_name, indices=None):
            return [getattr(venv, attr_name)] * self.num_envs

        def set_attr(self, attr_name, value, indices=None) -> None:
            pass

        def env_method(self, method_name, *args, indices=None, **kwargs):
            return [None] * self.num_envs

        def env_is_wrapped(self, wrapper_class, indices=None):
            return [False] * self.num_envs

    return Residual()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(HERE / "train-dr.toml"))
    ap.add_argument("--out", default="policy-dr", help="OUT.npz, OUT.json, OUT.png are written")
    ap.add_argument("--timesteps", type=int, default=4_000_000)
    ap.add_argument("--cpu-minutes", type=float, default=30.0)
    ap.add_argument("--envs", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback

    torch.set_num_threads(1)
    from gymnasium.vector import AutoresetMode

    venv = gym.make_vec("mlpfac/Track-v0", num_envs=args.envs, vectorization_mode="vector_entry_point",
                        scenario=args.scenario, autoreset_mode=AutoresetMode.SAME_STEP,
                        reward=tracking_reward)  # fmt: skip
    limits = venv.single_action_space.high.copy()  # (v_max, omega_max) of the scenario's robot
    env = learning_env(venv, limits)
    env.seed(args.seed)
    model = PPO("MlpPolicy", env, n_steps=256, batch_size=1024, n_epochs=10, learning_rate=3e-4, gamma=0.99,
                gae_lambda=0.95, clip_range=0.2, seed=args.seed, device="cpu", verbose=0,
                policy_kwargs={"net_arch": {"pi": [64, 64], "vf": [64, 64]}, "activation_fn": torch.nn.Tanh,
                               "log_std_init": -1.5})  # fmt: skip
    curve: list[dict] = []
    cpu0 = time.process_time()

    class Progress(BaseCallback):
        def _on_rollout_end(self) -> None:
            eps = env.episodes[-64:]
            if not eps:
                return
            rms = [e["rms_position_error_m"] for e in eps if e["rms_position_error_m"] is not None]
            row = {"timesteps": int(self.num_timesteps), "cpu_s": round(time.process_time() - cpu0, 1),
                   "episodes": len(env.episodes), "mean_return": float(np.mean([e["return"] for e in eps])),
                   "median_rms_position_error_m": float(np.median(rms)) if rms else None,
                   "tracking": sum(e["outcome"] == "tracking" for e in eps) / len(eps)}  # fmt: skip
            if not curve or row["timesteps"] - curve[-1]["timesteps"] >= 100_000:
                curve.append(row)
                print(json.dumps(row), flush=True)

        def _on_step(self) -> bool:
            return time.process_time() - cpu0 < 60.0 * args.cpu_minutes and not stopped

    stopped = False

    def stop(signum, frame) -> None:  # SIGTERM: end the training where it is, and write what it learnt
        nonlocal stopped
        stopped = True

    signal.signal(signal.SIGTERM, stop)
    model.learn(total_timesteps=args.timesteps, callback=Progress())
    cpu = time.process_time() - cpu0

    net, head = model.policy.mlp_extractor.policy_net, model.policy.action_net
    linears = [m for m in net if isinstance(m, torch.nn.Linear)] + [head]
    layers = [(m.weight.detach().double().numpy(), m.bias.detach().double().numpy()) for m in linears]
    command = "python " + shlex.join(sys.argv)
    out = Path(args.out)
    about = {
        "command": command,
        "seed": args.seed,
        "scenario": Path(args.scenario).name,
        "algorithm": "PPO (stable-baselines3), 64-64 tanh, residual on (v_r, omega_r)",
        "timesteps": int(model.num_timesteps),
        "cpu_s": round(cpu, 1),
        "stopped": "by SIGTERM"
        if stopped
        else "at --cpu-minutes"
        if cpu >= 60 * args.cpu_minutes
        else "at --timesteps",
        "versions": {
            "mlpfac": mlpfac.__version__,
            "stable_baselines3": __import__("stable_baselines3").__version__,
            "torch": torch.__version__,
            "gymnasium": gym.__version__,
        },  # fmt: skip
    }
    policy = save(out.with_suffix(".npz"), layers, OBS_SCALE, OBS_CLIP, ACT_SCALE, True, about=json.dumps(about))
    out.with_suffix(".json").write_text(json.dumps(about | {"curve": curve}, indent=1) + "\n")
    plot(curve, out.with_suffix(".png"))
    print(f"{policy.path}: {model.num_timesteps} timesteps in {cpu / 60:.1f} min of CPU")
    shipped = policy_file(out.name)  # a shipped policy's file is run by its name
    name = out.name if shipped.exists() and shipped.resolve() == out.with_suffix(".npz").resolve() else policy.path
    rec = mlpfac.run("eight-nominal", controller=name, seed=0)
    print("eight-nominal, seed 0:", mlpfac.metrics(rec)["phases"])
    return 0


def plot(curve: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [r["timesteps"] / 1e6 for r in curve]
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.2))
    a.plot(steps, [r["mean_return"] for r in curve])
    a.set(xlabel="timesteps (millions)", ylabel="mean return, last 64 episodes")
    b.plot(steps, [1e3 * (r["median_rms_position_error_m"] or np.nan) for r in curve])
    b.set(xlabel="timesteps (millions)", ylabel="median position RMS (mm)", yscale="log")
    fig.suptitle("policy-dr: PPO over randomized robots (train-dr.toml)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


if __name__ == "__main__":
    sys.exit(main())
