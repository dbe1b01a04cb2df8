"""The robot measured against its world, at rest on the flat floor, before anything runs: what it
stands on (its wheels, casters and skids, the load each carries, how low the rest of it reaches),
what its wheels hold against a force (the tyres' traction, the motors), what a kerb asks of them
(the standard geometry of a wheel against a step), and what it cannot climb or hold, refused or said
in words for the run's first line. :class:`MujocoHolds` is the part of
:class:`~mlpfac.plants.mujoco.world.MujocoWorld` that does it.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plants.events import MU_MAX, Force
from mlpfac.plants.world.table import CURVATURE

# The highest step a wheel of radius r climbs is STEP_SHARE r: there the step's edge leans its force
# MU_MAX to 1 from the vertical (:func:`climb`): a driven wheel would need a tyre friction of MU_MAX, the
# most a scenario takes, and a free one (a caster) a push of MU_MAX times its load. 1 - 1 / sqrt(1 + MU_MAX^2).
STEP_SHARE = 1.0 - 1.0 / math.sqrt(1.0 + MU_MAX * MU_MAX)


class MujocoHolds:
    """The terrain's checks against the robot and what it holds (its attributes are
    :class:`~mlpfac.plants.mujoco.plant.MujocoPlant`'s)."""

    def _check_terrain(self, terrain, where: str) -> None:
        """What the robot needs of ``terrain``: tyres that can touch the bottom of the rough ground's
        troughs, ramps and kerbs clear of it at its start, wheels that can climb each ramp, kerbs lower
        than its wheels' and casters' axles, tyres whose friction is the contact's (patches)."""
        r = float(self.robot.real_radius)
        if terrain.bumps is not None and terrain.bumps.curvature * r > 1.0:
            b = terrain.bumps
            need = math.sqrt(CURVATURE * b.height * r)
            raise ConfigError(
                f"{where} bumps wavelength",
                f"a heightfield too fine for the tyre: its troughs curve at up to {b.curvature:.3g} 1/m, tighter than "
                f"the tyre's radius of {r:g} m; lengthen the wavelength to at least {need:.3g} m or lower the height",
            )
        if terrain.patches:
            self._tyres_take_friction(f"{where} patches")
        for key, features in (("ramps", terrain.ramps), ("kerbs", terrain.kerbs)):
            for i, ramp in enumerate(features):
                if ramp.near(*terrain.start) < self._reach:
                    raise ConfigError(
                        f"{where} {key} #{i + 1} {ramp.placed}",
                        f"the {key[:-1]} lies under the robot's wheels or casters at its start (within "
                        f"{self._reach:.2g} m of it; a run starts on the flat floor, where the robot settled): "
                        + ("place it further along the path" if ramp.placed == "at" else "move it"),
                    )
        g, r_foot, _ = min(self._footing, key=lambda f: f[1]) if terrain.kerbs else (0, 0.0, 0.0)
        for i, kerb in enumerate(terrain.kerbs):
            if kerb.height > STEP_SHARE * r_foot:
                raise ConfigError(
                    f"{where} kerbs #{i + 1} height",
                    f"{kerb.height:g} m is more than {STEP_SHARE:.3f} of the radius of the robot's "
                    f"{'wheel' if g in self._tyres else 'caster'} ({r_foot:.3g} m): the step's edge would push it "
                    f"back more than {MU_MAX:g} times as hard as up (a tyre would need a friction above {MU_MAX:g}, the "
                    f"most a scenario takes; at the axle's height, a wall); lower it to {STEP_SHARE * r_foot:.3g} m",
                )
        mass, g = self.weight()
        _, drive, share, mu = self.holds()
        for i, ramp in enumerate(terrain.ramps):
            tan = ramp.height / ramp.up
            sin = tan / math.sqrt(1.0 + tan * tan)
            pull = mass * g * sin
            if pull > drive or tan > mu * share:
                why = (
                    f"its wheels' torque gives {drive:.3g} N"
                    if pull > drive
                    else f"the tyres' friction {mu:g} on the {share:.0%} of its weight its wheels carry holds a slope of "
                    f"at most {math.degrees(math.atan(mu * share)):.3g} deg"
                )
                raise ConfigError(
                    f"{where} ramps #{i + 1}",
                    f"the wheels cannot climb it: a slope of {math.degrees(math.atan(tan)):.3g} deg pulls the "
                    f"{mass:.3g} kg robot back with {pull:.3g} N, and {why}; lower it or lengthen it",
                )

    def _tyres_take_friction(self, where: str) -> None:
        """A ConfigError unless the tyres' contact priority is above the floor's (their friction is the contact's)."""
        m = self.model
        others = [g for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] != self._root]
        floor = max((int(m.geom_priority[g]) for g in others), default=-1)
        if any(m.geom_priority[g] <= floor for g in self._tyres):
            raise ConfigError(
                where,
                f"the tyre geoms need a priority above the floor's ({floor}) for their friction to be the "
                'contact\'s: give them one in the model, or set tyre = "sphere" in [plant]',
            )

    def weight(self) -> tuple[float, float]:
        """The robot's mass (kg, at the start: its nominal model's) and gravity's magnitude (m/s^2): what
        a force given relative to it is put in newtons with (:func:`mlpfac.plants.world.forces.in_newtons`)."""
        m0 = self.robot.model
        return float(m0.body_subtreemass[self._root]), float(np.sqrt(np.sum(m0.opt.gravity * m0.opt.gravity)))

    def each_wheel(self) -> float:
        """The torque each driven wheel gives with both pushing forward (N m; inf without a limit): its
        motor's limit, or a tendon drive's forward motor's shared by the two."""
        tl, tr = self._torque_max
        return min(tl, tr) / 2 if self.robot.mix is not None else min(tl, tr)

    def holds(self) -> tuple[float, float, float, float]:
        """What the robot's wheels hold against a force along the floor (N), at rest on the flat floor:
        the tyres' traction mu x its weight's share on the driven wheels x m g, the motors' torque
        limits / the wheels' radius (:meth:`each_wheel`; inf without a limit); and that share and mu."""
        m0 = self.robot.model
        mass, g = self.weight()
        share = _on_wheels(m0, self.robot.qpos_rest, self._tyres, mass * g)
        mu = float(m0.geom_friction[self._tyres[0], 0])
        drive = 2.0 * self.each_wheel() * (len(self._tyres) // 2) / float(self.robot.real_radius)
        return mu * share * mass * g, drive, share, mu

    def kerb_need(self, h: float) -> tuple[float, float, str]:
        """What climbing a step of ``h`` m from rest asks of the robot (:func:`climb`, each foot with the
        load it carries at rest): the torque a driven wheel needs (N m: the larger of climbing it on its
        own, and pushing the most loaded caster up it, shared by the driven wheels), the friction its
        tyres need at the edge, and which of the two the torque is for, in words."""
        r = float(self.robot.real_radius)
        wheel, caster, tan = 0.0, 0.0, 0.0
        for g, reach, load in self._footing:
            d, t = climb(reach, h)
            if g in self._tyres:
                wheel, tan = max(wheel, load * d), max(tan, t)
            else:
                caster = max(caster, load * t * r / len(self._tyres))
        if caster > wheel:
            return caster, tan, "to push its caster up it"
        return wheel, tan, "to climb it (W sqrt(2 r h - h^2))"

    def _kerb_said(self, i: int, h: float) -> str:
        """Kerb #i's need from rest (:meth:`kerb_need`), in words."""
        need, _, what = self.kerb_need(h)
        return f"kerb #{i + 1} ({h * 1e3:.3g} mm) asks {need:.3g} N m a driven wheel from rest {what}"

    def world_need(self) -> str:
        """What the kerbs ask of the motors from rest (:meth:`kerb_need`), in words for the run's
        ``world:`` line ('' without kerbs)."""
        kerbs = () if self.terrain is None else self.terrain.kerbs
        if not kerbs:
            return ""
        limit = self.each_wheel()
        of = f", of the {limit:.3g} N m a wheel the motors give" if math.isfinite(limit) else ""
        return ", ".join(self._kerb_said(i, k.height) for i, k in enumerate(kerbs)) + of

    def world_warning(self) -> str:
        """What the robot cannot hold of its world, in words for the run's first line ('' when it holds
        all): a force beyond its tyres' traction or its motors (:meth:`holds`), a kerb its motors or
        its tyres' friction cannot climb from rest, or that its chassis meets."""
        traction, drive, share, mu = self.holds()
        mass, g = self.weight()
        out = []
        limit = self.each_wheel()
        for i, k in enumerate(() if self.terrain is None else self.terrain.kerbs):
            need, tan, _ = self.kerb_need(k.height)
            beyond = [f"of motors that give {limit:.3g} N m"] * (need > limit)
            beyond += [f"a friction of {tan:.2g} at its edge, of tyres that have {mu:g}"] * (tan > mu)
            beyond += [f"a clearance its chassis lacks ({self._low * 1e3:.3g} mm at rest)"] * (k.height >= self._low)
            if beyond:
                out.append(
                    f"{self._kerb_said(i, k.height)}, {', and '.join(beyond)}: the robot climbs it on its momentum, "
                    "or not at all"
                )
        for given, f in zip(self._given, self._forces, strict=True):
            if not isinstance(f, Force):
                continue
            noise = 3.0 * (f.std or 0.0)
            fx, fy = f.fx or 0.0, f.fy or 0.0
            size = math.sqrt(fx * fx + fy * fy) + noise
            along = size if f.frame in (None, "world") else abs(fx) + noise  # what the motors meet
            beyond = [
                f"the tyres' traction ({mu:g} x {share:.0%} of the {mass * g:.4g} N weight on the driven wheels: "
                f"{traction:.3g} N)"
            ] * (size > traction)
            beyond += [f"the motors ({drive:.3g} N at the wheels' rims)"] * (along > drive)
            if beyond:
                out.append(
                    f"the force at {given.time:g} s ({size:.3g} N{' with its noise (3 std)' if noise else ''}, "
                    f"{size / (mass * g):.2g} m g) exceeds what {' and '.join(beyond)} can hold: "
                    + ("the wheels slide" if size > traction else "the robot is pushed back")
                )
        return "; ".join(out)


def floor_height(m: mujoco.MjModel, qpos: np.ndarray, root: int) -> float:
    """The floor's height under the robot at rest: where its contacts with the scene are (m)."""
    d = _at_rest(m, qpos)
    mine = {g for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] == root}
    z = [float(c.pos[2]) for c in d.contact[: d.ncon] if (int(c.geom1) in mine) != (int(c.geom2) in mine)]
    return sum(z) / len(z) if z else 0.0


