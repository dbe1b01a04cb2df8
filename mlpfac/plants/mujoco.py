"""A differential-drive robot simulated by MuJoCo, as a plant (see :mod:`mlpfac.plants.base`).

The controller's u = (v, omega) is turned into wheel speeds by the inverse kinematics
(:func:`mlpfac.kinematics.wheel_speeds`) with the wheel radius and track the IK *believes* (the
nominal ones), and held for one control period of ``n_substeps`` physics steps,
``control_dt = n_substeps * model.opt.timestep``. Two wheel drives:

- ``actuator = "velocity"``: the model's velocity servos (force = kv (w_cmd - w), clamped to the
  force range), integrated implicitly by MuJoCo (``implicitfast``); no Python per physics step.
- ``actuator = "torque"``: the same actuators turned into torque motors with the same force limit,
  driven by a discrete wheel-speed PI loop evaluated here once per physics step.

The pose (x, y, theta) is read at a site on the axle midpoint (``axle_mid``); theta is unwrapped
across steps. Events edit the model's :class:`mujoco.MjSpec` and recompile it keeping the state
(``spec.recompile``), so a changed model is exactly the model one would compile with the new
numbers (masses, inertias and every derived constant included); nothing edits XML text.

Data stay in step: each physics step is ``mj_step2`` (actuation, acceleration, integration) then
``mj_step1`` (positions, velocities and sensors of the new state), so between control steps every
derived quantity (site pose, ``cvel``, sensors) belongs to the current state.
"""

from __future__ import annotations

import hashlib
import importlib.resources
import math
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from mlpfac.events import EVENT_KINDS, Event
from mlpfac.exceptions import ConfigError
from mlpfac.kinematics import body_velocity, wheel_speeds

SETTLE_S = 0.5  # seconds the robot settles on its wheels at construction (the rest pose)
DIVERGENCE_WARNINGS = ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC")  # MuJoCo resets the data on these
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


