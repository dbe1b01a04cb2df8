"""What the plant needs of a robot beyond its files, made as :class:`mujoco.MjSpec` edits (the files
are never changed): a pose frame on a body or at an offset from a site, round tyres on mesh
wheels, the robot's other actuated joints locked at their start pose, the wheel drive turned into
torque motors, the servos' force limits kept by the plant; and the drive's limits as the plant
reads them (:func:`torque_limit`, :func:`servo_band`).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from mlpfac.model import matmul

POSE_SITE = "mlpfac_pose"  # the site added where the pose is measured (a body, or a site with an offset)
TYRE = "mlpfac_tyre"  # the sphere tyres added to mesh wheels (tyre = "sphere")
MESH = int(mujoco.mjtGeom.mjGEOM_MESH)


def add_pose_site(spec: mujoco.MjSpec, body: int, pos: np.ndarray, quat: np.ndarray) -> None:
    """A site on ``body`` at ``pos``, ``quat`` (body frame): the frame where the pose is measured."""
    spec.bodies[body].add_site(name=POSE_SITE, pos=pos, quat=quat)


def lock_other_joints(spec: mujoco.MjSpec, m: mujoco.MjModel, qpos: np.ndarray, keep: tuple[int, ...]) -> list[str]:
    """Fix every joint moved by an actuator not in ``keep`` (through the joint, or a fixed tendon), or
    coupled to such a joint by an equality, and every joint of what hangs from them, at its pose in ``qpos``; remove those actuators, the
    tendons, equalities and sensors on what is fixed (and the keyframes, whose sizes no longer fit).
    The locked bodies become rigid parts of their parents (fused when the model compiles with
    ``fusestatic``). Returns the joints' names."""
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    acts = [a for a in range(m.nu) if a not in keep and int(m.actuator_trntype[a]) in (JOINT_TRN, TENDON_TRN)]
    joints = set()
    for a in acts:
        t = int(m.actuator_trnid[a, 0])
        joints |= {t} if int(m.actuator_trntype[a]) == JOINT_TRN else set(_tendon_joints(m, t))
    bodies = _coupled({int(m.jnt_bodyid[j]) for j in joints}, m)
    below = set(bodies)  # what hangs from a locked part (a fingertip, a camera) is fixed with it
    for b in range(1, m.nbody):  # parents come before their children
        if int(m.body_parentid[b]) in below:
            below.add(b)
    bodies |= {b for b in below if int(m.body_jntnum[b])}
    gone = {j for j in range(m.njnt) if int(m.jnt_bodyid[j]) in bodies}
    locked = []
    for b in sorted(bodies):
        p = int(m.body_parentid[b])
        Rp = d.xmat[p].reshape(3, 3)
        qp_inv, q = np.empty(4), np.empty(4)
        mujoco.mju_negQuat(qp_inv, d.xquat[p])
        mujoco.mju_mulQuat(q, qp_inv, d.xquat[b])
        body = spec.bodies[b]
        body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        body.pos, body.quat = matmul(Rp.T, (d.xpos[b] - d.xpos[p])[:, None])[:, 0], q
        for j in list(body.joints):
            locked.append(j.name or f"joint of body {b}")
    tendons = {t for t in range(m.ntendon) if gone & set(_tendon_joints(m, t))}
    eqs = [e for e in range(m.neq) if _eq_objects(m, e) & ({("j", j) for j in gone} | {("t", t) for t in tendons})]
    objs = {(int(mujoco.mjtObj.mjOBJ_JOINT), j) for j in gone} | {(int(mujoco.mjtObj.mjOBJ_TENDON), t) for t in tendons}
    objs |= {(int(mujoco.mjtObj.mjOBJ_ACTUATOR), a) for a in acts}
    sensors = [i for i in range(m.nsensor) if (int(m.sensor_objtype[i]), int(m.sensor_objid[i])) in objs]
    doomed = [spec.sensors[i] for i in sensors] + [spec.equalities[e] for e in eqs]
    doomed += [spec.actuators[a] for a in acts] + [spec.tendons[t] for t in sorted(tendons)]
    doomed += [j for b in sorted(bodies) for j in spec.bodies[b].joints]
    for item in doomed:
        spec.delete(item)
    for key in list(spec.keys):
        spec.delete(key)
    return locked


JOINT_TRN, TENDON_TRN = int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_TENDON)


def _tendon_joints(m: mujoco.MjModel, t: int) -> list[int]:
    adr, n = int(m.tendon_adr[t]), int(m.tendon_num[t])
    return [int(m.wrap_objid[adr + i]) for i in range(n) if int(m.wrap_type[adr + i]) == mujoco.mjtWrap.mjWRAP_JOINT]


def _eq_objects(m: mujoco.MjModel, e: int) -> set[tuple[str, int]]:
    kind = {int(mujoco.mjtEq.mjEQ_JOINT): "j", int(mujoco.mjtEq.mjEQ_TENDON): "t"}.get(int(m.eq_type[e]))
    return {(kind, int(m.eq_obj1id[e])), (kind, int(m.eq_obj2id[e]))} if kind else set()