def _at_rest(m: mujoco.MjModel, qpos: np.ndarray) -> mujoco.MjData:
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_forward(m, d)
    return d


def feet_at_rest(
    m: mujoco.MjModel, qpos: np.ndarray, root: int, floor: float
) -> tuple[list[tuple[int, float, float, float]], float, float]:
    """The robot's geoms that touch the floor at rest (its tyres, casters, skids), each with where it
    is: (x, y) and the height of its centre above the floor (its reach below it); and how high above
    the floor the lowest point of its other colliding geoms is at rest (m): a bound (each geom's
    bounding box: the rough ground's heightfield is built where the robot may reach it) and the
    lowest point itself (a mesh's lowest vertex: the clearance a kerb is measured against)."""
    d = _at_rest(m, qpos)
    mine = [g for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] == root]
    feet = sorted({int(g) for c in d.contact[: d.ncon] for g in (c.geom1, c.geom2) if int(g) in mine})
    bound, low = np.inf, np.inf
    for g in mine:
        if g not in feet and (m.geom_contype[g] or m.geom_conaffinity[g]):
            bound, low = min(bound, _lowest(m, d, g, False) - floor), min(low, _lowest(m, d, g, True) - floor)
    x = d.geom_xpos
    return [(g, float(x[g, 0]), float(x[g, 1]), float(x[g, 2]) - floor) for g in feet], bound, low