class MujocoPlant:
    """The MuJoCo robot behind the :class:`~mlpfac.plants.base.Plant` interface.

    ``model`` and ``data`` are the current :class:`mujoco.MjModel` / :class:`mujoco.MjData` (an
    event that changes the robot replaces both); ``n_substeps`` physics steps make one control step.
    """

    supported_events = frozenset(EVENT_KINDS)

    def __init__(self, config: MujocoConfig, T: float) -> None:
        self.config = config
        self.T = float(T)
        self._where = str(config.path)
        try:
            spec = mujoco.MjSpec.from_file(self._where)
            model = spec.compile()
        except ValueError as err:
            raise ConfigError(self._where, f"MuJoCo cannot load the model: {err}") from None
        self._acts = (self._actuator_id(model, "left_actuator"), self._actuator_id(model, "right_actuator"))
        if self._acts[0] == self._acts[1]:
            raise ConfigError(
                "right_actuator", f"left and right wheels need two actuators, both are {config.left_actuator!r}"
            )
        if config.actuator == "torque":
            _to_torque_motors(spec, model, self._acts)
            model = spec.compile()
        self._spec_nominal = spec
        self._spec = spec.copy()
        self.model = model
        self.data = mujoco.MjData(model)

        m = model
        self._dt = float(m.opt.timestep)
        self.n_substeps = self._substeps(self.T, "T")
        self._site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, config.site)
        if self._site < 0:
            raise ConfigError(
                "site",
                f"no site named {config.site!r} in {self._where} ({_names(m, mujoco.mjtObj.mjOBJ_SITE, m.nsite)})",
            )
        self._root = int(m.body_rootid[m.site_bodyid[self._site]])
        jnt = int(m.body_jntadr[self._root])
        if jnt < 0 or int(m.jnt_type[jnt]) != mujoco.mjtJoint.mjJNT_FREE:
            raise ConfigError(
                "site", f"the body tree of site {config.site!r} must hang from a <freejoint/> (a robot free to drive)"
            )
        self._qroot, self._droot = int(m.jnt_qposadr[jnt]), int(m.jnt_dofadr[jnt])
        joints = [int(m.actuator_trnid[a, 0]) for a in self._acts]
        self._dofs = tuple(int(m.jnt_dofadr[j]) for j in joints)
        self._wheel_bodies = tuple(int(m.jnt_bodyid[j]) for j in joints)
        self._tyres = [g for b in self._wheel_bodies for g in _collision_geoms(m, b) if int(m.geom_type[g]) in ROUND]
        for key, b in zip(("left_actuator", "right_actuator"), self._wheel_bodies, strict=True):
            if not any(m.geom_bodyid[g] == b for g in self._tyres):
                raise ConfigError(
                    key,
                    f"the body moved by {getattr(config, key)!r} has no sphere or cylinder collision geom (the wheel)",
                )

        self._settle()
        d = self.data
        self._qpos_rest = d.qpos.copy()
        self._site_rest = (d.site_xpos[self._site].copy(), _yaw(d.site_xmat[self._site]))
        self.real_radius = max(float(m.geom_size[g, 0]) for g in self._tyres)
        anchors = [d.xanchor[j].copy() for j in joints]
        self.ik_radius = config.wheel_radius if config.wheel_radius is not None else self.real_radius
        self._real_track = float(np.linalg.norm(anchors[1] - anchors[0]))
        self.ik_track = config.track if config.track is not None else self._real_track
        self._sign = self._wheel_signs(joints, anchors)  # +-1: joint velocity -> forward wheel speed
        # Actuator units per forward wheel unit: ctrl = c w_cmd (servo), joint torque = c force (motor).
        c = [s * g for s, g in zip(self._sign, m.actuator_gear[list(self._acts), 0], strict=True)]
        self._act_per_wheel = (float(c[0]), float(c[1]))
        self._geometry = self._static_geometry()
        self._noise = config.noise_std()
        self._changed = False
        self.reset(np.zeros(3), np.random.default_rng(0))

    # --- construction helpers ------------------------------------------------------------------

    def _actuator_id(self, m: mujoco.MjModel, key: str) -> int:
        name = getattr(self.config, key)
        a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        if a < 0:
            raise ConfigError(
                key, f"no actuator named {name!r} in {self._where} ({_names(m, mujoco.mjtObj.mjOBJ_ACTUATOR, m.nu)})"
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

    def _substeps(self, period: float, where: str) -> int:
        n = period / self._dt
        if round(n) < 1 or abs(n - round(n)) > 1e-6 * n:
            raise ConfigError(
                where, f"{period:g} s is not a whole number of physics steps of {self._dt:g} s (the model's timestep)"
            )
        return int(round(n))

    def _settle(self) -> None:
        """From the model's initial pose, let the robot settle on its wheels with zero wheel speed."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        mujoco.mj_forward(m, d)
        mujoco.mj_step(m, d, nstep=int(round(SETTLE_S / self._dt)))
        mujoco.mj_forward(m, d)

    def _wheel_signs(self, joints: list[int], anchors: list[np.ndarray]) -> tuple[float, float]:
        d = self.data
        R = d.site_xmat[self._site].reshape(3, 3)  # columns: site axes in the world
        signs = []
        for key, j, p, side in zip(("left_actuator", "right_actuator"), joints, anchors, (1.0, -1.0), strict=True):
            roll = float(np.cross(d.xaxis[j], [0.0, 0.0, 1.0]) @ R[:, 0])  # forward speed per rad/s, / radius
            if abs(roll) < 0.5:
                raise ConfigError(key, "the wheel's hinge axis must be across the site's x axis (forward)")
            if side * float((p - d.site_xpos[self._site]) @ R[:, 1]) <= 0:
                raise ConfigError(
                    key,
                    f"this wheel is not on the {'left' if side > 0 else 'right'} of site {self.config.site!r} (y axis to the left)",
                )
            signs.append(1.0 if roll > 0 else -1.0)
        return signs[0], signs[1]

    def _static_geometry(self) -> list[dict]:
        """Visual geoms (contype = conaffinity = 0) of the robot, posed relative to the site frame."""
        m, d = self.model, self.data
        ps, Rs = d.site_xpos[self._site], d.site_xmat[self._site].reshape(3, 3)
        robot = [
            g for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] == self._root and int(m.geom_type[g]) in SHAPES
        ]
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

    # --- the Plant interface -------------------------------------------------------------------

    def reset(self, q0: np.ndarray, rng: np.random.Generator, u0: np.ndarray | None = None) -> None:
        """The nominal robot with its axle midpoint at (x0, y0), heading theta0, at rest.

        ``u0`` = (v0, omega0) (optional) starts it rolling at that body velocity instead (wheels
        turning at the matching speeds, no slip): a flying start on a reference already moving.
        """
        if self._changed:
            self._spec = self._spec_nominal.copy()
            self.model = self._spec.compile()
            self.data = mujoco.MjData(self.model)
            self.real_radius = max(float(self.model.geom_size[g, 0]) for g in self._tyres)
            self._changed = False
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[:] = self._qpos_rest
        # Turn the rest pose about the vertical through the site, then move the site to (x0, y0).
        p_site, yaw_site = self._site_rest
        turn = float(q0[2]) - yaw_site
        c, s = math.cos(turn), math.sin(turn)
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        root = slice(self._qroot, self._qroot + 7)
        pos, quat = d.qpos[root][:3].copy(), d.qpos[root][3:].copy()
        d.qpos[self._qroot : self._qroot + 3] = Rz @ (pos - p_site) + [float(q0[0]), float(q0[1]), p_site[2]]
        mujoco.mju_mulQuat(
            d.qpos[self._qroot + 3 : self._qroot + 7],
            np.array([math.cos(turn / 2), 0.0, 0.0, math.sin(turn / 2)]),
            quat,
        )
        mujoco.mj_forward(m, d)
        if u0 is not None:
            self._set_velocity(float(u0[0]), float(u0[1]), float(q0[2]))
        self._z_rest = float(d.site_xpos[self._site, 2])

        self.rng = rng
        self.sim_time = 0.0
        self._n = self.n_substeps
        self._kp, self._ki = float(self.config.pi_kp), float(self.config.pi_ki)
        self._torque_max = self._force_limits()
        self._integral = (0.0, 0.0)
        self._theta = float(q0[2])
        self._pose = self._read_pose()
        self._wheel_cmd = np.zeros(2)
        self._history: deque[np.ndarray] = deque([self._noisy(self._pose)], maxlen=1)

    def _set_velocity(self, v: float, omega: float, theta: float) -> None:
        """Body velocity (v, omega) at the site, the wheels rolling to match it."""
        m, d = self.model, self.data
        omega_w = np.array([0.0, 0.0, omega])
        v_site = np.array([v * math.cos(theta), v * math.sin(theta), 0.0])
        d.qvel[self._droot : self._droot + 3] = v_site + np.cross(omega_w, d.xpos[self._root] - d.site_xpos[self._site])
        d.qvel[self._droot + 3 : self._droot + 6] = d.xmat[self._root].reshape(3, 3).T @ omega_w  # local frame
        w = wheel_speeds(v, omega, self.real_radius, self._real_track)
        for dof, sign, wi in zip(self._dofs, self._sign, w, strict=True):
            d.qvel[dof] = sign * wi
        mujoco.mj_forward(m, d)

    def true_pose(self) -> np.ndarray:
        return self._pose

    def measure(self) -> np.ndarray:
        return self._history[0]

    def step(self, u: np.ndarray) -> None:
        w = wheel_speeds(float(u[0]), float(u[1]), self.ik_radius, self.ik_track, self.config.max_wheel_speed)
        self._wheel_cmd = w
        m, d, n = self.model, self.data, self._n
        if self.config.actuator == "velocity":
            al, ar = self._acts
            d.ctrl[al] = self._act_per_wheel[0] * w[0]
            d.ctrl[ar] = self._act_per_wheel[1] * w[1]
            mujoco.mj_step2(m, d)
            if n > 1:
                mujoco.mj_step(m, d, nstep=n - 1)
            mujoco.mj_step1(m, d)
        else:
            self._pi_steps(float(w[0]), float(w[1]), n)
        self.sim_time += n * self._dt
        self._pose = self._read_pose()
        self._history.append(self._noisy(self._pose))

    def _pi_steps(self, wl: float, wr: float, n: int) -> None:
        """n physics steps of the discrete wheel-speed PI loop (torque drive).

        tau = kp e + ki I, e = w_cmd - w, clamped to the torque limit; I integrates e only while
        tau is not clamped (conditional integration, so I does not wind up while saturated).
        """
        m, d = self.model, self.data
        qvel, ctrl = d.qvel, d.ctrl
        (dl, dr), (al, ar), (sl, sr) = self._dofs, self._acts, self._sign
        (cl, cr), (tl_max, tr_max) = self._act_per_wheel, self._torque_max
        kp, ki, dt = self._kp, self._ki, self._dt
        il, ir = self._integral
        for _ in range(n):
            el = wl - sl * qvel[dl]
            er = wr - sr * qvel[dr]
            tl = kp * el + ki * (il + el * dt)
            tr = kp * er + ki * (ir + er * dt)
            if -tl_max <= tl <= tl_max:
                il += el * dt
            else:
                tl = math.copysign(tl_max, tl)
            if -tr_max <= tr <= tr_max:
                ir += er * dt
            else:
                tr = math.copysign(tr_max, tr)
            ctrl[al] = tl / cl
            ctrl[ar] = tr / cr
            mujoco.mj_step2(m, d)
            mujoco.mj_step1(m, d)
        self._integral = (il, ir)

    def _read_pose(self) -> np.ndarray:
        d = self.data
        p = d.site_xpos[self._site]
        self._theta += math.remainder(_yaw(d.site_xmat[self._site]) - self._theta, 2.0 * math.pi)  # unwrapped
        return np.array([p[0], p[1], self._theta])

    def _noisy(self, pose: np.ndarray) -> np.ndarray:
        return pose if self._noise is None else pose + self._noise * self.rng.standard_normal(3)

    def _force_limits(self) -> tuple[float, float]:
        """Largest forward wheel torque of each drive (N m at the joint), inf when not limited."""
        m = self.model
        out = []
        for a, c in zip(self._acts, self._act_per_wheel, strict=True):
            limited = m.actuator_ctrllimited[a] if self.config.actuator == "torque" else m.actuator_forcelimited[a]
            lo, hi = m.actuator_ctrlrange[a] if self.config.actuator == "torque" else m.actuator_forcerange[a]
            out.append(min(-lo, hi) * abs(c) if limited else math.inf)
        return out[0], out[1]

    def telemetry(self) -> dict[str, np.ndarray | float]:
        """``u_meas`` (2,) (v, omega) from the measured wheel speeds through the nominal FK;
        ``u_true`` (2,) (v, omega) of the axle midpoint (differs from u_meas by slip and radius);
        ``wheel_cmd``, ``wheel_meas`` (2,) left/right in rad/s (forward positive); ``torque`` (2,)
        wheel torques in N m (forward positive)."""
        m, d = self.model, self.data
        wheel_meas = np.array([self._sign[0] * d.qvel[self._dofs[0]], self._sign[1] * d.qvel[self._dofs[1]]])
        torque = np.array([self._act_per_wheel[i] * d.actuator_force[a] for i, a in enumerate(self._acts)])
        vel = np.empty(6)  # (angular, linear) in the world frame
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, self._site, vel, 0)
        th = self._theta
        u_true = np.array([vel[3] * math.cos(th) + vel[4] * math.sin(th), vel[2]])
        return {
            "u_meas": body_velocity(wheel_meas, self.ik_radius, self.ik_track),
            "u_true": u_true,
            "wheel_cmd": self._wheel_cmd,
            "wheel_meas": wheel_meas,
            "torque": torque,
        }

    def mujoco_warnings(self) -> dict[str, int]:
        """MuJoCo's warning counters that are not zero, by name (``{}`` when all is well)."""
        return {mujoco.mjtWarning(i).name: int(w.number) for i, w in enumerate(self.data.warning) if w.number}

    def diverged(self) -> str | None:
        d = self.data
        if abs(d.time - self.sim_time) > 0.5 * self._dt:  # MuJoCo resets the data (time too) on a bad state
            bad = [w for w in DIVERGENCE_WARNINGS if d.warning[getattr(mujoco.mjtWarning, w)].number]
            return f"MuJoCo {' '.join(bad) or 'reset'}: the simulation became unstable and was reset"
        if not math.isfinite(d.qpos.sum() + d.qvel.sum()):
            return "non-finite MuJoCo state"
        lift = float(d.site_xpos[self._site, 2]) - self._z_rest
        if lift > 0.5 * self.real_radius:
            return f"the robot left the floor (axle {lift * 1e3:.0f} mm above its rest height)"
        up = float(d.xmat[self._root, 8])  # world z component of the chassis z axis
        if up < 0.5:
            return f"the robot tipped over (chassis up axis {math.degrees(math.acos(max(-1.0, up))):.0f} deg from vertical)"
        return None

    def geometry(self) -> list[dict]:
        return self._geometry

    def provenance(self) -> dict:
        """What is simulated, for config.toml: the model file and the hash of the compiled model, and
        the geometry, limits and timing read from it."""
        m, (tl, tr) = self.model, self._torque_max
        return {
            "model": str(self.config.path),
            "model_sha256": model_fingerprint(self.config.path),
            "mujoco": mujoco.__version__,
            "timestep_s": float(m.opt.timestep),
            "substeps": self.n_substeps,
            "wheel_radius_m": self.real_radius,
            "track_m": self._real_track,
            "ik_wheel_radius_m": float(self.ik_radius),
            "ik_track_m": float(self.ik_track),
            "torque_limit_Nm": [float(tl), float(tr)] if math.isfinite(tl + tr) else "none",
            "mass_kg": float(m.body_subtreemass[self._root]),
        }

    # --- events ----------------------------------------------------------------------------------

    def check_event(self, event: Event, where: str) -> None:
        """What this robot needs to apply ``event`` (its parameters were checked when it was parsed)."""
        kind, params = event.kind, event.params
        if kind == "control_period":
            self._substeps(float(params["factor"]) * self.T, f"{where} factor")
        elif kind == "payload":
            self._payload_body(params, where)
        elif kind == "friction":
            m = self.model
            others = [g for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] != self._root]
            floor = max((int(m.geom_priority[g]) for g in others), default=-1)
            if any(m.geom_priority[g] <= floor for g in self._tyres):
                raise ConfigError(
                    where,
                    f"the tyre geoms need a priority above the floor's ({floor}) for their friction to be the contact's",
                )

    def _payload_body(self, params: dict, where: str) -> int:
        if "body" not in params:
            return self._root
        name = params["body"]
        b = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, str(name))
        if b <= 0 or self.model.body_rootid[b] != self._root:
            raise ConfigError(f"{where} body", f"no body named {name!r} on the robot in {self._where}")
        if self.model.body_mass[b] <= 0:
            raise ConfigError(f"{where} body", f"body {name!r} has no mass to scale")
        return b

    def apply(self, event: Event) -> str:
        self.check_event(event, event.kind)
        p, m = event.params, self.model
        if event.kind == "control_period":
            old, self._n = self._n, self._substeps(float(p["factor"]) * self.T, "factor")
            return f"plant holds each command {old * self._dt:g} -> {self._n * self._dt:g} s ({self._n} physics steps; controller keeps T = {self.T:g} s)"
        if event.kind == "sensor_delay":
            n = int(p["steps"])
            old, self._history = self._history.maxlen - 1, deque(self._history, maxlen=n + 1)
            return f"sensor delay {old} -> {n} control steps"
        spec = self._spec
        if event.kind == "payload":
            b = self._payload_body(p, "")
            mass = float(m.body_mass[b])
            k = float(p["mass_scale"]) if "mass_scale" in p else (mass + float(p["mass_kg"])) / mass
            body = spec.bodies[b]
            body.explicitinertial = True  # pin the compiled inertial (it may have come from geoms), then scale it
            body.mass, body.ipos, body.iquat = k * mass, m.body_ipos[b].copy(), m.body_iquat[b].copy()
            body.inertia, body.fullinertia[0] = k * m.body_inertia[b], math.nan
            self._recompile()
            name = m.body(b).name or f"body {b}"
            return f"{name} mass {mass:g} -> {self.model.body_mass[b]:g} kg (inertia x{k:g})"
        if event.kind == "friction":
            old = float(m.geom_friction[self._tyres[0], 0])
            for g in self._tyres:
                spec.geoms[g].friction[0] = float(p["mu"])
            self._recompile()
            return f"tyre/floor sliding friction {old:g} -> {float(p['mu']):g}"
        if event.kind == "wheel_radius":
            k = float(p["scale"])
            for b in self._wheel_bodies:
                for geom in spec.bodies[b].geoms:
                    if int(geom.type) in ROUND:
                        geom.size[0] *= k
            old = self.real_radius
            self.real_radius = k * old
            self._recompile()
            lift = self.real_radius - old  # stand the robot on its new wheels (the caster end then settles)
            self.data.qpos[self._qroot + 2] += lift
            self._z_rest += lift
            mujoco.mj_forward(self.model, self.data)
            return f"real wheel radius {old:g} -> {self.real_radius:g} m (the IK keeps {self.ik_radius:g} m)"
        # actuator
        kv, fs = float(p.get("kv_scale", 1.0)), float(p.get("force_scale", 1.0))
        old_limit = self._torque_max[0]
        for a in self._acts:
            act = spec.actuators[a]
            act.forcerange = fs * np.asarray(act.forcerange)
            if self.config.actuator == "velocity":
                act.gainprm[0] *= kv
                act.biasprm[2] *= kv
            else:
                act.ctrlrange = fs * np.asarray(act.ctrlrange)
        self._recompile()
        self._torque_max = self._force_limits()
        if self.config.actuator == "velocity":
            old_kv = float(m.actuator_gainprm[self._acts[0], 0])
            gains = f"servo kv {old_kv:g} -> {float(self.model.actuator_gainprm[self._acts[0], 0]):g} N m s/rad"
        else:
            gains = f"PI gains ({self._kp:g}, {self._ki:g}) -> ({kv * self._kp:g}, {kv * self._ki:g})"
            self._kp, self._ki = kv * self._kp, kv * self._ki
        return f"wheel drive weakened: {gains}, torque limit {old_limit:g} -> {self._torque_max[0]:g} N m"

    def _recompile(self) -> None:
        """Compile the edited spec into a new model keeping the state (qpos, qvel, warm start, time)."""
        try:
            self.model, self.data = self._spec.recompile(self.model, self.data)
        except ValueError as err:
            raise ConfigError(self._where, f"MuJoCo cannot compile the changed model: {err}") from None
        mujoco.mj_forward(self.model, self.data)
        self._changed = True


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


def _yaw(xmat: np.ndarray) -> float:
    """Heading of a frame: the angle of its x axis projected on the floor, atan2(R[1, 0], R[0, 0])."""
    return math.atan2(xmat[3], xmat[0])
