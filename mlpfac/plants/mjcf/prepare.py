"""A robot's MJCF model made ready for the plant, step by step (:func:`mlpfac.plants.mjcf.robot.read_robot`
runs them in this order, each on the :class:`Reading` the one before left):

1. :func:`compiled`: the model file compiled as it is, its fingerprint, its start pose (keyframe);
2. :func:`find_drive`: the parts the configuration leaves unset found (:mod:`~mlpfac.plants.mjcf.detect`),
   the drive's actuators and wheel joints, the other actuators' and the timestep's rules;
3. :func:`lock_others`: the joints the drive does not move fixed where the robot starts;
4. :func:`find_wheels`: the pose frame, each driven wheel's hinge and collision geoms, the floor's priority;
5. :func:`make_wheels`: the tyres and a skid-steer's rotors chosen (:mod:`~mlpfac.plants.mjcf.defaults`),
   then made (:mod:`~mlpfac.plants.mjcf.edits`) with the torque drive's motors;
6. :func:`free_skids`: floor contacts that are not wheels made frictionless;
7. :func:`limit_servos`: the servos' force limits kept by the plant (``servo_limit = "control"``).

The robot is then settled and measured (:mod:`mlpfac.plants.mjcf.robot`). Nothing here steps a run.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.model import matmul
from mlpfac.plants.config import MujocoConfig
from mlpfac.plants.mjcf import defaults, drive, edits
from mlpfac.plants.mjcf import wheels as wheel_parts
from mlpfac.plants.mjcf.detect import WHEEL_SHAPES, collision_geoms, describe, is_motor, names, resolve
from mlpfac.plants.mjcf.settle import SETTLE_S, cannot_simulate
from mlpfac.plants.model_file import fingerprint, is_menagerie, load_spec


@dataclass
class Reading:
    """A robot being read (:func:`_read_robot`): what its steps found, chose and made so far."""

    user: MujocoConfig  # the configuration as given
    config: MujocoConfig  # ... with what was found and chosen so far
    where: str  # the model file, for messages
    spec: mujoco.MjSpec  # the model, edited as the steps go
    m: mujoco.MjModel  # the spec as last compiled
    spec_dt: float  # the model file's timestep
    sha256: str
    qpos0: np.ndarray  # the start pose and controls (the keyframe's)
    ctrl0: np.ndarray
    chosen: dict = field(default_factory=dict)  # the keys the rules chose (mlpfac.plants.mjcf.defaults), in order
    found: tuple[str, ...] = ()  # the keys found in the model (mlpfac.plants.mjcf.detect)
    drv: drive.Drive | None = None
    acts: tuple[int, int] = (-1, -1)
    seconds: tuple[int, int] = (-1, -1)
    joints: list[int] = field(default_factory=list)  # the left and right wheels' hinges
    description: str = ""
    locked: list[str] = field(default_factory=list)
    site: int | None = None  # the pose site's id; None: added to the spec, found by its name once compiled
    pose_site: tuple | None = None  # where it is added: (body, position, orientation)
    driven: list[int] = field(default_factory=list)  # every driven wheel's hinge
    wheels: list[tuple[int, list[int]]] = field(default_factory=list)  # (hinge, its collision geoms)
    root: int = -1  # the robot's root body
    floor: int = 0  # the contact priority of what the robot stands on
    visual_only: bool = False  # the model draws with geoms that do not collide
    wheel_speed: list = field(default_factory=list)  # each wheel's speed limit, from its servo
    servos: list[int] = field(default_factory=list)  # the drive's velocity servos
    suffix: str = ""  # said at the description's end

    def choose(self, more: dict) -> None:
        """Keys the rules chose, set in the configuration."""
        self.config, self.chosen = defaults.with_chosen(self.config, more), self.chosen | more

    def compile(self) -> None:
        self.m = _compile(self.spec, self.where)


def compiled(config: MujocoConfig) -> Reading:
    """The model file compiled as it is, its fingerprint, and the start pose (its keyframe: ``home``
    where the configuration names none and the model has one)."""
    spec, path = load_spec(config.model)
    where = config.model if is_menagerie(config.model) else str(path)
    m = _compile(spec, where)
    chosen = defaults.keyframe(config, m)
    qpos0, ctrl0 = _keyframe(m, defaults.with_chosen(config, chosen), where)
    r = Reading(config, config, where, spec, m, float(m.opt.timestep), fingerprint(m), qpos0, ctrl0)
    r.choose(chosen)
    return r


def find_drive(r: Reading, periods: tuple[float, ...]) -> None:
    """The parts the configuration leaves unset, found (:mod:`mlpfac.plants.mjcf.detect`); the drive's
    actuators and wheel joints; the other actuators' and the timestep's rules."""
    m = r.m
    found = resolve(r.config, m, r.qpos0)
    r.config, r.found = found.config, found.keys
    r.drv = drv = drive.resolve_ids(m, r.config, r.where)
    if drv.tendon:
        r.acts = drv.acts
    else:
        r.acts = tuple(
            wheel_parts.actuator_id(m, r.config, key, r.where) for key in ("left_actuator", "right_actuator")
        )
        if r.acts[0] == r.acts[1]:
            raise ConfigError(
                "right_actuator", f"left and right wheels need two actuators, both are {r.config.left_actuator!r}"
            )
    r.seconds = drv.seconds
    r.joints = list(drv.joints) if drv.tendon else [int(m.actuator_trnid[a, 0]) for a in r.acts]
    if drv.tendon:
        r.joints = wheel_parts.left_first(m, r.config, r.joints, r.qpos0)
    drives = {*r.acts, *(a for a in r.seconds if a >= 0)}
    r.choose(defaults.others(r.config, m, drives) | defaults.timestep(r.config, float(m.opt.timestep), periods))
    r.description = describe(m, r.config, r.acts, r.joints)


def lock_others(r: Reading) -> None:
    """With ``other_actuators = "lock"``: every joint the drive does not move fixed at the start pose
    (:func:`mlpfac.plants.mjcf.edits.lock_other_joints`), the model compiled again and the drive's
    ids, the pose and the controls moved to it by name."""
    if r.config.other_actuators != "lock":
        return
    m_full, keep = r.m, [*r.acts, *(a for a in r.seconds if a >= 0)]
    keep_names, joint_names = [m_full.actuator(a).name for a in keep], [m_full.joint(j).name for j in r.joints]
    r.locked = edits.lock_other_joints(r.spec, m_full, r.qpos0, tuple(keep))
    r.compile()
    m = r.m
    r.qpos0 = _by_name(m_full, r.qpos0, m, "qpos", m.qpos0)
    r.ctrl0 = _by_name(m_full, r.ctrl0, m, "ctrl", np.zeros(m.nu))
    keep = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in keep_names]
    r.joints = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joint_names]
    r.acts = (keep[0], keep[1])
    r.seconds = (keep[2] if r.seconds[0] >= 0 else -1, keep[-1] if r.seconds[1] >= 0 else -1)


def find_wheels(r: Reading) -> None:
    """The pose frame (a site, or where one is added: on a body, or at an offset), every driven wheel's
    hinge and collision geoms (each side's first must have a wheel's shape), the robot's root and
    the contact priority of what it stands on."""
    m, config = r.m, r.config
    r.site, r.pose_site = _pose_frame(m, config, r.where)
    r.driven = [*r.joints, *(int(m.actuator_trnid[a, 0]) for a in r.seconds if a >= 0)]
    r.wheels = [(j, collision_geoms(m, int(m.jnt_bodyid[j]))) for j in r.driven]
    for key, (_, geoms) in zip(("left_actuator", "right_actuator"), r.wheels, strict=False):
        if not any(int(m.geom_type[g]) in WHEEL_SHAPES for g in geoms):
            raise ConfigError(
                key,
                f"the body moved by {getattr(config, key)!r} has no sphere, cylinder or mesh collision geom (the wheel)",
            )
    r.root = int(m.body_rootid[m.jnt_bodyid[r.joints[0]]])
    r.floor = wheel_parts.floor_priority(m, r.root)
    drawn = [g for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] == r.root]
    r.visual_only = any(m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0 for g in drawn)


def make_wheels(r: Reading) -> None:
    """The tyres and a skid-steer's rotors chosen (:mod:`mlpfac.plants.mjcf.defaults`), then made as
    edits with the rest the model does not say: the timestep, the pose site, sphere tyres, the
    rotors' inertia, the torque drive's motors; the model compiled again."""
    m, wheels = r.m, r.wheels
    rims = [g for _, geoms in wheels for g in geoms if int(m.geom_type[g]) in WHEEL_SHAPES]
    r.choose(defaults.tyre(r.config, m, rims, r.floor))
    if len(r.driven) > 2:  # a skid-steer
        rim = max(wheel_parts.radius(m, g, j) for j, geoms in wheels for g in geoms if g in rims)
        dofs = [int(m.jnt_dofadr[j]) for j in r.driven]
        r.choose(defaults.armature(r.config, m, dofs, m.body_subtreemass[r.root], rim))
    config = r.config
    r.wheel_speed = wheel_parts.speed_limits(m, r.acts) if not r.drv.tendon else [None, None]
    if config.timestep is not None:
        r.spec.option.timestep = float(config.timestep)
    if r.pose_site is not None:
        edits.add_pose_site(r.spec, *r.pose_site)
    if config.tyre == "sphere":
        radius = config.wheel_radius or max(wheel_parts.radius(m, g, j) for j, geoms in wheels for g in geoms)
        edits.sphere_tyres(r.spec, m, wheels, radius, r.floor + 1)
    if config.armature is not None:
        edits.set_armature(r.spec, r.driven, config.armature)
    if config.actuator == "torque":
        motors = [a for a in (*r.acts, *r.seconds) if a >= 0 and not is_motor(m, a)]
        edits.to_torque_motors(r.spec, m, motors)
    edited = config.tyre == "sphere" or config.actuator == "torque" or config.armature is not None
    if r.site is None or edited or config.timestep is not None:
        r.compile()


def free_skids(r: Reading) -> None:
    """Floor contacts at rest that are not the wheels and drag (skids for casters), made frictionless
    where ``casters`` is unset or says so; the model compiled again."""
    if r.config.casters == "model":
        return
    m = r.m
    bodies = {int(m.jnt_bodyid[j]) for j in r.driven}
    try:
        skids = defaults.skids(m, r.qpos0, r.ctrl0, SETTLE_S, r.root, bodies)
    except mujoco.FatalError as err:  # an arena too small for the model (<size memory>), say
        raise cannot_simulate(r.where, err) from None
    if skids and r.config.casters is None:
        r.choose({"casters": "frictionless"})
    if skids:
        defaults.frictionless(r.spec, skids, r.floor)
        r.compile()


def limit_servos(r: Reading) -> None:
    """With ``servo_limit = "control"``: the drive's velocity servos' force limits kept by the plant
    through their control, not by MuJoCo (:func:`mlpfac.plants.mjcf.edits.unclamp`)."""
    velocity = r.config.actuator == "velocity" and not r.drv.tendon
    r.servos = [a for a in (*r.acts, *r.seconds) if a >= 0 and velocity]
    if r.config.servo_limit == "control" and r.servos:
        edits.unclamp(r.spec, r.m, r.servos)
        r.compile()


def _compile(spec: mujoco.MjSpec, where: str) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as err:
        raise ConfigError(where, f"MuJoCo cannot load the model: {' '.join(str(err).split())}") from None


def _keyframe(m: mujoco.MjModel, config: MujocoConfig, where: str) -> tuple[np.ndarray, np.ndarray]:
    """The start pose and controls: the named keyframe's, or the model's default pose and zero."""
    if config.keyframe is None:
        return m.qpos0.copy(), np.zeros(m.nu)
    k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, config.keyframe)
    if k < 0:
        raise ConfigError(
            "keyframe",
            f"no keyframe named {config.keyframe!r} in {where} ({names(m, mujoco.mjtObj.mjOBJ_KEY, m.nkey)})",
        )
    return m.key_qpos[k].copy(), m.key_ctrl[k].copy()


def _pose_frame(m: mujoco.MjModel, config: MujocoConfig, where: str) -> tuple[int | None, tuple | None]:
    """The pose frame's site id, or None and where a site is to be added for it (body, position,
    orientation): on a body, or at an offset from a site."""
    kind, name = config.frame
    offset = np.asarray(config.offset, dtype=float)
    if kind == "body":
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        if b <= 0:
            raise ConfigError(
                "body", f"no body named {name!r} in {where} ({names(m, mujoco.mjtObj.mjOBJ_BODY, m.nbody)})"
            )
        return None, (b, offset, np.array([1.0, 0.0, 0.0, 0.0]))
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)
    if site < 0:
        raise ConfigError(
            "site",
            f"no site named {name!r} in {where} ({names(m, mujoco.mjtObj.mjOBJ_SITE, m.nsite)}); a body's frame can be named instead (body = ...)",
        )
    if not np.any(offset):
        return site, None
    return None, _offset_from_site(m, site, offset)


def _offset_from_site(m: mujoco.MjModel, site: int, offset) -> tuple[int, np.ndarray, np.ndarray]:
    """Body, position and orientation of a frame ``offset`` (in the site's axes) from ``site``."""
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, m.site_quat[site])
    return (
        int(m.site_bodyid[site]),
        m.site_pos[site] + matmul(R.reshape(3, 3), np.asarray(offset, float)[:, None])[:, 0],
        m.site_quat[site],
    )


def _by_name(m_from: mujoco.MjModel, values: np.ndarray, m_to: mujoco.MjModel, obj: str, default: np.ndarray):
    """Values per joint (obj = "qpos") or actuator ("ctrl") of one model moved to another by name."""
    out = default.copy()
    if obj == "ctrl":
        for a in range(m_to.nu):
            b = mujoco.mj_name2id(m_from, mujoco.mjtObj.mjOBJ_ACTUATOR, m_to.actuator(a).name)
            if m_to.actuator(a).name and b >= 0:
                out[a] = values[b]
        return out
    width = {0: 7, 1: 4, 2: 1, 3: 1}
    for j in range(m_to.njnt):
        name = m_to.joint(j).name
        i = mujoco.mj_name2id(m_from, mujoco.mjtObj.mjOBJ_JOINT, name) if name else -1
        if i >= 0:
            n = width[int(m_to.jnt_type[j])]
            out[m_to.jnt_qposadr[j] : m_to.jnt_qposadr[j] + n] = values[
                m_from.jnt_qposadr[i] : m_from.jnt_qposadr[i] + n
            ]
    return out
