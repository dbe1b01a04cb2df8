"""What the robot senses of its own pose: the pose source's ``[plant]`` keys and what the MuJoCo plant
builds from them (:mod:`~mlpfac.plants.sensors.sensing`), and the robot's own estimate compiled into
its control step: wheel odometry, a gyro, an EKF of delayed fixes (:mod:`~mlpfac.plants.sensors.odometry`)."""
