"""The parts of a differential-drive MJCF that the ``[plant]`` table does not name, found in the model.

:func:`resolve` fills in what is left unset: the two wheel servos (``left_actuator``,
``right_actuator``) and the pose frame (``site``, or ``body`` with ``frame_offset``). A wheel is a
hinge joint driven by exactly one actuator, a velocity servo (the drive the plant supports), whose
body has a sphere, cylinder or mesh collision geom and whose axis is within 30 degrees of level, as
low as the lowest such wheel (within half its radius: an arm's joint high up is not a wheel).
Left and right come from the geometry at the start pose (the keyframe's, else the model's default):
the two wheels' axes parallel and on one axle line, the left one on the +y side of the base frame's
forward (x) axis. The pose frame is a site named ``axle_mid`` when the model has one, else the free
body the wheels hang from, moved to the axle midpoint. Anything ambiguous is a :class:`ConfigError`
listing the candidates and naming the key that picks.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from dataclasses import dataclass

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.model import dot, matmul, norm
from mlpfac.plants.config import MujocoConfig
from mlpfac.plants.mjcf import edits

ROUND = (int(mujoco.mjtGeom.mjGEOM_SPHERE), int(mujoco.mjtGeom.mjGEOM_CYLINDER))  # wheel shapes: size[0] is the radius
WHEEL_SHAPES = (*ROUND, edits.MESH)
AXLE_SITE = "axle_mid"  # the pose site's name by this project's convention (models/diffdrive.xml)
LEVEL = 0.5  # a wheel's hinge axis has a vertical component below this (within 30 degrees of level)
LOW = 0.5  # a wheel's lowest point is within this many of its radii of the lowest wheel's (not an arm's joint)
PARALLEL = 0.999  # |cos| of the angle between the two wheels' axes (within 2.6 degrees)
ON_AXLE = 0.01  # the right wheel's anchor lies this close to the left one's axis line, times the track
PICK = "name the two drive wheels' servos with left_actuator and right_actuator"


@dataclass(frozen=True)
class Found:
    """The configuration with every part named, and which of its keys were read from the model."""

    config: MujocoConfig
    keys: tuple[str, ...]  # the [plant] keys that were unset and are now filled in


def is_velocity_servo(m: mujoco.MjModel, a: int) -> bool:
    """A ``<velocity kv=...>`` actuator: force = kv (ctrl - joint velocity)."""
    kv = m.actuator_gainprm[a, 0]
    return (
        int(m.actuator_gaintype[a]) == mujoco.mjtGain.mjGAIN_FIXED
        and int(m.actuator_biastype[a]) == mujoco.mjtBias.mjBIAS_AFFINE
        and kv > 0
        and m.actuator_biasprm[a, 0] == 0
        and m.actuator_biasprm[a, 1] == 0
        and m.actuator_biasprm[a, 2] == -kv
    )


def is_motor(m: mujoco.MjModel, a: int) -> bool:
    """A ``<motor>``: force = gain x control, no bias (a torque the plant's PI loop sets)."""
    return (
        int(m.actuator_gaintype[a]) == mujoco.mjtGain.mjGAIN_FIXED
        and int(m.actuator_biastype[a]) == mujoco.mjtBias.mjBIAS_NONE
        and m.actuator_gainprm[a, 0] > 0
    )


def collision_geoms(m: mujoco.MjModel, body: int) -> list[int]:
    return [g for g in range(m.ngeom) if m.geom_bodyid[g] == body and (m.geom_contype[g] or m.geom_conaffinity[g])]


def names(m: mujoco.MjModel, obj: mujoco.mjtObj, n: int) -> str:
    found = [mujoco.mj_id2name(m, obj, i) for i in range(n)]
    return "it has: " + ", ".join(repr(x) for x in found if x) if any(found) else "it has none with a name"


def resolve(config: MujocoConfig, m: mujoco.MjModel, qpos: np.ndarray) -> Found:
    """``config`` with the wheels and the pose frame it leaves unset found in the model ``m`` (as its
    files describe it) at the start pose ``qpos``. A name that is set is used as it is (and checked
    by the robot's reader, not here)."""
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    changes: dict = {}
    named = [k for k in ("left_actuator", "right_actuator") if getattr(config, k) is not None]
    if config.tendon_actuators is None and not named:
        found = _candidates(m, d)
        pair = find_tendon_pair(m, d) if not found else None
        if pair is not None:
            changes["tendon_actuators"] = (m.actuator(pair[0]).name, m.actuator(pair[1]).name)
            named = ["left_actuator", "right_actuator"]  # the wheels are the tendons' two joints
        elif len(found) == 4 and len({_root(m, a) for a in found}) == 1:
            changes |= _skid_steer(m, d, config, found)
            named = ["left_actuator", "right_actuator"]
    if config.tendon_actuators is None and len(named) < 2:
        found = _candidates(m, d)
        if len(named) == 1 and len(found) > 2 and getattr(config, named[0]) in {m.actuator(a).name for a in found}:
            # more than two wheel servos, one named: the other side must be named too
            missing = "right_actuator" if named[0] == "left_actuator" else "left_actuator"
            others = [a for a in found if m.actuator(a).name != getattr(config, named[0])]
            what = (
                f"{named[0]} = {getattr(config, named[0])!r} is named; the other wheel is one of {_listed(m, others)}"
            )
            raise ConfigError(missing, f"{what}: name it")
        left, right = _wheel_pair(m, d, config, found)
        changes |= {
            k: m.actuator(a).name
            for k, a in (("left_actuator", left), ("right_actuator", right))
            if getattr(config, k) is None
        }
    if config.actuator is None:
        first = changes.get("left_actuator") or config.left_actuator
        a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, first) if first else -1
        changes["actuator"] = "velocity" if a >= 0 and is_velocity_servo(m, a) else "torque"
    if config.site is None and config.body is None:
        changes |= _pose_frame(m, d, config, changes)
    return Found(dataclasses.replace(config, **changes), tuple(changes))


