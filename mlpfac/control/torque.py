"""The torque-level contract: a controller that commands the wheels' torques, below the velocities
every other controller stops at (docs/controllers.md, "A controller of the torque level").

A class that says ``level = "torque"`` is built as ``Class(T=<control period in s>, robot=<RobotModel>,
**params)``: ``robot`` (:class:`mlpfac.dynamics.RobotModel`) holds the nominal dynamic parameters read
from the robot's model. Every control step it is given an :class:`Observation` and returns
``(tau_left, tau_right)`` in N m (forward positive), applied to the wheels' torque motors (clamped to
their limit) and held for the control period. ``reset``, ``telemetry``, ``name``, ``labels``, the
batch form and ``[controller.params]`` are as for a velocity-level controller
(:class:`mlpfac.control.baselines.Controller`). Only a MuJoCo robot with ``actuator = "torque"`` in
``[plant]`` runs one: any other is refused before anything runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mlpfac.control.baselines import PluginController
from mlpfac.control.plugins import Plugin
from mlpfac.dynamics import RobotModel

WHAT = "(tau_left, tau_right)"


@dataclass(frozen=True)
class Observation:
    """What a torque-level controller sees at step k (arrays (B, ...) in the batch form; ``r``, ``r_dot``
    and ``t`` are shared by the seeds). ``obs.e`` and ``obs["e"]`` are the same."""

    e: np.ndarray  # (3,) the tracking error (2) of the measured pose, in the robot's frame
    r: np.ndarray  # (5,) the reference sample (x_r, y_r, theta_r, v_r, omega_r)
    r_dot: np.ndarray  # (2,) (dv_r/dt, domega_r/dt): the reference's own where it gives them, else central differences
    pose: np.ndarray  # (3,) the measured pose (x, y, theta): noise and delay of the scenario's sensor
    twist: np.ndarray  # (2,) the base's (v, omega) as measured (same delay; [plant] twist_noise_std)
    wheel_speeds: np.ndarray  # (2,) (left, right) rad/s, forward positive, as the encoders measure them
    t: float  # s, the step's time k T

    def __getitem__(self, key: str):
        return getattr(self, key)

    def seed(self, b: int | slice) -> Observation:
        """Seed b's own observation, from a batch's (``slice(None)``: the whole batch's), every array a
        copy: what a controller writes into them is its own, never the runner's (its reference, errors,
        measurements) nor another seed's."""
        return Observation(
            self.e[b].copy(),
            self.r.copy(),
            self.r_dot.copy(),
            self.pose[b].copy(),
            self.twist[b].copy(),
            self.wheel_speeds[b].copy(),
            self.t,
        )


def reference_rates(ref: np.ndarray, T: float) -> np.ndarray:
    """(dv_r/dt, domega_r/dt) at each sample of ``ref`` (N, 5): central differences over the
    samples (one-sided at the ends), exact to O(T^2) on the smooth references. (A path and a
    reference class of the user's give their own: :func:`mlpfac.scenario.reference.sample_rates`.)"""
    out = np.zeros((len(ref), 2))
    if len(ref) > 2:
        out[1:-1] = (ref[2:, 3:5] - ref[:-2, 3:5]) / (2.0 * T)
    if len(ref) > 1:
        out[0] = (ref[1, 3:5] - ref[0, 3:5]) / T
        out[-1] = (ref[-1, 3:5] - ref[-2, 3:5]) / T
    return out


class TorquePluginController(PluginController):
    """A user's torque-level class stepped as the runner steps every controller: one instance per
    seed, or one in its batch form; ``step(obs)`` for B seeds returns (B, 2) wheel torques, a bad
    command ending its seed as diverged, the controller's own exception a PluginError."""

    level = "torque"

    def __init__(self, plugin: Plugin, T: float, robot: RobotModel, instance: object | None = None) -> None:
        super().__init__(plugin, T, instance)
        self.robot = robot

    def _new(self, cls: type):
        return cls(T=self.T, robot=self.robot, **self.plugin.params)

    def step(self, obs: Observation) -> np.ndarray:
        return self._commands(
            lambda: self._call("step", self.objs[0].step, obs.seed(slice(None) if self.whole_batch else 0)),
            lambda b: self._call("step", self.objs[b].step, obs.seed(b)),
            WHAT,
        )
