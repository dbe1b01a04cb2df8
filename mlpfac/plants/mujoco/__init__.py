"""A MuJoCo robot as a plant: :mod:`~mlpfac.plants.mujoco.plant` (:class:`MujocoPlant`: built, reset,
stepped, read) and its parts: what an event does to it (:mod:`~mlpfac.plants.mujoco.events`), the
world built into its scene (:mod:`~mlpfac.plants.mujoco.world`) and what it holds there
(:mod:`~mlpfac.plants.mujoco.holds`), its torque-level drive (:mod:`~mlpfac.plants.mujoco.torque`),
what it says of itself (:mod:`~mlpfac.plants.mujoco.report`), its control step compiled
(:mod:`~mlpfac.plants.mujoco.compiled`), and the same step as a model-predictive controller's
prediction (:mod:`~mlpfac.plants.mujoco.predict`).

``from mlpfac.plants.mujoco import MujocoPlant`` imports the plant when it is asked for: importing
one part (the compiled step, say) does not import the whole plant.
"""

from __future__ import annotations


def __getattr__(name: str):
    if name == "MujocoPlant":
        from mlpfac.plants.mujoco.plant import MujocoPlant

        return MujocoPlant
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