def describe(m: mujoco.MjModel, config: MujocoConfig, acts, joints) -> str:
    """The robot the plant drives, in one line: its wheels' joints and actuators and its pose frame."""
    joints = [m.joint(j).name or f"#{j}" for j in joints]
    kind, name = config.frame
    if config.tendon_actuators is not None:
        a, b = config.tendon_actuators
        text = f"left wheel joint {joints[0]}, right {joints[1]}, driven by tendon motors {a} and {b}"
    else:
        text = f"left wheel joint {joints[0]} (actuator {config.left_actuator}), right {joints[1]} ({config.right_actuator})"
    if config.left_actuator_2 or config.right_actuator_2:
        text += f", skid-steer with {config.left_actuator_2} and {config.right_actuator_2}"
    text += f", pose from {kind} {name}"
    if config.frame_offset is not None and any(config.frame_offset):
        text += " moved by ({:g}, {:g}, {:g}) m".format(*config.frame_offset)
    return text


def _candidates(m: mujoco.MjModel, d: mujoco.MjData) -> list[int]:
    """The actuators that may drive a wheel (the module's docstring says which)."""
    drivers = Counter(int(m.actuator_trnid[a, 0]) for a in range(m.nu) if _on_joint(m, a))
    low: dict[int, tuple[float, float]] = {}  # servo: its wheel's lowest point and radius
    for a in range(m.nu):
        j = int(m.actuator_trnid[a, 0])
        if not _on_joint(m, a) or int(m.jnt_type[j]) != mujoco.mjtJoint.mjJNT_HINGE or drivers[j] != 1:
            continue
        rims = [g for g in collision_geoms(m, int(m.jnt_bodyid[j])) if int(m.geom_type[g]) in WHEEL_SHAPES]
        if rims and (is_velocity_servo(m, a) or is_motor(m, a)) and abs(d.xaxis[j, 2]) < LEVEL:
            low[a] = min((float(d.geom_xpos[g, 2]) - _reach(m, g), _reach(m, g)) for g in rims)
    floor = min((z for z, _ in low.values()), default=0.0)
    return [a for a, (z, r) in low.items() if z <= floor + LOW * r]


def _reach(m: mujoco.MjModel, g: int) -> float:
    """How far a wheel geom reaches from its centre: a sphere's or cylinder's radius, a mesh's bound."""
    return float(m.geom_size[g, 0] if int(m.geom_type[g]) in ROUND else m.geom_rbound[g])


def _on_joint(m: mujoco.MjModel, a: int) -> bool:
    return int(m.actuator_trntype[a]) == mujoco.mjtTrn.mjTRN_JOINT


def _listed(m: mujoco.MjModel, acts: list[int]) -> str:
    return ", ".join(
        f"{m.actuator(a).name or f'#{a}'} (joint {m.joint(int(m.actuator_trnid[a, 0])).name})" for a in acts
    )


