"""A MuJoCo robot under a torque-level controller (:mod:`mlpfac.control.torque`): the wheels' torques
in, the base's twist and the wheel speeds measured, its drive's torque limits, and its dynamic model
read from its MuJoCo model (the nominal one, and as the events changed it).
:class:`TorqueDrive` is the part of :class:`~mlpfac.plants.mujoco.plant.MujocoPlant` that does it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mlpfac.normal import standard_normal
from mlpfac.plants.mjcf import drive
from mlpfac.plants.mjcf.edits import torque_limit
from mlpfac.plants.mujoco import compiled as K  # noqa: N812 - the kernel's layout constants, K.F_DT ...


class TorqueDrive:
    """The torque level of the MuJoCo plant (its attributes are :class:`MujocoPlant`'s)."""

    def torque_commands(self) -> None:
        """From the next reset on, the command is the wheels' torques (tau_l, tau_r) in N m, applied
        to the torque motors (clamped to their limit) and held for the control period, and the plant
        measures the base's twist and the wheel speeds (:meth:`motion`). Only a torque drive takes it."""
        if self.config.actuator != "torque":
            raise ValueError("wheel torques are commanded to a torque drive only")
        self.ints[K.I_TAU] = 1

    def dynamics(self):
        """The nominal dynamic model of the robot (:class:`mlpfac.dynamics.RobotModel`), read from its
        nominal MuJoCo model at rest (:func:`mlpfac.plants.mjcf.dynamics.read_model`), with the wheels'
        rated speed (``max_wheel_speed``, which the IK keeps: the model's or ``[plant]``'s)."""
        from mlpfac.plants.mjcf.dynamics import read_model

        model = read_model(self.robot.model, self.robot, self._torque_limits_of(self.robot.model))
        return dataclasses.replace(model, wheel_speed_limit_rad_s=self._rated_speed())

    def true_dynamics(self):
        """The dynamic model of the robot as it is now (after events: its wheels' true radius, its
        masses, its drive's torque limit): what an oracle is told."""
        from mlpfac.plants.mjcf.dynamics import read_model

        model = read_model(self.model, self.robot, self._torque_max)
        return dataclasses.replace(
            model, wheel_radius_m=float(self.real_radius), wheel_speed_limit_rad_s=self._rated_speed()
        )

    def _rated_speed(self) -> float:
        return math.inf if self.max_wheel_speed is None else float(self.max_wheel_speed)

    def _torque_limits_of(self, m) -> tuple[float, float]:
        if self.robot.mix is not None:
            return drive.wheel_torque_limits(self.robot.mix, self.robot.umax)
        return tuple(
            torque_limit(m, a, c, self.config.actuator == "torque", bool(self.ints[K.I_CLAMP]))
            for a, c in zip(self._acts, self._act_per_wheel, strict=True)
        )

    def _measure_motion(self, v: float, omega: float, wl: float, wr: float) -> None:
        x = np.array([v, omega, wl, wr])
        std = self._motion_std
        if std is not None:
            x += std * standard_normal(self._motion_rng, 4)
        self._motion.push(x)

    def motion(self) -> np.ndarray:
        """(v, omega, wheel_l, wheel_r) as measured (noise and delay of the scenario's sensors): the
        base's twist at the pose frame (m/s, rad/s) and the encoders' wheel speeds (rad/s, forward positive)."""
        return self._motion.read()

    def _force_limits(self) -> tuple[float, float]:
        """Largest forward wheel torque of each drive (N m at the joint), inf when not limited."""
        if self.robot.mix is not None:
            return drive.wheel_torque_limits(self.robot.mix, self.fl[K.F_UMAX : K.F_UMAX + 2])
        torque, kept = self.config.actuator == "torque", bool(self.ints[K.I_CLAMP])
        tl, tr = (
            torque_limit(self.model, a, c, torque, kept) for a, c in zip(self._acts, self._act_per_wheel, strict=True)
        )
        return tl, tr
