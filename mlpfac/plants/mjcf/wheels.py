"""The wheels of a robot's model: their radius, which way each rolls forward, their actuators and
their limits, the floor's contact priority (read once by :func:`mlpfac.plants.mjcf.robot.read_robot`)."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.model import dot, matmul, norm
from mlpfac.plants.config import MujocoConfig
from mlpfac.plants.mjcf import drive, edits
from mlpfac.plants.mjcf.detect import ROUND, base_frame, is_motor, is_velocity_servo, names


def radius(m: mujoco.MjModel, g: int, joint: int) -> float:
    """A wheel geom's radius: a sphere's or cylinder's size, a mesh's reach from the hinge axis."""
    return float(m.geom_size[g, 0]) if int(m.geom_type[g]) in ROUND else mesh_radius(m, g, joint)


def mesh_radius(m: mujoco.MjModel, geom: int, joint: int) -> float:
    """Largest distance of a mesh geom's vertices from its body's hinge axis: the wheel's radius."""
    mesh = int(m.geom_dataid[geom])
    verts = m.mesh_vert[m.mesh_vertadr[mesh] : m.mesh_vertadr[mesh] + m.mesh_vertnum[mesh]]
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, m.geom_quat[geom])
    p = matmul(verts, R.reshape(3, 3).T) + m.geom_pos[geom] - m.jnt_pos[joint]
    a = m.jnt_axis[joint] / norm(m.jnt_axis[joint])
    return float(np.sqrt(np.max(np.sum(p * p, axis=1) - matmul(p, a[:, None])[:, 0] ** 2)))


def skid_track(anchors: list[np.ndarray]) -> tuple[float, float]:
    """The rule for a skid-steer's turning track, and its wheelbase, from its wheels' hinge anchors
    (left, right, then each side's second): W + L^2 / W for wheels W apart across and L along (the
    plant measures the track instead, :func:`mlpfac.plants.mjcf.settle.turning`; the rule is said beside it).

    Turning, every wheel slides; where each one's friction is saturated (Coulomb's, the same on
    every wheel), the moments about the middle balance when the base turns at omega = u W/2 /
    ((W/2)^2 + (L/2)^2) for rim speeds +-u: a differential drive of that track (the instantaneous
    centres of rotation of skid-steer kinematics, with their expansion factor chi = 1 + (L/W)^2)."""
    width = norm(anchors[1] - anchors[0])
    base = [norm(anchors[i] - a) for i, a in zip((0, 1), anchors[2:], strict=False)]
    length = sum(base) / len(base)
    return width + length * length / width, length


def floor_priority(m: mujoco.MjModel, root: int) -> int:
    """The highest contact priority of the geoms that are not the robot's (the floor's)."""
    return max((int(m.geom_priority[g]) for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] != root), default=0)


def speed_limits(m: mujoco.MjModel, acts) -> list[float | None]:
    """Each velocity servo's control limit (actuator units; a wheel speed once divided by gear and
    sign); None for a motor (its control is a torque)."""
    return [
        float(min(-m.actuator_ctrlrange[a, 0], m.actuator_ctrlrange[a, 1]))
        if m.actuator_ctrllimited[a] and is_velocity_servo(m, a)
        else None
        for a in acts
    ]


def actuator_id(m: mujoco.MjModel, config: MujocoConfig, key: str, where: str) -> int:
    name = getattr(config, key)
    a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
    if a < 0:
        raise ConfigError(
            key, f"no actuator named {name!r} in {where} ({names(m, mujoco.mjtObj.mjOBJ_ACTUATOR, m.nu)})"
        )
    if (
        int(m.actuator_trntype[a]) != mujoco.mjtTrn.mjTRN_JOINT
        or int(m.jnt_type[m.actuator_trnid[a, 0]]) != mujoco.mjtJoint.mjJNT_HINGE
    ):
        raise ConfigError(key, f"actuator {name!r} must drive a hinge joint (the wheel)")
    if not is_velocity_servo(m, a) and not (config.actuator == "torque" and is_motor(m, a)):
        raise ConfigError(
            key,
            f"actuator {name!r} must be a velocity servo (<velocity kv=... forcerange=...>), or a motor with "
            'actuator = "torque"',
        )
    return a