def _root(m: mujoco.MjModel, a: int) -> int:
    return int(m.body_rootid[m.jnt_bodyid[m.actuator_trnid[a, 0]]])


def _wheel_pair(m: mujoco.MjModel, d: mujoco.MjData, config: MujocoConfig, found: list[int]) -> tuple[int, int]:
    """The (left, right) wheel servos: the model's only two (``found``), on one axle, one on either side."""
    roots = sorted({_root(m, a) for a in found})
    if len(roots) > 1:
        bodies = "; ".join(
            f"body {m.body(r).name or f'#{r}'}: {_listed(m, [a for a in found if _root(m, a) == r])}" for r in roots
        )
        raise ConfigError("left_actuator", f"wheel servos on {len(roots)} free bodies ({bodies}): {PICK}")
    if len(found) > 2:
        raise ConfigError("left_actuator", f"{len(found)} wheel servos found ({_listed(m, found)}): {PICK}")
    if len(found) < 2:
        have = f"only {_listed(m, found)}" if found else "none"
        raise ConfigError(
            "left_actuator",
            f"two wheel servos needed, found {have} (a wheel: a hinge joint driven by one velocity servo or motor, its axis "
            f"level, its body's sphere, cylinder or mesh collision geom low; {names(m, mujoco.mjtObj.mjOBJ_ACTUATOR, m.nu)}): "
            f"{PICK}",
        )
    j = [int(m.actuator_trnid[a, 0]) for a in found]
    axis, apart = d.xaxis[j[0]], d.xanchor[j[1]] - d.xanchor[j[0]]
    off_line = norm(apart - dot(apart, axis) * axis)
    if abs(dot(axis, d.xaxis[j[1]])) < PARALLEL or off_line > ON_AXLE * norm(apart):
        raise ConfigError(
            "left_actuator",
            f"the wheel servos {_listed(m, found)} are not on one axle (axes parallel and on one line; "
            f"{off_line:.3g} m off it): {PICK}",
        )
    origin, R = base_frame(m, d, config, _root(m, found[0]))
    side = [dot(d.xanchor[i] - origin, R[:, 1]) for i in j]
    if side[0] * side[1] >= 0:
        raise ConfigError(
            "left_actuator",
            f"the wheel servos {_listed(m, found)} are not on either side of the base's forward (x) axis: "
            f"{PICK}, or name the pose frame (site or body)",
        )
    return (found[0], found[1]) if side[0] > 0 else (found[1], found[0])


def base_frame(m: mujoco.MjModel, d: mujoco.MjData, config: MujocoConfig, root: int) -> tuple[np.ndarray, np.ndarray]:
    """Origin and axes (columns) of the frame that says which side is left: the named pose frame,
    else the axle_mid site, else the free body."""
    kind, name = config.frame if config.site or config.body else ("site", AXLE_SITE)
    obj = mujoco.mjtObj.mjOBJ_SITE if kind == "site" else mujoco.mjtObj.mjOBJ_BODY
    i = mujoco.mj_name2id(m, obj, name)
    if i >= 0 and kind == "site":
        return d.site_xpos[i], d.site_xmat[i].reshape(3, 3)
    b = i if i > 0 else root
    return d.xpos[b], d.xmat[b].reshape(3, 3)


def tendon_joints(m: mujoco.MjModel, a: int) -> dict[int, float] | None:
    """{joint: coefficient} of the fixed tendon actuator ``a`` drives, None for another transmission."""
    if int(m.actuator_trntype[a]) != mujoco.mjtTrn.mjTRN_TENDON:
        return None
    t = int(m.actuator_trnid[a, 0])
    adr, n = int(m.tendon_adr[t]), int(m.tendon_num[t])
    if any(int(m.wrap_type[adr + i]) != mujoco.mjtWrap.mjWRAP_JOINT for i in range(n)):
        return None
    return {int(m.wrap_objid[adr + i]): float(m.wrap_prm[adr + i]) for i in range(n)}


def find_tendon_pair(m: mujoco.MjModel, d: mujoco.MjData) -> tuple[int, int] | None:
    """Two motors on fixed tendons over the same two level hinge joints whose bodies have a round or
    mesh collision geom (the wheels), their coefficients independent; None when there are not."""
    pairs: dict[tuple[int, int], list[int]] = {}
    for a in range(m.nu):
        coef = tendon_joints(m, a)
        if coef is None or len(coef) != 2 or not is_motor(m, a):
            continue
        joints = tuple(sorted(coef))
        if all(_is_wheel(m, d, j) for j in joints):
            pairs.setdefault(joints, []).append(a)
    for joints, acts in pairs.items():
        if len(acts) == 2:
            c = np.array([[tendon_joints(m, a)[j] for j in joints] for a in acts])
            if abs(c[0, 0] * c[1, 1] - c[0, 1] * c[1, 0]) > 1e-9 * np.abs(c).max() * np.abs(c).max():  # det, 2x2
                return acts[0], acts[1]
    return None


