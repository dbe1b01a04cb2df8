"""A differential-drive robot simulated by MuJoCo, as a plant (see :mod:`mlpfac.plants.base`).

What the robot is (actuators, wheels, site, radius, track, rest pose) is read once from its model
by :func:`mlpfac.plants.mjcf.robot.read_robot`; this module resets it, applies events and reads what it
did; its control step is compiled (:func:`mlpfac.plants.mujoco.compiled.plant_step`, one call a step).
The controller's u = (v, omega) is turned into wheel speeds by the inverse kinematics
(:func:`mlpfac.plants.ik.wheel_speeds`) with the wheel radius and track the IK *believes* (the
nominal ones), and held for one control period of ``n_substeps`` physics steps,
``control_dt = n_substeps * model.opt.timestep``. Two wheel drives:

- ``actuator = "velocity"``: the model's velocity servos (force = kv (w_cmd - w), clamped to the
  force range), integrated implicitly by MuJoCo (``implicitfast``).
- ``actuator = "torque"``: the same actuators turned into torque motors with the same force limit,
  driven by a discrete wheel-speed PI loop evaluated once per physics step.

The pose (x, y, theta) is read at a site on the axle midpoint (``axle_mid``, or the frame
:mod:`mlpfac.plants.mjcf.detect` finds; a skid-steer's found frame is moved to its kinematic centre, and
the track it turns as is measured, as it settles: :func:`mlpfac.plants.mjcf.settle.turning`); theta is unwrapped
across steps. Events (:mod:`mlpfac.plants.mujoco.events`) edit the model's
:class:`mujoco.MjSpec` and recompile it keeping the state (``spec.recompile``). The torque level's
part (torques in, twist and wheel speeds measured, the dynamic model read) is
:mod:`mlpfac.plants.mujoco.torque`; what the robot says of itself (a divergence in words, the keys it
found, its provenance), :mod:`mlpfac.plants.mujoco.report`.

Data stay in step: each physics step is ``mj_step2`` (actuation, acceleration, integration) then
``mj_step1`` (positions, velocities and sensors of the new state), so between control steps every
derived quantity (site pose, ``cvel``, sensors) belongs to the current state.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import mujoco
import numpy as np

from mlpfac.elementary import cos, sin
from mlpfac.normal import Stream
from mlpfac.plants.config import MujocoConfig
from mlpfac.plants.events import EVENT_KINDS, DelayLine
from mlpfac.plants.ik import wheel_speeds
from mlpfac.plants.mjcf import drive
from mlpfac.plants.mjcf.edits import servo_band
from mlpfac.plants.mjcf.robot import Robot, read_robot
from mlpfac.plants.mjcf.settle import turning
from mlpfac.plants.mujoco import compiled as K  # noqa: N812 - the kernel's layout constants, K.F_DT ...
from mlpfac.plants.mujoco.events import MujocoEvents
from mlpfac.plants.mujoco.report import MujocoReport
from mlpfac.plants.mujoco.torque import TorqueDrive
from mlpfac.plants.mujoco.world import MujocoWorld
from mlpfac.plants.sensors.sensing import SensingPlant


class _Kept:
    """A plant attribute kept in one of the compiled step's arrays (``fl`` or ``ints``), its one copy."""

    def __init__(self, array: str, index: int, kind: type = float) -> None:
        self.array, self.index, self.kind = array, index, kind

    def __get__(self, plant, owner=None):
        return self if plant is None else self.kind(getattr(plant, self.array)[self.index])

    def __set__(self, plant, value) -> None:
        getattr(plant, self.array)[self.index] = value


