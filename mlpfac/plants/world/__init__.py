"""The world around the robot: a scenario's ``[world]`` as validated data (:mod:`~mlpfac.plants.world.table`),
laid out along a run's reference and drawn for its seed (:mod:`~mlpfac.plants.world.layout`), the
``force`` events' schedule (:mod:`~mlpfac.plants.world.forces`), and the world in the MuJoCo robot's
compiled step (:mod:`~mlpfac.plants.world.terrain`). The MuJoCo plant builds it into its scene
(:mod:`mlpfac.plants.mujoco.world`)."""