def _is_wheel(m: mujoco.MjModel, d: mujoco.MjData, j: int) -> bool:
    return (
        int(m.jnt_type[j]) == mujoco.mjtJoint.mjJNT_HINGE
        and abs(d.xaxis[j, 2]) < LEVEL
        and any(int(m.geom_type[g]) in WHEEL_SHAPES for g in collision_geoms(m, int(m.jnt_bodyid[j])))
    )


def tendon_wheels(m: mujoco.MjModel, pair: tuple[int, int]) -> tuple[int, int]:
    """The two wheel joints the tendon motors drive (in joint order; left and right come later)."""
    joints = sorted(tendon_joints(m, pair[0]) or {})
    return joints[0], joints[1]


def _skid_steer(m: mujoco.MjModel, d: mujoco.MjData, config: MujocoConfig, found: list[int]) -> dict:
    """Four wheel servos, two a side: the front pair the first wheels (the axle the pose is measured
    on), the rear pair each side's second, commanded as its first."""
    origin, R = base_frame(m, d, config, _root(m, found[0]))
    at = {a: matmul(R.T, (d.xanchor[int(m.actuator_trnid[a, 0])] - origin)[:, None])[:, 0] for a in found}
    left = sorted((a for a in found if at[a][1] > 0), key=lambda a: -at[a][0])
    right = sorted((a for a in found if at[a][1] < 0), key=lambda a: -at[a][0])
    if len(left) != 2 or len(right) != 2:
        raise ConfigError("left_actuator", f"4 wheel servos found ({_listed(m, found)}), not two a side: {PICK}")
    keys = ("left_actuator", "right_actuator", "left_actuator_2", "right_actuator_2")
    return {k: m.actuator(a).name for k, a in zip(keys, (left[0], right[0], left[1], right[1]), strict=True)}


def wheel_joints(m: mujoco.MjModel, config: MujocoConfig, changes: dict) -> list[int] | None:
    """The (left, right) wheel joints the configuration names (with ``changes``), None when a name is not there."""
    pair = changes.get("tendon_actuators") or config.tendon_actuators
    if pair is not None:
        acts = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name) for name in pair]
        if min(acts) < 0 or any(int(m.actuator_trntype[a]) != mujoco.mjtTrn.mjTRN_TENDON for a in acts):
            return None
        return list(tendon_wheels(m, (acts[0], acts[1])))
    named = (changes.get(k) or getattr(config, k) for k in ("left_actuator", "right_actuator"))
    acts = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name) for name in named]
    if min(acts) < 0 or any(not _on_joint(m, a) for a in acts):
        return None
    return [int(m.actuator_trnid[a, 0]) for a in acts]


def _pose_frame(m: mujoco.MjModel, d: mujoco.MjData, config: MujocoConfig, changes: dict) -> dict:
    """The axle_mid site if there is one, else the wheels' free body moved to the axle midpoint."""
    if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, AXLE_SITE) >= 0:
        return {"site": AXLE_SITE}
    joints = wheel_joints(m, config, changes)
    if joints is None:
        return {}  # a named servo that is not there: the robot's reader says so
    root = int(m.body_rootid[m.jnt_bodyid[joints[0]]])
    if not m.body(root).name:
        raise ConfigError("body", "the wheels' free body has no name: give it one in the model, or name a site (site)")
    seconds = (changes.get(k) or getattr(config, k) for k in ("left_actuator_2", "right_actuator_2"))
    for name in seconds:  # a skid-steer turns about the middle of its four wheels
        a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name) if name else -1
        if a >= 0 and _on_joint(m, a):
            joints.append(int(m.actuator_trnid[a, 0]))
    mid = sum(d.xanchor[j] for j in joints) / len(joints)
    offset = matmul(d.xmat[root].reshape(3, 3).T, (mid - d.xpos[root])[:, None])[:, 0]
    changes = {"body": m.body(root).name}
    if config.frame_offset is None:
        changes["frame_offset"] = tuple(round(float(x), 9) + 0.0 for x in offset)
    return changes
