"""``mpc`` and ``limit``: model-predictive control with the run's own MuJoCo robot as the model.

The physical limit beside every result: a controller whose model is not a model of the robot but
the robot, the plant a run steps, built from the scenario as the run's is
(:class:`~mlpfac.plants.mujoco.predict.Predictor`: its compiled model, world, drive and force schedule),
told every event at its time as the oracles are (the model after the event: a new wheel, a new
control period, a slope, a load), and the reference ahead of it. It commands what the robot's
drive takes: (v, omega) through the IK to velocity servos, the wheels' torques to torque motors,
within their ranges.

**The plan** (a Gauss-Newton step a control step, as MuJoCo MPC's gradient-based planners take
one from the last plan): the commands over a horizon of H control steps are a linear spline of
``knots`` knots, the first one the command sent now. The cost is the tracking error (2) over the
horizon, sum_j e1_j^2 + e2_j^2 + (heading_m e3_j)^2 (heading_end_m at the last step: the plan ends
along the path), its residuals' Jacobian in the knots found by
forward differences of rollouts of the model (1 + 2 knots rollouts of H steps), and the knots
moved by the Levenberg-Marquardt step (J'J + mu diag(J'J)) delta = -J'r, kept within the drive's
limits and within a trust radius (``trust`` times the commands' scale). A step is kept only where
a rollout of the moved plan costs less (mu falls); else mu grows and the step is taken again, up
to ``iterations`` a control step, stopping once a step lowers the cost by less than
``tolerance`` of it or the plan's RMS residual is below ``settled_m``; a settled plan's Jacobian
(and the estimator's step Jacobian) serve again for up to ``reuse`` control steps. The plan is
then shifted one step to start the next.

**The state** ``mpc`` plans from is estimated from the pose the scenario's pose source gives, as
every controller gets it (truth with noise, odometry, fused): an extended Kalman filter on the
model's state (positions and velocities, in their tangent space) but for the chassis' height, roll
and pitch, which no pose sees and the model carries from the wheels' contacts (corrected through
the filter's linearization they lift the model's robot off its floor: PAL TIAGo's estimate did
within 1.4 s), whose prediction is the model's step and whose Jacobian is the step's own (forward
differences, as ``mjd_transitionFD`` takes them, through the whole control step), process noise
``accel_std`` on every velocity, the pose noise it is told as the measurement's, and a pose that
arrives late (a sensor delay it is told) fused at its own step and predicted forward again. On
torque motors the wheels' speeds (their encoders, with the scenario's wheel-speed noise) are
measured beside the pose; a wheel whose speed is ``slip_gate`` standard deviations from the
model's slips as the model's does not (stick and slip at the traction limit turn on a micrometre
of the state), and its speed's variance grows by the innovation's square: the encoder resets the
wheel, not the chassis (without it a 20° slope's estimate is lost). ``limit`` is the same planner
given the robot's true state each step: what perfect information and a perfect model achieve.

One thread, no BLAS, MuJoCo's own C functions from compiled kernels: the same bits on every
machine. A seed of a batch is planned on its own model (its rough ground, its forces' noise).
"""
