"""A differential-drive robot as its MJCF model describes it: which actuators drive which wheels,
where the pose is measured, the wheel radius and track, the drive's limits and the rest pose.

:func:`read_robot` reads (and checks) all of it once from a :class:`MujocoConfig` (the parts it leaves
unset found first by :mod:`mlpfac.plants.mjcf.detect`), making what the
model does not say itself (a pose frame on a body, sphere tyres on mesh wheels, locked arms, a
timestep) as :class:`mujoco.MjSpec` edits (:mod:`mlpfac.plants.mjcf.edits`); the stepping plant
(:class:`mlpfac.plants.mujoco.MujocoPlant`) drives the robot it describes. Nothing here steps a run.
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.model import norm
from mlpfac.plants.compiled import yaw
from mlpfac.plants.config import MujocoConfig, check_timestep
from mlpfac.plants.mjcf import defaults, drive, edits, shapes
from mlpfac.plants.mjcf import wheels as wheel_parts
from mlpfac.plants.mjcf.detect import (
    WHEEL_SHAPES,
    collision_geoms,
    describe,
    is_motor,
    names,
    resolve,
)
from mlpfac.plants.mjcf.settle import SETTLE_S, cannot_simulate, settle
from mlpfac.plants.model_file import fingerprint, is_menagerie, load_spec

MAX_SUBSTEPS = 10_000  # physics steps in one control period, at most


@dataclass(frozen=True)
class Robot:
    """What the model says about the robot, read once by :func:`read_robot` (ids index the nominal model).

    ``spec`` and ``model`` are the nominal robot (the torque drive's motors already in place);
    ``qpos_rest`` is its pose settled on its wheels; ``sign`` turns a joint velocity into a forward
    wheel speed; ``act_per_wheel`` is actuator units per forward wheel unit (ctrl = c w_cmd for a
    servo, joint torque = c force for a motor).
    """

    where: str  # the model file, for messages
    config: MujocoConfig  # the configuration with every part named (mlpfac.plants.mjcf.detect found what was not)
    found: tuple[str, ...]  # the [plant] keys found in the model, not named by the configuration
    description: str  # the wheels' joints and servos and the pose frame, in one line
    sha256: str  # the file as compiled (before any change for the torque drive): model_fingerprint
    spec: mujoco.MjSpec
    model: mujoco.MjModel
    dt: float  # physics timestep
    acts: tuple[int, int]  # left, right actuator ids
    site: int
    root: int  # the robot's root body (the one with the free joint)
    qroot: int  # qpos address of the free joint
    droot: int  # dof address of the free joint
    dofs: tuple[int, int]  # wheel joints' dof addresses
    wheel_bodies: tuple[int, int]
    tyres: tuple[int, ...]  # the wheels' collision geoms (sphere, cylinder or mesh)
    qpos_rest: np.ndarray
    ctrl_rest: np.ndarray  # the controls at rest: the keyframe's (0 without one), the wheels' 0
    site_rest: tuple[np.ndarray, float]  # site position and heading at rest
    real_radius: float
    real_track: float
    sign: tuple[float, float]
    act_per_wheel: tuple[float, float]
    geometry: list[dict]  # visual shapes relative to the site frame
    max_wheel_speed: float | None  # the model's limit on the wheel speed (rad/s, a servo's ctrlrange), or None
    locked: tuple[str, ...] = ()  # joints fixed at the keyframe (other_actuators = "lock")
    seconds: tuple[int, int] = (-1, -1)  # each side's second wheel's actuator (skid-steer), -1: none
    second_per_wheel: tuple[float, float] = (0.0, 0.0)  # its actuator units per forward wheel unit
    mix: np.ndarray | None = None  # tendon drive: the two motors' controls per forward wheel torque (2, 2)
    umax: np.ndarray | None = None  # ... and their control limits (2,)

    def substeps(self, period: float, where: str) -> int:
        """Physics steps in ``period`` seconds; a ConfigError unless it is a whole number of them, at
        most MAX_SUBSTEPS (one control step is one compiled call, which no signal interrupts)."""
        n = period / self.dt
        if round(n) < 1 or abs(n - round(n)) > 1e-6 * n:
            raise ConfigError(
                where,
                f"{period:g} s is not a whole number of physics steps of {self.dt:g} s (the model's timestep; "
                "[plant] timestep can set another)",
            )
        if round(n) > MAX_SUBSTEPS:
            raise ConfigError(
                where,
                f"{period:g} s is {round(n)} physics steps of {self.dt:g} s; the limit is {MAX_SUBSTEPS} per control "
                "period: shorten the period or lengthen [plant] timestep",
            )
        return int(round(n))


_ROBOTS: dict[tuple, Robot] = {}  # (configuration, model file's stamp) -> its robot, newest last
CACHED = 8
_LOCK = threading.Lock()


def read_robot(config: MujocoConfig, periods: tuple[float, ...] = ()) -> Robot:
    """Load, check and describe the robot of ``config``; each problem a ConfigError naming its key.

    Read once per process for a configuration and model file (its size and time of change): the
    plants of a sweep share it and copy what they change (the spec; events compile new models).
    The configuration with the parts it found named (``Robot.config``, what a scenario's load
    writes into config.toml) is the same robot with nothing left to find: it is not read again.
    ``periods``: the control periods a run asks (T, and T x an event's factor): an unset timestep
    is chosen to divide them all."""
    st = config.path.stat()
    stamp = (st.st_mtime_ns, st.st_size)
    try:
        hash(config)
    except TypeError:  # made in Python with lists: not cached
        return _read_robot(config, stamp, periods)
    key = (config, stamp, periods)
    with _LOCK:  # a Dask worker may run several tasks in threads
        robot = _ROBOTS.pop(key, None)
    if robot is None:
        robot = _read_robot(config, stamp, periods)
    with _LOCK:
        _ROBOTS[key] = robot
        if robot.found and (robot.config, stamp, periods) not in _ROBOTS:
            _ROBOTS[robot.config, stamp, periods] = dataclasses.replace(robot, found=())
        while len(_ROBOTS) > CACHED:
            del _ROBOTS[next(iter(_ROBOTS))]
    return robot


def _read_robot(config: MujocoConfig, stamp: tuple[int, int], periods: tuple[float, ...] = ()) -> Robot:
    """The robot of ``config`` (:func:`read_robot`). Its wheel servos are tried, and where they chatter
    (:func:`mlpfac.plants.mjcf.defaults.chatters`) with ``servo_limit`` unset, their force limits are kept
    through their control instead (``servo_limit = "control"``, :func:`mlpfac.plants.mjcf.edits.unclamp`):
    the model compiled again, the robot settled again (the same robot as read with that key set)."""
    user, probe = config, True
    spec, path = load_spec(config.model)
    where = config.model if is_menagerie(config.model) else str(path)
    m = _compile(spec, where)
    spec_dt = float(m.opt.timestep)
    sha256 = fingerprint(m)
    chosen = defaults.keyframe(config, m)
    config = defaults.with_chosen(config, chosen)
    qpos0, ctrl0 = _keyframe(m, config, where)
    found = resolve(config, m, qpos0)
    config = found.config
    drv = drive.resolve_ids(m, config, where)
    if drv.tendon:
        acts = drv.acts
    else:
        acts = (
            wheel_parts.actuator_id(m, config, "left_actuator", where),
            wheel_parts.actuator_id(m, config, "right_actuator", where),
        )
        if acts[0] == acts[1]:
            raise ConfigError(
                "right_actuator", f"left and right wheels need two actuators, both are {config.left_actuator!r}"
            )
    keep = [*acts, *(a for a in drv.seconds if a >= 0)]
    joints = list(drv.joints) if drv.tendon else [int(m.actuator_trnid[a, 0]) for a in acts]
    if drv.tendon:
        joints = wheel_parts.left_first(m, config, joints, qpos0)
    more = defaults.others(config, m, set(keep)) | defaults.timestep(config, float(m.opt.timestep), periods)
    config = defaults.with_chosen(config, more)
    chosen |= more
    description = describe(m, config, acts, joints)
    keep_names = [m.actuator(a).name for a in keep]
    joint_names = [m.joint(j).name for j in joints]
    locked: list[str] = []
    if config.other_actuators == "lock":
        m_full = m
        locked = edits.lock_other_joints(spec, m, qpos0, tuple(keep))
        m = _compile(spec, where)
        qpos0 = edits.by_name(m_full, qpos0, m, "qpos", m.qpos0)
        ctrl0 = edits.by_name(m_full, ctrl0, m, "ctrl", np.zeros(m.nu))
        keep = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in keep_names]
        joints = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joint_names]
        acts = (keep[0], keep[1])
    seconds = [keep[2] if drv.seconds[0] >= 0 else -1]
    seconds.append(keep[-1] if drv.seconds[1] >= 0 else -1)
    if config.timestep is not None:
        spec.option.timestep = float(config.timestep)
    site = _pose_frame(spec, m, config, where)
    driven = [*joints, *(int(m.actuator_trnid[a, 0]) for a in seconds if a >= 0)]
    wheels = [(j, collision_geoms(m, int(m.jnt_bodyid[j]))) for j in driven]
    for key, (_, geoms) in zip(("left_actuator", "right_actuator"), wheels, strict=False):
        if not any(int(m.geom_type[g]) in WHEEL_SHAPES for g in geoms):
            raise ConfigError(
                key,
                f"the body moved by {getattr(config, key)!r} has no sphere, cylinder or mesh collision geom (the wheel)",
            )
    root0 = int(m.body_rootid[m.jnt_bodyid[joints[0]]])
    floor = wheel_parts.floor_priority(m, root0)
    rims = [g for _, geoms in wheels for g in geoms if int(m.geom_type[g]) in WHEEL_SHAPES]
    more = defaults.tyre(config, m, rims, floor)
    config, chosen = defaults.with_chosen(config, more), chosen | more
    drawn = [g for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] == root0]
    visual_only = any(m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0 for g in drawn)
    if config.tyre == "sphere":
        radius = config.wheel_radius or max(wheel_parts.radius(m, g, j) for j, geoms in wheels for g in geoms)
        edits.sphere_tyres(spec, m, wheels, radius, floor + 1)
    if len(driven) > 2:  # a skid-steer
        radius = max(wheel_parts.radius(m, g, j) for j, geoms in wheels for g in geoms if g in rims)
        more = defaults.armature(config, m, [int(m.jnt_dofadr[j]) for j in driven], m.body_subtreemass[root0], radius)
        config, chosen = defaults.with_chosen(config, more), chosen | more
    if config.armature is not None:
        edits.set_armature(spec, driven, config.armature)
    wheel_speed = wheel_parts.speed_limits(m, acts) if not drv.tendon else [None, None]
    if config.actuator == "torque":
        edits.to_torque_motors(spec, m, [a for a in (*acts, *seconds) if a >= 0 and not is_motor(m, a)])
    edited = config.tyre == "sphere" or config.actuator == "torque" or config.armature is not None
    if site is None or edited or config.timestep is not None:
        m = _compile(spec, where)
    if config.casters != "model":  # floor contacts at rest that are not the wheels and drag: they slide
        bodies = {int(m.jnt_bodyid[j]) for j in driven}
        try:
            skids = defaults.skids(m, qpos0, ctrl0, SETTLE_S, root0, bodies)
        except mujoco.FatalError as err:  # an arena too small for the model (<size memory>), say
            raise cannot_simulate(where, err) from None
        if skids and config.casters is None:
            config, chosen = (
                defaults.with_chosen(config, {"casters": "frictionless"}),
                chosen | {"casters": "frictionless"},
            )
        if skids:
            defaults.frictionless(spec, skids, floor)
            m = _compile(spec, where)
    servos = [a for a in (*acts, *seconds) if a >= 0 and config.actuator == "velocity" and not drv.tendon]
    if config.servo_limit == "control" and servos:
        edits.unclamp(spec, m, servos)
        m = _compile(spec, where)
    site0, suffix = site, ""
    while True:  # once, or twice: again with servo_limit = "control" where the servos chatter
        site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, edits.POSE_SITE if site0 is None else m.site(site0).name)
        root = int(m.body_rootid[m.site_bodyid[site]])
        jnt = int(m.body_jntadr[root])
        if jnt < 0 or int(m.jnt_type[jnt]) != mujoco.mjtJoint.mjJNT_FREE:
            kind, name = config.frame
            raise ConfigError(
                kind, f"the body tree of {kind} {name!r} must hang from a <freejoint/> (a robot free to drive)"
            )
        wheel_bodies = tuple(int(m.jnt_bodyid[j]) for j in driven)
        tyres = tuple(g for b in wheel_bodies for g in collision_geoms(m, b) if int(m.geom_type[g]) in WHEEL_SHAPES)
        dt = float(m.opt.timestep)
        check_timestep(dt, "timestep", "the model's timestep ")
        try:
            d = mujoco.MjData(m)
            settle(m, d, dt, qpos0, ctrl0, int(m.jnt_dofadr[jnt]), where)
        except mujoco.FatalError as err:  # an arena too small for the model (<size memory>), say
            raise cannot_simulate(where, err) from None
        anchors = [d.xanchor[j].copy() for j in driven]
        width = norm(anchors[1] - anchors[0])
        track, turns = width, ""
        if len(driven) > 2:  # a skid-steer: the track it turns as (turning_track, else wheel_parts.skid_track)
            rule, base = wheel_parts.skid_track(anchors)
            track = rule if config.turning_track is None else float(config.turning_track)
            turns = f"; turning as a track of {track:.3g} m ({width:.3g} m across, {base:.3g} m front to rear" + (
                ")" if config.turning_track is None else f"; W + L^2/W would be {rule:.3g} m)"
            )
        sign = wheel_parts.wheel_signs(config, d, site, joints, anchors[:2])
        dofs = (int(m.jnt_dofadr[joints[0]]), int(m.jnt_dofadr[joints[1]]))
        if drv.tendon:
            c, inverse, umax = [1.0, 1.0], *drive.mix(m, d.qpos, acts, dofs, sign)
        else:
            c = [s * g for s, g in zip(sign, m.actuator_gear[list(acts), 0], strict=True)]
            inverse, umax = None, None
        c2 = [
            0.0 if a < 0 else float(s * m.actuator_gear[a, 0] * wheel_parts.same_way(m, d, a, j))
            for a, s, j in zip(seconds, sign, joints, strict=True)
        ]
        limit = [w / abs(ci) for w, ci in zip(wheel_speed, c, strict=True) if w is not None]
        robot = Robot(
            where=where,
            config=config,
            found=(*found.keys, *chosen),
            description=description + turns + defaults.said(chosen, config) + suffix,
            sha256=sha256,
            spec=spec,
            model=m,
            dt=dt,
            acts=(acts[0], acts[1]),
            site=site,
            root=root,
            qroot=int(m.jnt_qposadr[jnt]),
            droot=int(m.jnt_dofadr[jnt]),
            dofs=dofs,
            wheel_bodies=wheel_bodies,
            tyres=tyres,
            qpos_rest=d.qpos.copy(),
            ctrl_rest=d.ctrl.copy(),
            site_rest=(d.site_xpos[site].copy(), yaw(d.site_xmat[site])),
            real_radius=max(wheel_parts.radius(m, g, int(m.body_jntadr[m.geom_bodyid[g]])) for g in tyres),
            real_track=track,
            sign=sign,
            act_per_wheel=(float(c[0]), float(c[1])),
            geometry=shapes.static_geometry(m, d, site, root, visual_only),
            max_wheel_speed=min(limit) if limit else None,
            locked=tuple(locked),
            seconds=(seconds[0], seconds[1]),
            second_per_wheel=(c2[0], c2[1]),
            mix=inverse,
            umax=umax,
        )
        defaults.check_drive(m, d, robot, config, where)
        chatter = probe and config.actuator == "velocity" and user.servo_limit is None and defaults.chatters(robot)
        if not chatter:
            return _pi_chosen(robot)
        floor = spec_dt * defaults.SMALLEST_STEP
        step = defaults.smaller_timestep(defaults.servo_step(robot), periods or (dt,), floor)
        if step is not None and user.timestep is None:  # a timestep that integrates them, read again at it
            robot = _read_robot(dataclasses.replace(user, timestep=step, servo_limit="model"), stamp, periods)
            return dataclasses.replace(
                robot,
                config=dataclasses.replace(robot.config, servo_limit=None),
                found=(*(k for k in robot.found if k != "servo_limit"), "timestep"),
                description=f"{robot.description}; timestep {step:g} s (the wheel servos chatter at {dt:g} s)",
            )
        edits.unclamp(spec, m, servos)  # kept within their limits by their control: no longer chatter
        m = _compile(spec, where)
        config, chosen, probe = defaults.with_chosen(config, {"servo_limit": "control"}), chosen, False
        chosen |= {"servo_limit": "control"}
        suffix = f"; the wheel servos' force limit kept by their control (as MuJoCo clamps it they chatter at {dt:g} s)"


def _pi_chosen(robot: Robot) -> Robot:
    """The robot with its torque drive's unset PI gains chosen for its inertia (:func:`mlpfac.plants.mjcf.defaults.pi_gains`)."""
    from mlpfac.plants.mjcf.dynamics import read_model

    if robot.config.actuator != "torque" or None not in (robot.config.pi_kp, robot.config.pi_ki):
        return robot
    model = read_model(robot.model, robot, (1.0, 1.0))
    chosen = defaults.pi_gains(robot.config, model.mass_kg, model.wheel_radius_m, model.wheel_inertia_kg_m2)
    config = defaults.with_chosen(robot.config, chosen)
    said = defaults.said(chosen, config)
    text = robot.description + (said if "; chosen:" not in robot.description else said.replace("; chosen:", ","))
    return dataclasses.replace(robot, config=config, found=(*robot.found, *chosen), description=text)


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


def _pose_frame(spec: mujoco.MjSpec, m: mujoco.MjModel, config: MujocoConfig, where: str) -> int | None:
    """The pose frame's site id, or None when a site is added for it (a body, or an offset)."""
    kind, name = config.frame
    offset = np.asarray(config.offset, dtype=float)
    if kind == "body":
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        if b <= 0:
            raise ConfigError(
                "body", f"no body named {name!r} in {where} ({names(m, mujoco.mjtObj.mjOBJ_BODY, m.nbody)})"
            )
        edits.add_pose_site(spec, b, offset, np.array([1.0, 0.0, 0.0, 0.0]))
        return None
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)
    if site < 0:
        raise ConfigError(
            "site",
            f"no site named {name!r} in {where} ({names(m, mujoco.mjtObj.mjOBJ_SITE, m.nsite)}); a body's frame can be named instead (body = ...)",
        )
    if not np.any(offset):
        return site
    edits.add_pose_site(spec, *edits.offset_from_site(m, site, offset))
    return None
