"""The world a run drove in, as the recording shows it: the terrain as meshes (the rough ground's
heightfield, the ramps, the kerbs, the floor patches in their own colour) under ``world/terrain``, the floor
tilted from a ``slope`` event on, the robot drawn at the ground's height under it, and the force of
a ``force`` event as an arrow on the robot while it acts (``world/force``).

The record carries the terrain as plain data (``record.world``, from
:meth:`mlpfac.plants.world.layout.Terrain.as_dict`) and the events as they were applied; nothing here
reads the plant. A slope turns the floor's frame in the 3D view: the entities drawn in it (the
floor, the terrain, the paths, the arrows) are given the tilt as their transform at the event's
time, and the robot's pose is composed with it (the top view stays a map).
"""

from __future__ import annotations

import math

import numpy as np
import rerun as rr

from mlpfac.log.schema import FORCE_COLORS
from mlpfac.log.series import ns
from mlpfac.loop.record import RunRecord
from mlpfac.plants.world.terrain import ground_height

FLOOR_FRAME = (
    "world/floor",
    "world/terrain",
    "world/reference_path",
    "world/reference_now",
    "world/path",
    "world/force",
)
LOW_COLOR, HIGH_COLOR = np.array([105, 92, 72]), np.array([196, 178, 140])  # the rough ground, by height
RAMP_COLOR = (150, 128, 96)
KERB_COLOR = (170, 170, 165)  # a kerb: concrete grey
# a ramp's prism (PlacedRamp.corners: its profile's points 0-3 along it, 2 i + side): each side's
# profile, the slope up, the top, the slope down, the bottom; a closed surface, each edge in two triangles
PRISM = np.array([[0, 2, 4], [0, 4, 6], [1, 5, 3], [1, 7, 5], [0, 1, 2], [1, 3, 2], [2, 3, 4], [3, 5, 4],
                  [4, 5, 6], [5, 7, 6], [0, 6, 1], [1, 6, 7]], dtype=np.uint32)  # fmt: skip
PATCH_COLOR = (50, 120, 230, 170)  # a wet patch: blue, half see-through
PATCH_LIFT = 0.003  # m: a patch drawn this far above the ground under it (it is flush with the floor)
FORCE_COLOR = FORCE_COLORS[0]
ARROW_M_PER_N = 0.02  # m of arrow a newton (30 N: 0.6 m)
ARROW_HEIGHT = 0.12  # m above the ground: the arrow's foot, about the robot's centre of mass


def send_terrain(rec: rr.RecordingStream, world: dict) -> None:
    """The terrain of ``world`` (``record.world``; nothing when empty) as static meshes."""
    if not world:
        return
    grid = world.get("grid")
    if grid is not None:
        rec.log("world/terrain/bumps", _heightfield(world), static=True)
    tri = PRISM
    for key, color in (("ramps", RAMP_COLOR), ("kerbs", KERB_COLOR)):  # a kerb: a ramp of vertical slopes
        for i, corners in enumerate(world.get(key, [])):
            v = np.asarray(corners, dtype=np.float32)
            rec.log(f"world/terrain/{key[:-1]}_{i}", rr.Mesh3D(vertex_positions=v, triangle_indices=tri,
                    albedo_factor=color), static=True)  # fmt: skip
    for i, p in enumerate(world.get("patches", [])):
        rec.log(f"world/terrain/patch_{i}", _disc(world, p), static=True)


def _heightfield(world: dict) -> rr.Mesh3D:
    """The rough ground's grid as a mesh of two triangles a cell, coloured by height."""
    z = np.asarray(world["grid"], dtype=np.float32)
    nrow, ncol = z.shape
    x0, y0 = world["arena"][:2]
    dx, dy = world["cell"]
    xs, ys = x0 + dx * np.arange(ncol), y0 + dy * np.arange(nrow)
    v = np.stack([np.broadcast_to(xs[None, :], z.shape), np.broadcast_to(ys[:, None], z.shape), z], axis=-1)
    idx = np.arange(nrow * ncol, dtype=np.uint32).reshape(nrow, ncol)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    faces = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    top = float(z.max()) or 1.0
    share = (z / top).reshape(-1, 1)
    colors = (LOW_COLOR + share * (HIGH_COLOR - LOW_COLOR)).astype(np.uint8)
    return rr.Mesh3D(vertex_positions=v.reshape(-1, 3), triangle_indices=faces, vertex_colors=colors)