def _coupled(bodies: set[int], m: mujoco.MjModel) -> set[int]:
    """``bodies`` and the bodies of every joint a joint equality couples to one of their joints."""
    while True:
        joints = {j for j in range(m.njnt) if int(m.jnt_bodyid[j]) in bodies}
        more = {
            int(m.jnt_bodyid[o])
            for e in range(m.neq)
            if int(m.eq_type[e]) == mujoco.mjtEq.mjEQ_JOINT
            for a, o in ((int(m.eq_obj1id[e]), int(m.eq_obj2id[e])), (int(m.eq_obj2id[e]), int(m.eq_obj1id[e])))
            if a in joints and o >= 0
        }
        if more <= bodies:
            return bodies
        bodies = bodies | more


def sphere_tyres(spec: mujoco.MjSpec, m: mujoco.MjModel, wheels, radius: float, priority: int) -> None:
    """On each wheel (joint, collision geoms): a sphere tyre of ``radius`` about the hinge's anchor,
    with the friction and contact bits of the wheel's own collision geom, which stops colliding."""
    own = [[spec.geoms[g] for g in geoms] for _, geoms in wheels]  # before any geom is added (ids move)
    for side, (joint, geoms) in zip(("left", "right", "left_2", "right_2"), wheels, strict=False):
        g0 = geoms[0]
        spec.bodies[int(m.jnt_bodyid[joint])].add_geom(
            name=f"{TYRE}_{side}",
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[radius, 0.0, 0.0],
            pos=m.jnt_pos[joint].copy(),
            friction=m.geom_friction[g0].copy(),
            condim=min(3, int(m.geom_condim[g0])) if len(wheels) > 2 else int(m.geom_condim[g0]),  # a skid-steer slides
            contype=int(m.geom_contype[g0]),
            conaffinity=int(m.geom_conaffinity[g0]),
            priority=priority,
            density=0.0,
            group=3,
        )
    for geom in (geom for wheel in own for geom in wheel):
        geom.contype, geom.conaffinity = 0, 0


def set_armature(spec: mujoco.MjSpec, joints: list[int], armature: float) -> None:
    """Rotor inertia ``armature`` (kg m^2) on each of the wheels' hinges."""
    for j in joints:
        spec.joints[j].armature = armature


def to_torque_motors(spec: mujoco.MjSpec, m: mujoco.MjModel, acts) -> None:
    """Turn the velocity servos into torque motors (force = ctrl) limited to the same force range
    (a servo's control range is a speed, not a torque: it is dropped)."""
    for a in acts:
        act = spec.actuators[a]
        act.gaintype, act.biastype = mujoco.mjtGain.mjGAIN_FIXED, mujoco.mjtBias.mjBIAS_NONE
        act.gainprm = [1.0] + [0.0] * 9
        act.biasprm = [0.0] * 10
        if m.actuator_forcelimited[a]:
            act.ctrllimited, act.ctrlrange = mujoco.mjtLimited.mjLIMITED_TRUE, m.actuator_forcerange[a].copy()
        else:
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE


def torque_limit(m: mujoco.MjModel, a: int, c: float, torque_drive: bool, kept: bool = False) -> float:
    """Largest forward wheel torque (N m at the joint) of drive ``a`` (``c`` actuator units per
    joint unit), wherever the model limits it: the actuator's force (or, for the torque drive, its
    control) range, and the joint's ``actuatorfrcrange``; inf when nothing limits it. ``kept``: the
    plant keeps the servo's limits (:func:`unclamp`): a range that is not zero limits."""
    limited = m.actuator_ctrllimited[a] if torque_drive else m.actuator_forcelimited[a] or kept
    lo, hi = m.actuator_ctrlrange[a] if torque_drive else m.actuator_forcerange[a]
    out = min(-lo, hi) * abs(c) if limited and (lo or hi) else math.inf
    j = int(m.actuator_trnid[a, 0])
    if m.jnt_actfrclimited[j] or (kept and np.any(m.jnt_actfrcrange[j])):
        out = min(out, float(min(-m.jnt_actfrcrange[j, 0], m.jnt_actfrcrange[j, 1])))
    return out


def unclamp(spec: mujoco.MjSpec, m: mujoco.MjModel, acts) -> None:
    """The velocity servos' force limits (theirs and their joints' ``actuatorfrcrange``) kept as ranges
    but no longer applied by MuJoCo (servo_limit = "control": the plant keeps them through the
    control); a range that did not limit is zeroed, so that a range that is not zero limits."""
    off = mujoco.mjtLimited.mjLIMITED_FALSE
    for a in acts:
        act, joint = spec.actuators[a], spec.joints[int(m.actuator_trnid[a, 0])]
        if not m.actuator_forcelimited[a]:
            act.forcerange = [0.0, 0.0]
        if not m.jnt_actfrclimited[int(m.actuator_trnid[a, 0])]:
            joint.actfrcrange = [0.0, 0.0]
        act.forcelimited, joint.actfrclimited = off, off


def servo_band(m: mujoco.MjModel, a: int) -> float:
    """How far servo ``a``'s control may stand from its actuator's speed with its force within its
    limits (:func:`unclamp`): the force limit (the actuator's and its joint's over the gear) / kv."""
    gear = abs(float(m.actuator_gear[a, 0]))
    return torque_limit(m, a, gear, False, kept=True) / gear / float(m.actuator_gainprm[a, 0])
