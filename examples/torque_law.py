"""A controller of the wheels' torques as an mlpfac plug-in, written from the torque-level contract
alone (docs/controllers.md): copy this file and change ``step``.

Run it on a robot with torque motors (from the folder that holds this file):

    mlpfac run eight-torque --controller torque_law.py:TorqueLaw
    mlpfac run eight-wheel-radius --robot my_robot.xml --controller torque_law.py:TorqueLaw

The contract: a class that says ``level = "torque"``, built as ``Class(T=..., robot=..., **params)``;
``step(obs)`` returns (tau_left, tau_right) in N m. ``robot`` holds the nominal parameters read
from the robot's model (mass_kg, yaw_inertia_kg_m2, com_offset_m, wheel_radius_m, track_m,
wheel_inertia_kg_m2, torque_limit_Nm, wheel_speed_limit_rad_s, ...); ``obs`` holds e (3,), r (5,),
r_dot (2,), pose (3,), twist (2,), wheel_speeds (2,) and t. ``Drive`` gives the law what a wheel
drive gives the shipped ones: the wheels' rated speed kept, and no torque that spins a wheel.
"""

from __future__ import annotations

import numpy as np

from mlpfac.control.torque import Drive
from mlpfac.elementary import cos, sin  # the same bits on every machine (math's differ by C library)


class TorqueLaw:
    """A tracking law in two loops: the velocities (v_c, omega_c) the base should have, from the pose
    error; then the torques that give them, through the robot's mass and inertia (each wheel's
    rotor reflected to the base), ignoring the centre of mass's offset and the wheels' damping."""

    level = "torque"  # it commands the wheels' torques
    name = "torque-law"
    labels = {"velocity_cmd": ["v_c", "omega_c"]}

    def __init__(self, T: float, robot, k_x: float = 10.0, k_y: float = 150.0, k_theta: float = 16.0,
                 rate: float = 50.0) -> None:  # fmt: skip
        self.T, self.k = T, (k_x, k_y, k_theta)
        self.rate = min(rate, 0.5 / T)  # 1/s: how fast the twist is brought to (v_c, omega_c)
        r, b, iw = robot.wheel_radius_m, robot.track_m / 2, robot.wheel_inertia_kg_m2
        self.r, self.b = r, b
        self.mass = robot.mass_kg + 2 * iw / r**2  # kg: the base's mass and the wheels' rotors
        self.inertia = robot.yaw_inertia_kg_m2 + 2 * b * b * iw / r**2  # kg m^2
        self.limit = robot.torque_limit_Nm
        self.drive = Drive(robot)
        self.velocity_cmd = np.zeros(2)

    def reset(self, rng: np.random.Generator) -> None:
        self.velocity_cmd[:] = 0.0

    def step(self, obs) -> tuple[float, float]:
        e1, e2, e3 = obs.e
        v_r, w_r = obs.r[3], obs.r[4]
        v, w = obs.twist
        k_x, k_y, k_t = self.k
        v_c = v_r * cos(e3) + k_x * e1
        w_c = w_r + v_r * (k_y * e2 + k_t * sin(e3))
        v_c, w_c = self.drive.rated(v_c, w_c)  # neither wheel asked past its rated speed
        self.velocity_cmd[:] = v_c, w_c
        # the accelerations: the reference's, and the twist's error closed at `rate`
        a = obs.r_dot[0] + self.rate * (v_c - v)
        alpha = obs.r_dot[1] + self.rate * (w_c - w)
        force, moment = self.mass * a, self.inertia * alpha  # N along the heading, N m about the vertical
        tau_sum, tau_diff = force * self.r, moment * self.r / self.b  # tau_l + tau_r, tau_r - tau_l
        tau_l, tau_r = (tau_sum - tau_diff) / 2, (tau_sum + tau_diff) / 2
        tau = [min(max(t, -self.limit), self.limit) for t in (tau_l, tau_r)]
        return self.drive.torques(obs, tau)  # cut where it would spin a wheel or pass its rated speed

    def telemetry(self) -> dict[str, np.ndarray]:
        return {"velocity_cmd": self.velocity_cmd}
