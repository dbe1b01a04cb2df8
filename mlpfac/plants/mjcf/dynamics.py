"""The dynamic model's nominal parameters (:class:`mlpfac.dynamics.RobotModel`) read from a MuJoCo
robot at rest, as :func:`mlpfac.plants.mjcf.robot.read_robot` made it (its other joints locked where
``other_actuators = "lock"``): what a torque-level controller is told of the robot.

- ``mass_kg``: the robot's subtree mass (wheels included);
- ``yaw_inertia_kg_m2``: the subtree's inertia about the vertical through the axle midpoint (each
  body's own inertia about its centre of mass, turned into the world, plus m_i times its horizontal
  distance from the axle squared): the bodies as rigid as a locked joint holds them;
- ``com_offset_m``, ``com_lateral_m``: the subtree's centre of mass ahead of and left of the axle
  midpoint, in the pose frame;
- ``wheel_inertia_kg_m2``: a driven wheel's diagonal of MuJoCo's mass matrix (its subtree about its
  hinge, and the hinge's armature), the two wheels' mean; a skid-steer's second wheel on a side
  adds its own, reflected to the first;
- ``wheel_radius_m``, ``track_m``: the robot's own (the rolling radius and the track it turns with);
- ``torque_limit_Nm``: the smaller of the two drives' largest forward torques;
- ``wheel_damping_Nm_s``: the driven hinges' joint damping, the mean of the two.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mlpfac.dynamics import RobotModel
from mlpfac.elementary import hypot
from mlpfac.model import dot


def read_model(m: mujoco.MjModel, robot, torque_limits: tuple[float, float]) -> RobotModel:
    """The nominal model of ``robot`` (:class:`mlpfac.plants.mjcf.robot.Robot`) in its compiled model ``m``
    (the nominal one, or one an event changed), at its rest pose; ``torque_limits`` each drive's."""
    d = mujoco.MjData(m)
    d.qpos[:] = robot.qpos_rest
    mujoco.mj_forward(m, d)
    root, site = robot.root, robot.site
    axle = d.site_xpos[site]
    R = d.site_xmat[site].reshape(3, 3)
    heading = np.array([R[0, 0], R[1, 0]])
    heading /= hypot(*heading)
    left = np.array([-heading[1], heading[0]])
    bodies = [b for b in range(m.nbody) if _under(m, b, root)]
    mass = float(m.body_subtreemass[root])
    com = d.subtree_com[root][:2] - axle[:2]
    inertia = 0.0
    for b in bodies:
        rot = d.ximat[b].reshape(3, 3)
        izz = float(sum(rot[2, k] * rot[2, k] * m.body_inertia[b, k] for k in range(3)))  # e_z' R diag(I) R' e_z
        dx, dy = d.xipos[b, 0] - axle[0], d.xipos[b, 1] - axle[1]
        inertia += izz + float(m.body_mass[b]) * (dx * dx + dy * dy)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    wheel = [float(M[dof, dof]) for dof in robot.dofs]
    for i, a in enumerate(robot.seconds):  # a skid-steer's second wheel, turning with the first
        if a >= 0 and robot.act_per_wheel[i]:
            dof = int(m.jnt_dofadr[m.actuator_trnid[a, 0]])
            ratio = robot.second_per_wheel[i] / robot.act_per_wheel[i]
            wheel[i] += float(M[dof, dof]) * ratio * ratio
    damping = [float(m.dof_damping[dof]) for dof in robot.dofs]
    return RobotModel(
        mass_kg=mass,
        yaw_inertia_kg_m2=inertia,
        com_offset_m=dot(com, heading),
        wheel_radius_m=float(robot.real_radius),
        track_m=float(robot.real_track),
        wheel_inertia_kg_m2=0.5 * (wheel[0] + wheel[1]),
        torque_limit_Nm=float(min(torque_limits)),
        wheel_damping_Nm_s=0.5 * (damping[0] + damping[1]),
        com_lateral_m=dot(com, left),
    )


def _under(m: mujoco.MjModel, b: int, root: int) -> bool:
    """Whether body ``b`` hangs from ``root`` (is ``root`` or one of its descendants)."""
    while b > 0:
        if b == root:
            return True
        b = int(m.body_parentid[b])
    return False
