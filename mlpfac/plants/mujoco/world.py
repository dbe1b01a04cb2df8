"""The world around a MuJoCo robot: the terrain of a scenario's ``[world]`` built into the scene the
plant compiles (the robot's files are never edited), the floor tilted by a ``slope`` event, and
the forces of ``force`` events. :class:`MujocoWorld` is the part of
:class:`~mlpfac.plants.mujoco.plant.MujocoPlant` that does it.

- **Ramps and kerbs**: one convex mesh each (a trapezoid prism: up, top, down; a kerb's a box, its
  steps vertical), a static geom of the world. What the robot can climb and hold is
  :mod:`mlpfac.plants.mujoco.holds`'s.
- **Rough ground**: the wheels and casters (the geoms the robot stands on at rest) touch it
  through a contact tile each, the surface's tangent plane under the geom moved before every
  physics step (:func:`mlpfac.plants.world.terrain.place_tiles`: MuJoCo's sphere-on-heightfield test
  would cost a step 2.5x over); a MuJoCo heightfield of the heights drawn for the run
  (:mod:`mlpfac.plants.world.layout`) is there for the rest of the robot, where it reaches that low.
- **Sprung casters**: a robot on more than three points gets its casters' contacts soft on
  terrain (a rigid chassis on four points lifts a drive wheel off uneven ground).
- **Patches**: flush with the floor, so no geom: each control step, the compiled step sets each
  tyre's sliding friction to the patch's under its centre, or to its own off the patches
  (:func:`mlpfac.plants.world.terrain.patches`). A flush geom with a contact priority would touch the
  tyre together with the floor, at the same point, and MuJoCo would share the normal force between
  two frictions; a patch a millimetre proud of the floor would be a step.
- **Slope**: gravity turned in the floor's frame at the event (the robot settled on the flat floor
  first: a scene tilted from the start fails the settle check); the viewer draws the floor tilted.
- **Forces**: in newtons for this robot (a force given relative to it:
  :func:`mlpfac.plants.world.forces.in_newtons`), a schedule per control step
  (:func:`mlpfac.plants.world.forces.force_schedule`, made at reset from the run's seed) that the compiled step writes into ``xfrc_applied`` of the root body
  every control step (MuJoCo keeps it across physics steps), turned into the world's axes when it
  is the robot's (:func:`mlpfac.plants.world.terrain.push`); telemetry ``force`` says what was applied.

The new geoms take the floor's friction and contact priority, so the tyres' friction stays the
contact's, as on the floor, and sit at the floor's height (read from the robot's contacts at rest:
a Menagerie scene's floor is not always at 0). A robot reset at a pose over the terrain is lifted
onto it (the highest ground under its wheels and casters); at a run's start it stands on the flat
pad the rough ground leaves there and on no ramp, as it settled.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from mlpfac.exceptions import ConfigError
from mlpfac.plants.events import Force, Slope
from mlpfac.plants.mjcf.wheels import floor_priority
from mlpfac.plants.mujoco.holds import MujocoHolds, carried, feet_at_rest, floor_height
from mlpfac.plants.world import terrain as W  # noqa: N812 - the packed world's layout, W.W_STEP ...
from mlpfac.plants.world.forces import RELATIVE, force_schedule, in_newtons_all, run_seed

FORCE_COLUMNS = 5  # a force schedule's row: world (fx, fy), robot (fx, fy), torque_z
HFIELD_BASE = 0.05  # m of the heightfield's base below the floor (MuJoCo's size[3])
TILE_SIZE = 0.5  # m: half the width a contact tile is drawn (a plane: it moves with its geom)
CLEARANCE = 1.5  # the heightfield collides where the robot's other geoms reach within this x its height at rest
SPRUNG_S = 0.2  # s: the time constant of a sprung caster's contact (MuJoCo's is 0.02 s: rigid)


class MujocoWorld(MujocoHolds):
    """set_world, the terrain's checks, the slope and the forces of the MuJoCo plant (its attributes
    are :class:`~mlpfac.plants.mujoco.plant.MujocoPlant`'s)."""

    def _no_world(self) -> None:
        """No terrain, no force: nothing packed, nothing done in the step (the bits of a run without them)."""
        self.terrain, self._forces, self._given, self._steps = None, (), (), 0
        self._wld, self._nodes = np.zeros(0), np.zeros((0, 0))
        self._push, self._force_now = np.zeros((0, FORCE_COLUMNS)), np.zeros(3)
        self._reach, self._footing, self._low = 0.0, [], math.inf  # how far the robot reaches; its feet at rest

    def set_world(
        self, terrain, events=(), steps: int = 0, where: str = "[world]", events_where: str = "[[events]]"
    ) -> None:
        """Build ``terrain`` (a :class:`~mlpfac.plants.world.layout.Terrain`, or None) into the robot's scene,
        checked against the robot first, and apply the ``force`` events of ``events`` over a run of
        ``steps`` control steps from each reset on, in newtons for this robot (a force given relative
        to it: :func:`mlpfac.plants.world.forces.in_newtons`; ``events_where`` names them in errors)."""
        self._given = tuple(events)
        self._forces, self._steps = in_newtons_all(events, *self.weight(), self.T, events_where), int(steps)
        tiles, floor = (), 0.0
        if terrain is not None:
            m0, rest = self.robot.model, self.robot.qpos_rest
            floor = floor_height(m0, rest, self._root)
            feet, low, clear = feet_at_rest(m0, rest, self._root, floor)
            loads = carried(m0, rest, [g for g, *_ in feet])
            self._footing, self._low = [(g, reach, loads[g]) for g, _, _, reach in feet], clear
            site = self.robot.site_rest[0]
            self._reach = max(
                math.sqrt((x - site[0]) * (x - site[0]) + (y - site[1]) * (y - site[1])) + r for _, x, y, r in feet
            )
            self._check_terrain(terrain, where)
            spec = self._spec_nominal.copy()
            tiles = _build(spec, terrain, m0, self._root, floor, feet, low, self._tyres, where)
            self._spec_nominal, self._spec = spec, spec.copy()
            self.model = spec.compile()
            self.data = mujoco.MjData(self.model)
            body = lambda name: mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)  # noqa: E731
            tiles = [(g, int(self.model.body_mocapid[body(b)]), reach) for g, b, reach in tiles]
        self.terrain = terrain
        has_force = any(isinstance(ev, Force) for ev in self._forces)
        if terrain is not None or has_force:
            mus = [float(self.model.geom_friction[g, 0]) for g in self._tyres]
            self._wld, self._nodes = W.pack(terrain, self._tyres, mus, tiles, floor)
        self._changed = True  # the next reset starts from the nominal scene, with the world

    def _world_reset(self, q0: np.ndarray, rng: np.random.Generator) -> None:
        """At a reset: the robot lifted onto the terrain under its footprint (not into it), the tyres'
        own friction, the force schedule of this run (from its seed) from its first step."""
        if self._wld.shape[0] == 0:
            return
        self._wld[W.W_STEP] = 0.0
        if self.terrain is not None:
            lift = self._ground_under(float(q0[0]), float(q0[1]), self._reach)
            if lift > 0.0:
                self.data.qpos[self._qroot + 2] += lift
                mujoco.mj_forward(self.model, self.data)
            if self._wld[W.W_NTILE] > 0:  # the contact tiles under the wheels and casters where they stand
                d = self.data
                W.place_tiles(self._wld, self._nodes, d.geom_xpos.reshape(-1), d.mocap_pos.reshape(-1),
                              d.mocap_quat.reshape(-1))  # fmt: skip
                mujoco.mj_forward(self.model, d)
        o = W.offsets(self._wld)[2]
        for k, g in enumerate(self._tyres):
            self.model.geom_friction[g, 0] = self._wld[o + W.W_TYRE * k + 1]
        sched = force_schedule(self._forces, self.T, self._steps, run_seed(rng))
        self._push = np.zeros((0, FORCE_COLUMNS)) if sched is None else sched

    def ground(self, x: float, y: float) -> float:
        """The ground's height at (x, y) (m; 0 without terrain)."""
        return float(W.ground_height(self._wld, self._nodes, float(x), float(y))) if self._wld.shape[0] else 0.0

    def _ground_under(self, x: float, y: float, reach: float) -> float:
        """The highest ground within ``reach`` of (x, y), sampled every 1 cm (and at every heightfield point)."""
        step = 0.01
        if self._nodes.shape[0]:
            step = min(step, 0.25 * float(self._wld[W.W_BS]))
        n = int(math.ceil(reach / step))
        best = 0.0
        for i in range(-n, n + 1):
            for j in range(-n, n + 1):
                if (i * i + j * j) * step * step <= reach * reach:
                    best = max(best, self.ground(x + i * step, y + j * step))
        return best

    def _world_friction(self, mu: float) -> None:
        """A ``friction`` event: the tyres' own friction off the patches is now ``mu``."""
        if self._wld.shape[0]:
            o = W.offsets(self._wld)[2]
            self._wld[o + 1 : o + W.W_TYRE * len(self._tyres) : W.W_TYRE] = mu

    def _slope(self, event: Slope) -> str:
        """The floor tilted: gravity turned in its frame (the nominal gravity's magnitude)."""
        g0 = self.robot.model.opt.gravity
        g = float(np.sqrt(np.sum(g0 * g0)))
        gx, gy, gz = event.gravity(g)
        self._spec.option.gravity = [gx, gy, gz]
        self._recompile()
        toward = f" uphill towards {event.heading_deg or 0.0:g} deg" if event.angle_deg else " (level)"
        return f"floor tilted {event.angle_deg:g} deg{toward}: gravity pulls {math.sqrt(gx * gx + gy * gy):.3g} m/s^2 downhill"

    @property
    def forces(self) -> tuple:
        """The run's events, each ``force`` among them in the newtons this robot is given (in their places)."""
        return self._forces

    def _force_text(self, event: Force) -> str:
        f = in_newtons_all((event,), *self.weight(), self.T)[0]  # in newtons, as the plant applies it
        unit = {"fx_mg": " m g", "fy_mg": " m g", "std_mg": " m g", "dv_x": " m/s", "dv_y": " m/s"}

        def said(key: str) -> str:
            rel = [k for k in RELATIVE[key] if getattr(event, k) is not None]
            return f" ({rel[0]} {getattr(event, rel[0]):g}{unit[rel[0]]})" if rel else ""

        parts = [f"{k} {v:.4g} N{said(k)}" for k, v in (("fx", f.fx), ("fy", f.fy)) if v]
        parts += [f"torque_z {f.torque_z:g} N m"] if f.torque_z else []
        what = ", ".join(parts)
        if f.std:
            gust = "a control step" if f.tau_s is None else f"a gust of correlation time {f.tau_s:g} s"
            what = (what + " + " if what else "") + f"noise of {f.std:.4g} N std{said('std')}, {gust}"
        how = f" for {event.steps(self.T) * self.T:g} s" if event.duration is not None else " from now on"
        wave = f", sinusoidal of period {event.period:g} s" if event.period is not None else ""
        return f"force {what} in the {event.frame or 'world'}'s axes on the robot{wave}{how}"

    def world_said(self) -> str:
        """What the terrain is built of on this robot, in words (its ``[provenance] world``)."""
        t, m, parts = self.terrain, self.model, []
        if t.ramps:
            parts.append(f"{len(t.ramps)} ramp{'s' * (len(t.ramps) > 1)} (convex meshes)")
        if t.kerbs:
            parts.append(f"{len(t.kerbs)} kerb{'s' * (len(t.kerbs) > 1)} (convex meshes)")
        if t.grid is not None:
            tiles = int(self._wld[W.W_NTILE])
            hfield = (
                f"a heightfield of {m.hfield_nrow[0]} x {m.hfield_ncol[0]} points" if m.nhfield else "no heightfield"
            )
            parts.append(f"rough ground under {tiles} contact tiles, {hfield} for the rest of the robot")
        if t.patches:
            parts.append(f"{len(t.patches)} floor patch{'es' * (len(t.patches) > 1)} (the tyres' friction switched)")
        sprung = [g for g in range(m.ngeom) if m.geom_solref[g, 0] == SPRUNG_S]
        if sprung:
            parts.append(f"{len(sprung)} casters sprung (contact time constant {SPRUNG_S:g} s)")
        return f"{'; '.join(parts)}; the floor at z = {float(self._wld[W.W_Z0]):.4g} m"

    def terrain_record(self) -> dict:
        """What a recording draws of the terrain (:meth:`mlpfac.plants.world.layout.Terrain.as_dict`; {} without)."""
        return {} if self.terrain is None else self.terrain.as_dict()


