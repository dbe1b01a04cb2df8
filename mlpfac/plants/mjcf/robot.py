"""A differential-drive robot as its MJCF model describes it: which actuators drive which wheels,
where the pose is measured, the wheel radius and track, the drive's limits and the rest pose.

:func:`read_robot` reads (and checks) all of it once from a :class:`MujocoConfig`: the model made
ready step by step (:mod:`mlpfac.plants.mjcf.prepare`: the parts the configuration leaves unset
found by :mod:`mlpfac.plants.mjcf.detect`, what the model does not say itself chosen by
:mod:`mlpfac.plants.mjcf.defaults` and made as :class:`mujoco.MjSpec` edits by
:mod:`mlpfac.plants.mjcf.edits`), then the robot settled on its wheels and measured there. The
stepping plant (:class:`mlpfac.plants.mujoco.plant.MujocoPlant`) drives the robot it describes. Nothing
here steps a run.
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.model import norm
from mlpfac.plants.config import MujocoConfig, check_timestep
from mlpfac.plants.mjcf import defaults, drive, edits, prepare, shapes
from mlpfac.plants.mjcf import wheels as wheel_parts
from mlpfac.plants.mjcf.detect import WHEEL_SHAPES, collision_geoms
from mlpfac.plants.mjcf.settle import cannot_simulate, settle

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
    site_rest: tuple[np.ndarray, np.ndarray]  # site position and orientation (xmat, row-major) at rest
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
    """The robot of ``config`` (:func:`read_robot`): its model made ready step by step
    (:mod:`mlpfac.plants.mjcf.prepare`: compiled, its drive found, its other joints locked, its
    wheels found, its tyres, rotors and motors made, its skids freed, its servos' limits), then the
    robot settled and measured. Where its wheel servos chatter (:func:`mlpfac.plants.mjcf.defaults.chatters`)
    with ``servo_limit`` unset, it is read again at a timestep that integrates them, else their
    force limits are kept through their control (``servo_limit = "control"``)."""
    r = prepare.compiled(config)
    prepare.find_drive(r, periods)
    prepare.lock_others(r)
    prepare.find_wheels(r)
    prepare.make_wheels(r)
    prepare.free_skids(r)
    prepare.limit_servos(r)
    robot = _settled(r)
    if r.config.actuator == "velocity" and config.servo_limit is None and defaults.chatters(robot):
        robot = _unchattered(r, robot, stamp, periods)
    return _pi_chosen(robot)


def _unchattered(r: prepare.Reading, robot: Robot, stamp: tuple[int, int], periods: tuple[float, ...]) -> Robot:
    """A robot whose wheel servos chatter: read again at the largest timestep that divides the periods
    and integrates them (down to 1/16 of the model's, where the configuration sets none), else with
    their force limits kept through their control (``servo_limit = "control"``), settled again."""
    dt = robot.dt
    step = defaults.smaller_timestep(defaults.servo_step(robot), periods or (dt,), r.spec_dt * defaults.SMALLEST_STEP)
    if step is not None and r.user.timestep is None:  # a timestep that integrates them, read again at it
        robot = _read_robot(dataclasses.replace(r.user, timestep=step, servo_limit="model"), stamp, periods)
        return dataclasses.replace(
            robot,
            config=dataclasses.replace(robot.config, servo_limit=None),
            found=(*(k for k in robot.found if k != "servo_limit"), "timestep"),
            description=f"{robot.description}; timestep {step:g} s (the wheel servos chatter at {dt:g} s)",
        )
    edits.unclamp(r.spec, r.m, r.servos)  # kept within their limits by their control: no longer chatter
    r.compile()
    r.choose({"servo_limit": "control"})
    r.suffix = f"; the wheel servos' force limit kept by their control (as MuJoCo clamps it they chatter at {dt:g} s)"
    return _settled(r)


def _settled(r: prepare.Reading) -> Robot:
    """The robot settled on its wheels from the start pose, measured there (its track, which way each
    wheel turns, the actuator units per wheel unit) and checked to drive as shipped."""
    m, config, joints, seconds = r.m, r.config, r.joints, r.seconds
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, edits.POSE_SITE if r.site is None else m.site(r.site).name)
    root = int(m.body_rootid[m.site_bodyid[site]])
    jnt = int(m.body_jntadr[root])
    if jnt < 0 or int(m.jnt_type[jnt]) != mujoco.mjtJoint.mjJNT_FREE:
        kind, name = config.frame
        raise ConfigError(
            kind, f"the body tree of {kind} {name!r} must hang from a <freejoint/> (a robot free to drive)"
        )
    wheel_bodies = tuple(int(m.jnt_bodyid[j]) for j in r.driven)
    tyres = tuple(g for b in wheel_bodies for g in collision_geoms(m, b) if int(m.geom_type[g]) in WHEEL_SHAPES)
    dt = float(m.opt.timestep)
    check_timestep(dt, "timestep", "the model's timestep ")
    try:
        d = mujoco.MjData(m)
        settle(m, d, dt, r.qpos0, r.ctrl0, int(m.jnt_dofadr[jnt]), r.where)
    except mujoco.FatalError as err:  # an arena too small for the model (<size memory>), say
        raise cannot_simulate(r.where, err) from None
    anchors = [d.xanchor[j].copy() for j in r.driven]
    track, turns = _track(config, anchors)
    sign = wheel_parts.wheel_signs(config, d, site, joints, anchors[:2])
    dofs = (int(m.jnt_dofadr[joints[0]]), int(m.jnt_dofadr[joints[1]]))
    if r.drv.tendon:
        c, inverse, umax = [1.0, 1.0], *drive.mix(m, d.qpos, r.acts, dofs, sign)
    else:
        c = [s * g for s, g in zip(sign, m.actuator_gear[list(r.acts), 0], strict=True)]
        inverse, umax = None, None
    c2 = [
        0.0 if a < 0 else float(s * m.actuator_gear[a, 0] * wheel_parts.same_way(m, d, a, j))
        for a, s, j in zip(seconds, sign, joints, strict=True)
    ]
    limit = [w / abs(ci) for w, ci in zip(r.wheel_speed, c, strict=True) if w is not None]
    robot = Robot(
        where=r.where, config=config, found=(*r.found, *r.chosen),
        description=r.description + turns + defaults.said(r.chosen, config) + r.suffix,
        sha256=r.sha256, spec=r.spec, model=m, dt=dt, acts=(r.acts[0], r.acts[1]), site=site, root=root,
        qroot=int(m.jnt_qposadr[jnt]), droot=int(m.jnt_dofadr[jnt]), dofs=dofs, wheel_bodies=wheel_bodies,
        tyres=tyres, qpos_rest=d.qpos.copy(), ctrl_rest=d.ctrl.copy(),
        site_rest=(d.site_xpos[site].copy(), d.site_xmat[site].copy()),
        real_radius=max(wheel_parts.radius(m, g, int(m.body_jntadr[m.geom_bodyid[g]])) for g in tyres),
        real_track=track, sign=sign, act_per_wheel=(float(c[0]), float(c[1])),
        geometry=shapes.static_geometry(m, d, site, root, r.visual_only),
        max_wheel_speed=min(limit) if limit else None, locked=tuple(r.locked), seconds=(seconds[0], seconds[1]),
        second_per_wheel=(c2[0], c2[1]), mix=inverse, umax=umax,
    )  # fmt: skip
    defaults.check_drive(m, d, robot, config, r.where)
    return robot


def _track(config: MujocoConfig, anchors: list[np.ndarray]) -> tuple[float, str]:
    """The track the robot turns as, from its wheels' anchors at rest, and what to say of it: the
    wheels' distance, or a skid-steer's (``turning_track``, else :func:`mlpfac.plants.mjcf.wheels.skid_track`)."""
    width = norm(anchors[1] - anchors[0])
    if len(anchors) <= 2:
        return width, ""
    rule, base = wheel_parts.skid_track(anchors)
    track = rule if config.turning_track is None else float(config.turning_track)
    turns = f"; turning as a track of {track:.3g} m ({width:.3g} m across, {base:.3g} m front to rear" + (
        ")" if config.turning_track is None else f"; W + L^2/W would be {rule:.3g} m)"
    )
    return track, turns


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
