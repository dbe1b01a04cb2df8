"""A differential-drive robot as its MJCF model describes it: which actuators drive which wheels,
where the pose is measured, the wheel radius and track, the drive's limits and the rest pose.

:func:`read_robot` reads (and checks) all of it once from a :class:`MujocoConfig`; the stepping plant
(:class:`mlpfac.plants.mujoco.MujocoPlant`) drives the robot it describes. Nothing here steps a run.
"""

from __future__ import annotations

import hashlib
import importlib.resources
import math
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError

SETTLE_S = 0.5  # seconds the robot settles on its wheels at construction (the rest pose)
SHAPES = {
    int(mujoco.mjtGeom.mjGEOM_BOX): "box",
    int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
    int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
}
SIZE_LEN = {"box": 3, "cylinder": 2, "sphere": 1}
ROUND = (int(mujoco.mjtGeom.mjGEOM_SPHERE), int(mujoco.mjtGeom.mjGEOM_CYLINDER))  # wheel shapes: size[0] is the radius


def _positive(name: str, value, optional: bool = False) -> None:
    if optional and value is None:
        return
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
        raise ConfigError(name, f"must be a positive number, got {value!r}")


def shipped_model() -> str:
    """The shipped robot's scene (models/scene.xml, installed as package data mlpfac.models)."""
    return str(importlib.resources.files("mlpfac.models") / "scene.xml")


def model_fingerprint(path: Path) -> str:
    """sha256 of the compiled model (MuJoCo's binary MJB): what is simulated, included files and
    meshes too. Compiled afresh each time: a file that changed is never mistaken for the old one."""
    try:
        model = mujoco.MjSpec.from_file(str(path)).compile()
    except ValueError as err:
        raise ConfigError(str(path), f"MuJoCo cannot load the model: {err}") from None
    return _fingerprint(model)


def _fingerprint(model: mujoco.MjModel) -> str:
    buf = np.empty(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buf)
    return hashlib.sha256(buf.tobytes()).hexdigest()