def _disc(world: dict, patch: dict, n: int = 48) -> rr.Mesh3D:
    """A floor patch as a disc just above the ground under it."""
    a = 2.0 * np.pi * np.arange(n) / n
    x = np.concatenate([[patch["x"]], patch["x"] + patch["radius"] * np.cos(a)])
    y = np.concatenate([[patch["y"]], patch["y"] + patch["radius"] * np.sin(a)])
    z = ground(world, x, y) + PATCH_LIFT
    faces = np.array([[0, 1 + k, 1 + (k + 1) % n] for k in range(n)], dtype=np.uint32)
    return rr.Mesh3D(
        vertex_positions=np.c_[x, y, z].astype(np.float32), triangle_indices=faces, albedo_factor=PATCH_COLOR
    )


def ground(world: dict, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The ground's height at the points (x, y) (:func:`mlpfac.plants.world.terrain.ground_height`, the
    function the plant measures the robot against); 0 without a world."""
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    if not world:
        return np.zeros(x.shape)
    w, nodes = (np.ascontiguousarray(a, dtype=float) for a in world["packed"])
    return np.array(
        [ground_height(w, nodes, float(a), float(b)) for a, b in zip(x.ravel(), y.ravel(), strict=True)]
    ).reshape(x.shape)


def tilt(event: dict) -> np.ndarray:
    """The quaternion (x, y, z, w) turning the floor of a ``slope`` event into the view's frame: its
    uphill heading rises by its angle (about the horizontal axis across it)."""
    a = math.radians(float(event["params"].get("angle_deg", 0.0)))
    h = math.radians(float(event["params"].get("heading_deg", 0.0)))
    axis = (math.sin(h), -math.cos(h), 0.0)  # heading x up: turns the heading upwards
    s = math.sin(a / 2)
    return np.array([axis[0] * s, axis[1] * s, 0.0, math.cos(a / 2)])


def tilts(record: RunRecord) -> list[tuple[float, np.ndarray]]:
    """(time, quaternion) of each slope event applied, in time order."""
    return [(float(ev["time"]), tilt(ev)) for ev in record.events if ev.get("kind") == "slope"]


def send_tilts(rec: rr.RecordingStream, record: RunRecord, events: list[dict]) -> None:
    """The floor's frame tilted at each slope event of ``events`` (just applied)."""
    slopes = [ev for ev in events if ev.get("kind") == "slope"]
    if not slopes:
        return
    times = np.array([float(ev["time"]) for ev in slopes])
    idx = [rr.TimeColumn("sim_time", duration=ns(times)), rr.TimeColumn("step", sequence=np.round(times / record.T).astype(np.int64))]  # fmt: skip
    quats = np.array([tilt(ev) for ev in slopes])
    for path in FLOOR_FRAME:
        rec.send_columns(path, indexes=idx, columns=rr.Transform3D.columns(quaternion=quats))


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternion products a b of rows (x, y, z, w)."""
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], axis=-1)  # fmt: skip


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Vectors v (rows) turned by quaternions q (rows)."""
    u, w = q[:, :3], q[:, 3:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def robot_pose(record: RunRecord, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The robot's translations and quaternions (x, y, z, w) at ``rows`` in the 3D view: its pose at
    the ground's height under it, in the floor's frame tilted as it was then."""
    x, y, th = record.pose[rows].T
    p = np.c_[x, y, ground(record.world, x, y)]
    q = np.c_[np.zeros_like(x), np.zeros_like(x), np.sin(th / 2), np.cos(th / 2)]
    slopes = tilts(record)
    if slopes:
        t = record.t[rows]
        now = np.tile([0.0, 0.0, 0.0, 1.0], (len(rows), 1))
        for time, quat in slopes:
            now[t >= time - 1e-9] = quat
        p, q = _rotate(now, p), _qmul(now, q)
    return p, q


def send_forces(rec: rr.RecordingStream, record: RunRecord, rows: np.ndarray, idx: list) -> None:
    """The force on the robot at ``rows`` (``record.plant["force"]``, the world's axes) as an arrow
    from its centre, in the floor's frame, with its size in newtons; none while no force acts."""
    f = record.plant.get("force")
    if f is None or not len(rows):
        return
    fx, fy = f[rows, 0], f[rows, 1]
    on = np.isfinite(fx) & np.isfinite(fy) & ((fx != 0) | (fy != 0))
    x, y = record.pose[rows, 0], record.pose[rows, 1]
    z = ground(record.world, x, y) + ARROW_HEIGHT
    size = np.hypot(fx, fy)
    rec.send_columns(
        "world/force",
        indexes=idx,
        columns=rr.Arrows3D.columns(
            origins=np.c_[x, y, z][on],
            vectors=ARROW_M_PER_N * np.c_[fx, fy, np.zeros_like(fx)][on],
            labels=[f"{s:.3g} N" for s in size[on]],
        ).partition(on.astype(np.int32)),
    )


def style_force(rec: rr.RecordingStream) -> None:
    """The force arrows' colour and width, once."""
    rec.log("world/force", rr.Arrows3D.from_fields(colors=[FORCE_COLOR], radii=[0.015]), static=True)