class MujocoPlant(MujocoEvents, TorqueDrive, MujocoReport, SensingPlant, MujocoWorld):
    """The MuJoCo robot behind the :class:`~mlpfac.plants.base.Plant` interface.

    ``model`` and ``data`` are the current :class:`mujoco.MjModel` / :class:`mujoco.MjData` (an
    event that changes the robot replaces both); ``n_substeps`` physics steps make one control step.
    """

    supported_events = frozenset(EVENT_KINDS)
    batched = False  # one robot: a batch is one object per seed
    # what the compiled step reads and events change: real wheel radius, axle height at rest, PI
    # gains, physics steps per control step
    real_radius, _z_rest = _Kept("fl", K.F_RADIUS), _Kept("fl", K.F_ZREST)
    _kp, _ki, _n = _Kept("fl", K.F_KP), _Kept("fl", K.F_KI), _Kept("ints", K.I_NSUB, int)

    def __init__(self, config: MujocoConfig, T: float, periods: tuple[float, ...] = ()) -> None:
        self._build(config, T, periods)
        if self.robot.seconds != (-1, -1) and config.turning_track is None:
            self._turning(config, T, periods)

    def _turning(self, config: MujocoConfig, T: float, periods: tuple[float, ...]) -> None:
        """A skid-steer's turning measured once it has settled (:func:`mlpfac.plants.mjcf.settle.turning`),
        and the robot built again with what was measured as ``[plant]`` keys, found (written into
        config.toml: a run of it measures nothing): the track it turns as, and a pose frame found in
        the middle of its wheels moved to its kinematic centre, where it moves along its heading."""
        r = self.robot
        track, ahead, said = turning(self)
        if not math.isfinite(track):
            self.robot = dataclasses.replace(r, description=f"{r.description}; its turning not measured ({said})")
            return
        keys: dict = {"turning_track": float(f"{track:.3g}")}
        if "frame_offset" in r.found and abs(ahead) < track / 2:
            ox, oy, oz = r.config.offset
            keys["frame_offset"] = (round(float(ox) + ahead, 4) + 0.0, float(oy), float(oz))
        self._build(dataclasses.replace(r.config, **keys), T, periods)  # every part named: read once
        way = f"{abs(ahead) * 1e3:.0f} mm {'ahead' if ahead >= 0 else 'back'}"
        moved = f", the pose frame moved {way} to its kinematic centre" if len(keys) > 1 else ""
        chosen = r.description[_turns_end(r.description) :]  # what the first read chose, said after the track
        self.robot = dataclasses.replace(
            self.robot,
            found=(*(k for k in r.found if k not in keys), *keys),
            description=f"{self.robot.description[: _turns_end(self.robot.description)]}{chosen}; measured as it "
            f"settled, {said}: the track{moved}",
        )

    def _build(self, config: MujocoConfig, T: float, periods: tuple[float, ...]) -> None:
        self.T = float(T)
        self.robot = r = read_robot(config, tuple(periods) or (self.T,))
        self.config = r.config  # every part named: what the model said where ``config`` did not
        self.ints, self.fl = np.zeros(K.N_INTS, dtype=np.int64), np.zeros(K.N_FL)
        self._where = r.where
        self._spec_nominal, self._spec = r.spec, r.spec.copy()
        self.model, self.data = r.model, mujoco.MjData(r.model)
        self._dt = r.dt
        self.n_substeps = self._substeps(self.T, "T")
        self._acts, self._site, self._root, self._dofs = r.acts, r.site, r.root, r.dofs
        self._qroot, self._droot = r.qroot, r.droot
        self._wheel_bodies, self._tyres = r.wheel_bodies, list(r.tyres)
        self._qpos_rest, self._site_rest = r.qpos_rest, (r.site_rest[0], K.yaw(r.site_rest[1]))  # heading at rest
        self.real_radius, self._real_track = r.real_radius, r.real_track
        self.ik_radius = config.wheel_radius if config.wheel_radius is not None else r.real_radius
        self.ik_track = config.track if config.track is not None else r.real_track
        self._sign, self._act_per_wheel = r.sign, r.act_per_wheel
        limit = config.max_wheel_speed if config.max_wheel_speed is not None else r.max_wheel_speed
        self.max_wheel_speed = None if limit is None or math.isinf(limit) else float(limit)
        self._geometry = r.geometry
        self._noise = config.noise_std()
        self._changed = False
        self._motion_std = config.motion_noise_std()
        self._motion: DelayLine | None = None  # (v, omega, wheel_l, wheel_r) as measured: torque_commands()
        self._no_world()  # the world: set_world (mlpfac.plants.mujoco.world)
        self.ints[[K.I_AL, K.I_AR, K.I_DL, K.I_DR, K.I_SITE]] = (*r.acts, *r.dofs, r.site)
        self.ints[K.I_TORQUE] = self.config.actuator == "torque"
        self.ints[K.I_ROOT] = r.root
        self.ints[[K.I_AL2, K.I_AR2, K.I_MIX]] = (*r.seconds, r.mix is not None)
        self.ints[K.I_CLAMP] = self.config.servo_limit == "control" and self.config.actuator == "velocity"
        self._servos = [(i, a) for i, a in enumerate((*r.acts, *r.seconds)) if a >= 0 and self.ints[K.I_CLAMP]]
        self.ints[[K.I_DL2, K.I_DR2]] = [int(r.model.jnt_dofadr[r.model.actuator_trnid[a, 0]]) if a >= 0 else 0
                                         for a in r.seconds]  # fmt: skip
        self.fl[[K.F_CL2, K.F_CR2]] = r.second_per_wheel
        self._umax()
        self._torque_max = self._force_limits()
        self.ints[K.I_NOISE] = self._noise is not None
        self.fl[[K.F_CL, K.F_CR, K.F_SL, K.F_SR]] = (*r.act_per_wheel, *r.sign)
        self.fl[[K.F_IK_R, K.F_IK_TRACK, K.F_DT]] = self.ik_radius, self.ik_track, self._dt
        self.fl[K.F_WMAX] = math.inf if self.max_wheel_speed is None else self.max_wheel_speed
        if self._noise is not None:
            self.fl[K.F_STD : K.F_STD + 3] = self._noise
        self._build_sensing(config, r, (self.T, *periods))  # the pose source (mlpfac.plants.sensors.sensing)

    def _umax(self) -> None:
        """The drive's limits of the current model into fl: the tendon drive's inverse and its motors'
        control limits; servos whose force limit the plant keeps (``servo_limit = "control"``): each
        one's gear and force limit / kv (:func:`mlpfac.plants.mjcf.edits.servo_band`)."""
        for i, a in self._servos:  # left, right, left second, right second
            self.fl[K.F_GEAR + i], self.fl[K.F_BAND + i] = self.model.actuator_gear[a, 0], servo_band(self.model, a)
        if self.robot.mix is not None:
            self.fl[K.F_MIX : K.F_MIX + 4] = self.robot.mix.ravel()
            self.fl[K.F_UMAX : K.F_UMAX + 2] = [drive.ctrl_limit(self.model, a) for a in self._acts]

    def _substeps(self, period: float, where: str) -> int:
        return self.robot.substeps(period, where)

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
            self.real_radius = self.robot.real_radius
            self._changed = False
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[:] = self._qpos_rest
        d.ctrl[:] = self.robot.ctrl_rest
        # Turn the rest pose about the vertical through the site, then move the site to (x0, y0).
        p_site, yaw_site = self._site_rest
        turn = float(q0[2]) - yaw_site
        c, s = cos(turn), sin(turn)
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        root = slice(self._qroot, self._qroot + 7)
        pos, quat = d.qpos[root][:3].copy(), d.qpos[root][3:].copy()
        d.qpos[self._qroot : self._qroot + 3] = np.einsum("ij,j->i", Rz, pos - p_site) + [
            float(q0[0]),
            float(q0[1]),
            p_site[2],
        ]
        mujoco.mju_mulQuat(
            d.qpos[self._qroot + 3 : self._qroot + 7],
            np.array([cos(turn / 2), 0.0, 0.0, sin(turn / 2)]),
            quat,
        )
        mujoco.mj_forward(m, d)
        self._world_reset(q0, rng)  # on the terrain, not in it; the force schedule (mlpfac.plants.mujoco.world)
        if u0 is not None:
            self._set_velocity(float(u0[0]), float(u0[1]), float(q0[2]))
        self._z_rest = float(d.site_xpos[self._site, 2]) - self.ground(*d.site_xpos[self._site, :2])

        self.rng = rng
        self._n = self.n_substeps
        self._kp, self._ki = float(self.config.pi_kp or 0.0), float(self.config.pi_ki or 0.0)  # None: no PI loop
        self._umax()
        self._torque_max = self._force_limits()
        self.st = np.zeros(K.N_ST)
        self.st[K.S_THETA] = float(q0[2])
        self._pose_noise = Stream(rng if self._noise is not None else None, 3)
        self._history = DelayLine(np.zeros(3))  # one row, which the first measurement replaces
        self._views()
        K.read_pose(self._site_xpos, self._site_xmat, self.st)
        draw = self.draws(1)[0] if self._sensing is None else np.zeros(3)  # the robot knows where it starts
        K.measure(self.ints, self.fl, self.st, draw, self._history.hist, self._history.fill)
        if self.ints[K.I_TAU]:
            self._motion_rng = rng.spawn(1)[0]  # its own stream: the pose noise's is the same with or without it
        if self._sensing is not None:  # spawned after the motion's: a truth run's streams are as they were
            self._sense = self._sensing.start(rng, d.qpos, d.sensordata, self.true_pose())
            self._pack()
        if self.ints[K.I_TAU]:
            self._motion = DelayLine(np.zeros(4))
            v = np.zeros(6)
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, self._site, v, 0)
            th = float(q0[2])
            wheels = [s * d.qvel[dof] for s, dof in zip(self._sign, self._dofs, strict=True)]
            self._measure_motion(v[3] * cos(th) + v[4] * sin(th), v[2], *wheels)

    def _views(self) -> None:
        """What the compiled step reads and writes: the current model and data (their addresses and
        views into them, made again when an event replaces them), the robot's arrays, the delay line."""
        self._site_xpos, self._site_xmat = self.data.site_xpos[self._site], self.data.site_xmat[self._site]
        forces = self._push.shape[0] > 0  # the force applied, telemetry "force" (mlpfac.plants.mujoco.world)
        self.tele = np.zeros(K.N_TELE + 3 * forces + self._sensing_width())
        self._tele = {key: self.tele[2 * i : 2 * i + 2] for i, key in enumerate(K.TELEMETRY)}
        if forces:
            self._tele["force"] = self.tele[K.N_TELE : K.N_TELE + 3]
        self._tele |= self._sensing_telemetry(self.tele, K.N_TELE + 3 * forces)  # after the force's
        self._pack()

    def _pack(self) -> None:
        m, d = self.model, self.data
        self._args = K.Robot(m._address, d._address, d.ctrl, d.qvel, d.qpos, d.qfrc_actuator, self._site_xpos,
                             self._site_xmat, d.xmat[self._root], self.ints, self.fl, self.st, self._history.hist,
                             self._history.fill, np.empty(6), self._sense, d.sensordata,
                             # the world (mlpfac.plants.mujoco.world): empty without terrain or forces
                             d.xfrc_applied.reshape(-1), d.geom_xpos.reshape(-1), d.mocap_pos.reshape(-1),
                             d.mocap_quat.reshape(-1), m.geom_friction.reshape(-1), self._wld, self._nodes,
                             self._push)  # fmt: skip

    def kernel_args(self) -> K.Robot:
        """The robot as :func:`mlpfac.plants.mujoco.compiled.plant_step` takes it (valid until the next event),
        watched for MuJoCo's warnings until another robot is."""
        K.watch(self.st)
        return self._args

    @property
    def _torque_max(self) -> tuple[float, float]:
        return float(self.fl[K.F_TLMAX]), float(self.fl[K.F_TRMAX])

    @_torque_max.setter
    def _torque_max(self, limits: tuple[float, float]) -> None:
        self.fl[[K.F_TLMAX, K.F_TRMAX]] = limits

    @property
    def sim_time(self) -> float:
        return float(self.st[K.S_TIME])

    def elapsed(self, n: int) -> float:
        return self.sim_time

    def draws(self, n: int) -> np.ndarray:
        """The next n pose-noise draws (n, 3) of the plant's stream (zeros without noise); with a pose
        source other than the truth, its sensors' draws (n, 4) (:meth:`mlpfac.plants.sensors.sensing.Sensing.draws`)."""
        if self._sensing is not None:
            return self._sensing.draws(n)
        return self._pose_noise.take(n)

    def _set_velocity(self, v: float, omega: float, theta: float) -> None:
        """Body velocity (v, omega) at the site, the wheels rolling to match it."""
        m, d = self.model, self.data
        omega_w = np.array([0.0, 0.0, omega])
        v_site = np.array([v * cos(theta), v * sin(theta), 0.0])
        d.qvel[self._droot : self._droot + 3] = v_site + np.cross(omega_w, d.xpos[self._root] - d.site_xpos[self._site])
        d.qvel[self._droot + 3 : self._droot + 6] = np.einsum(
            "ji,j->i", d.xmat[self._root].reshape(3, 3), omega_w
        )  # local
        w = wheel_speeds(v, omega, self.real_radius, self._real_track)
        for dof, sign, wi in zip(self._dofs, self._sign, w, strict=True):
            d.qvel[dof] = sign * wi
        for a, c, wi in zip(self.robot.seconds, self.robot.second_per_wheel, w, strict=True):
            if a >= 0:  # a skid-steer's second wheel turns as its side's first
                d.qvel[m.jnt_dofadr[m.actuator_trnid[a, 0]]] = wi * c / m.actuator_gear[a, 0]
        mujoco.mj_forward(m, d)

    def true_pose(self) -> np.ndarray:
        return self.st[K.S_POSE : K.S_POSE + 3].copy()

    def measure(self) -> np.ndarray:
        return self._history.read()

    def step(self, u: np.ndarray) -> None:
        """One control step (:func:`mlpfac.plants.mujoco.compiled.plant_step`): u = (v, omega), or the wheels'
        torques (tau_l, tau_r) in N m after :meth:`torque_commands`."""
        K.watch(self.st)
        K.plant_step(float(u[0]), float(u[1]), self.draws(1)[0], self.tele, self._args)
        self.stepped()

    def stepped(self) -> None:
        """What follows the compiled step in Python (a kernel that steps many robots calls it after
        :func:`~mlpfac.plants.mujoco.compiled.plant_step` too): under a torque-level controller, the twist
        and wheel speeds measured with their noise."""
        if self._motion is not None:
            t = self.tele
            if self._sensing is not None:  # from the encoders and the gyro
                self._measure_motion(*self._tele["sensed"])
            else:
                self._measure_motion(t[2], t[3], t[6], t[7])

    def telemetry(self) -> dict[str, np.ndarray | float]:
        """``u_meas`` (2,) (v, omega) from the measured wheel speeds through the nominal FK;
        ``u_true`` (2,) (v, omega) of the axle midpoint (differs from u_meas by slip and radius);
        ``wheel_cmd``, ``wheel_meas`` (2,) left/right in rad/s (forward positive); ``torque`` (2,)
        wheel torques in N m (forward positive), of the last step. The arrays are the plant's own,
        overwritten by the next step: copy what you keep."""
        return self._tele

    def geometry(self) -> list[dict]:
        return self._geometry

    def turning_change(self, events: Sequence) -> tuple[float, float] | None:
        """What ``events``, applied in turn from the start, do to a skid-steer's turning, measured as
        it is while the robot settles (:func:`~mlpfac.plants.mjcf.settle.turning`) with them and
        without: the track it turns as with them over the one without, and how far its kinematic
        centre moved ahead of the pose frame [m]. None where the turning is not measured (a robot
        that is not a skid-steer, or does not turn). The plant is reset first, each time."""
        if self.robot.seconds == (-1, -1):
            return None
        (track0, ahead0, _), (track1, ahead1, _) = turning(self), turning(self, events)
        if not (math.isfinite(track0) and math.isfinite(track1)):
            return None
        return track1 / track0, ahead1 - ahead0


def _turns_end(description: str) -> int:
    """Where a skid-steer's description says the track it turns as, its end."""
    return description.index(")", description.index("; turning as a track of")) + 1


def robot_of(config: MujocoConfig, periods: tuple[float, ...]) -> Robot:
    """The robot a run of ``config`` has (control period ``periods[0]``): read, and a skid-steer's
    turning measured."""
    return MujocoPlant(config, periods[0], periods).robot