@dataclass(frozen=True)
class MujocoConfig:
    """The robot and its drive. Defaults are the shipped robot (models/README.md)."""

    model: str = field(default_factory=shipped_model)  # MJCF file; a scenario file resolves it from its folder
    actuator: str = "velocity"  # "velocity": the model's velocity servos; "torque": torque motors + PI here
    left_actuator: str = "left_wheel"  # velocity servo (<velocity kv forcerange>) on the left wheel's hinge
    right_actuator: str = "right_wheel"
    site: str = "axle_mid"  # on the axle midpoint, x axis forward: the pose is measured here
    wheel_radius: float | None = None  # radius the IK believes (m); None: read from the model
    track: float | None = None  # wheel separation the IK believes (m); None: read from the model
    max_wheel_speed: float | None = None  # rad/s; faster commands are scaled down keeping the curvature
    pose_noise_std: float | tuple[float, ...] = 0.0  # std of Gaussian noise on (x, y, theta): scalar or 3
    pi_kp: float = 0.5  # torque drive: PI proportional gain, N m per rad/s of wheel-speed error
    pi_ki: float = 10.0  # torque drive: PI integral gain, N m per rad of integrated error

    def __post_init__(self) -> None:
        if self.actuator not in ("velocity", "torque"):
            raise ConfigError("actuator", f"choose 'velocity' or 'torque', got {self.actuator!r}")
        for name in ("model", "left_actuator", "right_actuator", "site"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ConfigError(name, f"expected a non-empty name, got {getattr(self, name)!r}")
        for name in ("wheel_radius", "track", "max_wheel_speed"):
            _positive(name, getattr(self, name), optional=True)
        _positive("pi_kp", self.pi_kp)
        ki = self.pi_ki
        if isinstance(ki, bool) or not isinstance(ki, int | float) or not math.isfinite(ki) or ki < 0:
            raise ConfigError("pi_ki", f"must be a number >= 0, got {ki!r}")
        self.noise_std()
        if not self.path.is_file():
            raise ConfigError(str(self.path), "MJCF model file not found")

    @property
    def path(self) -> Path:
        """The model file (a scenario file's relative path was resolved from its folder when it was loaded)."""
        return Path(self.model).absolute()

    def noise_std(self) -> np.ndarray | None:
        """(3,) standard deviations of the pose noise, or None when there is none."""
        try:
            std = np.broadcast_to(np.asarray(self.pose_noise_std, dtype=float), (3,))
        except (TypeError, ValueError):
            raise ConfigError(
                "pose_noise_std", f"expected a number or 3 numbers, got {self.pose_noise_std!r}"
            ) from None
        if not np.all(np.isfinite(std)) or np.any(std < 0):
            raise ConfigError(
                "pose_noise_std", f"standard deviations must be finite and >= 0, got {self.pose_noise_std!r}"
            )
        return std.copy() if np.any(std > 0) else None


@dataclass(frozen=True)
class Robot:
    """What the model says about the robot, read once by :func:`read_robot` (ids index the nominal model).

    ``spec`` and ``model`` are the nominal robot (the torque drive's motors already in place);
    ``qpos_rest`` is its pose settled on its wheels; ``sign`` turns a joint velocity into a forward
    wheel speed; ``act_per_wheel`` is actuator units per forward wheel unit (ctrl = c w_cmd for a
    servo, joint torque = c force for a motor).
    """

    where: str  # the model file, for messages
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
    tyres: tuple[int, ...]  # the wheels' round collision geoms
    qpos_rest: np.ndarray
    site_rest: tuple[np.ndarray, float]  # site position and heading at rest
    real_radius: float
    real_track: float
    sign: tuple[float, float]
    act_per_wheel: tuple[float, float]
    geometry: list[dict]  # visual shapes relative to the site frame

    def substeps(self, period: float, where: str) -> int:
        """Physics steps in ``period`` seconds; a ConfigError unless it is a whole number of them."""
        n = period / self.dt
        if round(n) < 1 or abs(n - round(n)) > 1e-6 * n:
            raise ConfigError(
                where, f"{period:g} s is not a whole number of physics steps of {self.dt:g} s (the model's timestep)"
            )
        return int(round(n))


def read_robot(config: MujocoConfig) -> Robot:
    """Load, check and describe the robot of ``config``; each problem a ConfigError naming its key."""
    where = str(config.path)
    try:
        spec = mujoco.MjSpec.from_file(where)
        m = spec.compile()
    except ValueError as err:
        raise ConfigError(where, f"MuJoCo cannot load the model: {err}") from None
    sha256 = _fingerprint(m)
    acts = (_actuator_id(m, config, "left_actuator", where), _actuator_id(m, config, "right_actuator", where))
    if acts[0] == acts[1]:
        raise ConfigError(
            "right_actuator", f"left and right wheels need two actuators, both are {config.left_actuator!r}"
        )
    if config.actuator == "torque":
        _to_torque_motors(spec, m, acts)
        m = spec.compile()
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, config.site)
    if site < 0:
        raise ConfigError(
            "site", f"no site named {config.site!r} in {where} ({_names(m, mujoco.mjtObj.mjOBJ_SITE, m.nsite)})"
        )
    root = int(m.body_rootid[m.site_bodyid[site]])
    jnt = int(m.body_jntadr[root])
    if jnt < 0 or int(m.jnt_type[jnt]) != mujoco.mjtJoint.mjJNT_FREE:
        raise ConfigError(
            "site", f"the body tree of site {config.site!r} must hang from a <freejoint/> (a robot free to drive)"
        )
    joints = [int(m.actuator_trnid[a, 0]) for a in acts]
    wheel_bodies = tuple(int(m.jnt_bodyid[j]) for j in joints)
    tyres = tuple(g for b in wheel_bodies for g in _collision_geoms(m, b) if int(m.geom_type[g]) in ROUND)
    for key, b in zip(("left_actuator", "right_actuator"), wheel_bodies, strict=True):
        if not any(m.geom_bodyid[g] == b for g in tyres):
            raise ConfigError(
                key, f"the body moved by {getattr(config, key)!r} has no sphere or cylinder collision geom (the wheel)"
            )
    dt = float(m.opt.timestep)
    d = mujoco.MjData(m)
    _settle(m, d, dt)
    anchors = [d.xanchor[j].copy() for j in joints]
    sign = _wheel_signs(config, d, site, joints, anchors)
    c = [s * g for s, g in zip(sign, m.actuator_gear[list(acts), 0], strict=True)]
    return Robot(
        where=where,
        sha256=sha256,
        spec=spec,
        model=m,
        dt=dt,
        acts=acts,
        site=site,
        root=root,
        qroot=int(m.jnt_qposadr[jnt]),
        droot=int(m.jnt_dofadr[jnt]),
        dofs=(int(m.jnt_dofadr[joints[0]]), int(m.jnt_dofadr[joints[1]])),
        wheel_bodies=(wheel_bodies[0], wheel_bodies[1]),
        tyres=tyres,
        qpos_rest=d.qpos.copy(),
        site_rest=(d.site_xpos[site].copy(), yaw(d.site_xmat[site])),
        real_radius=max(float(m.geom_size[g, 0]) for g in tyres),
        real_track=float(np.linalg.norm(anchors[1] - anchors[0])),
        sign=sign,
        act_per_wheel=(float(c[0]), float(c[1])),
        geometry=_static_geometry(m, d, site, root),
    )


