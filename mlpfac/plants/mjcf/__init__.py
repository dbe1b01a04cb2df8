"""A MuJoCo robot read from its MJCF (the file :mod:`~mlpfac.plants.model_file` finds), once, before
anything steps it: its parts found (:mod:`~mlpfac.plants.mjcf.detect`, :mod:`~mlpfac.plants.mjcf.wheels`),
its drive beyond one servo a wheel (:mod:`~mlpfac.plants.mjcf.drive`), the keys a scenario leaves unset
chosen (:mod:`~mlpfac.plants.mjcf.defaults`), what the plant adds through ``MjSpec``
(:mod:`~mlpfac.plants.mjcf.edits`), the robot settled and a skid-steer's turning measured
(:mod:`~mlpfac.plants.mjcf.settle`), its shapes for the viewer (:mod:`~mlpfac.plants.mjcf.shapes`),
the whole read (:mod:`~mlpfac.plants.mjcf.robot`), and its dynamic model's parameters
(:mod:`~mlpfac.plants.mjcf.dynamics`)."""
