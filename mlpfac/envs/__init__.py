"""Gymnasium environments of the testbed (docs/envs.md): ``import mlpfac.envs`` registers
``mlpfac/Track-v0`` (or name it ``"mlpfac.envs:mlpfac/Track-v0"`` in ``gymnasium.make``, which
imports this module first).

    import gymnasium, mlpfac.envs

    env = gymnasium.make("mlpfac/Track-v0", scenario="eight-wheel-radius", level="velocity")
    envs = gymnasium.make_vec("mlpfac/Track-v0", num_envs=16, vectorization_mode="vector_entry_point")

- :mod:`~mlpfac.envs.track`: :class:`TrackEnv`, one robot; its arguments (``configure``)
- :mod:`~mlpfac.envs.vector`: :class:`TrackVectorEnv`, N robots stepped by one compiled call a step
- :mod:`~mlpfac.envs.episode`: one episode, the run ``mlpfac run`` makes, stepped from outside
- :mod:`~mlpfac.envs.spaces`: the observation's layout and bounds, the action's, the reward
- :mod:`~mlpfac.envs.randomize`: numbers of the scenario drawn per episode

A block of its own: it imports the loop, the scenario and the controllers; nothing imports it.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from mlpfac.envs.spaces import TORQUE, VELOCITY, Reward
from mlpfac.envs.track import TrackEnv

ID = "mlpfac/Track-v0"

__all__ = ["ID", "TORQUE", "VELOCITY", "Reward", "TrackEnv", "register_envs"]


def register_envs() -> None:
    """Register ``mlpfac/Track-v0`` with gymnasium (once)."""
    if ID not in registry:
        register(
            id=ID, entry_point="mlpfac.envs.track:TrackEnv", vector_entry_point="mlpfac.envs.vector:TrackVectorEnv"
        )


register_envs()