def _actuator_id(m: mujoco.MjModel, config: MujocoConfig, key: str, where: str) -> int:
    name = getattr(config, key)
    a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
    if a < 0:
        raise ConfigError(
            key, f"no actuator named {name!r} in {where} ({_names(m, mujoco.mjtObj.mjOBJ_ACTUATOR, m.nu)})"
        )
    if (
        int(m.actuator_trntype[a]) != mujoco.mjtTrn.mjTRN_JOINT
        or int(m.jnt_type[m.actuator_trnid[a, 0]]) != mujoco.mjtJoint.mjJNT_HINGE
    ):
        raise ConfigError(key, f"actuator {name!r} must drive a hinge joint (the wheel)")
    kv = m.actuator_gainprm[a, 0]
    servo = (
        int(m.actuator_gaintype[a]) == mujoco.mjtGain.mjGAIN_FIXED
        and int(m.actuator_biastype[a]) == mujoco.mjtBias.mjBIAS_AFFINE
        and kv > 0
        and m.actuator_biasprm[a, 0] == 0
        and m.actuator_biasprm[a, 1] == 0
        and m.actuator_biasprm[a, 2] == -kv
    )
    if not servo:
        raise ConfigError(key, f"actuator {name!r} must be a velocity servo (<velocity kv=... forcerange=...>)")
    return a


def _settle(m: mujoco.MjModel, d: mujoco.MjData, dt: float) -> None:
    """From the model's initial pose, let the robot settle on its wheels with zero wheel speed."""
    mujoco.mj_resetData(m, d)
    mujoco.mj_forward(m, d)
    mujoco.mj_step(m, d, nstep=int(round(SETTLE_S / dt)))
    mujoco.mj_forward(m, d)


def _wheel_signs(
    config: MujocoConfig, d: mujoco.MjData, site: int, joints: list[int], anchors: list[np.ndarray]
) -> tuple[float, float]:
    R = d.site_xmat[site].reshape(3, 3)  # columns: site axes in the world
    signs = []
    for key, j, p, side in zip(("left_actuator", "right_actuator"), joints, anchors, (1.0, -1.0), strict=True):
        roll = float(np.cross(d.xaxis[j], [0.0, 0.0, 1.0]) @ R[:, 0])  # forward speed per rad/s, / radius
        if abs(roll) < 0.5:
            raise ConfigError(key, "the wheel's hinge axis must be across the site's x axis (forward)")
        if side * float((p - d.site_xpos[site]) @ R[:, 1]) <= 0:
            raise ConfigError(
                key,
                f"this wheel is not on the {'left' if side > 0 else 'right'} of site {config.site!r} (y axis to the left)",
            )
        signs.append(1.0 if roll > 0 else -1.0)
    return signs[0], signs[1]


def _static_geometry(m: mujoco.MjModel, d: mujoco.MjData, site: int, root: int) -> list[dict]:
    """Visual geoms (contype = conaffinity = 0) of the robot, posed relative to the site frame."""
    ps, Rs = d.site_xpos[site], d.site_xmat[site].reshape(3, 3)
    robot = [g for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] == root and int(m.geom_type[g]) in SHAPES]
    visual = [g for g in robot if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0] or robot
    shapes = []
    for g in visual:
        kind = SHAPES[int(m.geom_type[g])]
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, (Rs.T @ d.geom_xmat[g].reshape(3, 3)).ravel())
        rgba = m.mat_rgba[m.geom_matid[g]] if m.geom_matid[g] >= 0 else m.geom_rgba[g]
        shapes.append({
            "name": m.geom(g).name or f"geom{g}",
            "type": kind,
            "size": [round(float(x), 9) for x in m.geom_size[g, : SIZE_LEN[kind]]],
            "pos": [round(float(x), 9) for x in Rs.T @ (d.geom_xpos[g] - ps)],
            "quat": [round(float(x), 9) for x in quat],
            "rgba": [round(float(x), 6) for x in rgba],
        })  # fmt: skip
    return shapes


def _to_torque_motors(spec: mujoco.MjSpec, m: mujoco.MjModel, acts: tuple[int, int]) -> None:
    """Turn the velocity servos into torque motors (force = ctrl) limited to the same force range."""
    for a in acts:
        act = spec.actuators[a]
        act.gaintype, act.biastype = mujoco.mjtGain.mjGAIN_FIXED, mujoco.mjtBias.mjBIAS_NONE
        act.gainprm = [1.0] + [0.0] * 9
        act.biasprm = [0.0] * 10
        if m.actuator_forcelimited[a]:
            act.ctrllimited, act.ctrlrange = mujoco.mjtLimited.mjLIMITED_TRUE, m.actuator_forcerange[a].copy()


def _collision_geoms(m: mujoco.MjModel, body: int) -> list[int]:
    return [g for g in range(m.ngeom) if m.geom_bodyid[g] == body and (m.geom_contype[g] or m.geom_conaffinity[g])]


def _names(m: mujoco.MjModel, obj: mujoco.mjtObj, n: int) -> str:
    names = [mujoco.mj_id2name(m, obj, i) for i in range(n)]
    return "it has: " + ", ".join(repr(x) for x in names if x) if any(names) else "it has none with a name"


def yaw(xmat: np.ndarray) -> float:
    """Heading of a frame: the angle of its x axis projected on the floor, atan2(R[1, 0], R[0, 0])."""
    return math.atan2(xmat[3], xmat[0])
