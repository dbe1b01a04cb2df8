"""What an event does to a MuJoCo robot: checked against the robot before the run, then applied
mid-run by editing the model's :class:`mujoco.MjSpec` and recompiling it with the state kept
(``spec.recompile``), so a changed model is exactly the model one would compile with the new
numbers (masses, inertias and every derived constant included); nothing edits XML text.
:class:`MujocoEvents` is the part of :class:`~mlpfac.plants.mujoco.plant.MujocoPlant` that does it.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plants.events import (
    Actuator,
    ControlPeriod,
    Event,
    Force,
    Friction,
    Payload,
    SensorDelay,
    Slope,
    WheelRadius,
)
from mlpfac.plants.mjcf.detect import ROUND


class MujocoEvents:
    """check_event / apply of the MuJoCo plant (its attributes are :class:`MujocoPlant`'s)."""

    def check_event(self, event: Event, where: str) -> None:
        """What this robot needs to apply ``event`` (its parameters were checked when it was parsed)."""
        if isinstance(event, ControlPeriod):
            self._substeps(event.factor * self.T, f"{where} factor")
        elif isinstance(event, Payload):
            self._payload_bodies(event, where)
        elif isinstance(event, Friction):
            self._tyres_take_friction(where)
        elif isinstance(event, WheelRadius):
            if any(int(self.model.geom_type[g]) not in ROUND for g in self._tyres):
                raise ConfigError(
                    where,
                    'the wheels collide through meshes, which this event cannot resize: set tyre = "sphere" in [plant]',
                )
            if event.scale < 1 and not self._wheels_reach_floor(event.scale):
                raise ConfigError(
                    f"{where} scale",
                    f"wheels of {event.scale * self.robot.real_radius:g} m no longer reach the floor: the robot "
                    "stands on its other contacts (casters), and could not drive",
                )

    def _wheels_reach_floor(self, scale: float) -> bool:
        """Whether both tyres, scaled, still touch the floor once the robot has settled at rest."""
        spec = self._spec_nominal.copy()
        for g in self._tyres:
            spec.geoms[g].size[0] *= scale
        m = spec.compile()
        d = mujoco.MjData(m)
        d.qpos[:], d.ctrl[:] = self._qpos_rest, self.robot.ctrl_rest
        mujoco.mj_step(m, d, nstep=int(round(0.5 / self._dt)))
        touching = {int(g) for c in d.contact[: d.ncon] for g in c.geom}
        return all(g in touching for g in self._tyres)

    def _payload_bodies(self, event: Payload, where: str) -> list[int]:
        """The bodies a payload event scales: the root body, a named body, or the whole robot ("*")."""
        m = self.model
        if event.body is None:
            return [self._root]
        if event.body == "*":
            return [b for b in range(1, m.nbody) if m.body_rootid[b] == self._root and m.body_mass[b] > 0]
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, event.body)
        if b <= 0 or m.body_rootid[b] != self._root:
            raise ConfigError(f"{where} body", f"no body named {event.body!r} on the robot in {self._where}")
        if m.body_mass[b] <= 0:
            raise ConfigError(f"{where} body", f"body {event.body!r} has no mass to scale")
        return [b]

    def _place_load(self, event: Payload) -> str:
        """A point mass ``mass_kg`` on the root body at (offset, lateral) of the pose frame, at the
        height of the body's centre of mass: the body's inertial becomes the two's (parallel axes)."""
        m, d, b = self.model, self.data, self._root
        R = d.xmat[b].reshape(3, 3)  # root body -> world
        to_body = lambda w: [sum(R[i, j] * w[i] for i in range(3)) for j in range(3)]  # noqa: E731 (R' w)
        axes = d.site_xmat[self._site].reshape(3, 3)
        site = to_body(d.site_xpos[self._site] - d.xpos[b])
        fwd, left = to_body(axes[:, 0]), to_body(axes[:, 1])
        a, lat, mp = event.offset or 0.0, event.lateral or 0.0, float(event.mass_kg)
        c, M = [float(x) for x in m.body_ipos[b]], float(m.body_mass[b])
        p = [site[i] + a * fwd[i] + lat * left[i] for i in range(2)] + [c[2]]
        c_new = [(M * c[i] + mp * p[i]) / (M + mp) for i in range(3)]
        Q = np.zeros(9)
        mujoco.mju_quat2Mat(Q, m.body_iquat[b])  # principal axes -> body
        Q, Ip = Q.reshape(3, 3), [float(x) for x in m.body_inertia[b]]
        inertia = [[sum(Q[i, k] * Ip[k] * Q[j, k] for k in range(3)) for j in range(3)] for i in range(3)]
        for mass, at in ((M, c), (mp, p)):  # parallel axes to the new centre of mass
            r = [at[i] - c_new[i] for i in range(3)]
            r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
            for i in range(3):
                for j in range(3):
                    inertia[i][j] += mass * ((r2 if i == j else 0.0) - r[i] * r[j])
        body = self._spec.bodies[b]
        body.explicitinertial = True
        body.mass, body.ipos, body.inertia = M + mp, c_new, [0.0] * 3  # the full tensor instead
        body.fullinertia = [inertia[0][0], inertia[1][1], inertia[2][2], inertia[0][1], inertia[0][2], inertia[1][2]]
        self._recompile()
        name = m.body(b).name or f"body {b}"
        com = self.model.body_subtreemass[b]
        return (
            f"{mp:g} kg placed {a:g} m ahead, {lat:g} m left of the axle on {name} ({M:g} -> {M + mp:g} kg; "
            f"robot {float(com):g} kg)"
        )

    def apply(self, event: Event) -> str:
        self.check_event(event, event.kind)
        m = self.model
        if isinstance(event, ControlPeriod):
            old, self._n = self._n, self._substeps(event.factor * self.T, "factor")
            return f"plant holds each command {old * self._dt:g} -> {self._n * self._dt:g} s ({self._n} physics steps; controller keeps T = {self.T:g} s)"
        if isinstance(event, Slope):
            return self._slope(event)
        if isinstance(event, Force):
            return self._force_text(event)
        if isinstance(event, SensorDelay):
            text = self._history.delay(event.steps)
            if self._motion is not None:  # the twist and the wheel speeds a torque-level controller sees
                self._motion.delay(event.steps)
            self._pack()
            return text
        spec = self._spec
        if isinstance(event, Payload) and event.placed:
            return self._place_load(event)
        if isinstance(event, Payload):
            bodies = self._payload_bodies(event, "")
            mass = float(sum(m.body_mass[b] for b in bodies))
            k = event.mass_scale if event.mass_scale is not None else (mass + event.mass_kg) / mass
            for b in bodies:
                body = spec.bodies[b]
                body.explicitinertial = True  # pin the compiled inertial (it may have come from geoms), then scale it
                body.mass, body.ipos, body.iquat = (
                    k * float(m.body_mass[b]),
                    m.body_ipos[b].copy(),
                    m.body_iquat[b].copy(),
                )
                body.inertia, body.fullinertia[0] = k * m.body_inertia[b], math.nan
            self._recompile()
            name = "the whole robot" if event.body == "*" else m.body(bodies[0]).name or f"body {bodies[0]}"
            new = float(sum(self.model.body_mass[b] for b in bodies))
            return f"{name} mass {mass:g} -> {new:g} kg (inertia x{k:g}; robot {float(self.model.body_subtreemass[self._root]):g} kg)"
        if isinstance(event, Friction):
            old = float(m.geom_friction[self._tyres[0], 0])
            for g in self._tyres:
                spec.geoms[g].friction[0] = event.mu
            self._recompile()
            self._world_friction(event.mu)
            return f"tyre/floor sliding friction {old:g} -> {event.mu:g}"
        if isinstance(event, WheelRadius):
            k = event.scale
            for b in self._wheel_bodies:  # the tyres and the round visual wheels
                for geom in spec.bodies[b].geoms:
                    if int(geom.type) in ROUND:
                        geom.size[0] *= k
            old = self.real_radius
            self.real_radius = k * old
            self._recompile()
            lift = self.real_radius - old  # stand the robot on its new wheels (the casters then settle)
            self.data.qpos[self._qroot + 2] += lift
            self._z_rest += lift
            mujoco.mj_forward(self.model, self.data)
            return f"real wheel radius {old:g} -> {self.real_radius:g} m (the IK keeps {self.ik_radius:g} m)"
        assert isinstance(event, Actuator)
        kv = event.kv_scale if event.kv_scale is not None else 1.0
        fs = event.force_scale if event.force_scale is not None else 1.0
        old_limit = self._torque_max[0]
        for a in (*self._acts, *(a for a in self.robot.seconds if a >= 0)):
            act = spec.actuators[a]
            act.forcerange = fs * np.asarray(act.forcerange)
            if int(m.actuator_trntype[a]) == mujoco.mjtTrn.mjTRN_JOINT:
                joint = spec.joints[int(m.actuator_trnid[a, 0])]
                joint.actfrcrange = fs * np.asarray(joint.actfrcrange)
            if self.config.actuator == "velocity":
                act.gainprm[0] *= kv
                act.biasprm[2] *= kv
            else:
                act.ctrlrange = fs * np.asarray(act.ctrlrange)
        self._recompile()
        self._umax()
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
        self._views()
        self._changed = True