def wheel_signs(
    config: MujocoConfig, d: mujoco.MjData, site: int, joints: list[int], anchors: list[np.ndarray]
) -> tuple[float, float]:
    R = d.site_xmat[site].reshape(3, 3)  # columns: site axes in the world
    signs = []
    for key, j, p, side in zip(("left_actuator", "right_actuator"), joints, anchors, (1.0, -1.0), strict=True):
        roll = dot(np.cross(d.xaxis[j], [0.0, 0.0, 1.0]), R[:, 0])  # forward speed per rad/s, / radius
        if abs(roll) < 0.5:
            raise ConfigError(key, "the wheel's hinge axis must be across the site's x axis (forward)")
        if side * dot(p - d.site_xpos[site], R[:, 1]) <= 0:
            raise ConfigError(
                key,
                f"this wheel is not on the {'left' if side > 0 else 'right'} of {' '.join(config.frame)} (y axis to the left)",
            )
        signs.append(1.0 if roll > 0 else -1.0)
    return signs[0], signs[1]


def same_way(m: mujoco.MjModel, d: mujoco.MjData, a: int, first: int) -> float:
    """+1 when the second wheel's hinge turns the same way as its side's first wheel's, else -1."""
    return 1.0 if dot(d.xaxis[int(m.actuator_trnid[a, 0])], d.xaxis[first]) > 0 else -1.0


def left_first(m: mujoco.MjModel, config: MujocoConfig, joints: list[int], qpos: np.ndarray) -> list[int]:
    """The tendon drive's two wheel joints, the left one (+y of the pose frame) first."""
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    origin, R = base_frame(m, d, config, int(m.body_rootid[m.jnt_bodyid[joints[0]]]))
    side = [dot(d.xanchor[j] - origin, R[:, 1]) for j in joints]
    return joints if side[0] > side[1] else joints[::-1]


def wheel_speed_limit(r) -> float | None:
    """The robot's wheel-speed limit (rad/s): its servos', else where its largest wheel torque meets
    its wheel joints' damping; None when the model sets neither."""
    if r.max_wheel_speed is not None:
        return float(r.max_wheel_speed)
    m = r.model
    damping = min(float(m.dof_damping[dof]) for dof in r.dofs)
    if r.mix is not None:
        torque = min(drive.wheel_torque_limits(r.mix, r.umax)) / 2  # both wheels at once
    else:
        torque = min(edits.torque_limit(m, a, c, True) for a, c in zip(r.acts, r.act_per_wheel, strict=True))
    return torque / damping if damping > 0 and math.isfinite(torque) else None


def wheel_accel_limit(r) -> float | None:
    """The fastest the wheels of robot ``r`` (a :class:`~mlpfac.plants.mjcf.robot.Robot`) speed up
    on their largest torque tau (rad/s^2), the smaller of driving straight and turning in place:
    2 tau / (m r^2 + 2 I_w) and tau / (2 I r^2 / b^2 + I_w) (mass m, yaw inertia I, each wheel's
    inertia I_w, radius r, track b: the nominal dynamic model, :mod:`mlpfac.plants.mjcf.dynamics`);
    None where nothing limits the torque."""
    from mlpfac.plants.mjcf.dynamics import read_model

    if r.mix is not None:
        limits = drive.wheel_torque_limits(r.mix, r.umax)
    else:
        torque, kept = r.config.actuator == "torque", r.config.servo_limit == "control"
        limits = tuple(
            edits.torque_limit(r.model, a, c, torque, kept and not torque)
            for a, c in zip(r.acts, r.act_per_wheel, strict=True)
        )
    model = read_model(r.model, r, limits)
    tau = model.torque_limit_Nm
    if not math.isfinite(tau) or tau <= 0:
        return None
    rr, b, Iw = model.wheel_radius_m, model.track_m, model.wheel_inertia_kg_m2
    straight = 2.0 * tau / (model.mass_kg * rr * rr + 2.0 * Iw)
    turning = tau / (2.0 * model.yaw_inertia_kg_m2 * rr * rr / (b * b) + Iw)
    return min(straight, turning)
