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
from mlpfac.control.drive import drive_step, rated_step
from mlpfac.control.plugins import Plugin
from mlpfac.dynamics import RobotModel
from mlpfac.jit import as_rows

WHAT = "(tau_left, tau_right)"
_ARRAYS = ("e", "r", "r_dot", "pose", "twist", "wheel_speeds")


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

    def __eq__(self, other) -> bool:
        """Equal where every array is, element by element (the dataclass's own comparison of arrays fails)."""
        if not isinstance(other, Observation):
            return NotImplemented
        return self.t == other.t and all(np.array_equal(getattr(self, k), getattr(other, k)) for k in _ARRAYS)

    __hash__ = None  # type: ignore[assignment] - arrays: not hashable

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


class Drive:
    """What a wheel drive gives a torque-level law, for a law of one's own (the shipped ones step the
    same kernels, :mod:`mlpfac.control.drive`): ``drive = Drive(robot)`` once, then in ``step``

    - ``v_c, omega_c = drive.rated(v_c, omega_c)``: the velocity command scaled, both together, so
      that neither wheel passes the rated speed ``robot.wheel_speed_limit_rad_s`` (the IK's rule);
      ``drive.rated(v_c, omega_c, dv_c, domega_c)`` also returns the scaled command's rate;
    - ``tau = drive.torques(obs, tau)``: the torques cut where they would drive a wheel past its
      rated speed or spin (or lock) it beyond rolling against the ground the measured twist gives.

    One seed's values or a batch's (B,) / (B, 2) alike; the results are new arrays, as floats.
    Where nothing is cut the torques come back to the bit.
    """

    def __init__(self, robot: RobotModel) -> None:
        self.p = robot.packed()

    def rated(self, v, omega, dv=None, domega=None):
        one = np.ndim(v) == 0
        cmd = as_rows(np.stack(np.broadcast_arrays(v, omega), axis=-1), 2).copy()
        rate = np.zeros_like(cmd) if dv is None else as_rows(np.stack(np.broadcast_arrays(dv, domega), -1), 2).copy()
        rated_step(self.p, cmd, rate)
        out = [cmd[:, 0], cmd[:, 1]] + ([] if dv is None else [rate[:, 0], rate[:, 1]])
        return tuple(float(x[0]) for x in out) if one else tuple(out)

    def torques(self, obs, tau) -> np.ndarray:
        one = np.ndim(tau) == 1
        out = as_rows(tau, 2).copy()
        drive_step(self.p, as_rows(obs.twist, 2), as_rows(obs.wheel_speeds, 2), out)
        return out[0] if one else out


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