def _lowest(m: mujoco.MjModel, d: mujoco.MjData, g: int, exact: bool) -> float:
    """The lowest point of geom ``g`` (z, m): its bounding box's, or (``exact``) a mesh's lowest vertex."""
    R = d.geom_xmat[g].reshape(3, 3)
    if exact and int(m.geom_type[g]) == mujoco.mjtGeom.mjGEOM_MESH and m.geom_dataid[g] >= 0:
        mesh = int(m.geom_dataid[g])
        v = m.mesh_vert[m.mesh_vertadr[mesh] : m.mesh_vertadr[mesh] + m.mesh_vertnum[mesh]]
        return float(d.geom_xpos[g, 2]) + min(float(R[2, 0] * x + R[2, 1] * y + R[2, 2] * z) for x, y, z in v)
    c, h = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
    return float(d.geom_xpos[g, 2] + sum(R[2, k] * c[k] for k in range(3)) - sum(abs(R[2, k]) * h[k] for k in range(3)))


def carried(m: mujoco.MjModel, qpos: np.ndarray, geoms) -> dict[int, float]:
    """The normal force (N) each of ``geoms`` carries at rest, by geom."""
    d = _at_rest(m, qpos)
    f, out = np.zeros(6), dict.fromkeys(geoms, 0.0)
    for i in range(d.ncon):
        for g in (int(d.contact[i].geom1), int(d.contact[i].geom2)):
            if g in out:
                mujoco.mj_contactForce(m, d, i, f)
                out[g] += abs(float(f[0]))
    return out


def _on_wheels(m: mujoco.MjModel, qpos: np.ndarray, tyres, weight: float) -> float:
    """The share of the robot's weight its tyres carry at rest (the rest of it on casters and skids)."""
    on = sum(carried(m, qpos, tyres).values())
    return min(1.0, on / weight) if weight > 0 else 1.0


def climb(r: float, h: float) -> tuple[float, float]:
    """A wheel of radius ``r`` against a step of height ``h`` < r, at rest, touching its edge alone
    (the standard geometry): the edge lies sqrt(2 r h - h^2) ahead of the axle and r - h below it, so
    a driven wheel carrying W climbs it with a torque W sqrt(2 r h - h^2) about its axle, and the edge's
    force leans tan(a) = sqrt(2 r h - h^2) / (r - h) from its normal: the friction the tyre needs there,
    and the push W tan(a) a free wheel (a caster) needs at its axle. Returns (sqrt(2 r h - h^2), tan(a))."""
    d = math.sqrt(h * (2.0 * r - h))
    return d, d / (r - h)