def _build(
    spec: mujoco.MjSpec, terrain, m: mujoco.MjModel, root: int, z0: float, feet: list, low: float, tyres, where: str
) -> list:
    """The terrain's ramps (convex meshes) and rough ground in ``spec``, with the floor's friction,
    contact priority and contact bits (``m``: the robot's nominal model), on a static body of their
    own (the robot's geoms keep their ids) at the floor's height ``z0``. ``feet`` (geom, x, y, reach)
    are the robot's geoms on the floor at rest, ``low`` how high the lowest of its others is. The
    rough ground: a contact tile for each foot (a plane on a mocap body,
    :mod:`mlpfac.plants.world.terrain`), which that foot alone touches: its contact bits become its tile's
    and the ramps' (bits no geom uses), so it no longer touches the floor; and the heightfield, which
    the rest of the robot touches, where it reaches that low at rest (within ``CLEARANCE`` x the
    height: the heightfield's test costs a physics step as much as the robot's others). A robot on
    more than three feet (casters ahead of and behind its wheels, which a rigid chassis cannot keep
    all on uneven ground) has its casters sprung: their contacts soft (MuJoCo's solref, time
    constant ``SPRUNG_S``), as such robots' casters are. Returns (foot, its tile's body, its
    reach below its centre) of each tile."""
    scene = [g for g in range(m.ngeom) if m.body_rootid[m.geom_bodyid[g]] != root]
    top = max(scene, key=lambda g: int(m.geom_priority[g])) if scene else None
    look = {
        "priority": floor_priority(m, root),
        "friction": m.geom_friction[top].copy() if top is not None else [1.0, 0.005, 0.0001],
        "condim": int(m.geom_condim[top]) if top is not None else 3,
        "rgba": [0.45, 0.42, 0.38, 1.0],
    }
    ct, ca = (int(m.geom_contype[top]), int(m.geom_conaffinity[top])) if top is not None else (1, 1)
    if len(feet) > 3:  # a chassis on more than three points: its casters sprung
        for g, *_ in feet:
            if g not in tyres:
                spec.geoms[g].solref = [SPRUNG_S, 1.0]
    if terrain.grid is None:
        feet = []
    used = 0
    for g in range(m.ngeom):
        used |= int(m.geom_contype[g]) | int(m.geom_conaffinity[g])
    free = [1 << k for k in range(31) if not used & (1 << k)]
    if len(free) < len(feet) + 1:
        raise ConfigError(
            f"{where} bumps",
            f"the robot's model uses {31 - len(free)} of MuJoCo's 31 contact bits; the rough ground needs "
            f"{len(feet) + 1} free ones (one for each of its {len(feet)} geoms on the floor, one for the ramps)",
        )
    ramp_bit = free[-1] if feet else 0
    hfield = terrain.grid is not None and low < CLEARANCE * terrain.bumps.height
    ground = spec.worldbody.add_body(name="mlpfac_ground", pos=[0.0, 0.0, z0]) if terrain.raised or hfield else None
    for i, r in enumerate(terrain.raised):
        name = f"mlpfac_kerb_{i - len(terrain.ramps)}" if r.kerb else f"mlpfac_ramp_{i}"
        spec.add_mesh(name=name, uservert=r.corners().ravel().tolist())
        ground.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name, contype=ct, conaffinity=ca | ramp_bit,
                        **look)  # fmt: skip
    if hfield:
        x0, y0, x1, y1 = terrain.arena
        nrow, ncol = terrain.grid.shape
        height = float(terrain.grid.max())  # the heightfield's top: MuJoCo scales its data to [0, 1]
        spec.add_hfield(name="mlpfac_bumps", nrow=nrow, ncol=ncol, size=[(x1 - x0) / 2, (y1 - y0) / 2, height,
                        HFIELD_BASE], userdata=(terrain.grid / height).ravel().tolist())  # fmt: skip
        ground.add_geom(name="mlpfac_bumps", type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname="mlpfac_bumps",
                        pos=[(x0 + x1) / 2, (y0 + y1) / 2, 0.0], contype=ct, conaffinity=ca, **look)  # fmt: skip
    out = []
    for i, (g, x, y, reach) in enumerate(feet):  # each tile at first under its geom at rest, flat: the floor
        tile = spec.worldbody.add_body(name=f"mlpfac_tile_{i}", mocap=True, pos=[x, y, z0])
        tile.add_geom(name=f"mlpfac_tile_{i}", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[TILE_SIZE, TILE_SIZE, 1.0],
                      contype=0, conaffinity=free[i], group=4, **look)  # fmt: skip
        spec.geoms[g].contype, spec.geoms[g].conaffinity = free[i] | ramp_bit, 0
        out.append((g, f"mlpfac_tile_{i}", reach))
    return out
